"""ROS 2 type hashes (REP-2011, ``RIHS01_<sha256 hex>``) of the message and service types in our table.

A ROS 2 node since Iron announces, with each topic and service, a hash of its type's structure; ``rmw_zenoh``
puts it in every key expression, so a subscriber on a ROS 2 machine matches our topics only if the hashes agree.
The hash is the SHA-256 of a JSON text that rosidl builds from the type:

- the type's own description, ``{"type_name": "pkg/msg/Type", "fields": [...]}``, and the descriptions of every
  type it uses, directly or not, sorted by name (``referenced_type_descriptions``);
- each field as ``{"name", "type": {"type_id", "capacity", "string_capacity", "nested_type_name"}}``, where
  ``type_id`` is the ``type_description_interfaces/FieldType`` number of the base type plus 48 for a fixed
  array (``T[N]``), 96 for a bounded sequence (``T[<=N]``) and 144 for an unbounded one (``T[]``);
  ``capacity`` is N (0 otherwise), ``string_capacity`` the bound of a ``string<=N`` (0 otherwise); default
  values and constants are not part of it;
- a structure with no fields holds one ``uint8 structure_needs_at_least_one_member``, as rosidl generates it;
- Python's ``json.dumps`` layout: keys in the order above, ``", "`` and ``": "`` as separators.

In a ``.msg`` file ``byte`` is IDL ``octet`` (type id 16) and ``char`` is ``uint8`` (type id 3).

A service ``pkg/srv/S`` is described as a structure of three nested fields, ``request_message``
(``S_Request``), ``response_message`` (``S_Response``) and ``event_message`` (``S_Event``: the
``service_msgs/ServiceEventInfo`` ``info``, then the request and the response as sequences of at most one).

Types are named as in :data:`tactile_manip.interop.ros_msgs.MESSAGES` (``"std_msgs/String"``) or as ROS 2
names them (``"std_msgs/msg/String"``, ``"std_srvs/srv/Trigger"``). This module imports the standard library and
the message table only.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from tactile_manip.interop.ros_msgs import MESSAGES, SERVICES

Table = Mapping[str, Sequence[tuple[str, str]]]

# type_description_interfaces/msg/FieldType: the id of each base type of a .msg field
BASE_TYPE_IDS: dict[str, int] = {
    "nested": 1, "int8": 2, "uint8": 3, "int16": 4, "uint16": 5, "int32": 6, "uint32": 7, "int64": 8,
    "uint64": 9, "float32": 10, "float64": 11, "char": 3, "bool": 15, "byte": 16, "string": 17,
    "wstring": 18, "bounded_string": 21, "bounded_wstring": 22,
}
ARRAY_OFFSET, BOUNDED_SEQUENCE_OFFSET, SEQUENCE_OFFSET = 48, 96, 144
EMPTY_STRUCTURE_MEMBER = "structure_needs_at_least_one_member"
SERVICE_EVENT_INFO = "service_msgs/ServiceEventInfo"

_FIELD_TYPE = re.compile(r"^(?P<base>[A-Za-z_][A-Za-z0-9_/]*)(?:<=(?P<string_bound>\d+))?"
                         r"(?P<array>\[(?P<bounded><=)?(?P<size>\d*)\])?$")


@dataclass(frozen=True)
class FieldType:
    """One ``.msg`` field type taken apart: ``"float64[9]"`` -> base ``float64``, ``array_size`` 9."""

    base: str                 # a primitive, "string", "wstring" or a nested "pkg/Type"
    string_bound: int = 0     # N of string<=N (0: unbounded)
    array_size: int = 0       # N of T[N]
    sequence_bound: int = 0   # N of T[<=N]
    is_sequence: bool = False  # T[] or T[<=N]


def parse_field_type(text: str) -> FieldType:
    """``"string<=8[<=3]"`` -> FieldType("string", string_bound=8, sequence_bound=3, is_sequence=True)."""
    m = _FIELD_TYPE.match(text)
    if not m or (m["string_bound"] and m["base"] not in ("string", "wstring")) or (m["bounded"] and not m["size"]):
        raise ValueError(f"ROS 2 field type {text!r}: expected T, T[], T[N] or T[<=N] (T a primitive, "
                         f"string, string<=N or pkg/Type)")
    size = int(m["size"]) if m["size"] else 0
    return FieldType(base=m["base"], string_bound=int(m["string_bound"] or 0),
                     array_size=size if m["array"] and not m["bounded"] else 0,
                     sequence_bound=size if m["bounded"] else 0,
                     is_sequence=bool(m["array"]) and (bool(m["bounded"]) or not size))


def ros_name(type_name: str, services: Sequence[str] = SERVICES) -> str:
    """``"std_msgs/String"`` -> ``"std_msgs/msg/String"``; a service and its request, response and event
    types take ``srv`` (``"std_srvs/Trigger_Request"`` -> ``"std_srvs/srv/Trigger_Request"``)."""
    parts = type_name.split("/")
    if len(parts) == 3:
        return type_name
    if len(parts) != 2:
        raise ValueError(f"ROS 2 type name {type_name!r}: expected pkg/Type or pkg/msg/Type")
    pkg, name = parts
    stem = re.sub(r"_(Request|Response|Event)$", "", name)
    return f"{pkg}/{'srv' if f'{pkg}/{stem}' in services or f'{pkg}/{name}' in services else 'msg'}/{name}"


def table_name(type_name: str) -> str:
    """``"std_msgs/msg/String"`` -> ``"std_msgs/String"`` (the key of the message table)."""
    parts = type_name.split("/")
    return f"{parts[0]}/{parts[-1]}" if len(parts) == 3 else type_name


def dds_type_name(type_name: str, services: Sequence[str] = SERVICES) -> str:
    """The DDS type name ``rmw_zenoh`` puts in key expressions: ``"std_msgs/String"`` ->
    ``"std_msgs::msg::dds_::String_"``, ``"std_srvs/srv/Trigger"`` -> ``"std_srvs::srv::dds_::Trigger_"``."""
    pkg, kind, name = ros_name(type_name, services).split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def type_description(type_name: str, messages: Table = MESSAGES, services: Sequence[str] = SERVICES) -> dict[str, Any]:
    """The ``type_description_interfaces/TypeDescription`` of a message or service type as a dict, without
    default values: ``{"type_description": {...}, "referenced_type_descriptions": [...]}``."""
    types = _Types(messages, services)
    full = ros_name(type_name, services)
    if table_name(full) in services and full.split("/")[1] == "srv":
        top = types.service(full)
    else:
        top = types.individual(full)
    referenced = types.referenced(full)
    return {"type_description": top, "referenced_type_descriptions": [types.individual(n) for n in referenced]}


def type_hash(type_name: str, messages: Table = MESSAGES, services: Sequence[str] = SERVICES) -> str:
    """The REP-2011 hash of a message or service type: ``"RIHS01_"`` and 64 hex digits."""
    text = json.dumps(type_description(type_name, messages, services), separators=(", ", ": "), ensure_ascii=True)
    return "RIHS01_" + hashlib.sha256(text.encode("utf-8")).hexdigest()


class _Types:
    """The table seen with ROS 2 names, with each service's event message added."""

    def __init__(self, messages: Table, services: Sequence[str]) -> None:
        self.messages, self.services = messages, services

    def fields(self, full: str) -> list[tuple[str, str]]:
        pkg, kind, name = full.split("/")
        if kind == "srv" and name.endswith("_Event"):
            stem = f"{pkg}/{name[:-len('_Event')]}"
            return [(SERVICE_EVENT_INFO, "info"), (f"{stem}_Request[<=1]", "request"),
                    (f"{stem}_Response[<=1]", "response")]
        key = f"{pkg}/{name}"
        if key not in self.messages:
            raise KeyError(f"ROS 2 type {full!r} is not in the message table (known: {sorted(self.messages)})")
        return list(self.messages[key]) or [("uint8", EMPTY_STRUCTURE_MEMBER)]

    def service(self, full: str) -> dict[str, Any]:
        fields = [(f"{full}_{part}", f"{part.lower()}_message") for part in ("Request", "Response", "Event")]
        return {"type_name": full, "fields": [self.field(name, ft) for ft, name in fields]}

    def individual(self, full: str) -> dict[str, Any]:
        return {"type_name": full, "fields": [self.field(name, ft) for ft, name in self.fields(full)]}

    def field(self, name: str, text: str) -> dict[str, Any]:
        ft = parse_field_type(text)
        nested = ft.base not in BASE_TYPE_IDS
        if nested:
            base_id = BASE_TYPE_IDS["nested"]
        elif ft.string_bound:
            base_id = BASE_TYPE_IDS["bounded_" + ft.base]
        else:
            base_id = BASE_TYPE_IDS[ft.base]
        offset = (ARRAY_OFFSET if ft.array_size else BOUNDED_SEQUENCE_OFFSET if ft.sequence_bound
                  else SEQUENCE_OFFSET if ft.is_sequence else 0)
        return {"name": name, "type": {
            "type_id": base_id + offset, "capacity": ft.array_size or ft.sequence_bound,
            "string_capacity": ft.string_bound,
            "nested_type_name": ros_name(ft.base, self.services) if nested else ""}}

    def nested_of(self, full: str) -> list[str]:
        pkg, kind, name = full.split("/")
        if kind == "srv" and f"{pkg}/{name}" in self.services:
            return [f"{full}_{part}" for part in ("Request", "Response", "Event")]
        out = []
        for text, _ in self.fields(full):
            ft = parse_field_type(text)
            if ft.base not in BASE_TYPE_IDS:
                out.append(ros_name(ft.base, self.services))
        return out

    def referenced(self, full: str) -> list[str]:
        seen: set[str] = set()
        todo = self.nested_of(full)
        while todo:
            t = todo.pop()
            if t not in seen:
                seen.add(t)
                todo.extend(self.nested_of(t))
        return sorted(seen)
