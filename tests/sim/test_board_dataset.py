"""Simulated probe presses of any described board, as a dataset: what a probe rig records."""

from __future__ import annotations

import numpy as np
import pytest
from checks import assert_one_line_error

from tactile_manip.boards import load_board
from tactile_manip.cli import main
from tactile_manip.data import load_dataset
from tactile_manip.errors import ConfigError, SimulationError
from tactile_manip.sim.board_dataset import ProbePlan, probe_press_dataset


def test_presses_of_the_eflesh_board_are_labelled_in_its_reading_layout():
    data = probe_press_dataset(load_board("eflesh"), 12, seed=1)
    assert data.readings.shape == (12, 3, 3, 3) and data.target_names == ("x_mm", "y_mm", "depth_mm", "force_n")
    assert not data.readings[:, [0, 0, 2, 2], [0, 2, 0, 2]].any()            # the cross's corners: no chip
    x, y, depth, force = data.targets.T
    assert (np.abs(x) <= 18.0).all() and (np.abs(y) <= 18.0).all()         # 40 mm layer, 2 mm margin
    assert ((force >= 0.5) & (force <= 15.0)).all() and (depth > 0).all()
    assert np.corrcoef(force, np.abs(data.readings).reshape(12, -1).max(1))[0, 1] > 0.5  # harder: larger field
    assert data.provenance["layout"] == "eflesh" and data.provenance["probe"]["tip"] == "sphere"
    again = probe_press_dataset(load_board("eflesh"), 12, seed=1)
    assert again.fingerprint() == data.fingerprint()                       # the seed decides every draw


def test_a_press_in_the_middle_of_a_magnetised_layer_reads_largest_under_the_tip():
    board = load_board("supermag-4x4")
    data = probe_press_dataset(board, 6, plan=ProbePlan(tip="flat", tip_diameter_mm=6.0, min_force_n=2.0,
                                                        max_force_n=3.0, margin_mm=9.0), seed=0)
    assert (np.abs(data.targets[:, :2]) <= 1.0).all()                     # margin 9 mm on a 20 mm pad
    z = np.abs(data.readings[..., 2]).reshape(6, -1)
    assert set(np.argmax(z, axis=1)) <= {5, 6, 9, 10}                      # the four middle chips


def test_boards_that_cannot_be_simulated_and_bad_plans_are_refused(tmp_path):
    with pytest.raises(ConfigError, match="generic:4 has no geometry"):
        probe_press_dataset(load_board("generic:4"), 3)
    with pytest.raises(ValueError, match="presses must be an integer"):
        probe_press_dataset(load_board("eflesh"), 0)
    with pytest.raises(ValueError, match="leaves no room"):
        probe_press_dataset(load_board("supermag-4x4"), 2, plan=ProbePlan(margin_mm=10.0))
    with pytest.raises(SimulationError, match="went through board supermag-4x4's 2.5 mm layer"):
        probe_press_dataset(load_board("supermag-4x4"), 2, plan=ProbePlan(tip="sphere", tip_diameter_mm=0.5,
                                                                          min_force_n=500.0, max_force_n=600.0))
    with pytest.raises(ValueError, match="tip must be one of"):
        ProbePlan(tip="cone")
    with pytest.raises(ValueError, match="max_force_n"):
        ProbePlan(min_force_n=5.0, max_force_n=1.0)


def test_simulate_board_writes_a_dataset_and_refuses_generic_boards_in_one_line(tmp_path, capsys):
    out = tmp_path / "presses.npz"
    assert main(["simulate", "--board", "anyskin-5", "--presses", "5", "--seed", "3", "--out", str(out)]) == 0
    assert "5 probe presses of board anyskin-5" in capsys.readouterr().out
    assert load_dataset(out).provenance["layout"] == "anyskin-5"
    assert main(["simulate", "--board", "generic:10", "--presses", "5", "--out", str(tmp_path / "g.npz")]) == 2
    assert_one_line_error(capsys.readouterr().err, "simulate", "board generic:10 has no geometry")
    assert not (tmp_path / "g.npz").exists()
    assert main(["simulate", "--board", "eflesh", "--shard-size", "2", "--out", str(tmp_path / "s")]) == 2
    assert_one_line_error(capsys.readouterr().err, "simulate", "--shard-size is an option of a dataset config")
    assert main(["simulate", "--board", "eflesh", "--ray", "--shard-size", "2", "--out", str(tmp_path / "s")]) == 2
    assert_one_line_error(capsys.readouterr().err, "simulate", "--ray and --shard-size are options of a dataset config")


def test_too_few_presses_for_the_splits_are_refused_before_any_press(tmp_path, capsys):
    assert main(["simulate", "--board", "eflesh", "--presses", "2", "--out", str(tmp_path / "p.npz")]) == 2
    err = capsys.readouterr().err
    assert_one_line_error(err, "simulate", "--presses must be from 3 to 1000000", "got 2")
    assert "pressing" not in err and not (tmp_path / "p.npz").exists()
