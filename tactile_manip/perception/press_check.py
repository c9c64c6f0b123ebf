"""Is a reading a press at all? The board's noise floor, and the shape of the field of a press.

Two questions come before any angle, position or force, and :class:`PressCheck` answers both in one pass over
the reading (0.15-0.3 ms on one thread; the readings of one call in one batched product):

1. **Contact or not.** Without a press, a baseline-subtracted reading is the chips' noise and the baseline's
   drift since it was taken. With a per-axis noise floor ``sigma`` (x, y, z; uT), the reading's whitened energy
   ``E = sum((b / sigma)^2)`` over its R x C x 3 channels is chi-square distributed with R C 3 degrees of
   freedom where nothing presses; a reading with ``E`` below that distribution's ``1 - false_alarm`` quantile
   is "no contact". The false-alarm rate is stated, not tuned: :data:`FALSE_ALARM` (0.1 % of frames of an
   idle pad whose noise is the floor). The floor is the board's rated chip noise (its board file's ``[chip]``
   ``noise_xy_ut``, ``noise_z_ut``) and a drift allowance (:data:`DRIFT_ALLOWANCE_UT`, the simulator's nominal
   per-press drift, added in quadrature): 5.2 uT (x, y) and 5.6 uT (z) on the SuperMag board. A board whose
   baseline measured more noise sets its own floor (:meth:`PressCheck.with_noise`,
   ``TactileEstimator.set_noise_floor(sensor.baseline.noise_ut)``).
2. **A press, or a pattern no press makes.** Above the floor, the reading's direction (the reading scaled to
   unit length) is compared with the directions of simulated presses of the board (:func:`press_bank`: the
   shipped bank of training-family shapes on drawn sensors, ``benchmarks/press_bank.py``). Its likeness is
   the length of its projection on the span of its :data:`NEIGHBOURS` nearest press directions, taken in the
   reading's symmetric image nearest to a press: near 1 for a press (0.84 and more for 99 % of held-out
   simulated presses without noise), at most 0.75 for white noise. A reading below :data:`MIN_LIKENESS` is no
   press: the estimators give no answer for it (``plausible`` False).

A weak press on a noisy pad looks like noise too: it is detected (above the floor) and flagged (no answer),
which is what can honestly be said of it. ``benchmarks/no_contact.py`` measures both rates against force on
held-out sensors and shapes (docs/perception.md, "No contact, and readings that are no press").
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from pathlib import Path
from statistics import NormalDist

import numpy as np

#: the share of idle frames (noise at the floor) that the no-contact test calls a contact
FALSE_ALARM = 1e-3
#: uT: baseline drift between taking the baseline and a reading, per channel (one sigma): the simulator's
#: nominal per-press drift (``sim.params.ChipParams.drift_ut``), added in quadrature to the rated chip noise
DRIFT_ALLOWANCE_UT = 5.0
#: press directions whose span a reading is projected on
NEIGHBOURS = 3
#: a reading above the floor whose likeness to simulated presses is below this is no press. Chosen between the
#: bank's 704 held-out presses (noise-free fields of training-family shapes on other drawn sensors: 1 % below
#: 0.84, the lowest 0.74) and 2000 white-noise directions (99.9 % below 0.74, the largest 0.75);
#: ``benchmarks/press_bank.py`` prints both
MIN_LIKENESS = 0.76
#: the bank of press directions of each board layout that ships one (tactile_manip/data/)
BANKS = {"supermag-4x4": "press_directions_supermag-4x4.npy"}
NO_PRESS = "no press"


def chi2_quantile(p: float, dof: int) -> float:
    """The ``p`` quantile of the chi-square distribution with ``dof`` degrees of freedom (Wilson-Hilferty: within
    0.1 % of the exact value for dof >= 48 and p up to 1 - 1e-3, 1.2 % for dof >= 10 and p up to 1 - 1e-4)."""
    z = NormalDist().inv_cdf(p)
    a = 2.0 / (9.0 * dof)
    return dof * (1.0 - a + z * math.sqrt(a)) ** 3


@dataclass(frozen=True, eq=False)
class PressCheck:
    """The no-contact test and the press-likeness test of one board (see the module docstring).

    Attributes:
        noise_ut: (3,) the floor's sigma per axis (x, y, z), uT.
        false_alarm: the share of readings of noise at the floor called a contact.
        directions: (M, R*C*3) float32 unit press directions, or None (no likeness test).
        symmetries: (S*R*C*3, R*C*3) float32: the board's S symmetries as one matrix on flat readings (the
            reading's S images stacked), or None (the identity alone). A reading is compared with the bank in
            each of its symmetric images, so the bank holds each press once.
        min_likeness: the likeness below which a reading above the floor is no press.
    """

    noise_ut: np.ndarray
    false_alarm: float = FALSE_ALARM
    directions: np.ndarray | None = None
    symmetries: np.ndarray | None = None
    min_likeness: float = MIN_LIKENESS

    def __post_init__(self) -> None:
        noise = np.asarray(self.noise_ut, dtype=np.float64)
        if noise.shape != (3,) or not np.all(np.isfinite(noise)) or not np.all(noise > 0):
            raise ValueError(f"noise_ut must be 3 positive uT (x, y, z), got {self.noise_ut!r}")
        if not 0.0 < self.false_alarm < 0.5:
            raise ValueError(f"false_alarm must be in (0, 0.5), got {self.false_alarm!r}")
        object.__setattr__(self, "noise_ut", noise)
        object.__setattr__(self, "_inverse", (1.0 / noise).astype(np.float32))
        object.__setattr__(self, "_bank_t", None if self.directions is None else
                           np.ascontiguousarray(self.directions.T, dtype=np.float32))  # (R*C*3, M)
        object.__setattr__(self, "_verdicts", {})  # the last call's verdicts, by the readings' bytes

    def threshold(self, channels: int) -> float:
        """The whitened energy at and above which a reading of ``channels`` channels is a contact."""
        return chi2_quantile(1.0 - self.false_alarm, channels)

    def with_noise(self, noise_ut: np.ndarray) -> PressCheck:
        """The same check with another floor: ``noise_ut`` (3,) per axis or (R, C, 3) per channel (a sensor's
        measured baseline noise, whose per-axis RMS is taken), uT, in quadrature with the drift allowance, and
        never below this check's floor."""
        noise = np.asarray(noise_ut, dtype=np.float64)
        if noise.ndim > 1 and noise.shape[-1] == 3:
            noise = np.sqrt(np.mean(noise.reshape(-1, 3) ** 2, axis=0))
        if noise.shape != (3,) or not np.all(np.isfinite(noise)) or np.any(noise < 0):
            raise ValueError(f"noise_ut must be (3,) or (R, C, 3) finite uT >= 0, got shape {noise.shape}")
        floor = np.sqrt(noise ** 2 + DRIFT_ALLOWANCE_UT ** 2)
        return replace(self, noise_ut=np.maximum(floor, self.noise_ut))

    def energy(self, field_ut: np.ndarray) -> float:
        """The whitened energy ``sum((b / sigma)^2)`` of one reading (R, C, 3) uT."""
        w = np.asarray(field_ut, dtype=np.float32) * self._inverse
        return float(np.vdot(w, w))

    def likeness(self, field_ut: np.ndarray) -> float:
        """How much of the reading's direction lies in the span of its nearest press directions, in [0, 1]
        (1 without a bank; 0 for an all-zero reading)."""
        return float(self.likeness_many(np.asarray(field_ut)[None])[0])

    def likeness_many(self, fields_ut: np.ndarray) -> np.ndarray:
        """(n,) the likeness of each of the readings (n, R, C, 3), from one batched product with the bank."""
        b = np.asarray(fields_ut, dtype=np.float32).reshape(len(fields_ut), -1)
        if self.directions is None:
            return np.ones(len(b))
        out = np.zeros(len(b))
        norm = np.linalg.norm(b, axis=1)
        rows = np.flatnonzero((norm > 0.0) & np.isfinite(norm)) if b.shape[1] == self.directions.shape[1] else []
        if len(rows) == 0:
            return out
        u = b[rows] / norm[rows, None]
        images = u[:, None] if self.symmetries is None else (u @ self.symmetries.T).reshape(len(u), -1, u.shape[1])
        cos = (images.reshape(-1, u.shape[1]) @ self._bank_t).reshape(len(u), images.shape[1], -1)  # (n, S, M)
        for k, i in enumerate(rows):
            best = int(np.argmax(cos[k])) // cos.shape[2]  # the symmetric image nearest to a press
            out[i] = self._span_length(images[k, best].astype(np.float64), cos[k, best])
        return out

    def _span_length(self, image: np.ndarray, row: np.ndarray) -> float:
        """The length of the unit ``image``'s projection on the span of its :data:`NEIGHBOURS` nearest press
        directions (``row``: its cosines with every one)."""
        near = self.directions[np.argpartition(row, -NEIGHBOURS)[-NEIGHBOURS:]].astype(np.float64)  # (K, R*C*3)
        try:  # from the K x K normal equations
            projected = near @ image
            squared = float(projected @ np.linalg.solve(near @ near.T, projected))
        except np.linalg.LinAlgError:  # repeated directions: the nearest one alone
            return float(min(1.0, row.max()))
        return float(min(1.0, math.sqrt(max(0.0, squared))))

    def judge(self, field_ut: np.ndarray) -> tuple[bool, str]:
        """(in contact, why the reading is no press: "" when it is one or when it is below the floor). The verdicts
        of the last call that judged a new reading are kept: the pose part and the contact part of one estimator
        judge a reading (or the pads of one call) once."""
        return self.judge_many(np.asarray(field_ut)[None])[0]

    def judge_many(self, fields_ut: np.ndarray) -> list[tuple[bool, str]]:
        """:meth:`judge` of each of the readings (n, R, C, 3), the new ones in one batched product."""
        arr = np.asarray(fields_ut, dtype=np.float32)
        keys = [a.tobytes() for a in arr]
        verdicts = [self._verdicts.get(key) for key in keys]
        new = [i for i, v in enumerate(verdicts) if v is None]
        if new:
            fresh = arr[new]
            w = fresh * self._inverse
            contact = np.square(w).reshape(len(w), -1).sum(axis=1) >= self.threshold(fresh[0].size)
            like = np.ones(len(new))
            if contact.any():
                like[contact] = self.likeness_many(fresh[contact])
            for j, i in enumerate(new):
                verdicts[i] = (bool(contact[j]), self._why(fresh[j], like[j]) if contact[j] else "")
            # kept: this call's verdicts, for the other part of the same estimator on the same reading(s)
            object.__setattr__(self, "_verdicts", dict(zip(keys, verdicts)))
        return verdicts

    def _why(self, arr: np.ndarray, like: float) -> str:
        """Why a reading above the floor of likeness ``like`` is no press ("" when it is one)."""
        if like >= self.min_likeness:
            return ""
        rms = float(np.sqrt(np.mean(np.square(arr, dtype=np.float64))))
        return (f"{NO_PRESS}: the field ({rms:.3g} uT RMS, above the noise floor) has a pattern no simulated press "
                f"of the board makes (likeness {like:.2f} < {self.min_likeness:.2f}): noise beyond the floor, a "
                "uniform field or a fault, not a contact to measure")


def rated_noise_ut(board_layout: str) -> np.ndarray | None:
    """(3,) the board's rated chip noise (x, y, z) in uT from its board file, or None for a board not known."""
    if not board_layout:
        return None
    from tactile_manip.boards import load_board

    try:
        chip = load_board(board_layout).chip
    except (ValueError, OSError, LookupError):  # a board of its own (a dataset's layout name), or none
        return None
    return np.array([chip.noise_xy_ut, chip.noise_xy_ut, chip.noise_z_ut], dtype=np.float64)


@functools.cache
def press_bank(board_layout: str) -> tuple[np.ndarray, np.ndarray] | None:
    """The board's shipped bank: (M, R*C*3) float32 unit directions of simulated presses, and the board's
    symmetries as one (S*R*C*3, R*C*3) matrix (see :class:`PressCheck`); read-only; None where none ships."""
    name = BANKS.get(board_layout)
    if name is None:
        return None
    return bank_of(np.load(Path(__file__).resolve().parent.parent / "data" / name, allow_pickle=False))


def bank_of(directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A bank from press readings (M, R, C, 3) (any scale): their unit directions (M, R*C*3) float32 and the
    board's symmetries as one matrix (S*R*C*3, R*C*3), both read-only."""
    from tactile_manip.perception.board_symmetry import symmetry_group, transform_reading

    base = np.asarray(directions, dtype=np.float32)
    shape = base.shape[1:]
    flat = base.reshape(len(base), -1)
    flat /= np.linalg.norm(flat, axis=1, keepdims=True)
    size = flat.shape[1]
    unit = np.eye(size, dtype=np.float32).reshape(size, *shape)  # reading j: channel j at 1
    # transform_reading is linear: its matrix's column j is the image of reading j
    maps = [transform_reading(unit, k, m).reshape(size, size).T for k, m in symmetry_group(shape, shape[:2])]
    symmetries = np.ascontiguousarray(np.concatenate(maps), dtype=np.float32)
    for array in (flat, symmetries):
        array.flags.writeable = False
    return flat, symmetries


@functools.cache
def press_check_for(board_layout: str, input_shape: tuple[int, ...]) -> PressCheck | None:
    """The board's :class:`PressCheck` (its rated noise with the drift allowance, its press bank where one
    ships), or None for a board whose chip noise is not known here (the estimators then keep their older
    field rule) or readings that are not 3-axis. One instance per board: the pose and the contact part of an
    estimator share it (and its verdict of the last reading)."""
    rated = rated_noise_ut(board_layout)
    if rated is None or len(input_shape) != 3 or input_shape[-1] != 3:
        return None
    bank = press_bank(board_layout)
    if bank is not None and bank[0].shape[1] != int(np.prod(input_shape)):
        bank = None
    directions, symmetries = (None, None) if bank is None else bank
    return PressCheck(np.sqrt(rated ** 2 + DRIFT_ALLOWANCE_UT ** 2), directions=directions, symmetries=symmetries)
