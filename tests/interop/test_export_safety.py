"""``tactile-manip export`` replaces only what it wrote itself: never the source, a folder holding it or inside it,
nor a file or folder of the user's, even with ``--force``; what an export killed midway left is removed at the
next start, and SIGTERM leaves nothing behind."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("pyarrow", reason="the LeRobot export needs pyarrow (extra 'lerobot')")
pytest.importorskip("pandas", reason="the LeRobot export needs pandas (extra 'lerobot')")
pytest.importorskip("mcap", reason="the MCAP export needs mcap (extra 'mcap')")
pytest.importorskip("rerun", reason="the Rerun export needs rerun-sdk (extra 'rerun')")

from tactile_manip.cli import main  # noqa: E402

REFUSED = "refusing to replace it: choose another --out or remove it yourself"


def _export(source: Path, fmt: str, out: Path, *extra: str) -> int:
    return main(["export", str(source), "--format", fmt, "--out", str(out), *extra])


def _error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert err and err[-1].startswith("tactile-manip export: error: "), err
    return err[-1]


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if ".tmp-" in p.name or ".old-" in p.name)


def _snapshot(path: Path) -> dict[str, bytes]:
    """Every file under ``path`` (or ``path`` itself) with its bytes."""
    if path.is_file():
        return {path.name: path.read_bytes()}
    return {str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()}


def _out_for(fmt: str, folder: Path) -> Path:
    return folder / ("DS" if fmt == "lerobot" else f"x.{fmt}")


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()  # reaped: no process has this pid now
    return child.pid


# ------------------------------------------------------------------------------- the source is never an output

@pytest.mark.parametrize("fmt", ["mcap", "rrd", "lerobot"])
def test_a_recording_given_as_its_own_out_is_refused_even_with_force(fmt, make_recording, tmp_path, capsys) -> None:
    rec = make_recording(tmp_path / "REC.tmrec", seconds=1.0)
    before = rec.read_bytes()
    assert _export(rec, fmt, rec, "--force") == 2
    assert f"{rec} is the source {rec} itself" in _error_line(capsys)
    assert rec.read_bytes() == before and _leftovers(tmp_path) == []


def test_a_symlink_or_a_hard_link_to_the_source_is_refused_as_out(make_recording, tmp_path, capsys) -> None:
    rec = make_recording(tmp_path / "REC.tmrec", seconds=1.0)
    before = rec.read_bytes()
    (tmp_path / "soft.mcap").symlink_to(rec)
    os.link(rec, tmp_path / "hard.mcap")
    for name in ("soft.mcap", "hard.mcap"):
        assert _export(rec, "mcap", tmp_path / name, "--force") == 2
        assert "is the source" in _error_line(capsys)
    assert rec.read_bytes() == before and (tmp_path / "soft.mcap").is_symlink()


def test_a_trial_run_given_as_its_own_out_or_a_folder_inside_it_is_refused(trial_run, tmp_path, capsys) -> None:
    run = tmp_path / "RUN"
    shutil.copytree(trial_run, run)
    before = _snapshot(run)
    assert _export(run, "lerobot", run, "--force") == 2
    assert f"{run} is the source {run} itself" in _error_line(capsys)
    for fmt, out in (("lerobot", run / "frames"), ("lerobot", run / "DS"), ("mcap", run / "run.mcap")):
        assert _export(run, fmt, out, "--force") == 2
        assert f"{out} is inside the source {run}" in _error_line(capsys)
    assert _snapshot(run) == before


@pytest.mark.parametrize("fmt", ["lerobot", "mcap"])
def test_a_folder_holding_the_source_is_refused_as_out(fmt, make_recording, tmp_path, capsys) -> None:
    folder = tmp_path / "session"
    folder.mkdir()
    rec = make_recording(folder / "REC.tmrec", seconds=1.0)
    (folder / "notes.txt").write_text("mine")
    before = _snapshot(folder)
    assert _export(rec, fmt, folder, "--force") == 2
    assert f"{folder} holds the source {rec}" in _error_line(capsys)
    assert _snapshot(folder) == before and _leftovers(tmp_path) == []


# --------------------------------------------------------------------- what export did not write is never replaced

@pytest.mark.parametrize("fmt", ["lerobot", "mcap", "rrd"])
def test_a_folder_of_user_files_is_refused_even_with_force(fmt, recording, tmp_path, capsys) -> None:
    folder = tmp_path / "mine"
    (folder / "sub").mkdir(parents=True)
    (folder / "a.txt").write_text("keep")
    (folder / "sub" / "b.npz").write_bytes(b"\x00" * 100)
    before = _snapshot(folder)
    for extra in ((), ("--force",)):  # refused outright: --force would not help
        assert _export(recording, fmt, folder, *extra) == 2
        line = _error_line(capsys)
        assert f"{folder} is not a" in line and REFUSED in line
    assert _snapshot(folder) == before and _leftovers(tmp_path) == []


@pytest.mark.parametrize("fmt", ["mcap", "rrd", "lerobot"])
def test_a_file_export_did_not_write_is_refused_even_with_force(fmt, recording, tmp_path, capsys) -> None:
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes\n")
    assert _export(recording, fmt, notes, "--force") == 2
    assert f"{notes} is not a" in (line := _error_line(capsys)) and REFUSED in line
    assert notes.read_text() == "my notes\n" and _leftovers(tmp_path) == []


def test_a_lerobot_dataset_with_a_file_of_the_user_added_is_refused(recording, tmp_path, capsys) -> None:
    out = tmp_path / "DS"
    assert _export(recording, "lerobot", out) == 0
    (out / "README.md").write_text("my notes on this dataset")
    assert _export(recording, "lerobot", out, "--force") == 2
    line = _error_line(capsys)
    assert "README.md" in line and REFUSED in line
    assert (out / "README.md").read_text() == "my notes on this dataset"


@pytest.mark.parametrize("first, second", [("rrd", "mcap"), ("mcap", "rrd"), ("lerobot", "mcap")])
def test_an_earlier_export_of_another_format_is_refused(first, second, recording, tmp_path, capsys) -> None:
    out = tmp_path / "out"
    assert _export(recording, first, out) == 0
    before = _snapshot(out)
    assert _export(recording, second, out, "--force") == 2
    assert REFUSED in _error_line(capsys)
    assert _snapshot(out) == before


def test_an_mcap_file_of_other_software_is_refused(recording, tmp_path, capsys) -> None:
    from mcap.writer import Writer

    out = tmp_path / "theirs.mcap"
    with open(out, "wb") as f:
        writer = Writer(f)
        writer.start(profile="", library="someone else's recorder")
        writer.finish()
    before = out.read_bytes()
    assert _export(recording, "mcap", out, "--force") == 2
    assert "someone else's recorder" in (line := _error_line(capsys)) and REFUSED in line
    assert out.read_bytes() == before


@pytest.mark.parametrize("fmt", ["lerobot", "mcap", "rrd"])
def test_an_earlier_export_of_the_same_format_is_replaced_with_force(fmt, recording, make_recording, tmp_path,
                                                                      capsys) -> None:
    short = make_recording(tmp_path / "short.tmrec", seconds=1.0)
    out = _out_for(fmt, tmp_path)
    assert _export(short, fmt, out) == 0
    before = _snapshot(out)
    assert _export(recording, fmt, out) == 2
    assert "exists; pass --force to replace it" in _error_line(capsys)
    assert _snapshot(out) == before
    assert _export(recording, fmt, out, "--force") == 0
    assert "1250 frames" in capsys.readouterr().out
    assert _snapshot(out) != before and _leftovers(tmp_path) == []


# ------------------------------------------------------------------------------------ killed and stopped exports

def test_what_a_killed_export_left_is_removed_at_the_next_start_unless_its_process_lives(recording, tmp_path) -> None:
    dead, live = _dead_pid(), os.getpid()
    out = tmp_path / "DS"
    assert _export(recording, "lerobot", out) == 0
    stale = [f".DS.tmp-{dead}-0123abcd", f".DS.old-{dead}-89abcdef"]
    kept = [f".DS.tmp-{live}-0123abcd", f".DS.old-{live}-89abcdef",  # an export still running
            f".DS.tmp-{dead}-notours", f".DSX.tmp-{dead}-0123abcd", f"DS.tmp-{dead}-0123abcd",
            f".x.tmp-{dead}-0123abcd.mcap"]  # another output's temporary: its own next export removes it
    for name in stale + kept:
        (tmp_path / name / "meta").mkdir(parents=True)
        (tmp_path / name / "meta" / "info.json").write_text("{}")
    assert _export(recording, "lerobot", out, "--force") == 0
    assert _leftovers(tmp_path) == sorted(n for n in kept if ".tmp-" in n or ".old-" in n)
    assert all((tmp_path / n / "meta" / "info.json").is_file() for n in kept)


def test_a_killed_export_of_a_file_is_cleaned_and_a_stopped_replacement_is_kept_while_out_is_missing(
        recording, tmp_path) -> None:
    dead = _dead_pid()
    tmp = tmp_path / f".x.tmp-{dead}-0123abcd.mcap"
    tmp.write_bytes(b"\x89MCAP0\r\n half written")
    assert _export(recording, "mcap", tmp_path / "x.mcap") == 0
    assert not tmp.exists() and _leftovers(tmp_path) == []
    # killed between moving the old dataset aside and renaming the new one: the aside is the only copy left
    aside = tmp_path / f".DS.old-{dead}-0123abcd"
    (aside / "meta").mkdir(parents=True)
    assert _export(recording, "lerobot", tmp_path / "DS") == 0
    assert aside.is_dir()


SLOW_EXPORT = """
import sys, time
from tactile_manip.cli import main
from tactile_manip.interop import lerobot

write_data = lerobot._write_data

def slow(*args, **kwargs):
    result = write_data(*args, **kwargs)
    print("writing", flush=True)
    time.sleep(60)
    return result

lerobot._write_data = slow
sys.exit(main(sys.argv[1:]))
"""


def test_sigterm_while_writing_leaves_nothing_and_exits_143(recording, tmp_path) -> None:
    out = tmp_path / "DS"
    child = subprocess.Popen([sys.executable, "-c", SLOW_EXPORT, "export", str(recording), "--format", "lerobot",
                              "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "writing"
        assert _leftovers(tmp_path) != []  # the temporary exists while the writer works
        child.send_signal(signal.SIGTERM)
        _, err = child.communicate(timeout=60)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    assert child.returncode == 143, err
    assert err.strip().splitlines()[-1] == "tactile-manip export: terminated"
    assert not out.exists() and _leftovers(tmp_path) == []


# ------------------------------------------------------------------------------------------------- model export

def _onnx_model(path: Path, producer: str) -> Path:
    from onnx import TensorProto, helper, save

    x = helper.make_tensor_value_info("x", TensorProto.FLOAT, [1])
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, [1])
    graph = helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "g", [x], [y])
    save(helper.make_model(graph, producer_name=producer), str(path))
    return path


@pytest.mark.parametrize("command", ["export", "export-model"])  # export-model is export --checkpoint on its own
def test_model_export_refuses_its_inputs_and_files_that_are_not_its_models(tmp_path, capsys, command) -> None:
    pytest.importorskip("torch", reason="model export needs torch")
    pytest.importorskip("onnx", reason="model export needs onnx")
    pytest.importorskip("onnxruntime", reason="model export's parity check needs onnxruntime")
    checkpoint = tmp_path / "best.pt"
    checkpoint.write_bytes(b"a checkpoint")
    data = tmp_path / "d.npz"
    data.write_bytes(b"a dataset")
    notes = tmp_path / "notes.txt"
    notes.write_text("mine")
    theirs = _onnx_model(tmp_path / "theirs.onnx", "pytorch")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    cases = [([str(checkpoint)], f"{checkpoint} is the --checkpoint {checkpoint} itself"),
             ([str(data), "--data", str(data)], f"{data} is the --data {data} itself"),
             ([str(notes)], f"{notes} is not an ONNX model written by tactile-manip export"),
             ([str(theirs)], f"{theirs} is not an ONNX model written by tactile-manip export")]
    for out, message in cases:
        assert main(["export", "--checkpoint", str(checkpoint), "--out", *out, "--force"]) == 2
        assert message in _error_line(capsys)
    assert main(["export", "--checkpoint", str(checkpoint), "--out", str(tmp_path / "m.onnx"), "--card",
                 str(data), "--data", str(data)]) == 2
    assert f"{data} is the --data {data} itself" in _error_line(capsys)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    ours = _onnx_model(tmp_path / "ours.onnx", "tactile_manip")  # replaceable: the checkpoint is what fails next
    assert main(["export", "--checkpoint", str(checkpoint), "--out", str(ours), "--force"]) == 2
    assert "not a readable torch checkpoint" in _error_line(capsys)
