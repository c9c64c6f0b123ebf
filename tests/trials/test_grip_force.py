"""The grip force a scene's contact model estimates in each trial: records, frame streams, summary, refusals."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from checks import assert_one_line_error

from tactile_manip.trials.grip_force import grip_force_summary
from tactile_manip.trials.record import TrialRecord
from tactile_manip.trials.scene import MethodSpec, PresentationConfig, TrialObject, TrialScene

REPO = Path(__file__).resolve().parents[2]
SIM_SCENE = REPO / "configs" / "scenes" / "reorient_sim.toml"
RODS = [TrialObject("cylinder", "cylinder_3mm", {"size_mm": 3.0}),
        TrialObject("hex_bar", "hex_bar_4mm", {"size_mm": 4.0})]


def _scene(**changes) -> TrialScene:
    base = TrialScene(name="grip", trials=6, seed=3, methods=[MethodSpec("bilinear", "bilinear", output_px=16)],
                      presentation=PresentationConfig(objects=RODS, force_n=(3.0, 14.0)))
    return dataclasses.replace(base, **changes)


def _record(trial: int, method: str = "a", *, force: float | None = None, sigma: float | None = None,
            applied: float = 10.0, commanded: float | None = 10.0) -> TrialRecord:
    extra = {"force_n": applied, **({} if commanded is None else {"commanded_force_n": commanded})}
    return TrialRecord(trial=trial, seed=trial, method=method, object="rod", true_angle_rad=0.1, offset_mm=(0.0, 0.0),
                       target_angle_rad=0.0, outcome="abstained", estimated_grip_force_n=force,
                       estimated_grip_force_sigma_n=sigma, extra=extra)


# ---------------------------------------------------------------- trials on the simulated cell


def test_a_scene_with_a_contact_model_logs_the_estimated_grip_force(tmp_path) -> None:
    pytest.importorskip("roboticstoolbox", reason="simulated trials need roboticstoolbox-python (extra 'robot')")
    pytest.importorskip("onnxruntime", reason="the contact model runs on onnxruntime")
    from tactile_manip.trials.frames import frames_path, read_trial_frames
    from tactile_manip.trials.log import read_trials
    from tactile_manip.trials.runner import run_trials

    scene = _scene(contact_model="models/contact_supermag.onnx")  # found beside the scene file, as models are
    summary_doc = tmp_path / "run" / "summary.json"
    run_trials(scene, tmp_path / "run", scene_path=SIM_SCENE, progress=False)
    records = read_trials(tmp_path / "run")
    assert len(records) == 6
    for r in records:
        assert math.isfinite(r.estimated_grip_force_n) and r.estimated_grip_force_sigma_n > 0
        assert r.extra["commanded_force_n"] == scene.behaviour.force_n and "grip_force" in r.timings_s
        events = read_trial_frames(frames_path(tmp_path / "run", r.trial, r.method)).events
        assert [e["event"] for e in events] == ["grip_force"]
        assert events[0]["force_n"] == pytest.approx(r.estimated_grip_force_n, abs=1e-4)
    applied = np.array([r.extra["force_n"] for r in records])
    estimated = np.array([r.estimated_grip_force_n for r in records])
    assert applied.max() - applied.min() > 5.0
    assert np.corrcoef(applied, estimated)[0, 1] > 0.7  # harder grasps read as harder
    line = json.loads((tmp_path / "run" / "trials.jsonl").read_text().splitlines()[0])
    assert {"estimated_grip_force_n", "estimated_grip_force_sigma_n"} <= set(line)
    grip = json.loads(summary_doc.read_text())["grip_force"]["bilinear"]
    assert grip["n"] == 6 and grip["applied"] == 6 and grip["commanded_n"] == 10.0
    assert grip["rmse_vs_applied_n"] == pytest.approx(np.sqrt(np.mean((estimated - applied) ** 2)), rel=1e-6)
    assert "## Estimated grip force" in (tmp_path / "run" / "summary.md").read_text()


def test_without_a_contact_model_the_grip_force_is_left_out(tmp_path) -> None:
    pytest.importorskip("roboticstoolbox", reason="simulated trials need roboticstoolbox-python (extra 'robot')")
    from tactile_manip.trials.frames import frames_path, read_trial_frames
    from tactile_manip.trials.log import read_trials
    from tactile_manip.trials.runner import run_trials

    run_trials(_scene(trials=1), tmp_path / "run", progress=False)
    (record,) = read_trials(tmp_path / "run")
    assert record.estimated_grip_force_n is None and record.estimated_grip_force_sigma_n is None
    assert "grip_force" not in record.timings_s
    line = json.loads((tmp_path / "run" / "trials.jsonl").read_text())
    assert "estimated_grip_force_n" not in line and "estimated_grip_force_sigma_n" not in line
    assert "grip_force" not in json.loads((tmp_path / "run" / "summary.json").read_text())
    assert "grip force" not in (tmp_path / "run" / "summary.md").read_text()
    assert read_trial_frames(frames_path(tmp_path / "run", 0, "bilinear")).events == []


def _scene_file(tmp_path: Path, contact_model: str) -> Path:
    text = SIM_SCENE.read_text()
    assert 'contact_model = "models/contact_supermag.onnx"' in text  # the shipped scene logs it by default
    path = tmp_path / "scene.toml"
    path.write_text(text.replace('"models/contact_supermag.onnx"', json.dumps(contact_model)))
    return path


def test_a_contact_model_of_another_board_layout_is_refused_before_the_run_starts(tmp_path, capsys,
                                                                                 contact_model_of_layout) -> None:
    pytest.importorskip("roboticstoolbox", reason="simulated trials need roboticstoolbox-python (extra 'robot')")
    from tactile_manip.cli import main

    scene = _scene_file(tmp_path, str(contact_model_of_layout("anyskin-5")))
    out = tmp_path / "run"
    assert main(["trials", "--config", str(scene), "--trials", "1", "--methods", "bilinear", "--out", str(out),
                 "--quiet"]) == 2
    assert_one_line_error(capsys.readouterr().err, "trials", "contact_model", "'anyskin-5'", "'supermag-4x4'")
    assert not out.exists()


def test_a_contact_model_without_a_force_target_is_refused_before_the_run_starts(tmp_path,
                                                                                 contact_model_of_layout) -> None:
    pytest.importorskip("roboticstoolbox", reason="simulated trials need roboticstoolbox-python (extra 'robot')")
    from tactile_manip.trials.runner import run_trials

    positions = contact_model_of_layout("supermag-4x4", targets={"names": ["x_mm", "y_mm", "depth_mm", "z_mm",
                                                                           "in_contact"],
                                                                 "units": ["mm", "mm", "mm", "mm", "1"]})
    with pytest.raises(ValueError, match="estimates no grip force .*x_mm, y_mm, depth_mm, z_mm, in_contact"):
        run_trials(_scene(contact_model=str(positions)), tmp_path / "run", progress=False)
    assert not (tmp_path / "run").exists()


def test_a_missing_contact_model_is_refused_before_the_run_starts(tmp_path, capsys) -> None:
    pytest.importorskip("roboticstoolbox", reason="simulated trials need roboticstoolbox-python (extra 'robot')")
    from tactile_manip.cli import main

    scene = _scene_file(tmp_path, "models/no_such_contact.onnx")
    out = tmp_path / "run"
    assert main(["trials", "--config", str(scene), "--trials", "1", "--methods", "bilinear", "--out", str(out)]) == 2
    assert_one_line_error(capsys.readouterr().err, "trials", "no_such_contact.onnx")
    assert not out.exists()


@pytest.mark.parametrize("scene_file", ["configs/scenes/reorient_sim.toml", "configs/scenes/reorient_robust.toml",
                                        "configs/scenes/reorient_fr3.toml", "tasks/paper_experiment.toml",
                                        "tasks/reorient_study.toml"])
def test_the_shipped_scenes_of_the_supermag_board_log_the_grip_force(scene_file) -> None:
    from tactile_manip.trials.scene import load_scene

    assert load_scene(REPO / scene_file).contact_model == "models/contact_supermag.onnx"
    assert (REPO / "models" / "contact_supermag.onnx").is_file()


def test_a_scene_names_an_onnx_contact_model_or_none() -> None:
    assert _scene().contact_model == ""
    with pytest.raises(ValueError, match="contact_model must be an exported .onnx"):
        _scene(contact_model="models/contact_supermag.md")


def test_each_method_is_handed_one_estimator_with_its_own_contact_model_or_none() -> None:
    pytest.importorskip("onnxruntime", reason="the contact model runs on onnxruntime")
    from tactile_manip.perception.tactile_estimator import TactileEstimator
    from tactile_manip.perception.baselines import BlindPoseEstimator
    from tactile_manip.perception.estimator import TactilePoseEstimator
    from tactile_manip.trials.methods import build_tactile_estimators

    contact = str(REPO / "models" / "contact_supermag.onnx")
    scene = _scene(contact_model=contact, methods=[MethodSpec("bilinear", "bilinear", output_px=16),
                                                   MethodSpec("blind", "blind")])
    handed = build_tactile_estimators(scene, layout="supermag-4x4")
    assert all(isinstance(e, TactileEstimator) for e in handed.values())
    assert isinstance(handed["bilinear"].pose, TactilePoseEstimator)
    assert handed["bilinear"].contact.path.name == "contact_supermag.onnx"
    assert isinstance(handed["blind"].pose, BlindPoseEstimator) and handed["blind"].contact is None  # no touch
    plain = build_tactile_estimators(_scene(), layout="supermag-4x4")["bilinear"]
    assert isinstance(plain.pose, TactilePoseEstimator) and plain.contact is None  # the scene names no model
    with pytest.raises(ValueError, match="contact_model: .*'supermag-4x4' board layout"):
        build_tactile_estimators(scene, layout="anyskin-5")


# ---------------------------------------------------------------- records and summary


def test_records_round_trip_with_and_without_the_grip_force() -> None:
    with_force = _record(0, force=9.5, sigma=2.5)
    assert TrialRecord.from_dict(json.loads(json.dumps(with_force.to_dict()))) == with_force
    without = _record(1)
    d = without.to_dict()
    assert "estimated_grip_force_n" not in d and TrialRecord.from_dict(d) == without
    with pytest.raises(ValueError, match="both or neither"):
        _record(2, force=9.5)


def test_the_summary_compares_the_estimates_with_the_commanded_and_the_applied_force() -> None:
    records = [_record(0, force=12.0, sigma=3.0, applied=11.0), _record(1, force=7.0, sigma=1.0, applied=9.0),
               _record(0, "b"), _record(1, "b", force=10.0, sigma=1.0, commanded=None)]
    real = grip_force_summary(records)
    a = real["a"]
    assert (a.n, a.commanded_n, a.estimated_mean_n, a.sigma_mean_n) == (2, 10.0, 9.5, 2.0)
    assert a.error_mean_n == pytest.approx(-0.5) and a.rmse_vs_commanded_n == pytest.approx(math.sqrt(6.5))
    assert (a.applied, a.rmse_vs_applied_n, a.within_1_sigma) == (0, None, None)  # not a simulated run
    assert real["b"].n == 1 and real["b"].commanded_n is None and real["b"].rmse_vs_commanded_n is None
    sim = grip_force_summary(records, applied=True)["a"]
    assert sim.applied == 2 and sim.rmse_vs_applied_n == pytest.approx(math.sqrt(2.5)) and sim.within_1_sigma == 0.5
    assert grip_force_summary([_record(0), _record(1, "b")]) == {}


def test_the_report_scores_against_the_applied_force_only_for_a_simulated_run(tmp_path) -> None:
    pytest.importorskip("matplotlib", reason="the report draws its figures with matplotlib")
    from tactile_manip.trials.report import write_report

    records = [_record(0, force=12.0, sigma=3.0, applied=11.0), _record(1, force=7.0, sigma=1.0, applied=9.0)]
    write_report(tmp_path / "sim", records, 0.1, run_info={"config": {"robot": {"backend": "twin"}}})
    write_report(tmp_path / "real", records, 0.1, run_info={"config": {"robot": {"backend": "franky"}}})
    sim, real = ((tmp_path / d / "summary.md").read_text() for d in ("sim", "real"))
    assert "RMSE vs applied (N)" in sim and "| a | 2 | 10.00 | 9.50 | -0.50 | 2.55 | 2.00 | 1.58 | 50 % |" in sim
    assert "RMSE vs applied" not in real and "| a | 2 | 10.00 | 9.50 | -0.50 | 2.55 | 2.00 |" in real
    assert json.loads((tmp_path / "real" / "summary.json").read_text())["grip_force"]["a"]["applied"] == 0
