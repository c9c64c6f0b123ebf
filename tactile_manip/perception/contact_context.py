"""Temporal context of a reading: the frames before it, the same way in training, evaluation and at run time.

A window is T frames, frame 0 the reading itself and frame k the reading k frames before it in the same run.
A frame more than ``max_gap_s`` older than the reading (a pause, a restart, presses seconds apart) is no
context: the reading itself takes its place, so its change feature is 0. A dataset without sample times
(simulated presses, which are independent of each other) has no context at all.
"""

from __future__ import annotations

import numpy as np


def context_windows(readings: np.ndarray, *, frames: int, max_gap_s: float, time_s: np.ndarray | None = None,
                    groups: np.ndarray | None = None) -> np.ndarray:
    """Windows (N, T, R, C, A) float32 of ``readings`` (N, R, C, A), T = ``frames``.

    Args:
        readings: every reading of the dataset, uT.
        frames: T >= 1.
        max_gap_s: a frame older than this (s) before the reading is replaced by the reading.
        time_s: (N,) sample times, s; None: no context (every frame is the reading).
        groups: (N,) run of each sample (context never crosses runs); None: one run.
    """
    readings = np.asarray(readings, dtype=np.float32)
    n = len(readings)
    index = np.repeat(np.arange(n)[:, None], frames, axis=1)  # (N, T): which reading fills each frame
    if time_s is not None and frames > 1:
        t = np.asarray(time_s, dtype=np.float64)
        g = np.zeros(n, np.int64) if groups is None else np.asarray(groups)
        order = np.lexsort((t, g))                            # runs, each in time order
        rank = np.empty(n, np.int64)
        rank[order] = np.arange(n)
        for k in range(1, frames):
            before = order[np.maximum(rank - k, 0)]           # the sample k places earlier in that order
            usable = (rank - k >= 0) & (g[before] == g) & (t - t[before] <= max_gap_s)
            index[:, k] = np.where(usable, before, np.arange(n))
    return readings[index]


class ContextBuffer:
    """The last frames of a stream, as :func:`context_windows` builds them for a dataset.

    ``push(reading, t_s)`` adds the newest reading and returns its window (T, R, C, A) float32; ``frames_used``
    is then the number of real frames in it (1: the reading alone). The window is one array, rewritten in
    place by every push (the same object while the readings keep their shape, so a caller may hand it to a
    model once and keep reading it).

    A frame that is no context now never becomes context again (the readings only get newer, and a clock that
    goes back starts a new stream), so the buffer overwrites such frames with the reading and forgets their
    times: the history and the window are the same array, and a push copies one reading and nothing else.
    """

    def __init__(self, frames: int, max_gap_s: float, *, shape: tuple[int, ...] | None = None) -> None:
        if frames < 1:
            raise ValueError(f"frames must be >= 1, got {frames}")
        self.frames = frames
        self.max_gap_s = float(max_gap_s)
        # (T, R, C, A), frame 0 the newest; allocated by the first push unless the reading's shape is given
        self.window: np.ndarray | None = None if shape is None else np.zeros((frames, *shape), np.float32)
        self._times = [-np.inf] * frames             # s, -inf where no frame (or no context any more)
        self.frames_used = 0

    def clear(self) -> None:
        """Forget the history (the next reading has no context)."""
        self._times[:] = [-np.inf] * self.frames

    def push(self, reading: np.ndarray, t_s: float) -> np.ndarray:
        """The window (T, R, C, A) float32 of ``reading`` taken at ``t_s`` (s, any monotonic clock)."""
        window, times = self.window, self._times
        if window is None or window.shape[1:] != reading.shape:
            window = self.window = np.empty((self.frames, *reading.shape), np.float32)
            self.clear()
        if t_s < times[0]:  # a clock that went back: a new stream
            self.clear()
        if self.frames > 1:
            window[1:] = window[:-1]
            times.pop()
            times.insert(0, t_s)
        times[0] = t_s
        window[0] = reading
        used = 1   # the times fall with k, so the usable frames are the first ones (as in context_windows)
        while used < self.frames and t_s - times[used] <= self.max_gap_s:
            used += 1
        if used < self.frames:
            window[used:] = reading
            times[used:] = [-np.inf] * (self.frames - used)
        self.frames_used = used
        return window
