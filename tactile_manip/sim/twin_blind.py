"""Fit a board's twin (:mod:`tactile_manip.sim.twin`) with no label at all: from the untouched board's raw field and
the readings of unlabelled presses, with no probe pose.

Without poses the twin is not identifiable by a free fit (a twin with a free pose per press, free magnets, kernel
and readouts explains its rows well and places the presses anywhere), so the fit holds to physical priors and
frees one thing at a time:

1. ``rest``: the discs from the rest field alone, read through the board file's chip axes at unit gain (the
   chips' offsets nil): the file's layout of discs as one rigid body, shifted, turned and scaled in the plane, at
   one depth, each disc of its own strength (polarity as the file has it; N52 discs vary by a few per cent, and a
   disc set a little deeper reads as a weaker one);
2. ``kernel``: the press kernel's depth, lateral and tilt scales from a grid (:data:`KERNEL_GRID`), each with its
   chips' readouts fitted as in 3., the one whose bank of simulated presses over the pad (every place of a grid,
   every strength of :data:`STRENGTHS`) lies nearest the real readings both ways (:func:`symmetric_chamfer`: the
   mean squared distance of each real reading's direction, its unit vector over the channels, to the nearest bank
   reading's, plus that of each bank press where and as hard as the real ones land to the nearest real reading);
3. ``readout``: each chip's 3x3 readout, alternating with the presses' latent places: each real reading takes the
   bank press nearest it in direction and the best scale of it, and the readouts are refitted to those presses
   by ridge regression towards the file's axes at unit gain (:data:`READOUT_RIDGE`), :data:`READOUT_ROUNDS` times.

The twin written places presses in the pad frame of the board file; the rig's frame is not known (the ``[twin]``
table's rig origin is the pad centre, its turn nil), nor the depth scale: the strength law is ``s = A d`` with
``A`` set so that the strongest presses fitted (their 99th percentile of latent strength) reach
:data:`NOMINAL_DEPTH_MM`. The fit's EV is that of the fitting readings by their latent presses.

numpy and scipy only.
"""

from __future__ import annotations

import dataclasses
import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from tactile_manip.boards.load import Board
from tactile_manip.boards.spec import MagnetSpec, ReadoutSpec, TwinSpec
from tactile_manip.sim.twin import (
    Magnets,
    board_magnets,
    discs_field_pad_ut,
    press_change_pad_ut,
)
from tactile_manip.sim.twin_fit import (
    MAGNET_Z_LIMIT_MM,
    MAX_POLARISATION_T,
    TwinFitError,
    explained_variance,
)

KERNEL_GRID = {"kernel_depth_mm": (8.0, 11.0, 14.0, 17.0, 20.0), "lateral_scale": (0.0, 1.0),
               "tilt_scale": (0.5, 1.0, 1.5)}
STRENGTHS = tuple(np.geomspace(0.2, 60.0, 14))  # press strengths s of the bank, mm^2 (a touch to a hard press)
SEARCH_STEP_MM = 1.0       # bank grid over the pad while the kernel is searched
BANK_STEP_MM = 0.5         # ... and while the readouts are fitted
READOUT_RIDGE = 0.05       # pull of a chip's readout towards the file's axes at unit gain (share of the field power)
READOUT_ROUNDS = 6
NOMINAL_DEPTH_MM = 5.0     # the depth the strongest fitted presses are given: no reading tells depth in mm
MIN_PRESSES = 50           # fewer unlabelled presses cannot place a kernel
# each reading chooses its latent press and that press's scale freely, so even readings of no press of the board
# (random ones) are explained about 0.6 by them; the eFlesh run's 0.95, a simulated board's 0.99
MIN_BLIND_EV = 0.8


@dataclass
class BlindFit:
    """What :func:`fit_twin_unlabelled` found: the fitted board and per stage its rest-field rms (uT), direction
    chamfer, EV of the fitting readings by their latent presses, and seconds."""

    board: Board
    stages: dict[str, dict] = field(default_factory=dict)
    kernel: dict[str, float] = field(default_factory=dict)


def fit_rest_magnets(board: Board, rest_ut: np.ndarray, *, each_strength: bool = False) -> tuple[Magnets, float]:
    """The board file's discs as one rigid body (their layout shifted, turned and scaled in the plane, at one depth,
    of one strength, or of one strength each with ``each_strength``; polarity as the file's) that best gives
    ``rest_ut`` (C, 3, chip axes, uT) through the file's chip axes at unit gain, and the rms residual (uT).
    A printed body holds its discs as placed, so the layout's shape is kept: 15 numbers of five chips cannot place
    four discs one by one (a free fit leaves less of the rest field and skews the layout). Several starts."""
    chips, readout = board.chip_positions_mm(), np.transpose(board.chip_matrices(), (0, 2, 1))
    start = board_magnets(board)
    sign = np.where(start.polarisation_t < 0, -1.0, 1.0)
    size, m = start.size_mm, len(start.size_mm)
    centre = start.centres_mm[:, :2].mean(axis=0)
    layout = start.centres_mm[:, :2] - centre
    thick = board.layer.thickness_mm  # type: ignore[union-attr]
    half = max(board.layer.size_mm) / 2  # type: ignore[union-attr]
    top = float(size[:, 1].max()) / 2 + MAGNET_Z_LIMIT_MM
    strengths = m if each_strength else 1

    def magnets(x: np.ndarray) -> Magnets:
        cx, cy, turn, scale, z = x[:5]
        c, s = np.cos(turn), np.sin(turn)
        xy = scale * layout @ np.array([[c, -s], [s, c]]).T + [cx, cy]
        return Magnets(np.c_[xy, np.full(m, z)], sign * np.broadcast_to(x[5:], (m,)), size)

    def residual(x: np.ndarray) -> np.ndarray:
        mags = magnets(x)
        field_pad = discs_field_pad_ut(chips, mags, mags.centres_mm[None])[0]
        return (np.einsum("cij,cj->ci", readout, field_pad) - rest_ut).ravel()

    z0 = float(np.clip(start.centres_mm[:, 2].mean(), -thick + top, -top))
    j0 = float(np.clip(np.abs(start.polarisation_t).mean(), 0.1, 1.4))
    low = np.r_[-half, -half, -np.pi, 0.3, -thick + top, np.full(strengths, 0.05)]
    high = np.r_[half, half, np.pi, 3.0, -top, np.full(strengths, MAX_POLARISATION_T)]
    best = None
    for dx, dy, turn in itertools.product((-3.0, 0.0, 3.0), (-3.0, 0.0, 3.0), (0.0, 0.4)):
        x0 = np.r_[centre[0] + dx, centre[1] + dy, turn, 1.0, z0, np.full(strengths, j0)]
        sol = least_squares(residual, np.clip(x0, low, high), bounds=(low, high))
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None
    return magnets(best.x), float(np.sqrt(np.mean(best.fun ** 2)))


def pad_points(board: Board, step_mm: float) -> np.ndarray:
    """(G, 2) a grid over the board's layer (mm, pad frame), ``step_mm`` apart."""
    hx, hy = (s / 2 for s in board.layer.size_mm)  # type: ignore[union-attr]
    gx, gy = np.arange(-hx, hx + step_mm / 2, step_mm), np.arange(-hy, hy + step_mm / 2, step_mm)
    return np.stack(np.meshgrid(gx, gy, indexing="ij"), axis=-1).reshape(-1, 2)


def press_bank(board: Board, magnets: Magnets, kernel: dict[str, float], step_mm: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The twin's field change (M, C, 3; pad axes, uT) under presses at every grid point of the pad and every
    strength of :data:`STRENGTHS`, with those points (M, 2) and strengths (M,)."""
    points = pad_points(board, step_mm)
    where = np.repeat(points, len(STRENGTHS), axis=0)
    strength = np.tile(np.asarray(STRENGTHS), len(points))
    change = press_change_pad_ut(board.chip_positions_mm(), magnets, where, strength, **kernel)
    return change, where, strength


def unit_rows(readings: np.ndarray) -> np.ndarray:
    """(N, D) each reading (N, ...) as a unit vector over its channels."""
    x = np.asarray(readings, np.float64).reshape(len(readings), -1)
    return x / np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-9)


def direction_chamfer(readings: np.ndarray, bank: np.ndarray) -> tuple[float, np.ndarray]:
    """Mean squared distance of each reading's direction to the nearest bank reading's, and those bank rows."""
    dist, index = cKDTree(unit_rows(bank)).query(unit_rows(readings))
    return float(np.mean(dist ** 2)), index


def _read(readout: np.ndarray, change: np.ndarray) -> np.ndarray:
    return np.einsum("cij,ncj->nci", readout, change)


def _latent(readings: np.ndarray, bank_change: np.ndarray, readout: np.ndarray
            ) -> tuple[float, np.ndarray, np.ndarray]:
    """Each reading's nearest bank press (in direction) and the scale of it that fits best: chamfer, rows, scales."""
    cost, index = direction_chamfer(readings, _read(readout, bank_change))
    pred = _read(readout, bank_change[index]).reshape(len(readings), -1)
    y = readings.reshape(len(readings), -1)
    scale = np.einsum("nk,nk->n", pred, y) / np.maximum(np.einsum("nk,nk->n", pred, pred), 1e-12)
    return cost, index, np.maximum(scale, 0.0)


def solve_readouts(change: np.ndarray, readings: np.ndarray, prior: np.ndarray) -> np.ndarray:
    """(C, 3, 3) per chip, the ridge fit of ``readings`` (N, C, 3) on ``change`` (N, C, 3) drawn to ``prior``."""
    out = np.empty_like(prior)
    for c in range(len(prior)):
        b, y = change[:, c], readings[:, c]
        gram = b.T @ b
        ridge = READOUT_RIDGE * max(float(np.trace(gram)) / 3.0, 1e-12)
        out[c] = np.linalg.solve(gram + ridge * np.eye(3), b.T @ y + ridge * prior[c].T).T
    return out


def fit_twin_unlabelled(board: Board, readings_ut: np.ndarray, rest_ut: np.ndarray, *,
                        report: Callable[[str], None] | None = None) -> BlindFit:
    """Fit ``board``'s twin to unlabelled presses ``readings_ut`` (N, C, 3; baseline-subtracted, chip axes, uT) and
    the untouched board's raw reading ``rest_ut`` (C, 3); see the module docstring.

    Raises:
        TwinFitError: too few presses, or the latent presses explain less than :data:`MIN_BLIND_EV` of the
            readings' variance.
    """
    say = report or (lambda line: None)
    y = np.asarray(readings_ut, np.float64)
    if len(y) < MIN_PRESSES:
        raise TwinFitError(f"{len(y)} unlabelled presses: a fit without labels needs at least {MIN_PRESSES}")
    result = BlindFit(board=board)
    begin = time.monotonic()
    magnets, rest_rms = fit_rest_magnets(board, rest_ut, each_strength=True)
    result.stages["rest"] = {"rest_rms_ut": round(rest_rms, 1), "seconds": round(time.monotonic() - begin, 1)}
    say(f"stage rest: discs from the rest field, rms {rest_rms:.0f} uT ({time.monotonic() - begin:.1f} s)")

    prior = np.transpose(board.chip_matrices(), (0, 2, 1))
    begin = time.monotonic()
    tried = []
    for values in itertools.product(*KERNEL_GRID.values()):
        kernel = dict(zip(KERNEL_GRID, values))
        change, where, strength = press_bank(board, magnets, kernel, SEARCH_STEP_MM)
        readout = fit_readouts(y, change, prior)
        tried.append((sum(symmetric_chamfer(y, change, where, strength, readout)), values))
    cost, values = min(tried)
    kernel = dict(zip(KERNEL_GRID, values))
    result.stages["kernel"] = {"chamfer_both_ways": round(cost, 5), **kernel,
                               "seconds": round(time.monotonic() - begin, 1)}
    say(f"stage kernel: depth {kernel['kernel_depth_mm']:g} mm, lateral {kernel['lateral_scale']:g}, tilt "
        f"{kernel['tilt_scale']:g}, the nearest of {len(tried)} to the readings both ways (chamfer {cost:.4f}; "
        f"{time.monotonic() - begin:.1f} s)")
    begin = time.monotonic()
    change, _, strength = press_bank(board, magnets, kernel, BANK_STEP_MM)
    readout = fit_readouts(y, change, prior)
    result.stages["readout"] = line = _describe(y, change, readout, time.monotonic() - begin)
    say(f"stage readout: chamfer {line['chamfer']:.4f}, EV {line['ev']:.3f} on {len(y)} presses "
        f"({line['seconds']:.1f} s)")
    if not line["ev"] >= MIN_BLIND_EV:
        raise TwinFitError(f"the fit did not converge: its latent presses explain {line['ev']:.2f} of the readings' "
                           f"variance (less than {MIN_BLIND_EV}); check that the presses are this board's")
    _, index, scale = _latent(y, change, readout)
    strongest = float(np.percentile(strength[index] * np.maximum(scale, 1e-3), 99))
    result.kernel = kernel
    result.board = blind_board(board, magnets, kernel, readout, rest_ut, press_gain=strongest / NOMINAL_DEPTH_MM)
    return result


def fit_readouts(readings: np.ndarray, change: np.ndarray, prior: np.ndarray) -> np.ndarray:
    """(C, 3, 3) readouts fitted to ``readings`` (N, C, 3) against their latent presses among the bank's field
    changes ``change`` (M, C, 3), alternating :data:`READOUT_ROUNDS` times from ``prior``."""
    readout = prior.copy()
    for _ in range(READOUT_ROUNDS):
        _, index, scale = _latent(readings, change, readout)
        readout = solve_readouts(scale[:, None, None] * change[index], readings, prior)
    return readout


def symmetric_chamfer(readings: np.ndarray, change: np.ndarray, where: np.ndarray, strength: np.ndarray,
                      readout: np.ndarray) -> tuple[float, float]:
    """The direction chamfer both ways: from the readings to the twin's presses, and from the twin's presses where
    and as hard as the readings' latent presses are (their 5-95th percentiles of place and strength) to the
    readings. The second keeps a twin from winning by reading every direction somewhere."""
    bank = _read(readout, change)
    forward, index = direction_chamfer(readings, bank)
    low, high = np.percentile(where[index], 5, axis=0), np.percentile(where[index], 95, axis=0)
    weak, strong = np.percentile(strength[index], 5), np.percentile(strength[index], 95)
    inside = np.all((where >= low) & (where <= high), axis=1) & (strength >= weak) & (strength <= strong)
    if not inside.any():
        return forward, np.inf
    back = cKDTree(unit_rows(readings)).query(unit_rows(bank[inside]))[0]
    return forward, float(np.mean(back ** 2))


def _describe(y: np.ndarray, change: np.ndarray, readout: np.ndarray, seconds: float) -> dict:
    cost, index, scale = _latent(y, change, readout)
    ev, per_channel = explained_variance(y, scale[:, None, None] * _read(readout, change[index]))
    return {"chamfer": round(cost, 5), "ev": round(ev, 4), "ev_per_channel": [round(v, 4) for v in per_channel],
            "seconds": round(seconds, 1)}


def blind_board(board: Board, magnets: Magnets, kernel: dict[str, float], readout: np.ndarray, rest_ut: np.ndarray,
                *, press_gain: float) -> Board:
    """``board`` with the fitted discs and a ``[twin]`` table in the pad frame (rig origin at the pad centre, no
    turn, first touch at stage z 0, a smaller z deeper), strength law ``s = press_gain * d``."""
    assert board.body is not None
    specs = tuple(MagnetSpec(shape="cylinder", size_mm=m.size_mm, position_mm=tuple(float(v) for v in c),
                             polarisation_t=(0.0, 0.0, float(j)))
                  for m, c, j in zip(board.body.magnets, magnets.centres_mm, magnets.polarisation_t))
    rest_pad = discs_field_pad_ut(board.chip_positions_mm(), magnets, magnets.centres_mm[None])[0]
    offsets = rest_ut - np.einsum("cij,cj->ci", readout, rest_pad)
    twin = TwinSpec(rig_origin_mm=(0.0, 0.0), rig_turn_deg=0.0, contact_z_mm=0.0, press_gain=press_gain,
                    press_exponent=1.0, depth_per_z=-1.0, softening_per_hour=0.0,
                    readout=tuple(ReadoutSpec(matrix=tuple(tuple(float(v) for v in row) for row in m),  # type: ignore[arg-type]
                                              offset_ut=tuple(float(v) for v in o))  # type: ignore[arg-type]
                                  for m, o in zip(readout, offsets)), **kernel)
    return dataclasses.replace(board, body=dataclasses.replace(board.body, magnets=specs), twin=twin)
