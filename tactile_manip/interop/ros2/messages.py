"""The ROS 2 messages ``tactile-manip serve`` publishes, built from a reading and its estimate.

Per pad, under its namespace (``/tactile`` by default; SI units; ``<frame>`` is ``<name>_pad``, the pad frame):

==================  ==========================================  =================================================
topic               type                                        what
==================  ==========================================  =================================================
``field_raw``       ``std_msgs/msg/Float32MultiArray``          the field as the chips report it, uT, dims
                                                                ``taxels`` (R*C, row major from row 0 at +y) x
                                                                ``axes`` (x, y, z), every reading
``field``           ``std_msgs/msg/Float32MultiArray``          the same, baseline-subtracted
``angle``           ``tactile_manip_msgs/msg/Angle``            in-plane angle (rad), confidence, ``defined``,
                                                                ``plausible``
``contact``         ``tactile_manip_msgs/msg/Contact``          position (m; z: depth of the indentation) and
                                                                force (N; x, y shear, z normal) with their sigmas,
                                                                ``in_contact``, ``plausible``; NaN where the
                                                                estimator gives no value
``depth``           ``sensor_msgs/msg/Image`` (``32FC1``, mm)    the reconstructed depth image, at ``depth_hz``
==================  ==========================================  =================================================

and ``/diagnostics`` (``diagnostic_msgs/msg/DiagnosticArray``, ROS 2's global diagnostics topic) with one status
per pad. A whole reading is one message per topic (not one ``sensor_msgs/MagneticField`` per chip, which would be
16 messages per reading), as the MCAP export writes the field (:func:`~tactile_manip.interop.mcap_export.field_message`).
The angle and contact types are our own (package ``tactile_manip_msgs``, :data:`CUSTOM`): no standard message
carries a value with its confidence or sigma and the flags that say whether to use it. Their ``.msg`` files ship
in ``tactile_manip/interop/ros2/msg/`` and are the table's text (:func:`msg_text`; a test holds them equal).
"""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.interop.mcap_export import field_message, image_message, stamp
from tactile_manip.interop.ros_msgs import MESSAGES

CUSTOM = ("tactile_manip_msgs/Angle", "tactile_manip_msgs/Contact")
MSG_DIR = Path(__file__).resolve().parent / "msg"
NAN = float("nan")

# relative topic name -> message type (pkg/Type), as each pad publishes them
TOPICS: dict[str, str] = {"field_raw": "std_msgs/Float32MultiArray", "field": "std_msgs/Float32MultiArray",
                          "angle": "tactile_manip_msgs/Angle", "contact": "tactile_manip_msgs/Contact",
                          "depth": "sensor_msgs/Image"}
DIAGNOSTICS_TOPIC = "/diagnostics"
DIAGNOSTICS_TYPE = "diagnostic_msgs/DiagnosticArray"
TRIGGER = "std_srvs/Trigger"
# diagnostic_msgs/DiagnosticStatus levels
OK, WARN, ERROR, STALE = 0, 1, 2, 3


def ros2_type(type_name: str, *, service: bool = False) -> str:
    """``"std_msgs/String"`` -> ``"std_msgs/msg/String"`` (``srv`` for a service type)."""
    pkg, name = type_name.split("/")
    return f"{pkg}/{'srv' if service else 'msg'}/{name}"


def msg_text(type_name: str) -> str:
    """The ``.msg`` text of ``type_name``: one ``type name`` line per field, as the shipped files hold them."""
    return "".join(f"{ft} {name}\n" for ft, name in MESSAGES[type_name])


def msg_file(type_name: str) -> Path:
    """Where the shipped ``.msg`` file of one of :data:`CUSTOM` lies."""
    return MSG_DIR / f"{type_name.split('/')[1]}.msg"


def header(stamp_ns: int, frame_id: str) -> dict[str, Any]:
    return {"stamp": stamp(stamp_ns), "frame_id": frame_id}


def _num(value: float | None, scale: float = 1.0) -> float:
    return NAN if value is None else float(value) * scale


def vector(x: float | None, y: float | None, z: float | None, scale: float = 1.0) -> dict[str, float]:
    return {"x": _num(x, scale), "y": _num(y, scale), "z": _num(z, scale)}


def raw_field_message(field_raw_ut: np.ndarray) -> dict[str, Any]:
    """Float32MultiArray of the raw (R, C, 3) field in uT (as :func:`field_message` lays the field out)."""
    return field_message(field_raw_ut)


def angle_message(estimate, stamp_ns: int, frame_id: str) -> dict[str, Any]:
    """``tactile_manip_msgs/Angle`` of a :class:`~tactile_manip.perception.tactile_estimator.TactileEstimate`."""
    a = estimate.angle
    return {"header": header(stamp_ns, frame_id), "angle": float(a.angle_rad), "confidence": float(a.confidence),
            "defined": bool(a.defined), "plausible": bool(a.plausible)}


def contact_message(estimate, stamp_ns: int, frame_id: str) -> dict[str, Any]:
    """``tactile_manip_msgs/Contact`` of an estimate: the contact model's position (x, y and, as z, the depth of
    the indentation; m) and force (x, y shear, z normal; N) with their sigmas; without a contact model, the
    estimate's ``position_mm`` (the reconstructed contact's centroid) and no force. Position is NaN out of
    contact; any quantity the estimator does not give is NaN."""
    c = estimate.contact
    in_contact = bool(estimate.in_contact)
    msg = {"header": header(stamp_ns, frame_id), "in_contact": in_contact, "plausible": bool(estimate.plausible),
           "position": vector(None, None, None), "position_sigma": vector(None, None, None),
           "force": vector(None, None, None), "force_sigma": vector(None, None, None)}
    if c is not None:
        if in_contact:
            msg["position"] = vector(c.x_mm, c.y_mm, c.depth_mm, 1e-3)
            msg["position_sigma"] = vector(c.x_sigma_mm, c.y_sigma_mm, c.depth_sigma_mm, 1e-3)
        msg["force"] = vector(c.shear_x_n, c.shear_y_n, c.force_n)
        msg["force_sigma"] = vector(c.shear_x_sigma_n, c.shear_y_sigma_n, c.force_sigma_n)
    elif in_contact and estimate.position_mm is not None:
        x, y = estimate.position_mm
        msg["position"] = vector(x, y, None, 1e-3)
    return msg


def depth_message(depth_mm: np.ndarray, stamp_ns: int, frame_id: str) -> dict[str, Any]:
    """``sensor_msgs/Image`` ``32FC1`` of a depth image in mm."""
    return image_message(depth_mm, stamp_ns, frame_id)


def diagnostic_status(*, level: int, name: str, message: str, hardware_id: str,
                      values: dict[str, Any]) -> dict[str, Any]:
    """One ``diagnostic_msgs/DiagnosticStatus`` (values as strings, floats to 4 significant digits)."""
    def text(v: Any) -> str:
        return f"{v:.4g}" if isinstance(v, float) else str(v)

    return {"level": int(level), "name": name, "message": message, "hardware_id": hardware_id,
            "values": [{"key": k, "value": text(v)} for k, v in values.items()]}


def diagnostic_array(statuses: list[dict[str, Any]], stamp_ns: int) -> dict[str, Any]:
    return {"header": header(stamp_ns, ""), "status": statuses}


def trigger_response(success: bool, message: str) -> dict[str, Any]:
    """``std_srvs/Trigger`` response."""
    return {"success": bool(success), "message": message}






class StampedEncoder:
    """CDR of a message that is a ``std_msgs/Header`` (with a fixed ``frame_id``) then primitives only, in one
    ``struct.pack``: what :func:`~tactile_manip.interop.cdr.encode` writes (a test holds them equal), at a
    fraction of its cost, for the topics every reading publishes.

    ``body`` lists the primitive types after the header in order (nested messages flattened); ``encode(stamp_ns,
    *values)`` takes the values in that order.
    """

    def __init__(self, frame_id: str, body: tuple[str, ...]) -> None:
        from tactile_manip.interop.cdr import HEADER, PRIMITIVES

        name = frame_id.encode("utf-8")
        self._head = HEADER
        self._frame = struct.pack("<I", len(name) + 1) + name + b"\0"
        offset, fmt = 8 + len(self._frame), "<"
        for kind in body:
            code, size, _ = PRIMITIVES[kind]
            pad = -offset % size
            fmt += "x" * pad + code
            offset += pad + size
        self._body = struct.Struct(fmt)

    def encode(self, stamp_ns: int, *values: Any) -> bytes:
        sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
        return self._head + struct.pack("<iI", sec, nanosec) + self._frame + self._body.pack(*values)


ANGLE_BODY = ("float32", "float32", "bool", "bool")
CONTACT_BODY = ("bool", "bool") + ("float64",) * 12


def angle_values(estimate) -> tuple:
    """The values of :data:`ANGLE_BODY` for an estimate (as :func:`angle_message` sets them)."""
    a = estimate.angle
    return float(a.angle_rad), float(a.confidence), bool(a.defined), bool(a.plausible)


def contact_values(estimate) -> tuple:
    """The values of :data:`CONTACT_BODY` for an estimate (as :func:`contact_message` sets them)."""
    msg = contact_message(estimate, 0, "")
    return (msg["in_contact"], msg["plausible"],
            *(msg[k][axis] for k in ("position", "position_sigma", "force", "force_sigma") for axis in "xyz"))


class FieldEncoder:
    """CDR of :func:`field_message` for fields of one shape: the layout written once, the data appended."""

    def __init__(self, shape: tuple[int, ...]) -> None:
        from tactile_manip.interop.cdr import encode
        from tactile_manip.interop.ros_msgs import MESSAGES

        template = encode(MESSAGES, "std_msgs/Float32MultiArray", field_message(np.zeros(shape, np.float32)))
        self.values = int(np.prod(shape))
        self._prefix = template[:len(template) - 4 * self.values]  # everything up to the data, its count included
        self.shape = tuple(shape)

    def encode(self, field_ut: np.ndarray) -> bytes:
        f = np.asarray(field_ut, dtype="<f4")
        if f.shape != self.shape or not np.isfinite(f).all():
            from tactile_manip.interop.cdr import encode
            from tactile_manip.interop.ros_msgs import MESSAGES

            return encode(MESSAGES, "std_msgs/Float32MultiArray", field_message(f))  # refuses NaN, as it says
        return self._prefix + f.tobytes()
