"""The trial runner on the simulated cell: paired methods, faults recorded, runs that survive a kill."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tactile_manip.errors import SimulationError
from tactile_manip.robot.safety import SafetyLimits
from tactile_manip.trials.log import read_trials
from tactile_manip.trials.cells import SimulatedCell
from tactile_manip.trials.methods import build_pose_estimators, build_tactile_estimators
from tactile_manip.trials.presentation import draw_presentation
from tactile_manip.trials.runner import run_scene, run_trials
from tactile_manip.trials.scene import (FaultPlan, MethodSpec, PresentationConfig, RobotConfig, TrialObject,
                                        TrialScene, load_scene)

pytest.importorskip("roboticstoolbox")
pytest.importorskip("onnxruntime")

REPO = Path(__file__).resolve().parents[2]
MODEL = str(REPO / "models" / "supermag.onnx")
THIN_RODS = [TrialObject("cylinder", "cylinder_3mm", {"size_mm": 3.0}),
             TrialObject("hex_bar", "hex_bar_4mm", {"size_mm": 4.0})]


def _scene(**changes) -> TrialScene:
    base = TrialScene(name="test", trials=4, seed=3,
                      methods=[MethodSpec("supermag", MODEL), MethodSpec("bilinear", "bilinear", output_px=16)],
                      presentation=PresentationConfig(objects=THIN_RODS))
    return dataclasses.replace(base, **changes)


def _run(scene: TrialScene) -> list:
    records = []
    run_scene(scene, records.append, estimators=build_tactile_estimators(scene), progress=False)
    return records


def test_presentations_are_a_pure_function_of_seed_and_index() -> None:
    scene = _scene()
    a, b = draw_presentation(scene, 2), draw_presentation(scene, 2)
    assert a == b and a != draw_presentation(scene, 3)
    assert draw_presentation(dataclasses.replace(scene, seed=4), 2).seed != a.seed
    assert -math.pi / 2 < a.angle_rad <= math.pi / 2 and all(abs(o) <= 2.0 for o in a.offset_mm)


def test_a_draw_the_cell_cannot_hold_is_drawn_again_and_no_other_draw_moves() -> None:
    from tactile_manip.trials.presentation import MAX_REDRAWS

    scene = _scene()
    seen = []

    def refuse_first(p) -> bool:
        seen.append(p)
        return len(seen) > 1
    again = draw_presentation(scene, 2, holds=refuse_first)
    plain = draw_presentation(scene, 2)
    assert seen[0] == plain and again == seen[1] and again != plain
    assert again.obj == plain.obj and again.trial == 2  # the object is kept, the rest is drawn again
    assert draw_presentation(scene, 2, holds=lambda p: p != plain) == again  # a pure function of the refusals
    assert draw_presentation(scene, 3, holds=lambda p: True) == draw_presentation(scene, 3)
    calls = []
    last = draw_presentation(scene, 2, holds=lambda p: calls.append(p) is None and False)
    assert len(calls) == MAX_REDRAWS + 1 and last == calls[-1]  # never held: the last draw is kept


def test_the_simulated_cell_refuses_a_press_through_its_layer_and_the_run_redraws_it() -> None:
    bar = TrialObject("square_bar", "square_bar_2p5mm", {"size_mm": 2.5})
    scene = _scene(trials=1, presentation=PresentationConfig(objects=[bar], force_n=(10.0, 10.0)))
    cell = SimulatedCell(scene)
    p = draw_presentation(scene, 0)
    assert cell.holds(p)
    crushing = dataclasses.replace(p, force_n=60.0)
    assert not cell.holds(crushing)
    with cell.connected(), pytest.raises(SimulationError, match="bottoms out"):  # what the trial would meet
        cell.run_one(crushing, build_tactile_estimators(scene)["bilinear"])
    scene = _scene(trials=2, presentation=PresentationConfig(objects=[bar], force_n=(10.0, 60.0)))
    cell = SimulatedCell(scene)
    held = [draw_presentation(scene, i, holds=cell.holds) for i in range(2)]
    assert all(cell.holds(p) for p in held)
    assert not any(cell.holds(draw_presentation(scene, i)) for i in range(2))  # both first draws were refused
    records = []
    run_scene(scene, records.append, estimators=build_tactile_estimators(scene), progress=False, cell=cell)
    assert [r.seed for r in records] == [p.seed for p in held for _ in range(2)]
    assert all(r.outcome != "error" for r in records)


def test_every_method_runs_every_presentation_and_supermag_turns_rods_to_target() -> None:
    records = _run(_scene())
    assert [(r.trial, r.method) for r in records] == [(i, m) for i in range(4) for m in ("supermag", "bilinear")]
    by_trial = {}
    for r in records:
        by_trial.setdefault(r.trial, []).append(r)
    for pair in by_trial.values():  # identical presentation for both methods
        assert len({(r.seed, r.object, r.true_angle_rad, r.offset_mm) for r in pair}) == 1
    supermag = [r for r in records if r.method == "supermag"]
    assert all(r.outcome == "done" for r in supermag), [r.detail for r in supermag]
    for r in supermag:
        # the error is measured on the twin's object pose, and matches estimate error up to the arm's tolerance
        assert abs(r.error_rad) < math.radians(5.0)
        est_err = wrap(r.true_angle_rad - r.estimated_angle_rad)
        assert abs(abs(r.error_rad) - abs(est_err)) < math.radians(0.2)


def wrap(a: float) -> float:
    return float((a + math.pi / 2) % math.pi - math.pi / 2)


def test_injected_faults_are_recorded_and_the_next_trial_runs() -> None:
    scene = _scene(methods=[MethodSpec("supermag", MODEL)],
                   faults=FaultPlan(arm_fault_trials=[1], sensor_stall_trials=[2]))
    records = _run(scene)
    outcomes = [r.outcome for r in records]
    assert outcomes == ["done", "arm_fault", "sensor_stale", "done"], [r.detail for r in records]
    assert "reflex" in records[1].detail and "tactile sensor" in records[2].detail
    assert records[1].final_angle_rad is None and records[1].error_rad is None


def test_an_unreachable_turn_is_an_ik_failure_and_the_arm_stays() -> None:
    # joint 7 at +pi/4 puts joint 6 near its limit: an 80 degree turn has no joint path either way round
    robot = RobotConfig(home_q_rad=(0.0, -0.3, 0.0, -2.2, 0.0, 1.9, math.pi / 4))
    scene = _scene(trials=2, methods=[MethodSpec("supermag", MODEL)], robot=robot,
                   presentation=PresentationConfig(angle_deg=(-80.0, -80.0), objects=THIN_RODS))
    records = _run(scene)
    assert [r.outcome for r in records] == ["ik_failed", "ik_failed"]
    assert "no IK solution" in records[0].detail and "did not move" in records[0].detail


def test_a_refused_target_is_recorded_as_a_safety_refusal() -> None:
    robot = RobotConfig(safety=SafetyLimits(max_rotation_rad=0.01))
    scene = _scene(trials=2, methods=[MethodSpec("supermag", MODEL)], robot=robot,
                   presentation=PresentationConfig(angle_deg=(40.0, 50.0), objects=THIN_RODS))
    assert [r.outcome for r in _run(scene)] == ["safety_refused", "safety_refused"]


def test_the_abstain_policy_counts_an_empty_grasp_as_abstained() -> None:
    # a procedural dome is round: the angle is undefined, the abstain policy does not act
    dome = TrialObject("procedural", "dome", {"seed": 3}, width_mm=4.0)
    behaviour = dataclasses.replace(_scene().behaviour, low_confidence="abstain", min_confidence=0.99)
    scene = _scene(trials=1, methods=[MethodSpec("bilinear", "bilinear", output_px=16)], behaviour=behaviour,
                   presentation=PresentationConfig(objects=[dome]))
    (record,) = _run(scene)
    assert record.outcome == "abstained" and record.action == "abstain"


def test_run_trials_writes_log_summary_and_plots(tmp_path) -> None:
    summary = run_trials(_scene(trials=2), tmp_path / "run", progress=False)
    files = {p.name for p in (tmp_path / "run").iterdir()}
    assert {"trials.jsonl", "run.json", "summary.md", "summary.json", "errors.png", "success_vs_tolerance.png"} <= files
    assert len(read_trials(tmp_path / "run")) == 4
    assert summary.methods["supermag"].n == 2


def test_the_shipped_scenes_load() -> None:
    paths = [*sorted((REPO / "configs/scenes").glob("reorient_*.toml")), *sorted((REPO / "tasks").glob("*.toml"))]
    assert REPO / "configs/scenes/reorient_fr3.toml" in paths
    for path in paths:
        scene = load_scene(path)
        assert scene.presentation.objects and scene.methods, path
    robust = load_scene(REPO / "configs/scenes/reorient_robust.toml")
    assert robust.presentation.force_n == (2.0, 15.0) and robust.presentation.sensor_spread == 1.0
    assert robust.trials >= 300 and [m.name for m in robust.methods] == ["supermag", "supermag_esc", "bilinear"]
    assert robust.methods[1].escalate_below == 0.5 and robust.methods[1].escalation == "symmetry"
    assert robust.behaviour.min_confidence == 0.8  # compared with the calibrated confidence


def test_the_real_robot_scene_parses_into_the_simulated_scenes_trials_on_franky_and_a_serial_board() -> None:
    """Parsing needs no robot: the FR3 scene is the simulated scene's presentations, methods and behaviour, run
    by the franky backend at low dynamics inside its workspace, with the board on a serial port."""
    from tactile_manip.sensors.config import SerialSensorConfig

    fr3 = load_scene(REPO / "configs/scenes/reorient_fr3.toml")
    sim = load_scene(REPO / "configs/scenes/reorient_sim.toml")
    assert (fr3.name, fr3.trials, fr3.tolerance_deg, fr3.target_deg) == ("reorient_fr3", 12, 5.0, 0.0)
    assert (fr3.presentation, fr3.methods, fr3.behaviour) == (sim.presentation, sim.methods, sim.behaviour)
    assert (fr3.robot.backend, fr3.robot.host, fr3.robot.relative_dynamics_factor) == ("franky", "172.16.0.2", 0.05)
    assert fr3.robot.safety.workspace_min_m == (0.25, -0.4, 0.1) and fr3.robot.safety.max_speed_factor == 0.3
    assert isinstance(fr3.sensor, SerialSensorConfig)
    assert (fr3.sensor.port, fr3.sensor.serial_number, fr3.sensor.dtr) == ("/dev/ttyUSB0", "", False)
    assert not fr3.faults.arm_fault_trials and not fr3.faults.sensor_stall_trials  # no injected faults on a robot


@pytest.mark.parametrize("scene_file", ["configs/scenes/reorient_sim.toml", "configs/scenes/reorient_robust.toml"])
def test_the_shipped_scenes_use_the_calibration_beside_their_model(scene_file) -> None:
    """The calibration files shipped beside the models fit the trials' estimators (prior samples, symmetry,
    the pose aperture); one that did not would be dropped and the re-grasp policy would read raw confidence."""
    estimators = build_pose_estimators(load_scene(REPO / scene_file))
    assert estimators["supermag"].calibration is not None
    assert estimators["bilinear"].calibration is None


def test_the_cell_wires_the_grasp_to_the_sensor() -> None:
    cell = SimulatedCell(_scene())
    with cell.connected():
        p = draw_presentation(cell.scene, 0)
        with cell.presented(p) as (obj, truth):
            assert not np.any(cell.sensor.contact_field_ut)
            assert cell.gripper.grasp(obj.width_m, 10.0).success
            assert np.abs(cell.sensor.contact_field_ut).max() > 20.0   # the rod's field, uT
            assert np.allclose(truth.object_pose_base(), cell.world.object_pose(obj))
        assert not np.any(cell.sensor.contact_field_ut)                 # released: the pad is empty again


@pytest.mark.slow
def test_killing_a_run_loses_no_completed_trial_and_resume_finishes_it(tmp_path) -> None:
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text(f'''name = "kill"
trials = 40
seed = 1
[[methods]]
name = "supermag"
reconstructor = "{MODEL}"
[[presentation.objects]]
name = "cylinder"
kwargs = {{ size_mm = 3.0 }}
''')
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "tactile_manip.cli", "trials", "--config", str(scene_file), "--out", str(out),
           "--quiet"]
    proc = subprocess.Popen(cmd, cwd=REPO, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    log = out / "trials.jsonl"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if log.exists() and log.read_text().count("\n") >= 5:
            break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    lines = [ln for ln in log.read_text().split("\n") if ln.strip()]
    complete = [json.loads(ln) for ln in lines if ln.endswith("}")]
    assert 5 <= len(complete) < 40
    assert [r["trial"] for r in complete] == list(range(len(complete)))
    done = subprocess.run(cmd + ["--resume"], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    records = read_trials(out)
    assert sorted(r.trial for r in records) == list(range(40))
    assert [r.to_dict() for r in records[:len(complete)]] == complete


# ---------------------------------------------------------------- the operator cell (real-robot path)


class _ScriptedOperator:
    """Stands in for the person at a real robot, using the twin world to present and measure the object."""

    def __init__(self, sim: SimulatedCell, answer_blank_on: set[int]) -> None:
        self.sim, self.blank, self.trial, self.obj = sim, answer_blank_on, -1, None
        self.said: list[str] = []

    def say(self, text: str) -> None:
        self.said.append(text)
        if text.startswith("trial "):
            self.trial = int(text.split(":")[0].split()[1])

    def ask(self, prompt: str) -> str:
        from tactile_manip.robot.frames import angle_in_plane, hand_T_finger_pad
        from tactile_manip.robot.twin import WorldObject
        from tactile_manip.trials.presentation import pad_T_object

        sim = self.sim
        if prompt.startswith("press Enter when it is in place"):
            p = draw_presentation(sim.scene, self.trial)
            self.obj = WorldObject(p.obj.display_name, p.obj.grasp_width_m, payload=sim._indenters[p.obj.display_name])
            sim._presentation = p
            sim.world.present(self.obj, hand_T_finger_pad(self.obj.width_m)
                              @ pad_T_object(p.angle_rad, p.offset_mm, self.obj.width_m))
            self.base_T_pad = sim.arm.state().base_T_hand @ hand_T_finger_pad(self.obj.width_m)
        elif prompt.startswith("measured final angle"):
            if self.trial in self.blank:
                return ""
            axis = sim.world.object_pose(self.obj)[:3, 0]
            return f"{math.degrees(angle_in_plane(axis, self.base_T_pad)):.3f}"
        elif prompt.startswith("take the object out"):
            sim.world.remove(self.obj)
        return ""


def test_the_operator_cell_runs_the_same_behaviour_with_a_person_in_the_loop() -> None:
    from tactile_manip.trials.operator import OperatorCell

    scene = _scene(trials=3, methods=[MethodSpec("supermag", MODEL)])
    sim = SimulatedCell(scene)
    person = _ScriptedOperator(sim, answer_blank_on={2})
    cell = OperatorCell(scene, arm=sim.arm, gripper=sim.gripper, sensor=sim.sensor, ask=person.ask, say=person.say)
    records = []
    run_scene(scene, records.append, estimators=build_tactile_estimators(scene), progress=False, cell=cell)
    assert [r.outcome for r in records] == ["done", "done", "unmeasured"], [r.detail for r in records]
    assert all(abs(r.error_rad) < math.radians(5.0) for r in records[:2])
    assert any("between the fingers" in s for s in person.said)


def test_the_operator_cell_logs_the_grip_force_of_the_scenes_contact_model() -> None:
    from tactile_manip.trials.operator import OperatorCell

    scene = _scene(trials=2, methods=[MethodSpec("bilinear", "bilinear", output_px=16)],
                   contact_model=str(REPO / "models" / "contact_supermag.onnx"))
    sim = SimulatedCell(scene)
    person = _ScriptedOperator(sim, answer_blank_on=set())
    cell = OperatorCell(scene, arm=sim.arm, gripper=sim.gripper, sensor=sim.sensor, ask=person.ask, say=person.say)
    records = []
    run_scene(scene, records.append, progress=False, cell=cell,
              estimators=build_tactile_estimators(scene, layout=cell.sensor.layout.name))
    assert [r.outcome for r in records] == ["done", "done"], [r.detail for r in records]
    for r in records:
        assert abs(r.estimated_grip_force_n - r.extra["force_n"]) < 3 * r.estimated_grip_force_sigma_n
        assert r.extra["commanded_force_n"] == scene.behaviour.force_n


def test_the_operator_cell_needs_a_real_sensor_and_no_injected_faults() -> None:
    from tactile_manip.errors import ConfigError
    from tactile_manip.trials.operator import OperatorCell

    with pytest.raises(ConfigError, match="port"):
        OperatorCell(_scene(), arm=object(), gripper=object())
    with pytest.raises(ConfigError, match="only in simulation"):
        OperatorCell(_scene(faults=FaultPlan(arm_fault_trials=[0])), arm=object(), gripper=object(), sensor=object())


def test_drawn_sensors_differ_per_trial_are_shared_by_methods_and_are_recalibrated() -> None:
    scene = _scene(trials=3, presentation=PresentationConfig(objects=THIN_RODS, force_n=(2.0, 15.0),
                                                             sensor_spread=1.0))
    records = _run(scene)
    sensors = {}
    for r in records:
        assert 2.0 <= r.extra["force_n"] <= 15.0
        sensors.setdefault(r.trial, []).append(r.extra["sensor"])
    assert all(a == b for a, b in sensors.values())  # every method met the trial's sensor
    remanence = [s[0]["magnet.remanence_t"] for s in sensors.values()]
    assert len(set(remanence)) == 3 and all(0.03 <= j <= 0.055 for j in remanence)
    cell = SimulatedCell(scene)
    with cell.connected():
        cell._use_sensor_of(draw_presentation(scene, 1))
        assert cell.sensor.pair.params == draw_presentation(scene, 1).sensor_params()
        unloaded = cell.sensor.wait_new(timeout_s=1.0).field_ut
        assert np.abs(unloaded).max() < 60.0  # the new baseline holds: only chip noise, no stale offset
    nominal = _run(_scene(trials=1))
    assert "sensor" not in nominal[0].extra


def test_a_model_whose_graph_does_not_match_its_metadata_stops_the_run_before_the_first_trial(
        tmp_path, graph_with_shipped_metadata) -> None:
    from tactile_manip.perception.reconstruct import ModelFileError

    foreign = graph_with_shipped_metadata("identity")
    scene = _scene(methods=[MethodSpec("bilinear", "bilinear", output_px=16), MethodSpec("copied", str(foreign))])
    with pytest.raises(ModelFileError, match="does not match its tactile_manip metadata"):
        run_trials(scene, tmp_path / "run", progress=False)
    assert not (tmp_path / "run" / "trials.jsonl").exists()  # no trial ran, not even for the good method


def test_a_method_names_where_its_angle_comes_from_and_the_main_job_runs_the_papers_route() -> None:
    scene = _scene(methods=[MethodSpec("supermag", MODEL), MethodSpec("paper_route", MODEL, angle_source="image")])
    est = build_pose_estimators(scene)
    assert est["supermag"].angle_head is not None and est["supermag"].angle_source == "head"  # "auto": the head
    assert est["paper_route"].angle_head is None and est["paper_route"].angle_source == "image"
    main = {m.name: m for m in load_scene(REPO / "configs" / "scenes" / "reorient_sim.toml").methods}
    assert main["paper_route"].angle_source == "image"
    assert main["paper_route"].reconstructor == main["supermag"].reconstructor
    with pytest.raises(ValueError, match="angle_source must be one of auto, image, head, likelier"):
        MethodSpec("x", MODEL, angle_source="pca")


def test_the_place_task_runs_through_the_runner_and_its_success_needs_the_slot_clearance(tmp_path) -> None:
    from tactile_manip.behaviours.place import PlaceConfig

    scene = _scene(trials=3, task="place", task_config=PlaceConfig(clearance_mm=1.0),
                   methods=[MethodSpec("supermag", MODEL), MethodSpec("bilinear", "bilinear", output_px=16)])
    summary = run_trials(scene, tmp_path / "run", progress=False)
    records = read_trials(tmp_path / "run" / "trials.jsonl")
    assert {r.task for r in records} == {"place"} and len(records) == 6
    for r in records:
        assert r.outcome == "done" and r.clearance_mm == 1.0 and r.lateral_error_mm is not None
        assert r.succeeded(math.radians(5.0)) == (abs(r.error_rad) <= math.radians(5.0) and r.lateral_error_mm <= 1.0)
    ours = [r for r in records if r.method == "supermag"]
    assert all(r.lateral_error_mm < 0.5 for r in ours)            # the centroid puts the axis onto the slot
    doc = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert doc["task"] == "place" and doc["title"].startswith("Slot placement trials")
    assert summary.methods["supermag"].successes == sum(r.succeeded(math.radians(5.0)) for r in ours)
    assert "## Lateral error (placed rods)" in (tmp_path / "run" / "summary.md").read_text()


def test_a_reorientation_run_names_its_task_and_a_bad_task_is_refused(tmp_path) -> None:
    run_trials(_scene(trials=1, methods=[MethodSpec("bilinear", "bilinear", output_px=16)]), tmp_path / "r",
               progress=False)
    assert json.loads((tmp_path / "r" / "summary.json").read_text())["task"] == "reorient"
    assert {r.task for r in read_trials(tmp_path / "r" / "trials.jsonl")} == {"reorient"}
    with pytest.raises(ValueError, match="task must be one of reorient, place, grip"):
        _scene(task="insert")
    with pytest.raises(ValueError, match="simulated cell only"):
        _scene(task="place", robot=RobotConfig(backend="franky", host="172.16.0.2"))


def test_the_blind_baseline_reads_the_sensor_and_answers_the_prior(tmp_path) -> None:
    scene = _scene(trials=3, methods=[MethodSpec("blind", "blind")])
    est = build_pose_estimators(scene)["blind"]
    assert est.calibration is None and est.angle_head is None
    records = _run(scene)
    assert [r.method for r in records] == ["blind"] * 3
    for r in records:  # the rod taken along the pad's x axis: the error is the presented angle itself
        assert r.defined and r.estimated_angle_rad == 0.0 and r.confidence == 1.0
        assert r.outcome == "done" and abs(r.error_rad) == pytest.approx(abs(r.true_angle_rad), abs=math.radians(1))
    main = {m.name: m.reconstructor for m in load_scene(REPO / "configs" / "scenes" / "reorient_sim.toml").methods}
    place = {m.name: m.reconstructor for m in load_scene(REPO / "configs" / "scenes" / "place_sim.toml").methods}
    assert main["blind"] == place["blind"] == "blind"


def test_the_grip_task_runs_through_the_runner_with_a_contact_model_per_method(tmp_path) -> None:
    from tactile_manip.behaviours.grip import GripConfig
    from tactile_manip.behaviours.skills import BehaviourConfig

    contact = str(REPO / "models" / "contact_supermag.onnx")
    scene = _scene(trials=3, task="grip", task_config=GripConfig(force_tolerance_n=1.5, centre_tolerance_mm=0.5),
                   behaviour=BehaviourConfig(force_n=8.0),
                   presentation=PresentationConfig(force_n=(5.0, 11.0), objects=THIN_RODS),
                   methods=[MethodSpec("supermag", MODEL, contact_model=contact), MethodSpec("blind", "blind")])
    summary = run_trials(scene, tmp_path / "run", progress=False)
    records = read_trials(tmp_path / "run" / "trials.jsonl")
    assert {r.task for r in records} == {"grip"} and len(records) == 6
    for r in records:
        assert r.outcome == "done" and r.force_tolerance_n == 1.5 and r.clearance_mm == 0.5
        applied = r.extra["applied_force_n"]
        assert r.force_error_n == pytest.approx(applied - 8.0, abs=1e-3)
        # the force felt is the presentation's at the target command, in proportion to the last command
        assert applied == pytest.approx(r.extra["force_n"] * r.extra["final_command_n"] / 8.0, rel=1e-3)
        assert r.succeeded(math.radians(5.0)) == (abs(r.error_rad) <= math.radians(5.0)
                                                  and r.lateral_error_mm <= 0.5 and abs(r.force_error_n) <= 1.5)
    blind = [r for r in records if r.method == "blind"]
    assert all(r.extra["final_command_n"] == 8.0 and r.estimated_grip_force_n is None for r in blind)
    ours = [r for r in records if r.method == "supermag"]
    assert all(r.estimated_grip_force_n is not None and r.lateral_error_mm < 0.5 for r in ours)  # centred
    doc = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert doc["task"] == "grip" and doc["title"].startswith("Grip-to-force trials")
    assert summary.methods["supermag"].successes == sum(r.succeeded(math.radians(5.0)) for r in ours)
    text = (tmp_path / "run" / "summary.md").read_text()
    assert "## Grip force: what the rod felt against the target" in text and "## Centring" in text


def test_a_grip_scene_needs_a_contact_model_and_the_simulated_cell() -> None:
    with pytest.raises(ValueError, match="needs a contact_model"):
        _scene(task="grip")
    with pytest.raises(ValueError, match="simulated cell only"):
        _scene(task="grip", contact_model="models/contact_supermag.onnx",
               robot=RobotConfig(backend="franky", host="172.16.0.2"))
    with pytest.raises(ValueError, match="contact_model must be an exported .onnx"):
        MethodSpec("x", MODEL, contact_model="contact.pt")
