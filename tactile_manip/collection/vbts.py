"""DTact-style depth from VBTS camera frames, and the paper's geometric alignment to the MBTS pad.

DTact (Lin et al., ICRA 2023) reads depth from how much darker the semi-transparent gel looks than in a
no-contact reference. :class:`DepthPipeline` does, per frame:

1. grey conversion (BGR frames: ITU-R BT.601 weights, as OpenCV) and the shape check against the calibration;
2. *calibrate*: the pad is rectified from the camera image through the homography of its four corners
   (:class:`PadAlignment`), cropped to the MBTS pad (20 mm of the 21 mm VBTS module) at ``raw_px`` (325,
   SuperMag Sec. III-D) pixels a side;
3. grey difference ``reference - frame`` (positive where the gel is pressed); differences below the lighting
   threshold read as 0; a Gaussian blur;
4. grey difference -> depth through the calibrated lookup table (piecewise linear, saturating at its end);
5. Gaussian smoothing passes;
6. *mirror*: the VBTS faces the MBTS in the symmetric gripper, so its pad frame is the MBTS pad frame turned
   about a pad axis (``mirror="x"``: x -> -x); *resize*: area-averaged to ``out_px`` (200) pixels a side.

The output follows the conventions of docs/design.md in the MBTS pad frame: float32 (200, 200) mm, >= 0, pixel (0, 0) at
the (-x, +y) corner, 0.1 mm per pixel. The lookup table comes from a ball press
(:mod:`tactile_manip.collection.vbts_calibration`).
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy import ndimage

from tactile_manip.checks import check_finite_scalar
from tactile_manip.errors import CalibrationError

MIRRORS = ("x", "y", "none")
BT601_BGR = np.array([0.114, 0.587, 0.299], np.float32)


# --------------------------------------------------------------------------------------- geometry


def homography_from_points(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """The 3x3 homography H (H[2, 2] = 1) with ``dst ~ H @ [src, 1]`` for four point pairs (4, 2)."""
    src = np.asarray(src, np.float64).reshape(4, 2)
    dst = np.asarray(dst, np.float64).reshape(4, 2)
    a, b = np.zeros((8, 8)), np.zeros(8)
    for k, ((x, y), (u, v)) in enumerate(zip(src, dst)):
        a[2 * k] = [x, y, 1, 0, 0, 0, -u * x, -u * y]
        a[2 * k + 1] = [0, 0, 0, x, y, 1, -v * x, -v * y]
        b[2 * k], b[2 * k + 1] = u, v
    try:
        h = np.linalg.solve(a, b)
    except np.linalg.LinAlgError as e:
        raise ValueError(f"the four corners {dst.tolist()} are degenerate (three on a line?)") from e
    return np.append(h, 1.0).reshape(3, 3)


def apply_homography(h: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Map points (any equal shapes) through ``h``; returns (u, v)."""
    w = h[2, 0] * x + h[2, 1] * y + h[2, 2]
    return (h[0, 0] * x + h[0, 1] * y + h[0, 2]) / w, (h[1, 0] * x + h[1, 1] * y + h[1, 2]) / w


@functools.lru_cache(maxsize=16)
def _area_matrix(n_in: int, n_out: int) -> np.ndarray:
    """(n_out, n_in) weights of each input pixel's overlap with each output pixel; rows sum to 1."""
    edges_in = np.arange(n_in + 1, dtype=np.float64)
    edges_out = np.linspace(0.0, n_in, n_out + 1)
    lo = np.maximum(edges_out[:-1, None], edges_in[None, :-1])
    hi = np.minimum(edges_out[1:, None], edges_in[None, 1:])
    m = np.clip(hi - lo, 0.0, None)
    m /= m.sum(axis=1, keepdims=True)
    m.setflags(write=False)
    return m


def resize_area(image: np.ndarray, out_shape: tuple[int, int]) -> np.ndarray:
    """Area-averaged resize of a 2-D image (each output pixel is the mean of the input it covers), float32."""
    img = np.asarray(image, np.float64)
    if img.ndim != 2:
        raise ValueError(f"resize_area: expected a 2-D image, got shape {img.shape}")
    rows = _area_matrix(img.shape[0], int(out_shape[0]))
    cols = _area_matrix(img.shape[1], int(out_shape[1]))
    return (rows @ img @ cols.T).astype(np.float32)


def mirror_image(image: np.ndarray, mirror: str) -> np.ndarray:
    """Flip an image in the pad layout: ``"x"`` negates x (columns), ``"y"`` negates y (rows), ``"none"``."""
    if mirror == "x":
        return image[..., ::-1]
    if mirror == "y":
        return image[..., ::-1, :]
    if mirror == "none":
        return image
    raise ValueError(f"mirror must be one of {list(MIRRORS)}, got {mirror!r}")


def pad_grid(n: int, side_mm: float, centre_mm: tuple[float, float] = (0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Pixel-centre pad coordinates (x, y) in mm of an (n, n) image of ``side_mm``: row 0 at +y, col 0 at -x."""
    c = (np.arange(n) - (n - 1) / 2.0) * (side_mm / n)
    x, y = np.meshgrid(c + centre_mm[0], -c + centre_mm[1])
    return x, y


@dataclass(frozen=True)
class PadAlignment:
    """Where the VBTS pad is in the camera image, and how its crop maps onto the MBTS pad.

    ``corners_px`` are the camera pixel coordinates (u = column, v = row, pixel centres at integers) of the
    VBTS pad's corners at pad coordinates (-s/2, +s/2), (+s/2, +s/2), (+s/2, -s/2), (-s/2, -s/2) for
    s = ``pad_mm``, in the VBTS pad frame (the frame of the gel's outer surface, seen from outside). Whatever
    mirror or rotation the camera's own view has is absorbed by the order of the corners.
    """

    corners_px: tuple[tuple[float, float], ...]  # 4 x (u, v), camera px
    camera_shape: tuple[int, int]                # (H, W) of the camera image, px
    pad_mm: float = 21.0                         # side of the square the corners outline, mm (VBTS module)
    crop_mm: float = 20.0                        # side of the MBTS pad, mm
    centre_mm: tuple[float, float] = (0.0, 0.0)  # MBTS pad centre in the VBTS pad frame, mm
    mirror: Literal["x", "y", "none"] = "x"      # VBTS pad frame -> MBTS pad frame (the facing sensors)
    raw_px: int = 325                            # rectified crop, px a side (SuperMag: 325)
    out_px: int = 200                            # output depth image, px a side (SuperMag: 200)

    def __post_init__(self) -> None:
        corners = np.asarray(self.corners_px, dtype=np.float64)
        if corners.shape != (4, 2) or not np.isfinite(corners).all():
            raise ValueError(f"PadAlignment.corners_px must be 4 finite (u, v) pairs, got {self.corners_px!r}")
        object.__setattr__(self, "corners_px", tuple(tuple(float(c) for c in p) for p in corners))
        shape = tuple(int(s) for s in self.camera_shape)
        if len(shape) != 2 or min(shape) < 2:
            raise ValueError(f"PadAlignment.camera_shape must be (H, W), got {self.camera_shape!r}")
        object.__setattr__(self, "camera_shape", shape)
        check_finite_scalar("PadAlignment.pad_mm", self.pad_mm, low=0.0, low_open=True)
        check_finite_scalar("PadAlignment.crop_mm", self.crop_mm, low=0.0, low_open=True)
        if self.mirror not in MIRRORS:
            raise ValueError(f"PadAlignment.mirror must be one of {list(MIRRORS)}, got {self.mirror!r}")
        for name in ("raw_px", "out_px"):
            v = getattr(self, name)
            if not isinstance(v, int) or v < 2:
                raise ValueError(f"PadAlignment.{name} must be an integer >= 2, got {v!r}")
        cx, cy = (float(c) for c in self.centre_mm)
        object.__setattr__(self, "centre_mm", (cx, cy))
        half = self.crop_mm / 2.0
        if max(abs(cx), abs(cy)) + half > self.pad_mm / 2.0 + 1e-9:
            raise ValueError(f"PadAlignment: the {self.crop_mm} mm crop centred at {self.centre_mm} mm leaves the "
                             f"{self.pad_mm} mm pad the corners outline")
        u, v = self.crop_corners_px()
        h, w = shape
        if u.min() < -0.5 or v.min() < -0.5 or u.max() > w - 0.5 or v.max() > h - 0.5:
            raise ValueError(f"PadAlignment: the crop reaches outside the {w}x{h} camera image (corners "
                             f"{np.round(np.stack([u, v], 1), 1).tolist()} px); check corners_px and camera_shape")

    @property
    def raw_pixel_mm(self) -> float:
        """Pixel size of the rectified crop, mm (20 mm / 325 px = 0.0615 mm)."""
        return self.crop_mm / self.raw_px

    @property
    def out_pixel_mm(self) -> float:
        """Pixel size of the output depth image, mm (0.1 mm)."""
        return self.crop_mm / self.out_px

    @functools.cached_property
    def homography(self) -> np.ndarray:
        """3x3 map from VBTS pad coordinates (x_mm, y_mm) to camera pixels (u, v)."""
        s = self.pad_mm / 2.0
        return homography_from_points([(-s, s), (s, s), (s, -s), (-s, -s)], self.corners_px)

    def crop_corners_px(self) -> tuple[np.ndarray, np.ndarray]:
        """Camera pixels (u, v) of the crop's four corners."""
        (cx, cy), s = self.centre_mm, self.crop_mm / 2.0
        return apply_homography(self.homography, np.array([cx - s, cx + s, cx + s, cx - s]),
                                np.array([cy + s, cy + s, cy - s, cy - s]))

    @functools.cached_property
    def _coords(self) -> np.ndarray:
        x, y = pad_grid(self.raw_px, self.crop_mm, self.centre_mm)
        u, v = apply_homography(self.homography, x, y)
        return np.stack([v, u]).astype(np.float32)

    def rectify(self, grey: np.ndarray) -> np.ndarray:
        """The crop (raw_px, raw_px) float32 in the VBTS pad frame, bilinear from a grey camera image."""
        return ndimage.map_coordinates(np.asarray(grey, np.float32), self._coords, order=1, mode="nearest",
                                       prefilter=False)

    def to_mbts(self, image_raw: np.ndarray) -> np.ndarray:
        """A rectified crop (VBTS pad frame, raw_px) -> MBTS pad frame at out_px: mirror, then area resize."""
        return resize_area(mirror_image(image_raw, self.mirror), (self.out_px, self.out_px))


# ---------------------------------------------------------------------------------------- pipeline


@dataclass(frozen=True)
class DepthParams:
    """DTact's processing of the grey difference (values for a 325 px crop of a 20 mm pad)."""

    threshold_levels: float = 2.0     # lighting threshold: grey differences below this read as 0, levels
    blur_mm: float = 0.05             # Gaussian sigma on the grey difference before the lookup, mm (0: off)
    smooth_mm: float = 0.07           # Gaussian sigma of each smoothing pass on the depth, mm (0: off)
    smooth_passes: int = 3            # smoothing passes (docs/design.md, Physics sources: three of ~0.07 mm)

    def __post_init__(self) -> None:
        for name in ("threshold_levels", "blur_mm", "smooth_mm"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ValueError(f"DepthParams.{name} must be a finite number >= 0, got {v!r}")
        if not isinstance(self.smooth_passes, int) or self.smooth_passes < 0:
            raise ValueError(f"DepthParams.smooth_passes must be an integer >= 0, got {self.smooth_passes!r}")


def to_grey(image: np.ndarray, camera_shape: tuple[int, int] | None = None) -> np.ndarray:
    """A camera image (H, W) grey or (H, W, 3) BGR, uint8 -> (H, W) float32 grey levels.

    Raises:
        ValueError: not uint8, not (H, W) or (H, W, 3), or not ``camera_shape`` (when given).
    """
    img = np.asarray(image)
    if img.dtype != np.uint8:
        raise ValueError(f"camera image: expected uint8 grey levels, got dtype {img.dtype}")
    if not (img.ndim == 2 or (img.ndim == 3 and img.shape[2] == 3)):
        raise ValueError(f"camera image: expected shape (H, W) or (H, W, 3), got {img.shape}")
    if camera_shape is not None and img.shape[:2] != tuple(camera_shape):
        raise ValueError(f"camera image: shape {img.shape[:2]} does not match the calibration's {tuple(camera_shape)}; "
                         "was the camera resolution changed since calibration? calibrate again")
    return img.astype(np.float32) if img.ndim == 2 else img.astype(np.float32) @ BT601_BGR


@dataclass(frozen=True, eq=False)
class Reference:
    """A no-contact reference, rectified: ``grey`` (raw_px, raw_px) float32 levels in the VBTS pad frame."""

    grey: np.ndarray
    frames: int
    noise_levels: float           # median per-pixel std across the frames (camera noise), grey levels
    t_host_s: float = field(default_factory=time.monotonic)


class DepthPipeline:
    """Depth images (MBTS pad frame, mm) from camera frames with one calibration.

    Args:
        alignment: where the pad is in the camera image and how it maps to the MBTS pad.
        table_levels, table_mm: the lookup table, grey difference (levels, increasing) -> depth (mm).
        params: threshold, blur and smoothing.
        reference: the no-contact reference, or None until :meth:`set_reference`.
    """

    def __init__(self, alignment: PadAlignment, table_levels: np.ndarray, table_mm: np.ndarray, *,
                 params: DepthParams | None = None, reference: Reference | None = None) -> None:
        levels = np.asarray(table_levels, np.float64)
        depth = np.asarray(table_mm, np.float64)
        if levels.ndim != 1 or levels.shape != depth.shape or levels.size < 2:
            raise ValueError(f"lookup table: levels {levels.shape} and depths {depth.shape} must be equal 1-D arrays "
                             "of at least 2 entries")
        if not (np.isfinite(levels).all() and np.isfinite(depth).all()) or np.any(np.diff(levels) <= 0):
            raise ValueError("lookup table: levels must be finite and strictly increasing, depths finite")
        if np.any(np.diff(depth) < -1e-9):
            raise ValueError("lookup table: depth must not decrease with the grey difference")
        self.alignment = alignment
        self.params = params or DepthParams()
        self.table_levels, self.table_mm = levels, depth
        self.reference = reference

    def set_reference(self, images: list[np.ndarray], *, max_noise_levels: float = 4.0) -> Reference:
        """Average no-contact frames into the reference.

        Raises:
            CalibrationError: fewer than 2 frames, or the image changed between them (something touched or
                moved: the 99.9th percentile of the per-pixel std exceeds ``max_noise_levels``).
            ValueError: a frame of the wrong shape or dtype.
        """
        if len(images) < 2:
            raise CalibrationError(f"a reference needs at least 2 no-contact frames, got {len(images)}")
        rect = np.stack([self.alignment.rectify(to_grey(im, self.alignment.camera_shape)) for im in images])
        std = rect.std(axis=0)
        worst = float(np.percentile(std, 99.9))
        if worst > max_noise_levels:
            raise CalibrationError(f"the camera image changed while the reference was taken (per-pixel std up to "
                                   f"{worst:.1f} grey levels, limit {max_noise_levels}): something touched the pad "
                                   "or the lighting flickers; clear the pad and take the reference again")
        self.reference = Reference(grey=rect.mean(axis=0), frames=len(images), noise_levels=float(np.median(std)))
        return self.reference

    def grey_difference(self, image: np.ndarray) -> np.ndarray:
        """``reference - frame`` on the rectified crop (raw_px, raw_px) float32, VBTS pad frame, no threshold."""
        if self.reference is None:
            raise CalibrationError("no reference frame: call set_reference() with no-contact frames first")
        return self.reference.grey - self.alignment.rectify(to_grey(image, self.alignment.camera_shape))

    def depth_raw(self, image: np.ndarray) -> np.ndarray:
        """Depth (raw_px, raw_px) float32 mm on the rectified crop, VBTS pad frame (before mirror and resize)."""
        return self.depth_from_difference(self.grey_difference(image))

    def depth_from_difference(self, diff: np.ndarray) -> np.ndarray:
        """Threshold, blur, lookup and smoothing of a rectified grey difference; float32 mm."""
        p, px = self.params, self.alignment.raw_pixel_mm
        d = np.where(diff < p.threshold_levels, 0.0, diff).astype(np.float32)
        if p.blur_mm > 0:
            d = ndimage.gaussian_filter(d, p.blur_mm / px, mode="nearest", truncate=3.0)
        depth = np.interp(d, self.table_levels, self.table_mm).astype(np.float32)
        for _ in range(p.smooth_passes if p.smooth_mm > 0 else 0):
            depth = ndimage.gaussian_filter(depth, p.smooth_mm / px, mode="nearest", truncate=3.0)
        return depth

    def depth(self, image: np.ndarray) -> np.ndarray:
        """Depth image (out_px, out_px) float32 mm >= 0 in the MBTS pad frame (docs/design.md) from a camera frame.

        Raises:
            ValueError: the image is not uint8 (H, W) / (H, W, 3) of the calibrated camera shape.
            CalibrationError: no reference yet.
        """
        return np.clip(self.alignment.to_mbts(self.depth_raw(image)), 0.0, None)
