"""Validation helpers for values that cross the public API.

Each ``check_*`` coerces its input and raises ``ValueError`` with a message that names the argument, the
value received and what is allowed, so bad input fails at the edge rather than as a NaN deep inside.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def check_finite_scalar(name: str, value: float, *, low: float | None = None, high: float | None = None,
                        low_open: bool = False) -> float:
    """Return ``value`` as a float after checking it is finite and inside ``[low, high]``.

    With ``low_open=True`` the lower bound is exclusive (``value > low``).
    """
    try:
        x = float(value)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name} must be a number, got {value!r}") from e
    if not math.isfinite(x):
        raise ValueError(f"{name} must be finite, got {x}")
    if low is not None and (x <= low if low_open else x < low):
        op = ">" if low_open else ">="
        raise ValueError(f"{name} must be {op} {low}, got {x}")
    if high is not None and x > high:
        raise ValueError(f"{name} must be <= {high}, got {x}")
    return x


def check_array(name: str, value: object, *, shape: Sequence[int | None] | None = None,
                dtype: type | np.dtype = np.float64, allow_nan: bool = False) -> np.ndarray:
    """Return ``value`` as an array of ``dtype`` after checking its shape and finiteness.

    ``shape`` may hold ``None`` for an axis of any length. NaN is refused unless ``allow_nan``; infinities
    are always refused, and so are complex and boolean values where real numbers are asked for (their
    conversion would drop the imaginary part, or read True as 1).
    """
    raw = np.asarray(value)
    if raw.dtype.kind in "cb" and np.dtype(dtype).kind not in "cb":
        raise ValueError(f"{name}: expected real numbers, got dtype {raw.dtype}")
    arr = raw.astype(dtype, copy=False)
    if shape is not None:
        ok = arr.ndim == len(shape) and all(s is None or s == n for s, n in zip(shape, arr.shape))
        if not ok:
            want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
            raise ValueError(f"{name}: expected shape {want}, got {arr.shape}")
    if np.issubdtype(arr.dtype, np.floating):
        if np.isinf(arr).any():
            raise ValueError(f"{name} contains infinite values")
        if not allow_nan and np.isnan(arr).any():
            raise ValueError(f"{name} contains NaN values")
    return arr


def check_choice(name: str, value: str, allowed: Sequence[str]) -> str:
    """Return ``value`` after checking it is one of ``allowed``."""
    if value not in allowed:
        raise ValueError(f"{name} must be one of {list(allowed)}, got {value!r}")
    return value


def check_nonblank(name: str, value: str, *, hint: str = "") -> str:
    """Return ``value`` after checking it is a string with something other than whitespace in it.

    An empty string is falsy, so code that tests ``if value:`` would quietly take another branch (an empty
    ``--port`` once meant the simulated sensor); callers check here first. ``hint`` says what to give instead.
    """
    if not isinstance(value, str) or not value.strip():
        raise ValueError(f"{name} must not be empty, got {value!r}" + (f": {hint}" if hint else ""))
    return value


def npz_read_problem(error: Exception) -> str:
    """Why ``np.load(..., allow_pickle=False)`` refused a file, in words for a user (no ``allow_pickle`` hint:
    files are data, and pickled objects are never loaded)."""
    text = str(error)
    if "pickle" in text.lower() or "object arrays" in text.lower():
        return "it is not an archive of plain arrays (reading it would need unpickling, which tactile_manip never does)"
    return text
