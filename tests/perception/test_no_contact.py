"""An honest "no contact": the board's noise floor, readings that are no press, and inputs of any kind.

The shipped models through ``TactileEstimator.load()``; the press check of the SuperMag board
(tactile_manip/perception/press_check.py). The property-based tests are bounded (a fixed number of examples,
derandomized, no deadline) like the repository's other hypothesis tests.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

pytest.importorskip("onnxruntime", reason="the shipped models run on onnxruntime")

from tactile_manip.perception import TactileEstimator  # noqa: E402
from tactile_manip.perception.press_check import (DRIFT_ALLOWANCE_UT, FALSE_ALARM, PressCheck,  # noqa: E402
                                                  chi2_quantile, press_check_for)

FUZZ = settings(max_examples=60, derandomize=True, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@pytest.fixture(scope="module")
def est() -> TactileEstimator:
    return TactileEstimator.load()


@pytest.fixture(scope="module")
def press() -> np.ndarray:
    from tactile_manip.sim.objects import IndenterPose
    from tactile_manip.sim.pair import SensorPair
    from tactile_manip.sim.shapes import make_indenter

    sample = SensorPair(seed=3).press(make_indenter("hex_bar", size_mm=4.0), IndenterPose(1.0, -1.0, yaw_rad=0.4),
                                      10.0, np.random.default_rng(3), render_depth=False)
    return sample.field_ut


def assert_no_contact(e) -> None:
    """in_contact False: no position, no force, no angle."""
    assert not e.in_contact and e.position_mm is None
    assert e.contact.force_n is None and e.contact.position_mm is None and e.contact.values == {}
    assert e.angle.confidence == 0.0 and not e.angle.defined


def test_the_chi_square_quantile_is_the_one_tables_give() -> None:
    assert chi2_quantile(0.999, 48) == pytest.approx(84.037, rel=2e-3)
    assert chi2_quantile(0.99, 10) == pytest.approx(23.209, rel=2e-3)


def test_noise_at_the_floor_is_called_a_contact_at_the_stated_rate() -> None:
    check = press_check_for("supermag-4x4", (4, 4, 3))
    assert check.noise_ut == pytest.approx(np.sqrt(np.array([1.5, 1.5, 2.5]) ** 2 + DRIFT_ALLOWANCE_UT ** 2))
    noise = np.random.default_rng(0).standard_normal((40000, 4, 4, 3)) * check.noise_ut
    energy = np.sum((noise / check.noise_ut) ** 2, axis=(1, 2, 3))
    rate = float(np.mean(energy >= check.threshold(48)))
    assert FALSE_ALARM / 2.5 < rate < FALSE_ALARM * 2.5     # 40 expected: a binomial count within 16-100
    assert all(not check.judge(n)[0] for n in noise[:200])   # the check's own verdict on a few


def test_an_empty_pad_and_chip_noise_are_no_contact(est) -> None:
    rng = np.random.default_rng(1)
    for reading in (np.zeros((4, 4, 3)), rng.normal(0.0, 5.0, (4, 4, 3)), rng.normal(0.0, 1.5, (4, 4, 3))):
        e = est.estimate(reading)
        assert_no_contact(e)
        assert e.plausible and e.contact.plausible            # an empty pad is an answer: no contact
    many = est.estimate_many([np.zeros((4, 4, 3)), rng.normal(0.0, 5.0, (4, 4, 3))])
    for e in many:
        assert_no_contact(e)


def test_noise_and_uniform_fields_are_no_press(est) -> None:
    rng = np.random.default_rng(2)
    for reading in (rng.normal(0.0, 200.0, (4, 4, 3)), np.full((4, 4, 3), 800.0), np.full((4, 4, 3), -300.0),
                    np.broadcast_to([40.0, -25.0, 60.0], (4, 4, 3))):
        e = est.estimate(reading)
        assert e.in_contact and not e.plausible and not e.contact.plausible
        assert e.contact.implausible_reason.startswith("no press") and e.angle.implausible_reason.startswith("no press")
        assert e.angle.confidence == 0.0 and e.contact.force_n is None and e.position_mm is None


def test_a_press_is_measured(est, press) -> None:
    e = est.estimate(press)
    assert e.in_contact and e.plausible and e.angle.defined and e.angle.confidence > 0.5
    assert 5.0 < e.contact.force_n < 15.0 and e.position_mm is not None


def test_a_measured_noise_floor_raises_the_floor_and_never_lowers_it(press) -> None:
    estimator = TactileEstimator.load()
    noisy = np.random.default_rng(4).normal(0.0, 9.0, (4, 4, 3))
    assert estimator.estimate(noisy).in_contact                  # beyond the rated floor
    rated = estimator.contact.press_check.noise_ut.copy()
    estimator.set_noise_floor(np.full((4, 4, 3), 12.0))          # a board whose baseline measured 12 uT
    assert estimator.pose.press_check is estimator.contact.press_check
    assert estimator.contact.press_check.noise_ut == pytest.approx(np.hypot(12.0, DRIFT_ALLOWANCE_UT))
    assert not estimator.estimate(noisy).in_contact
    assert estimator.estimate(press).in_contact and estimator.estimate(press).plausible
    estimator.set_noise_floor(np.zeros(3))                       # a quieter chip than rated: the rated floor stays
    assert np.all(estimator.contact.press_check.noise_ut >= rated - 1e-12)
    with pytest.raises(ValueError, match="noise_ut"):
        PressCheck(np.array([1.0, -1.0, 1.0]))


@pytest.mark.parametrize("dtype", [np.complex128, np.bool_, np.str_, object])
def test_a_reading_of_no_real_numbers_is_refused_naming_its_dtype(est, dtype) -> None:
    reading = np.zeros((4, 4, 3), dtype=dtype)
    for call in (est.estimate, est.contact.estimate, est.pose.estimate, lambda r: est.estimate_many([r]),
                 lambda r: est.estimate_frames([r, r])):
        with pytest.raises(ValueError, match="dtype"):
            call(reading)


@FUZZ
@given(scale=st.floats(1.0, 500.0), seed=st.integers(0, 2 ** 32 - 1), kind=st.sampled_from(["white", "uniform",
                                                                                              "vector"]))
def test_pure_noise_and_constant_fields_never_claim_a_contact_nor_a_confident_angle(est, scale, seed, kind) -> None:
    rng = np.random.default_rng(seed)
    if kind == "white":
        reading = rng.standard_normal((4, 4, 3)) * scale
    elif kind == "uniform":
        reading = np.full((4, 4, 3), scale * 4.0 * rng.choice([-1.0, 1.0]))   # up to 2000 uT
    else:
        reading = np.broadcast_to(rng.standard_normal(3) * scale * 2.0, (4, 4, 3))
    e = est.estimate(reading)
    assert e.angle.confidence <= 0.2
    assert not (e.in_contact and e.plausible)


READINGS = hnp.arrays(
    dtype=st.sampled_from([np.float32, np.float64, np.float16, np.int16, np.int64, np.uint8, np.complex64,
                           np.bool_]),
    shape=st.one_of(st.just((4, 4, 3)), hnp.array_shapes(min_dims=0, max_dims=4, max_side=5)),
    elements=None)


@FUZZ
@given(reading=READINGS)
def test_any_array_gives_an_estimate_or_one_clear_value_error(est, reading) -> None:
    try:
        e = est.estimate(reading)
    except ValueError as error:                  # a wrong shape, NaN or inf, or no real numbers: named
        assert any(word in str(error) for word in ("shape", "NaN", "infinite", "dtype")), error
        return
    with np.errstate(invalid="ignore"):
        assert not np.isnan(np.asarray(reading, dtype=np.float64)).any()   # NaN is never estimated
    assert 0.0 <= e.angle.confidence <= 1.0 and math.isfinite(e.angle.angle_rad)
    if not e.in_contact:
        assert e.position_mm is None and e.contact.force_n is None and e.contact.position_mm is None
    if e.plausible:
        assert all(math.isfinite(v) for v in e.contact.values.values())
