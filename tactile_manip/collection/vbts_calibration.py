"""Calibration of the VBTS depth pipeline from a ball press of known radius, and its file.

A rigid ball of radius R pressed a depth d0 into the gel leaves a spherical cap: at distance rho from the
contact centre the indentation is ``sqrt(R^2 - rho^2) - c`` with ``c = R - d0``, for rho below the contact
radius ``a = sqrt(R^2 - c^2)``. From the averaged grey difference of the press:

1. the contact is the largest connected region clearly above the noise; it must lie inside the crop;
2. its centre is the difference-weighted centroid (the cap is symmetric);
3. the contact radius ``a`` is where the ring-averaged grey difference falls to half a grey level (about
   0.01 mm of depth), so ``c = sqrt(R^2 - a^2)``; or ``c = R - press_depth_mm`` when the press depth is
   known (e.g. from the robot). An error in ``a`` moves the press depth by ``a / c`` times as much, so keep
   the press shallower than about half the radius (a / c < 2);
4. every contact pixel then has a known depth; the table at grey level k is the median depth of the pixels
   whose difference rounds to k, made non-decreasing (weighted isotonic regression: fitting needs
   scikit-learn, the ``calibration`` extra), 0 at level 0, and flat past the deepest level seen (a plateau of
   the camera's response is detected and cut).

Press deep enough to cover the depths you will measure (1.2-1.8 mm; the table saturates beyond the press).
:class:`VbtsCalibration` holds the alignment, the processing parameters, the table and the reference, and
is saved as ``.npz`` (read back with ``allow_pickle=False``).
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage

from tactile_manip.checks import check_finite_scalar, npz_read_problem
from tactile_manip.errors import CalibrationError
from tactile_manip.extras import require
from tactile_manip.collection.vbts import DepthParams, DepthPipeline, PadAlignment, Reference, to_grey
from tactile_manip.version import code_version

FORMAT_VERSION = 1
MIN_PRESS_DEPTH_MM = 0.3
EDGE_LEVEL = 0.5        # the contact edge: where the azimuthal mean of the grey difference falls below this
RADIAL_BIN_MM = 0.02    # width of the rings of that azimuthal mean, mm


@dataclass(frozen=True)
class BallFit:
    """The spherical cap found in a ball press (crop coordinates: VBTS pad frame about the crop centre)."""

    radius_mm: float            # the ball's radius, as given
    centre_mm: tuple[float, float]
    press_depth_mm: float       # d0 = R - c
    contact_radius_mm: float    # a
    edge_level: float           # grey difference that marked the contact edge (nan: press_depth_mm given)
    contact_pixels: int


def _crop_xy(n: int, pixel_mm: float) -> tuple[np.ndarray, np.ndarray]:
    c = (np.arange(n) - (n - 1) / 2.0) * pixel_mm
    return np.meshgrid(c, -c)


def _noise(diff: np.ndarray) -> float:
    """Robust noise of a (mostly contact-free) difference image, grey levels."""
    return float(1.4826 * np.median(np.abs(diff - np.median(diff))))


def fit_ball(diff: np.ndarray, radius_mm: float, *, pixel_mm: float, press_depth_mm: float | None = None
             ) -> BallFit:
    """Locate the spherical cap of a ball press in a rectified grey difference (levels, VBTS pad frame).

    Raises:
        ValueError: ``radius_mm`` or ``press_depth_mm`` not a finite positive number.
        CalibrationError: no contact, a contact cut by the crop, a contact wider than the ball (wrong radius,
            a diameter given as radius, or wrong pad corners), or a press too shallow to calibrate.
    """
    radius = check_finite_scalar("radius_mm", radius_mm, low=0.0, low_open=True)
    d = np.asarray(diff, np.float64)
    if d.ndim != 2:
        raise ValueError(f"diff: expected a 2-D image, got shape {d.shape}")
    noise = max(_noise(d), 0.1)
    threshold = max(2.0, 5.0 * noise)
    if d.max() < threshold + 6.0:
        raise CalibrationError(f"no ball contact in the press frames (largest grey difference {d.max():.1f} levels, "
                               f"noise {noise:.2f}): press the ball into the pad; if it was on the pad, the reference "
                               "was taken with it there: take the reference with the pad clear")
    labels, count = ndimage.label(d > threshold)
    sizes = np.bincount(labels.ravel())[1:]
    mask = labels == (1 + int(np.argmax(sizes)))
    if mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any():
        raise CalibrationError("the ball's contact is cut by the edge of the pad crop: press nearer the pad centre, "
                               f"or use a smaller ball (radius {radius:g} mm)")
    x, y = _crop_xy(d.shape[0], pixel_mm)
    w = np.where(mask, d, 0.0)
    cx, cy = float((w * x).sum() / w.sum()), float((w * y).sum() / w.sum())
    rho2 = (x - cx) ** 2 + (y - cy) ** 2
    extent = math.sqrt(float(rho2[mask].max()))
    if extent >= radius:
        raise CalibrationError(f"the contact reaches {extent:.2f} mm from its centre, wider than a ball of radius "
                               f"{radius:g} mm can make: check radius_mm (a radius, not a diameter) and the pad "
                               "corners / pad_mm of the alignment")
    edge = math.nan
    if press_depth_mm is None:
        a_edge, edge = _edge_radius(d, np.sqrt(rho2), mask, noise)
        if a_edge >= radius:
            raise CalibrationError(f"the contact's edge lies {a_edge:.2f} mm from its centre, wider than a ball of "
                                   f"radius {radius:g} mm can make: check radius_mm (a radius, not a diameter)")
        c = math.sqrt(radius * radius - a_edge * a_edge)
    else:
        c = radius - check_finite_scalar("press_depth_mm", press_depth_mm, low=0.0, low_open=True)
    if not 0 < c < radius:
        raise CalibrationError(f"the fitted press depth {radius - c:.2f} mm is not between 0 and the ball radius "
                               f"{radius:g} mm: check radius_mm")
    depth0 = radius - c
    if depth0 < MIN_PRESS_DEPTH_MM:
        raise CalibrationError(f"the ball press is only {depth0:.2f} mm deep: the table would cover 0-{depth0:.2f} mm; "
                               "press harder (aim for 1.2-1.8 mm)")
    a = math.sqrt(radius * radius - c * c)
    half = d.shape[0] * pixel_mm / 2.0
    if max(abs(cx), abs(cy)) + a > half:
        raise CalibrationError(f"the ball's contact circle (radius {a:.2f} mm at ({cx:.2f}, {cy:.2f}) mm) leaves the "
                               f"{2 * half:g} mm crop: press nearer the centre or use a smaller ball")
    return BallFit(radius, (cx, cy), depth0, a, edge, int(mask.sum()))


def _edge_radius(diff: np.ndarray, rho_mm: np.ndarray, mask: np.ndarray, noise: float) -> tuple[float, float]:
    """Contact radius (mm) where the ring-averaged difference falls to ``EDGE_LEVEL`` (or 4x its noise).

    Averaging rings of ``RADIAL_BIN_MM`` leaves ~0.05 levels of noise, so the edge is found at a depth of
    about 0.01 mm: the contact radius to ~0.01 mm, which a straight-line fit of the edge (biased by the
    table's curvature near zero, ~0.05 mm of press depth) cannot give.
    """
    n = int(math.ceil(float(rho_mm[mask].max()) / RADIAL_BIN_MM)) + 10
    ring = np.minimum((rho_mm.ravel() / RADIAL_BIN_MM).astype(np.int64), n)
    count = np.bincount(ring, minlength=n + 1)[:n]
    mean = np.bincount(ring, diff.ravel(), minlength=n + 1)[:n] / np.maximum(count, 1)
    level = max(EDGE_LEVEL, 4.0 * noise / math.sqrt(max(1.0, float(np.median(count[count > 0])))))
    above = np.flatnonzero((mean > level) & (count > 0))
    j = int(above.max())
    if j + 1 >= n:
        raise CalibrationError("the ball's contact has no clear edge inside the crop: press nearer the pad centre")
    centre = (j + 0.5) * RADIAL_BIN_MM
    return centre + (mean[j] - level) / (mean[j] - mean[j + 1]) * RADIAL_BIN_MM, level


def cap_depth_mm(shape: tuple[int, int], fit: BallFit, pixel_mm: float) -> np.ndarray:
    """Indentation (mm) of the fitted cap at every crop pixel (0 outside the contact)."""
    x, y = _crop_xy(shape[0], pixel_mm)
    rho2 = (x - fit.centre_mm[0]) ** 2 + (y - fit.centre_mm[1]) ** 2
    r2 = fit.radius_mm ** 2
    c = fit.radius_mm - fit.press_depth_mm
    return np.clip(np.sqrt(np.clip(r2 - rho2, 0.0, None)) - c, 0.0, None)


def _isotonic(y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted least-squares non-decreasing fit of ``y`` in its order (scikit-learn's IsotonicRegression)."""
    isotonic = require("sklearn.isotonic", "fitting a calibration")
    y = np.asarray(y, np.float64)
    return isotonic.IsotonicRegression().fit_transform(np.arange(y.size, dtype=np.float64), y,
                                                       sample_weight=np.asarray(w, np.float64))


def table_from_samples(diff_levels: np.ndarray, depth_mm: np.ndarray, *, min_count: int = 5
                       ) -> tuple[np.ndarray, np.ndarray, bool]:
    """Lookup table (levels 0..K, depth mm) from grey differences and known depths of the same pixels.

    Returns the levels, the non-decreasing depths (0 at level 0) and whether the camera's response saturated
    (a plateau at the deepest level, whose entry is then its shallowest pixels' depth).
    """
    k = np.rint(np.asarray(diff_levels, np.float64)).astype(np.int64)
    dep = np.asarray(depth_mm, np.float64)
    keep = k >= 1
    k, dep = k[keep], dep[keep]
    order = np.argsort(k, kind="stable")
    k, dep = k[order], dep[order]
    levels, starts, counts = np.unique(k, return_index=True, return_counts=True)
    good = counts >= min_count
    if good.sum() < 3:
        raise CalibrationError(f"only {int(good.sum())} grey levels have {min_count}+ contact pixels: press deeper "
                               "or average more frames")
    groups = [dep[s:s + n] for s, n, g in zip(starts, counts, good) if g]
    levels = levels[good]
    spreads = np.array([np.percentile(g, 90) - np.percentile(g, 10) for g in groups])
    saturated = bool(spreads[-1] > max(0.1, 4.0 * np.median(spreads[:-1])))
    if saturated:
        # The deepest level is a plateau: it starts at its shallowest pixels, and plateau pixels that noise
        # pushed into the levels below must not pull those up.
        onset = float(np.percentile(groups[-1], 2))
        groups = [g[g <= onset] if g[g <= onset].size >= min_count else g for g in groups[:-1]] + [np.array([onset])]
    medians = np.array([np.median(g) for g in groups])
    fitted = _isotonic(medians, np.array([g.size for g in groups], np.float64))
    full = np.arange(int(levels[-1]) + 1, dtype=np.float64)
    table = np.interp(full, np.concatenate([[0.0], levels]), np.concatenate([[0.0], fitted]))
    return full, np.maximum.accumulate(table), saturated


@dataclass(eq=False)
class VbtsCalibration:
    """Everything the depth pipeline needs for one VBTS: alignment, processing, lookup table and reference."""

    alignment: PadAlignment
    params: DepthParams
    table_levels: np.ndarray
    table_mm: np.ndarray
    reference: Reference
    report: dict[str, Any] = field(default_factory=dict)

    def pipeline(self) -> DepthPipeline:
        """A depth pipeline with this calibration (and its reference, until a fresh one is set)."""
        return DepthPipeline(self.alignment, self.table_levels, self.table_mm, params=self.params,
                             reference=self.reference)

    def save(self, path: str | Path) -> Path:
        """Write an ``.npz`` (atomically: a temp file, then rename)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = {"format": "tactile_manip.vbts_calibration", "format_version": FORMAT_VERSION,
                "alignment": dataclasses.asdict(self.alignment), "params": dataclasses.asdict(self.params),
                "reference_frames": self.reference.frames, "reference_noise_levels": self.reference.noise_levels,
                "report": self.report, "code_version": code_version(),
                "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        tmp = path.with_name(path.name + ".partial")
        with tmp.open("wb") as f:
            np.savez_compressed(f, table_levels=self.table_levels, table_mm=self.table_mm,
                                reference_grey=self.reference.grey.astype(np.float32),
                                metadata=np.array(json.dumps(meta)))
        tmp.replace(path)
        return path

    @classmethod
    def load(cls, path: str | Path) -> VbtsCalibration:
        """Read a file written by :meth:`save` (``tactile-manip collect calibrate``).

        Raises:
            CalibrationError: missing, not a calibration file, or a newer format.
        """
        path = Path(path)
        if not path.is_file():
            raise CalibrationError(f"VBTS calibration not found: {path} "
                                   "(make one with `tactile-manip collect calibrate`)")
        try:
            with np.load(path, allow_pickle=False) as z:
                arrays = {k: z[k] for k in ("table_levels", "table_mm", "reference_grey", "metadata")}
            meta = json.loads(str(arrays["metadata"]))
        except (KeyError, ValueError, OSError) as e:
            raise CalibrationError(f"{path} is not a VBTS calibration file: {npz_read_problem(e)}") from e
        if meta.get("format") != "tactile_manip.vbts_calibration" or meta.get("format_version", 0) > FORMAT_VERSION:
            raise CalibrationError(f"{path}: not a VBTS calibration of format <= {FORMAT_VERSION}")
        al = meta["alignment"]
        alignment = PadAlignment(**{**al, "corners_px": tuple(map(tuple, al["corners_px"])),
                                    "camera_shape": tuple(al["camera_shape"]), "centre_mm": tuple(al["centre_mm"])})
        reference = Reference(grey=arrays["reference_grey"], frames=int(meta["reference_frames"]),
                              noise_levels=float(meta["reference_noise_levels"]))
        return cls(alignment, DepthParams(**meta["params"]), arrays["table_levels"], arrays["table_mm"], reference,
                   meta.get("report", {}))


def calibrate_ball(alignment: PadAlignment, reference_images: list[np.ndarray], press_images: list[list[np.ndarray]],
                   radius_mm: float, *, params: DepthParams | None = None,
                   press_depths_mm: list[float | None] | None = None) -> VbtsCalibration:
    """Calibrate from no-contact frames and one or more ball presses (each a list of frames of a still press).

    Raises:
        CalibrationError: the reference changed while taken, or a press does not fit a ball of ``radius_mm``.
        ValueError: frames of the wrong shape or dtype, a bad radius.
    """
    if not press_images:
        raise CalibrationError("calibration needs at least one ball press")
    params = params or DepthParams()
    pipe = DepthPipeline(alignment, np.array([0.0, 1.0]), np.array([0.0, 0.0]), params=params)
    reference = pipe.set_reference(reference_images)
    depths = press_depths_mm or [None] * len(press_images)
    if len(depths) != len(press_images):
        raise ValueError(f"press_depths_mm has {len(depths)} entries for {len(press_images)} presses")
    px = alignment.raw_pixel_mm
    diffs, truths, fits = [], [], []
    for frames, known in zip(press_images, depths):
        if not frames:
            raise CalibrationError("a ball press has no frames")
        mean = np.mean([alignment.rectify(to_grey(f, alignment.camera_shape)) for f in frames], axis=0)
        diff = reference.grey - mean
        fit = fit_ball(diff, radius_mm, pixel_mm=px, press_depth_mm=known)
        truth = cap_depth_mm(diff.shape, fit, px)
        inside = truth > 0
        diffs.append(diff[inside])
        truths.append(truth[inside])
        fits.append(fit)
    levels, table, saturated = table_from_samples(np.concatenate(diffs), np.concatenate(truths))
    report = {"ball_radius_mm": float(radius_mm), "presses": [dataclasses.asdict(f) for f in fits],
              "table_max_mm": float(table[-1]), "table_levels": int(levels[-1]), "saturated": saturated,
              "reference_noise_levels": reference.noise_levels}
    return VbtsCalibration(alignment, params, levels, table, reference, report)


def check_reference_clear(reference: Reference, previous: Reference, *, min_area_mm2: float = 0.3,
                          pixel_mm: float, threshold_levels: float = 3.0) -> None:
    """Refuse a reference that looks pressed compared with an earlier (calibration) reference.

    A uniform lighting change is allowed; a region of at least ``min_area_mm2`` that is darker by more than
    ``threshold_levels`` (or 4x the noise) is a contact.

    Raises:
        CalibrationError: naming the region's size and darkening.
    """
    if reference.grey.shape != previous.grey.shape:
        raise CalibrationError(f"reference shape {reference.grey.shape} does not match the calibration's "
                               f"{previous.grey.shape}")
    d = previous.grey - reference.grey
    d = ndimage.gaussian_filter(d - np.median(d), 0.1 / pixel_mm)
    limit = max(threshold_levels, 4.0 * max(reference.noise_levels, previous.noise_levels) / math.sqrt(
        max(1, min(reference.frames, previous.frames))))
    labels, count = ndimage.label(d > limit)
    if count == 0:
        return
    sizes = np.bincount(labels.ravel())[1:]
    area = float(sizes.max()) * pixel_mm * pixel_mm
    if area >= min_area_mm2:
        darkest = float(d[labels == 1 + int(np.argmax(sizes))].max())
        raise CalibrationError(f"the reference looks pressed: a {area:.1f} mm^2 region is up to {darkest:.0f} grey "
                               "levels darker than in the calibration reference; clear the pad (open the gripper) "
                               "and take the reference again")
