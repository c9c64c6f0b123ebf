"""Ball-press calibration against the simulated camera's known response, its bad-input errors, and its file.

Figures printed with `pytest tests/collection/test_ball_calibration.py -s`.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest

from tactile_manip.errors import CalibrationError
from tactile_manip.extras import MissingExtraError
from tactile_manip.collection.camera_sim import SimulatedCamera, SimulatedCameraConfig, ball_indenter
from tactile_manip.collection.vbts_calibration import (
    VbtsCalibration,
    _isotonic,
    calibrate_ball,
    fit_ball,
    table_from_samples,
)
from tactile_manip.sim.objects import IndenterPose
from tactile_manip.sim.vbts import lookup_table

RADIUS = 4.0


def _table_error(cal: VbtsCalibration, name: str) -> tuple[float, float]:
    true = lookup_table(name)
    n = min(true.size, cal.table_mm.size)
    err = np.abs(cal.table_mm[1:n] - true[1:n])
    return float(err.max()), float(err.mean())


def _ball_depth_error(cal: VbtsCalibration, camera: SimulatedCamera, force_n: float, pose: IndenterPose
                      ) -> tuple[float, float]:
    ball = ball_indenter(RADIUS)
    camera.set_contact(ball, pose, force_n)
    depth = cal.pipeline().depth(camera.render(0.0, np.random.default_rng(9)))
    camera.clear_contact()
    imprint = camera.pair.press(ball, pose, force_n, np.random.default_rng(0)).imprint_mm
    inside = imprint > 0
    return float(np.sqrt(np.mean((depth - imprint)[inside] ** 2))), float(np.abs(depth - imprint).max())


def test_calibration_recovers_the_simulated_cameras_table(calibration, sim_camera):
    worst, mean = _table_error(calibration, "sensor_1")
    fit = calibration.report["presses"][0]
    truth = sim_camera.pair.press(ball_indenter(RADIUS), IndenterPose(x_mm=0.7, y_mm=-0.4), 4.5,
                                  np.random.default_rng(0))
    rmse, peak = _ball_depth_error(calibration, sim_camera, 3.0, IndenterPose(x_mm=-2.0, y_mm=1.5))
    print(f"\nsensor_1: press depth {fit['press_depth_mm']:.3f} mm (true {truth.approach_mm:.3f}); table error max "
          f"{worst:.4f} mm, mean {mean:.4f} mm over 0-{calibration.report['table_max_mm']:.2f} mm; another ball press "
          f"through the calibrated pipeline: RMSE in contact {rmse:.4f} mm, max {peak:.3f} mm")
    assert abs(fit["press_depth_mm"] - truth.approach_mm) < 0.03
    assert fit["centre_mm"] == pytest.approx((-0.7, -0.4), abs=0.02)  # the VBTS sees the MBTS frame mirrored
    assert worst < 0.04 and mean < 0.015
    assert not calibration.report["saturated"]
    assert rmse < 0.025 and peak < 0.1


def test_calibration_recovers_another_response_and_flags_saturation(ball_press, render):
    camera = SimulatedCamera(SimulatedCameraConfig(lookup_table="sensor_2", seed=3))
    rng = np.random.default_rng(3)
    reference = render(camera, 10, rng)
    shallow = calibrate_ball(camera.alignment, reference, [ball_press(camera, rng, force_n=2.5)], RADIUS)
    deep = calibrate_ball(camera.alignment, reference, [ball_press(camera, rng, force_n=4.5)], RADIUS)
    w1, m1 = _table_error(shallow, "sensor_2")
    w2, m2 = _table_error(deep, "sensor_2")
    print(f"\nsensor_2: table error max {w1:.4f} / mean {m1:.4f} mm (1.33 mm press); pressed past saturation "
          f"(1.78 mm > 1.35 mm): max {w2:.4f} / mean {m2:.4f} mm, saturated={deep.report['saturated']}")
    assert not shallow.report["saturated"] and w1 < 0.04 and m1 < 0.02
    assert deep.report["saturated"] and w2 < 0.06


def test_a_known_press_depth_replaces_the_edge_estimate(sim_camera, reference_frames, ball_press):
    pose = IndenterPose(x_mm=0.7, y_mm=-0.4)
    true_depth = sim_camera.pair.press(ball_indenter(RADIUS), pose, 4.5, np.random.default_rng(0)).approach_mm
    press = ball_press(sim_camera, np.random.default_rng(2), pose=pose)
    cal = calibrate_ball(sim_camera.alignment, reference_frames, [press], RADIUS, press_depths_mm=[true_depth])
    assert cal.report["presses"][0]["press_depth_mm"] == pytest.approx(true_depth)
    assert _table_error(cal, "sensor_1")[1] < 0.01


def test_no_ball_on_the_pad_is_refused(sim_camera, reference_frames):
    with pytest.raises(CalibrationError, match="no ball contact"):
        calibrate_ball(sim_camera.alignment, reference_frames, [reference_frames], RADIUS)


def test_a_radius_smaller_than_the_contact_is_refused(sim_camera, reference_frames, ball_press):
    press = ball_press(sim_camera, np.random.default_rng(2))
    with pytest.raises(CalibrationError, match="wider than a ball of radius 2"):
        calibrate_ball(sim_camera.alignment, reference_frames, [press], 2.0)


def test_a_contact_cut_by_the_crop_is_refused(sim_camera, reference_frames, ball_press):
    press = ball_press(sim_camera, np.random.default_rng(2), pose=IndenterPose(x_mm=8.5))
    with pytest.raises(CalibrationError, match="cut by the edge|leaves the"):
        calibrate_ball(sim_camera.alignment, reference_frames, [press], RADIUS)


def test_a_too_shallow_press_is_refused(sim_camera, reference_frames, ball_press):
    press = ball_press(sim_camera, np.random.default_rng(2), force_n=0.05)
    with pytest.raises(CalibrationError, match="deep|no ball contact"):
        calibrate_ball(sim_camera.alignment, reference_frames, [press], RADIUS)


@pytest.mark.parametrize("radius", [0.0, -1.0, float("nan")])
def test_a_nonsense_radius_is_a_value_error(radius):
    with pytest.raises(ValueError, match="radius_mm"):
        fit_ball(np.zeros((10, 10)), radius, pixel_mm=0.1)


def test_calibration_file_round_trip_and_bad_files(calibration, tmp_path, reference_frames):
    path = calibration.save(tmp_path / "cal.npz")
    back = VbtsCalibration.load(path)
    assert back.alignment == calibration.alignment and back.params == calibration.params
    assert np.array_equal(back.table_mm, calibration.table_mm)
    assert np.array_equal(back.pipeline().depth(reference_frames[0]), calibration.pipeline().depth(reference_frames[0]))
    with pytest.raises(CalibrationError, match="not found"):
        VbtsCalibration.load(tmp_path / "missing.npz")
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(CalibrationError, match="not a VBTS calibration"):
        VbtsCalibration.load(tmp_path / "other.npz")


def test_table_fit_is_monotone_and_starts_at_zero():
    pytest.importorskip("sklearn", reason="fitting a calibration needs scikit-learn (extra 'sklearn')")
    rng = np.random.default_rng(0)
    depth = rng.uniform(0, 1.5, 5000)
    levels = depth / 0.03 + rng.normal(0, 0.8, depth.size)
    lv, table, saturated = table_from_samples(levels, depth)
    assert table[0] == 0 and np.all(np.diff(table) >= 0) and not saturated
    assert np.abs(table[5:40] - lv[5:40] * 0.03).max() < 0.03
    assert np.all(np.diff(_isotonic(np.array([3.0, 1.0, 2.0, 5.0]), np.ones(4))) >= 0)


def test_the_table_fit_is_weighted_least_squares_and_names_its_extra(monkeypatch):
    pytest.importorskip("sklearn", reason="fitting a calibration needs scikit-learn (extra 'sklearn')")
    # 3 then 1 violate the order: pooled to their weighted mean (3 * 1 + 1 * 3) / 4 = 1.5
    np.testing.assert_allclose(_isotonic(np.array([3.0, 1.0, 2.0]), np.array([1.0, 3.0, 1.0])), [1.5, 1.5, 2.0])
    np.testing.assert_allclose(_isotonic(np.array([3.0, 1.0, 2.0, 5.0]), np.ones(4)), [2.0, 2.0, 2.0, 5.0])
    monkeypatch.setitem(sys.modules, "sklearn", None)     # `import sklearn` now raises ImportError
    monkeypatch.setitem(sys.modules, "sklearn.isotonic", None)
    with pytest.raises(MissingExtraError, match=r"needs scikit-learn.*extra 'sklearn'"):
        table_from_samples(np.arange(1, 40, dtype=float).repeat(5), np.linspace(0, 1, 195))
