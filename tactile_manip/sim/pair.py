"""The co-located sensor pair: one press of a rigid object gives a magnetic reading and a depth image.

As in SuperMag's symmetric calibration rig, the same object is squeezed between the magnetic sensor
(MBTS) and the vision-based sensor (VBTS), which share a contact module (the board's layer; 20x20x2.5 mm on
the SuperMag board) but not its modulus. The magnetic sensor is any simulatable board
(:class:`~tactile_manip.boards.Board`, default ``supermag-4x4``): its chips, layer and magnetic body come from
its board file, its readings have its grid's shape (``board.shape``, pad axes, 0 at cells no chip feeds). A
press is quasi-static and force controlled:

1. the object's gap to each pad from its protrusion heightmap and pose;
2. a Polonsky-Keer contact solve per sensor (gel modulus for the VBTS, skin modulus for the MBTS);
3. VBTS: the DTact pipeline on the rigid imprint ``clip(delta - s, 0)`` (200x200, 0.1 mm/px);
4. MBTS: the deformed-dipole field change, plus baseline, Earth field, drift, noise, quantisation.

A square magnetised layer (the SuperMag pad) takes the dipole-cell skin of :mod:`tactile_manip.sim.mbts`; any
other body (a rectangular layer, discrete magnets) the board skin of :mod:`tactile_manip.sim.board_skin`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tactile_manip.boards import DEFAULT_BOARD, Board, load_board
from tactile_manip.checks import check_finite_scalar
from tactile_manip.errors import SimulationError
from tactile_manip.sim.board_skin import BoardSkin
from tactile_manip.sim.chip import ChipArray
from tactile_manip.sim.contact import ContactSolution, solve_contact
from tactile_manip.sim.mbts import MagneticSkin, is_square_layer
from tactile_manip.sim.objects import Indenter, IndenterPose
from tactile_manip.sim.params import SimParams, for_board, nominal_remanence_t
from tactile_manip.sim.vbts import dtact_depth


@dataclass(frozen=True)
class PressureSummary:
    """Summary of the magnetic skin's contact pressure (the VBTS gel sees the same shape, softer)."""

    peak_kpa: float = 0.0
    mean_kpa: float = 0.0
    area_mm2: float = 0.0
    centroid_mm: tuple[float, float] = (0.0, 0.0)       # centre of pressure (pressure-weighted), pad frame
    area_centroid_mm: tuple[float, float] = (0.0, 0.0)  # centroid of the contact patch (unweighted), pad frame
    iterations: int = 0


@dataclass(frozen=True)
class PairedSample:
    """One co-located reading pair. Arrays follow docs/design.md, Conventions; readings have the board's
    reading shape ``(rows, cols, 3)`` (``(4, 4, 3)`` on the SuperMag board), 0 at cells no chip feeds.

    Attributes:
        field_ut: (rows, cols, 3) float32, MBTS reading, baseline-subtracted, microtesla.
        field_raw_ut: (rows, cols, 3) float32, raw reading (counts x LSB), microtesla.
        saturated: (rows, cols, 3) bool, channels at the int16 rail.
        field_change_ut: (rows, cols, 3) float32, noise-free field change caused by the contact, microtesla.
        field_clean_ut: (rows, cols, 3) float32, what ``field_ut`` would read without drift, noise and quantisation
            (the contact's field change in chip axes), microtesla.
        depth_mm: (200, 200) float32 VBTS depth image (DTact pipeline), or None when not rendered.
        imprint_mm: (200, 200) float32 ideal rigid imprint on the VBTS gel, mm.
        contact_mask: (200, 200) bool, where the imprint is positive.
        contact: whether the object touched the pad at all.
        approach_mm: rigid approach into the VBTS gel; skin_approach_mm: into the magnetic skin.
        force_n: press force on each sensor, N.
        pressure: pressure summary on the magnetic skin.
        object_name, pose, params, board: everything used to make the sample.
        t_s: time within a sequence (0 for a single press).
        bottomed_out: the approach into either layer reached its thickness: the object would press on the
            rigid base, where the elastic layer model (and so the whole sample) no longer holds.
            :meth:`check_within_layer` turns it into an error for callers that ask for one press.
    """

    field_ut: np.ndarray
    field_raw_ut: np.ndarray
    saturated: np.ndarray
    field_change_ut: np.ndarray
    field_clean_ut: np.ndarray
    depth_mm: np.ndarray | None
    imprint_mm: np.ndarray
    contact_mask: np.ndarray
    contact: bool
    approach_mm: float
    skin_approach_mm: float
    force_n: float
    pressure: PressureSummary
    object_name: str
    pose: IndenterPose
    params: SimParams = field(repr=False)
    board: Board = field(repr=False)
    t_s: float = 0.0
    bottomed_out: bool = False

    def check_within_layer(self) -> PairedSample:
        """Return the sample, or raise :class:`SimulationError` when it bottomed out (see ``bottomed_out``)."""
        if self.bottomed_out:
            deepest = max(self.approach_mm, self.skin_approach_mm)
            raise SimulationError(
                f"{self.force_n:g} N drives {self.object_name} {deepest:.4g} mm into the "
                f"{self.board.layer.thickness_mm:g} mm layer: past its thickness the object bottoms out on the "
                "rigid base, outside the elastic layer model; use a smaller force (10-11 N is the gripper's)")
        return self


class SensorPair:
    """Simulated MBTS + VBTS pair with one fixed set of parameters and per-sensor chip constants.

    Args:
        params: the simulator's parameters; fields left None take the board's values
            (:func:`~tactile_manip.sim.params.for_board`; default :class:`~tactile_manip.sim.params.SimParams`).
        board: the magnetic sensor's board (default ``supermag-4x4``); it must describe its body and layer.
        seed: draws the per-sensor constants (Earth field direction, chip misalignment).

    Attributes:
        board: the board; params: the parameters, the board's values filled in.
        baseline_field_ut: (n_chips, 3) the magnet's field at the chips, pad axes, uT (firmware order).
        baseline_ut: (n_chips, 3) the chips' noise-free idle reading, uT.

    Raises:
        ConfigError: a board that cannot be simulated (``generic:N``, no ``[body]`` / ``[layer]``).
    """

    def __init__(self, params: SimParams | None = None, *, board: Board | None = None, seed: int = 0) -> None:
        self.board = board if board is not None else load_board(DEFAULT_BOARD)
        self.params = for_board(self.board, params)
        p, layer = self.params, self.board.layer
        self.chips = ChipArray.create(p.chip, np.random.default_rng(seed), n_chips=self.board.n_chips)
        side = max(layer.size_mm)
        n = max(2, int(round(side / p.contact.pixel_mm)))
        self._contact_xy = _grid(n, side / n)
        self.skin = _skin(self.board, p)
        self.baseline_field_ut = self.skin.rest_field_ut()
        self.baseline_ut = self.chips.expected_ut(self.baseline_field_ut)
        x, y, _ = self._contact_xy  # a rectangular layer: no contact on the square grid beyond it
        self._on_pad = None if layer.size_mm[0] == layer.size_mm[1] else (
            (np.abs(x) < layer.size_mm[0] / 2) & (np.abs(y) < layer.size_mm[1] / 2))
        self._image_xy = _grid(p.vbts.image_px, p.vbts.pixel_mm)

    @property
    def thickness_mm(self) -> float:
        """The board's layer thickness, mm."""
        return self.board.layer.thickness_mm

    def to_reading(self, chips: np.ndarray) -> np.ndarray:
        """(n_chips, ...) values in firmware order -> the board's reading grid (rows, cols, ...), 0 at unused cells
        (a reshape on the SuperMag board)."""
        return self.board.cells_from_pad(chips)

    @property
    def baseline_reading_ut(self) -> np.ndarray:
        """(rows, cols, 3) float64 noise-free idle reading, uT: :attr:`baseline_ut` on the reading grid."""
        return self.to_reading(self.baseline_ut)

    def press(self, indenter: Indenter, pose: IndenterPose, force_n: float, rng: np.random.Generator, *,
              render_depth: bool = True) -> PairedSample:
        """Press ``indenter`` at ``pose`` with ``force_n`` on both pads and read both sensors.

        An object entirely off the pad gives a valid sample with ``contact=False``, zero depth and a
        reading of noise and drift only. A force that pushes the object through the layer's thickness gives a
        sample with ``bottomed_out=True`` (call ``check_within_layer()`` to refuse it). ``render_depth=False``
        skips the VBTS pipeline (``depth_mm`` is None) for jobs that need no ground truth.

        Raises:
            ValueError: ``force_n`` not finite and > 0.
            SimulationError: a contact solve did not converge.
        """
        force = check_finite_scalar("force_n", force_n, low=0.0, low_open=True)
        return self._sample(indenter, pose, force, rng, self.chips.draw_drift(rng), render_depth, 0.0)

    def expected_reading_ut(self, indenter: Indenter, pose: IndenterPose, force_n: float) -> np.ndarray:
        """The magnetic reading of a press as a dataset records it, without drift, noise or quantisation.

        Returns:
            (rows, cols, 3) float64 uT: the chips' expected values less this sensor's own unloaded reading, what
            :meth:`press` returns as ``field_clean_ut``. Only the skin's contact is solved (no gel, no image), so
            it costs about a third of a press: for derivatives and fits of the physics. An object off the pad
            gives 0.

        Raises:
            ValueError: ``force_n`` not finite and > 0.
            SimulationError: the contact solve did not converge.
        """
        force = check_finite_scalar("force_n", force_n, low=0.0, low_open=True)
        x, y, _ = self._contact_xy
        protrusion = self._on_layer(indenter.protrusion_mm(x, y, pose))
        change_ut = np.zeros((self.board.n_chips, 3))
        if np.isfinite(protrusion).any():  # a force-controlled solve: the gaps' datum does not matter
            skin = self._solve(np.nanmax(protrusion) - protrusion, force, self.params.layer.skin_modulus_kpa)
            change_ut = self.skin.contact_change_ut(skin.pressure_mpa, skin.pixel_mm)
        return self.to_reading(self.chips.expected_ut(self.baseline_field_ut + change_ut) - self.baseline_ut)

    def ramp(self, indenter: Indenter, pose: IndenterPose, forces_n: np.ndarray, rng: np.random.Generator, *,
             render_depth: bool = False) -> list[PairedSample]:
        """A press as a sequence at the chip rate (125 Hz): one sample per entry of ``forces_n``.

        Entries <= 0 are frames without contact. One drift draw holds for the whole press.
        """
        forces = np.asarray(forces_n, dtype=np.float64)
        if forces.ndim != 1 or not np.isfinite(forces).all():
            raise ValueError(f"forces_n must be a finite 1-D array, got shape {forces.shape}")
        drift = self.chips.draw_drift(rng)
        period = 1.0 / self.params.chip.rate_hz
        return [self._sample(indenter, pose, float(f), rng, drift, render_depth, i * period)
                for i, f in enumerate(forces)]

    @staticmethod
    def ramp_profile(peak_force_n: float, *, rise_s: float = 0.4, hold_s: float = 0.2, rate_hz: float = 125.0
                     ) -> np.ndarray:
        """Force profile (N) of a press: linear rise to ``peak_force_n``, hold, linear release."""
        peak = check_finite_scalar("peak_force_n", peak_force_n, low=0.0, low_open=True)
        rise = np.linspace(0.0, peak, max(2, int(round(rise_s * rate_hz))) + 1)[1:]
        hold = np.full(int(round(hold_s * rate_hz)), peak)
        return np.concatenate([rise, hold, rise[::-1][1:], [0.0]])

    def _sample(self, indenter: Indenter, pose: IndenterPose, force: float, rng: np.random.Generator,
                drift_ut: np.ndarray, render_depth: bool, t_s: float) -> PairedSample:
        p = self.params
        gap_c, gap_i = self._gaps(indenter, pose)
        touching = force > 0 and np.isfinite(gap_c).any() and np.isfinite(gap_i).any()
        change_ut = np.zeros((self.board.n_chips, 3))
        imprint = np.zeros(gap_i.shape)
        delta_v = delta_m = 0.0
        summary = PressureSummary()
        if touching:
            skin = self._solve(gap_c, force, p.layer.skin_modulus_kpa)
            gel = self._solve(gap_c, force, p.layer.vbts_modulus_kpa, warm=skin.pressure_mpa)
            delta_m, delta_v = skin.approach_mm, gel.approach_mm
            change_ut = self.skin.contact_change_ut(skin.pressure_mpa, skin.pixel_mm)
            imprint = np.clip(delta_v - np.nan_to_num(gap_i, nan=np.inf), 0.0, None)
            summary = self._summary(skin)
        m = self.chips.measure(self.baseline_field_ut + change_ut, rng, drift_ut=drift_ut)
        clean = self.chips.expected_ut(self.baseline_field_ut + change_ut) - self.baseline_ut
        depth = None
        if render_depth:
            depth = dtact_depth(imprint, p.vbts, rng) if imprint.any() else np.zeros(imprint.shape, np.float32)
        grid = self.to_reading
        return PairedSample(
            field_ut=grid((m.raw_ut - self.baseline_ut).astype(np.float32)), field_raw_ut=grid(m.raw_ut),
            saturated=grid(m.saturated), field_change_ut=grid(change_ut.astype(np.float32)),
            field_clean_ut=grid(clean.astype(np.float32)), depth_mm=depth,
            imprint_mm=imprint.astype(np.float32), contact_mask=imprint > 0, contact=bool(imprint.any()),
            approach_mm=delta_v, skin_approach_mm=delta_m, force_n=force if touching else 0.0,
            pressure=summary, object_name=indenter.name, pose=pose, params=p, board=self.board, t_s=t_s,
            bottomed_out=max(delta_v, delta_m) >= self.thickness_mm)

    def _gaps(self, indenter: Indenter, pose: IndenterPose) -> tuple[np.ndarray, np.ndarray]:
        """Initial gaps (mm, NaN off the object) on the contact grid and the image grid, same datum."""
        prot_c = self._on_layer(indenter.protrusion_mm(self._contact_xy[0], self._contact_xy[1], pose))
        prot_i = indenter.protrusion_mm(self._image_xy[0], self._image_xy[1], pose)
        if not (np.isfinite(prot_c).any() and np.isfinite(prot_i).any()):
            return np.full(prot_c.shape, np.nan), np.full(prot_i.shape, np.nan)
        top = max(np.nanmax(prot_c), np.nanmax(prot_i))
        return top - prot_c, top - prot_i

    def _on_layer(self, protrusion_mm: np.ndarray) -> np.ndarray:
        """The protrusion on the contact grid, NaN beyond a rectangular layer's edges."""
        return protrusion_mm if self._on_pad is None else np.where(self._on_pad, protrusion_mm, np.nan)

    def _solve(self, gap_mm: np.ndarray, force_n: float, modulus_kpa: float,
               warm: np.ndarray | None = None) -> ContactSolution:
        c = self.params.contact
        return solve_contact(gap_mm, force_n=force_n, modulus_mpa=modulus_kpa * 1e-3,
                             thickness_mm=self.thickness_mm, pixel_mm=self._contact_xy[2],
                             tolerance=c.tolerance, max_iterations=c.max_iterations, initial_pressure_mpa=warm)

    def _summary(self, sol: ContactSolution) -> PressureSummary:
        p = sol.pressure_mpa
        x, y, _ = self._contact_xy
        total, patch = p.sum(), p > 0
        return PressureSummary(peak_kpa=float(p.max() * 1e3), mean_kpa=float(p[patch].mean() * 1e3),
                               area_mm2=sol.contact_area_mm2,
                               centroid_mm=(float((p * x).sum() / total), float((p * y).sum() / total)),
                               area_centroid_mm=(float(x[patch].mean()), float(y[patch].mean())),
                               iterations=sol.iterations)


def _skin(board: Board, p: SimParams) -> MagneticSkin | BoardSkin:
    """The skin model of ``board`` at parameters ``p`` (the board's values filled in): the dipole-cell skin of a
    square magnetised layer, else the board skin on the pair's contact grid."""
    if is_square_layer(board):
        return MagneticSkin(board, p.layer, p.magnet)
    return BoardSkin(board, modulus_kpa=p.layer.skin_modulus_kpa, pixel_mm=p.contact.pixel_mm,
                     remanence_scale=p.magnet.remanence_t / nominal_remanence_t(board), cell_mm=p.magnet.cell_mm,
                     thickness_nodes=p.magnet.thickness_nodes, gap_mm=p.magnet.chip_gap_mm)


def _grid(n: int, pixel_mm: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Pixel-centre coordinates (x, y) of an (n, n) image grid centred on the pad, and its spacing."""
    c = (np.arange(n) - (n - 1) / 2.0) * pixel_mm
    x, y = np.meshgrid(c, -c)  # row 0 at +y, column 0 at -x
    return x, y, pixel_mm
