"""The sensor's symmetries: exact on the simulator, the same as the training augmentation, and a reconstructor
averaged over them that is exactly equivariant."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from checks import TORCH_MISSING

from tactile_manip.perception import TactilePoseEstimator, load_reconstructor, wrap_axial
from tactile_manip.perception.symmetry import (SymmetrizedReconstructor, inverse_transform_image, symmetry_group,
                                               transform_image, transform_reading)
from tactile_manip.sim.objects import IndenterPose
from tactile_manip.sim.pair import SensorPair
from tactile_manip.sim.shapes import make_indenter

MODEL = Path(__file__).resolve().parents[2] / "models" / "supermag.onnx"
GROUP = symmetry_group((4, 4, 3), (200, 200))


def _turned(pose: IndenterPose, k: int, mirror: bool) -> IndenterPose:
    """The pose after mirror (x -> -x) and k counter-clockwise quarter turns about the pad centre."""
    x, y, yaw = pose.x_mm, pose.y_mm, pose.yaw_rad
    if mirror:
        x, yaw = -x, math.pi - yaw
    for _ in range(k):
        x, y, yaw = -y, x, yaw + math.pi / 2
    return IndenterPose(x, y, yaw)


@pytest.mark.parametrize("k, mirror", [(1, False), (2, False), (0, True), (3, True)])
def test_a_transformed_contact_gives_the_transformed_reading_and_image(k, mirror) -> None:
    pair, rod = SensorPair(seed=0), make_indenter("square_bar", size_mm=2.5)
    pose = IndenterPose(1.2, -0.7, 0.4)
    a = pair.press(rod, pose, 10.0, np.random.default_rng(0))
    b = pair.press(rod, _turned(pose, k, mirror), 10.0, np.random.default_rng(0))
    peak = np.abs(a.field_change_ut).max()
    assert np.abs(transform_reading(a.field_change_ut, k, mirror) - b.field_change_ut).max() < 0.02 * peak
    overlap = np.logical_and(transform_image(a.contact_mask, k, mirror), b.contact_mask).sum()
    assert overlap > 0.95 * b.contact_mask.sum()


def test_the_group_and_the_inverse() -> None:
    assert len(GROUP) == 8 and len(symmetry_group((4, 5, 3), (40, 50))) == 4
    img = np.random.default_rng(0).random((3, 7, 7))
    for k, m in GROUP:
        assert np.array_equal(inverse_transform_image(transform_image(img, k, m), k, m), img)
    turned = transform_reading(np.ones((4, 4, 3)) * [1.0, 0.0, 0.0], 1, False)
    assert np.allclose(turned[..., :2], [0.0, 1.0])            # +x field turned a quarter CCW points to +y


def test_the_same_transforms_as_the_training_augmentation() -> None:
    torch = pytest.importorskip("torch", reason=TORCH_MISSING)
    from tactile_manip.learning.cvae.data import dihedral

    rng = np.random.default_rng(1)
    field, image = rng.normal(size=(2, 4, 4, 3)), rng.random((2, 12, 12))
    for k, m in GROUP:
        f, im = dihedral(torch.from_numpy(field), torch.from_numpy(image), k, m)
        assert np.allclose(f.numpy(), transform_reading(field, k, m))
        assert np.allclose(im.numpy(), transform_image(image, k, m))


def test_the_averaged_reconstructor_is_exactly_equivariant() -> None:
    pytest.importorskip("onnxruntime")
    sym = SymmetrizedReconstructor(load_reconstructor(MODEL), spread=True)
    pair = SensorPair(seed=0)
    field = pair.press(make_indenter("hex_bar", size_mm=4.0), IndenterPose(0.5, 1.0, 0.3), 10.0,
                       np.random.default_rng(2), render_depth=False).field_ut
    base = sym.reconstruct(field)
    assert sym.name.endswith("+sym") and base.spread_mm is not None and np.isfinite(base.spread_mm).all()
    for k, m in GROUP[1:]:
        turned = sym.reconstruct(transform_reading(field, k, m)).depth_mm
        assert np.abs(turned - transform_image(base.depth_mm, k, m)).max() < 1e-4
    batch = sym.reconstruct_batch(np.stack([field, field]))
    assert batch.shape == (2, 200, 200) and np.allclose(batch[0], base.depth_mm, atol=1e-6)


def test_averaging_over_the_symmetries_sharpens_the_rod_angle() -> None:
    pytest.importorskip("onnxruntime")
    pair, rng = SensorPair(seed=0), np.random.default_rng(3)
    # the image's angle alone: the model's angle head reads the reading, not the averaged image
    single = TactilePoseEstimator(load_reconstructor(MODEL), angle_source="image")
    averaged = TactilePoseEstimator(SymmetrizedReconstructor(load_reconstructor(MODEL)), angle_source="image")
    errors = {"single": [], "averaged": []}
    for i in range(24):
        size = (8.0, 5.0)[i % 2]
        rod = make_indenter(("hex_bar", "square_bar")[i % 2], size_mm=size)   # the wide bars, the hard cases
        yaw = rng.uniform(-math.pi / 2, math.pi / 2)
        field = pair.press(rod, IndenterPose(*rng.uniform(-2, 2, 2), yaw), 10.5, rng, render_depth=False).field_ut
        for name, est in (("single", single), ("averaged", averaged)):
            errors[name].append(abs(wrap_axial(est.estimate(field).angle_rad - yaw)))
    assert np.mean(errors["averaged"]) < np.mean(errors["single"])
    assert np.percentile(errors["averaged"], 90) <= np.percentile(errors["single"], 90)
    assert np.percentile(np.degrees(errors["averaged"]), 90) < 5.0


def test_large_batches_are_processed_in_chunks_with_the_same_result(monkeypatch) -> None:
    from tactile_manip.perception import symmetry
    from tactile_manip.perception.reconstruct import BilinearReconstructor

    sym = SymmetrizedReconstructor(BilinearReconstructor(gain_mm_per_ut=-0.01, offset_mm=0.0), spread=True)
    fields = np.random.default_rng(4).normal(0, 100, (5, 4, 4, 3))
    whole = sym.reconstruct_batch(fields)
    monkeypatch.setattr(symmetry, "CHUNK", 2)
    assert np.allclose(sym.reconstruct_batch(fields), whole)


# ---------------------------------------------------------------- a model's own image symmetry


def _press(seed: int = 2) -> np.ndarray:
    return SensorPair(seed=0).press(make_indenter("hex_bar", size_mm=4.0), IndenterPose(0.5, 1.0, 0.3), 10.0,
                                    np.random.default_rng(seed), render_depth=False).field_ut


def test_the_default_models_file_averages_its_images_over_the_turns_exactly() -> None:
    pytest.importorskip("onnxruntime")
    from tactile_manip.perception.reconstruct import OnnxReconstructor

    turns, once = OnnxReconstructor(MODEL, image_symmetry="stored"), OnnxReconstructor(MODEL)
    assert (turns.image_symmetry, once.image_symmetry) == ("rotations", "none")  # the file says rotations
    field = _press()
    base = turns.reconstruct(field).depth_mm
    by_hand = np.mean([inverse_transform_image(once.reconstruct(transform_reading(field, k, False)).depth_mm, k, False)
                       for k in range(4)], axis=0)
    assert np.abs(base - by_hand).max() < 1e-5 and np.abs(base - once.reconstruct(field).depth_mm).max() > 1e-3
    for k in (1, 2, 3):  # equivariant under the turns, not under a mirror
        turned = turns.reconstruct(transform_reading(field, k, False)).depth_mm
        assert np.abs(turned - transform_image(base, k, False)).max() < 1e-4
    mirrored = turns.reconstruct(transform_reading(field, 0, True)).depth_mm
    assert np.abs(mirrored - transform_image(base, 0, True)).max() > 1e-3
    batch = turns.reconstruct_batch(np.stack([field, _press(3), field]))
    assert np.abs(batch[0] - base).max() < 1e-5 and np.array_equal(batch[0], batch[2])


def test_averaging_a_turn_averaged_model_over_the_group_takes_one_copy_per_mirror() -> None:
    pytest.importorskip("onnxruntime")
    from tactile_manip.perception.reconstruct import OnnxReconstructor

    turns = SymmetrizedReconstructor(OnnxReconstructor(MODEL, image_symmetry="stored"))
    full = SymmetrizedReconstructor(OnnxReconstructor(MODEL, image_symmetry="none"))
    assert turns.group == [(0, False), (0, True)] and len(full.group) == 8
    every = OnnxReconstructor(MODEL, image_symmetry="all")
    assert SymmetrizedReconstructor(every).group == [(0, False)]
    field = _press()
    want = full.reconstruct(field).depth_mm
    for got in (turns.reconstruct(field).depth_mm, every.reconstruct(field).depth_mm):
        assert np.abs(got - want).max() < 1e-5  # the same group average, 8 decoder passes each


def test_a_rectangular_board_turns_by_half_turns(onnx_5x6) -> None:
    from tactile_manip.perception.reconstruct import OnnxReconstructor

    rect = OnnxReconstructor(onnx_5x6.path, image_symmetry="rotations")
    field = np.random.default_rng(0).normal(0, 50, (5, 6, 3))
    base = rect.reconstruct(field).depth_mm
    assert np.abs(rect.reconstruct(transform_reading(field, 2, False)).depth_mm
                  - transform_image(base, 2, False)).max() < 1e-4
    assert OnnxReconstructor(onnx_5x6.path, image_symmetry="stored").image_symmetry == "none"  # the file says none


def test_an_unknown_image_symmetry_is_refused(onnx_4x4, tmp_path) -> None:
    import json

    import onnx

    from tactile_manip.perception.model_metadata import ModelFileError
    from tactile_manip.perception.reconstruct import METADATA_KEY, OnnxReconstructor

    with pytest.raises(ValueError, match="image_symmetry must be one of none, rotations, all, got 'mirrors'"):
        OnnxReconstructor(onnx_4x4.path, image_symmetry="mirrors")
    proto = onnx.load(str(onnx_4x4.path))
    for p in proto.metadata_props:
        if p.key == METADATA_KEY:
            p.value = json.dumps({**json.loads(p.value), "image_symmetry": "twice"})
    onnx.save(proto, str(tmp_path / "edited.onnx"))
    with pytest.raises(ModelFileError, match="metadata field image_symmetry is 'twice', not one of none, rotations"):
        OnnxReconstructor(tmp_path / "edited.onnx")


def test_a_large_batch_of_turned_copies_runs_in_chunks_with_the_same_images(onnx_4x4) -> None:
    from tactile_manip.perception.reconstruct import SYMMETRY_CHUNK, OnnxReconstructor

    turns = OnnxReconstructor(onnx_4x4.path, image_symmetry="rotations")
    fields = np.random.default_rng(1).normal(0, 80, (SYMMETRY_CHUNK + 6, 4, 4, 3))
    batch = turns.reconstruct_batch(fields)
    assert batch.shape == (len(fields), *turns.output_shape)
    for i in (0, SYMMETRY_CHUNK - 1, SYMMETRY_CHUNK, len(fields) - 1):
        assert np.abs(batch[i] - turns.reconstruct(fields[i]).depth_mm).max() < 1e-5
