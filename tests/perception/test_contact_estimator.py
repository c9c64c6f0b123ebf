"""ContactEstimator: an exported contact model on onnxruntime, one reading at a time, with its own context."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime", reason="the contact estimator runs onnxruntime")

from tactile_manip.errors import SensorTimeoutError  # noqa: E402
from tactile_manip.perception.contact import ContactEstimator, ContactState  # noqa: E402
from tactile_manip.perception.contact_context import ContextBuffer, context_windows  # noqa: E402
from tactile_manip.perception.reconstruct import ModelFileError  # noqa: E402
from tactile_manip.types import TactileReading  # noqa: E402


def test_a_stream_of_readings_gives_what_the_model_gives_on_the_dataset_windows(contact_model_files,
                                                                                labelled_presses) -> None:
    _, _, model_path = contact_model_files
    data = labelled_presses()
    est = ContactEstimator(model_path)
    times = data.extra("time_s")
    states = [est.estimate(data.readings[i], t_s=times[i]) for i in range(len(data))]
    windows = context_windows(data.readings, frames=3, max_gap_s=1.0, time_s=times)
    mean, sigma = est.session.run(None, {"field_ut": windows})
    # a reading within the board's noise floor is no contact and holds no quantity, yet stays context
    touch = np.array([s.in_contact for s in states])
    assert 0.8 < touch.mean() < 1.0
    assert all(s.force_n is None and s.position_mm is None and s.plausible for s in np.array(states)[~touch])
    got = np.array([[s.x_mm, s.y_mm, s.force_n] for s in np.array(states)[touch]], dtype=float)
    np.testing.assert_allclose(got, mean[touch], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose([s.force_sigma_n for s in np.array(states)[touch]], sigma[touch, 2], rtol=1e-5)
    test = np.intersect1d(data.indices("test"), np.flatnonzero(touch))
    assert np.sqrt(np.mean((mean[test, 2] - data.target("force_n")[test]) ** 2)) < 2.0


def test_the_state_has_a_positive_sigma_for_each_trained_quantity_and_none_for_the_rest(contact_model_files,
                                                                                       labelled_presses) -> None:
    state = ContactEstimator(contact_model_files[2]).estimate(labelled_presses().readings[10])
    assert isinstance(state, ContactState)
    for value, sigma in ((state.x_mm, state.x_sigma_mm), (state.y_mm, state.y_sigma_mm),
                         (state.force_n, state.force_sigma_n)):
        assert np.isfinite(value) and sigma > 0
    assert state.depth_mm is None and state.depth_sigma_mm is None and state.shear_x_n is None
    assert state.position_mm == (state.x_mm, state.y_mm)
    assert set(state.sigmas) == {"x_mm", "y_mm", "force_n"}
    with pytest.raises(AttributeError):
        state.force_n = 1.0  # frozen


def test_in_contact_follows_the_field_for_a_model_without_that_target(contact_model_files) -> None:
    est = ContactEstimator(contact_model_files[2], min_field_ut=20.0)
    assert not est.estimate(np.zeros((3, 3, 3), np.float32)).in_contact
    pressed = np.zeros((3, 3, 3), np.float32)
    pressed[1, 1, 2] = 300.0
    assert est.estimate(pressed).in_contact


def test_context_is_dropped_after_a_gap_and_on_reset(contact_model_files, labelled_presses) -> None:
    est = ContactEstimator(contact_model_files[2])
    r = labelled_presses().readings
    assert est.estimate(r[0], t_s=0.0).context_frames == 1
    assert est.estimate(r[1], t_s=0.05).context_frames == 2
    assert est.estimate(r[2], t_s=0.10).context_frames == 3
    assert est.estimate(r[3], t_s=5.0).context_frames == 1  # 4.9 s after the last: no context
    est.reset()
    alone = est.estimate(r[3], t_s=5.05)
    assert alone.context_frames == 1


def test_the_buffer_builds_the_same_windows_as_the_dataset(labelled_presses) -> None:
    data = labelled_presses(50)
    t = data.extra("time_s").copy()
    t[30:] += 3.0  # a pause longer than max_gap_s
    buf = ContextBuffer(4, 1.0)
    windows = context_windows(data.readings, frames=4, max_gap_s=1.0, time_s=t)
    for i in range(len(data)):
        np.testing.assert_array_equal(buf.push(data.readings[i], t[i]), windows[i])
    np.testing.assert_array_equal(windows[31, 2], data.readings[31])


def test_context_never_crosses_runs(labelled_presses) -> None:
    data = labelled_presses(10)
    groups = np.array([0] * 5 + [1] * 5)
    w = context_windows(data.readings, frames=2, max_gap_s=10.0, time_s=np.arange(10.0), groups=groups)
    np.testing.assert_array_equal(w[5, 1], data.readings[5])
    np.testing.assert_array_equal(w[6, 1], data.readings[5])


def test_nan_and_wrong_shapes_are_refused_and_leave_the_history_alone(contact_model_files, labelled_presses) -> None:
    est = ContactEstimator(contact_model_files[2])
    r = labelled_presses().readings
    est.estimate(r[0], t_s=0.0)
    bad = r[1].copy()
    bad[1, 1, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        est.estimate(bad, t_s=0.05)
    with pytest.raises(ValueError, match=r"shape \(3, 3, 3\)"):
        est.estimate(np.zeros((4, 4, 3)), t_s=0.05)
    assert est.estimate(r[1], t_s=0.05).context_frames == 2


def test_after_gaps_resets_and_a_clock_going_back_the_stream_still_gives_the_graph_on_the_dataset_windows(
        contact_model_files, labelled_presses) -> None:
    est = ContactEstimator(contact_model_files[2], press_check=False)  # the model's outputs on every reading
    data = labelled_presses(120)
    rng = np.random.default_rng(0)
    steps = np.where(rng.random(120) < 0.15, rng.uniform(1.1, 5.0, 120), 0.05)  # some pauses past max_gap_s
    t = np.cumsum(steps)
    got = np.array([est.estimate(r, t_s=ti).values["force_n"] for r, ti in zip(data.readings, t)])
    windows = context_windows(data.readings, frames=3, max_gap_s=1.0, time_s=t)
    mean, _ = est.session.run(None, {"field_ut": windows})
    np.testing.assert_allclose(got, mean[:, 2], rtol=1e-5, atol=1e-5)
    est.estimate(data.readings[0], t_s=t[-1] + 0.05)
    back = est.estimate(data.readings[1], t_s=0.0)  # a clock that went back: a new stream, no context
    alone, _ = est.session.run(None, {"field_ut": np.repeat(data.readings[1][None, None], 3, axis=1)})
    assert back.context_frames == 1
    np.testing.assert_allclose(back.force_n, alone[0, 2], rtol=1e-5, atol=1e-5)


def test_the_buffer_rewrites_one_window_in_place() -> None:
    rng = np.random.default_rng(0)
    buf = ContextBuffer(3, 1.0, shape=(3, 3, 3))
    first = buf.window
    readings = rng.normal(0, 50, (6, 3, 3, 3)).astype(np.float32)
    for i, t in enumerate([0.0, 0.1, 0.2, 5.0, 5.1, 5.2]):
        assert buf.push(readings[i], t) is first
    np.testing.assert_array_equal(first, readings[[5, 4, 3]])
    buf.push(readings[0], 5.3)
    buf.clear()
    np.testing.assert_array_equal(buf.push(readings[1], 5.4), readings[[1, 1, 1]])


def test_a_state_is_the_one_its_dataclass_builds(contact_model_files, labelled_presses) -> None:
    import dataclasses
    import pickle

    models = [ContactEstimator(contact_model_files[2]),
              ContactEstimator(Path(__file__).resolve().parents[2] / "models" / "contact_supermag.onnx")]
    for est, reading in zip(models, [labelled_presses().readings[10], np.full((4, 4, 3), 40.0, np.float32)]):
        state = est.estimate(reading)
        built = ContactState(**{f.name: getattr(state, f.name) for f in dataclasses.fields(ContactState)})
        assert built == state and repr(built) == repr(state)
        assert pickle.loads(pickle.dumps(state)) == state
        assert dataclasses.replace(state, force_n=1.0).force_n == 1.0
        assert isinstance(state.in_contact, bool) and isinstance(state.context_frames, int)
        with pytest.raises(dataclasses.FrozenInstanceError):
            state.in_contact = not state.in_contact
    empty = models[1].estimate(np.zeros((4, 4, 3)))   # within the noise floor: the model does not run
    assert not empty.in_contact and empty.in_contact_probability is None and empty.force_n is None
    assert ContactEstimator(models[1].path, press_check=False).estimate(
        np.zeros((4, 4, 3))).in_contact_probability is not None


def test_readings_of_any_float_dtype_or_as_tactile_readings_give_the_same_state(contact_model_files,
                                                                                labelled_presses) -> None:
    r = labelled_presses().readings[20]
    states = []
    as_reading = TactileReading(r, r, np.zeros(r.shape, bool), t_host_s=3.0, seq=1)
    for reading in (r, r.astype(np.float64), r.tolist(), as_reading):
        est = ContactEstimator(contact_model_files[2])
        states.append(est.estimate(reading, t_s=3.0))
    for state in states[1:]:
        assert state.values == states[0].values and state.in_contact == states[0].in_contact


def test_a_graph_without_the_exported_inputs_and_outputs_is_refused(tmp_path, contact_model_files) -> None:
    onnx = pytest.importorskip("onnx", reason="renaming a graph output needs onnx")
    proto = onnx.load(str(contact_model_files[2]))
    old = proto.graph.output[1].name
    for node in proto.graph.node:
        node.output[:] = ["spread" if o == old else o for o in node.output]
    proto.graph.output[1].name = "spread"
    onnx.save(proto, str(tmp_path / "renamed.onnx"))
    with pytest.raises(ModelFileError, match="renamed.onnx.*'spread'"):
        ContactEstimator(tmp_path / "renamed.onnx")


def test_a_stored_image_share_outside_0_to_1_is_refused(tmp_path, contact_model_files) -> None:
    onnx = pytest.importorskip("onnx", reason="rewriting the metadata needs onnx")
    import json

    proto = onnx.load(str(contact_model_files[2]))
    entry = next(e for e in proto.metadata_props if e.key == "tactile_manip")
    entry.value = json.dumps(json.loads(entry.value) | {"image_position_weight": 1.5})
    onnx.save(proto, str(tmp_path / "share.onnx"))
    with pytest.raises(ModelFileError, match="share.onnx.*image_position_weight 1.5"):
        ContactEstimator(tmp_path / "share.onnx")


def test_missing_foreign_and_image_model_files_are_one_clear_error(tmp_path) -> None:
    with pytest.raises(ModelFileError, match="not found: .*nothere.onnx"):
        ContactEstimator(tmp_path / "nothere.onnx")
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a model")
    with pytest.raises(ModelFileError, match="junk.onnx"):
        ContactEstimator(junk)
    shipped = Path(__file__).resolve().parents[2] / "models" / "supermag.onnx"
    with pytest.raises(ModelFileError, match="not a contact model"):
        ContactEstimator(shipped)


class _Frames:
    """What ``stream`` uses of a sensor: ``layout`` and ``wait_new`` (each frame once, then a timeout)."""

    def __init__(self, fields: np.ndarray, layout: str = "anyskin-5") -> None:
        from tactile_manip.boards import load_board

        self.layout, self.fields, self.next = load_board(layout), fields, 0

    def wait_new(self, timeout_s: float) -> TactileReading:
        if self.next >= len(self.fields):
            raise SensorTimeoutError(f"no new frame within {timeout_s} s")
        f = self.fields[self.next]
        self.next += 1
        return TactileReading(f, f, np.zeros(f.shape, bool), t_host_s=0.05 * self.next, seq=self.next)


def test_stream_yields_one_state_per_frame_and_refuses_another_board(contact_model_files, labelled_presses) -> None:
    from tactile_manip.perception import StreamStats, TactileEstimator
    from tactile_manip.perception.baselines import BlindPoseEstimator

    est = TactileEstimator(BlindPoseEstimator(), ContactEstimator(contact_model_files[2]))  # the contact part alone
    stats = StreamStats()
    states = [e.contact for e in est.stream(_Frames(labelled_presses().readings[:5]), max_estimates=5, stats=stats)]
    assert len(states) == 5 and stats.estimates == 5 and stats.skipped_frames == 0
    assert [s.context_frames for s in states] == [1, 2, 3, 3, 3]
    with pytest.raises(ValueError, match="anyskin-5"):
        next(est.stream(_Frames(np.zeros((2, 4, 4, 3), np.float32), layout="supermag-4x4")))


def test_one_reading_gives_angle_and_contact_with_the_pose_estimator(tmp_path, contact_model_files) -> None:
    pytest.importorskip("torch", reason="training the 4 x 4 contact model needs torch")
    from tactile_manip.data import PairedDataset, save_dataset
    from tactile_manip.learning.contact.export import export_contact_onnx
    from tactile_manip.learning.contact.train import ContactTrainConfig, train_contact
    from tactile_manip.perception import TactilePoseEstimator, load_reconstructor
    from tactile_manip.perception.tactile_estimator import TactileEstimate, TactileEstimator, image_centroid_mm
    from tactile_manip.types import AngleEstimate

    rng = np.random.default_rng(0)
    readings = rng.normal(0, 50, (80, 4, 4, 3)).astype(np.float32)
    force = np.abs(readings[..., 2]).mean((1, 2)) / 10
    data = PairedDataset(readings=readings, images=None, split=np.array(["train"] * 64 + ["test"] * 16),
                         targets=force[:, None].astype(np.float32), target_names=("force_n",),
                         groups=np.zeros(80, np.int64), provenance={"layout": "supermag-4x4"})
    save_dataset(tmp_path / "board.npz", data)
    train_contact(ContactTrainConfig(hidden=8, members=1, epochs=3, threads=1), [tmp_path / "board.npz"],
                  tmp_path / "run")
    export_contact_onnx(tmp_path / "run" / "best.pt", tmp_path / "board.onnx")
    pose = TactilePoseEstimator(load_reconstructor("bilinear"))
    # readings of white noise, which the board's press check calls no press: the model runs without it
    both = TactileEstimator(pose, ContactEstimator(tmp_path / "board.onnx", press_check=False))
    assert both.image_position_weight == 0.0  # a model exported without a share: its own position
    export_contact_onnx(tmp_path / "run" / "best.pt", tmp_path / "shared.onnx", image_position_weight=0.25)
    assert TactileEstimator(pose, ContactEstimator(tmp_path / "shared.onnx")).image_position_weight == 0.25
    assert TactileEstimator(pose, ContactEstimator(tmp_path / "shared.onnx"),
                            image_position_weight=1.0).image_position_weight == 1.0
    with pytest.raises(ValueError, match="image_position_weight"):
        export_contact_onnx(tmp_path / "run" / "best.pt", tmp_path / "bad.onnx", image_position_weight=2.0)
    assert not (tmp_path / "bad.onnx").exists()
    est = both.estimate(readings[3])
    assert isinstance(est, TactileEstimate) and isinstance(est.angle, AngleEstimate)
    alone = ContactEstimator(tmp_path / "board.onnx", press_check=False).estimate(readings[3])
    assert not ContactEstimator(tmp_path / "board.onnx").estimate(readings[3]).plausible   # noise: no press
    assert est.contact.force_n == pytest.approx(alone.force_n, rel=1e-6) and est.contact.force_sigma_n > 0
    with pytest.raises(ValueError, match="one board"):
        TactileEstimator(pose, ContactEstimator(contact_model_files[2]))
    # a force-only model gives no position: where the contact is comes from the image alone
    assert est.position_mm == image_centroid_mm(est.angle, both.pose.min_contact_area_mm2)
    with pytest.raises(ValueError, match="image_position_weight"):
        TactileEstimator(pose, ContactEstimator(tmp_path / "board.onnx"), image_position_weight=1.5)


def test_a_model_with_a_sigma_map_reports_the_mapped_sigma(contact_model_of_layout) -> None:
    from tactile_manip.perception.confidence import SigmaCalibration

    plain = ContactEstimator(contact_model_of_layout("supermag-4x4"))
    halve = SigmaCalibration(knots=(0.01, 100.0), values=(0.005, 50.0))
    mapped = ContactEstimator(contact_model_of_layout("supermag-4x4",
                                                      sigma_calibration={"force_n": halve.to_dict()}))
    reading = np.zeros((4, 4, 3), np.float32)
    reading[1:3, 1:3, 2] = 150.0
    a, b = plain.estimate(reading), mapped.estimate(reading)
    assert b.force_n == a.force_n and b.force_sigma_n == pytest.approx(a.force_sigma_n / 2)
    assert b.x_sigma_mm == a.x_sigma_mm   # targets without a map keep the graph's sigma
    sigmas = np.array([[a.sigmas[n] for n in plain.target_names]])
    np.testing.assert_allclose(mapped.calibrated_sigma(sigmas)[0, 3], a.force_sigma_n / 2)
    with pytest.raises(ModelFileError, match="not its targets"):
        ContactEstimator(contact_model_of_layout("supermag-4x4", sigma_calibration={"shear_z_n": halve.to_dict()}))
    with pytest.raises(ModelFileError, match="sigma calibration"):
        ContactEstimator(contact_model_of_layout("supermag-4x4", sigma_calibration={"force_n": {"knots": [1.0]}}))
