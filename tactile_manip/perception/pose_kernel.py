"""The pose stage's C kernel (``_pose_kernel.c``) through ctypes, and which path the pose stage runs.

:func:`contact_moments` runs, in one call into C, what :func:`~tactile_manip.perception.pose.angle_from_image`
otherwise runs in numpy on a float32 image: the contact's regions and their outliers, the Gaussian filter over
the contact's box and the moments (a third of the numpy path's time on whole-pad rods; ``python -m
benchmarks.check_pose_parity`` measures both). The kernel is an optional part of the install (setup.py):
where it was not built, or with ``TACTILE_MANIP_POSE_KERNEL=numpy`` in the environment, :func:`available` is
False and the numpy path runs, with the same results to float32 rounding. ``tactile-manip --version`` says
which path runs, and why.
"""

from __future__ import annotations

import ctypes
import importlib.util
import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import NamedTuple

import numpy as np

ENV_VAR = "TACTILE_MANIP_POSE_KERNEL"  # "numpy": never use the kernel
OK, EMPTY, TOO_SMALL, NO_MEMORY, BAD_ARGUMENT = 0, 1, 2, -1, -2
_OUT_SIZE = 7  # the out[] slots of tm_contact_moments
_RAW_PX, _N_PX, _CX, _CY, _SXX, _SYY, _SXY = range(7)


class ContactMoments(NamedTuple):
    """What the kernel found: ``status`` (OK, EMPTY: nothing above the threshold, TOO_SMALL: fewer weighted
    pixels than asked), the kept contact's pixels before filtering (``raw_px``) and the weighted pixels after
    (``n_px``), the centroid of all weights (mm) and the central second moments (mm^2) of the weights the
    angle uses (inside the aperture, when it applies). The moments are 0 unless ``status`` is OK."""

    status: int
    raw_px: int
    n_px: int
    centroid_mm: tuple[float, float]
    sxx: float
    syy: float
    sxy: float


def _load() -> tuple[ctypes.CDLL | None, str]:
    """The kernel's library and where it came from, or None and why not."""
    if os.environ.get(ENV_VAR, "").strip().lower() == "numpy":
        return None, f"numpy path: {ENV_VAR}=numpy in the environment"
    try:
        spec = importlib.util.find_spec("tactile_manip.perception._pose_kernel")
    except (ImportError, ValueError):
        spec = None
    if spec is None or not spec.origin:
        return None, ("numpy path: the C kernel was not built (reinstall with a C compiler: "
                      "pip install -e . builds tactile_manip/perception/_pose_kernel.c)")
    try:
        lib = ctypes.CDLL(spec.origin)
        fn = lib.tm_contact_moments
    except (OSError, AttributeError) as exc:
        return None, f"numpy path: the C kernel {spec.origin} does not load ({exc})"
    fn.restype = ctypes.c_int
    fn.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int, ctypes.c_float, ctypes.c_double, ctypes.c_void_p,
                   ctypes.c_int, ctypes.c_void_p, ctypes.c_int, ctypes.c_double, ctypes.POINTER(ctypes.c_double)]
    return lib, f"C kernel: {spec.origin}"


_LIB, _SOURCE = _load()


def available() -> bool:
    """True when the pose stage runs the C kernel on float32 images."""
    return _LIB is not None


def describe() -> str:
    """Which path the pose stage runs on float32 images, and the kernel's file or why not."""
    return _SOURCE


@contextmanager
def numpy_path() -> Iterator[None]:
    """Within the block, the pose stage runs its numpy path even where the kernel is built (for benchmarks and
    tests that compare the two paths; it switches the whole process, so not while other threads estimate)."""
    global _LIB
    saved, _LIB = _LIB, None
    try:
        yield
    finally:
        _LIB = saved


def contact_moments(depth_mm: np.ndarray, *, threshold_mm: float, outlier_fraction: float, kernel: np.ndarray,
                    disc: np.ndarray | None, min_px: int, pixel_mm: float) -> ContactMoments:
    """The contact's moments in ``depth_mm`` (H, W) float32, finite, its background removed already, as
    pose.py's numpy path computes them (see the C source for the steps).

    ``kernel``: the float32 Gaussian taps (odd length; ``[1.0]``: no filter); ``disc``: the (H, W) float32
    aperture or None; ``min_px``: the fewest weighted pixels for a defined angle (and for the aperture to apply).

    Raises:
        RuntimeError: the kernel is not available (check :func:`available` first).
        ValueError: an image or kernel the kernel does not take (a programming error: pose.py checks them).
        MemoryError: the kernel could not allocate its scratch buffers.
    """
    if _LIB is None:
        raise RuntimeError(f"the pose kernel is not available here ({_SOURCE})")
    d = np.ascontiguousarray(depth_mm, dtype=np.float32)
    taps = np.ascontiguousarray(kernel, dtype=np.float32)
    h, w = d.shape
    if disc is not None:
        disc = np.ascontiguousarray(disc, dtype=np.float32)
        if disc.shape != d.shape:
            raise ValueError(f"aperture of shape {disc.shape} for an image of shape {d.shape}")
    out = (ctypes.c_double * _OUT_SIZE)()
    status = _LIB.tm_contact_moments(d.ctypes.data, h, w, threshold_mm, outlier_fraction, taps.ctypes.data,
                                     taps.size, None if disc is None else disc.ctypes.data, min_px, pixel_mm, out)
    if status == NO_MEMORY:
        raise MemoryError(f"the pose kernel could not allocate its buffers for a {h}x{w} image")
    if status == BAD_ARGUMENT:
        raise ValueError(f"the pose kernel refused its arguments: image {h}x{w}, {taps.size} taps, "
                         f"pixel {pixel_mm} mm")
    return ContactMoments(int(status), int(out[_RAW_PX]), int(out[_N_PX]), (float(out[_CX]), float(out[_CY])),
                          float(out[_SXX]), float(out[_SYY]), float(out[_SXY]))

