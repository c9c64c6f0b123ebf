"""``fit-board`` and ``simulate-log`` on a log simulated from a known twin: the fitted file reads back and scores
its log; bad input is one line, status 2 and nothing written."""

import dataclasses
import json

import numpy as np
import pytest

from tactile_manip.boards import load_board
from tactile_manip.boards.spec import TwinSpec
from tactile_manip.cli import main
from tactile_manip.sim.twin import BoardTwin

COLUMNS = "time_s,x_mm,y_mm,z_mm"


def write_log(folder, rows=240, seed=0, chips=5, shuffle_labels=False):
    """sensor.csv (raw), sub.csv (baseline-subtracted) and states.csv of presses on a known twin of the eFlesh
    board; returns the paths."""
    board = load_board("eflesh")
    twin = TwinSpec(rig_origin_mm=(289.0, -100.0), rig_turn_deg=90.0, contact_z_mm=145.0, press_gain=0.6,
                    press_exponent=1.3, kernel_depth_mm=9.0, lateral_scale=0.8, tilt_scale=1.0)
    sim = BoardTwin(dataclasses.replace(board, twin=twin))
    rng = np.random.default_rng(seed)
    stage = np.column_stack([rng.uniform(274, 304, rows), rng.uniform(-115, -85, rows), rng.uniform(141, 145, rows)])
    t = 1000.0 + 0.5 * np.arange(rows)
    sub = sim.readings_ut(stage) + rng.normal(0.0, 2.0, (rows, 5, 3))
    raw = sub + sim.rest_readings_ut() + rng.normal(0.0, 5.0, (1, 5, 3))
    folder.mkdir(parents=True, exist_ok=True)
    paths = {"raw": folder / "sensor.csv", "sub": folder / "sub.csv", "states": folder / "states.csv"}
    np.savetxt(paths["raw"], np.column_stack([t, raw.reshape(rows, -1)[:, :3 * chips]]), delimiter=",")
    np.savetxt(paths["sub"], np.column_stack([t, sub.reshape(rows, -1)[:, :3 * chips]]), delimiter=",")
    if shuffle_labels:
        stage = stage[rng.permutation(rows)]
    np.savetxt(paths["states"], np.column_stack([t + 0.001, stage]), delimiter=",")
    return paths


def fit_args(paths, out, *more):
    return ["fit-board", "--board", "eflesh", "--raw", str(paths["raw"]), "--subtracted", str(paths["sub"]),
            "--labels", str(paths["states"]), "--label-columns", COLUMNS, "--rows", "120", "--evaluations", "12",
            "--out", str(out), "--quiet", *more]


@pytest.mark.slow
def test_fit_board_then_simulate_log_scores_the_log(tmp_path, capsys):
    paths = write_log(tmp_path / "log")
    out = tmp_path / "cube.toml"
    assert main(fit_args(paths, out)) == 0
    board = load_board(out)
    assert board.twin is not None and board.fit["rows"]["fitting"] == 192  # the first 80 % of 240 rows
    assert board.fit["sha256_16"]["labels"] and board.name == "eflesh-fitted"
    capsys.readouterr()
    sim = tmp_path / "sim.csv"
    assert main(["simulate-log", "--board", str(out), "--labels", str(paths["states"]), "--label-columns", COLUMNS,
                 "--readings", str(paths["sub"]), "--out", str(sim)]) == 0
    printed = capsys.readouterr().out
    assert "EV of the subtracted readings on the test tail (48 rows" in printed
    table = np.loadtxt(sim, delimiter=",")
    real = np.loadtxt(paths["sub"], delimiter=",")
    assert table.shape == real.shape
    np.testing.assert_allclose(table[:, 0], real[:, 0])  # the log's rows, in its order
    score = json.loads((tmp_path / "sim.score.json").read_text())
    assert score["ev_test"] > 0.9 and len(score["ev_test_per_channel"]) == 15
    assert (tmp_path / "sim.png").stat().st_size > 10_000


def test_a_raw_stream_that_is_not_at_rest_is_refused(tmp_path, capsys):
    paths = write_log(tmp_path / "log", rows=60)
    out = tmp_path / "cube.toml"
    argv = ["fit-board", "--board", "eflesh", "--raw", str(paths["raw"]), "--presses", str(paths["raw"]),
            "--labels", str(paths["states"]), "--label-columns", COLUMNS, "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "is not at rest" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_a_short_capture_and_a_wrong_chip_count_are_refused(tmp_path, capsys):
    short = write_log(tmp_path / "short", rows=8)
    assert main(fit_args(short, tmp_path / "a.toml")) == 2
    assert "too short to fit" in capsys.readouterr().err
    four = write_log(tmp_path / "four", rows=60, chips=4)
    assert main(fit_args(four, tmp_path / "b.toml")) == 2
    assert "13 columns, expected 16" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.toml"))


def test_a_fit_that_does_not_converge_is_not_written(tmp_path, capsys):
    paths = write_log(tmp_path / "log", rows=120, shuffle_labels=True)
    out = tmp_path / "cube.toml"
    assert main(fit_args(paths, out, "--evaluations", "4", "--rows", "40")) == 2
    err = capsys.readouterr().err
    assert "did not converge" in err and len(err.strip().splitlines()) == 1
    assert not out.exists() and not list(tmp_path.glob("*.toml"))


def test_an_untouched_capture_and_raw_presses_fit_a_twin(tmp_path, capsys):
    paths = write_log(tmp_path / "log", rows=120)
    raw = np.loadtxt(paths["raw"], delimiter=",")
    sub = np.loadtxt(paths["sub"], delimiter=",")
    rng = np.random.default_rng(3)
    rest = (raw - sub)[0, 1:] + rng.normal(0.0, 5.0, (100, 15))  # 10 s of the untouched board at 10 Hz
    untouched = tmp_path / "untouched.csv"
    np.savetxt(untouched, np.column_stack([np.arange(100) * 0.1, rest]), delimiter=",")
    out = tmp_path / "cube.toml"
    argv = ["fit-board", "--board", "eflesh", "--raw", str(untouched), "--presses", str(paths["raw"]),
            "--labels", str(paths["states"]), "--label-columns", COLUMNS, "--rows", "80", "--evaluations", "12",
            "--out", str(out)]
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "rest field: median of an untouched capture, 100 rows" in err
    assert all(f"stage {stage}: EV" in err for stage in ("file", "magnets", "readout"))
    board = load_board(out)
    assert board.fit["rest"]["from"] == "an untouched capture" and board.fit["ev_on_fitted_rows"]["readout"] > 0.5


def blind_args(paths, out, *more):
    return ["fit-board", "--board", "eflesh", "--raw", str(paths["raw"]), "--subtracted", str(paths["sub"]),
            "--out", str(out), "--quiet", *more]


@pytest.mark.slow
def test_a_fit_without_labels_reads_no_label_and_writes_a_pad_frame_twin(tmp_path, capsys):
    paths = write_log(tmp_path / "log", rows=200)
    paths["states"].unlink()  # no label log anywhere near the fit
    out = tmp_path / "cube.toml"
    assert main(blind_args(paths, out, "--rows", "120")) == 0
    assert "no labels: EV" in capsys.readouterr().out
    board = load_board(out)
    assert board.twin is not None and board.twin.rig_origin_mm == (0.0, 0.0) and board.fit["labelled"] == 0
    assert "labels" not in board.fit["files"] and board.fit["rows"]["fitting"] == 160
    assert board.fit["stages"]["readout"]["ev"] > 0.8


def test_a_fit_without_labels_refuses_a_stream_not_at_rest_or_too_short(tmp_path, capsys):
    paths = write_log(tmp_path / "log", rows=60)
    assert main(["fit-board", "--board", "eflesh", "--raw", str(paths["raw"]), "--presses", str(paths["raw"]),
                 "--out", str(tmp_path / "a.toml")]) == 2
    err = capsys.readouterr().err
    assert "is not at rest" in err and len(err.strip().splitlines()) == 1
    short = write_log(tmp_path / "short", rows=8)
    assert main(blind_args(short, tmp_path / "b.toml")) == 2
    err = capsys.readouterr().err
    assert "too short to fit" in err and len(err.strip().splitlines()) == 1
    assert not list(tmp_path.glob("*.toml"))


def test_a_fit_without_labels_refuses_too_few_presses(tmp_path, capsys):
    paths = write_log(tmp_path / "log", rows=40)  # 32 fitting rows: fewer than a kernel can be placed by
    out = tmp_path / "cube.toml"
    assert main(blind_args(paths, out)) == 2
    err = capsys.readouterr().err
    assert "a fit without labels needs at least 50" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


@pytest.mark.slow
def test_a_fit_without_labels_that_does_not_converge_is_not_written(tmp_path, capsys):
    paths = write_log(tmp_path / "log", rows=120)
    sub, raw = (np.loadtxt(paths[k], delimiter=",") for k in ("sub", "raw"))
    baseline = raw[:, 1:] - sub[:, 1:]
    rng = np.random.default_rng(5)  # readings no press of this board gives: each channel's own noise
    sub[:, 1:] = rng.normal(0.0, 1.0, sub[:, 1:].shape) * np.abs(sub[:, 1:]).max(axis=0)
    raw[:, 1:] = sub[:, 1:] + baseline
    np.savetxt(paths["sub"], sub, delimiter=",")
    np.savetxt(paths["raw"], raw, delimiter=",")
    out = tmp_path / "cube.toml"
    assert main(blind_args(paths, out, "--rows", "80")) == 2
    err = capsys.readouterr().err
    assert "did not converge" in err and len(err.strip().splitlines()) == 1
    assert not out.exists() and not list(tmp_path.glob("*.toml"))


def test_labelled_presses_without_a_label_log_are_refused(tmp_path, capsys):
    paths = write_log(tmp_path / "log", rows=60)
    assert main(blind_args(paths, tmp_path / "a.toml", "--labelled", "25")) == 2
    err = capsys.readouterr().err
    assert "--labelled 25 draws labelled presses from --labels" in err and len(err.strip().splitlines()) == 1
    assert not list(tmp_path.glob("*.toml"))
