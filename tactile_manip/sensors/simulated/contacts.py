"""Scripted contacts for the simulated sensor and the firmware emulator: presses precomputed once.

A press costs ~30-100 ms of physics, far more than the 8 ms between frames, so a script of presses is solved
before streaming: each press's noise-free field change at a handful of force levels, linearly interpolated
in force at frame time. Streaming then only looks up a (n_chips, 3) field (the pair's board's chips, firmware
order, pad axes) and adds fresh chip noise.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from tactile_manip.checks import check_finite_scalar
from tactile_manip.sim.objects import Indenter, IndenterPose
from tactile_manip.sim.pair import SensorPair
from tactile_manip.sim.shapes import SHAPES, make_indenter

# Fractions of the peak force solved per press; the field change is concave in force, so denser at the start.
FORCE_LEVELS = (0.0, 0.04, 0.1, 0.2, 0.35, 0.5, 0.7, 0.85, 1.0)


@dataclass(frozen=True)
class Press:
    """One scripted press: ramp up over ``rise_s``, hold ``hold_s``, release over ``rise_s``.

    ``obj`` is a built-in shape name (see ``tactile_manip.sim.shapes.SHAPES``, with ``object_kwargs``) or an
    :class:`~tactile_manip.sim.objects.Indenter`.
    """

    obj: str | Indenter
    start_s: float                     # start of the ramp, s from the start of the script
    peak_force_n: float = 10.0         # N
    pose: IndenterPose = field(default_factory=IndenterPose)
    rise_s: float = 0.4                # ramp-up (and release) time, s
    hold_s: float = 0.5                # time at the peak force, s
    object_kwargs: Mapping[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_finite_scalar("Press.start_s", self.start_s, low=0.0)
        check_finite_scalar("Press.peak_force_n", self.peak_force_n, low=0.0, low_open=True)
        check_finite_scalar("Press.rise_s", self.rise_s, low=0.0, low_open=True)
        check_finite_scalar("Press.hold_s", self.hold_s, low=0.0)

    @property
    def name(self) -> str:
        return self.obj if isinstance(self.obj, str) else self.obj.name

    @property
    def end_s(self) -> float:
        return self.start_s + 2.0 * self.rise_s + self.hold_s

    def force_at(self, t_s: float) -> float:
        """Force (N) at script time ``t_s``: 0 outside the press, a trapezoid inside."""
        u = t_s - self.start_s
        if u <= 0.0 or t_s >= self.end_s:
            return 0.0
        if u < self.rise_s:
            return self.peak_force_n * u / self.rise_s
        if u <= self.rise_s + self.hold_s:
            return self.peak_force_n
        return self.peak_force_n * (self.end_s - t_s) / self.rise_s

    def indenter(self) -> Indenter:
        return self.obj if isinstance(self.obj, Indenter) else make_indenter(self.obj, **dict(self.object_kwargs))


def field_change_levels(pair: SensorPair, indenter: Indenter, pose: IndenterPose, forces_n: Sequence[float],
                        rng: np.random.Generator) -> np.ndarray:
    """Noise-free field change (L, n_chips, 3) in uT (pad axes, firmware order) at each force; 0 N gives zeros.

    Raises SimulationError when a force pushes the object through the layer (it would bottom out)."""
    out = np.zeros((len(forces_n), pair.board.n_chips, 3))
    for i, f in enumerate(forces_n):
        if f > 0:
            sample = pair.press(indenter, pose, float(f), rng, render_depth=False).check_within_layer()
            out[i] = pair.board.chips_from_cells(sample.field_change_ut)
    return out


class ContactTimeline:
    """A script of non-overlapping presses, solved up front, queried by time.

    Args:
        pair: the simulated sensor pair (its skin and chips).
        presses: the script; presses must not overlap in time.
        period_s: repeat the script with this period (>= the end of the last press), or None to play once.
        seed: seed of the (unused but required) press noise; the field changes are noise-free.
    """

    def __init__(self, pair: SensorPair, presses: Sequence[Press], *, period_s: float | None = None,
                 seed: int = 0) -> None:
        ordered = sorted(presses, key=lambda p: p.start_s)
        for a, b in zip(ordered, ordered[1:]):
            if b.start_s < a.end_s:
                raise ValueError(f"presses overlap: {a.name} at {a.start_s:g}-{a.end_s:g} s and {b.name} starting "
                                 f"at {b.start_s:g} s; start the second after the first ends")
        end = ordered[-1].end_s if ordered else 0.0
        if period_s is not None and (not math.isfinite(period_s) or period_s < max(end, 1e-3)):
            raise ValueError(f"period_s must be >= the end of the last press ({end:g} s), got {period_s}")
        self.presses = tuple(ordered)
        self.board = pair.board
        self.period_s = period_s
        self.duration_s = end
        rng = np.random.default_rng(seed)
        solved: dict[tuple, np.ndarray] = {}
        self._levels: list[tuple[np.ndarray, np.ndarray]] = []
        for p in self.presses:
            forces = np.array(FORCE_LEVELS) * p.peak_force_n
            key = (id(p.obj) if isinstance(p.obj, Indenter) else p.obj, tuple(sorted(p.object_kwargs.items())),
                   p.pose, p.peak_force_n)
            if key not in solved:
                solved[key] = field_change_levels(pair, p.indenter(), p.pose, forces, rng)
            self._levels.append((forces, solved[key]))

    def _local(self, t_s: float) -> float:
        if self.period_s is not None and t_s >= 0:
            return t_s % self.period_s
        return t_s

    def active(self, t_s: float) -> int | None:
        """Index of the press under way at ``t_s``, or None."""
        u = self._local(t_s)
        for i, p in enumerate(self.presses):
            if p.start_s < u < p.end_s:
                return i
        return None

    def force_at(self, t_s: float) -> float:
        """Total scripted force at ``t_s``, N."""
        i = self.active(t_s)
        return 0.0 if i is None else self.presses[i].force_at(self._local(t_s))

    def change_at(self, t_s: float) -> np.ndarray:
        """Noise-free field change (rows, cols, 3) in uT, pad axes, on the board's reading grid, at script time
        ``t_s`` (zeros between presses)."""
        return self.board.cells_from_pad(self.chip_change_at(t_s))

    def chip_change_at(self, t_s: float) -> np.ndarray:
        """Noise-free field change (n_chips, 3) in uT, pad axes, firmware order, at script time ``t_s`` (zeros
        between presses): what the frame threads add to the chips' field."""
        i = self.active(t_s)
        if i is None:
            return np.zeros((self.board.n_chips, 3))
        f = self.presses[i].force_at(self._local(t_s))
        forces, changes = self._levels[i]
        k = int(np.clip(np.searchsorted(forces, f) - 1, 0, len(forces) - 2))
        w = (f - forces[k]) / (forces[k + 1] - forces[k])
        return (1.0 - w) * changes[k] + w * changes[k + 1]


_PRESS_KEYS = {"t": "start_s", "force": "peak_force_n", "rise": "rise_s", "hold": "hold_s"}
_POSE_KEYS = {"x": "x_mm", "y": "y_mm"}


def parse_press(spec: str) -> Press:
    """A press from ``"NAME[,t=S][,force=N][,x=MM][,y=MM][,yaw=DEG][,rise=S][,hold=S][,size=MM]"``.

    ``size`` goes to the shape factory (rods); e.g. ``"letter_r,t=1,force=10,x=0.5,yaw=30"``.
    """
    name, *items = [s.strip() for s in spec.split(",")]
    if not name:
        raise ValueError(f"press {spec!r}: expected an object name first, e.g. 'letter_r,t=1,force=10'")
    if name not in SHAPES:
        raise ValueError(f"press {spec!r}: unknown object {name!r}; known: {', '.join(SHAPES)}")
    kwargs: dict[str, float] = {"start_s": 0.0}
    pose: dict[str, float] = {}
    shape: dict[str, float] = {}
    for item in items:
        key, sep, value = item.partition("=")
        try:
            number = float(value)
        except ValueError:
            number = None
        if not sep or number is None:
            raise ValueError(f"press {spec!r}: expected key=number, got {item!r}")
        if key in _PRESS_KEYS:
            kwargs[_PRESS_KEYS[key]] = number
        elif key in _POSE_KEYS:
            pose[_POSE_KEYS[key]] = number
        elif key == "yaw":
            pose["yaw_rad"] = math.radians(number)
        elif key == "size":
            shape["size_mm"] = number
        else:
            raise ValueError(f"press {spec!r}: unknown key {key!r}; known: t, force, x, y, yaw, rise, hold, size")
    return Press(obj=name, pose=IndenterPose(**pose), object_kwargs=shape, **kwargs)
