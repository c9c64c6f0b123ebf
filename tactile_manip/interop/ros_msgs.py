"""The ROS 2 message types of the MCAP export: their fields, their ``ros2msg`` schema text and a JSON Schema.

The fields are those of the ROS 2 interface packages (``builtin_interfaces``, ``std_msgs``, ``sensor_msgs``,
``geometry_msgs``, ``diagnostic_msgs``, ``std_srvs``), for the MCAP export and the live topics of
``tactile-manip serve`` alike (one definition of each; :mod:`tactile_manip.interop.ros2.type_hash` hashes them);
types are keyed ``pkg/Type`` as ``.msg`` files refer to each other, and MCAP schemas are named
``pkg/msg/Type`` as rosbag2 names them. The ``ros2msg`` text is the type's own fields followed by each type it
uses, after a line of 80 ``=`` and ``MSG: pkg/Type``, which is how rosbag2 stores a definition in MCAP. The
JSON Schema (for JSON-encoded messages) maps numbers to ``number`` / ``integer``, strings to ``string``,
``T[]`` to arrays, and ``uint8[]`` to a base64 string (``contentEncoding: base64``). This module imports
numpy only.
"""

from __future__ import annotations

import base64
from typing import Any

import numpy as np

from tactile_manip.interop.cdr import PRIMITIVES, split_type

# pkg/Type -> [(field type, field name)], in the order of the ROS 2 .msg files
MESSAGES: dict[str, list[tuple[str, str]]] = {
    "builtin_interfaces/Time": [("int32", "sec"), ("uint32", "nanosec")],
    "std_msgs/Header": [("builtin_interfaces/Time", "stamp"), ("string", "frame_id")],
    "std_msgs/MultiArrayDimension": [("string", "label"), ("uint32", "size"), ("uint32", "stride")],
    "std_msgs/MultiArrayLayout": [("std_msgs/MultiArrayDimension[]", "dim"), ("uint32", "data_offset")],
    "std_msgs/Float32MultiArray": [("std_msgs/MultiArrayLayout", "layout"), ("float32[]", "data")],
    "std_msgs/Float32": [("float32", "data")],
    "std_msgs/String": [("string", "data")],
    "sensor_msgs/Image": [("std_msgs/Header", "header"), ("uint32", "height"), ("uint32", "width"),
                          ("string", "encoding"), ("uint8", "is_bigendian"), ("uint32", "step"),
                          ("uint8[]", "data")],
    "sensor_msgs/JointState": [("std_msgs/Header", "header"), ("string[]", "name"), ("float64[]", "position"),
                               ("float64[]", "velocity"), ("float64[]", "effort")],
    # live topics (tactile-manip serve)
    "geometry_msgs/Vector3": [("float64", "x"), ("float64", "y"), ("float64", "z")],
    "geometry_msgs/Point": [("float64", "x"), ("float64", "y"), ("float64", "z")],
    "geometry_msgs/PointStamped": [("std_msgs/Header", "header"), ("geometry_msgs/Point", "point")],
    "geometry_msgs/Wrench": [("geometry_msgs/Vector3", "force"), ("geometry_msgs/Vector3", "torque")],
    "geometry_msgs/WrenchStamped": [("std_msgs/Header", "header"), ("geometry_msgs/Wrench", "wrench")],
    "sensor_msgs/MagneticField": [("std_msgs/Header", "header"), ("geometry_msgs/Vector3", "magnetic_field"),
                                  ("float64[9]", "magnetic_field_covariance")],
    "diagnostic_msgs/KeyValue": [("string", "key"), ("string", "value")],
    # level: OK = 0, WARN = 1, ERROR = 2, STALE = 3
    "diagnostic_msgs/DiagnosticStatus": [("byte", "level"), ("string", "name"), ("string", "message"),
                                         ("string", "hardware_id"), ("diagnostic_msgs/KeyValue[]", "values")],
    "diagnostic_msgs/DiagnosticArray": [("std_msgs/Header", "header"),
                                        ("diagnostic_msgs/DiagnosticStatus[]", "status")],
    # services: a .srv's request and response are the messages <Service>_Request and <Service>_Response
    "std_srvs/Trigger_Request": [],
    "std_srvs/Trigger_Response": [("bool", "success"), ("string", "message")],
    # what ROS 2 (Iron on) adds to every service's event message; needed for a service's type hash
    "service_msgs/ServiceEventInfo": [("uint8", "event_type"), ("builtin_interfaces/Time", "stamp"),
                                      ("char[16]", "client_gid"), ("int64", "sequence_number")],
    # our own, where no standard type fits (their .msg files: tactile_manip/interop/ros2/msg/)
    "tactile_manip_msgs/Angle": [("std_msgs/Header", "header"), ("float32", "angle"), ("float32", "confidence"),
                                 ("bool", "defined"), ("bool", "plausible")],
    "tactile_manip_msgs/Contact": [("std_msgs/Header", "header"), ("bool", "in_contact"), ("bool", "plausible"),
                                   ("geometry_msgs/Point", "position"), ("geometry_msgs/Vector3", "position_sigma"),
                                   ("geometry_msgs/Vector3", "force"), ("geometry_msgs/Vector3", "force_sigma")],
}
# pkg/Service: its request and response are MESSAGES[f"{pkg/Service}_Request"] and [..._Response]. A request
# with no fields (std_srvs/Trigger's) travels as one uint8 on the ROS 2 wire, the member rosidl adds to an empty
# structure (``structure_needs_at_least_one_member``).
SERVICES: tuple[str, ...] = ("std_srvs/Trigger",)
SEPARATOR = "=" * 80
_INTEGER = {k for k in PRIMITIVES if k not in ("float32", "float64", "bool")}


def schema_name(type_name: str) -> str:
    """``"std_msgs/Float32"`` -> ``"std_msgs/msg/Float32"`` (the MCAP schema name rosbag2 uses)."""
    pkg, name = type_name.split("/")
    return f"{pkg}/msg/{name}"


def dependencies(type_name: str) -> list[str]:
    """The message types ``type_name`` uses, directly or not, in order of first use."""
    out: list[str] = []

    def visit(t: str) -> None:
        for field_type, _ in MESSAGES[t]:
            base, _ = split_type(field_type)
            if base in MESSAGES and base not in out:
                out.append(base)
                visit(base)

    visit(type_name)
    return out


def ros2msg_text(type_name: str) -> str:
    """The ``ros2msg`` schema text of ``type_name`` with the definitions of every type it uses."""
    def fields(t: str) -> str:
        return "\n".join(f"{ft} {name}" for ft, name in MESSAGES[t])

    parts = [fields(type_name)] + [f"{SEPARATOR}\nMSG: {d}\n{fields(d)}" for d in dependencies(type_name)]
    return "\n".join(parts) + "\n"


def json_schema(type_name: str) -> dict[str, Any]:
    """A JSON Schema (draft 2020-12) of ``type_name`` as :func:`to_json` writes it."""
    schema = _json_object(type_name)
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": schema_name(type_name), **schema}


def _json_object(type_name: str) -> dict[str, Any]:
    props = {}
    for field_type, name in MESSAGES[type_name]:
        base, is_seq = split_type(field_type)
        if base in ("uint8", "byte", "char") and is_seq:
            props[name] = {"type": "string", "contentEncoding": "base64"}
            continue
        item = (_json_object(base) if base in MESSAGES else {"type": "string"} if base == "string"
                else {"type": "boolean"} if base == "bool" else {"type": "integer" if base in _INTEGER else "number"})
        props[name] = {"type": "array", "items": item} if is_seq else item
    return {"type": "object", "properties": props, "required": [n for _, n in MESSAGES[type_name]]}


def to_json(type_name: str, msg: dict[str, Any]) -> dict[str, Any]:
    """``msg`` as JSON-able values: arrays to lists (float32 through float64, which is exact), bytes to base64."""
    out = {}
    for field_type, name in MESSAGES[type_name]:
        base, is_seq = split_type(field_type)
        value = msg[name]
        if base in MESSAGES:
            out[name] = [to_json(base, v) for v in value] if is_seq else to_json(base, value)
        elif is_seq and base in ("uint8", "byte", "char"):
            out[name] = base64.b64encode(bytes(value)).decode("ascii")
        elif base in PRIMITIVES:  # through the field's own type, so a float32 holds what CDR would carry
            out[name] = np.asarray(value, dtype=PRIMITIVES[base][2]).tolist()
        else:
            out[name] = list(value) if is_seq else value
    return out


def from_json(type_name: str, obj: dict[str, Any]) -> dict[str, Any]:
    """The inverse of :func:`to_json`: numeric sequences back to numpy arrays of their type, base64 to bytes."""
    out = {}
    for field_type, name in MESSAGES[type_name]:
        base, is_seq = split_type(field_type)
        value = obj[name]
        if base in MESSAGES:
            out[name] = [from_json(base, v) for v in value] if is_seq else from_json(base, value)
        elif is_seq and base in ("uint8", "byte", "char"):
            out[name] = base64.b64decode(value)
        elif is_seq and base in PRIMITIVES:
            out[name] = np.asarray(value, dtype=PRIMITIVES[base][2])
        else:
            out[name] = value
    return out
