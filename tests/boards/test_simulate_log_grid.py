"""``simulate-log --grid``: a fitted board's twin pressed all over its pad, as the dataset ``train --prior`` reads."""

import dataclasses

import numpy as np
import pytest

from tactile_manip.boards import load_board
from tactile_manip.boards.spec import TwinSpec
from tactile_manip.boards.write import board_toml
from tactile_manip.cli import main
from tactile_manip.data import load_dataset
from tactile_manip.sim.twin import BoardTwin, rig_to_pad


@pytest.fixture
def twin_file(tmp_path):
    board = load_board("eflesh")
    twin = TwinSpec(rig_origin_mm=(289.0, -100.0), rig_turn_deg=90.0, contact_z_mm=145.0, press_gain=0.6,
                    press_exponent=1.3, kernel_depth_mm=9.0, lateral_scale=0.8, tilt_scale=1.0)
    path = tmp_path / "cube.toml"
    path.write_text(board_toml(dataclasses.replace(board, twin=twin, name="cube-twin", path=None)))
    return path


def test_the_grid_presses_the_whole_pad_through_the_rig_frame_and_reads_as_the_twin(twin_file, tmp_path, capsys):
    out = tmp_path / "twin.npz"
    assert main(["simulate-log", "--board", str(twin_file), "--grid", "--out", str(out)]) == 0
    assert "presses of board cube-twin's twin over its pad (12 approaches" in capsys.readouterr().out
    bank = load_dataset(out, images=False)
    board = load_board(twin_file)
    stage = np.stack([bank.target(n) for n in ("x_mm", "y_mm", "z_mm")], axis=1).astype(np.float64)
    t = board.twin
    pad, approach = rig_to_pad(stage, origin_mm=t.rig_origin_mm, turn_deg=t.rig_turn_deg, contact_z_mm=t.contact_z_mm,
                               depth_per_z=t.depth_per_z, mirror=t.rig_mirror)
    half = np.array(board.layer.size_mm) / 2
    np.testing.assert_allclose(pad.min(axis=0), -half - 4.0, atol=1e-6)  # the layer and 4 mm beyond it
    np.testing.assert_allclose(pad.max(axis=0), half + 4.0, atol=0.5)
    np.testing.assert_allclose(np.unique(approach.round(6)), np.linspace(0.5, 6.0, 12), atol=1e-6)
    # the readings are the twin's at those poses, in the layout import gives
    rows = np.random.default_rng(0).choice(len(bank), 50, replace=False)
    expected = board.readings_from_chips(BoardTwin(board).readings_ut(stage[rows]))
    np.testing.assert_allclose(bank.readings[rows], expected, rtol=1e-5, atol=1e-3)
    # the board's identity, so that presses imported with the board file it was fitted from are accepted
    assert bank.provenance["board"]["fingerprint"] == load_board("eflesh").record["fingerprint"]


def test_the_grid_refuses_a_log_a_csv_and_a_board_without_a_twin_in_one_line(twin_file, tmp_path, capsys):
    cases = [
        (["--board", str(twin_file), "--grid", "--labels", "states.csv", "--out", str(tmp_path / "a.npz")],
         "not a log: drop --labels"),
        (["--board", str(twin_file), "--grid", "--out", str(tmp_path / "a.csv")], "writes a dataset of presses"),
        (["--board", "eflesh", "--grid", "--out", str(tmp_path / "a.npz")], "has no [twin] table"),
    ]
    for argv, said in cases:
        assert main(["simulate-log", *argv]) == 2
        err = capsys.readouterr().err
        assert said in err and len(err.strip().splitlines()) == 1, err
        assert not list(tmp_path.glob("a.*"))


def test_a_grid_of_no_point_is_refused(twin_file):
    from tactile_manip.errors import ConfigError
    from tactile_manip.sim.twin import stage_grid

    board = load_board(twin_file)
    with pytest.raises(ConfigError, match="positive step"):
        stage_grid(board, step_mm=0.0)
    with pytest.raises(ConfigError, match="leaves nothing"):
        stage_grid(board, margin_mm=max(board.layer.size_mm))
    assert stage_grid(board, step_mm=2.0, depths=1).shape[1] == 3
