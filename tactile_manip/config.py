"""Load TOML files into typed, validated dataclasses.

Config files are data: they are parsed with ``tomllib``, never executed. Every table of a file maps onto
a dataclass of the same shape; unknown keys, wrong types and values refused by a dataclass's
``__post_init__`` all raise one ``ConfigError`` that names the file and the dotted key.
"""

from __future__ import annotations

import dataclasses
import sys
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

from tactile_manip.errors import ConfigError

T = TypeVar("T")
UTF8_BOM = b"\xef\xbb\xbf"


def load_config(path: str | Path, cls: type[T]) -> T:
    """Parse the TOML file at ``path`` into an instance of the dataclass ``cls``.

    Raises:
        ConfigError: the file is missing, a directory, unreadable, not UTF-8, not valid TOML, or does not fit
            ``cls`` (a UTF-8 byte-order mark at its start is read past).
    """
    return from_dict(cls, read_toml(path), where=str(path))


def read_toml(path: str | Path) -> dict[str, Any]:
    """The TOML file at ``path`` as a dict.

    Raises:
        ConfigError: the file is missing, a directory, unreadable, not UTF-8 or not valid TOML.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
        # a byte-order mark (some editors write one) is no part of the text
        return tomllib.loads(data.removeprefix(UTF8_BOM).decode("utf-8"))
    except FileNotFoundError as e:
        raise ConfigError(f"config file not found: {path}") from e
    except IsADirectoryError as e:
        raise ConfigError(f"config {path} is a directory; give a .toml file") from e
    except OSError as e:
        raise ConfigError(f"cannot read config {path}: {e.strerror or e}") from e
    except UnicodeDecodeError as e:
        raise ConfigError(f"{path}: not a text (UTF-8) TOML file: byte {e.start} is not UTF-8") from e
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: not valid TOML: {e}") from e


def from_dict(cls: type[T], data: dict[str, Any], *, where: str = "config", prefix: str = "") -> T:
    """Build the dataclass ``cls`` from a nested dict, checking keys and types recursively."""
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: [{prefix or cls.__name__}] must be a table, got {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(_dot(prefix, k) for k in unknown)}; "
                          f"allowed: {', '.join(sorted(fields))}")
    missing = [name for name, f in fields.items() if name not in data
               and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING]
    if missing:
        raise ConfigError(f"{where}: missing key(s) {', '.join(_dot(prefix, k) for k in missing)}")
    kwargs = {}
    for name, value in data.items():
        kwargs[name] = _coerce(hints[name], value, where=where, key=_dot(prefix, name))
    try:
        return cls(**kwargs)
    except (ValueError, TypeError) as e:  # refused by __post_init__ (a ConfigError too): name the file
        if isinstance(e, ConfigError) and str(e).startswith(f"{where}:"):
            raise
        raise ConfigError(f"{where}: {_dot(prefix, '') or cls.__name__}: {e}") from e


def check_ranges(obj: Any, ranges: dict[str, tuple[float, float]], *, units: dict[str, str] | None = None) -> None:
    """Refuse a field of ``obj`` (a config dataclass) outside its closed range ``ranges[name] = (low, high)``.

    Integer bounds ask for an integer; the upper bounds keep a typo (1000000 frames of context) from allocating
    gigabytes or running for days. ``units`` names the unit of a field in the message.

    Raises:
        ConfigError: the field, its value and the allowed range.
    """
    for name, (low, high) in ranges.items():
        value = getattr(obj, name)
        integer = isinstance(low, int) and isinstance(high, int)
        kind = (int,) if integer else (int, float)
        if isinstance(value, bool) or not isinstance(value, kind) or not low <= value <= high:  # NaN fails too
            unit = f" {units[name]}" if units and name in units else ""
            what = "an integer" if integer else "a number"
            raise ConfigError(f"{name} must be {what} in [{low:g}, {high:g}]{unit}, got {value!r}")


def to_dict(obj: Any) -> Any:
    """Turn a (nested) dataclass into plain dicts, lists and scalars, for JSON or TOML output."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_dict(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, (list, tuple)):
        return [to_dict(v) for v in obj]
    if isinstance(obj, dict):
        return {k: to_dict(v) for k, v in obj.items()}
    return obj


def config_differences(saved: dict[str, Any], current: dict[str, Any], *, prefix: str = "",
                       limit: int = 8) -> list[str]:
    """``"key: saved -> current"`` for each leaf that differs between two nested config dicts (dotted keys,
    sorted; tables are compared key by key, arrays as a whole). At most ``limit`` entries, then ``"..."``."""
    out = []
    for key in sorted(set(saved) | set(current)):
        a, b = saved.get(key, "<absent>"), current.get(key, "<absent>")
        if isinstance(a, dict) and isinstance(b, dict):
            out += config_differences(a, b, prefix=_dot(prefix, key), limit=limit)
        elif a != b:
            out.append(f"{_dot(prefix, key)}: {_short(a)} -> {_short(b)}")
    return out if len(out) <= limit else [*out[:limit], "..."]


def _short(value: Any, width: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= width else text[:width - 3] + "..."


def _dot(prefix: str, key: str) -> str:
    return f"{prefix}.{key}" if prefix and key else (prefix or key)


def _coerce(hint: Any, value: Any, *, where: str, key: str) -> Any:
    origin = typing.get_origin(hint)
    if dataclasses.is_dataclass(hint):
        return from_dict(hint, value, where=where, prefix=key)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(hint)
        present = [a for a in args if a is not type(None)]
        if value is not None and len(present) == 1:  # an optional table or value: its own error names the key
            return _coerce(present[0], value, where=where, key=key)
        errors = []
        for arg in args:
            try:
                return _coerce(arg, value, where=where, key=key)
            except ConfigError as e:
                errors.append(str(e))
        raise ConfigError(f"{where}: {key} = {value!r} fits none of {_name(hint)}")
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: {key} must be an array, got {value!r}")
        args = typing.get_args(hint)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(args) != len(value):
                raise ConfigError(f"{where}: {key} must have {len(args)} items, got {len(value)}")
            items = [_coerce(a, v, where=where, key=f"{key}[{i}]") for i, (a, v) in enumerate(zip(args, value))]
        else:
            inner = args[0] if args else Any
            items = [_coerce(inner, v, where=where, key=f"{key}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is typing.Literal:
        if value not in typing.get_args(hint):
            raise ConfigError(f"{where}: {key} must be one of {list(typing.get_args(hint))}, got {value!r}")
        return value
    if hint is type(None):
        if value is not None:
            raise ConfigError(f"{where}: {key} must be empty")
        return None
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: {key} must be a number, got {value!r}")
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: {key} must be an integer, got {value!r}")
        return value
    if hint in (str, bool):
        if not isinstance(value, hint):
            raise ConfigError(f"{where}: {key} must be a {hint.__name__}, got {value!r}")
        return value
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(f"{where}: {key} must be a table, got {value!r}")
        return value
    if hint is Any:
        return value
    raise ConfigError(f"{where}: {key}: unsupported config type {_name(hint)}")


def _name(hint: Any) -> str:
    return getattr(hint, "__name__", None) or str(hint)
