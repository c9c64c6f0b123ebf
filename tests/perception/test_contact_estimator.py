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
    got = np.array([[s.x_mm, s.y_mm, s.force_n] for s in states])
    np.testing.assert_allclose(got, mean, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose([s.force_sigma_n for s in states], sigma[:, 2], rtol=1e-5)
    test = data.indices("test")
    assert np.sqrt(np.mean((got[test, 2] - data.target("force_n")[test]) ** 2)) < 2.0


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
        from tactile_manip.sensors.layout import get_layout

        self.layout, self.fields, self.next = get_layout(layout), fields, 0

    def wait_new(self, timeout_s: float) -> TactileReading:
        if self.next >= len(self.fields):
            raise SensorTimeoutError(f"no new frame within {timeout_s} s")
        f = self.fields[self.next]
        self.next += 1
        return TactileReading(f, f, np.zeros(f.shape, bool), t_host_s=0.05 * self.next, seq=self.next)


def test_stream_yields_one_state_per_frame_and_refuses_another_board(contact_model_files, labelled_presses) -> None:
    from tactile_manip.perception import StreamStats

    est = ContactEstimator(contact_model_files[2])
    stats = StreamStats()
    states = list(est.stream(_Frames(labelled_presses().readings[:5]), max_estimates=5, stats=stats))
    assert len(states) == 5 and stats.estimates == 5 and stats.skipped_frames == 0
    assert [s.context_frames for s in states] == [1, 2, 3, 3, 3]
    with pytest.raises(ValueError, match="anyskin-5"):
        next(est.stream(_Frames(np.zeros((2, 4, 4, 3), np.float32), layout="supermag-4x4")))


def test_one_reading_gives_angle_and_contact_with_the_pose_estimator(tmp_path, contact_model_files) -> None:
    pytest.importorskip("torch", reason="training the 4 x 4 contact model needs torch")
    from tactile_manip.data import PairedDataset, save_dataset
    from tactile_manip.learning.contact_export import export_contact_onnx
    from tactile_manip.learning.contact_train import ContactTrainConfig, train_contact
    from tactile_manip.perception import TactilePoseEstimator, load_reconstructor
    from tactile_manip.perception.contact_pose import TactileEstimate, TactileEstimator
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
    both = TactileEstimator(pose, ContactEstimator(tmp_path / "board.onnx"))
    est = both.estimate(readings[3])
    assert isinstance(est, TactileEstimate) and isinstance(est.angle, AngleEstimate)
    alone = ContactEstimator(tmp_path / "board.onnx").estimate(readings[3])
    assert est.contact.force_n == pytest.approx(alone.force_n, rel=1e-6) and est.contact.force_sigma_n > 0
    with pytest.raises(ValueError, match="one board"):
        TactileEstimator(pose, ContactEstimator(contact_model_files[2]))
