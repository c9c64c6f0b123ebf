"""The shipped contact model of the SuperMag board: its file, its card's figures, and simulated presses."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime", reason="the contact estimator runs onnxruntime")

from tactile_manip.perception.contact import ContactEstimator  # noqa: E402

MODELS = Path(__file__).resolve().parents[2] / "models"
MODEL = MODELS / "contact_supermag.onnx"


def test_the_shipped_file_is_small_and_reads_one_frame_of_the_4x4_board() -> None:
    assert MODEL.stat().st_size < 1_000_000
    est = ContactEstimator(MODEL)
    assert tuple(est.input_shape[-3:]) == (4, 4, 3)
    assert est.context_frames == 1
    assert list(est.target_names) == ["x_mm", "y_mm", "depth_mm", "force_n", "in_contact"]


def test_the_card_quotes_the_metrics_file() -> None:
    metrics = json.loads((MODELS / "contact_supermag.metrics.json").read_text())
    card = (MODELS / "contact_supermag.md").read_text()
    ours = metrics["contact_unseen"]["methods"]["ours"]["rmse"]
    mlp = metrics["contact_unseen"]["methods"]["MLP"]["rmse"]
    for value in (ours["force_n"], mlp["force_n"]):
        assert f"{value:.3f}" in card


def test_simulated_cylinder_presses_give_forces_that_rise_with_the_press() -> None:
    from tactile_manip.sim.objects import IndenterPose
    from tactile_manip.sim.pair import SensorPair
    from tactile_manip.sim.shapes import make_indenter

    rng = np.random.default_rng(0)
    pair = SensorPair()
    rod = make_indenter("cylinder", size_mm=6.0)
    est = ContactEstimator(MODEL)
    forces = []
    for force_n in (3.0, 8.0, 14.0):
        sample = pair.press(rod, IndenterPose(x_mm=1.0, y_mm=-1.0), force_n, rng)
        state = est.estimate(sample.field_ut.astype(np.float32))
        assert state.force_sigma_n > 0 and np.isfinite(state.force_n)
        forces.append(state.force_n)
    assert forces[0] < forces[1] < forces[2]


def test_with_the_pose_model_the_position_lies_between_the_image_and_the_model_and_is_none_on_an_empty_pad() -> None:
    from tactile_manip.perception import TactilePoseEstimator, load_reconstructor
    from tactile_manip.perception.tactile_estimator import TactileEstimator
    from tactile_manip.sim.objects import IndenterPose
    from tactile_manip.sim.pair import SensorPair
    from tactile_manip.sim.shapes import make_indenter

    both = TactileEstimator(TactilePoseEstimator(load_reconstructor(MODELS / "supermag.onnx")),
                            ContactEstimator(MODEL))
    assert both.image_position_weight == 0.5  # stored in the shipped file
    assert both.estimate(np.zeros((4, 4, 3), np.float32)).position_mm is None
    press = SensorPair().press(make_indenter("hex_bar", size_mm=4.0), IndenterPose(x_mm=2.0, y_mm=-1.0, yaw_rad=0.5),
                               8.0, np.random.default_rng(0))
    est = both.estimate(press.field_ut.astype(np.float32))
    image, model = np.array(est.angle.centroid_mm), np.array(est.contact.position_mm)
    np.testing.assert_allclose(est.position_mm, (image + model) / 2, atol=1e-9)
    assert np.hypot(*(np.array(est.position_mm) - press.pressure.centroid_mm)) < 1.0  # the centre of pressure
    # a tenth of that press is within the board's noise floor: no contact for both parts, and no position
    faint = both.estimate((press.field_ut * 0.1).astype(np.float32))
    assert not faint.contact.in_contact and faint.angle.reason == "no contact field"
    assert faint.position_mm is None and faint.contact.force_n is None and not faint.in_contact


def test_several_pads_through_one_tactile_estimator_equal_each_pad_alone() -> None:
    from tactile_manip.perception import TactilePoseEstimator, load_reconstructor
    from tactile_manip.perception.tactile_estimator import TactileEstimator
    from tactile_manip.sim.objects import IndenterPose
    from tactile_manip.sim.pair import SensorPair
    from tactile_manip.sim.shapes import make_indenter

    both = TactileEstimator(TactilePoseEstimator(load_reconstructor(MODELS / "supermag.onnx")),
                            ContactEstimator(MODEL))
    pair, rng = SensorPair(), np.random.default_rng(3)
    readings = [pair.press(make_indenter("cylinder", size_mm=s), IndenterPose(x_mm=x, yaw_rad=y), f, rng).field_ut
                for s, x, y, f in ((3.0, 1.0, 0.3, 6.0), (6.0, -1.0, -1.2, 12.0), (4.0, 0.0, 1.5, 9.0))]
    readings.append(np.zeros((4, 4, 3)))  # an empty pad
    many = both.estimate_many(readings)
    alone = [both.estimate(r) for r in readings]
    assert [m.angle for m in many] == [a.angle for a in alone]
    # the contact model's batched run differs from one reading's only in float32 rounding
    for m, a in zip(many[:3], alone[:3]):
        assert m.contact.force_n == pytest.approx(a.contact.force_n, rel=1e-5)
        assert m.position_mm == pytest.approx(a.position_mm, abs=1e-5)
    assert many[3].position_mm is None and alone[3].position_mm is None and many[0].angle.source == "head"
    assert [m.contact.in_contact for m in many] == [a.contact.in_contact for a in alone]
    with pytest.raises(ValueError, match="NaN"):
        both.estimate_many([readings[0], np.full((4, 4, 3), np.nan)])
    both.contact.context_frames = 3  # a model that reads a pad's history cannot serve several pads
    with pytest.raises(ValueError, match="one TactileEstimator per pad"):
        both.estimate_many(readings)


def test_the_contact_model_estimates_several_pads_in_one_run_as_each_alone() -> None:
    from tactile_manip.sim.objects import IndenterPose
    from tactile_manip.sim.pair import SensorPair
    from tactile_manip.sim.shapes import make_indenter

    est = ContactEstimator(MODEL)
    pair, rng = SensorPair(), np.random.default_rng(5)
    readings = [pair.press(make_indenter("hex_bar", size_mm=5.0), IndenterPose(x_mm=x), f, rng).field_ut
                for x, f in ((-2.0, 4.0), (1.0, 9.0), (0.0, 14.0))]
    huge = np.zeros((4, 4, 3))
    huge[1, 2, 2] = 5000.0  # beyond any press: no answer, and the model does not run on it
    many = est.estimate_many([*readings, huge])
    for m, r in zip(many, readings):
        est.reset()
        one = est.estimate(r)
        assert m.plausible and m.context_frames == one.context_frames == 1
        for name in est.target_names:
            assert m.values[name] == pytest.approx(one.values[name], rel=1e-5, abs=1e-6)
            assert m.sigmas[name] == pytest.approx(one.sigmas[name], rel=1e-5, abs=1e-6)
    assert not many[3].plausible and "5000" in many[3].implausible_reason and many[3].force_n is None
    assert est.estimate_many([]) == []
    with pytest.raises(ValueError, match="NaN"):
        est.estimate_many([readings[0], np.full((4, 4, 3), np.nan)])
    est.context_frames = 3
    with pytest.raises(ValueError, match="one ContactEstimator each"):
        est.estimate_many(readings)


def test_a_pads_position_is_measured_when_read_and_travels_as_a_value() -> None:
    import pickle

    from tactile_manip.perception import TactilePoseEstimator, load_reconstructor
    from tactile_manip.perception.tactile_estimator import TactileEstimator
    from tactile_manip.sim.objects import IndenterPose
    from tactile_manip.sim.pair import SensorPair
    from tactile_manip.sim.shapes import make_indenter

    rec = load_reconstructor(MODELS / "supermag.onnx")
    runs = []
    run = rec._run
    rec._run = lambda fields: runs.append(len(fields)) or run(fields)  # count the image decodes
    both = TactileEstimator(TactilePoseEstimator(rec), ContactEstimator(MODEL))
    press = SensorPair().press(make_indenter("cylinder", size_mm=6.0), IndenterPose(x_mm=1.0, yaw_rad=0.2), 8.0,
                               np.random.default_rng(2))
    many = both.estimate_many([press.field_ut, press.field_ut])
    assert runs == []                                   # angles and forces only: no image decoded yet
    copy = pickle.loads(pickle.dumps(many[1]))          # a copy measures the position first
    assert runs == [2] and copy.position_mm == many[1].position_mm is not None
    assert many[0].position_mm == many[1].position_mm and runs == [2]
