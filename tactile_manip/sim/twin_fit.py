"""Fit a board's twin (:mod:`tactile_manip.sim.twin`) to what its owner can record: the untouched board's raw
field and labelled presses from a probe rig.

The fit runs in stages, each starting from the last, so that what each term buys can be read off:

1. ``file``: the board file's magnets and chip axes; the rig frame (origin, turn, contact height) and the press
   kernel (strength law ``A d^n``, kernel depth, lateral and tilt scales) are fitted, with one gain per chip;
2. ``magnets``: the magnets' places (x, y each, a common depth), strengths and polarities are freed, and each
   chip's turn is searched among the 16 signed quarter turns and mirror images (with one gain per chip); the
   untouched board's raw field joins the residual (the chips' offsets taken as nil);
3. ``readout``: each chip's readout becomes a free 3x3 matrix (gain, turn and misalignment; the chips' offsets
   follow from the rest field), and the skin may soften over the run;
4. ``base``: the press's image in the rigid base the layer is bonded to (one share);
5. ``cells``: the printed lattice's nodes (pitch, turn and phase searched over a few starts, then the node's
   sharpness and its factors on strength, kernel depth and tilt; :mod:`tactile_manip.sim.twin`).

The last two need a rig's many presses spread over the pad (at least :data:`SKIN_MIN_ROWS`, over
:data:`PINNING_SPAN_MM` for the base and :data:`CELLS_MIN_SPAN` lattice pitches for the cells); with fewer (a
handful of labelled presses, one place pressed again and again) they stay off and their stages repeat the last
fitted one: on 25 labelled presses of the spatial eFlesh run the base's one share raised the fitted rows' EV and
placed the test presses worse through the twin.

Every stage is a robust (soft-L1) least squares over the chosen presses on channels scaled by their spread
(:func:`scipy.optimize.least_squares`); the chips' readout is solved in closed form inside it (variable
projection). Results carry the explained variance (EV) of the fitting rows per stage and per channel.

numpy and scipy only.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from tactile_manip.boards.load import Board
from tactile_manip.boards.spec import MagnetSpec, ReadoutSpec, TwinSpec
from tactile_manip.errors import SimulationError
from tactile_manip.sim.twin import (Cells, Magnets, board_magnets, discs_field_pad_ut, press_change_pad_ut,
                                    rig_to_pad)

STAGES = ("file", "magnets", "readout", "base", "cells")
FREE_READOUT = ("readout", "base", "cells")  # the stages whose chips read through a free 3x3 readout
MIN_FIT_EV = 0.3          # a fit that explains less of its own rows has not converged on this board
READOUT_RIDGE = 0.05      # pull of a free readout towards its chip's turn at unit gain (share of the field's power)
READOUT_PRIOR_ROWS = 12   # ... and at least as much as this many presses would weigh (a handful of labels)
# share of the cost the untouched board's field carries per stage (the chips' offsets taken as nil); in "readout"
# only where the presses do not pin the magnets (all at one point: less than PINNING_SPAN_MM apart), and then only
# enough to keep them from wandering; elsewhere the offsets take up what the geometry leaves of the rest field
REST_WEIGHT = {"file": 0.0, "magnets": 0.2, "readout": 0.0, "base": 0.0, "cells": 0.0}
UNPINNED_REST_WEIGHT = 0.01
PINNING_SPAN_MM = 5.0
MAGNET_Z_LIMIT_MM = 0.1   # discs' faces stay this far inside the layer
MAX_POLARISATION_T = 1.5  # N52, the strongest grade of NdFeB, has a remanence of 1.42-1.48 T
SKIN_MIN_ROWS = 200       # presses the base and cells terms are fitted on at least ...
CELLS_MIN_SPAN = 2.0      # ... spread, for the cells, over this many lattice pitches along both of the pad's axes
CELL_STARTS_MM = (6.0, 8.0, 10.0)  # lattice pitches the search starts from (printed cut cells: a few mm)
CELL_START_PHASES = ((0.0, 0.0), (0.5, 0.0), (0.0, 0.5), (0.5, 0.5))
CELL_SEARCH_ROWS = 300    # presses each start of the search is fitted on


class TwinFitError(SimulationError):
    """A fit that did not converge (its residual says how far off it is); nothing is written."""


@dataclass(frozen=True)
class PressLog:
    """Labelled presses of one run: (N, 3) stage poses (mm), (N, C, 3) baseline-subtracted chip-axes readings (uT,
    firmware order) and (N,) hours since the run's first row."""

    stage_xyz_mm: np.ndarray
    readings_ut: np.ndarray
    time_h: np.ndarray


@dataclass
class TwinFit:
    """What :func:`fit_twin` found: the fitted board, and per stage its EV on the fitting rows (overall and per
    channel), the rest field's rms residual (uT) and the time taken (s); the boards of the stages with free
    readouts, to score what each term buys."""

    board: Board
    stages: dict[str, dict] = field(default_factory=dict)
    chip_turns: list[list[list[float]]] = field(default_factory=list)
    orders: list[dict] = field(default_factory=list)
    stage_boards: dict[str, Board] = field(default_factory=dict)  # the board as fitted at stages readout, base, cells


# 16 signed quarter turns and mirror images of a chip (in-plane axis permutations, z either way)
def _turn_candidates() -> np.ndarray:
    out = []
    for k in range(4):
        c, s = [1, 0, -1, 0][k], [0, 1, 0, -1][k]
        for mirror in (1, -1):
            for zsign in (1, -1):
                out.append(np.array([[c, -s * mirror, 0], [s, c * mirror, 0], [0, 0, zsign]], float))
    return np.stack(out)


TURNS = _turn_candidates()


@dataclass
class _Params:
    """The fitted numbers as one vector, and which of them a stage frees."""

    names: list[str]
    values: np.ndarray
    low: np.ndarray
    high: np.ndarray

    def get(self, name: str) -> float:
        return float(self.values[self.names.index(name)])


def initial_params(board: Board, log: PressLog) -> _Params:
    """Start values: the rig's origin at the presses' centre, contact at the shallowest logged z (or the deepest,
    by the stage's direction), the board file's magnets."""
    mag = board_magnets(board)
    t = board.layer.thickness_mm  # type: ignore[union-attr]
    xy = log.stage_xyz_mm[:, :2]
    z = log.stage_xyz_mm[:, 2]
    mean_z = float(np.mean(mag.centres_mm[:, 2]))
    top = float(mag.size_mm[:, 1].max()) / 2 + MAGNET_Z_LIMIT_MM  # a disc's faces stay inside the layer
    contact = float(z.max()) + 0.5 if _depth_per_z(log) < 0 else float(z.min()) - 0.5
    rows = [("origin_x", np.median(xy[:, 0]), -1e4, 1e4), ("origin_y", np.median(xy[:, 1]), -1e4, 1e4),
            ("turn_deg", 0.0, -360.0, 360.0), ("contact_z", contact, -1e4, 1e4),
            ("log_gain", 0.0, -12.0, 8.0), ("exponent", 1.0, 0.3, 3.0), ("kernel_depth", max(2.0, -mean_z), 0.5, 60.0),
            ("lateral", 1.0, 0.0, 5.0), ("tilt", 1.0, 0.0, 5.0), ("softening", 0.0, -0.5, 2.0), ("mirror", 0.0, 0.0, 1.0),
            ("magnet_z", mean_z, -t + top, -top), ("base_image", 0.0, 0.0, 1.0),
            ("cell_period", 0.0, 2.0, 30.0), ("cell_angle", 0.0, -45.0, 45.0), ("cell_phase1", 0.0, -2.0, 2.0),
            ("cell_phase2", 0.0, -2.0, 2.0), ("cell_log_sharpness", 0.0, -2.5, 4.0), ("cell_stiffness", 0.0, -3.0, 3.0),
            ("cell_depth", 0.0, -3.0, 3.0), ("cell_tilt", 0.0, -3.0, 3.0)]
    half = max(board.layer.size_mm) / 2  # type: ignore[union-attr]
    for i, (c, j) in enumerate(zip(mag.centres_mm, mag.polarisation_t)):
        rows += [(f"magnet{i}_x", c[0], -half, half), (f"magnet{i}_y", c[1], -half, half),
                 (f"magnet{i}_j", j, -MAX_POLARISATION_T, MAX_POLARISATION_T)]
    names = [r[0] for r in rows]
    values = np.array([r[1] for r in rows], float)
    low, high = np.array([r[2] for r in rows], float), np.array([r[3] for r in rows], float)
    values = np.clip(values, low, high)
    values[names.index("cell_period")] = 0.0  # no lattice until the cells stage searches one (2-30 mm then)
    return _Params(names, values, low, high)


def _free(stage: str, names: list[str]) -> list[int]:
    base = ["origin_x", "origin_y", "turn_deg", "contact_z", "log_gain", "exponent", "kernel_depth", "lateral", "tilt"]
    if stage != "file":
        base += ["magnet_z"] + [n for n in names if n.startswith("magnet") and n != "magnet_z"]
    if stage in FREE_READOUT:
        base += ["softening"]
    if stage in ("base", "cells"):
        base += ["base_image"]
    if stage == "cells":
        base += [n for n in names if n.startswith("cell_")]
    return [names.index(n) for n in base]


def _cells(p: _Params) -> Cells | None:
    if p.get("cell_period") <= 0.0:
        return None
    return Cells(p.get("cell_period"), p.get("cell_angle"), (p.get("cell_phase1"), p.get("cell_phase2")),
                 float(np.exp(p.get("cell_log_sharpness"))), p.get("cell_stiffness"), p.get("cell_depth"),
                 p.get("cell_tilt"))


def _magnets(p: _Params, size_mm: np.ndarray) -> Magnets:
    m = len(size_mm)
    centres = np.array([[p.get(f"magnet{i}_x"), p.get(f"magnet{i}_y"), p.get("magnet_z")] for i in range(m)])
    return Magnets(centres_mm=centres, polarisation_t=np.array([p.get(f"magnet{i}_j") for i in range(m)]),
                   size_mm=size_mm)


def change_pad_ut(p: _Params, chips_mm: np.ndarray, size_mm: np.ndarray, log: PressLog,
                  base_depth_mm: float = 0.0) -> np.ndarray:
    """(N, C, 3) the twin's field change (pad axes, uT) at the log's poses for parameters ``p``."""
    xy, approach = rig_to_pad(log.stage_xyz_mm, origin_mm=(p.get("origin_x"), p.get("origin_y")),
                              turn_deg=p.get("turn_deg"), contact_z_mm=p.get("contact_z"),
                              depth_per_z=_depth_per_z(log), mirror=p.get("mirror") > 0.5)
    strength = np.exp(p.get("log_gain")) * np.power(approach, p.get("exponent")) * (
        1.0 + p.get("softening") * log.time_h)
    return press_change_pad_ut(chips_mm, _magnets(p, size_mm), xy, strength, kernel_depth_mm=p.get("kernel_depth"),
                               lateral_scale=p.get("lateral"), tilt_scale=p.get("tilt"),
                               base_image=p.get("base_image"), base_depth_mm=base_depth_mm, cells=_cells(p))


def _depth_per_z(log: PressLog) -> float:
    """-1 where the presses go in as the stage's z falls (the eFlesh rigs), +1 where it rises: the readings change
    most at the far end of z's range from where they change least (-1 where z or the readings do not vary)."""
    z = log.stage_xyz_mm[:, 2]
    size = np.linalg.norm(log.readings_ut.reshape(len(z), -1), axis=1)
    if np.ptp(z) == 0.0 or np.ptp(size) == 0.0:  # nothing to tell by: the rigs' usual way
        return -1.0
    return 1.0 if np.corrcoef(z, size)[0, 1] > 0 else -1.0


def solve_readout(stage: str, change: np.ndarray, readings: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """(C, 3, 3) readout per chip (pad field -> chip reading) that best maps ``change`` (N, C, 3) onto
    ``readings`` (N, C, 3): a gain on the file's axes (``file``), a gain on the best of :data:`TURNS`
    (``magnets``), or a 3x3 matrix drawn towards that turn at unit gain (``readout``: ridge regression, so a
    field direction the presses hardly excite keeps the chip's turn, and a handful of presses cannot pull the
    readout far). ``axes``: (C, 3, 3) the file's chip -> pad
    matrices."""
    out = np.empty((change.shape[1], 3, 3))
    for c in range(change.shape[1]):
        b, y = change[:, c], readings[:, c]
        candidates = axes[c].T[None] if stage == "file" else TURNS
        best = None
        for turn in candidates:
            pred = b @ turn.T
            gain = max(float(np.sum(pred * y)) / max(float(np.sum(pred * pred)), 1e-12), 0.0)
            err = float(np.sum((y - gain * pred) ** 2))
            if best is None or err < best[0]:
                best = (err, gain, turn)
        if stage not in FREE_READOUT:
            out[c] = best[1] * best[2]
            continue
        gram = b.T @ b
        share = max(READOUT_RIDGE, READOUT_PRIOR_ROWS / len(b))
        ridge = share * max(float(np.trace(gram)) / 3.0, 1e-12)
        out[c] = np.linalg.solve(gram + ridge * np.eye(3), b.T @ y + ridge * best[2].T).T
    return out


def fit_twin(board: Board, log: PressLog, *, rest_ut: np.ndarray | None = None, max_evaluations: int = 60,
             search_order: bool = False, report: Callable[[str], None] | None = None) -> TwinFit:
    """Fit ``board``'s twin to a press log (and the untouched board's raw reading ``rest_ut``, (C, 3) chip axes).

    The search starts from the rig's four quarter turns (the rig frame and press kernel fitted with free readouts
    on a subset of rows), fits every term from the best start (stage ``readout``: the twin written), and then
    refits the simpler stages ``file`` and ``magnets`` from there, to say what each term buys. With
    ``search_order`` the chips' order is searched first (:func:`search_chip_orders`) and the best order fitted.

    Raises:
        TwinFitError: the twin explains less than :data:`MIN_FIT_EV` of its rows' variance.
    """
    say = report or (lambda line: None)
    fitter = _Fitter(board, log, rest_ut)
    p = initial_params(board, log)
    start = time.monotonic()
    starts = []
    subset = np.linspace(0, len(log.readings_ut) - 1, min(300, len(log.readings_ut))).astype(int)
    for mirror in (0.0, 1.0):
        for turn in (0.0, 90.0, 180.0, 270.0):
            q = dataclasses.replace(p, values=p.values.copy())
            q.values[q.names.index("turn_deg")] = turn
            q.values[q.names.index("mirror")] = mirror
            cost = fitter.run(q, "readout", _free("file", q.names), max_evaluations // 4, rows=subset)
            starts.append((cost, q))
    p = min(starts, key=lambda item: item[0])[1]
    say(f"stage start: rig turn {p.get('turn_deg'):.0f} deg{', mirrored' if p.get('mirror') > 0.5 else ''}, the best "
        f"of 8 quarter turns and mirror images ({time.monotonic() - start:.1f} s)")
    result = TwinFit(board=board)
    file_fitter = fitter
    if search_order:
        begin = time.monotonic()
        result.orders = search_chip_orders(board, log, p, rest_ut=rest_ut, max_evaluations=max_evaluations // 3)
        best = result.orders[0]
        say(f"stage order: of {len(result.orders)} placements of the chips, the best explains {best['ev']:.3f} "
            f"(rest field rms {best['rest_rms_ut']:.0f} uT), the file's {_file_order(result.orders)['ev']:.3f} "
            f"({time.monotonic() - begin:.1f} s)")
        board = with_chip_order(board, best["order"])
        fitter = _Fitter(board, log, rest_ut)
    final = dataclasses.replace(p, values=p.values.copy())
    fitter.run(final, "readout", _free("readout", final.names), max_evaluations)
    fitted = {"readout": final}
    fitted["base"], fitted["cells"], notes = _skin_terms(fitter, final, max_evaluations)
    for stage, q in (("file", p), ("magnets", final), *fitted.items()):
        begin = time.monotonic()
        use = file_fitter if stage == "file" else fitter
        if stage not in FREE_READOUT:
            q = dataclasses.replace(q, values=q.values.copy())
            use.run(q, stage, _free(stage, q.names), max_evaluations // 2)
        result.stages[stage] = use.describe(stage, q, round(time.monotonic() - begin, 1))
        line = result.stages[stage]
        if stage in notes:
            line["note"] = notes[stage]
        say(f"stage {stage}: EV {line['ev']:.3f} on {len(log.readings_ut)} rows"
            + ("" if line["rest_rms_ut"] is None else f", rest field rms {line['rest_rms_ut']:.0f} uT")
            + (f"; {notes[stage]}" if stage in notes else f" ({line['seconds']:.1f} s)"))
        if stage == "magnets":
            result.chip_turns = [np.round(m / np.abs(m).max(), 3).tolist() for m in fitter.readout(stage, q)]
    last = result.stages["cells"]
    if not last["ev"] >= MIN_FIT_EV:
        raise TwinFitError(f"the fit did not converge: it explains {last['ev']:.2f} of its rows' reading variance "
                           f"(less than {MIN_FIT_EV}); check the label columns, the rig's z direction and the board")
    result.stage_boards = {stage: fitted_board(board, q, fitter.readout(stage, q), rest_ut, _depth_per_z(log))
                           for stage, q in fitted.items()}
    result.board = result.stage_boards["cells"]
    return result


def _skin_terms(fitter: _Fitter, start: _Params, max_evaluations: int) -> tuple[_Params, _Params, dict[str, str]]:
    """The ``base`` and ``cells`` stages from the ``readout`` stage's ``start``: each term fitted where the presses
    can tell it, and kept where it lowers the cost (else the stage repeats the one before, with a note why)."""
    notes: dict[str, str] = {}
    span = np.ptp(fitter.log.stage_xyz_mm[:, :2], axis=0)
    base = dataclasses.replace(start, values=start.values.copy())
    rows = len(fitter.log.readings_ut)
    if rows >= SKIN_MIN_ROWS and span.max() >= PINNING_SPAN_MM:
        begin = time.monotonic()
        trial = dataclasses.replace(base, values=base.values.copy())
        trial.values[trial.names.index("base_image")] = 0.3
        if fitter.run(trial, "base", _free("base", trial.names), max_evaluations // 2) < fitter.cost("base", base):
            base = trial
        notes["base"] = f"image share {base.get('base_image'):.2f} ({time.monotonic() - begin:.1f} s)"
    else:
        notes["base"] = (f"off: {rows} presses over {span.max():.0f} mm (the base needs {SKIN_MIN_ROWS} over "
                         f"{PINNING_SPAN_MM:g} mm)")
    cells = dataclasses.replace(base, values=base.values.copy())
    if rows < SKIN_MIN_ROWS or span.min() < CELLS_MIN_SPAN * max(CELL_STARTS_MM):
        notes["cells"] = (f"off: {rows} presses over {span.min():.0f} mm (a lattice needs {SKIN_MIN_ROWS} over "
                          f"{CELLS_MIN_SPAN * max(CELL_STARTS_MM):.0f} mm)")
        return base, cells, notes
    begin = time.monotonic()
    subset = np.linspace(0, rows - 1, min(CELL_SEARCH_ROWS, rows)).astype(int)
    names = [n for n in cells.names if n.startswith("cell_")]
    starts = []
    for period in CELL_STARTS_MM:
        for phase in CELL_START_PHASES:
            q = dataclasses.replace(cells, values=cells.values.copy())
            for name, value in zip(("cell_period", "cell_phase1", "cell_phase2"), (period, *phase)):
                q.values[q.names.index(name)] = value
            starts.append((fitter.run(q, "cells", [q.names.index(n) for n in names], max_evaluations // 4,
                                      rows=subset), q))
    trial = min(starts, key=lambda item: item[0])[1]
    if fitter.run(trial, "cells", _free("cells", trial.names), max_evaluations) < fitter.cost("cells", base):
        cells = trial
        notes["cells"] = (f"pitch {cells.get('cell_period'):.2f} mm, turned {cells.get('cell_angle'):.1f} deg, "
                          f"{len(starts)} starts ({time.monotonic() - begin:.1f} s)")
    else:
        notes["cells"] = f"off: no lattice of {len(starts)} starts lowers the cost ({time.monotonic() - begin:.1f} s)"
    return base, cells, notes


MAX_ORDER_SEARCH_CHIPS = 6  # 6! placements, fewer up to the pad's symmetries; more chips: no exhaustive search


def chip_orders(positions_mm: np.ndarray) -> list[tuple[int, ...]]:
    """The placements of the chips on their positions (``order[i]``: the position chip i sits at) that no turn or
    mirror image of the pad mapping the positions onto themselves turns into one another; the identity first.

    Raises:
        ValueError: more than :data:`MAX_ORDER_SEARCH_CHIPS` chips.
    """
    import itertools

    n = len(positions_mm)
    if n > MAX_ORDER_SEARCH_CHIPS:
        raise ValueError(f"the chips' order is searched for at most {MAX_ORDER_SEARCH_CHIPS} chips, not {n}")
    xy = np.asarray(positions_mm, float)[:, :2]
    maps = []
    for g in TURNS[::2, :2, :2]:  # the 8 turns and mirror images of the plane
        moved = xy @ g.T
        dist = np.linalg.norm(moved[:, None] - xy[None], axis=-1)
        if np.all(dist.min(axis=1) < 1e-6):
            maps.append(dist.argmin(axis=1))  # position k goes to position maps[k]
    seen, out = set(), []
    for order in itertools.permutations(range(n)):
        key = min(tuple(int(m[k]) for k in order) for m in maps)
        if key not in seen:
            seen.add(key)
            out.append(order)
    return out


def with_chip_order(board: Board, order: tuple[int, ...]) -> Board:
    """``board`` with chip i moved to chip ``order[i]``'s position and cell (its turn kept)."""
    chips = tuple(dataclasses.replace(c, position_mm=board.chips[k].position_mm, cell=board.chips[k].cell)
                  for c, k in zip(board.chips, order))
    return dataclasses.replace(board, chips=chips)


def search_chip_orders(board: Board, log: PressLog, start: _Params, *, rest_ut: np.ndarray | None,
                       max_evaluations: int, rows: int = 200) -> list[dict]:
    """Fit the ``magnets`` stage (one gain and quarter turn per chip, free magnets, the rest field) for each of
    :func:`chip_orders` on ``rows`` of the log, from ``start``; best first, each ``{"order", "ev",
    "rest_rms_ut", "cost"}``."""
    subset = np.linspace(0, len(log.readings_ut) - 1, min(rows, len(log.readings_ut))).astype(int)
    part = PressLog(log.stage_xyz_mm[subset], log.readings_ut[subset], log.time_h[subset])
    out = []
    for order in chip_orders(board.chip_positions_mm()):
        candidate = with_chip_order(board, order)
        fitter = _Fitter(candidate, part, rest_ut)
        q = dataclasses.replace(start, values=start.values.copy())
        cost = fitter.run(q, "magnets", _free("magnets", q.names), max_evaluations)
        line = fitter.describe("magnets", q, 0.0)
        out.append({"order": [int(k) for k in order], "ev": line["ev"], "rest_rms_ut": line["rest_rms_ut"],
                    "cost": round(cost, 3)})
    return sorted(out, key=lambda item: item["cost"])


def _file_order(orders: list[dict]) -> dict:
    return next(o for o in orders if o["order"] == sorted(o["order"]))


class _Fitter:
    """The residual of one stage and its robust least squares, over a log's rows."""

    def __init__(self, board: Board, log: PressLog, rest_ut: np.ndarray | None) -> None:
        self.log, self.rest_ut = log, rest_ut
        self.chips_mm = board.chip_positions_mm()
        self.axes = board.chip_matrices()
        self.size = board_magnets(board).size_mm
        self.base_mm = board.layer.thickness_mm  # type: ignore[union-attr]
        y = log.readings_ut
        self.scale = np.maximum(y.reshape(len(y), -1).std(axis=0), 1e-6).reshape(1, -1, 3)

    def _rows(self, rows: np.ndarray | None) -> PressLog:
        if rows is None:
            return self.log
        return PressLog(self.log.stage_xyz_mm[rows], self.log.readings_ut[rows], self.log.time_h[rows])

    def _rest_pad(self, q: _Params) -> np.ndarray:
        mags = _magnets(q, self.size)
        return discs_field_pad_ut(self.chips_mm, mags, mags.centres_mm[None])[0]

    def run(self, p: _Params, stage: str, free: list[int], max_evaluations: int,
            rows: np.ndarray | None = None) -> float:
        """Fit the ``free`` entries of ``p`` (in place) for ``stage``'s readout; returns the final cost."""
        log = self._rows(rows)
        weight = REST_WEIGHT[stage]
        if stage in FREE_READOUT and np.ptp(log.stage_xyz_mm[:, :2], axis=0).max() < PINNING_SPAN_MM:
            weight = UNPINNED_REST_WEIGHT
        use_rest = self.rest_ut is not None and weight > 0

        def residual(x: np.ndarray) -> np.ndarray:
            q = dataclasses.replace(p, values=p.values.copy())
            q.values[free] = x
            change = change_pad_ut(q, self.chips_mm, self.size, log, self.base_mm)
            m = solve_readout(stage, change, log.readings_ut, self.axes)
            r = ((np.einsum("cij,ncj->nci", m, change) - log.readings_ut) / self.scale).ravel()
            if use_rest:
                miss = (np.einsum("cij,cj->ci", m, self._rest_pad(q)) - self.rest_ut) / self.scale[0]
                r = np.concatenate([r, miss.ravel() * np.sqrt(weight * r.size / miss.size)])
            return r

        if not free:  # the cost where it stands: least_squares' soft-L1 cost, 0.5 sum 2 (sqrt(1 + r^2) - 1)
            r = residual(p.values[free])
            return float(np.sum(np.sqrt(1.0 + r * r) - 1.0))
        sol = least_squares(residual, p.values[free], bounds=(p.low[free], p.high[free]), loss="soft_l1",
                            f_scale=1.0, x_scale="jac", max_nfev=max(1, max_evaluations))
        p.values[free] = sol.x
        return float(sol.cost)

    def cost(self, stage: str, p: _Params) -> float:
        """The robust cost :meth:`run` minimises, at ``p`` (nothing fitted)."""
        return self.run(dataclasses.replace(p, values=p.values.copy()), stage, [], 0)

    def readout(self, stage: str, p: _Params) -> np.ndarray:
        change = change_pad_ut(p, self.chips_mm, self.size, self.log, self.base_mm)
        return solve_readout(stage, change, self.log.readings_ut, self.axes)

    def describe(self, stage: str, p: _Params, seconds: float) -> dict:
        change = change_pad_ut(p, self.chips_mm, self.size, self.log, self.base_mm)
        m = solve_readout(stage, change, self.log.readings_ut, self.axes)
        ev, per_channel = explained_variance(self.log.readings_ut, np.einsum("cij,ncj->nci", m, change))
        rest_rms = None if self.rest_ut is None else float(np.sqrt(np.mean(
            (np.einsum("cij,cj->ci", m, self._rest_pad(p)) - self.rest_ut) ** 2)))
        return {"ev": round(ev, 4), "ev_per_channel": [round(v, 4) for v in per_channel],
                "rest_rms_ut": None if rest_rms is None else round(rest_rms, 1), "seconds": seconds}


def fitted_board(board: Board, p: _Params, readout: np.ndarray, rest_ut: np.ndarray | None,
                 depth_per_z: float) -> Board:
    """``board`` with the fitted magnets and a ``[twin]`` table (offsets from the rest field, where given)."""
    assert board.body is not None
    mags = _magnets(p, board_magnets(board).size_mm)
    magnets = tuple(MagnetSpec(shape="cylinder", size_mm=m.size_mm, position_mm=tuple(float(v) for v in c),
                               polarisation_t=(0.0, 0.0, float(j)))
                    for m, c, j in zip(board.body.magnets, mags.centres_mm, mags.polarisation_t))
    chips_mm = board.chip_positions_mm()
    rest_pad = discs_field_pad_ut(chips_mm, mags, mags.centres_mm[None])[0]
    offsets = np.zeros((board.n_chips, 3)) if rest_ut is None else rest_ut - np.einsum("cij,cj->ci", readout, rest_pad)
    twin = TwinSpec(rig_origin_mm=(p.get("origin_x"), p.get("origin_y")), rig_turn_deg=p.get("turn_deg"),
                    contact_z_mm=p.get("contact_z"), press_gain=float(np.exp(p.get("log_gain"))),
                    press_exponent=p.get("exponent"), kernel_depth_mm=p.get("kernel_depth"),
                    depth_per_z=depth_per_z, rig_mirror=bool(p.get("mirror") > 0.5), lateral_scale=p.get("lateral"), tilt_scale=p.get("tilt"),
                    softening_per_hour=p.get("softening"), base_image=p.get("base_image"),
                    cell_period_mm=p.get("cell_period"), cell_angle_deg=p.get("cell_angle"),
                    cell_phase=(p.get("cell_phase1"), p.get("cell_phase2")),
                    cell_sharpness=float(np.exp(p.get("cell_log_sharpness"))), cell_stiffness=p.get("cell_stiffness"),
                    cell_depth=p.get("cell_depth"), cell_tilt=p.get("cell_tilt"),
                    readout=tuple(ReadoutSpec(matrix=tuple(tuple(float(v) for v in row) for row in m),  # type: ignore[arg-type]
                                              offset_ut=tuple(float(v) for v in o))  # type: ignore[arg-type]
                                  for m, o in zip(readout, offsets)))
    body = dataclasses.replace(board.body, magnets=magnets)
    return dataclasses.replace(board, body=body, twin=twin)


def explained_variance(measured: np.ndarray, predicted: np.ndarray) -> tuple[float, list[float]]:
    """Overall and per-channel EV, ``1 - sum (y - y_hat)^2 / sum (y - mean y)^2`` over rows (overall: both sums
    pooled over channels, so a channel weighs by its variance). Arrays (N, ...) of the same shape."""
    y = measured.reshape(len(measured), -1).astype(np.float64)
    e = y - predicted.reshape(len(predicted), -1)
    ss = ((y - y.mean(axis=0)) ** 2).sum(axis=0)
    se = (e ** 2).sum(axis=0)
    per = 1.0 - se / np.maximum(ss, 1e-12)
    return float(1.0 - se.sum() / max(float(ss.sum()), 1e-12)), [float(v) for v in per]
