"""The pose stage's C kernel against its numpy path, and how it is found, refused and shared by threads.

Both paths are held to the float64 reference in test_pose_fast.py and test_pose_aperture.py; here the kernel's
own parts: the labelling (the kept contact's pixel count must be exact on images of many tangled regions), the
scratch buffers it keeps between calls (images growing and shrinking, several threads at once), the choice of
path per image, and its errors.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import threading

import numpy as np
import pytest
from scipy import ndimage

from tactile_manip.perception import pose, pose_kernel
from tactile_manip.perception.pose import PoseParams, angle_from_image, aperture_disc

needs_kernel = pytest.mark.skipif(not pose_kernel.available(), reason=pose_kernel.describe())
SIGMA_PX = 3.0
RADIUS_PX = 12


def both_paths(img: np.ndarray, params: PoseParams = PoseParams(), pixel_mm: float = 0.1):
    """The kernel's and the numpy path's ContactMoments of a float32 image."""
    sigma_px = params.sigma_mm / pixel_mm
    radius_px = int(pose.GAUSS_TRUNCATE * sigma_px + 0.5) if sigma_px > 0 else 0
    disc = aperture_disc(*img.shape, sigma_px, "f") if params.aperture == "disc" else None
    c = pose_kernel.contact_moments(img, threshold_mm=params.threshold_mm, outlier_fraction=params.outlier_fraction,
                                    kernel=pose._gaussian_taps(sigma_px, radius_px), disc=disc,
                                    min_px=params.min_contact_px, pixel_mm=pixel_mm)
    n = pose._contact_moments(img, params, pixel_mm, sigma_px, radius_px, disc)
    return c, n


def assert_close(c, n) -> None:
    assert (c.status, c.raw_px) == (n.status, n.raw_px)
    assert abs(c.n_px - n.n_px) <= 5  # pixels whose filtered depth is within float32 rounding of the threshold
    scale = max(abs(n.sxx) + abs(n.syy), 1e-12)
    np.testing.assert_allclose(c.centroid_mm, n.centroid_mm, atol=1e-5)
    np.testing.assert_allclose([c.sxx, c.syy, c.sxy], [n.sxx, n.syy, n.sxy], atol=1e-5 * scale)


@needs_kernel
@pytest.mark.parametrize("density", [0.3, 0.45, 0.55, 0.7])
def test_the_kept_contact_is_labelled_exactly_on_tangled_regions(density) -> None:
    # random speckle near the percolation threshold: hundreds of regions with holes, U-shapes and spirals that
    # join rows below where they start; the kept pixel count must equal scipy's labelling to the pixel
    rng = np.random.default_rng(int(density * 100))
    for fraction in (0.0, 0.1, 0.5, 1.0):
        img = np.where(rng.random((120, 90)) < density, rng.uniform(0.2, 1.0, (120, 90)), 0.0).astype(np.float32)
        params = PoseParams(outlier_fraction=fraction, min_contact_px=1, aperture="none")
        c, n = both_paths(img, params)
        labels, count = ndimage.label(img > params.threshold_mm)
        sizes = np.bincount(labels.ravel())[1:]
        assert c.raw_px == int(sizes[sizes >= fraction * sizes.max()].sum())
        assert_close(c, n)


@needs_kernel
def test_scratch_buffers_follow_images_that_grow_and_shrink() -> None:
    rng = np.random.default_rng(1)
    for h, w in [(1, 1), (5, 300), (400, 400), (3, 3), (200, 200), (31, 7), (640, 480), (200, 200)]:
        img = np.zeros((h, w), np.float32)
        img[h // 4:max(h // 4 + 1, 3 * h // 4), w // 3:max(w // 3 + 1, w // 2)] = 1.0
        img += np.where(rng.random((h, w)) < 0.01, 0.5, 0.0).astype(np.float32)
        for params in (PoseParams(min_contact_px=1), PoseParams(aperture="none", sigma_mm=0.0, min_contact_px=1)):
            assert_close(*both_paths(img, params))


@needs_kernel
def test_threads_share_the_kernel_without_mixing_their_buffers() -> None:
    rng = np.random.default_rng(2)
    shapes = [(200, 200), (120, 300), (64, 64), (300, 90)]
    images = []
    for k in range(24):
        h, w = shapes[k % len(shapes)]
        yy, xx = np.mgrid[:h, :w]
        a = rng.uniform(-math.pi / 2, math.pi / 2)
        along = (xx - w / 2) * math.cos(a) - (yy - h / 2) * math.sin(a)
        across = (xx - w / 2) * math.sin(a) + (yy - h / 2) * math.cos(a)
        images.append((np.clip(1 - (along / (w / 3)) ** 2 - (across / 12) ** 2, 0, None)).astype(np.float32))
    serial = [angle_from_image(img) for img in images]
    results: dict[int, list] = {}
    errors: dict[int, BaseException] = {}

    def work(t: int) -> None:
        try:
            results[t] = [angle_from_image(images[(t + i) % len(images)]) for i in range(60)]
        except BaseException as e:  # noqa: BLE001 - a thread's exception is lost unless the test keeps it
            errors[t] = e

    threads = [threading.Thread(target=work, args=(t,)) for t in range(4)]
    for th in threads:
        th.start()
    for th in threads:
        th.join(timeout=120)
    assert not any(th.is_alive() for th in threads), "a thread is still running (deadlock in the kernel?)"
    assert errors == {}, errors
    assert sorted(results) == [0, 1, 2, 3] and all(len(got) == 60 for got in results.values())  # every thread reported
    for t, got in results.items():
        for i, est in enumerate(got):
            assert est == serial[(t + i) % len(images)]  # bit for bit: the same image, the same arithmetic


def test_float32_images_take_the_kernel_and_others_the_numpy_path(monkeypatch) -> None:
    calls = []
    monkeypatch.setattr(pose_kernel, "_LIB", object())  # "built", so the choice is what is tested
    monkeypatch.setattr(pose_kernel, "contact_moments", lambda d, **kw: calls.append(d.dtype) or
                        pose_kernel.ContactMoments(pose_kernel.EMPTY, 0, 0, (0.0, 0.0), 0.0, 0.0, 0.0))
    img = np.zeros((50, 50))
    img[20:30, 10:40] = 1.0
    assert not angle_from_image(img.astype(np.float32)).defined  # what the stub said
    assert angle_from_image(img).defined  # float64: the numpy path
    assert angle_from_image(np.zeros((0, 0), np.float32)).reason == "empty contact"  # no pixels: numpy
    assert calls == [np.float32]


def test_the_kernel_refuses_what_it_cannot_take(monkeypatch) -> None:
    img = np.ones((10, 10), np.float32)
    taps = np.ones(1, np.float32)
    if pose_kernel.available():
        with pytest.raises(ValueError, match="aperture of shape"):
            pose_kernel.contact_moments(img, threshold_mm=0.1, outlier_fraction=0.1, kernel=taps,
                                        disc=np.ones((5, 5), np.float32), min_px=1, pixel_mm=0.1)
        with pytest.raises(ValueError, match="refused its arguments"):
            pose_kernel.contact_moments(img, threshold_mm=0.1, outlier_fraction=0.1, kernel=np.ones(2, np.float32),
                                        disc=None, min_px=1, pixel_mm=0.1)
    monkeypatch.setattr(pose_kernel, "_LIB", None)
    with pytest.raises(RuntimeError, match="not available"):
        pose_kernel.contact_moments(img, threshold_mm=0.1, outlier_fraction=0.1, kernel=taps, disc=None, min_px=1,
                                    pixel_mm=0.1)


def test_the_environment_can_turn_the_kernel_off_and_the_cli_says_which_path_runs() -> None:
    code = "from tactile_manip.perception import pose_kernel as k; print(k.available(), k.describe())"
    off = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, pose_kernel.ENV_VAR: "numpy"})
    assert off.stdout.startswith("False numpy path")
    version = subprocess.run([sys.executable, "-m", "tactile_manip", "--version"], capture_output=True, text=True,
                             check=True)
    assert f"pose stage: {pose_kernel.describe()}" in version.stdout
