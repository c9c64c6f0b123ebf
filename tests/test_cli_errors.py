"""Every subcommand, on the three path faults a new user meets first, answers in one line and exits with 2.

For each command in ``cli.COMMANDS`` (in-process, so the whole file runs in seconds) and each fault:

- ``missing``: an input path that does not exist;
- ``readonly``: an output in a location where nothing can be created. As a normal user that is a folder with
  mode 0o500. The tests often run as root, which writes through 0o500, so there the location is a folder
  under ``/proc`` (a kernel file system that refuses new files even to root). Either way the test proves the
  command checks that it can create its output and says so in one line; it does not prove anything about
  disks that fill up mid-write;
- ``dir``: a directory where a file is expected (or a file where a folder is expected, for folder outputs).

Each must give exit status 2, exactly one line on stderr starting ``tactile-manip CMD: error:``, and no
traceback anywhere. Commands or faults without such a path are listed in ``NO_PATH`` with the reason.

The same one line, alone, when numpy warned before the error (an overflow) and when argparse refuses the
command line (no usage block; ``--help`` still shows it).
"""

from __future__ import annotations

import os
import subprocess
import sys
import types
import warnings
from pathlib import Path

import numpy as np
import pytest
from checks import assert_one_line_error

from tactile_manip.cli import COMMANDS, main

ROOT = Path(__file__).resolve().parents[1]
SCENE = str(ROOT / "configs/scenes/reorient_sim.toml")
DATASET_CONFIG = str(ROOT / "configs/dataset/supermag.toml")
TRAIN_CONFIG = str(ROOT / "configs/train/compact.toml")


def _readonly_dir(tmp_path: Path) -> Path:
    """A folder in which no file can be created (see the module docstring for root)."""
    folder = tmp_path / "readonly"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        (folder / "probe").write_bytes(b"")
    except PermissionError:
        return folder
    (folder / "probe").unlink()  # root: permissions do not stop it; /proc refuses new files to everyone
    return Path("/proc") / f"tactile_manip_readonly_{os.getpid()}"


@pytest.fixture
def paths(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "folder").mkdir()
    (tmp_path / "file").write_text("not what anyone expects\n")
    ro = _readonly_dir(tmp_path)
    yield {"missing": str(tmp_path / "missing.bin"), "dir": str(tmp_path / "folder"), "file": str(tmp_path / "file"),
           "ro": str(ro), "tmp": tmp_path}
    if ro.parent == tmp_path:
        ro.chmod(0o700)


# command -> fault -> argv (after the command name); P is the paths fixture
CASES = {
    "simulate": {"missing": lambda p: ["--config", p["missing"], "--out", f"{p['tmp']}/d.npz"],
                 "readonly": lambda p: ["--config", DATASET_CONFIG, "--out", f"{p['ro']}/d.npz"],
                 "dir": lambda p: ["--config", p["dir"], "--out", f"{p['tmp']}/d.npz"]},
    "import": {"missing": lambda p: ["--readings", p["missing"], "--images", p["missing"], "--out", f"{p['tmp']}/d.npz"],
               "readonly": lambda p: ["--readings", p["file"], "--images", p["file"], "--out", f"{p['ro']}/d.npz"],
               "dir": lambda p: ["--readings", p["dir"], "--images", p["dir"], "--out", f"{p['tmp']}/d.npz"]},
    "show": {"missing": lambda p: ["--data", p["missing"], "--out", f"{p['tmp']}/s.png"],
             "readonly": lambda p: ["--object", "letter_r", "--out", f"{p['ro']}/s.png"],
             "dir": lambda p: ["--data", p["dir"], "--out", f"{p['tmp']}/s.png"]},
    "train": {"missing": lambda p: ["--config", p["missing"], "--data", p["file"], "--out", f"{p['tmp']}/run"],
              "readonly": lambda p: ["--config", TRAIN_CONFIG, "--data", p["file"], "--out", f"{p['ro']}/run"],
              "dir": lambda p: ["--config", TRAIN_CONFIG, "--data", p["dir"], "--out", f"{p['tmp']}/run"]},
    "export": {"missing": lambda p: ["--checkpoint", p["missing"], "--out", f"{p['tmp']}/m.onnx"],
               "readonly": lambda p: ["--checkpoint", p["file"], "--out", f"{p['ro']}/m.onnx"],
               "dir": lambda p: ["--checkpoint", p["dir"], "--out", f"{p['tmp']}/m.onnx"]},
    "export-model": {"missing": lambda p: ["--checkpoint", p["missing"], "--out", f"{p['tmp']}/m.onnx"],
                     "readonly": lambda p: ["--checkpoint", p["file"], "--out", f"{p['ro']}/m.onnx"],
                     "dir": lambda p: ["--checkpoint", p["dir"], "--out", f"{p['tmp']}/m.onnx"]},
    "evaluate": {"missing": lambda p: ["--data", p["missing"], "--out", f"{p['tmp']}/eval"],
                 "readonly": lambda p: ["--data", p["file"], "--out", f"{p['ro']}/eval"],
                 "dir": lambda p: ["--data", p["dir"], "--out", f"{p['tmp']}/eval"]},
    "emulate": {"readonly": lambda p: ["--link", f"{p['ro']}/board", "--frames", "1"],
                "dir": lambda p: ["--link", p["dir"], "--frames", "1"]},
    "record": {"missing": lambda p: ["--port", p["missing"], "--out", f"{p['tmp']}/r.tmrec"],
               "readonly": lambda p: ["--sim", "--out", f"{p['ro']}/r.tmrec"],
               "dir": lambda p: ["--sim", "--out", p["dir"]]},
    "view": {"missing": lambda p: ["--replay", p["missing"], "--snapshot", f"{p['tmp']}/v.png"],
             "readonly": lambda p: ["--replay", p["file"], "--snapshot", f"{p['ro']}/v.png"],
             "dir": lambda p: ["--replay", p["dir"], "--snapshot", f"{p['tmp']}/v.png"]},
    "trials": {"missing": lambda p: ["--config", p["missing"], "--quiet"],
               "readonly": lambda p: ["--config", SCENE, "--out", f"{p['ro']}/run", "--quiet"],
               "dir": lambda p: ["--config", p["dir"], "--quiet"]},
    "calibrate": {"missing": lambda p: ["--model", str(ROOT / "models/supermag.onnx"), "--fit", p["missing"],
                                        "--report", p["missing"], "--out", f"{p['tmp']}/c.json"],
                  "readonly": lambda p: ["--model", "bilinear", "--fit", p["file"], "--report", p["file"],
                                         "--out", f"{p['ro']}/c.json"],
                  "dir": lambda p: ["--model", "bilinear", "--fit", p["dir"], "--report", p["dir"],
                                    "--out", f"{p['tmp']}/c.json"]},
    "score": {"missing": lambda p: [p["missing"]],
              "readonly": lambda p: [p["dir"], "--out", f"{p['ro']}/scores"],
              "dir": lambda p: [p["dir"], "--out", p["file"]]},  # a file where the report folder goes
    "collect": {"missing": lambda p: ["run", "--sim", "--calibration", p["missing"], "--out", f"{p['tmp']}/c.npz"],
                "readonly": lambda p: ["calibrate", "--sim", "--ball-radius-mm", "4", "--out", f"{p['ro']}/cal.npz"],
                "dir": lambda p: ["finalize", p["dir"], "--out", f"{p['tmp']}/c.npz"]},
    "bench": {"missing": lambda p: ["--out", f"{p['tmp']}/bench", "--scene", p["missing"]],
              "readonly": lambda p: ["--out", f"{p['ro']}/bench"],
              "dir": lambda p: ["--out", p["file"]]},  # a file where the report folder goes
    "fit-board": {"missing": lambda p: ["--board", "eflesh", "--raw", p["missing"], "--subtracted", p["missing"],
                                        "--labels", p["missing"], "--out", f"{p['tmp']}/b.toml"],
                  "readonly": lambda p: ["--board", "eflesh", "--raw", p["file"], "--subtracted", p["file"],
                                         "--labels", p["file"], "--out", f"{p['ro']}/b.toml"],
                  "dir": lambda p: ["--board", "eflesh", "--raw", p["dir"], "--subtracted", p["dir"],
                                    "--labels", p["dir"], "--out", f"{p['tmp']}/b.toml"]},
    "simulate-log": {"missing": lambda p: ["--board", p["missing"], "--labels", p["missing"],
                                           "--out", f"{p['tmp']}/s.csv"],
                     "readonly": lambda p: ["--board", p["file"], "--labels", p["file"], "--out", f"{p['ro']}/s.csv"],
                     "dir": lambda p: ["--board", p["dir"], "--labels", p["dir"], "--out", f"{p['tmp']}/s.csv"]},
    "demo": {"readonly": lambda p: ["--out", f"{p['ro']}/demo"],
             "dir": lambda p: ["--out", p["file"]]},  # a file where the PNG folder goes
}

NO_PATH = {
    ("params", "missing"): "reads no file", ("params", "readonly"): "writes only to stdout",
    ("params", "dir"): "takes no path",
    ("find-port", "missing"): "reads no file", ("find-port", "readonly"): "writes only to stdout",
    ("find-port", "dir"): "takes no path",
    ("emulate", "missing"): "reads no input file (presses are specs, not paths)",
    ("demo", "missing"): "reads no input file",
}

FAULTS = ("missing", "readonly", "dir")


def test_every_command_and_fault_is_covered_or_excused():
    for command in COMMANDS:
        for fault in FAULTS:
            assert (fault in CASES.get(command, {})) != ((command, fault) in NO_PATH), (command, fault)


@pytest.mark.parametrize("command,fault", [(c, f) for c in COMMANDS for f in FAULTS if f in CASES.get(c, {})])
def test_a_path_fault_is_one_line_and_status_2(command, fault, paths, capsys):
    before = sorted(p.name for p in paths["tmp"].iterdir())
    rc = main([command, *CASES[command][fault](paths)])
    out, err = capsys.readouterr()
    assert rc == 2, (out, err)
    assert_one_line_error(err, command)
    assert "Traceback" not in out
    assert sorted(p.name for p in paths["tmp"].iterdir()) == before  # nothing was created on the way out


def test_a_closed_stdout_exits_quietly():
    proc = subprocess.Popen([sys.executable, "-m", "tactile_manip.cli", "params", "--markdown"], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env={**os.environ, "PYTHONPATH": str(ROOT)})
    proc.stdout.close()  # the reader is gone before the first line, like `| head -0`
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 141
    assert err == ""


@pytest.mark.parametrize("module,argv,install", [
    ("serial", ["record", "--port", "/dev/ttyUSB9", "--out", "r.tmrec"], 'pip install -e ".[serial]"'),
    ("serial", ["find-port"], 'pip install -e ".[serial]"'),
    ("torch", ["train", "--config", TRAIN_CONFIG, "--data", "d.npz", "--out", "run"],
     'pip install torch==2.13.0 && pip install -e ".[train]"'),
    ("torch", ["export", "--checkpoint", "best.pt", "--out", "m.onnx"],
     'pip install torch==2.13.0 && pip install -e ".[train]"'),
    ("torch", ["export-model", "--checkpoint", "best.pt", "--out", "m.onnx"],
     'pip install torch==2.13.0 && pip install -e ".[train]"'),
    ("onnxruntime", ["evaluate", "--data", "d.npz", "--model", "M=m.onnx", "--out", "eval"],
     'pip install -e ".[onnx]"'),
    ("sklearn", ["calibrate", "--model", "bilinear", "--fit", "d.npz", "--report", "d.npz", "--out", "c.json"],
     'pip install -e ".[sklearn]"'),
    ("sklearn", ["collect", "calibrate", "--sim", "--ball-radius-mm", "4", "--out", "c.npz"],
     'pip install -e ".[sklearn]"'),
])
def test_a_missing_extra_names_its_install_line_before_any_work(module, argv, install, tmp_path, monkeypatch,
                                                                 capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setitem(sys.modules, module, None)  # `import module` now raises ImportError
    if module == "serial":
        monkeypatch.setitem(sys.modules, "serial.tools.list_ports", None)
    if module == "sklearn":
        monkeypatch.setitem(sys.modules, "sklearn.isotonic", None)
    assert main(argv) == 2
    assert_one_line_error(capsys.readouterr().err, argv[0], install)
    assert list(tmp_path.iterdir()) == []  # nothing written before the check


def test_an_import_error_of_our_own_code_keeps_its_traceback(monkeypatch):
    """Only optional extras become one line: a broken module of the package is a bug."""
    monkeypatch.setitem(sys.modules, "tactile_manip.sim.params", None)
    with pytest.raises(ImportError):
        main(["params"])


# ---------------------------------------------------------------- nothing before the one line


def _overflowing_import(folder: Path) -> list[str]:
    """``import`` arguments whose images hold 1e300 (beyond float32, where storing them as float32 made numpy warn
    of an overflow) and whose split names an unknown part."""
    folder.mkdir()
    images = np.zeros((10, 20, 20))
    images[:, 5, 5] = 1e300
    np.save(folder / "readings.npy", np.random.default_rng(0).normal(0.0, 50.0, (10, 4, 4, 3)))
    np.save(folder / "images.npy", images)
    np.save(folder / "split.npy", np.array(["train"] * 9 + ["bogus"]))
    return ["import", "--readings", str(folder / "readings.npy"), "--images", str(folder / "images.npy"),
            "--split", str(folder / "split.npy"), "--out", str(folder / "d.npz")]


def test_an_overflow_before_an_expected_error_prints_only_the_error_line(tmp_path):
    """The user reads one line, not numpy's warning and its source line above it: values that would overflow the
    dataset's float32 are refused by name before any cast warns."""
    argv = _overflowing_import(tmp_path / "in")
    done = subprocess.run([sys.executable, "-m", "tactile_manip.cli", *argv], capture_output=True, text=True,
                          timeout=120, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 2, done.stderr
    assert_one_line_error(done.stderr, "import", "beyond float32's range")


def _warning_command(monkeypatch, outcome: str) -> None:
    """Adds a command ``warn`` that warns of an overflow, then fails (ValueError), crashes (a bug) or succeeds."""

    def run(args) -> int:
        np.float32(np.float64(1e300))  # RuntimeWarning: overflow encountered in cast
        if outcome == "fails":
            raise ValueError("the readings are not finite")
        if outcome == "crashes":
            raise ZeroDivisionError("a bug")
        return 0

    module = types.ModuleType("warning_command")
    module.add_arguments, module.run = lambda parser: None, run
    monkeypatch.setitem(sys.modules, module.__name__, module)
    monkeypatch.setitem(COMMANDS, "warn", (module.__name__, "warn, then " + outcome))


def test_warnings_of_a_command_that_fails_on_its_input_are_not_shown(monkeypatch, capsys):
    _warning_command(monkeypatch, "fails")
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        assert main(["warn"]) == 2
    assert [str(w.message) for w in shown] == []
    assert_one_line_error(capsys.readouterr().err, "warn", "the readings are not finite")


@pytest.mark.parametrize("outcome", ["succeeds", "crashes"])
def test_warnings_of_a_command_that_succeeds_or_crashes_are_shown_once(outcome, monkeypatch):
    _warning_command(monkeypatch, outcome)
    with warnings.catch_warnings(record=True) as shown:
        warnings.simplefilter("always")
        if outcome == "crashes":
            with pytest.raises(ZeroDivisionError):  # a bug keeps its traceback
                main(["warn"])
        else:
            assert main(["warn"]) == 0
    assert [(w.category, str(w.message)) for w in shown] == [(RuntimeWarning, "overflow encountered in cast")]
    assert shown[0].filename == __file__  # where it was raised, not where it was shown


# ---------------------------------------------------------------- argparse's refusals


@pytest.mark.parametrize("argv,prog,needles", [
    (["export", "run.tmrec", "--format", "parquet", "--out", "x"], "tactile-manip export",
     ["argument --format: invalid choice: 'parquet'", "'lerobot'", "'mcap'", "'rrd'"]),
    (["export", "run.tmrec"], "tactile-manip export", ["the following arguments are required: --out"]),
    (["export", "run.tmrec", "--out", "x", "--bogus"], "tactile-manip export", ["unrecognized arguments: --bogus"]),
    (["collect", "run", "--sim", "--calibration", "c.npz", "--out", "x", "--bogus"], "tactile-manip collect run",
     ["unrecognized arguments: --bogus"]),
    (["collect", "run", "--sim"], "tactile-manip collect run",
     ["the following arguments are required: --calibration, --out"]),
    (["exprot"], "tactile-manip", ["argument COMMAND: invalid choice: 'exprot'", "'export'"]),
    ([], "tactile-manip", ["the following arguments are required: COMMAND"]),
])
def test_a_bad_command_line_is_one_line_naming_the_command(argv, prog, needles, capsys):
    """argparse's refusals: the (sub)command's name, what is wrong and where the usage is, without the usage."""
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    out, err = capsys.readouterr()
    assert out == ""
    line = assert_one_line_error(err, prog, *needles, program="")
    assert line.endswith(f"(see `{prog} --help`)"), line


def test_help_still_shows_the_usage(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["export", "--help"])
    assert stop.value.code == 0
    out, err = capsys.readouterr()
    assert out.startswith("usage: tactile-manip export") and "--format {lerobot,mcap,rrd}" in out and err == ""
