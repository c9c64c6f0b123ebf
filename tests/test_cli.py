"""The ``tactile-manip`` command line, called in-process: outputs, files written, and one-line errors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from checks import assert_one_line_error

from tactile_manip.cli import COMMANDS, main
from tactile_manip.commands.demo import DEMO_OBJECTS
from tactile_manip.data import load_dataset
from tactile_manip.boards import load_board
from tactile_manip.sim.params import describe, for_board

ROOT = Path(__file__).resolve().parents[1]
CONFIG = "configs/dataset/supermag.toml"  # relative: the commands are run from the repository root
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture
def at_root(monkeypatch):
    monkeypatch.chdir(ROOT)
    return ROOT


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    """A small dataset written by ``simulate`` (28 pairs, one worker), shared by the tests that read one."""
    out = tmp_path_factory.mktemp("cli") / "x.npz"
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(ROOT)
        rc = main(["simulate", "--config", CONFIG, "--scale", "0.003", "--workers", "1", "--out", str(out)])
    assert rc == 0
    return out


def _assert_png(path: Path) -> None:
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    assert len(data) > 10_000  # a real figure, not an empty canvas


# ---------------------------------------------------------------- params


def test_params_prints_every_parameter(capsys):
    assert main(["params"]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = describe(for_board(load_board("supermag-4x4")))
    assert len(lines) == len(rows)
    for line, row in zip(lines, rows):
        assert line.split()[0] == row["name"]
        assert row["source"][:20] in line


def test_params_markdown_is_a_table_of_every_parameter(capsys):
    assert main(["params", "--markdown"]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = describe(for_board(load_board("supermag-4x4")))
    assert lines[0].startswith("| parameter | default | unit |") and lines[1].startswith("|---")
    assert len(lines) == 2 + len(rows)
    for line, row in zip(lines[2:], rows):
        assert line.startswith(f"| `{row['name']}` | {row['value']} |") and line.endswith(" |")
        assert line.count("|") == 6
    assert "| 120 - 300 |" in "\n".join(lines)  # skin modulus randomisation range


# ---------------------------------------------------------------- simulate


def test_simulate_writes_a_loadable_dataset(dataset):
    data = load_dataset(dataset)
    # 0.003 x 2025 -> 6 per paper object, at least one of each test object, 0.003 x 1600 -> 5 procedural,
    # 0.003 x 1200 -> 4 wide procedural
    assert len(data) == 6 + 6 + 7 + 5 + 4
    assert data.field_ut.shape == (28, 4, 4, 3) and data.images.shape == (28, 200, 200)
    assert list(data.split).count("test") == 7 and list(data.split).count("val") == 4
    assert data.provenance["config"]["objects"][0]["count"] == 6
    assert data.provenance["workers"] == 1
    assert np.isfinite(data.field_ut).all() and data.images.max() > 0


def test_simulate_refuses_to_overwrite_without_force(at_root, dataset, capsys):
    before = dataset.read_bytes()
    rc = main(["simulate", "--config", CONFIG, "--scale", "0.003", "--workers", "1", "--out", str(dataset)])
    assert rc == 2
    err = assert_one_line_error(capsys.readouterr().err, "simulate")
    assert str(dataset) in err and "--force" in err
    assert dataset.read_bytes() == before


def test_simulate_force_overwrites_its_own_dataset(at_root, tmp_path, capsys):
    out = tmp_path / "y.npz"
    args = ["simulate", "--config", CONFIG, "--scale", "0.0001", "--workers", "1", "--out", str(out)]
    assert main([*args, "--seed", "4"]) == 0
    rc = main([*args, "--seed", "5", "--force"])
    assert rc == 0
    data = load_dataset(out)
    assert len(data) == 11 and data.provenance["config"]["seed"] == 5
    assert f"wrote {out}" in capsys.readouterr().out


@pytest.mark.parametrize("text, expected", [
    ("seed = 0\n[poses\noffset_mm = 5.0\n", "not valid TOML"),
    ("seed = 0\nsped = 1\n[[objects]]\nname = \"cylinder\"\ncount = 1\n", "unknown key(s) sped"),
    ("[[objects]]\nname = \"cylinder\"\ncount = -1\n", "count must be >= 0"),
])
def test_simulate_bad_config_is_one_line(at_root, tmp_path, capsys, text, expected):
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    out = tmp_path / "never.npz"
    assert main(["simulate", "--config", str(bad), "--workers", "1", "--out", str(out)]) == 2
    err = assert_one_line_error(capsys.readouterr().err, "simulate")
    assert str(bad) in err and expected in err
    assert not out.exists()


def test_simulate_missing_config_is_one_line(at_root, tmp_path, capsys):
    missing = tmp_path / "missing.toml"
    assert main(["simulate", "--config", str(missing), "--out", str(tmp_path / "z.npz")]) == 2
    err = assert_one_line_error(capsys.readouterr().err, "simulate")
    assert "not found" in err and str(missing) in err


@pytest.mark.parametrize("args, expected", [
    (["--workers", "-1"], "--workers"),
    (["--scale", "0"], "--scale"),
])
def test_simulate_bad_arguments(at_root, tmp_path, capsys, args, expected):
    assert main(["simulate", "--out", str(tmp_path / "z.npz"), *args]) == 2
    assert_one_line_error(capsys.readouterr().err, "simulate", expected)


# ---------------------------------------------------------------- show


def test_show_sample_from_dataset(dataset, tmp_path, capsys):
    out = tmp_path / "a.png"
    assert main(["show", "--data", str(dataset), "--index", "0", "--out", str(out)]) == 0
    _assert_png(out)
    assert f"wrote {out}" in capsys.readouterr().out


def test_show_simulated_press(tmp_path):
    out = tmp_path / "sub" / "b.png"  # the folder is created
    assert main(["show", "--object", "letter_r", "--out", str(out)]) == 0
    _assert_png(out)


def test_show_refuses_a_force_that_bottoms_out(tmp_path, capsys):
    out = tmp_path / "f.png"
    assert main(["show", "--object", "letter_r", "--force-n", "1e6", "--out", str(out)]) == 2
    err = assert_one_line_error(capsys.readouterr().err, "show")
    assert "into the 2.5 mm layer" in err and "smaller force" in err
    assert not out.exists()


def test_show_notes_an_object_off_the_pad(tmp_path, capsys):
    out = tmp_path / "g.png"
    assert main(["show", "--object", "letter_r", "--x-mm", "30", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "note: letter_r at (30, 0) mm does not touch the 20 mm pad" in printed
    assert main(["show", "--object", "letter_r", "--out", str(out), "--force"]) == 0
    assert "note:" not in capsys.readouterr().out  # a normal press has no note


def test_show_index_out_of_range(dataset, tmp_path, capsys):
    out = tmp_path / "c.png"
    assert main(["show", "--data", str(dataset), "--index", "99999", "--out", str(out)]) == 2
    err = assert_one_line_error(capsys.readouterr().err, "show")
    assert "--index must be in [0, 27]" in err and "99999" in err
    assert not out.exists()


def test_show_missing_dataset(tmp_path, capsys):
    missing = tmp_path / "none.npz"
    assert main(["show", "--data", str(missing), "--out", str(tmp_path / "d.png")]) == 2
    assert_one_line_error(capsys.readouterr().err, "show", "dataset not found")


def test_show_unknown_object(tmp_path, capsys):
    assert main(["show", "--object", "teapot", "--out", str(tmp_path / "e.png")]) == 2
    err = assert_one_line_error(capsys.readouterr().err, "show")
    assert "teapot" in err and "letter_r" in err


def test_show_needs_a_source():
    with pytest.raises(SystemExit) as info:
        main(["show", "--out", "never.png"])
    assert info.value.code == 2


# ---------------------------------------------------------------- demo and the entry point


def test_demo_writes_one_figure_per_object(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out)]) == 0
    pngs = sorted(out.glob("*.png"))
    assert [p.stem for p in pngs] == sorted(name for name, _ in DEMO_OBJECTS)
    assert len(pngs) == 6
    for p in pngs:
        _assert_png(p)
    table = capsys.readouterr().out
    for name, _ in DEMO_OBJECTS:
        assert name in table


def test_module_entry_point_help():
    done = subprocess.run([sys.executable, "-m", "tactile_manip", "--help"], capture_output=True, text=True,
                          timeout=120, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("usage: tactile-manip")
    for name in COMMANDS:
        assert name in done.stdout


def test_no_command_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as info:
        main([])
    assert info.value.code == 2
    assert_one_line_error(capsys.readouterr().err, "tactile-manip", "required: COMMAND",
                          "(see `tactile-manip --help`)", program="")
