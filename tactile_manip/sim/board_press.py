"""Probe presses on any simulatable board, as a probe rig makes them, and the chip model of the board's file.

A press puts a rigid tip (a sphere, or a flat-ended cylinder) on the board's layer at ``(x_mm, y_mm)`` and
either pushes with a force (``force_n``: one Polonsky-Keer solve, :func:`~tactile_manip.sim.contact.solve_contact`)
or to an approach (``depth_mm``: the force that gives it, by a secant search on ``log F`` against ``log depth``).
The pressure then deforms the layer and moves the magnetic body (:class:`~tactile_manip.sim.board_skin.BoardSkin`).

The approach is the tip's travel past the point where its lowest point meets the undeformed top surface (what a
rig's stage reports from first touch). The tip is frictionless, and material exists only over the layer's
rectangle.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from tactile_manip.boards.load import Board
from tactile_manip.checks import check_array, check_choice, check_finite_scalar
from tactile_manip.errors import SimulationError
from tactile_manip.sim.board_skin import BoardSkin
from tactile_manip.sim.contact import ContactSolution, solve_contact

TIPS = ("sphere", "flat")
_DEPTH_ITERATIONS = 30


@dataclass(frozen=True)
class BoardPress:
    """One quasi-static probe press on a board.

    Attributes:
        reading_ut: (n_chips, 3) noise-free, baseline-subtracted reading, each chip's axes, firmware order, uT.
        field_change_pad_ut: (n_chips, 3) the same change in pad axes, uT.
        force_n: total normal force, N.
        approach_mm: the tip's approach past first touch, mm.
        centre_mm: centre of pressure (x, y) in the pad frame, mm.
        contact_area_mm2: area of the pixels carrying pressure, mm^2.
        peak_kpa: peak contact pressure, kPa.
        iterations: contact solves (depth control) or conjugate-gradient iterations of the one solve.
        bottomed_out: the approach reached the layer's thickness (outside the elastic layer model).
        pressure_mpa: (n, n) pressure on the skin's pad grid, MPa.
    """

    reading_ut: np.ndarray
    field_change_pad_ut: np.ndarray
    force_n: float
    approach_mm: float
    centre_mm: tuple[float, float]
    contact_area_mm2: float
    peak_kpa: float
    iterations: int
    bottomed_out: bool
    pressure_mpa: np.ndarray = field(repr=False)


def tip_gap_mm(skin: BoardSkin, *, tip: Literal["sphere", "flat"], tip_diameter_mm: float, x_mm: float,
               y_mm: float) -> np.ndarray:
    """(n, n) gap (mm) from the tip's lowest point to each pad pixel, NaN where no tip or no layer is.

    ``"sphere"``: the exact sphere ``R - sqrt(R^2 - r^2)`` within its radius. ``"flat"``: 0 over the disc.
    """
    check_choice("tip", tip, TIPS)
    radius = check_finite_scalar("tip_diameter_mm", tip_diameter_mm, low=0.0, low_open=True) / 2.0
    r2 = (skin.x_mm - check_finite_scalar("x_mm", x_mm)) ** 2 + (skin.y_mm - check_finite_scalar("y_mm", y_mm)) ** 2
    under = (r2 < radius ** 2) & skin.pad_mask
    if not under.any():
        raise ValueError(f"a {tip_diameter_mm:g} mm {tip} tip at ({x_mm:g}, {y_mm:g}) mm misses the "
                         f"{skin.layer.size_mm[0]:g} x {skin.layer.size_mm[1]:g} mm pad")
    if tip == "sphere":
        gap = radius - np.sqrt(np.clip(radius ** 2 - r2, 0.0, None))
    else:
        gap = np.zeros_like(r2)
    return np.where(under, gap, np.nan)


def press(skin: BoardSkin, *, tip: Literal["sphere", "flat"] = "sphere", tip_diameter_mm: float,
          x_mm: float = 0.0, y_mm: float = 0.0, force_n: float | None = None, depth_mm: float | None = None,
          tolerance: float = 1e-5, max_iterations: int = 300) -> BoardPress:
    """Press a tip on the board's layer with a force or to an approach; give exactly one of them.

    Args:
        skin: the board's magnetic skin (its pad grid and layer).
        tip, tip_diameter_mm: "sphere" or "flat" (flat-ended cylinder), and its diameter, mm.
        x_mm, y_mm: the tip's axis in the pad frame, mm.
        force_n: total force, N (> 0).
        depth_mm: approach past first touch, mm (> 0); met to 0.1 %.
        tolerance, max_iterations: of each contact solve.

    Raises:
        ValueError: neither or both of force and depth, a bad value, or a tip off the pad.
        SimulationError: a contact solve, or the depth search, did not converge.
    """
    if (force_n is None) == (depth_mm is None):
        raise ValueError("give exactly one of force_n (force control) and depth_mm (depth control)")
    gap = tip_gap_mm(skin, tip=tip, tip_diameter_mm=tip_diameter_mm, x_mm=x_mm, y_mm=y_mm)

    def solve(force: float, warm: np.ndarray | None = None) -> ContactSolution:
        return solve_contact(gap, force_n=force, modulus_mpa=skin.modulus_kpa * 1e-3,
                             thickness_mm=skin.layer.thickness_mm, pixel_mm=skin.pixel_mm, tolerance=tolerance,
                             max_iterations=max_iterations, initial_pressure_mpa=warm)

    if force_n is not None:
        sol = solve(check_finite_scalar("force_n", force_n, low=0.0, low_open=True))
        iterations = sol.iterations
    else:
        depth = check_finite_scalar("depth_mm", depth_mm, low=0.0, low_open=True)
        sol, iterations = _solve_for_depth(solve, depth, _half_space_force_n(skin, tip, tip_diameter_mm, depth))
    return _result(skin, sol, iterations)


def _half_space_force_n(skin: BoardSkin, tip: str, diameter_mm: float, depth_mm: float) -> float:
    """Force (N) the tip needs for ``depth_mm`` on an incompressible half-space (E* = 4E/3): a first guess,
    low for a thin bonded layer, which is stiffer."""
    e_star = 4.0 / 3.0 * skin.modulus_kpa * 1e-3
    radius = diameter_mm / 2.0
    if tip == "sphere":
        return 4.0 / 3.0 * e_star * math.sqrt(radius) * depth_mm ** 1.5  # Hertz
    return 2.0 * e_star * radius * depth_mm  # Boussinesq flat punch


def _solve_for_depth(solve: Callable[..., ContactSolution], depth_mm: float,
                     force_guess_n: float) -> tuple[ContactSolution, int]:
    """Secant search on ``log F`` against ``log approach`` for the force giving ``depth_mm`` (to 0.1 %)."""
    log_target = math.log(depth_mm)
    sol = solve(force_guess_n)
    points = [(math.log(max(sol.approach_mm, 1e-12)), math.log(force_guess_n))]
    for count in range(1, _DEPTH_ITERATIONS + 1):
        if abs(sol.approach_mm / depth_mm - 1.0) < 1e-3:
            return sol, count
        if len(points) < 2:
            slope = 1.5  # F ~ d^1.5 (sphere) to d (flat): start between, the secant takes over
        else:
            (d0, f0), (d1, f1) = points[-2:]
            slope = (f1 - f0) / (d1 - d0) if d1 != d0 else 1.5
            slope = min(max(slope, 0.5), 5.0)
        d_last, f_last = points[-1]
        force = math.exp(f_last + slope * (log_target - d_last))
        sol = solve(force, sol.pressure_mpa)
        points.append((math.log(max(sol.approach_mm, 1e-12)), math.log(force)))
    raise SimulationError(f"no force gives an approach of {depth_mm:g} mm to 0.1 % after {_DEPTH_ITERATIONS} "
                          f"contact solves (last {sol.approach_mm:.4g} mm); use a smaller depth or a finer pixel_mm")


def _result(skin: BoardSkin, sol: ContactSolution, iterations: int) -> BoardPress:
    p = sol.pressure_mpa
    change_pad = skin.field_change_pad_ut(p)
    total = p.sum()
    return BoardPress(reading_ut=skin.to_chip_axes(change_pad), field_change_pad_ut=change_pad,
                      force_n=sol.force_n, approach_mm=sol.approach_mm,
                      centre_mm=(float((p * skin.x_mm).sum() / total), float((p * skin.y_mm).sum() / total)),
                      contact_area_mm2=sol.contact_area_mm2, peak_kpa=float(p.max() * 1e3), iterations=iterations,
                      bottomed_out=sol.approach_mm >= skin.layer.thickness_mm, pressure_mpa=p)


@dataclass(frozen=True)
class ChipReading:
    """What the board's chips report for one frame.

    Attributes:
        reading_ut: (n_chips, 3) float32 ``raw_ut - baseline_ut``, chip axes, uT.
        raw_ut: (n_chips, 3) float32 ``counts x LSB``, uT.
        counts: (n_chips, 3) int32 register values, LSB.
        saturated: (n_chips, 3) bool, True where a count hit the rail.
    """

    reading_ut: np.ndarray
    raw_ut: np.ndarray
    counts: np.ndarray
    saturated: np.ndarray


def readings_with_chip(change_ut: np.ndarray, board: Board, rng: np.random.Generator, *,
                       baseline_ut: np.ndarray | None = None, noise_scale: float = 1.0) -> ChipReading:
    """The chips' frame for a field change: + baseline, + Gaussian noise, quantised to the LSBs, clipped to the rail.

    Noise, LSB sizes and rail come from ``board.chip``.

    Args:
        change_ut: (n_chips, 3) field change in each chip's axes, uT (e.g. :attr:`BoardPress.reading_ut`).
        board: the board (chip model).
        rng: source of the noise (one standard normal draw of shape (n_chips, 3)).
        baseline_ut: (n_chips, 3) no-contact field in chip axes, uT (e.g. ``BoardSkin.baseline_ut()``), so that
            saturation sees the whole field; None: zero.
        noise_scale: multiplies the chip's noise (0: noise-free, still quantised).
    """
    n = board.n_chips
    change = check_array("change_ut", change_ut, shape=(n, 3))
    base = np.zeros((n, 3)) if baseline_ut is None else check_array("baseline_ut", baseline_ut, shape=(n, 3))
    scale = check_finite_scalar("noise_scale", noise_scale, low=0.0)
    spec = board.chip
    lsb = np.array([spec.lsb_xy_ut, spec.lsb_xy_ut, spec.lsb_z_ut])
    noise = np.array([spec.noise_xy_ut, spec.noise_xy_ut, spec.noise_z_ut]) * scale
    value = base + change + rng.standard_normal((n, 3)) * noise
    rail = spec.saturation_counts
    counts = np.clip(np.rint(value / lsb), -rail, rail).astype(np.int32)
    raw = counts * lsb
    return ChipReading(reading_ut=(raw - base).astype(np.float32), raw_ut=raw.astype(np.float32), counts=counts,
                       saturated=np.abs(counts) >= rail)
