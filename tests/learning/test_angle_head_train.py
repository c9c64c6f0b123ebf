"""The angle head: labels, training, attaching it to a pose model, and the commands that drive them."""

from __future__ import annotations

import math

import numpy as np
import pytest
from checks import REFERENCE_MODELS_DIR, TORCH_MISSING, assert_one_line_error

torch = pytest.importorskip("torch", reason=TORCH_MISSING)
pytest.importorskip("onnx", reason="attaching a head needs onnx")
pytest.importorskip("onnxruntime", reason="running a head needs onnxruntime")

from tactile_manip.cli import main  # noqa: E402
from tactile_manip.data import PairedDataset, depth_image_spec, quantise_depth, save_dataset  # noqa: E402
from tactile_manip.errors import DatasetError  # noqa: E402
from tactile_manip.learning.angle_head.export import attach_angle_head, load_angle_checkpoint  # noqa: E402
from tactile_manip.learning.angle_head.train import (AngleTrainConfig, axis_labels, is_axial, symmetric,  # noqa: E402
                                                     train_angle_head)
from tactile_manip.learning.cvae.export import ExportError  # noqa: E402
from tactile_manip.perception import load_reconstructor, wrap_axial  # noqa: E402
from tactile_manip.perception.reconstruct import read_metadata  # noqa: E402
from tactile_manip.perception.symmetry import transform_reading  # noqa: E402

BASE = REFERENCE_MODELS_DIR / "supermag_robust.onnx"


def _bar_readings(angle_rad: np.ndarray, rng: np.random.Generator, noise_ut: float | np.ndarray = 1.0
                  ) -> np.ndarray:
    """Readings whose pattern turns with the axis, as a bar's does (the sensor's symmetries map them onto each
    other with the axis moved accordingly), plus Gaussian noise of ``noise_ut`` (per reading)."""
    rows, cols = np.mgrid[0:4, 0:4]
    ys, xs = 1.5 - rows, cols - 1.5        # pad frame: row 0 at +y, column 0 at -x
    out = np.empty((len(angle_rad), 4, 4, 3), np.float32)
    for k, a in enumerate(angle_rad):
        across = -xs * math.sin(a) + ys * math.cos(a)   # distance across the bar, in pitches
        bump = np.exp(-across**2)
        out[k, ..., 0] = -60 * bump * math.sin(a) * across   # in-plane field across the bar, away from its axis
        out[k, ..., 1] = 60 * bump * math.cos(a) * across
        out[k, ..., 2] = 120 * bump
    noise = np.broadcast_to(np.asarray(noise_ut, np.float32), (len(out),))[:, None, None, None]
    return out + (noise * rng.normal(0, 1.0, out.shape)).astype(np.float32)


def bar_dataset(n: int = 600, *, seed: int = 0, images: bool = False) -> PairedDataset:
    """Bars at random axes; a quarter of the readings drown in noise, so the head must learn where it is sure."""
    rng = np.random.default_rng(seed)
    yaw = rng.uniform(-math.pi / 2, math.pi / 2, n)
    noise = np.where(rng.random(n) < 0.25, 80.0, 1.0)
    pose = np.zeros((n, 5), np.float32)
    pose[:, 2] = yaw
    split = np.where(np.arange(n) < 0.8 * n, "train", "val")
    kwargs = {"images": None, "targets": np.ones((n, 1), np.float32), "target_names": ("in_contact",)}
    if images:  # a second object that is no bar: round blobs, whose image axis is undefined
        kwargs = {"images": np.stack([quantise_depth(np.zeros((20, 20)))] * n), "image": depth_image_spec(0.5)}
    return PairedDataset(readings=_bar_readings(yaw, rng, noise), split=split, object_index=np.zeros(n, np.int16),
                         object_names=np.array(["procedural_bar"]), extras={"pose": pose}, **kwargs)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    root = tmp_path_factory.mktemp("angle_head")
    data = save_dataset(root / "bars.npz", bar_dataset())
    cfg = AngleTrainConfig(hidden=64, layers=2, epochs=40, batch_size=64, lr=5e-3, patience=40, threads=1)
    summary = train_angle_head(cfg, [data], root / "run")
    return data, root / "run", summary


def test_the_trained_head_finds_the_axis_far_better_than_chance(trained) -> None:
    _, _, summary = trained
    assert summary["val"]["val_within_5"] > 0.5      # chance: 10 / 180; a quarter is noise
    assert summary["val"]["val_median_deg"] < 5.0
    assert summary["best_epoch"] >= 1 and summary["train_presses"] == 480


def test_the_concentration_says_how_sure_the_head_is(trained) -> None:
    _, run, _ = trained
    model, _ = load_angle_checkpoint(run / "best.pt")
    rng = np.random.default_rng(5)
    yaw = rng.uniform(-1.5, 1.5, 200)
    with torch.no_grad():
        sure = model(torch.from_numpy(_bar_readings(yaw, rng)))
        noisy = model(torch.from_numpy(_bar_readings(yaw, rng, 80.0)))
    assert sure.norm(dim=1).median() > 5 * noisy.norm(dim=1).median()
    err = np.degrees(np.abs(wrap_axial(0.5 * np.arctan2(sure[:, 1].numpy(), sure[:, 0].numpy()) - yaw)))
    assert np.median(err) < 5.0


def test_symmetries_move_the_axis_with_the_reading() -> None:
    rng = np.random.default_rng(1)
    yaw = rng.uniform(-1.5, 1.5, 64)
    readings = _bar_readings(yaw, np.random.default_rng(2))
    moved, moved_yaw = symmetric(readings, yaw, rng)
    fresh = _bar_readings(moved_yaw, np.random.default_rng(2))
    assert np.abs(moved - fresh).max() < 8.0   # the same bar at the moved angle, up to the noise draws
    one = transform_reading(readings[:1], 1, False)
    np.testing.assert_allclose(one, _bar_readings(yaw[:1] + math.pi / 2, np.random.default_rng(2))[:1], atol=8.0)


def test_labels_come_from_the_axis_of_bars_and_the_image_of_the_rest() -> None:
    assert is_axial("procedural_bar") and is_axial("cylinder_6mm") and is_axial("flat_bar_10x2mm")
    assert is_axial("ridge_70deg") and is_axial("procedural_prism_3")
    assert not is_axial("letter_r") and not is_axial("procedural")
    data = bar_dataset(20, images=True)
    idx, angle, axial = axis_labels(data, np.arange(20))
    assert axial.all() and np.allclose(angle, wrap_axial(data.extra("pose")[:, 2]))
    blobs = PairedDataset(readings=data.readings, split=data.split, object_index=data.object_index,
                          object_names=np.array(["letter_r"]), extras={"pose": data.extra("pose")},
                          images=data.images, image=data.image)
    idx, _, _ = axis_labels(blobs, np.arange(20))
    assert idx.size == 0   # flat images have no axis: left out, not labelled 0
    with pytest.raises(DatasetError, match="pose"):
        axis_labels(PairedDataset(readings=data.readings, split=data.split, images=data.images, image=data.image),
                    np.arange(20))


def test_attaching_keeps_the_image_model_and_adds_a_head_that_matches_torch(trained, tmp_path) -> None:
    data, run, _ = trained
    out = tmp_path / "with_head.onnx"
    record = attach_angle_head(run / "best.pt", BASE, out, check_readings=bar_dataset(8).readings, symmetries=False)
    assert record["parity_max_abs"] < 1e-3 and record["validation"]["val_within_5"] > 0.5
    assert record["symmetries"] == 1
    with_head, plain = load_reconstructor(out), load_reconstructor(BASE)
    assert plain.angle_head is None and with_head.angle_head is not None
    reading = bar_dataset(1, seed=3).readings[0]
    np.testing.assert_array_equal(with_head.reconstruct(reading).depth_mm, plain.reconstruct(reading).depth_mm)
    model, _ = load_angle_checkpoint(run / "best.pt")
    with torch.no_grad():
        ref = model(torch.from_numpy(reading[None])).numpy()[0]
    angle, kappa = with_head.angle_head.axis(reading)
    assert angle == pytest.approx(0.5 * math.atan2(ref[1], ref[0]), abs=1e-4)
    assert kappa == pytest.approx(math.hypot(*ref), rel=1e-4)
    assert load_reconstructor(out, angle_head=False).angle_head is None


def test_the_default_head_reads_the_8_symmetric_copies_and_turns_exactly_with_the_reading(trained, tmp_path) -> None:
    _, run, _ = trained
    out = tmp_path / "symmetric.onnx"
    record = attach_angle_head(run / "best.pt", BASE, out)
    assert record["symmetries"] == 8 and record["parity_max_abs"] < 1e-3
    head = load_reconstructor(out).angle_head
    model, _ = load_angle_checkpoint(run / "best.pt")
    readings = bar_dataset(6, seed=5).readings
    # the mean of the head's axes over the copies, each turned back, by hand
    total = np.zeros((len(readings), 2))
    for mirror in (False, True):
        for turns in range(4):
            copy = transform_reading(readings, turns, mirror).astype(np.float32)
            with torch.no_grad():
                v = model(torch.from_numpy(copy)).numpy()
            a = 0.5 * np.arctan2(v[:, 1], v[:, 0]) - turns * math.pi / 2
            a = -a if mirror else a
            total += np.hypot(v[:, 0], v[:, 1])[:, None] * np.c_[np.cos(2 * a), np.sin(2 * a)]
    angle, kappa = head.axes(readings)
    np.testing.assert_allclose(kappa, np.hypot(*(total / 8).T), rtol=1e-4)
    np.testing.assert_allclose(wrap_axial(angle - 0.5 * np.arctan2(total[:, 1], total[:, 0])), 0.0, atol=1e-4)
    # a turned and mirrored reading gives the turned and mirrored axis, to rounding, and the same kappa
    turned_angle, turned_kappa = head.axes(transform_reading(readings, 1, True).astype(np.float32))
    np.testing.assert_allclose(wrap_axial(turned_angle - (-angle + math.pi / 2)), 0.0, atol=1e-4)
    np.testing.assert_allclose(turned_kappa, kappa, rtol=1e-4)


def test_a_head_for_another_board_is_refused(trained, tmp_path) -> None:
    _, run, _ = trained
    model, payload = load_angle_checkpoint(run / "best.pt")
    payload["model_config"]["cells"] = [5, 6, 3]
    other = tmp_path / "other.pt"
    torch.save(payload, other)
    with pytest.raises(Exception, match="checkpoint does not fit|shape"):
        attach_angle_head(other, BASE, tmp_path / "x.onnx")
    assert not (tmp_path / "x.onnx").exists()


def test_a_corrupted_head_in_a_model_file_is_named_at_load(trained, tmp_path) -> None:
    import onnx

    from tactile_manip.perception.angle_head import ANGLE_HEAD_KEY
    from tactile_manip.perception.reconstruct import ModelFileError

    _, run, _ = trained
    out = tmp_path / "head.onnx"
    attach_angle_head(run / "best.pt", BASE, out)
    proto = onnx.load(str(out))
    for p in proto.metadata_props:
        if p.key == ANGLE_HEAD_KEY:
            p.value = "not base64 !"
    onnx.save(proto, str(out))
    with pytest.raises(ModelFileError, match="angle head"):
        load_reconstructor(out)


def test_the_commands_train_and_attach_and_refuse_what_does_not_fit(trained, tmp_path, capsys) -> None:
    data, run, _ = trained
    cfg = tmp_path / "head.toml"
    cfg.write_text('kind = "angle_head"\nhidden = 32\nlayers = 1\nepochs = 2\nbatch_size = 64\nthreads = 1\n')
    assert main(["train", "--config", str(cfg), "--data", str(data), "--out", str(tmp_path / "r")]) == 0
    assert "within 5 deg" in capsys.readouterr().out
    assert main(["train", "--config", str(cfg), "--data", str(data), "--out", str(tmp_path / "r2"),
                 "--resume"]) == 2
    assert_one_line_error(capsys.readouterr().err, "train", "--resume", "angle head")
    out = tmp_path / "m.onnx"
    assert main(["export", "--checkpoint", str(run / "best.pt"), "--out", str(out)]) == 2
    assert_one_line_error(capsys.readouterr().err, "export", "--attach-to")
    assert not out.exists()
    assert main(["export", "--checkpoint", str(run / "best.pt"), "--attach-to", str(BASE), "--out", str(out),
                 "--data", str(data)]) == 0
    assert "its 8 symmetric copies" in capsys.readouterr().out and out.exists()
    once = tmp_path / "once.onnx"
    assert main(["export", "--checkpoint", str(run / "best.pt"), "--attach-to", str(BASE), "--out", str(once),
                 "--head-symmetries", "1"]) == 0
    assert "no symmetric copies" in capsys.readouterr().out
    assert read_metadata(once).get("image_symmetry", "none") == read_metadata(BASE).get("image_symmetry", "none")
    turned = tmp_path / "turned.onnx"
    assert main(["export", "--checkpoint", str(run / "best.pt"), "--attach-to", str(BASE), "--out", str(turned),
                 "--image-symmetry", "rotations"]) == 0
    assert read_metadata(turned)["image_symmetry"] == "rotations"  # the pose model's images, averaged over turns
    assert load_reconstructor(turned, image_symmetry="stored").image_symmetry == "rotations"
    assert main(["export", "--checkpoint", str(run / "best.pt"), "--attach-to", str(tmp_path / "missing.onnx"),
                 "--out", str(tmp_path / "n.onnx")]) == 2
    assert_one_line_error(capsys.readouterr().err, "export", "missing.onnx")
    assert not (tmp_path / "n.onnx").exists()


def test_too_few_presses_is_one_clear_error(tmp_path) -> None:
    data = save_dataset(tmp_path / "few.npz", bar_dataset(10))
    with pytest.raises(DatasetError, match="too few"):
        train_angle_head(AngleTrainConfig(batch_size=64, threads=1), [data], tmp_path / "run")
    with pytest.raises(ValueError, match="epochs"):
        AngleTrainConfig(epochs=0)
    assert ExportError  # imported for the refusals above
