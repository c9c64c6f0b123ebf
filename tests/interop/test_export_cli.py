"""``tactile-manip export SOURCE --format F --out OUT``: whole outputs or none, --force, damaged sources."""

from __future__ import annotations

import json
import shutil

import pytest

pytest.importorskip("pyarrow", reason="the LeRobot export needs pyarrow (extra 'lerobot')")
pytest.importorskip("pandas", reason="the LeRobot export needs pandas (extra 'lerobot')")

from tactile_manip.cli import main  # noqa: E402
from tactile_manip.trials.frames import frames_path  # noqa: E402
from tactile_manip.trials.log import read_trials  # noqa: E402


def _error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert err and err[-1].startswith("tactile-manip export: error: "), err
    return err[-1]


def _leftovers(folder) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if ".tmp-" in p.name or ".old-" in p.name)


def test_a_trial_run_exports_to_a_lerobot_dataset(trial_run, tmp_path, capsys) -> None:
    out = tmp_path / "DS"
    assert main(["export", str(trial_run), "--format", "lerobot", "--out", str(out)]) == 0
    assert "9 episodes" in capsys.readouterr().out
    info = json.loads((out / "meta" / "info.json").read_text())
    assert info["total_episodes"] == 9 and info["fps"] == 125
    assert info["features"]["observation.tactile.field"]["shape"] == [48]
    assert _leftovers(tmp_path) == []


def test_an_earlier_export_is_refused_without_force_and_replaced_whole_with_it(recording, make_recording, tmp_path,
                                                                              capsys) -> None:
    out = tmp_path / "DS"
    short = make_recording(tmp_path / "short.tmrec", seconds=1.0)
    assert main(["export", str(short), "--format", "lerobot", "--out", str(out)]) == 0
    assert main(["export", str(recording), "--format", "lerobot", "--out", str(out)]) == 2
    assert "exists; pass --force" in _error_line(capsys)
    assert json.loads((out / "meta" / "info.json").read_text())["total_frames"] == 125
    assert main(["export", str(recording), "--format", "lerobot", "--out", str(out), "--force"]) == 0
    assert json.loads((out / "meta" / "info.json").read_text())["total_frames"] == 1250
    assert _leftovers(tmp_path) == []


def test_a_failure_while_writing_leaves_nothing_under_the_final_name(recording, tmp_path, capsys,
                                                                     monkeypatch) -> None:
    from tactile_manip.interop import lerobot

    def disk_full(*args, **kwargs):
        raise OSError(28, "No space left on device", "meta/episodes")

    monkeypatch.setattr(lerobot, "_write_episodes", disk_full)  # after the frames were written
    out = tmp_path / "DS"
    assert main(["export", str(recording), "--format", "lerobot", "--out", str(out)]) == 2
    assert "No space left on device" in _error_line(capsys)
    assert not out.exists() and _leftovers(tmp_path) == []
    monkeypatch.undo()
    assert main(["export", str(recording), "--format", "lerobot", "--out", str(out)]) == 0
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    monkeypatch.setattr(lerobot, "_write_episodes", disk_full)
    assert main(["export", str(recording), "--format", "lerobot", "--out", str(out), "--force"]) == 2
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before and _leftovers(tmp_path) == []


def test_a_damaged_source_exports_what_is_intact_and_lists_what_was_skipped(trial_run, tmp_path, capsys) -> None:
    run = tmp_path / "R"
    shutil.copytree(trial_run, run)
    first = read_trials(run)[0]
    frames_path(run, first.trial, first.method).unlink()
    assert main(["export", str(run), "--format", "lerobot", "--out", str(tmp_path / "DS")]) == 0
    captured = capsys.readouterr()
    assert "8 episodes" in captured.out and "1 damaged or missing parts skipped" in captured.out
    assert f"skipped: trial 0 ({first.method}): no frames file" in captured.err
    ours = json.loads((tmp_path / "DS" / "meta" / "tactile.json").read_text())
    assert len(ours["source"]["skipped"]) == 1


def test_a_format_whose_writer_is_missing_gives_one_line_and_writes_nothing(recording, tmp_path, capsys,
                                                                            monkeypatch) -> None:
    from tactile_manip.interop import export

    monkeypatch.setitem(export.WRITERS, "rrd", "tactile_manip.interop.no_such_writer:write_rrd")
    assert main(["export", str(recording), "--format", "rrd", "--out", str(tmp_path / "x.rrd")]) == 2
    assert "no rrd writer" in _error_line(capsys)
    assert list(tmp_path.iterdir()) == []


def test_a_writer_whose_extra_is_missing_names_it_before_reading_the_source(recording, tmp_path, capsys,
                                                                          monkeypatch) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "mcap", None)  # as if not installed: importing it raises ImportError
    assert main(["export", str(recording), "--format", "mcap", "--out", str(tmp_path / "x.mcap")]) == 2
    captured = capsys.readouterr()
    assert "read " not in captured.out  # nothing was read before the refusal
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("tactile-manip export: error: ") and ".[mcap]" in err[0], err
    assert list(tmp_path.iterdir()) == []


def test_depth_from_a_model_becomes_an_image_feature(recording, tmp_path) -> None:
    out = tmp_path / "DS"
    assert main(["export", str(recording), "--format", "lerobot", "--out", str(out), "--depth", "bilinear"]) == 0
    info = json.loads((out / "meta" / "info.json").read_text())
    assert info["features"]["observation.images.tactile_depth"]["dtype"] == "image"
    ours = json.loads((out / "meta" / "tactile.json").read_text())
    assert ours["source"]["depth_model"]["model"] == "bilinear"
    assert ours["episodes"][0]["baseline_for_depth"].startswith("mean of the first 125 frames")


def test_depth_without_a_model_takes_the_shipped_one_from_any_folder(recording, tmp_path, monkeypatch,
                                                                     capsys) -> None:
    pytest.importorskip("onnxruntime", reason="the shipped model runs on onnxruntime")
    from pathlib import Path

    monkeypatch.chdir(tmp_path)  # not the repository root: models/ is not here
    assert main(["export", str(recording), "--format", "lerobot", "--out", "DS", "--depth"]) == 0
    ours = json.loads((tmp_path / "DS" / "meta" / "tactile.json").read_text())["source"]["depth_model"]
    shipped = Path(__file__).resolve().parents[2] / "models" / "supermag.onnx"
    assert ours["model"] == "supermag" and ours["path"] == str(shipped)
    assert ours["metadata"]["image_symmetry"] == "rotations"  # offline: the file's four-pass average
    capsys.readouterr()
    assert main(["export", str(recording), "--format", "lerobot", "--out", "DS2", "--depth", "models/none.onnx"]) == 2
    line = _error_line(capsys)  # names the file it looked for, where, and the shipped default by its full path
    assert "models/none.onnx (looked in " in line and str(shipped) in line


@pytest.mark.parametrize("argv, message", [
    (["REC", "--out", "DS"], "SOURCE needs --format"),
    (["REC", "--format", "lerobot", "--checkpoint", "best.pt", "--out", "DS"], "either SOURCE"),
    (["REC", "--format", "lerobot", "--ros2", "--out", "DS"], "--ros2 is an option of --format mcap"),
    (["REC", "--format", "lerobot", "--card", "c.md", "--out", "DS"], "--card: only for --checkpoint"),
    (["--out", "m.onnx"], "give SOURCE with --format"),
    (["--checkpoint", "best.pt", "--format", "lerobot", "--out", "m.onnx"], "--format converts a SOURCE"),
])
def test_mixed_up_options_are_refused_with_one_line(argv, message, recording, tmp_path, capsys) -> None:
    argv = [str(recording) if a == "REC" else str(tmp_path / a) if a in ("DS", "m.onnx") else a for a in argv]
    assert main(["export", *argv]) == 2
    assert message in _error_line(capsys)
    assert list(tmp_path.iterdir()) == []


def test_the_interop_modules_import_pyarrow_and_pandas_only_when_writing() -> None:
    import subprocess
    import sys

    code = ("import sys, tactile_manip.interop.export, tactile_manip.interop.lerobot, tactile_manip.interop.sources, "
            "tactile_manip.trials.frames, tactile_manip.commands.export; "
            "print(sorted(m for m in ('pyarrow', 'pandas', 'torch', 'onnxruntime', 'PIL') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
