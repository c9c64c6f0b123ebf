"""The parts of the live ROS 2 path: names as rcl judges them, the shipped .msg files against the message table,
fixed-size arrays in CDR against an independent codec, rmw_zenoh's attachment and QoS text, the in-memory
transport and a publisher's messages."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactile_manip.interop import cdr
from tactile_manip.interop.ros2 import messages as m
from tactile_manip.interop.ros2.names import check_namespace, fully_qualified
from tactile_manip.interop.ros2.publisher import TactilePublisher
from tactile_manip.interop.ros2.transport import (
    DEFAULT,
    SENSOR_DATA,
    MemoryTransport,
    Qos,
    Tee,
)
from tactile_manip.interop.ros2.zenoh_transport import (
    attachment,
    check_bind,
    parse_attachment,
    qos_keyexpr,
    rmw_zid,
)
from tactile_manip.interop.ros_msgs import MESSAGES, ros2msg_text
from tactile_manip.types import TactileReading


@pytest.mark.parametrize("ns, name, full", [("/tactile", "field", "/tactile/field"), ("tactile", "a/b", "/tactile/a/b"),
                                            ("/", "field", "/field"), ("/x", "/abs/t", "/abs/t"),
                                            ("/x", "~/t", "/x/tactile_manip/t"), ("/x", "~", "/x/tactile_manip")])
def test_names_expand_as_rcl_expands_them(ns, name, full):
    assert fully_qualified(ns, name) == full


@pytest.mark.parametrize("ns, name, says", [("/a", "x//y", "empty token"), ("/a", "x/", "no trailing"),
                                            ("/a", "1x", "start with a digit"), ("/a", "x~", "'~' may only come first"),
                                            ("/a", "x__y", "'__'"), ("/a", "{node}", "substitutions"),
                                            ("/a", "x-y", "character '-'"), ("/a~", "x", "'~' is not allowed"),
                                            ("/a", "", "non-empty"), ("/a", "/", "root alone")])
def test_names_ros2_refuses_are_refused_naming_the_part(ns, name, says):
    with pytest.raises(ValueError, match=says):
        fully_qualified(ns, name)
    assert check_namespace("") == "/"


def test_shipped_msg_files_are_the_tables_definitions():
    for type_name in m.CUSTOM:
        lines = [ln for ln in m.msg_file(type_name).read_text().splitlines() if ln and not ln.startswith("#")]
        assert "\n".join(lines) + "\n" == m.msg_text(type_name), type_name


def test_fixed_size_arrays_in_cdr_agree_with_an_independent_codec():
    dyn = pytest.importorskip("mcap_ros2._dynamic", reason="mcap-ros2-support is not installed")
    msg = {"header": {"stamp": {"sec": 5, "nanosec": 9}, "frame_id": "pad"},
           "magnetic_field": {"x": 1e-6, "y": -2e-6, "z": 3.5e-5}, "magnetic_field_covariance": np.arange(9.0)}
    data = cdr.encode(MESSAGES, "sensor_msgs/MagneticField", msg)
    back = cdr.decode(MESSAGES, "sensor_msgs/MagneticField", data)
    assert back["magnetic_field_covariance"].tolist() == list(range(9)) and back["magnetic_field"]["z"] == 3.5e-5
    name = "sensor_msgs/msg/MagneticField"
    theirs = dyn.generate_dynamic(name, ros2msg_text("sensor_msgs/MagneticField"))[name](data)
    assert list(theirs.magnetic_field_covariance) == list(range(9)) and theirs.header.frame_id == "pad"
    enc = dyn.serialize_dynamic(name, ros2msg_text("sensor_msgs/MagneticField"))[name]
    assert enc({"header": {"stamp": {"sec": 5, "nanosec": 9}, "frame_id": "pad"},
                "magnetic_field": {"x": 1e-6, "y": -2e-6, "z": 3.5e-5},
                "magnetic_field_covariance": list(np.arange(9.0))}) == data
    with pytest.raises(ValueError, match=r"float64\[9\], got 8"):
        cdr.encode(MESSAGES, "sensor_msgs/MagneticField", {**msg, "magnetic_field_covariance": np.zeros(8)})


def test_the_attachment_is_zenohs_serialization_of_rmw_zenohs_fields():
    gid = bytes(range(16))
    data = attachment(42, 1_700_000_000_123_456_789, gid)
    assert parse_attachment(data) == (42, 1_700_000_000_123_456_789, gid)
    zext = pytest.importorskip("zenoh.ext", reason="eclipse-zenoh is not installed (extra 'ros2')")
    theirs = zext.z_serialize((zext.Int64(42), zext.Int64(1_700_000_000_123_456_789), gid)).to_bytes()
    assert data == theirs
    with pytest.raises(ValueError):
        parse_attachment(data[:-1])


def test_qos_and_ids_as_rmw_zenoh_writes_them():
    assert qos_keyexpr(SENSOR_DATA) == "2::,5:,:,:,,"   # best effort, keep last 5; the rest rmw_zenoh's defaults
    assert qos_keyexpr(DEFAULT) == "::,10:,:,:,,"
    assert qos_keyexpr(Qos(reliability="reliable", durability="transient_local", depth=42)) == ":1:,:,:,:,,"
    assert rmw_zid("0a0b10") == "ab10"
    with pytest.raises(ValueError, match="depth"):
        Qos(depth=0)
    assert check_bind("127.0.0.1", allow_remote=False) == "127.0.0.1"
    assert check_bind("0.0.0.0", allow_remote=True) == "0.0.0.0"
    for bad, says in [("0.0.0.0", "--allow-remote"), ("myhost", "IP address")]:
        with pytest.raises(ValueError, match=says):
            check_bind(bad, allow_remote=False)


class _Estimate:
    """A stand-in estimator answer with every quantity set (no model needed)."""

    def __init__(self, contact):
        from tactile_manip.types import AngleEstimate

        self.angle = AngleEstimate(angle_rad=0.25, confidence=0.8, defined=True)
        self.contact, self.position_mm = contact, (1.0, -2.0)
        self.in_contact, self.plausible = True, True


def _reading(seq: int) -> TactileReading:
    rng = np.random.default_rng(seq)
    f = rng.normal(0, 50, (4, 4, 3)).astype(np.float32)
    return TactileReading(field_ut=f, field_raw_ut=f + 100, saturated=np.zeros((4, 4, 3), bool), t_host_s=10.0 + seq,
                          seq=seq)


def test_a_publisher_sends_every_topic_with_a_sequence_and_the_estimates_values():
    from tactile_manip.perception.contact import ContactState

    state = ContactState(in_contact=True, x_mm=1.5, y_mm=-0.5, depth_mm=0.3, force_n=4.0, x_sigma_mm=0.2,
                         y_sigma_mm=0.25, force_sigma_n=0.4)
    mt, other = MemoryTransport(), MemoryTransport()
    pub = TactilePublisher(object(), Tee([mt, other]), namespace="/hand/right")
    for seq in range(3):
        pub.publish(_reading(seq), _Estimate(state))
    assert set(mt.topics) == {f"/hand/right/{n}" for n in ("field_raw", "field", "angle", "contact")}
    assert mt.topics["/hand/right/angle"] == ("tactile_manip_msgs/msg/Angle", SENSOR_DATA)
    assert [x.seq for x in mt.on("/hand/right/contact")] == [1, 2, 3] and len(other.messages) == len(mt.messages)
    c = cdr.decode(MESSAGES, "tactile_manip_msgs/Contact", mt.on("/hand/right/contact")[-1].cdr)
    assert c["header"]["frame_id"] == "right_pad" and c["in_contact"] and c["plausible"]
    assert (c["position"]["x"], c["position"]["y"], c["position"]["z"]) == (1.5e-3, -0.5e-3, 0.3e-3)
    assert c["force"]["z"] == 4.0 and c["force_sigma"]["z"] == 0.4 and math.isnan(c["force"]["x"])
    assert math.isnan(c["position_sigma"]["z"])  # the model gives no sigma of the depth: NaN, not 0
    raw = cdr.decode(MESSAGES, "std_msgs/Float32MultiArray", mt.on("/hand/right/field_raw")[-1].cdr)
    assert np.array_equal(raw["data"], np.ravel(_reading(2).field_raw_ut))
    assert pub.drops == 0
    capped = MemoryTransport(max_messages=5)
    pub2 = TactilePublisher(object(), capped, namespace="/t")
    pub2.publish(_reading(0), _Estimate(None))
    pub2.publish(_reading(1), _Estimate(None))
    assert pub2.drops == 3 and len(capped.messages) == 5
    c = cdr.decode(MESSAGES, "tactile_manip_msgs/Contact", capped.on("/t/contact")[0].cdr)
    assert (c["position"]["x"], c["position"]["y"]) == (1e-3, -2e-3) and math.isnan(c["force"]["z"])


def test_depth_needs_a_pose_part_that_decodes_images():
    with pytest.raises(ValueError, match="decodes no depth image"):
        TactilePublisher(object(), MemoryTransport(), depth_hz=5.0)
    with pytest.raises(ValueError, match="positive rate"):
        TactilePublisher(object(), MemoryTransport(), depth_hz=0.0)


def test_services_answer_trigger_responses():
    from tactile_manip.interop.ros2.publisher import trigger_service

    mt = MemoryTransport()
    mt.add_service("/t/ok", "std_srvs/srv/Trigger", trigger_service(lambda: (True, "done")))
    mt.add_service("/t/fails", "std_srvs/srv/Trigger", trigger_service(lambda: 1 / 0))
    request = cdr.HEADER + b"\x00"  # an empty request: the one uint8 rosidl gives an empty structure
    assert cdr.decode(MESSAGES, "std_srvs/Trigger_Response", mt.call("/t/ok", request)) == {"success": True,
                                                                                             "message": "done"}
    failed = cdr.decode(MESSAGES, "std_srvs/Trigger_Response", mt.call("/t/fails", request))
    assert failed["success"] is False and "ZeroDivisionError" in failed["message"]


@pytest.mark.parametrize("frame_id", ["", "p", "pad", "left_pad", "a_longer_frame_name"])
def test_the_one_step_encoders_write_what_the_cdr_codec_writes(frame_id):
    from tactile_manip.perception.contact import ContactState

    rng = np.random.default_rng(len(frame_id))
    for state in (ContactState(in_contact=True, x_mm=1.5, y_mm=-0.5, depth_mm=0.3, force_n=4.0, x_sigma_mm=0.2,
                               y_sigma_mm=0.25, force_sigma_n=0.4, shear_x_n=0.1), None):
        e = _Estimate(state)
        stamp_ns = int(rng.integers(0, 2_000_000_000 * 10**9))  # any time until 2033
        assert m.StampedEncoder(frame_id, m.ANGLE_BODY).encode(stamp_ns, *m.angle_values(e)) == cdr.encode(
            MESSAGES, "tactile_manip_msgs/Angle", m.angle_message(e, stamp_ns, frame_id))
        fast = m.StampedEncoder(frame_id, m.CONTACT_BODY).encode(stamp_ns, *m.contact_values(e))
        slow = cdr.encode(MESSAGES, "tactile_manip_msgs/Contact", m.contact_message(e, stamp_ns, frame_id))
        assert fast.hex() == slow.hex()  # NaNs included: same bits
    for shape in [(4, 4, 3), (5, 1, 3)]:
        f = rng.normal(0, 80, shape).astype(np.float32)
        assert m.FieldEncoder(shape).encode(f) == cdr.encode(MESSAGES, "std_msgs/Float32MultiArray", m.field_message(f))
    with pytest.raises(ValueError, match="NaN"):
        m.FieldEncoder((4, 4, 3)).encode(np.full((4, 4, 3), np.nan))
