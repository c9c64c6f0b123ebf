"""The documented contact workflow on the real eFlesh development runs, with the acceptance figures.

import -> train (configs/train/contact.toml, default settings) -> export -> evaluate, through the CLI, on the
chronological 80/20 split of each run: 2-D localisation RMSE <= 0.5 mm on the spatial run, normal force RMSE
<= 0.27 N on the normal-force run, both better than the plain-MLP baseline evaluate prints beside them, and
68 +- 7 % of the test errors within 1 sigma (each exported model carries a sigma map per target). Minutes of
CPU: marked slow.
"""

from __future__ import annotations

import json

import pytest

from tactile_manip.cli import main

pytest.importorskip("torch", reason="training needs torch")
pytest.importorskip("onnxruntime", reason="evaluating the exported model needs onnxruntime")

SPATIAL = "spatial_20250316_155729"
NORMAL = "normal_20250401_014340"


def _run(run_dir, tmp_path, name: str, import_args: list[str]) -> dict:
    data = tmp_path / f"{name}.npz"
    assert main(["import", "--readings-csv", str(run_dir / "sensor_post_baselines.csv"),
                 "--labels-csv", str(run_dir / "states.csv"), *import_args, "--board", "eflesh",
                 "--out", str(data)]) == 0
    assert main(["train", "--config", "configs/train/contact.toml", "--data", str(data),
                 "--out", str(tmp_path / f"run_{name}")]) == 0
    model = tmp_path / f"{name}.onnx"
    assert main(["export", "--checkpoint", str(tmp_path / f"run_{name}" / "best.pt"), "--out", str(model)]) == 0
    from tactile_manip.perception.contact import ContactEstimator

    assert len(ContactEstimator(model).sigma_maps) == len(import_args[import_args.index("--targets") + 1].split(","))
    assert main(["evaluate", "--data", str(data), "--model", f"ours={model}",
                 "--out", str(tmp_path / f"ev_{name}")]) == 0
    return json.loads((tmp_path / f"ev_{name}" / "results.json").read_text())["methods"]


@pytest.mark.slow
def test_localisation_on_the_spatial_run(eflesh_dir, tmp_path) -> None:
    methods = _run(eflesh_dir / SPATIAL, tmp_path, "spatial",
                   ["--label-columns", "time_s,x_mm,y_mm,z_mm", "--contact", "z_mm < 145.1", "--targets", "x_mm,y_mm"])
    ours = methods["ours"]
    assert ours["position_rmse_mm"] <= 0.5
    assert ours["position_rmse_mm"] < methods["MLP"]["position_rmse_mm"]
    assert 0.61 <= ours["within_1_sigma"]["all"] <= 0.75


@pytest.mark.slow
def test_normal_force_on_the_load_cell_run(eflesh_dir, tmp_path) -> None:
    methods = _run(eflesh_dir / NORMAL, tmp_path, "normal",
                   ["--label-columns", "time_s,x_mm,y_mm,z_mm,force_gf", "--missing", "-1", "--targets", "force_n"])
    ours = methods["ours"]
    assert ours["rmse"]["force_n"] <= 0.27
    assert ours["rmse"]["force_n"] < methods["MLP"]["rmse"]["force_n"]
    assert 0.61 <= ours["within_1_sigma"]["all"] <= 0.75
