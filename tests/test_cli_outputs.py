"""Outputs are never overwritten unasked, the path printed is the path written, and configs fail in one line.

The cases: a second ``simulate --out x`` (which writes ``x.npz``), ``show`` to a
bare name, report folders of ``demo`` / ``score`` / ``bench``, a config that is a directory or not UTF-8,
unknown shape arguments in a dataset or scene config, and a bad scene (or a real robot's scene whose board is
not plugged in) that must not leave a run folder.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import pytest
from checks import assert_one_line_error

from tactile_manip.cli import main
from tactile_manip.errors import ConfigError
from tactile_manip.outputs import unique_folder
from tactile_manip.sim.dataset import load_dataset_config
from tactile_manip.trials.log import run_folder
from tactile_manip.trials.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
DATASET_CONFIG = ROOT / "configs/dataset/supermag.toml"
SCENE = ROOT / "configs/scenes/reorient_sim.toml"
FR3_SCENE = ROOT / "configs/scenes/reorient_fr3.toml"


def test_simulate_checks_the_file_it_writes_and_refuses_it_the_second_time(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(ROOT)
    args = ["simulate", "--config", str(DATASET_CONFIG), "--scale", "0.001", "--workers", "1",
            "--out", str(tmp_path / "x")]
    assert main(args) == 0
    written = tmp_path / "x.npz"
    assert f"wrote {written} " in capsys.readouterr().out
    before = written.read_bytes()
    t0 = time.perf_counter()
    assert main(args) == 2  # `x` does not exist, but `x.npz`, the file it would write, does
    assert_one_line_error(capsys.readouterr().err, "simulate", f"{written} exists; pass --force")
    assert written.read_bytes() == before
    assert time.perf_counter() - t0 < 5.0  # refused before simulating (the run above took longer)


def test_show_prints_the_path_it_wrote_and_refuses_to_replace_it(tmp_path, capsys):
    assert main(["show", "--object", "cylinder", "--out", str(tmp_path / "press")]) == 0
    assert capsys.readouterr().out.strip() == f"wrote {tmp_path / 'press.png'}"
    assert (tmp_path / "press.png").read_bytes()[:4] == b"\x89PNG"
    assert main(["show", "--object", "cylinder", "--out", str(tmp_path / "press.png")]) == 2
    assert_one_line_error(capsys.readouterr().err, "show", "exists; pass --force")
    assert main(["show", "--object", "cylinder", "--out", str(tmp_path / "press.png"), "--force"]) == 0


@pytest.mark.parametrize("argv,existing", [
    (["demo", "--out", "{d}"], "letter_r.png"),
    (["score", "{d}"], "summary_5deg.md"),
    (["bench", "--out", "{d}", "--quick"], "report.json"),
])
def test_report_folders_are_not_overwritten_without_force(argv, existing, tmp_path, capsys):
    (tmp_path / existing).write_text("an earlier run")
    assert main([a.format(d=tmp_path) for a in argv]) == 2
    err = assert_one_line_error(capsys.readouterr().err, argv[0])
    assert existing in err and "--force" in err
    assert (tmp_path / existing).read_text() == "an earlier run"


def test_a_config_that_is_a_directory_or_not_utf8_is_one_line_naming_it(tmp_path):
    with pytest.raises(ConfigError, match=f"config {tmp_path} is a directory"):
        load_dataset_config(tmp_path)
    latin1 = tmp_path / "latin1.toml"
    latin1.write_bytes("name = \"Müller\"\n".encode("latin-1"))
    with pytest.raises(ConfigError, match=r"latin1.toml: not a text \(UTF-8\) TOML file"):
        load_scene(latin1)


def test_unknown_shape_arguments_are_named_with_the_accepted_ones(tmp_path):
    text = DATASET_CONFIG.read_text().replace('name = "allen_key"\ncount = 2025',
                                              'name = "allen_key"\ncount = 2025\nkwargs = { bogus = 1 }', 1)
    (tmp_path / "d.toml").write_text(text)
    with pytest.raises(ConfigError, match=r"allen_key: unknown argument\(s\) objects.kwargs.bogus; allen_key "
                                          r"accepts across_flats_mm, "):
        load_dataset_config(tmp_path / "d.toml")
    scene = SCENE.read_text().replace("kwargs = { size_mm = 3.0 }", "kwargs = { radius_mm = 3.0, bogus = 1 }", 1)
    (tmp_path / "s.toml").write_text(scene)
    with pytest.raises(ConfigError, match=r"cylinder: unknown argument\(s\) kwargs.bogus, kwargs.radius_mm; "
                                          r"cylinder accepts size_mm, length_mm"):
        load_scene(tmp_path / "s.toml")


@pytest.mark.parametrize("old,new,named", [
    ('reconstructor = "models/supermag.onnx"', 'reconstructor = "models/missing.onnx"', "missing.onnx"),
    ("seed = 0                      # chip noise", 'port = "/dev/ttyUSB0"\n# chip noise', "simulated sensor"),
])
def test_a_bad_scene_leaves_no_run_folder_behind(old, new, named, tmp_path, monkeypatch, capsys):
    """Every part the scene names is built before the run folder: a late error would leave a folder that
    blocks the next run with the same --out."""
    monkeypatch.chdir(ROOT)  # the scene's model paths are relative to the repository root
    scene = SCENE.read_text().replace(old, new)
    assert scene != SCENE.read_text()
    (tmp_path / "s.toml").write_text(scene)
    assert main(["trials", "--config", str(tmp_path / "s.toml"), "--out", str(tmp_path / "run"), "--quiet"]) == 2
    assert_one_line_error(capsys.readouterr().err, "trials", named)
    assert not (tmp_path / "run").exists()


def test_a_robot_scene_whose_board_is_unplugged_fails_before_its_run_folder(tmp_path, monkeypatch, capsys):
    """The FR3 scene with its sensor port missing: one line naming the port and find-port, status 2, no run.json
    (nor any folder) left behind to block the next run."""
    pytest.importorskip("serial", reason="the serial sensor needs pyserial (the serial extra)")
    monkeypatch.chdir(ROOT)
    port = tmp_path / "ttyUSB9"
    scene = FR3_SCENE.read_text().replace('port = "/dev/ttyUSB0"', f'port = "{port}"')
    assert str(port) in scene
    (tmp_path / "s.toml").write_text(scene)
    out = tmp_path / "run"
    assert main(["trials", "--config", str(tmp_path / "s.toml"), "--out", str(out), "--quiet"]) == 2
    assert_one_line_error(capsys.readouterr().err, "trials", str(port), "find-port")
    assert not out.exists()
    # the board is there (any existing path stands in for it) but franky is not: also before the run folder
    port.write_bytes(b"")
    monkeypatch.setitem(sys.modules, "franky", None)
    assert main(["trials", "--config", str(tmp_path / "s.toml"), "--out", str(out), "--quiet"]) == 2
    assert_one_line_error(capsys.readouterr().err, "trials", "franky-control", '".[franky]"')
    assert not out.exists()


def test_run_folders_started_in_the_same_second_stay_apart(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(time, "strftime", lambda *_: "20260101T000000Z")
    first = run_folder("scene", None)
    first.mkdir(parents=True)
    second = run_folder("scene", None)
    assert second != first and second.name == "scene-20260101T000000Z-2"
    second.mkdir()
    assert unique_folder(first).name == "scene-20260101T000000Z-3"


def test_a_command_folder_is_claimed_once_and_refused_to_others(tmp_path):
    from tactile_manip.outputs import OWNER_FILE, OutputPathError, check_command_folder, claim_folder, folder_owner

    out = tmp_path / "a" / "b"
    assert check_command_folder(out, "bench", ["report.md"], force=False) == out and not out.exists()
    claim_folder(out, "bench")
    assert folder_owner(out) == "bench" and (out / OWNER_FILE).is_file()
    (out / "report.md").write_text("x")
    claim_folder(out, "bench")  # kept as it is
    with pytest.raises(OutputPathError, match="report.md of an earlier run"):
        check_command_folder(out, "bench", ["report.md"], force=False)
    assert check_command_folder(out, "bench", ["report.md"], force=True) == out
    with pytest.raises(OutputPathError, match="is a folder of tactile-manip bench, not of evaluate"):
        check_command_folder(out, "evaluate", ["table.md"], force=True)
    assert check_command_folder(out, "score", ["summary.md"], force=False, also=("bench",)) == out
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("n")
    with pytest.raises(OutputPathError, match=r"holds files that tactile-manip bench did not write \(notes.txt\)"):
        check_command_folder(mine, "bench", ["report.md"], force=True)
    (mine / OWNER_FILE).write_text("not json")  # an unreadable mark is no mark
    assert folder_owner(mine) is None


def test_force_replaces_only_a_dataset_the_same_command_wrote(tmp_path, capsys):
    """simulate --force over a user's file of the same name, or over import's dataset, is refused and the file
    is left as it was; over simulate's own dataset it goes ahead."""
    from checks import assert_one_line_error

    from tactile_manip.cli import main

    mine = tmp_path / "notes.npz"
    mine.write_bytes(b"my notes")
    args = ["simulate", "--board", "anyskin-5", "--presses", "3", "--force", "--out"]
    assert main([*args, str(mine)]) == 2
    assert_one_line_error(capsys.readouterr().err, "simulate", str(mine), "not a dataset written by tactile-manip simulate")
    assert mine.read_bytes() == b"my notes"
    ours = tmp_path / "sim.npz"
    assert main([*args, str(ours)]) == 0 and main([*args, str(ours)]) == 0
    capsys.readouterr()
