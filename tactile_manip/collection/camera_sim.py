"""The simulated VBTS camera: DTact grey images rendered from the simulator's contact, at ~30 Hz.

Each frame is what the DTact camera would see: a fixed no-contact image (LED illumination falling off
towards the edges, a fixed pixel pattern, the dark housing around the pad) darkened where the gel is
pressed by ``grey_from_depth(indentation, table)`` (the inverse of a measured DTact lookup table, as the
simulator's VBTS model uses), plus read noise, rounded to uint8.

The indentation comes from the paired-sensor simulator: a press is solved once per force level for the gel's
rigid approach, and the imprint ``clip(protrusion - level, 0)`` is evaluated at the camera's own pixels
(through the pad homography and the rig's mirror), so calibration and the depth pipeline are checked against
the simulator's ground truth at the camera's resolution. Timing faults are configurable: exposure jitter, a
fixed latency, dropped frames, and :meth:`SimulatedCamera.stall` for a camera that stops.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar, Literal

import numpy as np

from tactile_manip.checks import check_finite_scalar
from tactile_manip.collection.camera import Camera
from tactile_manip.sensors.simulated.contacts import Press
from tactile_manip.collection.vbts import MIRRORS, PadAlignment, apply_homography
from tactile_manip.sim.objects import Indenter, IndenterPose
from tactile_manip.sim.pair import SensorPair
from tactile_manip.sim.vbts import grey_from_depth, lookup_table

# Fractions of a press's peak force solved for the gel's approach; the imprint level is interpolated between.
FORCE_LEVELS = (0.05, 0.15, 0.3, 0.5, 0.7, 0.85, 1.0)
REBASE_LATE_S = 0.25  # a frame this late restarts the schedule instead of bursting to catch up
# Where the 21 mm VBTS pad lies in the default 640x480 image (~16 px/mm, slightly rotated and keystoned). The
# camera looks at the gel from behind, so pad +x runs to the left: the corners carry that mirror.
DEFAULT_CORNERS_PX = ((489.0, 72.0), (151.0, 66.0), (146.0, 411.0), (494.0, 413.0))


@dataclass(frozen=True)
class SimulatedCameraConfig:
    """The simulated DTact camera and the rig it sits in."""

    backend: ClassVar[str] = "simulated"
    rate_hz: float = 30.0                       # frame rate, Hz (SuperMag Sec. III-C: 30 Hz)
    image_shape: tuple[int, int] = (480, 640)   # (H, W) px (SuperMag: 640x480 USB camera)
    corners_px: tuple[tuple[float, float], ...] = DEFAULT_CORNERS_PX  # pad corners, see PadAlignment
    pad_mm: float = 21.0                        # side of the VBTS contact module, mm
    mirror: Literal["x", "y", "none"] = "x"     # the rig: VBTS pad frame = MBTS pad frame mirrored so
    lookup_table: Literal["sensor_1", "sensor_2"] = "sensor_1"  # the camera's true grey response
    noise_levels: float = 1.0                   # read noise, grey levels (std)
    jitter_s: float = 0.0                       # std of each exposure about its slot, s (clipped to 0.4 period)
    latency_s: float = 0.0                      # exposure -> host timestamp delay, s
    drop_rate: float = 0.0                      # probability that a frame is lost (its seq is skipped)
    seed: int = 0                               # noise, jitter and drops
    unit: int = 0                               # which camera: seeds its fixed pixel pattern (keep it to reuse
                                                # a calibration across runs with other seeds)
    buffer_frames: int = 8                      # FIFO length, frames

    def __post_init__(self) -> None:
        check_finite_scalar("SimulatedCameraConfig.rate_hz", self.rate_hz, low=0.0, low_open=True)
        for name in ("noise_levels", "jitter_s", "latency_s"):
            check_finite_scalar(f"SimulatedCameraConfig.{name}", getattr(self, name), low=0.0)
        check_finite_scalar("SimulatedCameraConfig.drop_rate", self.drop_rate, low=0.0, high=0.9)
        if self.mirror not in MIRRORS:
            raise ValueError(f"SimulatedCameraConfig.mirror must be one of {list(MIRRORS)}, got {self.mirror!r}")
        if len(self.image_shape) != 2 or min(self.image_shape) < 16:
            raise ValueError(f"SimulatedCameraConfig.image_shape must be (H, W) >= 16 px, got {self.image_shape!r}")

    def alignment(self, **kwargs: object) -> PadAlignment:
        """The true :class:`PadAlignment` of this camera (what a perfect corner measurement gives)."""
        return PadAlignment(corners_px=self.corners_px, camera_shape=self.image_shape, pad_mm=self.pad_mm,
                            mirror=self.mirror, **kwargs)


def ball_indenter(radius_mm: float, *, pixel_mm: float = 0.02) -> Indenter:
    """A rigid ball of ``radius_mm`` (its pad-facing half) as an indenter, reference point at its centre."""
    r = check_finite_scalar("radius_mm", radius_mm, low=0.0, low_open=True)
    n = 2 * int(math.ceil(r / pixel_mm)) + 1
    c = (np.arange(n) - (n - 1) / 2.0) * pixel_mm
    rho2 = c[None, :] ** 2 + c[:, None] ** 2
    height = np.where(rho2 <= r * r, np.sqrt(np.clip(r * r - rho2, 0.0, None)), np.nan)
    return Indenter(height, pixel_mm, name=f"ball_r{r:g}mm")


class _Contact:
    """One solved press at the camera's pixels: flat pixel indices, protrusion there, level per force."""

    def __init__(self, index: np.ndarray, protrusion_mm: np.ndarray, forces_n: np.ndarray, levels_mm: np.ndarray):
        self.index, self.protrusion_mm = index, protrusion_mm
        self.forces_n, self.levels_mm = forces_n, levels_mm

    def indentation_mm(self, force_n: float) -> np.ndarray:
        if force_n <= 0 or self.index.size == 0:
            return np.zeros(self.index.size)
        return np.clip(self.protrusion_mm - np.interp(force_n, self.forces_n, self.levels_mm), 0.0, None)


class SimulatedCamera(Camera):
    """The DTact camera of the simulated rig (see :class:`~tactile_manip.collection.camera.Camera` for the contract).

    Args:
        config: rate, image geometry, true lookup table, noise and timing faults.
        pair: the simulated sensor pair whose gel is pressed (share it with the MBTS side for one physics).
    """

    def __init__(self, config: SimulatedCameraConfig | None = None, *, pair: SensorPair | None = None) -> None:
        self.config = config or SimulatedCameraConfig()
        super().__init__(source="simulated", buffer_frames=self.config.buffer_frames)
        self.pair = pair if pair is not None else SensorPair(seed=self.config.seed)
        self.table = lookup_table(self.config.lookup_table)
        self.alignment = self.config.alignment()
        self.reference_image = self._no_contact_image()
        self._pad_xy, self._pad_index = self._pad_pixels()
        # what presses the gel: None, a static (contact, force) or a script (presses, contacts, start); one
        # attribute, replaced whole, so the frame thread never reads half of a switch between them
        self._scene: tuple[_Contact, float] | tuple[list[Press], list[_Contact], float] | None = None
        self._stalled = False
        self._stall_lock = threading.Lock()
        self._solved: dict[tuple, _Contact] = {}

    # ------------------------------------------------------------------ contacts

    def set_contact(self, indenter: Indenter, pose: IndenterPose, force_n: float) -> None:
        """Press ``indenter`` at ``pose`` (MBTS pad frame) with ``force_n`` from the next frame on (~50 ms solve)."""
        force = check_finite_scalar("force_n", force_n, low=0.0)
        contact = self._solve(indenter, pose, np.array([force])) if force > 0 else None
        self._scene = None if contact is None else (contact, force)

    def clear_contact(self) -> None:
        """Nothing on the pad from the next frame on (stops a script too)."""
        self._scene = None

    def play(self, presses: Sequence[Press], *, start_host_s: float | None = None) -> None:
        """Play a script of presses from ``start_host_s`` (default now); replaces any contact.

        Script time ``t`` is host time ``start_host_s + t``: pass the MBTS emulator's start to share its clock.
        Each distinct press is solved in the caller's thread (~0.3 s) the first time this camera sees it, so
        call ``play`` once ahead (any start) to have the physics done before the streams start.
        """
        ordered = sorted(presses, key=lambda p: p.start_s)
        contacts = []
        for p in ordered:
            key = (p.obj, tuple(sorted(p.object_kwargs.items())), p.pose, p.peak_force_n)
            if key not in self._solved:
                self._solved[key] = self._solve(p.indenter(), p.pose, np.array(FORCE_LEVELS) * p.peak_force_n)
            contacts.append(self._solved[key])
        self._scene = (ordered, contacts, time.monotonic() if start_host_s is None else float(start_host_s))

    def indentation_at(self, t_host_s: float) -> np.ndarray:
        """True indentation (H, W) float32 mm at the camera's pixels at host time ``t_host_s`` (ground truth)."""
        out = np.zeros(self.config.image_shape[0] * self.config.image_shape[1], np.float32)
        contact, force = self._contact_at(t_host_s)
        if contact is not None:
            out[contact.index] = contact.indentation_mm(force)
        return out.reshape(self.config.image_shape)

    def render(self, t_host_s: float, rng: np.random.Generator | None = None) -> np.ndarray:
        """The (H, W) uint8 frame exposed at ``t_host_s``; ``rng=None`` renders without noise."""
        img = self.reference_image.ravel().copy()
        contact, force = self._contact_at(t_host_s)
        if contact is not None:
            img[contact.index] -= grey_from_depth(contact.indentation_mm(force), self.table).astype(np.float32)
        if rng is not None and self.config.noise_levels > 0:
            img += rng.standard_normal(img.size, dtype=np.float32) * np.float32(self.config.noise_levels)
        return np.clip(np.rint(img), 0, 255).astype(np.uint8).reshape(self.config.image_shape)

    def stall(self) -> None:
        """Stop delivering frames (a camera that hangs) until :meth:`resume`; no frame is published after this
        returns (one being rendered is dropped)."""
        with self._stall_lock:
            self._stalled = True

    def resume(self) -> None:
        self._stalled = False

    # ------------------------------------------------------------------ Camera hooks

    def _open(self) -> None:
        self._thread = threading.Thread(target=self._run, daemon=True, name="camera-simulated")
        self._thread.start()

    def _stale_hint(self) -> str:
        return "the simulated camera is stalled: call resume()" if self._stalled else \
            "the simulated camera's thread is not keeping up (is the machine overloaded?)"

    def _run(self) -> None:
        cfg = self.config
        rng = np.random.default_rng([cfg.seed, 7])
        period = 1.0 / cfg.rate_hz
        t0, k = time.monotonic(), 0
        while not self._stop.is_set():
            jitter = float(np.clip(rng.normal(0.0, cfg.jitter_s), -0.4 * period, 0.4 * period)) if cfg.jitter_s else 0.0
            dropped = cfg.drop_rate > 0 and rng.random() < cfg.drop_rate
            exposure = t0 + (k + 1) * period + jitter
            t_host = exposure + cfg.latency_s
            wait = t_host - time.monotonic()
            if wait > 0 and self._stop.wait(wait):
                break
            try:
                if wait < -REBASE_LATE_S:
                    t0 = time.monotonic() - (k + 1) * period
                if not dropped and not self._stalled:
                    frame = self.render(exposure, rng)
                    with self._stall_lock:  # a stall() during the render stops this frame too
                        if not self._stalled:
                            self._publish(frame, seq=k, t_host_s=t_host, t_exposure_s=exposure)
            except Exception as e:  # noqa: BLE001 - the thread must survive anything and report it
                self._last_error = f"{type(e).__name__} in the frame thread: {e}"
            k += 1

    # ------------------------------------------------------------------ physics and optics

    def _contact_at(self, t_host_s: float) -> tuple[_Contact | None, float]:
        scene = self._scene
        if scene is None:
            return None, 0.0
        if len(scene) == 2:
            return scene
        presses, contacts, start = scene
        t = t_host_s - start
        for p, c in zip(presses, contacts):
            if p.start_s < t < p.end_s:
                return c, p.force_at(t)
        return None, 0.0

    def _solve(self, indenter: Indenter, pose: IndenterPose, forces_n: np.ndarray) -> _Contact:
        """Gel approach at each force (the simulator's contact solve) -> imprint level on the common datum."""
        vbts = self.pair.params.vbts
        side = vbts.image_px * vbts.pixel_mm
        c = (np.arange(vbts.image_px) - (vbts.image_px - 1) / 2.0) * (side / vbts.image_px)
        gx, gy = np.meshgrid(c, -c)
        prot_grid = indenter.protrusion_mm(gx, gy, pose)
        rng = np.random.default_rng(0)  # the press's chip noise is not used
        levels = []
        for f in forces_n:
            sample = self.pair.press(indenter, pose, float(f), rng, render_depth=False).check_within_layer()
            imprint = sample.imprint_mm
            touch = imprint > 0
            # imprint = prot - level wherever it is positive: recover the level on the simulator's own datum
            levels.append(float(np.median(prot_grid[touch] - imprint[touch])) if touch.any() else np.inf)
        prot = indenter.protrusion_mm(*self._pad_xy, pose)
        deepest = min(levels)
        keep = np.isfinite(prot) & (prot > deepest)
        top = float(np.nanmax(prot_grid)) if np.isfinite(prot_grid).any() else np.inf
        levels_mm = np.array([top] + [min(lv, top) for lv in levels])
        forces = np.concatenate([[0.0], forces_n])
        return _Contact(self._pad_index[keep], prot[keep], forces, levels_mm)

    def _pad_pixels(self) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
        """MBTS-frame pad coordinates (x, y) of the camera pixels that see the pad, and their flat indices."""
        h, w = self.config.image_shape
        v, u = np.mgrid[0:h, 0:w].astype(np.float64)
        x, y = apply_homography(np.linalg.inv(self.alignment.homography), u, v)
        half = self.config.pad_mm / 2.0
        inside = (np.abs(x) <= half) & (np.abs(y) <= half)
        x, y = x[inside], y[inside]
        if self.config.mirror == "x":
            x = -x
        elif self.config.mirror == "y":
            y = -y
        return (x, y), np.flatnonzero(inside.ravel())

    def _no_contact_image(self) -> np.ndarray:
        """LED illumination over the pad (brighter in the middle), a fixed pixel pattern, a dark housing."""
        h, w = self.config.image_shape
        v, u = np.mgrid[0:h, 0:w].astype(np.float64)
        x, y = apply_homography(np.linalg.inv(self.alignment.homography), u, v)
        half = self.config.pad_mm / 2.0
        r2 = (x * x + y * y) / (2 * half * half)
        pattern = np.random.default_rng([self.config.unit, 3]).normal(0.0, 1.5, (h, w))
        pad = 175.0 - 45.0 * r2 + pattern
        housing = 35.0 + 0.3 * pattern
        inside = (np.abs(x) <= half) & (np.abs(y) <= half)
        img = np.where(inside, pad, housing).astype(np.float32)
        img.setflags(write=False)
        return img

