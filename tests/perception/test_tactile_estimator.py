"""The estimator users take: one loader, the interface every baseline implements, contact None without a model."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tactile_manip.errors import SensorTimeoutError
from tactile_manip.perception.baselines import BlindPoseEstimator, blind_estimator
from tactile_manip.perception.estimator import TactilePoseEstimator
from tactile_manip.perception.reconstruct import ModelFileError, load_reconstructor
from tactile_manip.perception.tactile_estimator import Estimator, PoseEstimator, TactileEstimate, TactileEstimator
from tactile_manip.sim.objects import IndenterPose
from tactile_manip.sim.pair import SensorPair
from tactile_manip.sim.shapes import make_indenter

pytest.importorskip("onnxruntime")

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def rod_reading() -> np.ndarray:
    """A 4 mm hex bar at 30 deg, 10 N, on the nominal sensor: (4, 4, 3) uT."""
    pair = SensorPair(seed=0)
    rod = make_indenter("hex_bar", size_mm=4.0)
    return pair.press(rod, IndenterPose(yaw_rad=math.radians(30.0)), 10.0, np.random.default_rng(0)).field_ut


def test_the_package_exports_the_estimator_without_loading_perception_at_import() -> None:
    code = ("import sys, tactile_manip; assert 'tactile_manip.perception' not in sys.modules; "
            "from tactile_manip import TactileEstimator, Estimator; "
            "from tactile_manip.perception.tactile_estimator import TactileEstimator as T; assert TactileEstimator is T; "
            "assert 'onnxruntime' not in sys.modules and 'torch' not in sys.modules")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    with pytest.raises(AttributeError, match="no attribute 'NoSuchThing'"):
        import tactile_manip

        tactile_manip.NoSuchThing  # noqa: B018


def test_load_finds_the_shipped_models_from_any_working_folder(tmp_path, monkeypatch, rod_reading) -> None:
    monkeypatch.chdir(tmp_path)
    est = TactileEstimator.load()
    assert est.pose.reconstructor.path == REPO / "models" / "supermag.onnx"
    assert est.contact.path == REPO / "models" / "contact_supermag.onnx"
    # a path the checkout holds, given relative to it, is found from elsewhere too
    same = TactileEstimator.load("models/supermag.onnx", "models/contact_supermag.onnx")
    assert same.pose.reconstructor.path == est.pose.reconstructor.path
    e = est.estimate(rod_reading)
    assert isinstance(e, TactileEstimate) and e.plausible and e.contact is not None and e.contact.in_contact
    assert e.angle.defined and abs(math.degrees(e.angle.angle_rad) - 30.0) < 5.0
    assert e.position_mm is not None


def test_a_missing_model_is_named_with_where_it_was_looked_for(tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ModelFileError, match=r"models/nothere\.onnx \(looked in .* and .*\).*supermag\.onnx"):
        TactileEstimator.load("models/nothere.onnx")
    with pytest.raises(ModelFileError, match="model file not found"):
        TactileEstimator.load(contact_model=str(tmp_path / "missing.onnx"))


def test_without_a_contact_model_contact_is_none_and_the_position_is_the_images(rod_reading) -> None:
    est = TactileEstimator.load(contact_model=None)
    assert est.contact is None
    e = est.estimate(rod_reading)
    assert e.contact is None and e.plausible
    assert e.position_mm == pytest.approx(e.angle.centroid_mm)
    many = est.estimate_many([rod_reading, rod_reading * 0.0])
    assert [m.contact for m in many] == [None, None]
    assert many[0].angle == e.angle and many[0].position_mm == pytest.approx(e.position_mm)
    assert many[1].position_mm is None  # an empty pad: no contact anywhere
    both = TactileEstimator.load()
    assert both.estimate(rod_reading).angle == e.angle  # the contact model changes nothing of the angle


@pytest.mark.parametrize("make", [
    lambda: TactileEstimator.load(),
    lambda: TactileEstimator.load("bilinear", None),
    lambda: TactileEstimator.load("bicubic", None, output_px=16),
    lambda: TactileEstimator.load("blind"),
    blind_estimator,
], ids=["supermag", "bilinear", "bicubic", "blind", "blind_estimator"])
def test_every_estimator_and_baseline_implements_the_interface(make, rod_reading) -> None:
    est = make()
    assert isinstance(est, Estimator) and isinstance(est.pose, PoseEstimator)
    e = est.estimate(rod_reading)
    assert isinstance(e, TactileEstimate) and -math.pi / 2 < e.angle.angle_rad <= math.pi / 2
    assert len(est.estimate_many([rod_reading] * 3)) == 3


def test_the_protocols_refuse_what_does_not_implement_them() -> None:
    assert not isinstance(object(), Estimator) and not isinstance(load_reconstructor("bilinear"), PoseEstimator)
    with pytest.raises(TypeError, match="pose must be a pose estimator"):
        TactileEstimator(load_reconstructor("bilinear"))  # type: ignore[arg-type]


def test_the_blind_baseline_answers_the_prior_and_reads_the_sensor_as_the_others(rod_reading) -> None:
    from tactile_manip.sensors.simulated import SimulatedSensor

    est = TactileEstimator.load("blind")  # the default contact model is not attached: no tactile input
    assert isinstance(est.pose, BlindPoseEstimator) and est.contact is None
    for e in (est.estimate(rod_reading), est.estimate(np.zeros((5, 1, 3))), *est.estimate_many([rod_reading] * 2)):
        assert (e.angle.angle_rad, e.angle.confidence, e.angle.defined, e.angle.source) == (0.0, 1.0, True, "prior")
        assert e.angle.centroid_mm == (0.0, 0.0) and e.contact is None
    with SimulatedSensor() as sensor:
        sensor.calibrate_baseline(frames=10)
        assert est.read(sensor, frames=2, timeout_s=0.5).angle.source == "prior"
        sensor.stall()
        with pytest.raises(SensorTimeoutError):  # a stalled sensor still ends a blind trial
            est.read(sensor, timeout_s=0.05)
    with pytest.raises(ValueError, match="at least one reading"):
        est.estimate_frames([])


def test_the_depth_image_is_one_pass_by_default_and_the_files_average_on_request(rod_reading) -> None:
    one = TactileEstimator.load(contact_model=None)
    stored = TactileEstimator.load(contact_model=None, image_symmetry="stored")
    assert one.pose.reconstructor.image_symmetry == "none"
    assert stored.pose.reconstructor.image_symmetry == "rotations"  # what models/supermag.onnx says
    a = one.pose.reconstructor.reconstruct(rod_reading).depth_mm
    b = stored.pose.reconstructor.reconstruct(rod_reading).depth_mm
    assert a.shape == b.shape == (200, 200) and not np.array_equal(a, b)
    # the angle comes from the head, which reads the reading: the same whatever the image averages
    assert one.estimate(rod_reading).angle.angle_rad == stored.estimate(rod_reading).angle.angle_rad


def test_load_passes_the_pose_options_and_refuses_bad_ones() -> None:
    est = TactileEstimator.load(contact_model=None, angle_source="image", calibrated=False)
    assert isinstance(est.pose, TactilePoseEstimator)
    assert est.pose.angle_source == "image" and est.pose.calibration is None
    assert TactileEstimator.load(contact_model=None).pose.calibration is not None  # the file's, fitted for it
    with pytest.raises(ValueError, match="escalation must be one of symmetry, samples"):
        TactileEstimator.load(escalation="more")
    with pytest.raises(ValueError, match="'samples' escalation"):
        TactileEstimator.load("bilinear", None, escalate_below=0.5, escalation="samples")


def test_a_board_with_a_contact_model_alone_gives_no_angle_and_the_models_position(rod_reading) -> None:
    from tactile_manip.perception.baselines import NO_POSE_MODEL, NoPoseEstimator

    est = TactileEstimator.load(pose_model=None)  # the shipped contact model, no pose model
    assert isinstance(est.pose, NoPoseEstimator) and isinstance(est, Estimator)
    e = est.estimate(rod_reading)
    assert not e.angle.defined and e.angle.confidence == 0.0 and e.angle.reason == NO_POSE_MODEL
    assert e.contact.plausible and e.position_mm == e.contact.position_mm  # nothing else says where it is
    with pytest.raises(ValueError, match="both are None"):
        TactileEstimator.load(None, None)
