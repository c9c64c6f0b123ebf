"""Datasets of probe presses on any simulatable board: what a probe rig would record, made by the simulator.

:func:`probe_press_dataset` presses a tip at random places of the board's layer (uniform over the layer, a
margin from its edges), each with a random force, through :func:`~tactile_manip.sim.board_press.press`, reads
the chips through the board's chip model (noise, LSBs, rail) and stores each frame in the board's reading layout
(pad axes, the cells of its board file). Targets: ``x_mm``, ``y_mm`` (the tip's axis), ``depth_mm`` (its approach
past first touch) and ``force_n``; the split is drawn at random. Presses that go through the whole layer
(outside the elastic model) are drawn again. One press costs ~20 ms on one core.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from tactile_manip.boards import Board
from tactile_manip.checks import check_finite_scalar
from tactile_manip.data import PairedDataset, from_arrays
from tactile_manip.errors import SimulationError
from tactile_manip.sim.board_press import TIPS, press, readings_with_chip
from tactile_manip.sim.board_skin import BoardSkin
from tactile_manip.version import code_version

MAX_PRESSES = 1_000_000
MAX_REDRAWS = 50  # presses in a row that go through the layer before the plan is refused


@dataclass(frozen=True)
class ProbePlan:
    """How a simulated probe rig presses: the tip, the force range and how far from the layer's edges."""

    tip: str = "sphere"            # "sphere" or "flat"
    tip_diameter_mm: float = 6.0   # mm
    min_force_n: float = 0.5       # N
    max_force_n: float = 15.0      # N
    margin_mm: float = 2.0         # the tip's axis stays this far inside the layer's edges, mm

    def __post_init__(self) -> None:
        if self.tip not in TIPS:
            raise ValueError(f"tip must be one of {', '.join(TIPS)}, got {self.tip!r}")
        check_finite_scalar("tip_diameter_mm", self.tip_diameter_mm, low=0.0, low_open=True, high=100.0)
        check_finite_scalar("min_force_n", self.min_force_n, low=0.0, low_open=True, high=1e4)
        check_finite_scalar("max_force_n", self.max_force_n, low=self.min_force_n, high=1e4)
        check_finite_scalar("margin_mm", self.margin_mm, low=0.0, high=1000.0)


def probe_press_dataset(board: Board, presses: int, *, plan: ProbePlan = ProbePlan(), seed: int = 0,
                        val_fraction: float = 0.1, test_fraction: float = 0.1,
                        progress: Callable[[int], None] | None = None) -> PairedDataset:
    """``presses`` simulated probe presses of ``board`` as a targets-only dataset (see the module docstring).

    Raises:
        ConfigError: the board cannot be simulated (``generic:N``, or no ``[body]`` / ``[layer]``).
        ValueError: a press count outside 1 to 1,000,000, or a margin that leaves no room on the layer.
        SimulationError: the plan's presses keep going through the layer (force too high for the tip).
    """
    board.require_simulation()
    if isinstance(presses, bool) or not isinstance(presses, int) or not 1 <= presses <= MAX_PRESSES:
        raise ValueError(f"presses must be an integer from 1 to {MAX_PRESSES}, got {presses!r}")
    half = np.array(board.layer.size_mm) / 2 - plan.margin_mm
    if (half <= 0).any():
        raise ValueError(f"margin_mm {plan.margin_mm:g} leaves no room on the {board.layer.size_mm[0]:g} x "
                         f"{board.layer.size_mm[1]:g} mm layer")
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    skin = BoardSkin(board)
    baseline = skin.baseline_ut()
    cells = [c.cell for c in board.chips]
    readings = np.zeros((presses, *board.shape), np.float32)
    targets = {name: np.zeros(presses) for name in ("x_mm", "y_mm", "depth_mm", "force_n")}
    saturated = np.zeros(presses, bool)
    redrawn = 0
    for i in range(presses):
        for _ in range(MAX_REDRAWS):
            x, y = rng.uniform(-half, half)
            force = float(np.exp(rng.uniform(np.log(plan.min_force_n), np.log(plan.max_force_n))))
            result = press(skin, tip=plan.tip, tip_diameter_mm=plan.tip_diameter_mm, x_mm=x, y_mm=y, force_n=force)
            if not result.bottomed_out:
                break
            redrawn += 1
        else:
            raise SimulationError(f"{MAX_REDRAWS} presses in a row of a {plan.tip_diameter_mm:g} mm {plan.tip} at "
                                  f"{plan.min_force_n:g}-{plan.max_force_n:g} N went through board {board.name}'s "
                                  f"{board.layer.thickness_mm:g} mm layer: lower the force or widen the tip")
        frame = readings_with_chip(result.reading_ut, board, rng, baseline_ut=baseline)
        pad = skin.to_pad_axes(frame.reading_ut)
        for (r, c), value in zip(cells, pad):
            readings[i, r, c] = value
        saturated[i] = frame.saturated.any()
        for name, value in zip(targets, (x, y, result.approach_mm, result.force_n)):
            targets[name][i] = value
        if progress is not None:
            progress(1)
    seconds = time.perf_counter() - t0
    prov = {"source": "tactile_manip.sim.board_dataset", "code_version": code_version(), "layout": board.name,
            "board": board.record, "board_file": None if board.path is None else str(board.path), "seed": seed,
            "probe": {"tip": plan.tip, "tip_diameter_mm": plan.tip_diameter_mm, "min_force_n": plan.min_force_n,
                      "max_force_n": plan.max_force_n, "margin_mm": plan.margin_mm},
            "redrawn_bottomed_out": redrawn, "saturated_presses": int(saturated.sum()),
            "generation_seconds": seconds}
    return from_arrays(readings, targets=targets, val_fraction=val_fraction, test_fraction=test_fraction, seed=seed,
                       extras={"saturated": saturated}, provenance=prov)
