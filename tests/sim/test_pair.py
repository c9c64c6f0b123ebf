"""The sensor pair end to end: published magnitudes, symmetry, linearity, convergence, bad input."""

import dataclasses

import numpy as np
import pytest

from tactile_manip.sim.objects import IndenterPose
from tactile_manip.sim.shapes import make_indenter
from tactile_manip.sim.pair import SensorPair
from tactile_manip.sim.params import ContactParams, MagnetParams, SimParams

CENTRE = IndenterPose()


@pytest.fixture(scope="module")
def pair():
    return SensorPair()


def _peak(sample):
    return float(np.abs(sample.field_change_ut).max())


@pytest.mark.parametrize("name", ["allen_key", "letter_r"])
def test_paper_objects_at_10n_match_published_magnitudes(pair, name):
    s = pair.press(make_indenter(name), IndenterPose(0.5, -0.5, 0.3), 10.0, np.random.default_rng(0))
    assert s.contact and s.force_n == 10.0
    assert 0.4 <= float(s.depth_mm.max()) <= 1.9                # docs/design.md, Physics sources: 0.75-1.7 mm at 10 N
    assert 50.0 <= _peak(s) <= 500.0                           # docs/design.md, Physics sources: ~80-300 uT
    assert not s.saturated.any()
    assert s.field_ut.dtype == np.float32 and s.field_ut.shape == (4, 4, 3)
    assert s.depth_mm.dtype == np.float32 and s.depth_mm.shape == (200, 200)
    assert s.approach_mm > s.skin_approach_mm > 0               # the gel is softer than the skin


def test_nothing_saturates_at_defaults_for_the_raw_reading(pair):
    s = pair.press(make_indenter("cylinder", size_mm=8.0), CENTRE, 11.0, np.random.default_rng(1))
    lim = np.array([0.2, 0.2, 0.323]) * 32767
    assert np.all(np.abs(s.field_raw_ut) < 0.97 * lim)


def test_mirror_symmetry_of_a_centred_rod(pair):
    s = pair.press(make_indenter("cylinder", size_mm=4.0), CENTRE, 8.0, np.random.default_rng(0))
    b = s.field_change_ut.astype(np.float64)
    tol = 1e-4 * np.abs(b).max()
    # x -> -x mirror (columns reversed): Bx odd, By and Bz even
    np.testing.assert_allclose(b[:, ::-1, 0], -b[..., 0], atol=tol)
    np.testing.assert_allclose(b[:, ::-1, 1:], b[..., 1:], atol=tol)
    # y -> -y mirror (rows reversed): By odd, Bx and Bz even
    np.testing.assert_allclose(b[::-1, :, 1], -b[..., 1], atol=tol)
    np.testing.assert_allclose(b[::-1, :, ::2], b[..., ::2], atol=tol)


def test_field_change_is_near_linear_at_small_force(pair):
    rod = make_indenter("hex_bar", size_mm=5.0)
    rng = np.random.default_rng(0)
    small = pair.press(rod, CENTRE, 0.1, rng).field_change_ut
    double = pair.press(rod, CENTRE, 0.2, rng).field_change_ut
    i = np.unravel_index(np.abs(small).argmax(), small.shape)
    assert double[i] / small[i] == pytest.approx(2.0, rel=0.15)
    ten = pair.press(rod, CENTRE, 10.0, rng).field_change_ut
    assert abs(ten[i]) < 100 * abs(small[i])  # stiffening as the contact widens


def test_dipole_discretisation_converges():
    rod = make_indenter("cylinder", size_mm=5.0)
    coarse = SensorPair().press(rod, IndenterPose(1.0, 0.5, 0.4), 10.0, np.random.default_rng(0))
    fine = SensorPair(SimParams(magnet=MagnetParams(cell_mm=0.25, thickness_nodes=10))).press(
        rod, IndenterPose(1.0, 0.5, 0.4), 10.0, np.random.default_rng(0))
    err = np.abs(coarse.field_change_ut - fine.field_change_ut).max()
    assert err < 0.05 * _peak(fine)


def test_contact_grid_invariance_of_the_whole_pair():
    r = make_indenter("letter_r")
    a = SensorPair().press(r, CENTRE, 10.0, np.random.default_rng(0))
    b = SensorPair(SimParams(contact=ContactParams(pixel_mm=0.125))).press(r, CENTRE, 10.0,
                                                                           np.random.default_rng(0))
    assert a.approach_mm == pytest.approx(b.approach_mm, rel=0.02)
    assert np.abs(a.field_change_ut - b.field_change_ut).max() < 0.05 * _peak(b)


def test_half_millimetre_shift_of_the_r_changes_readings_by_tens_of_microtesla(pair):
    r = make_indenter("letter_r")
    a = pair.press(r, CENTRE, 10.0, np.random.default_rng(0)).field_change_ut
    b = pair.press(r, IndenterPose(0.5, 0.0), 10.0, np.random.default_rng(0)).field_change_ut
    assert np.abs(a - b).max() > 10.0


def test_rotating_moments_matters(pair):
    """A translation-only skin model gives a qualitatively different field (docs/design.md, Physics sources)."""
    rod = make_indenter("cylinder", size_mm=4.0)
    full = pair.press(rod, CENTRE, 10.0, np.random.default_rng(0)).field_change_ut
    skin = pair.skin
    moved = skin._moved_moments
    skin._moved_moments = lambda grad: skin._moments  # positions move, moments keep their direction
    try:
        translation_only = pair.press(rod, CENTRE, 10.0, np.random.default_rng(0)).field_change_ut
    finally:
        skin._moved_moments = moved
    assert np.abs(full - translation_only).max() > 0.3 * np.abs(full).max()


def test_object_off_the_pad_is_a_valid_no_contact_sample(pair):
    s = pair.press(make_indenter("letter_r"), IndenterPose(40.0, 0.0), 10.0, np.random.default_rng(0))
    assert not s.contact and s.force_n == 0.0 and not s.depth_mm.any() and not s.contact_mask.any()
    assert not s.field_change_ut.any()
    assert np.abs(s.field_ut).max() < 60.0  # noise and drift only
    assert np.isfinite(s.field_ut).all()


def test_a_force_past_the_layer_is_flagged_and_refused_on_request(pair):
    from tactile_manip.errors import SimulationError

    normal = pair.press(make_indenter("letter_r"), CENTRE, 10.0, np.random.default_rng(0), render_depth=False)
    assert not normal.bottomed_out and normal.check_within_layer() is normal
    crushed = pair.press(make_indenter("letter_r"), CENTRE, 1e6, np.random.default_rng(0), render_depth=False)
    assert crushed.bottomed_out and crushed.approach_mm > pair.board.layer.thickness_mm
    with pytest.raises(SimulationError, match=r"1e\+06 N drives letter_r \d+ mm into the 2.5 mm layer"):
        crushed.check_within_layer()


def test_same_rng_same_sample(pair):
    a = pair.press(make_indenter("allen_key"), CENTRE, 10.0, np.random.default_rng(5))
    b = pair.press(make_indenter("allen_key"), CENTRE, 10.0, np.random.default_rng(5))
    np.testing.assert_array_equal(a.field_ut, b.field_ut)
    np.testing.assert_array_equal(a.depth_mm, b.depth_mm)


@pytest.mark.parametrize("force", [0.0, -1.0, np.nan, np.inf])
def test_bad_force_raises(pair, force):
    with pytest.raises(ValueError, match="force_n"):
        pair.press(make_indenter("letter_r"), CENTRE, force, np.random.default_rng(0))


def test_bad_parameters_raise_before_any_work():
    with pytest.raises(ValueError, match="remanence_t"):
        MagnetParams(remanence_t=np.nan)
    with pytest.raises(ValueError, match="skin_modulus_kpa"):
        SimParams(layer=dataclasses.replace(SimParams().layer, skin_modulus_kpa=-200.0))
    with pytest.raises(ValueError, match="tilt"):
        IndenterPose(tilt_x_rad=1.0)


def test_ramp_is_a_125hz_press_sequence(pair):
    profile = SensorPair.ramp_profile(5.0, rise_s=0.08, hold_s=0.04)
    seq = pair.ramp(make_indenter("cylinder", size_mm=4.0), CENTRE, profile, np.random.default_rng(0))
    assert len(seq) == len(profile)
    assert np.diff([s.t_s for s in seq]) == pytest.approx(np.full(len(seq) - 1, 0.008))
    assert not seq[-1].contact and seq[len(seq) // 2].contact
    peaks = [_peak(s) for s in seq]
    rise = peaks[: int(np.argmax(profile))]
    assert np.all(np.diff(rise) > 0)  # the field grows while the force rises
    assert all(s.depth_mm is None for s in seq)  # no ground truth rendered unless asked


@pytest.mark.parametrize("name, pose, force_n", [("hex_bar", IndenterPose(1.0, -0.5, 0.4, 0.03, -0.02), 3.0),
                                                  ("flat_bar", IndenterPose(-2.0, 1.5, 2.0), 12.0),
                                                  ("letter_r", CENTRE, 10.0)])
def test_the_expected_reading_is_the_press_clean_field_without_its_image(name, pose, force_n):
    params = SimParams(magnet=MagnetParams(remanence_t=0.035))  # not the nominal sensor: its own baseline comes off
    pair = SensorPair(params, seed=3)
    rod = make_indenter(name)
    sample = pair.press(rod, pose, force_n, np.random.default_rng(0), render_depth=False)
    expected = pair.expected_reading_ut(rod, pose, force_n)
    assert expected.shape == (4, 4, 3) and expected.dtype == np.float64
    assert np.abs(expected).max() > 20.0  # a press well above the noise
    np.testing.assert_allclose(expected, sample.field_clean_ut, rtol=1e-5, atol=1e-3)
    assert not pair.expected_reading_ut(rod, IndenterPose(40.0, 0.0), force_n).any()  # off the pad
    with pytest.raises(ValueError, match="force_n"):
        pair.expected_reading_ut(rod, pose, float("nan"))
