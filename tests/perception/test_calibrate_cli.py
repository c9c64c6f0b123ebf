"""``tactile-manip calibrate`` end to end on a small simulated rod set, the estimates it is fitted on, and the
trials building estimators with the calibration beside the model and an escalation."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from checks import assert_one_line_error

from tactile_manip.cli import main
from tactile_manip.data import load_dataset, save_dataset
from tactile_manip.perception import TactilePoseEstimator, load_reconstructor
from tactile_manip.perception.confidence import ConfidenceCalibration, calibration_path, load_calibration_beside
from tactile_manip.evaluation.images import rod_estimates
from tactile_manip.sim.dataset import DatasetConfig, ObjectSpec, PoseRanges, generate

pytest.importorskip("onnxruntime")

MODEL = Path(__file__).resolve().parents[2] / "models" / "supermag.onnx"


@pytest.fixture(scope="module")
def rods(tmp_path_factory) -> Path:
    cfg = DatasetConfig(objects=[ObjectSpec("cylinder", 30, "test", "cylinder_3mm", {"size_mm": 3.0}),
                                 ObjectSpec("square_bar", 30, "test", "square_bar_4mm", {"size_mm": 4.0}),
                                 ObjectSpec("letter_r", 10, "test")],
                        poses=PoseRanges(offset_mm=3.0, force_n=(2.0, 15.0)), seed=7)
    return save_dataset(tmp_path_factory.mktemp("rods") / "rods.npz", generate(cfg, workers=1))


def test_rod_estimates_are_the_estimators_own_on_rods_only(rods) -> None:
    from tactile_manip.data import load_dataset

    data = load_dataset(rods)
    estimator = TactilePoseEstimator(load_reconstructor(MODEL))
    idx, conf, err = rod_estimates(data, data.indices("test"), estimator, chunk=7)
    assert idx.size == 60 and set(data.objects(idx)) == {"cylinder_3mm", "square_bar_4mm"}
    one = estimator.estimate(data.readings[idx[9]].astype(np.float64))
    assert conf[9] == pytest.approx(one.confidence if one.defined else 0.0, abs=1e-12)
    assert ((err >= 0) & (err <= 90)).all() and ((conf >= 0) & (conf <= 1)).all()
    with pytest.raises(ValueError, match="no presses of elongated objects"):
        rod_estimates(data, data.indices("test")[data.objects(data.indices("test")) == "letter_r"], estimator)


def test_calibrate_writes_a_calibration_beside_the_model_and_its_reliability_report(rods, tmp_path, capsys) -> None:
    model = tmp_path / "m.onnx"
    shutil.copy(MODEL, model)
    args = ["calibrate", "--model", str(model), "--fit", str(rods), "--report", str(rods)]
    assert main([*args, "--tolerance-deg", "5"]) == 0
    cal = load_calibration_beside(model)
    assert cal is not None and calibration_path(model) == tmp_path / "m.calibration.json"
    assert cal.samples == 60 and cal.tolerance_deg == 5.0
    report = json.loads((tmp_path / "m.calibration.reliability.json").read_text())
    assert report["fit"]["presses"] == report["report"]["presses"] == 60
    assert len(report["deciles_calibrated"]) == 10 and (tmp_path / "m.calibration.reliability.png").stat().st_size
    # (here fitted and checked on the same presses) the mean calibrated confidence is the share within tolerance
    rows = report["deciles_calibrated"]
    mean_conf = sum(r["mean_confidence"] * r["count"] for r in rows) / 60
    assert mean_conf == pytest.approx(report["report"]["within_tolerance"], abs=0.05)
    assert "expected calibration error" in capsys.readouterr().out
    # fitted on the confidence of the route the estimator takes by default: the angle head's, for this model
    image = TactilePoseEstimator(load_reconstructor(model), angle_source="image")
    default = TactilePoseEstimator(load_reconstructor(model))
    assert default.angle_source == "head" and cal.route == "head" and report["route"] == "head"
    _, conf_image, _ = rod_estimates(load_dataset(rods), load_dataset(rods).indices("test"), image)
    _, conf_default, _ = rod_estimates(load_dataset(rods), load_dataset(rods).indices("test"), default)
    assert not np.allclose(conf_image, conf_default)
    assert sorted(r["mean_confidence"] for r in report["deciles_raw"]) == pytest.approx(
        sorted(float(np.mean(c)) for c in np.array_split(np.sort(conf_default), 10)), abs=1e-9)
    # a second run refuses to replace it without --force, in one line
    assert main(args) == 2
    assert_one_line_error(capsys.readouterr().err, "calibrate", "exists")
    assert main([*args, "--force", "--tolerance-deg", "91"]) == 2
    assert_one_line_error(capsys.readouterr().err, "calibrate", "tolerance")
    assert main([*args, "--force", "--fit-split", "train"]) == 2  # no rods there: one line naming the split
    assert_one_line_error(capsys.readouterr().err, "calibrate", "split 'train'")
    # a symmetry-averaged estimator gets its own calibration, marked as such
    assert main([*args, "--symmetrized", "--out", str(tmp_path / "sym" / "m.json")]) == 0
    assert ConfidenceCalibration.load(tmp_path / "sym" / "m.json").symmetrized


def test_trials_use_the_calibration_beside_the_model_and_build_the_escalation(rods, tmp_path) -> None:
    from tactile_manip.perception.symmetry import SymmetrizedReconstructor
    from tactile_manip.trials.methods import build_pose_estimators
    from tactile_manip.trials.scene import MethodSpec, PresentationConfig, TrialObject, TrialScene

    model = tmp_path / "m.onnx"
    shutil.copy(MODEL, model)
    fitted = ConfidenceCalibration((0.2, 0.9), (0.1, 0.95), 5.0, 100, route="head")  # the model's route
    fitted.save(calibration_path(model))
    scene = TrialScene(methods=[MethodSpec("a", str(model), escalate_below=0.5),
                                MethodSpec("b", str(model), calibrated=False, escalate_below=0.5,
                                           escalation="samples", escalation_samples=4),
                                MethodSpec("c", "bilinear", output_px=16),
                                MethodSpec("d", str(model), symmetrize=True)],
                       presentation=PresentationConfig(objects=[TrialObject("cylinder", "c3", {"size_mm": 3.0})]))
    est = build_pose_estimators(scene)
    assert est["a"].calibration == fitted
    assert isinstance(est["a"].escalation, SymmetrizedReconstructor) and est["a"].escalate_below == 0.5
    assert est["b"].calibration is None and est["b"].escalation.samples == 4
    assert est["c"].calibration is None and est["c"].escalation is None
    # the head reads the reading whatever reconstructs the image: symmetry averaging does not change its angles
    assert est["d"].calibration == fitted
    ConfidenceCalibration((0.2, 0.9), (0.1, 0.95), 5.0, 100).save(calibration_path(model))   # the image's route
    assert build_pose_estimators(scene)["a"].calibration is None   # fitted for another route: not applied
    for bad in ({"escalate_below": 1.5}, {"escalation": "more"}, {"escalation_samples": 1},
                {"symmetrize": True, "escalate_below": 0.5},
                {"reconstructor": "bilinear", "escalate_below": 0.5, "escalation": "samples"}):
        with pytest.raises(ValueError, match="method x"):
            MethodSpec(**{"name": "x", "reconstructor": str(model), **bad})
