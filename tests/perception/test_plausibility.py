"""No answer is silently wrong: a reading no press gives, or an output off the pad or beyond the trained force,
is flagged (``plausible`` False, ``implausible_reason``) and never confident, for the pose estimator, the contact
estimator and the two together; a chip at its rail caps the confidence after the calibration."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from checks import assert_sane_estimate
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytest.importorskip("onnxruntime", reason="the shipped models run on onnxruntime")

from tactile_manip.perception import TactilePoseEstimator, load_reconstructor  # noqa: E402
from tactile_manip.perception.confidence import load_calibration_beside  # noqa: E402
from tactile_manip.perception.contact import STATE_FIELDS, ContactEstimator, ContactState  # noqa: E402
from tactile_manip.perception.tactile_estimator import TactileEstimator  # noqa: E402
from tactile_manip.perception.estimator import (CHANGE_LIMIT_UT, PLAUSIBLE_FIELD_UT,  # noqa: E402
                                                SATURATED_CONFIDENCE_CAP, implausible_field, plausible_limits_ut)
from tactile_manip.perception.reconstruct import ModelFileError  # noqa: E402
from tactile_manip.perception.symmetry import SymmetrizedReconstructor  # noqa: E402
from tactile_manip.shipped import shipped_model  # noqa: E402
from tactile_manip.sim.objects import IndenterPose  # noqa: E402
from tactile_manip.sim.pair import SensorPair  # noqa: E402
from tactile_manip.sim.shapes import make_indenter  # noqa: E402
from tactile_manip.types import IMPLAUSIBLE_READING, TactileReading  # noqa: E402

BOUND_UT = PLAUSIBLE_FIELD_UT["supermag-4x4"]
TRUE_YAW_DEG = 28.4


@pytest.fixture(scope="module")
def pose() -> TactilePoseEstimator:
    """The default model with its calibration, as a user builds it from tactile_manip.shipped."""
    path = shipped_model()
    return TactilePoseEstimator(load_reconstructor(path), calibration=load_calibration_beside(path))


@pytest.fixture(scope="module")
def contact() -> ContactEstimator:
    return ContactEstimator(shipped_model().parent / "contact_supermag.onnx")


@pytest.fixture(scope="module")
def press() -> np.ndarray:
    """A 4 mm hex bar at 28.4 deg and 10 N on the nominal sensor: (4, 4, 3) float32 uT, peak about 400 uT."""
    sample = SensorPair(seed=0).press(make_indenter("hex_bar", size_mm=4.0),
                                      IndenterPose(0.5, -0.5, math.radians(TRUE_YAW_DEG)), 10.0,
                                      np.random.default_rng(0), render_depth=False)
    return sample.field_ut


def assert_no_contact_answer(state: ContactState) -> None:
    """An implausible contact state: flagged, why, and not one number to use."""
    assert not state.plausible and state.implausible_reason, state
    assert all(getattr(state, f) is None and getattr(state, s) is None for f, s in STATE_FIELDS.items()), state
    assert state.values == {} and state.sigmas == {} and state.position_mm is None
    assert isinstance(state.in_contact, bool)
    assert state.in_contact_probability is None or 0.0 <= state.in_contact_probability <= 1.0


def assert_no_angle_answer(est) -> None:
    assert_sane_estimate(est)
    assert not est.plausible and est.implausible_reason and est.reason == IMPLAUSIBLE_READING, est
    assert not est.defined and est.confidence == 0.0 and est.angle_rad == 0.0


# ------------------------------------------------------------------------------------- the measured failures


def test_a_reading_of_1e6_everywhere_gives_no_position_and_no_force(contact) -> None:
    state = contact.estimate(np.full((4, 4, 3), 1e6))  # was x 4608 mm, 9461 N, in contact
    assert_no_contact_answer(state)
    assert state.in_contact and state.context_frames == 0   # the field rule: the model did not run
    assert "1e+06 uT" in state.implausible_reason and "MLX90393" in state.implausible_reason


def test_one_chip_at_5e4_gives_no_position_on_a_20_mm_pad(contact, pose, press) -> None:
    field = press.copy()
    field[0, 0] = 5e4                                        # was y 110 mm
    assert_no_contact_answer(contact.estimate(field))
    est = pose.estimate(field)                               # was flagged saturated at calibrated confidence 0.74
    assert_no_angle_answer(est)
    assert est.saturated_chips == 1 and "chip (0, 0)" in est.implausible_reason


@pytest.mark.parametrize("value, dtype", [(1e30, np.float32), (1e30, np.float64), (1e300, np.float64)])
def test_huge_readings_are_flagged_never_nan(contact, pose, value, dtype) -> None:
    field = np.full((4, 4, 3), value, dtype)                 # 1e30 was NaN in every contact output
    with np.errstate(over="ignore"):                         # 1e300 does not fit the model's float32 input
        state = contact.estimate(field)
    assert_no_contact_answer(state)
    assert_no_angle_answer(pose.estimate(field))


@pytest.mark.parametrize("value", [BOUND_UT, 3000.0, 5000.0, -3000.0])
@pytest.mark.parametrize("chip", [(0, 0), (1, 1), (2, 3)])
def test_one_chip_far_beyond_a_press_but_within_the_chips_range_is_no_answer(pose, press, chip, value) -> None:
    field = press.astype(np.float64)
    field[chip] = value                                      # was -26.9 deg against 28.4 at confidence 1.00
    est = pose.estimate(field)
    assert_no_angle_answer(est)
    assert est.saturated_chips == 0                          # within the chip's range: not flagged saturated


def test_a_railed_chip_caps_the_calibrated_confidence_and_escalation_keeps_the_cap(pose, press) -> None:
    flags = np.zeros((4, 4, 3), bool)
    clean = pose.estimate(TactileReading(press, press, flags, t_host_s=0.0))
    assert clean.confidence > 0.9 and clean.plausible
    flags[1, 2, 2] = True                                    # one chip at its rail: its value is a bound
    railed = pose.estimate(TactileReading(press, press, flags, t_host_s=0.0))
    assert railed.plausible and railed.defined and railed.saturated_chips == 1 and railed.source == "image"
    assert 0.0 < railed.confidence <= SATURATED_CONFIDENCE_CAP * 15 / 16
    escalating = TactilePoseEstimator(pose.reconstructor, calibration=pose.calibration,
                                      escalation=SymmetrizedReconstructor(pose.reconstructor), escalate_below=0.5)
    again = escalating.estimate(TactileReading(press, press, flags, t_host_s=0.0))
    assert again.escalated and again.confidence <= SATURATED_CONFIDENCE_CAP * 15 / 16


@pytest.mark.parametrize("chips, values, name", [
    ([(0, 0)], [[1950.0, -1014.0, -1828.0]], "force_n"),
    ([(0, 2), (0, 3), (1, 3)], [[-511.0, -369.0, -1754.0], [-805.0, 1986.0, 1525.0], [-1228.0, 1262.0, 1541.0]],
     "y_mm"),
])
def test_an_output_off_the_pad_or_beyond_the_trained_force_is_no_answer(contact, chips, values, name) -> None:
    field = np.zeros((4, 4, 3), np.float32)                  # below the field bound
    for chip, value in zip(chips, values):
        field[chip] = value
    # a few chips alone at hundreds of uT: a pattern no press makes, which the board's press check refuses first
    checked = contact.estimate(field)
    assert_no_contact_answer(checked)
    assert checked.implausible_reason.startswith("no press") and checked.in_contact
    unchecked = ContactEstimator(contact.path, press_check=False)   # the model runs: its outputs are judged
    state = unchecked.estimate(field)
    assert_no_contact_answer(state)
    assert state.implausible_reason.startswith(name)
    assert state.in_contact_probability is not None and state.context_frames == 1   # the model's own flag
    bounds = {n: (lo, hi) for n, lo, hi, _ in contact.output_bounds}
    assert bounds["x_mm"] == bounds["y_mm"] == (-10.0, 10.0)   # the SuperMag pad: 20 mm
    assert bounds["force_n"][0] < 0.0 and 20.0 < bounds["force_n"][1] < 25.0


def test_a_non_finite_model_output_is_no_answer(contact, press, monkeypatch) -> None:
    def broken(binding) -> None:
        contact._mean[:] = np.nan

    monkeypatch.setattr(contact.session, "run_with_iobinding", broken)
    state = contact.estimate(press)
    assert_no_contact_answer(state)
    assert state.implausible_reason == "the model gave a non-finite output" and state.in_contact  # field rule


# ------------------------------------------------------------------- the rest of the contract, plausible too


def test_a_plausible_press_is_an_answer_from_both(contact, pose, press) -> None:
    both = TactileEstimator(pose, contact).estimate(press)
    assert both.plausible and both.angle.plausible and both.contact.plausible
    assert both.angle.implausible_reason == both.contact.implausible_reason == ""
    assert both.angle.defined and both.contact.force_n is not None and both.position_mm is not None


def test_the_composed_estimate_of_an_implausible_reading_has_no_position(contact, pose, press) -> None:
    field = press.copy()
    field[2, 1, 2] = -4000.0
    both = TactileEstimator(pose, contact).estimate(field)
    assert not both.plausible and both.position_mm is None
    assert_no_angle_answer(both.angle)
    assert_no_contact_answer(both.contact)


def test_an_implausible_frame_makes_the_frame_mean_implausible_and_a_batch_flags_only_its_reading(pose, press):
    bad = press.copy()
    bad[3, 3, 0] = 2.5e3
    assert_no_angle_answer(pose.estimate_frames([press, press, bad]))   # its mean is below the bound
    good, flagged = pose.estimate_many([press, bad])
    assert good.plausible and good == pose.estimate(press)
    assert_no_angle_answer(flagged)


def test_an_implausible_reading_stays_out_of_the_context(contact_model_files, labelled_presses) -> None:
    *_, path = contact_model_files
    readings = labelled_presses().readings[:3]
    alone, spoiled = ContactEstimator(path), ContactEstimator(path)
    assert alone.context_frames > 1
    bad = readings[1].copy()
    bad[1, 1, 0] = 2e4                                        # more than the chip can report as a change
    for i, reading in enumerate(readings):
        state = alone.estimate(reading, t_s=0.05 * i)
        if i == 1:
            flagged = spoiled.estimate(bad, t_s=0.05 * i)
            assert_no_contact_answer(flagged)
            assert "MLX90393" in flagged.implausible_reason and "13107" in flagged.implausible_reason
        assert replace(spoiled.estimate(reading, t_s=0.05 * i), latency_s=0.0) == replace(state, latency_s=0.0)


# --------------------------------------------------------------------------------- where the bounds come from


def test_the_limits_come_from_the_model_else_its_board_else_the_chip() -> None:
    meta = {"input": {"plausible_field_ut": 800.0}}
    np.testing.assert_array_equal(plausible_limits_ut(meta, channels=3, board_layout="supermag-4x4"), [800.0] * 3)
    np.testing.assert_array_equal(plausible_limits_ut({}, channels=3, board_layout="supermag-4x4"), [BOUND_UT] * 3)
    np.testing.assert_array_equal(plausible_limits_ut({}, channels=3, board_layout="anyskin-5"), CHANGE_LIMIT_UT)
    big = {"input": {"plausible_field_ut": 1e9}}
    np.testing.assert_array_equal(plausible_limits_ut(big, channels=3, board_layout="x"), CHANGE_LIMIT_UT)
    assert np.isinf(plausible_limits_ut({}, channels=3, board_layout="x", magnetic_ut=False)).all()
    for bad in (0.0, -5.0, "500", True):
        with pytest.raises(ModelFileError, match="plausible_field_ut"):
            plausible_limits_ut({"input": {"plausible_field_ut": bad}}, channels=3, board_layout="supermag-4x4")


def test_the_reason_names_the_chip_the_value_and_the_bound() -> None:
    field = np.zeros((4, 4, 3))
    assert implausible_field(field, np.full(3, BOUND_UT)) == ""
    field[2, 1, 2], field[0, 3, 1] = 2500.0, np.nan
    why = implausible_field(field, np.full(3, BOUND_UT))
    assert why.startswith("chip (0, 3) reads nan uT along y (and 1 more channel)") and "2000 uT" in why
    field[0, 3, 1] = 0.0
    assert implausible_field(field, np.full(3, BOUND_UT)).startswith("chip (2, 1) reads 2500 uT along z, ")


def test_a_stored_field_bound_and_trained_range_are_read(contact_model_of_layout, press) -> None:
    from tactile_manip.perception.reconstruct import read_metadata

    shipped = read_metadata(shipped_model().parent / "contact_supermag.onnx")
    targets = dict(shipped["targets"], range={"force_n": [2.0, 3.0]})
    model = ContactEstimator(contact_model_of_layout("supermag-4x4", targets=targets,
                                                     input=dict(shipped["input"], plausible_field_ut=300.0)))
    np.testing.assert_array_equal(model.plausible_limits_ut, [300.0] * 3)
    assert dict((n, (lo, hi)) for n, lo, hi, _ in model.output_bounds)["force_n"] == (1.75, 3.25)
    assert_no_contact_answer(model.estimate(press))          # its peak is above 300 uT
    state = model.estimate(press * 0.5)                      # below 300 uT: the model runs, its force is > 3.25 N
    assert not state.plausible and state.implausible_reason.startswith("force_n")
    with pytest.raises(ModelFileError, match="range"):
        ContactEstimator(contact_model_of_layout("supermag-4x4", targets=dict(shipped["targets"],
                                                                              range={"force_n": "2 to 3"})))


def test_export_stores_the_field_bound_and_the_trained_ranges(contact_model_files, tmp_path) -> None:
    pytest.importorskip("torch", reason="exporting a contact model needs torch")
    from tactile_manip.learning.contact.export import export_contact_onnx

    _, run, _ = contact_model_files
    meta = export_contact_onnx(run / "best.pt", tmp_path / "c.onnx", plausible_field_ut=1500.0,
                               target_ranges={"force_n": (0.0, 10.0)})
    assert meta["input"]["plausible_field_ut"] == 1500.0 and meta["targets"]["range"] == {"force_n": [0.0, 10.0]}
    model = ContactEstimator(tmp_path / "c.onnx")
    np.testing.assert_array_equal(model.plausible_limits_ut, [1500.0] * 3)
    assert dict((n, (lo, hi)) for n, lo, hi, _ in model.output_bounds)["force_n"] == (-2.5, 12.5)
    for kwargs in ({"plausible_field_ut": -1.0}, {"target_ranges": {"force_n": (3.0, 1.0)}},
                   {"target_ranges": {"torque_nm": (0.0, 1.0)}}):
        with pytest.raises(ValueError):
            export_contact_onnx(run / "best.pt", tmp_path / "d.onnx", **kwargs)
    assert not list(tmp_path.glob("d.onnx*"))


def test_an_image_model_export_stores_the_field_bound_for_the_pose_estimator(onnx_4x4, tmp_path) -> None:
    import warnings

    torch = pytest.importorskip("torch", reason="exporting a model needs torch")
    from tactile_manip.learning.cvae.export import export_onnx

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        meta = export_onnx(onnx_4x4.path.parent / "model.pt", tmp_path / "m.onnx", pixel_mm=0.5,
                           plausible_field_ut=900.0)
    assert meta["input"]["plausible_field_ut"] == 900.0
    model = load_reconstructor(tmp_path / "m.onnx")
    for reconstructor in (model, SymmetrizedReconstructor(model)):   # read through the wrapper too
        estimator = TactilePoseEstimator(reconstructor, angle_source="image")
        np.testing.assert_array_equal(estimator.plausible_limits_ut, [900.0] * 3)
        assert_no_angle_answer(estimator.estimate(np.full((4, 4, 3), 950.0)))
    with pytest.raises(ValueError, match="plausible_field_ut"):
        export_onnx(onnx_4x4.path.parent / "model.pt", tmp_path / "n.onnx", pixel_mm=0.5, plausible_field_ut=0.0)


# ------------------------------------------------------------------------- random corruptions (hypothesis)

KINDS = ("huge", "absurd", "inf", "nan", "negative huge")


def _corrupt(field: np.ndarray, chips: list[tuple[int, int, int]], kind: str, scale: float) -> np.ndarray:
    out = field.astype(np.float64)
    for r, c, a in chips:
        out[r, c, a] = {"huge": 10.0 ** (4 + 34 * scale), "negative huge": -(10.0 ** (4 + 34 * scale)),
                        "absurd": math.copysign(BOUND_UT + scale * (6553.0 - BOUND_UT), scale - 0.5),
                        "inf": math.copysign(math.inf, scale - 0.5), "nan": math.nan}[kind]
    return out


corruptions = st.tuples(
    st.lists(st.tuples(st.integers(0, 3), st.integers(0, 3), st.integers(0, 2)), min_size=1, max_size=3),
    st.sampled_from(KINDS), st.floats(0.0, 1.0), st.sampled_from([np.float32, np.float64]),
    st.lists(st.booleans(), min_size=48, max_size=48))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(corruption=corruptions)
def test_a_corrupted_reading_is_refused_by_name_or_flagged_never_confident_never_nan(contact, pose, press,
                                                                                    corruption) -> None:
    chips, kind, scale, dtype, flags = corruption
    with np.errstate(over="ignore"):                          # float32 of 1e38 and beyond is inf: refused
        field = _corrupt(press, chips, kind, scale).astype(dtype)
    saturated = np.array(flags).reshape(4, 4, 3)
    reading = TactileReading(field, field, saturated, t_host_s=0.0)
    both = TactileEstimator(pose, contact)
    for estimate in (lambda: both.estimate(field), lambda: both.estimate(reading)):
        try:
            with np.errstate(over="ignore"):
                est = estimate()
        except ValueError as e:
            assert not np.isfinite(field).all() and "NaN or infinite" in str(e)
            continue
        assert np.isfinite(field).all()
        assert_no_angle_answer(est.angle)
        assert_no_contact_answer(est.contact)
        assert not est.plausible and est.position_mm is None


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(flags=st.lists(st.booleans(), min_size=48, max_size=48), scale=st.floats(0.05, 4.0),
       dtype=st.sampled_from([np.float32, np.float64]))
def test_railed_chips_in_a_plausible_press_are_never_confident(pose, press, flags, scale, dtype) -> None:
    saturated = np.array(flags).reshape(4, 4, 3)
    field = (press * scale).astype(dtype)                     # up to 4 times the press: still below the bound
    est = pose.estimate(TactileReading(field, field, saturated, t_host_s=0.0))
    assert_sane_estimate(est)
    assert est.plausible and est.saturated_chips == int(saturated.any(axis=-1).sum())
    if saturated.any():
        assert est.confidence <= SATURATED_CONFIDENCE_CAP * (1.0 - est.saturated_chips / 16)


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_a_float64_reading_beyond_float32_is_judged_without_an_overflow_warning(contact, pose) -> None:
    reading = np.full((4, 4, 3), 1e300)
    assert_no_contact_answer(contact.estimate(reading))
    assert_no_angle_answer(pose.estimate(reading))
