"""ROS 2 names: the checks rcl makes of a namespace, a topic or service name and a node name, and name expansion.

A name is tokens joined by ``/``; each token is ``[A-Za-z_][A-Za-z0-9_]*`` (so none starts with a digit). A
namespace is absolute (``/`` or ``/a/b``; a relative one is made absolute, as rclpy does), without a trailing
``/``. A topic or service name is absolute (``/a/b``), relative (``a/b``, placed under the namespace) or private
(``~`` or ``~/a``, under the node); ``~`` may come first only, ``//`` and a trailing ``/`` are refused, and so are
``__`` (which ROS 2 reserves) and substitutions (``{node}``), which this package does not expand. A fully
qualified name is at most 247 characters (what DDS-based middlewares leave a topic after their prefix). Every
refusal is a ValueError naming the name, the part at fault and the rule.
"""

from __future__ import annotations

import re

TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
MAX_NAME_LENGTH = 247  # 255 less the "rt/" style prefixes of DDS middlewares, as rmw checks it


def _check_tokens(what: str, name: str, tokens: list[str]) -> None:
    for token in tokens:
        if token == "":
            raise ValueError(f"{what} {name!r}: empty token (no '//', and no trailing '/')")
        if not TOKEN.fullmatch(token):
            bad = next((c for c in token if not (c.isascii() and (c.isalnum() or c == "_"))), None)
            why = (f"character {bad!r} is not allowed (letters, digits and '_' only)" if bad is not None
                   else "a token may not start with a digit")
            raise ValueError(f"{what} {name!r}: token {token!r}: {why}")
        if "__" in token:
            raise ValueError(f"{what} {name!r}: token {token!r} holds '__', which ROS 2 reserves")


def check_namespace(namespace: str) -> str:
    """The absolute namespace of ``namespace`` (``"tactile"`` -> ``"/tactile"``, ``""`` -> ``"/"``)."""
    if not isinstance(namespace, str):
        raise TypeError(f"namespace: expected a string, got {type(namespace).__name__}")
    ns = namespace if namespace.startswith("/") else "/" + namespace
    if ns == "/":
        return ns
    if "~" in ns:
        raise ValueError(f"namespace {namespace!r}: '~' is not allowed in a namespace")
    _check_tokens("namespace", namespace, ns[1:].split("/"))
    if len(ns) > MAX_NAME_LENGTH:
        raise ValueError(f"namespace {namespace!r}: {len(ns)} characters, at most {MAX_NAME_LENGTH}")
    return ns


def check_node_name(name: str) -> str:
    """``name`` when it is a valid node name (one token)."""
    if not isinstance(name, str) or not name:
        raise ValueError(f"node name {name!r}: expected a non-empty name")
    _check_tokens("node name", name, [name])
    return name


def check_name(name: str, *, what: str = "topic name") -> str:
    """``name`` when ROS 2 would accept it as a topic or service name (absolute, relative or private)."""
    if not isinstance(name, str) or not name:
        raise ValueError(f"{what} {name!r}: expected a non-empty name")
    if "{" in name or "}" in name:
        raise ValueError(f"{what} {name!r}: substitutions ({{...}}) are not expanded here; write the name out")
    if "~" in name[1:] or (name.startswith("~") and name not in ("~",) and not name.startswith("~/")):
        raise ValueError(f"{what} {name!r}: '~' may only come first, alone or followed by '/'")
    body = name.lstrip("~").lstrip("/") if name.startswith("~") else name.removeprefix("/")
    if name.startswith("/") and name == "/":
        raise ValueError(f"{what} {name!r}: the root alone is not a name")
    if body or not name.startswith("~"):
        _check_tokens(what, name, body.split("/"))
    return name


def fully_qualified(namespace: str, name: str, *, node: str = "tactile_manip", what: str = "topic name") -> str:
    """The absolute name ``name`` stands for in ``namespace`` (``"/tactile"``, ``"field"`` -> ``"/tactile/field"``;
    ``"~/x"`` -> ``"/tactile/<node>/x"``; an absolute name stays as it is)."""
    ns = check_namespace(namespace)
    check_name(name, what=what)
    check_node_name(node)
    if name.startswith("/"):
        full = name
    else:
        if name.startswith("~"):
            name = node + name[1:]
        full = (ns.rstrip("/") + "/" + name) if ns != "/" else "/" + name
    if len(full) > MAX_NAME_LENGTH:
        raise ValueError(f"{what} {full!r}: {len(full)} characters, at most {MAX_NAME_LENGTH}")
    return full
