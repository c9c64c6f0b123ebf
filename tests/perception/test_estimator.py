"""TactilePoseEstimator: the pose API on the shipped model and the baselines, from arrays and from sensors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from checks import assert_sane_estimate

from tactile_manip.errors import SensorTimeoutError
from tactile_manip.perception import PoseParams, TactileEstimator, TactilePoseEstimator, load_reconstructor, wrap_axial
from tactile_manip.sim.objects import IndenterPose
from tactile_manip.sim.pair import SensorPair
from tactile_manip.sim.shapes import make_indenter

pytest.importorskip("onnxruntime")

MODEL = Path(__file__).resolve().parents[2] / "models" / "supermag.onnx"


@pytest.fixture(scope="module")
def supermag() -> TactilePoseEstimator:
    return TactilePoseEstimator(load_reconstructor(MODEL))


@pytest.fixture(scope="module")
def pair() -> SensorPair:
    return SensorPair(seed=0)


def _rod_field(pair: SensorPair, yaw_deg: float, *, size_mm: float = 4.0, seed: int = 0) -> np.ndarray:
    rod = make_indenter("hex_bar", size_mm=size_mm)
    sample = pair.press(rod, IndenterPose(0.5, -0.5, math.radians(yaw_deg)), 10.0, np.random.default_rng(seed),
                        render_depth=False)
    return sample.field_ut


def _axial_error_deg(a_rad: float, b_rad: float) -> float:
    return abs(math.degrees(wrap_axial(a_rad - b_rad)))


@pytest.mark.parametrize("yaw_deg", [-60.0, 0.0, 35.0, 90.0, -89.5])
def test_rod_angle_from_one_reading(supermag, pair, yaw_deg) -> None:
    est = supermag.estimate(_rod_field(pair, yaw_deg))
    assert est.defined and 0.5 < est.confidence <= 1.0
    assert _axial_error_deg(est.angle_rad, math.radians(yaw_deg)) < 3.0
    assert -math.pi / 2 < est.angle_rad <= math.pi / 2          # wrapped, also at the +-90 degree seam
    assert est.area_mm2 > 20.0
    assert set(est.timings_s) == {"head", "total"} and est.timings_s["total"] > 0  # the head's angle: no image yet
    image = TactilePoseEstimator(supermag.reconstructor, angle_source="image").estimate(_rod_field(pair, yaw_deg))
    assert set(image.timings_s) == {"reconstruct", "pose", "total"} and image.source == "image"


def test_empty_reading_is_undefined_not_nan(supermag) -> None:
    est = supermag.estimate(np.zeros((4, 4, 3)))
    assert not est.defined and est.reason == "no contact field"
    assert_sane_estimate(est)


def test_saturated_reading_gives_a_finite_estimate(supermag) -> None:
    est = supermag.estimate(np.full((4, 4, 3), 1e5, np.float32))  # clamped to +-500 uT as in training
    assert_sane_estimate(est)


@pytest.mark.parametrize("bad, match", [(np.full((4, 4, 3), np.nan), "NaN"), (np.zeros((4, 4, 2)), "shape"),
                                        (np.zeros((16, 3)), "shape")])
def test_bad_readings_raise_a_clear_error(supermag, bad, match) -> None:
    with pytest.raises(ValueError, match=match):
        supermag.estimate(bad)


def test_float32_and_float64_readings_agree(supermag, pair) -> None:
    field = _rod_field(pair, 20.0).astype(np.float64)
    a, b = supermag.estimate(field), supermag.estimate(field.astype(np.float32))
    assert a.defined and b.defined
    assert abs(a.angle_rad - b.angle_rad) < 1e-4 and abs(a.confidence - b.confidence) < 1e-4


def test_frames_are_averaged_before_the_estimate(supermag, pair) -> None:
    fields = [_rod_field(pair, 20.0, seed=s) for s in range(3)]
    mean = supermag.estimate(np.mean(np.stack(fields).astype(np.float64), axis=0))
    avg = supermag.estimate_frames(fields)
    assert avg.angle_rad == pytest.approx(mean.angle_rad, abs=1e-9)
    with pytest.raises(ValueError, match="at least one"):
        supermag.estimate_frames([])
    with pytest.raises(ValueError, match="different shapes"):
        supermag.estimate_frames([np.zeros((4, 4, 3)), np.zeros((4, 4, 2))])


def test_prior_samples_can_only_lower_the_confidence(pair) -> None:
    field = _rod_field(pair, -30.0)
    one = TactilePoseEstimator(load_reconstructor(MODEL)).estimate(field)
    many = TactilePoseEstimator(load_reconstructor(MODEL, samples=4, seed=0)).estimate(field)
    assert many.defined and 0.0 <= many.confidence <= one.confidence + 1e-9


def test_bilinear_16px_baseline_runs_the_same_pipeline(pair) -> None:
    est = TactilePoseEstimator(load_reconstructor("bilinear", output_px=16)).estimate(_rod_field(pair, 10.0))
    assert_sane_estimate(est)


def test_pose_params_are_validated() -> None:
    with pytest.raises(ValueError, match="isotropy_limit"):
        PoseParams(isotropy_limit=0.0)
    with pytest.raises(ValueError, match="sigma_mm"):
        PoseParams(sigma_mm=float("nan"))
    with pytest.raises(TypeError, match="Reconstructor"):
        TactilePoseEstimator("models/supermag.onnx")  # type: ignore[arg-type]


# ---------------------------------------------------------------- from a sensor


@pytest.fixture
def sensor():
    from tactile_manip.sensors.simulated import SimulatedSensor

    with SimulatedSensor() as s:
        s.calibrate_baseline(frames=20)
        yield s


def test_read_uses_only_frames_after_the_call(supermag, sensor) -> None:
    rod = make_indenter("cylinder", size_mm=3.0)
    sensor.set_contact(rod, IndenterPose(0.0, 0.0, math.radians(-40.0)), 10.0)
    both = TactileEstimator(supermag)
    got = both.read(sensor, frames=3, timeout_s=0.5)
    est = got.angle
    assert got.contact is None and got.position_mm is not None  # no contact model: the image's centroid
    assert est.defined and _axial_error_deg(est.angle_rad, math.radians(-40.0)) < 3.0
    assert est.timings_s["age"] >= 0.0
    sensor.clear_contact()
    assert not both.read(sensor, timeout_s=0.5).angle.defined


def test_stream_yields_one_estimate_per_new_frame(supermag, sensor) -> None:
    sensor.set_contact(make_indenter("square_bar", size_mm=2.5), IndenterPose(yaw_rad=0.3), 10.0)
    estimates = list(TactileEstimator(supermag).stream(sensor, timeout_s=0.5, max_estimates=4))
    assert len(estimates) == 4
    assert all(math.isfinite(e.angle.angle_rad) and e.contact is None for e in estimates)


def test_a_stalled_sensor_raises_instead_of_returning_stale_estimates(supermag, sensor) -> None:
    sensor.stall()
    both = TactileEstimator(supermag)
    with pytest.raises(SensorTimeoutError):
        both.read(sensor, timeout_s=0.05)
    with pytest.raises(SensorTimeoutError):
        next(both.stream(sensor, timeout_s=0.05))
    sensor.resume()
    assert both.read(sensor, timeout_s=0.5) is not None


def test_saturated_chips_lower_the_confidence(supermag, pair) -> None:
    """A flagged chip hands the angle to the image (the head was trained on sound readings), whose confidence
    it caps at SATURATED_CONFIDENCE_CAP times the unsaturated fraction of chips."""
    from tactile_manip.perception.estimator import SATURATED_CONFIDENCE_CAP
    from tactile_manip.types import TactileReading

    field = _rod_field(pair, 25.0).astype(np.float32)
    flags = np.zeros((4, 4, 3), bool)
    assert supermag.estimate(TactileReading(field, field, flags, t_host_s=0.0)).source == "head"
    image = TactilePoseEstimator(supermag.reconstructor, angle_source="image")
    clean = image.estimate(TactileReading(field, field, flags, t_host_s=0.0))
    flags[1, 2, 2] = flags[2, 2, 0] = True                  # two chips with an axis at the rail
    railed = supermag.estimate(TactileReading(field, field, flags, t_host_s=0.0))
    assert railed.source == "image" and railed.angle_rad == clean.angle_rad
    assert railed.confidence == pytest.approx(min(clean.confidence, SATURATED_CONFIDENCE_CAP) * 14 / 16)
    frames = supermag.estimate_frames([TactileReading(field, field, np.zeros_like(flags), t_host_s=0.0),
                                       TactileReading(field, field, flags, t_host_s=0.0)])
    assert frames.confidence == pytest.approx(min(clean.confidence, SATURATED_CONFIDENCE_CAP) * 14 / 16, rel=1e-6)


def test_a_reading_without_a_contact_field_is_no_contact_whatever_the_model_draws(supermag) -> None:
    rng = np.random.default_rng(0)
    for field in (np.zeros((4, 4, 3)), rng.normal(0.0, 2.5, (4, 4, 3))):   # empty pad, chip noise only
        est = supermag.estimate(field)
        assert not est.defined and est.reason == "no contact field" and est.confidence == 0.0
    trusting = TactilePoseEstimator(supermag.reconstructor, min_field_ut=0.0)
    _, rec = trusting.estimate_with_image(np.zeros((4, 4, 3)))
    assert rec.depth_mm.max() > 0.0  # the shipped model does draw something into an empty reading
    with pytest.raises(ValueError, match="min_field_ut"):
        TactilePoseEstimator(supermag.reconstructor, min_field_ut=float("nan"))


@pytest.mark.parametrize("value", [3e38, -3e38, 1e6])
def test_a_value_beyond_the_chips_range_is_clamped_flagged_and_lowers_the_confidence(supermag, pair, value) -> None:
    from tactile_manip.perception.reconstruct import READING_LIMIT_UT, out_of_range

    field = _rod_field(pair, 25.0).astype(np.float64)
    supermag = TactilePoseEstimator(supermag.reconstructor, angle_source="image")  # where a flagged chip leads
    clean = supermag.estimate(field)
    bad = field.copy()
    bad[1, 2, 2] = value                                     # one channel, e.g. a corrupt buffer
    clamped = field.copy()
    clamped[1, 2, 2] = np.sign(value) * READING_LIMIT_UT[2]  # what every reconstructor sees instead
    assert out_of_range(bad).sum() == 1 and not out_of_range(clamped).any()
    est = supermag.estimate(bad)
    assert est.saturated_chips == 1 and clean.saturated_chips == 0
    assert est.confidence == pytest.approx(supermag.estimate(clamped).confidence * 15 / 16)
    assert est.confidence < clean.confidence
    # the same flag through the frame average
    frames = supermag.estimate_frames([field, bad])
    assert frames.saturated_chips == 1


@pytest.mark.parametrize("name", ["bilinear", "bicubic"])
def test_baselines_clamp_to_the_same_range_as_the_model(pair, name) -> None:
    from tactile_manip.perception.reconstruct import READING_LIMIT_UT

    rec = load_reconstructor(name)
    field = _rod_field(pair, 25.0).astype(np.float64)
    bad, clamped = field.copy(), field.copy()
    bad[0, 0, 2], clamped[0, 0, 2] = -3e38, -READING_LIMIT_UT[2]
    np.testing.assert_array_equal(rec.reconstruct(bad).depth_mm, rec.reconstruct(clamped).depth_mm)
    assert np.isfinite(rec.reconstruct(bad).depth_mm).all()


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_and_infinite_values_still_raise(supermag, pair, bad) -> None:
    field = _rod_field(pair, 25.0).astype(np.float64)
    field[3, 0, 1] = bad
    with pytest.raises(ValueError, match="NaN or infinite values"):
        supermag.estimate(field)


# ---------------------------------------------------------------- several pads, and streams that fall behind


def _pad_readings(pair: SensorPair) -> list:
    """Two pads' readings as arrays and TactileReadings (one with a railed chip), and an empty pad."""
    from tactile_manip.types import TactileReading

    left, right = _rod_field(pair, 30.0).astype(np.float32), _rod_field(pair, -75.0, size_mm=6.0, seed=1)
    flags = np.zeros((4, 4, 3), bool)
    flags[0, 1, 2] = True
    return [left, TactileReading(right.astype(np.float32), right.astype(np.float32), flags, t_host_s=0.0),
            np.zeros((4, 4, 3)), right]


@pytest.mark.parametrize("method", ["supermag", "supermag_3_samples", "bilinear"])
def test_estimate_many_equals_estimating_one_by_one(pair, method) -> None:
    def make() -> TactilePoseEstimator:
        if method == "bilinear":
            return TactilePoseEstimator(load_reconstructor("bilinear"))
        return TactilePoseEstimator(load_reconstructor(MODEL, samples=3 if "3" in method else 1, seed=7))

    readings = _pad_readings(pair)
    together = make().estimate_many(readings)
    single = make()  # a fresh one: with prior samples, the same noise draws in the same order
    one_by_one = [single.estimate(r) for r in readings]
    assert together == one_by_one  # AngleEstimate equality: angle, confidence, flag, centroid, area, reason
    assert [e.defined for e in together] == [True, True, False, True]
    stage = "head" if method == "supermag" else "reconstruct"  # the head answers the sound readings of its model
    assert stage in together[0].timings_s and set(together[2].timings_s) == {"total"}  # no contact: nothing run
    assert together[0].timings_s[stage] == together[3].timings_s[stage]  # one batch


def test_estimate_many_of_nothing_and_of_bad_readings(supermag) -> None:
    assert supermag.estimate_many([]) == []
    with pytest.raises(ValueError, match="different shapes"):
        supermag.estimate_many([np.zeros((4, 4, 3)), np.zeros((4, 4, 1))])
    bad = np.zeros((4, 4, 3))
    bad[1, 1, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        supermag.estimate_many([np.zeros((4, 4, 3)), bad])


class _FramesDuringEstimates:
    """A sensor stand-in (what ``stream`` uses: ``layout`` and ``wait_new``) whose next frames arrive while an
    estimate runs: the reconstructor below publishes ``per_estimate`` frames each time it is called."""

    def __init__(self, fields: np.ndarray) -> None:
        from tactile_manip.boards import load_board

        self.layout = load_board("supermag-4x4")
        self.fields, self.published, self.seen = fields, 1, -1

    def publish(self, n: int) -> None:
        self.published = min(self.published + n, len(self.fields))

    def wait_new(self, timeout_s: float):
        from tactile_manip.types import TactileReading

        newest = self.published - 1
        if newest <= self.seen:
            raise SensorTimeoutError(f"no new frame within {timeout_s} s")
        self.seen = newest
        f = self.fields[newest]
        return TactileReading(f, f, np.zeros(f.shape, bool), t_host_s=0.0, seq=newest)


def test_a_stream_that_falls_behind_takes_the_newest_frame_and_counts_the_skipped_ones(pair) -> None:
    from tactile_manip.perception import StreamStats
    from tactile_manip.perception.reconstruct import Reconstructor

    fields = np.stack([_rod_field(pair, a, seed=i) for i, a in enumerate(np.linspace(-80.0, 80.0, 10))])
    sensor = _FramesDuringEstimates(fields.astype(np.float32))
    bilinear, used = load_reconstructor("bilinear"), []

    class SlowerThanTheSensor(Reconstructor):
        pixel_mm, output_shape = bilinear.pixel_mm, bilinear.output_shape

        def _run(self, fields_ut):
            used.append(fields_ut[0].copy())
            sensor.publish(3)  # three frames arrive while this one is processed
            return bilinear._run(fields_ut)

    stats = StreamStats()
    estimates = list(TactileEstimator(TactilePoseEstimator(SlowerThanTheSensor())).stream(sensor, max_estimates=4,
                                                                                          stats=stats))
    assert len(estimates) == 4 and stats.estimates == 4
    assert stats.last_seq == 9 and stats.skipped_frames == 6  # frames 0, 3, 6, 9 estimated; 1-2, 4-5, 7-8 not
    np.testing.assert_array_equal(np.stack(used), fields[[0, 3, 6, 9]].astype(np.float32))
    with pytest.raises(SensorTimeoutError):  # nothing newer than frame 9: a stale frame is never re-used
        next(TactileEstimator(TactilePoseEstimator(SlowerThanTheSensor())).stream(sensor))


def test_a_slow_estimator_on_the_simulated_sensor_skips_frames_instead_of_queueing_them(sensor) -> None:
    import time

    from tactile_manip.perception import StreamStats
    from tactile_manip.perception.reconstruct import Reconstructor

    bilinear, seqs = load_reconstructor("bilinear"), []

    class FortyMilliseconds(Reconstructor):  # five sensor periods at 125 Hz
        pixel_mm, output_shape = bilinear.pixel_mm, bilinear.output_shape

        def _run(self, fields_ut):
            time.sleep(0.04)
            return bilinear._run(fields_ut)

    stats = StreamStats()
    slow = TactilePoseEstimator(FortyMilliseconds(), min_field_ut=0.0)  # reconstructs even the empty pad's readings
    for est in TactileEstimator(slow).stream(sensor, timeout_s=0.5, max_estimates=4, stats=stats):
        seqs.append(stats.last_seq)
        assert math.isfinite(est.angle.angle_rad)
    gaps = np.diff(seqs)
    assert (gaps >= 1).all() and stats.skipped_frames == int((gaps - 1).sum()) >= 1


def test_a_calibration_maps_the_raw_confidence_of_defined_estimates(pair) -> None:
    from tactile_manip.perception.confidence import ConfidenceCalibration

    rec = load_reconstructor("bilinear", output_px=16)
    raw = TactilePoseEstimator(rec)
    # a calibration that says: raw 0.5 -> 10 % within tolerance, raw 1.0 -> 90 %
    cal = ConfidenceCalibration(knots=(0.5, 1.0), values=(0.1, 0.9), tolerance_deg=5.0, samples=200)
    calibrated = TactilePoseEstimator(rec, calibration=cal)
    field = _rod_field(pair, 25.0)
    a, b = raw.estimate(field), calibrated.estimate(field)
    assert a.defined and b.defined and a.angle_rad == b.angle_rad
    assert b.confidence == pytest.approx(float(np.interp(a.confidence, (0.5, 1.0), (0.1, 0.9))))
    empty = calibrated.estimate(np.zeros((4, 4, 3)))
    assert not empty.defined and empty.confidence == 0.0  # an undefined angle stays at 0
    with pytest.raises(TypeError, match="ConfidenceCalibration"):
        TactilePoseEstimator(rec, calibration={"knots": [0, 1]})


def test_escalation_runs_only_below_the_level_and_replaces_the_estimate(pair) -> None:
    from tactile_manip import perception
    from tactile_manip.perception.symmetry import SymmetrizedReconstructor

    calls = []

    class Counting(SymmetrizedReconstructor):
        def _run(self, fields_ut):
            calls.append(len(fields_ut))
            return super()._run(fields_ut)

    model = load_reconstructor(MODEL)
    field = _rod_field(pair, 25.0)
    # the head reads the reading, which another reconstruction does not change: escalation is for the image
    by_head = perception.TactilePoseEstimator(model, escalation=Counting(model), escalate_below=1.0)
    head = by_head.estimate(field)
    assert calls == [] and head.source == "head" and not head.escalated
    # ... but where the head stands aside (a chip flagged at its rail), the image's angle escalates
    from tactile_manip.types import TactileReading

    flags = np.zeros((4, 4, 3), bool)
    flags[0, 0, 2] = True
    railed = TactileReading(field, field, flags, t_host_s=0.0)
    aside = by_head.estimate(railed)
    assert aside.source == "image" and aside.escalated and calls == [1]
    calls.clear()

    def TactilePoseEstimator(*args, **kwargs):  # noqa: N802 - the image's route from here on
        return perception.TactilePoseEstimator(*args, angle_source="image", **kwargs)

    plain = TactilePoseEstimator(model).estimate(field)
    assert plain.defined and not plain.escalated and "escalate" not in plain.timings_s
    never = TactilePoseEstimator(model, escalation=Counting(model), escalate_below=0.0).estimate(field)
    assert calls == [] and never.angle_rad == plain.angle_rad and not never.escalated
    always = TactilePoseEstimator(model, escalation=Counting(model), escalate_below=1.0)
    est = always.estimate(field)
    assert calls == [1] and est.escalated and est.timings_s["escalate"] > 0
    assert est.timings_s["total"] >= est.timings_s["escalate"] + est.timings_s["reconstruct"]
    want = TactilePoseEstimator(SymmetrizedReconstructor(model)).estimate(field)
    assert est.angle_rad == want.angle_rad and est.confidence == want.confidence
    # no contact field: nothing to escalate
    assert not always.estimate(np.zeros((4, 4, 3))).escalated and calls == [1]
    # several pads: only the low ones escalate, each with its own reading
    both = always.estimate_many([field, np.zeros((4, 4, 3))])
    assert [e.escalated for e in both] == [True, False] and calls == [1, 1]


def test_escalation_is_checked_at_construction(pair) -> None:
    model = load_reconstructor(MODEL)
    with pytest.raises(TypeError, match="escalation must be a Reconstructor"):
        TactilePoseEstimator(model, escalation="symmetry", escalate_below=0.5)
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="escalate_below"):
            TactilePoseEstimator(model, escalate_below=bad)
    other = load_reconstructor("bilinear", output_px=16)
    with pytest.raises(ValueError, match="must match"):
        TactilePoseEstimator(model, escalation=other, escalate_below=0.5)
