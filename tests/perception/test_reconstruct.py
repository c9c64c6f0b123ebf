"""Reconstructors: the exported-model runtime (shapes, errors, clamping, metadata) and the interpolation baselines."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from checks import assert_one_line_message

from tactile_manip.perception.reconstruct import (BASELINES, BicubicReconstructor, BilinearReconstructor,
                                                  InterpolationReconstructor, ModelFileError, OnnxReconstructor,
                                                  Reconstruction, default_baseline_fit, load_reconstructor,
                                                  read_metadata)

def _readings(rng: np.random.Generator, n: int, shape: tuple[int, int, int], scale_ut: float = 150.0) -> np.ndarray:
    return rng.normal(0.0, scale_ut, (n, *shape)).astype(np.float32)


def _foreign_onnx(path: Path, *, metadata: dict[str, str] | None = None) -> Path:
    """A valid one-node Identity model, optionally with metadata props."""
    onnx = pytest.importorskip("onnx")
    from onnx import TensorProto, helper

    x = helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 4])
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 4])
    graph = helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "identity", [x], [y])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    for key, value in (metadata or {}).items():
        entry = model.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


# ================================================================ OnnxReconstructor


def test_output_shapes_for_one_reading_and_a_batch(onnx_4x4, onnx_5x6) -> None:
    rng = np.random.default_rng(0)
    for model in (onnx_4x4, onnx_5x6):
        rec = OnnxReconstructor(model.path)
        assert rec.input_shape == model.taxels
        assert rec.output_shape == model.image_hw
        assert rec.pixel_mm == model.pixel_mm
        one = rec.reconstruct(_readings(rng, 1, model.taxels)[0])
        assert isinstance(one, Reconstruction)
        assert one.depth_mm.shape == model.image_hw and one.depth_mm.dtype == np.float32
        assert one.spread_mm is None and one.latency_s > 0
        batch = rec.reconstruct_batch(_readings(rng, 5, model.taxels))
        assert batch.shape == (5, *model.image_hw) and batch.dtype == np.float32


def test_batch_equals_one_by_one(onnx_4x4) -> None:
    rec = OnnxReconstructor(onnx_4x4.path)
    fields = _readings(np.random.default_rng(1), 4, onnx_4x4.taxels)
    batch = rec.reconstruct_batch(fields)
    for f, depth in zip(fields, batch):
        np.testing.assert_allclose(rec.reconstruct(f).depth_mm, depth, atol=1e-5)
    # the model fixture is not degenerate: different readings give different images
    assert np.abs(batch[0] - batch[1]).max() > 1e-3


def test_prior_samples_give_a_spread(onnx_4x4) -> None:
    field = _readings(np.random.default_rng(2), 1, onnx_4x4.taxels)[0]
    sampled = OnnxReconstructor(onnx_4x4.path, samples=4, seed=3).reconstruct(field)
    assert sampled.spread_mm is not None
    assert sampled.spread_mm.shape == onnx_4x4.image_hw
    assert np.all(sampled.spread_mm >= 0) and sampled.spread_mm.max() > 0
    assert np.all(sampled.depth_mm >= 0)
    again = OnnxReconstructor(onnx_4x4.path, samples=4, seed=3).reconstruct(field)
    np.testing.assert_array_equal(again.depth_mm, sampled.depth_mm)  # seeded
    assert OnnxReconstructor(onnx_4x4.path, samples=1).reconstruct(field).spread_mm is None
    with pytest.raises(ValueError, match="samples must be >= 1"):
        OnnxReconstructor(onnx_4x4.path, samples=0)


def test_missing_file_is_a_clear_error(tmp_path: Path) -> None:
    pytest.importorskip("onnxruntime", reason="the onnx extra is not installed")
    missing = tmp_path / "nope.onnx"
    with pytest.raises(ModelFileError, match="model file not found") as info:
        OnnxReconstructor(missing)
    assert str(missing) in str(info.value)
    with pytest.raises(ModelFileError, match="model file not found"):
        load_reconstructor(missing)


def test_corrupt_file_is_a_clear_error(tmp_path: Path) -> None:
    pytest.importorskip("onnxruntime", reason="the onnx extra is not installed")
    corrupt = tmp_path / "corrupt.onnx"
    corrupt.write_bytes(np.random.default_rng(0).bytes(4096))
    with pytest.raises(ModelFileError, match="not a readable ONNX file"):
        OnnxReconstructor(corrupt)
    assert issubclass(ModelFileError, ValueError)


def test_empty_file_is_rejected(tmp_path: Path) -> None:
    pytest.importorskip("onnxruntime", reason="the onnx extra is not installed")
    empty = tmp_path / "empty.onnx"
    empty.write_bytes(b"")
    with pytest.raises(ModelFileError):
        OnnxReconstructor(empty)


def test_empty_file_error_names_the_cause(tmp_path: Path) -> None:
    empty = tmp_path / "model.onnx"
    empty.write_bytes(b"")
    with pytest.raises(ModelFileError) as info:
        read_metadata(empty)
    cause = str(info.value).replace(str(empty), "")  # tmp_path itself may contain the word "empty"
    assert "empty" in cause or "not a readable ONNX file" in cause


def test_truncated_export_is_a_clear_error(onnx_4x4, tmp_path: Path) -> None:
    data = onnx_4x4.path.read_bytes()
    truncated = tmp_path / "truncated.onnx"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(ModelFileError, match=str(truncated.name)):
        OnnxReconstructor(truncated)


def test_foreign_onnx_without_our_metadata_is_rejected(tmp_path: Path) -> None:
    foreign = _foreign_onnx(tmp_path / "identity.onnx")
    with pytest.raises(ModelFileError, match="without tactile_manip metadata"):
        OnnxReconstructor(foreign)
    with pytest.raises(ModelFileError, match="without tactile_manip metadata"):
        read_metadata(foreign)


def test_metadata_of_another_format_version_or_not_json_is_rejected(tmp_path: Path) -> None:
    newer = _foreign_onnx(tmp_path / "newer.onnx", metadata={"tactile_manip": json.dumps({"format_version": 2})})
    with pytest.raises(ModelFileError, match="model format 2"):
        read_metadata(newer)
    garbled = _foreign_onnx(tmp_path / "garbled.onnx", metadata={"tactile_manip": "{not json"})
    with pytest.raises(ModelFileError, match="not valid JSON"):
        read_metadata(garbled)


def test_reading_shape_must_match_the_model(onnx_4x4, onnx_5x6) -> None:
    rec_4x4, rec_5x6 = OnnxReconstructor(onnx_4x4.path), OnnxReconstructor(onnx_5x6.path)
    with pytest.raises(ValueError, match=r"expected readings of shape \(5, 6, 3\), got \(4, 4, 3\)"):
        rec_5x6.reconstruct(np.zeros((4, 4, 3), np.float32))
    with pytest.raises(ValueError, match=r"expected readings of shape \(4, 4, 3\), got \(5, 6, 3\)"):
        rec_4x4.reconstruct(np.zeros((5, 6, 3), np.float32))
    with pytest.raises(ValueError, match=r"\(N, 4, 4, 3\)"):
        rec_4x4.reconstruct_batch(np.zeros((2, 5, 6, 3), np.float32))
    with pytest.raises(ValueError, match=r"\(N, 4, 4, 3\)"):
        rec_4x4.reconstruct_batch(np.zeros((4, 4, 3), np.float32))  # one reading where a batch is expected
    with pytest.raises(ValueError, match=r"got \(48,\)"):
        rec_4x4.reconstruct(np.zeros(48, np.float32))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_readings_are_rejected(onnx_4x4, bad: float) -> None:
    rec = OnnxReconstructor(onnx_4x4.path)
    field = np.zeros(onnx_4x4.taxels, np.float32)
    field[1, 2, 0] = bad
    with pytest.raises(ValueError, match=r"NaN or infinite values \(first at index \[1, 2, 0\]\)"):
        rec.reconstruct(field)
    with pytest.raises(ValueError, match="NaN or infinite"):
        rec.reconstruct_batch(np.stack([np.zeros_like(field), field]))


def test_saturated_readings_are_clamped_as_in_training(onnx_4x4) -> None:
    assert onnx_4x4.clamp_ut == 500.0
    rec = OnnxReconstructor(onnx_4x4.path)
    rng = np.random.default_rng(4)
    base = rng.normal(0, 100, onnx_4x4.taxels).astype(np.float32)
    sign = np.where(rng.random(onnx_4x4.taxels) < 0.5, -1.0, 1.0).astype(np.float32)
    mask = rng.random(onnx_4x4.taxels) < 0.3
    at_clamp = np.where(mask, 500.0 * sign, base)
    huge = np.where(mask, 1e6 * sign, base)
    inside = np.where(mask, 400.0 * sign, base)
    out_clamp, out_huge = rec.reconstruct(at_clamp).depth_mm, rec.reconstruct(huge).depth_mm
    np.testing.assert_allclose(out_huge, out_clamp, atol=1e-6)
    # not vacuous: a reading below the clamp does change the image
    assert np.abs(rec.reconstruct(inside).depth_mm - out_clamp).max() > 1e-4


def test_output_is_never_nan(onnx_4x4, onnx_5x6) -> None:
    rng = np.random.default_rng(5)
    f32_max = np.finfo(np.float32).max
    for model in (onnx_4x4, onnx_5x6):
        rec = OnnxReconstructor(model.path, samples=3)
        fields = np.concatenate([
            _readings(rng, 8, model.taxels, 1.0),
            _readings(rng, 8, model.taxels, 1e4),
            _readings(rng, 8, model.taxels, 1e30),
            np.full((1, *model.taxels), f32_max, np.float32),
            np.full((1, *model.taxels), -f32_max, np.float32),
            np.zeros((1, *model.taxels), np.float32),
        ])
        depth = rec.reconstruct_batch(fields)
        assert np.isfinite(depth).all() and (depth >= 0).all()
        one = rec.reconstruct(fields[-3])
        assert np.isfinite(one.depth_mm).all() and np.isfinite(one.spread_mm).all()


def test_metadata_round_trip(onnx_4x4, onnx_5x6) -> None:
    for model in (onnx_4x4, onnx_5x6):
        meta = read_metadata(model.path)
        rows, cols, axes = model.taxels
        assert meta["format_version"] == 1
        assert meta["input"]["shape"] == ["batch", rows, cols, axes]
        assert meta["input"]["clamp_ut"] == model.clamp_ut
        assert meta["input"]["axes_used"] == "xyz"
        assert meta["output"]["shape"] == ["batch", *model.image_hw]
        assert meta["output"]["pixel_mm"] == model.pixel_mm
        assert meta["preset"] == "small"
        assert meta["data_fingerprint"] == model.fingerprint
        assert meta["model_config"]["taxel_rows"] == rows and meta["model_config"]["taxel_cols"] == cols
        # what export returned is what the file holds (export adds only the parity it measured)
        exported = {k: v for k, v in model.metadata.items() if k != "parity_max_abs_mm"}
        assert json.loads(json.dumps(exported)) == meta
        assert OnnxReconstructor(model.path).name == "supermag-small"


@pytest.mark.parametrize("which", ["onnx", "bilinear"])
def test_empty_batch_gives_an_empty_result(onnx_4x4, which: str) -> None:
    rec = OnnxReconstructor(onnx_4x4.path) if which == "onnx" else load_reconstructor("bilinear")
    out = rec.reconstruct_batch(np.zeros((0, 4, 4, 3), np.float32))
    assert out.shape == (0, *rec.output_shape)


def test_load_reconstructor_opens_an_onnx_path(onnx_4x4) -> None:
    rec = load_reconstructor(str(onnx_4x4.path), samples=2)
    assert isinstance(rec, OnnxReconstructor) and rec.samples == 2


# ================================================================ interpolation baselines

# Pixel centres exactly on the chips: 31 px of 0.5 mm span -7.5..7.5 mm, so pixel (10 r, 10 c) is chip (r, c).
ON_CHIPS = {"output_shape": (31, 31), "pixel_mm": 0.5}


def _z_fields(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.normal(0.0, 150.0, (n, 4, 4, 3)).astype(np.float32)


@pytest.mark.parametrize("cls", [BilinearReconstructor, BicubicReconstructor])
def test_fit_recovers_gain_and_offset(cls: type[InterpolationReconstructor]) -> None:
    rng = np.random.default_rng(6)
    fields = _z_fields(rng, 20)
    gain, offset = -0.0015, 0.14
    probe = cls(gain_mm_per_ut=1.0, offset_mm=0.0, output_shape=(30, 30), pixel_mm=20.0 / 30)
    depth = gain * probe.upsample(fields) + offset
    fitted = cls.fit(fields, depth, pixel_mm=20.0 / 30)
    assert fitted.gain == pytest.approx(gain, rel=1e-6)
    assert fitted.offset == pytest.approx(offset, abs=1e-6)
    assert fitted.output_shape == (30, 30)
    noisy = cls.fit(fields, depth + rng.normal(0, 0.01, depth.shape), pixel_mm=20.0 / 30)
    assert noisy.gain == pytest.approx(gain, rel=0.02)
    assert noisy.offset == pytest.approx(offset, abs=0.002)


def test_bilinear_of_a_map_linear_in_x_is_linear_in_the_interior() -> None:
    rec = BilinearReconstructor(gain_mm_per_ut=1.0, offset_mm=0.0)  # the real 200 x 200, 0.1 mm geometry
    field = np.zeros((4, 4, 3), np.float32)
    field[..., 2] = 100.0 + 20.0 * np.arange(4)[None, :]  # 20 uT per chip column
    field[..., :2] = np.random.default_rng(7).normal(0, 300, (4, 4, 2))  # x and y axes must not matter
    up = rec.upsample(field[None])[0]
    x = (np.arange(200) - 99.5) * 0.1
    interior = np.abs(x) <= 7.5  # between the outer chip centres
    np.testing.assert_allclose(up[:, interior], np.broadcast_to(100.0 + 20.0 * (x[interior] / 5.0 + 1.5),
                                                                (200, interior.sum())), atol=1e-9)
    assert np.allclose(up[:, x < -7.5], 100.0) and np.allclose(up[:, x > 7.5], 160.0)  # edges held
    depth = rec.reconstruct(field).depth_mm
    np.testing.assert_allclose(depth, up, rtol=1e-6)


@pytest.mark.parametrize("cls", [BilinearReconstructor, BicubicReconstructor])
def test_interpolation_reproduces_the_chip_values_at_the_chip_centres(cls) -> None:
    rec = cls(gain_mm_per_ut=1.0, offset_mm=0.0, **ON_CHIPS)
    fields = _z_fields(np.random.default_rng(8), 3)
    up = rec.upsample(fields)
    np.testing.assert_allclose(up[:, ::10, ::10], fields[..., 2], atol=1e-6)


def test_bicubic_near_the_chip_centres_on_the_real_grid() -> None:
    # 200 px of 0.1 mm: the chips sit between pixels 24/25, 74/75, ...; the 4 nearest pixels average to
    # within a few percent of the chip value for a smooth map.
    rec = BicubicReconstructor(gain_mm_per_ut=1.0, offset_mm=0.0)
    field = np.zeros((1, 4, 4, 3), np.float32)
    yy, xx = np.mgrid[:4, :4]
    field[0, ..., 2] = 50.0 * np.sin(0.6 * xx) + 30.0 * np.cos(0.5 * yy)
    up = rec.upsample(field)[0]
    px = [24, 74, 124, 174]
    near = np.array([[up[r:r + 2, c:c + 2].mean() for c in px] for r in px])
    np.testing.assert_allclose(near, field[0, ..., 2], atol=0.02 * np.ptp(field[0, ..., 2]))


@pytest.mark.parametrize("name", ["bilinear", "bicubic"])
def test_depth_is_never_negative(name: str) -> None:
    rec = load_reconstructor(name)
    rng = np.random.default_rng(9)
    fields = np.concatenate([_z_fields(rng, 6), np.full((1, 4, 4, 3), 1e4, np.float32),
                             np.full((1, 4, 4, 3), -1e4, np.float32)])
    depth = rec.reconstruct_batch(fields)
    assert depth.shape == (8, 200, 200) and depth.dtype == np.float32
    assert depth.min() >= 0.0 and np.isfinite(depth).all()
    assert depth[-2].max() == 0.0          # a strong positive z field maps (gain < 0) to no contact
    assert depth[-1].min() > 1.0           # a strong negative one to a deep contact


@pytest.mark.parametrize("name", ["bilinear", "bicubic"])
def test_load_reconstructor_uses_the_shipped_fit(name: str) -> None:
    fit = default_baseline_fit()[name]
    rec = load_reconstructor(name)
    assert isinstance(rec, BASELINES[name]) and rec.name == name
    assert rec.gain == fit["gain_mm_per_ut"] and rec.offset == fit["offset_mm"]
    assert rec.input_shape == (4, 4, 3) and rec.output_shape == (200, 200) and rec.pixel_mm == 0.1
    assert rec.gain < 0  # the magnet is pushed towards the chips: z field falls as depth grows
    out = rec.reconstruct(np.zeros((4, 4, 3), np.float32))
    assert out.spread_mm is None
    np.testing.assert_allclose(out.depth_mm, max(fit["offset_mm"], 0.0), rtol=1e-6)
    assert rec.to_dict() == {**fit, "output_shape": list(rec.output_shape), "input_shape": [4, 4, 3], "channel": 2}


def test_load_reconstructor_rejects_an_unknown_name() -> None:
    with pytest.raises(ModelFileError, match="unknown reconstructor 'nonsense'") as info:
        load_reconstructor("nonsense")
    assert "'bilinear'" in str(info.value) and "'bicubic'" in str(info.value) and ".onnx" in str(info.value)


@pytest.mark.parametrize("name", ["bilinear", "bicubic"])
def test_baseline_rejects_wrong_shapes_and_non_finite_readings(name: str) -> None:
    rec = load_reconstructor(name)
    with pytest.raises(ValueError, match=rf"{name}: expected readings of shape \(4, 4, 3\), got \(4, 4\)"):
        rec.reconstruct(np.zeros((4, 4)))
    with pytest.raises(ValueError, match=r"\(N, 4, 4, 3\), got \(3, 5, 6, 3\)"):
        rec.reconstruct_batch(np.zeros((3, 5, 6, 3)))
    field = np.zeros((4, 4, 3))
    field[0, 0, 2] = np.nan
    with pytest.raises(ValueError, match="NaN or infinite"):
        rec.reconstruct(field)


def test_baseline_rejects_a_non_finite_fit() -> None:
    with pytest.raises(ValueError, match="must be finite"):
        BilinearReconstructor(gain_mm_per_ut=float("nan"), offset_mm=0.0)


@pytest.mark.parametrize("kind, problem", [("identity", "other input/output names"),
                                           ("input_dims", "input field_ut of other dimensions"),
                                           ("image_size", r"outputs of shape \[\(1, 100, 100\)")])
def test_metadata_copied_onto_another_graph_is_refused(graph_with_shipped_metadata, kind, problem) -> None:
    path = graph_with_shipped_metadata(kind)
    read_metadata(path)  # the metadata alone looks fine
    with pytest.raises(ModelFileError, match=problem) as err:
        load_reconstructor(path)
    message = assert_one_line_message(str(err.value), str(path))
    # names both sides: what the graph has and what the metadata describes
    assert "the graph maps (" in message and "the metadata describes (field_ut ['N', 4, 4, 3] float" in message
    if kind == "identity":
        assert "x [1, 48] float" in message


def test_models_name_their_board_layout_and_refuse_another(onnx_4x4, onnx_5x6):
    from tactile_manip.perception.estimator import TactilePoseEstimator
    from tactile_manip.perception.tactile_estimator import TactileEstimator
    from tactile_manip.sensors import SerialSensor, SerialSensorConfig

    model = OnnxReconstructor(onnx_4x4.path)
    assert model.board_layout == "supermag-4x4" and OnnxReconstructor(onnx_5x6.path).board_layout == "grid-5x6"
    model.check_layout("supermag-4x4")
    with pytest.raises(ValueError, match="'supermag-4x4' board layout, but the sensor has the 'anyskin-5' layout"):
        model.check_layout("anyskin-5")
    with pytest.raises(ValueError, match=r"\(4, 4, 3\), got \(3, 3, 3\) \(it takes readings of the supermag-4x4"):
        model.reconstruct(np.zeros((3, 3, 3)))
    # the estimator checks the sensor's layout before reading a frame (this sensor is never connected)
    anyskin = SerialSensor(SerialSensorConfig(port="/dev/null-x", wire_format="anyskin"))
    with pytest.raises(ValueError, match="anyskin-5"):
        TactileEstimator(TactilePoseEstimator(load_reconstructor("bilinear"))).read(anyskin)


def test_a_model_without_a_board_layout_in_its_metadata_is_a_supermag_model(onnx_4x4, tmp_path):
    import onnx

    from tactile_manip.perception.reconstruct import METADATA_KEY

    proto = onnx.load(str(onnx_4x4.path))
    for prop in proto.metadata_props:
        if prop.key == METADATA_KEY:
            meta = json.loads(prop.value)
            meta.pop("board_layout")
            prop.value = json.dumps(meta)
    old = tmp_path / "old.onnx"
    onnx.save(proto, str(old))
    assert OnnxReconstructor(old).board_layout == "supermag-4x4"
