"""Pairing two streams by host time: each depth frame with the magnetic frame nearest in time, within a tolerance.

- :func:`nearest_within`: the pure rule on arrays: for each query time, the index of the nearest reference time
  if it is at most ``tolerance_s`` away, else -1. Never a pair beyond the tolerance; ties go to the earlier
  frame; nothing is assumed about order or uniqueness.
- :class:`DeviceClock`: host time of a device-clocked frame. Frames reach the host in bursts (one USB read can
  carry several), so their arrival times bunch up; the device clock is regular. Its offset to the host clock
  is the smallest ``t_host - t_device`` seen over a sliding window (the frame that arrived fastest), so mapped
  times are never later than arrival and follow the device's spacing.
- :class:`StreamPairer`: the same rule on live streams. A depth frame is decided once a magnetic frame later
  than ``t + tolerance`` has arrived (no later arrival can be nearer within the tolerance), or when flushed.
"""

from __future__ import annotations

import bisect
import collections
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from tactile_manip.checks import check_finite_scalar


def _times(name: str, t: object) -> np.ndarray:
    arr = np.asarray(t, dtype=np.float64)
    if arr.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D array of times, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name}: times must be finite")
    return arr


def nearest_within(t_query_s: object, t_ref_s: object, tolerance_s: float) -> np.ndarray:
    """For each query time, the index into ``t_ref_s`` of the nearest time at most ``tolerance_s`` away, or -1.

    Ties between the frames just before and just after a query go to the earlier one; among frames with equal
    times, to the lower index.
    """
    tol = check_finite_scalar("tolerance_s", tolerance_s, low=0.0)
    q, r = _times("t_query_s", t_query_s), _times("t_ref_s", t_ref_s)
    out = np.full(q.shape, -1, np.int64)
    if r.size == 0 or q.size == 0:
        return out
    order = np.argsort(r, kind="stable")
    rs = r[order]
    right = np.clip(np.searchsorted(rs, q, side="left"), 0, rs.size - 1)
    # the leftmost of any run of equal times just below q
    left_pos = np.clip(np.searchsorted(rs, q, side="left") - 1, 0, rs.size - 1)
    left = np.searchsorted(rs, rs[left_pos], side="left")
    d_left, d_right = np.abs(q - rs[left]), np.abs(rs[right] - q)
    pick = np.where(d_left <= d_right, left, right)
    dist = np.minimum(d_left, d_right)
    ok = dist <= tol
    out[ok] = order[pick[ok]]
    return out


class DeviceClock:
    """Host time of frames stamped by a device clock (see the module docstring).

    Args:
        window_s: the offset is the minimum over this much recent host time (follows slow drift), s.
        max_latency_s: a frame mapped more than this before its arrival means the device clock jumped back
            (a restarted board): the estimate starts again from that frame.
    """

    def __init__(self, *, window_s: float = 10.0, max_latency_s: float = 0.25) -> None:
        self.window_s = check_finite_scalar("window_s", window_s, low=0.0, low_open=True)
        self.max_latency_s = check_finite_scalar("max_latency_s", max_latency_s, low=0.0, low_open=True)
        self._mins: collections.deque[tuple[float, float]] = collections.deque()
        self.resets = 0

    def update(self, t_host_s: float, t_device_s: float) -> float:
        """Record a frame's arrival and device time; return its estimated host time (<= ``t_host_s``)."""
        if not math.isfinite(t_device_s):
            return t_host_s
        offset = t_host_s - t_device_s
        if self._mins and t_host_s - (t_device_s + self._mins[0][1]) > self.max_latency_s:
            self._mins.clear()
            self.resets += 1
        while self._mins and self._mins[-1][1] >= offset:
            self._mins.pop()
        self._mins.append((t_host_s, offset))
        while self._mins[0][0] < t_host_s - self.window_s:
            self._mins.popleft()
        return t_device_s + self._mins[0][1]


@dataclass(frozen=True)
class Match:
    """A decided depth frame: its time and payload, and the paired magnetic frame (None: no pair)."""

    t_depth_s: float
    depth: Any
    t_field_s: float
    field: Any

    @property
    def paired(self) -> bool:
        return self.field is not None

    @property
    def dt_s(self) -> float:
        """``t_field - t_depth``, s (NaN when unpaired)."""
        return self.t_field_s - self.t_depth_s


class StreamPairer:
    """Pairs depth frames with the nearest magnetic frame within ``tolerance_s`` as both streams arrive.

    Args:
        tolerance_s: the largest allowed ``|t_field - t_depth|``, s.
        horizon_s: magnetic frames older than the oldest pending depth frame by more than this are dropped.
    """

    def __init__(self, tolerance_s: float, *, horizon_s: float = 2.0) -> None:
        self.tolerance_s = check_finite_scalar("tolerance_s", tolerance_s, low=0.0)
        self.horizon_s = check_finite_scalar("horizon_s", horizon_s, low=0.0)
        self._field_t: list[float] = []
        self._field: list[Any] = []
        self._pending: list[tuple[float, Any]] = []
        self.latest_field_s = -math.inf

    def add_field(self, t_s: float, item: Any) -> None:
        """A magnetic frame at time ``t_s`` (any order; kept sorted)."""
        i = bisect.bisect_right(self._field_t, t_s)
        self._field_t.insert(i, t_s)
        self._field.insert(i, item)
        self.latest_field_s = max(self.latest_field_s, t_s)

    def add_depth(self, t_s: float, item: Any) -> None:
        """A depth frame at time ``t_s`` waiting for its pair."""
        self._pending.append((float(t_s), item))

    @property
    def pending(self) -> int:
        return len(self._pending)

    def resolve(self, *, flush: bool = False) -> list[Match]:
        """Decide every pending depth frame whose pair can no longer change (all of them with ``flush``)."""
        ready = [p for p in self._pending if flush or self.latest_field_s > p[0] + self.tolerance_s]
        if not ready:
            return []
        self._pending = [p for p in self._pending if not (flush or self.latest_field_s > p[0] + self.tolerance_s)]
        idx = nearest_within([t for t, _ in ready], self._field_t, self.tolerance_s)
        out = [Match(t, item, self._field_t[i] if i >= 0 else math.nan, self._field[i] if i >= 0 else None)
               for (t, item), i in zip(ready, idx)]
        self._trim()
        return out

    def _trim(self) -> None:
        keep_from = (min(t for t, _ in self._pending) if self._pending else self.latest_field_s) \
            - self.tolerance_s - self.horizon_s
        k = bisect.bisect_left(self._field_t, keep_from)
        if k:
            del self._field_t[:k], self._field[:k]
