"""The calibration-time benchmark: its routes, how it splits a command's time by stage, and its table (no
calibration is run here)."""

from __future__ import annotations

import io
import re
import sys
from pathlib import Path

import pytest

from benchmarks.calibrate_time import (
    GOAL_S,
    ROUTES,
    STAGES,
    Case,
    Step,
    claimed_total_s,
    manifold_route,
    markdown,
    run_step,
)
from tactile_manip.progress import progress_bar


def test_the_manifold_route_is_the_owner_s_four_commands_and_splits_train_at_the_labeller_s_last_line() -> None:
    steps, results = manifold_route(Case(Path("runs"), "spatial_20250316_155729", 25, 1, Path("work")))
    assert [s.argv[0] for s in steps] == ["import", "train", "export", "evaluate"]
    assert [s.stage for s in steps] == ["import", "train", "export", "evaluate"]
    assert steps[0].argv[steps[0].argv.index("--labelled") + 1] == "25"
    assert steps[0].argv[steps[0].argv.index("--seed") + 1] == "1"
    assert "configs/train/contact_fewlabel.toml" in steps[1].argv
    assert results == Path("work/ev_spatial_20250316_155729_25_1/results.json")
    stage, pattern = steps[1].split
    assert stage == "label" and set(ROUTES) == {"manifold"}
    # the pattern is that of the labeller's own closing lines, not of its lines while it runs
    log = io.StringIO()
    bar = progress_bar(total=2, desc="labelling: placing the unlabelled presses", unit="start", stream=log,
                       heartbeat_s=0.0)
    bar.update()
    bar.close()
    running, closing = log.getvalue().splitlines()
    assert re.match(pattern, closing) and not re.match(pattern, running)


def test_a_command_s_time_is_split_at_the_last_marked_line_and_its_longest_silence_kept() -> None:
    script = ("import time; print('labelling: a: 1/1 map in 0.0 s', flush=True); time.sleep(0.6); "
              "print('labelling: b: 1/1 start in 0.6 s', flush=True); time.sleep(1.5); print('done')")
    done = run_step(Step("train", (), split=("label", r"^labelling: .* in [0-9.]+ s$")),
                    program=(sys.executable, "-c", script))
    assert set(done["stages"]) == {"label", "train"}
    # lines are timed when read: on a busy machine a line may arrive late, moving time from train to label, so
    # train is held to half its sleep
    assert done["stages"]["label"] >= 0.6 and done["stages"]["train"] >= 0.75
    assert done["stages"]["label"] + done["stages"]["train"] == pytest.approx(done["wall_s"])
    assert 0.75 <= done["longest_silence_s"] < done["wall_s"]
    assert done["lines"][-1] == "done" and done["cpu_s"] >= 0.0
    unmarked = run_step(Step("export", ()), program=(sys.executable, "-c", "print('x')"))
    assert set(unmarked["stages"]) == {"export"}


def test_a_failing_command_stops_the_benchmark_with_its_last_lines() -> None:
    with pytest.raises(SystemExit, match="failed \\(3\\):\nwhat went wrong"):
        run_step(Step("import", ()), program=(sys.executable, "-c", "print('what went wrong'); raise SystemExit(3)"))


def test_the_table_shows_every_stage_the_total_against_the_goal_and_the_error() -> None:
    row = {"run": "spatial_20250316_155729", "route": "manifold", "k": 25, "seed": 0, "cpu_s": 270.0,
           "stages_s": {"import": 1.0, "label": 140.0, "train": 125.0, "export": 4.0, "evaluate": 6.0},
           "total_s": 276.0, "within_goal": True, "longest_silence_s": 21.0, "train_says_s": 262.0,
           "error": {"ours": 1.1, "kNN": 6.9}, "figure": "position_rmse_mm",
           "other_load": {"other_processes_cores": 0.1}}
    text = markdown({"machine": {"load_average": (0.1, 0.2, 0.3)}, "goal_s": GOAL_S, "cases": [row]})
    assert "| spatial | manifold | 25 | 0 | 1 | 140 | 125 | 4 | 6 | 4.6 min | 4.5 min | yes | 21 | 1.100 mm | 6.900 | 0.10 |" \
        in text, text
    assert len(STAGES) == 5 and f"<= {GOAL_S / 60:.0f} min" in text
    # a route of other stages (a twin's fit and simulation) adds their columns; the stages a row lacks show "-"
    twin = {**row, "route": "twin", "stages_s": {"fit": 120.0, "simulate": 60.0, "train": 100.0, "export": 4.0,
                                                 "evaluate": 6.0}}
    text = markdown({"machine": {"load_average": None}, "goal_s": GOAL_S, "cases": [row, twin]})
    assert "| evaluate s | fit s | simulate s | total |" in text
    assert "| spatial | twin | 25 | 0 | - | - | 100 | 4 | 6 | 120 | 60 |" in text
    assert "| spatial | manifold | 25 | 0 | 1 | 140 | 125 | 4 | 6 | - | - |" in text


def test_train_s_own_account_of_its_time_is_read_in_seconds() -> None:
    assert claimed_total_s(["x", "validation RMSE ...; labelling 95 s, network 80 s, train in all 3.1 min; wrote"]) \
        == pytest.approx(186.0)
    assert claimed_total_s(["train in all 58 s"]) == 58.0 and claimed_total_s(["nothing"]) is None
