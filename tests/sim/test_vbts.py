"""The DTact-style depth pipeline: quantisation, dead band, saturation, blur, noise."""

import numpy as np
import pytest

from tactile_manip.sim.params import VbtsParams
from tactile_manip.sim.vbts import dtact_depth, grey_from_depth, lookup_table, saturation_depth_mm

QUIET = VbtsParams(noise_grey_levels=0.0)


def test_shipped_tables_are_the_measured_curves():
    t1, t2 = lookup_table("sensor_1"), lookup_table("sensor_2")
    assert t1.shape == (61,) and t2.shape == (55,)
    assert saturation_depth_mm("sensor_1") == pytest.approx(1.915, abs=1e-3)
    assert saturation_depth_mm("sensor_2") == pytest.approx(1.348, abs=1e-3)
    assert np.all(np.diff(t1) >= 0) and t1[0] == 0
    assert 0.02 < np.mean(np.diff(t1)) < 0.04  # about 0.03 mm per grey level


def test_grey_round_trip_on_the_table_knots():
    t = lookup_table("sensor_1")
    levels = grey_from_depth(t[5:50], t)
    np.testing.assert_allclose(t[np.rint(levels).astype(int)], t[5:50])


def test_smooth_imprint_is_reproduced_within_quantisation():
    x = np.linspace(-10, 10, 200)
    imprint = np.tile(np.clip(1.5 - 0.02 * x**2, 0, None), (200, 1))
    depth = dtact_depth(imprint, QUIET, None)
    inside = imprint[0] > 0.3
    assert depth.dtype == np.float32 and depth.shape == (200, 200)
    assert np.abs(depth[100, inside] - imprint[100, inside]).max() < 0.04


def test_saturation_dead_band_and_clipping():
    img = np.zeros((50, 50))
    img[:, :10] = 5.0            # far past saturation
    img[:, 20:30] = 0.03         # one level: inside the 2-level dead band
    img[:, 40:] = -1.0           # negative imprint is treated as none
    depth = dtact_depth(img, VbtsParams(noise_grey_levels=0.0, blur_passes=0), None)
    assert depth[:, :10].max() == pytest.approx(saturation_depth_mm("sensor_1"))
    assert not depth[:, 20:30].any() and not depth[:, 40:].any()
    d2 = dtact_depth(img, VbtsParams(noise_grey_levels=0.0, blur_passes=0, lookup_table="sensor_2"), None)
    assert d2.max() == pytest.approx(saturation_depth_mm("sensor_2"))


def test_blur_spreads_a_single_pixel_and_conserves_its_volume():
    img = np.zeros((41, 41))
    img[20, 20] = 1.0
    sharp = dtact_depth(img, VbtsParams(noise_grey_levels=0.0, blur_passes=0), None)
    blurred = dtact_depth(img, QUIET, None)
    assert blurred[20, 20] < 0.5 * sharp[20, 20]
    assert blurred.sum() == pytest.approx(sharp.sum(), rel=1e-3)


def test_noise_is_seeded_and_bounded():
    imprint = np.full((60, 60), 1.0)
    a = dtact_depth(imprint, VbtsParams(), np.random.default_rng(3))
    b = dtact_depth(imprint, VbtsParams(), np.random.default_rng(3))
    np.testing.assert_array_equal(a, b)
    assert 0.002 < float(np.std(a[10:-10, 10:-10])) < 0.03  # ~1 grey level, blurred


def test_bad_inputs():
    with pytest.raises(ValueError, match="NaN"):
        dtact_depth(np.full((4, 4), np.nan), QUIET, None)
    with pytest.raises(ValueError, match="2-D"):
        dtact_depth(np.zeros(4), QUIET, None)
    with pytest.raises(ValueError, match="lookup_table"):
        lookup_table("sensor_3")
