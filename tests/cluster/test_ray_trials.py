"""``trials --ray`` on a private local Ray instance: the local run's outcomes per seed, the log in trial order,
``--resume``, and one-line refusals (extra ``ray``)."""

import importlib.util
import json
import math

import pytest
from checks import assert_one_line_error

if importlib.util.find_spec("ray") is None:  # not imported here: ray_session sets its environment before import
    pytest.skip("the 'ray' extra is not installed", allow_module_level=True)
pytest.importorskip("roboticstoolbox", reason="the simulated trial cell needs roboticstoolbox-python")
pytest.importorskip("onnxruntime", reason="the scene's model methods need onnxruntime")

from tactile_manip.cli import main  # noqa: E402

pytestmark = [pytest.mark.ray, pytest.mark.slow]
SCENE = "configs/scenes/reorient_sim.toml"


def _outcomes(run):
    """(trial, method, outcome, within 5 deg) per line, in file order. Float values are not compared: the simulated
    sensor's noise frame depends on timing, so two local runs differ in the third decimal of a degree too."""
    rows = [json.loads(line) for line in (run / "trials.jsonl").read_text().splitlines()]
    return [(r["trial"], r["method"], r["outcome"], r["error_rad"] is not None and abs(r["error_rad"]) <= math.radians(5))
            for r in rows]


@pytest.fixture(scope="module")
def local_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("local") / "R"
    assert main(["trials", "--config", SCENE, "--trials", "5", "--out", str(out), "--quiet", "--no-frames"]) == 0
    return out


def test_ray_trials_log_the_local_outcomes_in_trial_order(local_run, tmp_path):
    out = tmp_path / "R"
    assert main(["trials", "--config", SCENE, "--trials", "5", "--out", str(out), "--quiet", "--ray", "--workers", "2",
                 "--block-trials", "2"]) == 0
    got = _outcomes(out)
    assert got == _outcomes(local_run)
    assert [t for t, *_ in got] == sorted(t for t, *_ in got)
    assert len(list((out / "frames").glob("*.tmframes"))) == len(got)  # written by the workers into the run folder
    assert (out / "summary.json").is_file()


def test_ray_trials_resume_a_killed_run(local_run, tmp_path):
    out = tmp_path / "R"
    out.mkdir()
    for name in ("run.json",):
        (out / name).write_text((local_run / name).read_text())
    lines = (local_run / "trials.jsonl").read_text().splitlines(keepends=True)
    (out / "trials.jsonl").write_text("".join(lines[:4]) + lines[4][:20])  # four trials and a torn line
    assert main(["trials", "--config", SCENE, "--trials", "5", "--out", str(out), "--quiet", "--no-frames",
                 "--ray", "--workers", "2", "--resume"]) == 0
    assert _outcomes(out) == _outcomes(local_run)


@pytest.mark.parametrize("argv, message", [
    (["--ray", "--rerun"], "cannot watch Ray workers"),
    (["--block-trials", "2"], "apply to --ray runs only"),
    (["--ray", "--block-trials", "0"], "--block-trials must be >= 1"),
    (["--ray", "127.0.0.1:9"], "cannot reach the Ray cluster at 127.0.0.1:9"),
])
def test_bad_ray_options_are_one_line_and_make_no_run_folder(tmp_path, capsys, argv, message):
    out = tmp_path / "R"
    assert main(["trials", "--config", SCENE, "--trials", "2", "--out", str(out), "--quiet", *argv]) == 2
    assert_one_line_error(capsys.readouterr().err, "trials", message)
    assert not out.exists()
