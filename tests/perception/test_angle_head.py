"""The angle head at run time: its probability table, and how the pose estimator weighs it against the image."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from tactile_manip.perception import TactilePoseEstimator
from tactile_manip.perception.angle_head import within_probability
from tactile_manip.perception.reconstruct import Reconstructor
from tactile_manip.perception.symmetry import SymmetrizedReconstructor

TOLERANCE = math.radians(5.0)


class FakeHead:
    """An angle head that reads every reading as the same axis with the same concentration."""

    def __init__(self, angle_rad: float, kappa: float) -> None:
        self.angle_rad, self.kappa, self.calls = angle_rad, kappa, 0

    def axis(self, field_ut: np.ndarray) -> tuple[float, float]:
        assert field_ut.dtype == np.float32 and field_ut.shape == (4, 4, 3)
        self.calls += 1
        return self.angle_rad, self.kappa

    def axes(self, fields_ut: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        assert fields_ut.dtype == np.float32 and fields_ut.shape[1:] == (4, 4, 3)
        self.calls += 1
        return np.full(len(fields_ut), self.angle_rad), np.full(len(fields_ut), self.kappa)


class Stripe(Reconstructor):
    """A contact stripe along ``angle_rad`` (or a round blob with ``round_=True``), whatever the reading."""

    name = "stripe"
    output_shape = (60, 60)
    pixel_mm = 0.33

    def __init__(self, angle_rad: float = 0.0, *, round_: bool = False, head: FakeHead | None = None) -> None:
        self.angle_rad, self.round_, self.angle_head = angle_rad, round_, head

    def _run(self, fields_ut: np.ndarray) -> tuple[np.ndarray, None]:
        ys, xs = np.mgrid[0:60, 0:60] - 29.5
        if self.round_:
            img = np.where(np.hypot(xs, ys) < 12, 1.0, 0.0)
        else:
            u = xs * math.cos(self.angle_rad) - ys * math.sin(self.angle_rad)
            v = xs * math.sin(self.angle_rad) + ys * math.cos(self.angle_rad)
            img = np.where((np.abs(v) < 3) & (np.abs(u) < 25), 1.0, 0.0)
        return np.repeat(img[None].astype(np.float32), len(fields_ut), axis=0), None


def _reading(value: float = 80.0) -> np.ndarray:
    return np.full((4, 4, 3), value)


@pytest.mark.parametrize("kappa", [1e-3, 0.5, 3.0, 20.0, 150.0, 2000.0])
def test_the_probability_within_tolerance_is_the_von_mises_mass_of_the_doubled_angle(kappa) -> None:
    want = stats.vonmises.cdf(2 * TOLERANCE, kappa) - stats.vonmises.cdf(-2 * TOLERANCE, kappa)
    assert within_probability(kappa, TOLERANCE) == pytest.approx(want, abs=2e-3)


def test_the_probability_rises_with_the_concentration_from_chance_to_certainty() -> None:
    kappa = np.geomspace(1e-4, 1e6, 200)
    p = within_probability(kappa, TOLERANCE)
    assert np.all(np.diff(p) >= 0)
    assert p[0] == pytest.approx(10.0 / 180.0, abs=1e-3) and p[-1] == pytest.approx(1.0)
    assert within_probability(0.0, TOLERANCE) == pytest.approx(10.0 / 180.0, abs=1e-3)  # log(0) is clipped


def test_with_a_head_the_angle_is_the_heads_by_default() -> None:
    head = FakeHead(math.radians(40.0), 20.0)
    estimator = TactilePoseEstimator(Stripe(0.0, head=head))
    assert estimator.angle_source == "head"
    est = estimator.estimate(_reading())
    assert est.source == "head" and est.defined and head.calls == 1
    assert est.angle_rad == pytest.approx(math.radians(40.0))
    assert est.confidence == pytest.approx(within_probability(20.0, TOLERANCE))
    image = TactilePoseEstimator(Stripe(0.0, head=head), angle_source="image").estimate(_reading())
    assert image.source == "image" and image.angle_rad == pytest.approx(0.0, abs=0.02)
    assert (est.centroid_mm, est.area_mm2) == (image.centroid_mm, image.area_mm2)


def test_likelier_takes_the_head_only_where_it_is_the_more_probable() -> None:
    image_only = TactilePoseEstimator(Stripe(0.3)).estimate(_reading())
    unsure = TactilePoseEstimator(Stripe(0.3, head=FakeHead(-1.0, 1e-3)), angle_source="likelier")
    est = unsure.estimate(_reading())
    assert est.source == "image"
    assert (est.angle_rad, est.confidence, est.defined) == (image_only.angle_rad, image_only.confidence, True)
    sure = TactilePoseEstimator(Stripe(0.3, head=FakeHead(-1.0, 1e5)), angle_source="likelier")
    assert sure.estimate(_reading()).source == "head"


def test_angle_sources_are_checked() -> None:
    with pytest.raises(ValueError, match="angle_source"):
        TactilePoseEstimator(Stripe(), angle_source="both")
    with pytest.raises(ValueError, match="no angle head"):
        TactilePoseEstimator(Stripe(), angle_source="head")
    assert TactilePoseEstimator(Stripe()).angle_source == "image"


def test_the_head_defines_an_angle_the_image_cannot() -> None:
    assert not TactilePoseEstimator(Stripe(round_=True)).estimate(_reading()).defined
    est = TactilePoseEstimator(Stripe(round_=True, head=FakeHead(1.2, 80.0))).estimate(_reading())
    assert est.defined and est.source == "head" and est.reason == ""
    assert est.angle_rad == pytest.approx(1.2) and 0 < est.confidence < 1


def test_no_contact_field_stays_no_contact_whatever_the_head_says() -> None:
    head = FakeHead(0.5, 1e4)
    est = TactilePoseEstimator(Stripe(head=head)).estimate(_reading(1.0))
    assert not est.defined and est.reason == "no contact field" and head.calls == 0


def test_a_saturated_chip_leaves_the_angle_to_the_image() -> None:
    from tactile_manip.types import TactileReading

    head = FakeHead(0.5, 1e4)
    reading, flags = _reading(), np.zeros((4, 4, 3), bool)
    flags[0, 0, 2] = True    # at the ADC rail (a value beyond the chip's range is implausible: no answer at all)
    est = TactilePoseEstimator(Stripe(0.2, head=head)).estimate(TactileReading(reading, reading, flags, t_host_s=0.0))
    assert est.saturated_chips == 1 and est.source == "image" and head.calls == 0
    assert est.angle_rad == pytest.approx(0.2, abs=0.02)


class Empty(Stripe):
    def _run(self, fields_ut: np.ndarray) -> tuple[np.ndarray, None]:
        return np.zeros((len(fields_ut), *self.output_shape), np.float32), None


def test_an_image_without_any_contact_is_not_given_an_angle_by_the_head_where_the_image_is_read_first() -> None:
    head = FakeHead(0.5, 1e4)
    rec = Empty(head=head)
    rec.deterministic = False  # drawn per call: the image is decoded with the estimate, before the head is asked
    est = TactilePoseEstimator(rec).estimate(_reading())
    assert not est.defined and est.reason == "empty contact" and head.calls == 0


def test_where_the_image_is_deferred_the_head_answers_any_contact_field_and_the_image_tells_its_area() -> None:
    head = FakeHead(0.5, 1e4)
    estimator = TactilePoseEstimator(Empty(head=head))
    assert estimator.defers_images
    est = estimator.estimate(_reading())
    assert est.defined and est.source == "head" and head.calls == 1
    assert est.area_mm2 == 0.0  # decoded now: an image without contact has no area (and so no centroid to use)


class Counting(Stripe):
    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.runs: list[int] = []

    def _run(self, fields_ut: np.ndarray) -> tuple[np.ndarray, None]:
        self.runs.append(len(fields_ut))
        return super()._run(fields_ut)


def test_the_images_of_a_call_are_decoded_once_together_and_only_when_read() -> None:
    import pickle

    rec = Counting(0.0, head=FakeHead(0.4, 50.0))
    estimator = TactilePoseEstimator(rec)
    many = estimator.estimate_many([_reading(), _reading(90.0), _reading(1.0), _reading(70.0)])
    assert rec.runs == [] and [e.source for e in many] == ["head", "head", "image", "head"]
    assert many[2].reason == "no contact field"
    assert many[0].angle_rad == pytest.approx(0.4) and "head" in many[0].timings_s
    centroid = many[3].centroid_mm                       # the first read decodes the call's three images at once
    assert rec.runs == [3]
    assert many[0].area_mm2 > 0 and many[1].centroid_mm == centroid and rec.runs == [3]
    one = estimator.estimate(_reading(70.0))
    assert one == many[3] and rec.runs == [3, 1]          # equality reads the deferred fields
    assert pickle.loads(pickle.dumps(many[0])) == many[0]  # a copy holds the measured values


def test_a_tactile_estimate_decodes_its_image_only_when_its_position_is_read() -> None:
    from tactile_manip.perception.tactile_estimator import TactileEstimator

    rec = Counting(0.0, head=FakeHead(0.4, 50.0))
    est = TactileEstimator(TactilePoseEstimator(rec)).estimate(_reading(70.0))
    assert est.angle.source == "head" and est.angle.angle_rad == pytest.approx(0.4)
    assert rec.runs == []                                  # the angle alone decodes nothing
    position = est.position_mm                             # the image's centroid: decoded now, once
    assert rec.runs == [1] and position == est.angle.centroid_mm and est.position_mm == position
    assert rec.runs == [1]


def test_the_head_can_be_left_out_and_bad_readings_are_still_refused() -> None:
    rec = Stripe(round_=True, head=FakeHead(0.5, 1e4))
    assert not TactilePoseEstimator(rec, angle_source="image").estimate(_reading()).defined
    bad = _reading()
    bad[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        TactilePoseEstimator(rec).estimate(bad)


def test_estimate_many_and_the_symmetrised_model_use_the_head_alike() -> None:
    head = FakeHead(-0.7, 3000.0)
    rec = Stripe(round_=True, head=head)
    many = TactilePoseEstimator(rec).estimate_many([_reading(), _reading(90.0)])
    assert [e.source for e in many] == ["head", "head"]
    sym = SymmetrizedReconstructor(rec)
    assert sym.angle_head is head
    assert TactilePoseEstimator(sym).estimate(_reading()).angle_rad == pytest.approx(-0.7)


def test_a_calibration_is_for_the_route_it_was_fitted_on() -> None:
    from tactile_manip.perception.confidence import ConfidenceCalibration

    rng = np.random.default_rng(0)
    raw = rng.uniform(0, 1, 400)
    err = np.where(rng.uniform(0, 1, 400) < raw, 1.0, 30.0)
    head_cal = ConfidenceCalibration.fit(raw, err, route="head")
    assert ConfidenceCalibration.from_dict(head_cal.to_dict()).route == "head"
    assert head_cal.fits(prior_samples=8, symmetrized=True, route="head")   # the head ignores the image's settings
    assert not head_cal.fits(prior_samples=1, symmetrized=False, route="image")
    rec = Stripe(round_=True, head=FakeHead(0.5, 30.0))
    est = TactilePoseEstimator(rec, calibration=head_cal).estimate(_reading())
    assert est.confidence == pytest.approx(head_cal(within_probability(30.0, TOLERANCE)))
    image_cal = ConfidenceCalibration.fit(raw, err)
    assert ConfidenceCalibration.from_dict({k: v for k, v in image_cal.to_dict().items() if k != "route"}).route == "image"
    with pytest.raises(ValueError, match="fitted for angles from the 'image' route"):
        TactilePoseEstimator(rec, calibration=image_cal)
    assert TactilePoseEstimator(rec, calibration=image_cal, angle_source="image").calibration is image_cal
