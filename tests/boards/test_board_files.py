"""Board files: the shipped boards, generic:N, a user's own file, and every way a file can be wrong."""

from __future__ import annotations

import numpy as np
import pytest

from checks import assert_one_line_error
from tactile_manip.boards import Board, ChipSpec, board_names, load_board
from tactile_manip.boards.spec import ChipGridSpec, axis_matrix
from tactile_manip.cli import main
from tactile_manip.errors import ConfigError

GRID_2X3 = """
[board]
name = "my-grid"
grid = [2, 3]
pitch_mm = 4.0

[chip_grid]
rows = 2
cols = 3
pitch_mm = 4.0
"""

TWO_CHIPS = """
[board]
name = "two"
grid = [1, 2]
pitch_mm = 6.0

[[chips]]
cell = [0, 0]
position_mm = [-3.0, 0.0]
axes = ["-y", "+x", "+z"]

[[chips]]
cell = [0, 1]
position_mm = [3.0, 0.0]
"""

SIM_TABLES = """
[body]
kind = "layer"
remanence_t = 0.05

[layer]
size_mm = [20.0, 10.0]
thickness_mm = 2.0
modulus_kpa = 150.0
gap_mm = 1.0
"""


def _write(tmp_path, text, name="board.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def _same_layout(a, b) -> bool:
    return (a.grid == b.grid and np.array_equal(a._index, b._index) and np.array_equal(a._rot, b._rot)
            and np.array_equal(np.nan_to_num(a.positions_mm()), np.nan_to_num(b.positions_mm())))


def _cross(pitch_mm: float) -> Board:
    """The five-chip cross (centre, left, right, up, down) in a 3x3 reading, chip axes turned as the AnySkin
    visualiser turns them."""
    cells = ((1, 1), (1, 0), (1, 2), (0, 1), (2, 1))
    chips = tuple(ChipSpec(cell=cell, position_mm=((cell[1] - 1) * pitch_mm, (1 - cell[0]) * pitch_mm),
                           rotation_deg=rot) for cell, rot in zip(cells, (90.0, 90.0, 180.0, -90.0, 0.0)))
    return Board(name="cross", grid=(3, 3), chips=chips, pitch_mm=pitch_mm)


def test_the_shipped_files_give_the_layouts_the_boards_always_had():
    supermag, anyskin = load_board("supermag-4x4"), load_board("anyskin-5")
    assert {"supermag-4x4", "anyskin-5", "eflesh"} <= set(board_names())
    grid = Board(name="grid", grid=(4, 4), pitch_mm=5.0, chips=ChipGridSpec(rows=4, cols=4, pitch_mm=5.0).chips())
    assert _same_layout(supermag, grid)
    assert supermag._identity                                      # the default board's frames stay a reshape
    assert _same_layout(anyskin, _cross(7.0))
    # the eFlesh cube sits on the AnySkin board: the same chips at the same places in the same firmware order; its
    # chips' axes are the ones its runs ask for (each chip read upside down, a proper turn, over discs polarised -z),
    # where anyskin-5 keeps the AnySkin visualiser's turns, having no data of its own skin to fit them on
    eflesh = load_board("eflesh")
    assert eflesh.grid == anyskin.grid and np.array_equal(eflesh._index, anyskin._index)
    np.testing.assert_array_equal(eflesh.positions_mm(), anyskin.positions_mm())
    assert [round(float(np.linalg.det(m))) for m in eflesh.chip_matrices()] == [1] * 5
    assert [m[2, 2] for m in eflesh.chip_matrices()] == [-1.0] * 5         # each chip's z along the pad's -z
    assert [m.polarisation_t for m in eflesh.body.magnets] == [(0.0, 0.0, -1.45)] * 4


def test_every_shipped_board_but_generic_can_be_simulated_and_says_its_chip_model():
    for name in board_names():
        board = load_board(name)
        assert board.simulatable, name
        board.require_simulation()
        z = board.chip_positions_mm()[:, 2]
        assert np.allclose(z, -(board.layer.thickness_mm + board.layer.gap_mm))
    eflesh = load_board("eflesh")
    assert eflesh.body.kind == "magnets" and len(eflesh.body.magnets) == 4
    assert (eflesh.chip.lsb_xy_ut, eflesh.chip.lsb_z_ut) == (2.4, 3.872)   # the published runs' steps
    assert eflesh.wire.format == "anyskin"


def test_generic_boards_have_no_geometry_and_refuse_simulation():
    board = load_board("generic:10")
    assert board.shape == (1, 10, 3) and board.n_chips == 10 and not board.simulatable
    layout = load_board("generic:10")
    frame = np.arange(30, dtype=np.float32).reshape(10, 3)
    np.testing.assert_array_equal(layout.reading_from_chips(frame), frame.reshape(1, 10, 3))
    assert np.isnan(layout.positions_mm()).all()
    with pytest.raises(ConfigError, match="generic:10 has no geometry and cannot be simulated"):
        board.require_simulation()
    for bad in ("generic:0", "generic:65", "generic:ten", "generic:", "generic:-3"):
        with pytest.raises(ConfigError, match="chip count N from 1 to 64"):
            load_board(bad)


def test_a_users_file_describes_a_grid_and_turned_chips(tmp_path):
    grid = load_board(str(_write(tmp_path, GRID_2X3)))
    assert grid.name == "my-grid" and grid.shape == (2, 3, 3)
    assert grid.positions_mm()[1, 2].tolist() == [4.0, -2.0]
    two = load_board(_write(tmp_path, TWO_CHIPS + SIM_TABLES, "two.toml"))
    assert two.simulatable and two.layer.size_mm == (20.0, 10.0)
    layout = load_board(str(two.path))
    reading = layout.reading_from_chips(np.array([[1.0, 0, 5], [1.0, 0, 6]], np.float32))
    np.testing.assert_allclose(reading[0, 0], [0, -1, 5], atol=1e-6)   # chip x along pad -y
    np.testing.assert_allclose(reading[0, 1], [1, 0, 6])


def test_an_axis_map_is_the_same_turn_as_its_angle():
    turned = load_board("anyskin-5").chips[3]                       # rotation_deg = -90
    np.testing.assert_array_equal(turned.matrix(), axis_matrix(("-y", "+x", "+z")))
    np.testing.assert_array_equal(axis_matrix(("+x", "-y", "-z")), np.diag([1.0, -1.0, -1.0]))  # mounted upside down
    for bad in (("+x", "+x", "+z"), ("x", "+y", "+z"), ("+x", "+y")):
        with pytest.raises(ValueError):
            axis_matrix(bad)


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("grid = [2, 3]\n", ""), "missing key(s) board.grid"),
    (lambda t: t.replace("pitch_mm = 4.0\n\n[chip_grid]", "pitch_mm = 4.0\ncolour = 'red'\n\n[chip_grid]"),
     "unknown key(s) board.colour"),
    (lambda t: t.replace("rows = 2", "rows = 3"), "9 chips do not fit the 2x3 reading grid"),
    (lambda t: t.replace("pitch_mm = 4.0\n", "pitch_mm = 2.0\n", 2).replace("pitch_mm = 4.0", "pitch_mm = 2.0"),
     "overlap: their centres are 2.00 mm apart"),
    (lambda t: t.replace("[chip_grid]\nrows = 2\ncols = 3\npitch_mm = 4.0\n", ""), "got neither"),
    (lambda t: t + "[body]\nkind = 'layer'\nremanence_t = 0.05\n", "[body] without [layer]"),
    (lambda t: t.replace("grid = [2, 3]", "grid = [2, 0]"), "board.grid must be two integers from 1 to 64"),
    (lambda t: t + "[wire]\nformat = 'i2c'\n", "wire.format must be one of supermag, anyskin"),
    (lambda t: t + "[chip]\nlsb_xy_ut = -0.2\n", "chip.lsb_xy_ut must be > 0.0"),
    (lambda t: t + "[layer]\nsize_mm = [20.0, 10.0]\nthickness_mm = 2.0\nmodulus_kpa = 1.0\ngap_mm = 1.0\n"
                   "[body]\nkind = 'magnets'\n[[body.magnets]]\nshape = 'cylinder'\nsize_mm = [3.0, 1.0]\n"
                   "position_mm = [0.0, 0.0, -3.2]\npolarisation_t = [0.0, 0.0, 1.3]\n",
     "body.magnets[0] reaches below the chips' plane"),
    (lambda t: t + "[layer]\nsize_mm = [20.0, 10.0]\nthickness_mm = 2.0\nmodulus_kpa = 1.0\ngap_mm = 1.0\n"
                   "[body]\nkind = 'magnets'\n[[body.magnets]]\nshape = 'cylinder'\nsize_mm = [3.0, 1.0, 2.0]\n"
                   "position_mm = [0.0, 0.0, -1.0]\npolarisation_t = [0.0, 0.0, 1.3]\n",
     "cylinder magnet's size_mm has 2 values"),
    (lambda t: t + "[layer]\nsize_mm = [20.0, 10.0]\nthickness_mm = 2.0\nmodulus_kpa = 1.0\ngap_mm = 1.0\n"
                   "[body]\nkind = 'magnets'\n[[body.magnets]]\nshape = 'cylinder'\nsize_mm = [3.0, 1.0]\n"
                   "position_mm = [0.0, 0.0, 0.8]\npolarisation_t = [0.0, 0.0, 1.3]\n",
     "body.magnets[0]'s centre z = 0.8 mm is outside the layer"),
    (lambda t: t + "[layer]\nsize_mm = [20.0, 10.0]\nthickness_mm = 2.0\nmodulus_kpa = 1.0\ngap_mm = 1.0\n"
                   "[body]\nkind = 'magnets'\n[[body.magnets]]\nshape = 'cylinder'\nsize_mm = [3.0, 1.0]\n"
                   "position_mm = [0.0, 0.0, -1.0]\npolarisation_t = [1.0, 0.0, 1.3]\n",
     "is a cylinder polarised off its axis"),
])
def test_a_bad_board_file_is_refused_naming_the_field(tmp_path, edit, message):
    path = _write(tmp_path, edit(GRID_2X3))
    with pytest.raises(ConfigError, match=None) as caught:
        load_board(path)
    assert message in str(caught.value) and str(path) in str(caught.value)


def test_chips_that_share_a_cell_are_refused(tmp_path):
    text = TWO_CHIPS.replace("cell = [0, 1]", "cell = [0, 0]")
    with pytest.raises(ConfigError, match=r"chips\[0\] and chips\[1\] feed the same cell"):
        load_board(_write(tmp_path, text))


def test_an_unknown_board_names_the_known_ones(tmp_path):
    with pytest.raises(ConfigError, match="known boards: anyskin-5, eflesh, supermag-4x4, or generic:N"):
        load_board("reskin-9")
    with pytest.raises(ConfigError, match="config file not found"):
        load_board(tmp_path / "missing.toml")


def _import_args(tmp_path, board, columns=16):
    rows = 40
    t = np.arange(rows) * 0.01
    readings = np.column_stack([t, np.random.default_rng(0).normal(0, 5, (rows, columns - 1))])
    labels = np.column_stack([t, np.linspace(0, 1, rows), np.zeros(rows), np.zeros(rows)])
    np.savetxt(tmp_path / "sensor.csv", readings, delimiter=",")
    np.savetxt(tmp_path / "states.csv", labels, delimiter=",")
    return ["import", "--readings-csv", str(tmp_path / "sensor.csv"), "--labels-csv", str(tmp_path / "states.csv"),
            "--label-columns", "time_s,x_mm,y_mm,z_mm", "--targets", "x_mm", "--board", board,
            "--out", str(tmp_path / "out.npz")]


def test_import_takes_a_board_by_name_by_file_and_as_generic(tmp_path, capsys):
    from tactile_manip.data import load_dataset

    assert main(_import_args(tmp_path, "generic:10", columns=31)) == 0
    assert load_dataset(tmp_path / "out.npz").provenance["layout"] == "generic:10"
    (tmp_path / "out.npz").unlink()
    board = _write(tmp_path, GRID_2X3.replace("rows = 2", "rows = 1").replace("grid = [2, 3]", "grid = [1, 3]"))
    assert main(_import_args(tmp_path, str(board), columns=10)) == 0
    assert load_dataset(tmp_path / "out.npz").readings.shape[1:] == (1, 3, 3)


@pytest.mark.parametrize("board, columns, needle", [
    ("generic:10", 16, "16 columns, expected 31"),
    ("generic:0", 16, "chip count N from 1 to 64"),
    ("hexagon", 16, "unknown board 'hexagon'"),
])
def test_import_refuses_a_board_that_does_not_fit_in_one_line_and_writes_nothing(tmp_path, capsys, board, columns,
                                                                                 needle):
    assert main(_import_args(tmp_path, board, columns=columns)) == 2
    assert_one_line_error(capsys.readouterr().err, "import", needle)
    assert not (tmp_path / "out.npz").exists()


def test_import_refuses_a_bad_board_file_in_one_line(tmp_path, capsys):
    board = _write(tmp_path, GRID_2X3.replace("pitch_mm = 4.0\n", "", 1))
    assert main(_import_args(tmp_path, str(board))) == 2
    assert_one_line_error(capsys.readouterr().err, "import", "missing key(s) board.pitch_mm")
    assert not (tmp_path / "out.npz").exists()


def test_the_wire_formats_a_board_may_name_are_the_serial_backends(tmp_path):
    from tactile_manip.wire import WIRE_FORMATS

    for name in board_names():
        assert load_board(name).wire.format in WIRE_FORMATS
    with pytest.raises(ConfigError, match="wire.format must be one of supermag, anyskin, got 'morse'"):
        load_board(_write(tmp_path, GRID_2X3 + '\n[wire]\nformat = "morse"\n'))


def test_the_emulator_streams_a_boards_chips_and_refuses_what_it_cannot(tmp_path, capsys):
    from tactile_manip.sensors.simulated.emulator import EmulatorConfig, FirmwareEmulator
    from tactile_manip.wire import make_decoder

    emulator = FirmwareEmulator(EmulatorConfig(wire_format="anyskin", board="eflesh"))
    decoder = make_decoder("anyskin", n_chips=5, chip=load_board("eflesh").chip)
    frames = decoder.feed(emulator.frame_bytes(0, 0.0, np.random.default_rng(0)) * 3)
    assert frames and frames[-1].field_ut.shape == (5, 3)
    with pytest.raises(ValueError, match="generic:5 has no geometry and cannot be simulated"):
        EmulatorConfig(wire_format="anyskin", board="generic:5")
    with pytest.raises(ValueError, match=r"has no \[body\] and \[layer\]"):
        EmulatorConfig(wire_format="anyskin", board=str(_write(tmp_path, TWO_CHIPS.replace(
            "[board]", "[wire]\nformat = \"anyskin\"\n\n[board]"), "two.toml")))
    with pytest.raises(ValueError, match="supermag wire format carries the 16 chips"):
        EmulatorConfig(wire_format="supermag", board="eflesh")
    assert main(["emulate", "--board", "generic:5", "--frames", "1"]) == 2
    assert_one_line_error(capsys.readouterr().err, "emulate", "has no geometry and cannot be simulated")
