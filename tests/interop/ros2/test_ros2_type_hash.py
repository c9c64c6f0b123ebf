"""ROS 2 type hashes (RIHS01) of our message table against the hashes ROS 2 itself publishes, and the DDS type
names rmw_zenoh puts in its key expressions."""

from __future__ import annotations

import json

import pytest

from tactile_manip.interop.ros2.type_hash import (
    dds_type_name,
    parse_field_type,
    ros_name,
    type_description,
    type_hash,
)
from tactile_manip.interop.ros_msgs import MESSAGES, SERVICES

# Where the expected values come from:
# - std_msgs/msg/String: rmw_zenoh's docs/design.md (ros2/rmw_zenoh, the `chatter` key expression example,
#   `0/chatter/std_msgs::msg::dds_::String_/RIHS01_df66...`), the hash a Jazzy talker announces.
# - every other type: the hash arrays rosidl_generator_c writes into `<type>__description.c` for ROS 2 Kilted, as
#   vendored in hpmicro/hpm_sdk under middleware/microros/kilted/include/<pkg>/<pkg>/{msg,srv}/detail/ (e.g.
#   sensor_msgs/msg/detail/image__description.c; ServiceEventInfo and KeyValue from the EXPECTED_HASH blocks of
#   std_srvs/srv/detail/trigger__description.c and diagnostic_msgs/msg/detail/diagnostic_array__description.c).
#   These interface definitions and the hashing are the same in Jazzy and Kilted; std_msgs/Header and
#   builtin_interfaces/Time there equal the values rmw_zenoh and rosbag2 users quote for Jazzy.
PUBLISHED = {
    "std_msgs/msg/String": "df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    "builtin_interfaces/msg/Time": "b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197",
    "std_msgs/msg/Header": "f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01",
    "std_msgs/msg/MultiArrayDimension": "5e773a60a4c7fc8a54985f307c7837aa2994252a126c301957a24e31282c9cbe",
    "std_msgs/msg/MultiArrayLayout": "4c66e6f78e740ac103a94cf63259f968e48c617e7699e829b63c21a5cb50dac6",
    "std_msgs/msg/Float32MultiArray": "0599f6f85b4bfca379873a0b4375a0aca022156bd2d7021275d116ed1fa8bfe0",
    "sensor_msgs/msg/Image": "d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47",
    "sensor_msgs/msg/JointState": "a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e",
    "sensor_msgs/msg/MagneticField": "e80f32f56a20486c9923008fc1a1db07bbb273cbbf6a5b3bfa00835ee00e4dff",
    "geometry_msgs/msg/Vector3": "cc12fe83e4c02719f1ce8070bfd14aecd40f75a96696a67a2a1f37f7dbb0765d",
    "geometry_msgs/msg/Point": "6963084842a9b04494d6b2941d11444708d892da2f4b09843b9c43f42a7f6881",
    "geometry_msgs/msg/PointStamped": "4c0296af86e01e562e9e0405d138a01537247580076c58ea38d7923ac1045897",
    "geometry_msgs/msg/Wrench": "018e8519d57c16adbe97c9fe1460ef21fec7e31bc541de3d653a35895677ce52",
    "geometry_msgs/msg/WrenchStamped": "8dc3deaf06b2ab281f9f9a742a8961c328ca7cec16e3fd6586d3a5c83fa78f77",
    "diagnostic_msgs/msg/KeyValue": "d68081eaa540288c5440753baecef0c4e16e81a5f78ad68902ded5100413bb42",
    "diagnostic_msgs/msg/DiagnosticStatus": "b0e3e692ea2d54a8af2f4ef1930e81556a2db55216b771f8a7d2724ed47bf0e4",
    "diagnostic_msgs/msg/DiagnosticArray": "5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e",
    "service_msgs/msg/ServiceEventInfo": "41bcbbe07a75c9b52bc96bfd5c24d7f0fc0a08c0cb7921b3373c5732345a6f45",
    "std_srvs/srv/Trigger": "eeff2cd6fa5ad9d27cdf4dec64818317839b62f212a91e6b5304b634b2062c5f",
    "std_srvs/srv/Trigger_Request": "d010825374ce8918e72bfd826c82603e60f45419e932ea976f807b74a863a199",
    "std_srvs/srv/Trigger_Response": "2d946c21e2fc3f1e9ca6986a8191d85fcc70097a8bb7771a053564bc47009cdf",
    "std_srvs/srv/Trigger_Event": "ec4a1d26b0575e61906890342aba9523a2360e9845857c5590fa6e23bc39e1c2",
}


@pytest.mark.parametrize("name", sorted(PUBLISHED))
def test_our_hash_of_each_type_is_the_one_ros2_publishes(name):
    assert type_hash(name) == "RIHS01_" + PUBLISHED[name]


def test_table_names_and_ros2_names_give_the_same_hash():
    assert type_hash("std_msgs/String") == type_hash("std_msgs/msg/String")
    assert type_hash("std_srvs/Trigger") == type_hash("std_srvs/srv/Trigger")
    assert ros_name("std_srvs/Trigger_Response") == "std_srvs/srv/Trigger_Response"
    assert ros_name("diagnostic_msgs/KeyValue") == "diagnostic_msgs/msg/KeyValue"


def test_every_type_of_the_table_and_every_service_hashes():
    for name in [*MESSAGES, *SERVICES]:
        h = type_hash(name)
        assert h.startswith("RIHS01_") and len(h) == 7 + 64 and int(h[7:], 16) >= 0, name


def test_dds_type_names_as_rmw_zenoh_writes_them():
    assert dds_type_name("std_msgs/msg/String") == "std_msgs::msg::dds_::String_"
    assert dds_type_name("sensor_msgs/MagneticField") == "sensor_msgs::msg::dds_::MagneticField_"
    assert dds_type_name("std_srvs/srv/Trigger") == "std_srvs::srv::dds_::Trigger_"
    assert dds_type_name("std_srvs/Trigger") == "std_srvs::srv::dds_::Trigger_"


def test_the_description_of_a_nested_type_lists_what_it_uses_sorted_and_without_defaults():
    d = type_description("sensor_msgs/MagneticField")
    assert [t["type_name"] for t in d["referenced_type_descriptions"]] == \
        ["builtin_interfaces/msg/Time", "geometry_msgs/msg/Vector3", "std_msgs/msg/Header"]
    cov = d["type_description"]["fields"][2]
    # float64 is FieldType 11; a fixed array adds 48 and carries its size as capacity
    assert cov == {"name": "magnetic_field_covariance",
                   "type": {"type_id": 11 + 48, "capacity": 9, "string_capacity": 0, "nested_type_name": ""}}
    assert "default_value" not in json.dumps(d)


def test_field_types_of_every_shape_get_rosidl_type_ids():
    table = {"demo/Shapes": [("string<=8", "label"), ("int32[<=4]", "few"), ("string<=5[3]", "tags"),
                             ("byte", "b"), ("char", "c"), ("wstring[]", "w"), ("demo/Empty[]", "empties")],
             "demo/Empty": []}
    d = type_description("demo/Shapes", table, ())
    got = [(f["name"], f["type"]["type_id"], f["type"]["capacity"], f["type"]["string_capacity"],
            f["type"]["nested_type_name"]) for f in d["type_description"]["fields"]]
    assert got == [("label", 21, 0, 8, ""), ("few", 6 + 96, 4, 0, ""), ("tags", 21 + 48, 3, 5, ""),
                   ("b", 16, 0, 0, ""), ("c", 3, 0, 0, ""), ("w", 18 + 144, 0, 0, ""),
                   ("empties", 1 + 144, 0, 0, "demo/msg/Empty")]
    # a structure with no fields is hashed with the one member rosidl gives it
    assert d["referenced_type_descriptions"] == [{"type_name": "demo/msg/Empty", "fields": [
        {"name": "structure_needs_at_least_one_member",
         "type": {"type_id": 3, "capacity": 0, "string_capacity": 0, "nested_type_name": ""}}]}]


def test_any_change_of_structure_changes_the_hash():
    base = {"demo/A": [("float64", "x"), ("float32", "y")]}
    variants = [{"demo/A": [("float64", "x"), ("float64", "y")]},      # a type
                {"demo/A": [("float64", "x"), ("float32", "z")]},      # a name
                {"demo/A": [("float32", "y"), ("float64", "x")]},      # the order
                {"demo/A": [("float64", "x"), ("float32[2]", "y")]}]   # an array
    hashes = {type_hash("demo/A", t, ()) for t in [base, *variants]}
    assert len(hashes) == 1 + len(variants)


def test_bad_names_and_field_types_are_refused_with_what_was_given():
    with pytest.raises(KeyError, match="demo/msg/Nothing"):
        type_hash("demo/Nothing")
    with pytest.raises(ValueError, match="'a/b/c/d'"):
        type_hash("a/b/c/d")
    for bad in ("float64[<=]", "int32<=4", "float64[", "9lives"):
        with pytest.raises(ValueError, match="field type"):
            parse_field_type(bad)
