"""Presses on any described board: parity with the SuperMag skin, closed forms of moved magnets, symmetry,
force and depth control, the chip model, refusal of a board without geometry, and the real eFlesh field."""

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tactile_manip.boards import load_board
from tactile_manip.errors import ConfigError
from tactile_manip.sim import board_skin as board_skin_module
from tactile_manip.sim.board_press import press, readings_with_chip
from tactile_manip.sim.board_skin import BoardSkin, rotation_matrix
from tactile_manip.sim.magnets import magnet_field_t
from tactile_manip.sim.mbts import MagneticSkin
from tactile_manip.sim.params import for_board

# eFlesh firmware order: centre, left, right, up, down
CENTRE, LEFT, RIGHT, UP, DOWN = range(5)


@pytest.fixture(scope="module")
def eflesh():
    return BoardSkin(load_board("eflesh"))


@pytest.fixture(scope="module")
def supermag():
    return BoardSkin(load_board("supermag-4x4"))


def test_supermag_board_matches_the_magnetic_skin(supermag):
    board = load_board("supermag-4x4")
    p = for_board(board)
    ref = MagneticSkin(board, p.layer, p.magnet)
    np.testing.assert_allclose(supermag.baseline_pad_ut(), ref.baseline_t() * 1e6, rtol=1e-12)
    sample = press(supermag, tip="sphere", tip_diameter_mm=6.0, x_mm=1.3, y_mm=-0.7, force_n=5.0)
    expected = ref.field_change_t(sample.pressure_mpa, supermag.pixel_mm) * 1e6
    peak = np.abs(expected).max()
    assert 50.0 < peak < 1000.0
    np.testing.assert_allclose(sample.field_change_pad_ut, expected, atol=1e-6 * peak)
    # axes already in the pad frame on this board
    np.testing.assert_array_equal(sample.reading_ut, sample.field_change_pad_ut)


def test_rectangular_layer_press_at_centre_is_mirror_symmetric():
    skin = BoardSkin(load_board("anyskin-5"))
    field = skin.to_pad_axes(press(skin, tip="sphere", tip_diameter_mm=6.0, force_n=3.0).reading_ut)
    peak = np.abs(field).max()
    np.testing.assert_allclose(field[CENTRE, :2], 0.0, atol=1e-9 * peak)
    np.testing.assert_allclose(field[LEFT] * [-1, 1, 1], field[RIGHT], atol=1e-6 * peak)
    np.testing.assert_allclose(field[UP] * [1, -1, 1], field[DOWN], atol=1e-6 * peak)


@pytest.mark.parametrize(("name", "fine_mm", "rtol"), [("anyskin-5", 0.2, 0.02), ("eflesh", 0.25, 0.01)])
def test_reading_does_not_depend_on_the_pad_grid(name, fine_mm, rtol):
    board = load_board(name)
    kwargs = {"tip": "sphere", "tip_diameter_mm": 6.0, "x_mm": 1.1, "y_mm": -2.3, "force_n": 3.0}
    coarse = press(BoardSkin(board), **kwargs).reading_ut
    fine = press(BoardSkin(board, pixel_mm=fine_mm), **kwargs).reading_ut
    np.testing.assert_allclose(coarse, fine, atol=rtol * np.abs(fine).max())


def test_rotation_matrix_is_rodrigues():
    omega = np.random.default_rng(0).normal(size=(4, 3))
    np.testing.assert_allclose(rotation_matrix(omega), Rotation.from_rotvec(omega).as_matrix(), atol=1e-14)


def test_magnets_without_pressure_or_motion_change_nothing(eflesh):
    assert not eflesh.field_change_pad_ut(np.zeros((eflesh.n, eflesh.n))).any()
    assert not eflesh.magnets_change_pad_ut(np.zeros((4, 3)), np.zeros((4, 3))).any()


def _shifted_field_ut(board, u_mm):
    """Closed form: every magnet moved by ``u_mm``, minus at rest, pad axes, uT."""
    chips = board.chip_positions_mm()

    def total(points):
        return sum(magnet_field_t(points, shape=m.shape, size_mm=m.size_mm, polarisation_t=m.polarisation_t,
                                  centre_mm=m.position_mm) for m in board.body.magnets) * 1e6
    return total(chips - u_mm) - total(chips)


def test_uniform_layer_motion_moves_the_field_as_the_closed_form(eflesh, monkeypatch):
    u = np.array([0.3, -0.2, -0.5])
    expected = _shifted_field_ut(eflesh.board, u)
    assert np.abs(expected).max() > 50.0
    np.testing.assert_allclose(eflesh.magnets_change_pad_ut(np.tile(u, (4, 1)), np.zeros((4, 3))), expected,
                               rtol=1e-9, atol=1e-9)

    def uniform(pressure_mpa, *, z_mm, **_):
        shape = (len(np.ravel(z_mm)),) + pressure_mpa.shape
        return np.broadcast_to(u, shape + (3,)), np.zeros(shape + (3, 3))

    monkeypatch.setattr(board_skin_module, "layer_fields", uniform)  # the press path with an imposed u
    pressure = np.zeros((eflesh.n, eflesh.n))
    pressure[40:60, 40:60] = 0.01
    np.testing.assert_allclose(eflesh.field_change_pad_ut(pressure), expected, rtol=1e-9, atol=1e-9)


def test_turning_a_disc_magnet_about_its_axis_changes_nothing(eflesh):
    omega = np.tile([0.0, 0.0, 0.7], (4, 1))
    np.testing.assert_allclose(eflesh.magnets_change_pad_ut(np.zeros((4, 3)), omega), 0.0, atol=1e-6)
    tilted = eflesh.magnets_change_pad_ut(np.zeros((4, 3)), np.tile([0.1, 0.0, 0.0], (4, 1)))
    assert np.abs(tilted).max() > 10.0


def test_centre_press_on_eflesh_has_the_boards_fourfold_symmetry(eflesh):
    sample = press(eflesh, tip="sphere", tip_diameter_mm=6.0, force_n=3.0)
    field = eflesh.to_pad_axes(sample.reading_ut)
    peak = np.abs(field).max()
    assert peak > 10.0
    np.testing.assert_allclose(field[CENTRE, :2], 0.0, atol=1e-6 * peak)
    np.testing.assert_allclose(field[[LEFT, RIGHT, UP, DOWN], 2], field[LEFT, 2], rtol=1e-6)
    np.testing.assert_allclose([field[LEFT, 0], -field[RIGHT, 0], field[DOWN, 1], -field[UP, 1]], field[LEFT, 0],
                               rtol=1e-6)
    np.testing.assert_allclose(field[[LEFT, RIGHT], 1], 0.0, atol=1e-6 * peak)
    np.testing.assert_allclose(sample.centre_mm, 0.0, atol=1e-9)


def test_force_control_gives_the_force_and_a_deeper_press_a_larger_change(eflesh):
    light = press(eflesh, tip="sphere", tip_diameter_mm=6.0, x_mm=2.0, y_mm=1.0, force_n=1.0)
    hard = press(eflesh, tip="sphere", tip_diameter_mm=6.0, x_mm=2.0, y_mm=1.0, force_n=4.0)
    assert light.force_n == pytest.approx(1.0, rel=1e-9) and hard.force_n == pytest.approx(4.0, rel=1e-9)
    assert hard.approach_mm > light.approach_mm > 0
    assert np.linalg.norm(hard.reading_ut) > 2.0 * np.linalg.norm(light.reading_ut)
    assert not hard.bottomed_out


@pytest.mark.parametrize("tip", ["sphere", "flat"])
def test_depth_control_reaches_the_approach(eflesh, tip):
    sample = press(eflesh, tip=tip, tip_diameter_mm=5.0, x_mm=-3.0, depth_mm=1.5)
    assert sample.approach_mm == pytest.approx(1.5, rel=0.01)
    again = press(eflesh, tip=tip, tip_diameter_mm=5.0, x_mm=-3.0, force_n=sample.force_n)
    assert again.approach_mm == pytest.approx(sample.approach_mm, rel=1e-3)


def test_press_refuses_bad_requests(eflesh):
    with pytest.raises(ValueError, match="exactly one"):
        press(eflesh, tip_diameter_mm=5.0)
    with pytest.raises(ValueError, match="exactly one"):
        press(eflesh, tip_diameter_mm=5.0, force_n=1.0, depth_mm=1.0)
    with pytest.raises(ValueError, match="misses"):
        press(eflesh, tip_diameter_mm=5.0, x_mm=40.0, force_n=1.0)
    with pytest.raises(ValueError, match="tip"):
        press(eflesh, tip="cone", tip_diameter_mm=5.0, force_n=1.0)


def test_a_board_without_geometry_is_refused_in_one_line():
    with pytest.raises(ConfigError, match="has no geometry and cannot be simulated") as err:
        BoardSkin(load_board("generic:5"))
    assert "\n" not in str(err.value)


def test_chip_model_quantises_adds_noise_and_saturates():
    board = load_board("eflesh")
    change = np.random.default_rng(1).normal(0, 300, (5, 3))
    clean = readings_with_chip(change, board, np.random.default_rng(0), noise_scale=0.0)
    lsb = np.array([2.4, 2.4, 3.872])
    np.testing.assert_allclose(clean.raw_ut / lsb, clean.counts, atol=1e-3)
    assert np.all(np.abs(clean.reading_ut - change) <= lsb / 2 + 1e-4)
    rng = np.random.default_rng(2)
    noisy = np.stack([readings_with_chip(change, board, rng).reading_ut for _ in range(2000)])
    np.testing.assert_allclose(noisy.std(axis=0).mean(axis=0), [10.0, 10.0, 15.0], rtol=0.1)
    rail = board.chip.saturation_counts
    big = readings_with_chip(change, board, rng, baseline_ut=np.full((5, 3), 1e6))
    assert big.saturated.all() and np.all(big.counts == rail)
    small = dataclasses.replace(board.chip, saturation_counts=100)
    assert readings_with_chip(change, dataclasses.replace(board, chip=small), rng).saturated.any()


def test_eflesh_no_contact_field_matches_the_real_runs(eflesh, eflesh_dir):
    sim = eflesh.baseline_ut()
    print("\nchip axes, uT: simulated (x, y, z) | real (x, y, z), the publishers' baseline (raw - subtracted)")
    for run in sorted(eflesh_dir.glob("*_2025*")):
        raw = np.loadtxt(run / "sensor.csv", delimiter=",")[:, 1:]
        real = np.median(raw - np.loadtxt(run / "sensor_post_baselines.csv", delimiter=",")[:, 1:], axis=0)
        real = real.reshape(5, 3)
        print(run.name)
        for i, name in enumerate(("centre", "left", "right", "up", "down")):
            print(f"  {name:6s} " + " ".join(f"{v:7.0f}" for v in sim[i]) + " | "
                  + " ".join(f"{v:7.0f}" for v in real[i]))
        assert np.all(np.abs(sim[:, 2] - real[:, 2]) < 0.35 * np.abs(real[:, 2])), run.name
