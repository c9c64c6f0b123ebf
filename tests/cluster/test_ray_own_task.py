"""A task of one's own (docs/your_task.md) on Ray: a module outside the package, named by the scene, imports on the
workers of a private instance, and the Ray run logs what the local run logs (extra 'ray')."""

import importlib.util
import json
from pathlib import Path

import pytest

if importlib.util.find_spec("ray") is None:  # not imported here: ray_session sets its environment before import
    pytest.skip("the 'ray' extra is not installed", allow_module_level=True)
pytest.importorskip("roboticstoolbox", reason="the simulated trial cell needs roboticstoolbox-python")
pytest.importorskip("onnxruntime", reason="the scene's model methods need onnxruntime")

from tactile_manip.cli import main  # noqa: E402

pytestmark = [pytest.mark.ray, pytest.mark.slow]
REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "examples" / "your_task"


def _rows(run: Path) -> list[tuple]:
    rows = [json.loads(line) for line in (run / "trials.jsonl").read_text().splitlines()]
    return [(r["trial"], r["method"], r["task"], r["outcome"],
             r["error_rad"] is not None and abs(r["error_rad"]) < 0.05) for r in rows]


def test_a_task_module_outside_the_package_runs_on_ray_as_locally(tmp_path, monkeypatch) -> None:
    (tmp_path / "their_lab").mkdir()
    (tmp_path / "their_lab" / "lifting.py").write_text((EXAMPLE / "lift.py").read_text())
    scene = (EXAMPLE / "lift_sim.toml").read_text().replace('"examples.your_task.lift:Lift"',
                                                            '"their_lab.lifting:Lift"')
    scene = scene.replace('"models/supermag.onnx"', f'"{REPO / "models" / "supermag.onnx"}"')
    (tmp_path / "lift.toml").write_text(scene.replace("trials = 6", "trials = 3"))
    monkeypatch.chdir(tmp_path)
    assert main(["trials", "--config", "lift.toml", "--out", "local", "--quiet"]) == 0
    assert main(["trials", "--config", "lift.toml", "--out", "ray", "--quiet", "--ray", "--workers", "2",
                 "--block-trials", "2"]) == 0
    assert _rows(tmp_path / "ray") == _rows(tmp_path / "local")
    assert {r[2] for r in _rows(tmp_path / "ray")} == {"lift"}
    doc = json.loads((tmp_path / "ray" / "summary.json").read_text())
    assert doc["task"] == "lift" and "lift_change" in doc
