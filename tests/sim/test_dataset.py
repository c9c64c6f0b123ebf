"""Dataset generation and its file: worker-count independence, seeding, splits, round trip, loading errors.

The simulator takes ~50-70 ms per pair and spawning workers ~2 s, so the generated datasets are tiny
(``scaled(0.004)``: 34 pairs) and shared across tests.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from tactile_manip.config import from_dict, to_dict
from tactile_manip.errors import DatasetError
from tactile_manip.sim.dataset import DatasetConfig, ObjectSpec, PoseRanges, generate, load_dataset_config
from tactile_manip.sim.objects import IndenterPose
from tactile_manip.sim.pair import SensorPair
from tactile_manip.sim.params import SimParams, randomised_values, with_values
from tactile_manip.sim.shapes import make_indenter
from tactile_manip.data import FORMAT_VERSION, PairedDataset, load_dataset, save_dataset
from tactile_manip.version import __version__, code_version

ROOT = Path(__file__).resolve().parents[2]
SUPERMAG = ROOT / "configs" / "dataset" / "supermag.toml"
ARRAYS = ("readings", "images", "targets", "object_index", "object_names", "split")
EXTRAS = ("field_raw_ut", "saturated", "pose", "force_n", "approach_mm", "skin_approach_mm", "contact")


@pytest.fixture(scope="module")
def cfg() -> DatasetConfig:
    return load_dataset_config(SUPERMAG).scaled(0.004)


@pytest.fixture(scope="module")
def data(cfg) -> PairedDataset:
    return generate(cfg, workers=1)


@pytest.fixture(scope="module")
def saved(data, tmp_path_factory) -> Path:
    return save_dataset(tmp_path_factory.mktemp("ds") / "small.npz", data)


def _assert_same_arrays(a: PairedDataset, b: PairedDataset) -> None:
    pairs = [(name, getattr(a, name), getattr(b, name)) for name in ARRAYS]
    pairs += [(name, a.extra(name), b.extra(name)) for name in EXTRAS]
    for name, x, y in pairs:
        assert x.dtype == y.dtype and x.shape == y.shape, name
        np.testing.assert_array_equal(x, y, err_msg=name)


# ---------------------------------------------------------------- generation


def test_shapes_and_dtypes(data, cfg):
    n = sum(o.count for o in cfg.objects)
    assert n == 34 and len(data) == n
    assert data.field_ut.shape == (n, 4, 4, 3) and data.field_ut.dtype == np.float32
    assert data.extra("saturated").dtype == bool and not data.extra("saturated").any()
    assert data.images.shape == (n, 200, 200) and data.images.dtype == np.uint8
    assert data.extra("pose").shape == (n, 5) and data.extra("force_n").shape == (n,)
    contact = data.extra("contact")
    assert contact.sum() >= n // 2  # offsets of +-5 mm mostly land on the pad
    assert ((data.extra("force_n")[contact] >= 10.0) & (data.extra("force_n")[contact] <= 11.0)).all()
    assert np.abs(data.extra("pose")[:, :2]).max() <= 5.0


def test_worker_count_does_not_change_the_data(data, cfg):
    parallel = generate(cfg, workers=2)
    _assert_same_arrays(data, parallel)
    assert parallel.fingerprint() == data.fingerprint()
    assert parallel.provenance["workers"] == 2


def test_sample_depends_only_on_seed_and_index(data, cfg):
    """Generating only the first object reproduces its samples: nothing leaks between samples."""
    first = generate(dataclasses.replace(cfg, objects=cfg.objects[:1]), workers=1)
    k = cfg.objects[0].count
    np.testing.assert_array_equal(first.field_ut, data.field_ut[:k])
    np.testing.assert_array_equal(first.images, data.images[:k])


def test_a_different_seed_changes_the_readings(data, cfg):
    other = generate(dataclasses.replace(cfg, seed=1), workers=1)
    assert other.fingerprint() != data.fingerprint()
    assert not np.array_equal(other.extra("pose"), data.extra("pose"))
    assert np.abs(other.field_ut - data.field_ut).max() > 1.0  # microtesla, well above rounding
    np.testing.assert_array_equal(other.split, data.split)  # splits come from the config, not the seed


def test_splits_follow_the_config(data, cfg):
    start = 0
    for spec in cfg.objects:
        part = list(data.split[start:start + spec.count])
        if spec.split == "test":
            assert part == ["test"] * spec.count
        else:
            n_train = math.floor(spec.count * (1 - cfg.validation_fraction))
            assert part == ["train"] * n_train + ["val"] * (spec.count - n_train)
        assert set(data.objects(np.arange(start, start + spec.count))) == {spec.display_name}
        start += spec.count
    assert [len(data.indices(s)) for s in ("train", "val", "test")] == [23, 4, 7]
    assert list(data.object_names) == [o.display_name for o in cfg.objects]


def test_scaling_keeps_a_zero_count_at_zero():
    cfg = DatasetConfig(objects=[ObjectSpec("cylinder", count=0), ObjectSpec("letter_r", count=10)])
    assert [o.count for o in cfg.scaled(5.0).objects] == [0, 50]
    assert [o.count for o in cfg.scaled(0.01).objects] == [0, 1]  # a small scale keeps one press of the others


def test_pose_ranges_that_put_the_object_off_the_pad_are_refused():
    objects = [ObjectSpec("letter_r", count=1)]
    DatasetConfig(objects=objects, poses=PoseRanges(offset_mm=10.0))  # up to the pad's edge is fine
    with pytest.raises(ValueError, match=r"poses.offset_mm = 12 puts object centres off the 20 mm pad.*<= 10"):
        DatasetConfig(objects=objects, poses=PoseRanges(offset_mm=12.0))


def test_simulate_notes_empty_and_bottomed_out_presses(data):
    from tactile_manip.commands.simulate import _physics_notes

    assert _physics_notes(data, thickness_mm=2.5) == []  # the small default dataset is inside the model
    thin = 0.5 * float(np.maximum(data.extra("approach_mm"), data.extra("skin_approach_mm")).max())
    notes = _physics_notes(data, thickness_mm=thin)
    assert len(notes) == 1 and "bottom out" in notes[0] and f"{len(data)} presses" in notes[0]
    empty = dataclasses.replace(data, extras={**data.extras, "contact": np.zeros(len(data), bool)})
    assert f"{len(data)} of {len(data)} presses do not touch the pad" in _physics_notes(empty, thickness_mm=2.5)[0]


def test_procedural_variants_are_different_shapes():
    spec = ObjectSpec("procedural", count=2, variants=2, kwargs={"seed": 3})
    d = generate(DatasetConfig(objects=[spec], poses=PoseRanges(offset_mm=0.0, tilt_deg=0.0)), workers=1)
    assert d.extra("contact").all()
    assert not np.array_equal(d.images[0] > 0, d.images[1] > 0)


def test_depth_mm_is_float32_within_the_quantised_range(data):
    depth = data.depth_mm()
    assert depth.dtype == np.float32 and depth.shape == data.images.shape
    assert depth.min() >= 0.0 and depth.max() <= 2.55 + 1e-6
    assert depth.max() > 0.5  # 10 N presses indent the gel by ~0.75-1.7 mm
    np.testing.assert_allclose(data.depth_mm([3])[0], data.images[3] * 0.01, rtol=1e-6)
    assert not depth[~data.extra("contact")].any()  # no contact, no depth


# ---------------------------------------------------------------- the file


def test_save_load_round_trip(data, saved, cfg):
    loaded = load_dataset(saved)
    _assert_same_arrays(data, loaded)
    assert loaded.fingerprint() == data.fingerprint()
    meta = loaded.provenance
    assert meta["code_version"] == code_version() and meta["code_version"].startswith(__version__)
    assert loaded.image.scale == 0.01 and loaded.image.unit == "mm" and loaded.image.data_range == 2.0
    assert loaded.channels.kind == "magnetic_vector" and loaded.channels.unit == "uT"
    with np.load(saved, allow_pickle=False) as z:
        assert json.loads(str(z["metadata"]))["format_version"] == FORMAT_VERSION
    assert meta["config"] == json.loads(json.dumps(to_dict(cfg)))
    assert from_dict(DatasetConfig, meta["config"]) == cfg  # a file tells how to regenerate it


def test_save_appends_the_suffix_and_leaves_no_partial_file(data, tmp_path):
    path = save_dataset(tmp_path / "noext", data)
    assert path == tmp_path / "noext.npz" and path.is_file()
    assert [p.name for p in tmp_path.iterdir()] == ["noext.npz"]


def _rewrite(src: Path, dst: Path, **changes) -> Path:
    """Copy the npz at ``src`` to ``dst`` with arrays replaced (a value of None drops the array)."""
    with np.load(src, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    for k, v in changes.items():
        if v is None:
            arrays.pop(k)
        else:
            arrays[k] = v
    np.savez(dst, **arrays)
    return dst


def _metadata_with(saved: Path, **items) -> np.ndarray:
    with np.load(saved, allow_pickle=False) as z:
        meta = json.loads(str(z["metadata"]))
    meta.update(items)
    return np.array(json.dumps(meta))


def _load_error(path: Path) -> str:
    with pytest.raises(DatasetError) as info:
        load_dataset(path)
    msg = str(info.value)
    assert str(path) in msg
    return msg


def test_load_missing_file(tmp_path):
    assert "dataset not found" in _load_error(tmp_path / "absent.npz")


def test_load_random_bytes(tmp_path):
    path = tmp_path / "noise.npz"
    path.write_bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    assert "is not a tactile_manip dataset" in _load_error(path)


def test_load_pickled_objects_says_not_a_dataset_without_suggesting_allow_pickle(tmp_path):
    path = tmp_path / "objects.npz"
    with path.open("wb") as f:
        np.save(f, np.array([{"a": 1}], dtype=object))  # an object array: loading it would unpickle
    msg = _load_error(path)
    assert "is not a tactile_manip dataset" in msg and "never" in msg and "allow_pickle" not in msg


def test_load_truncated_file(saved, tmp_path):
    path = tmp_path / "cut.npz"
    path.write_bytes(saved.read_bytes()[: saved.stat().st_size // 2])
    assert "is not a tactile_manip dataset" in _load_error(path)


def test_load_npz_missing_arrays(saved, tmp_path):
    msg = _load_error(_rewrite(saved, tmp_path / "m.npz", images=None, split=None))
    assert "missing arrays" in msg and "images" in msg and "split" in msg


def test_load_wrong_format_version(saved, tmp_path):
    path = _rewrite(saved, tmp_path / "v.npz", metadata=_metadata_with(saved, format_version=FORMAT_VERSION + 1))
    msg = _load_error(path)
    assert f"format version {FORMAT_VERSION + 1}" in msg and f"reads 1, 2, {FORMAT_VERSION}" in msg


def test_load_metadata_not_json(saved, tmp_path):
    msg = _load_error(_rewrite(saved, tmp_path / "j.npz", metadata=np.array("{not json")))
    assert "metadata is not valid JSON" in msg


def test_load_inconsistent_lengths(saved, data, tmp_path):
    msg = _load_error(_rewrite(saved, tmp_path / "n.npz", extra__force_n=data.extra("force_n")[:-1]))
    assert "force_n" in msg and f"{len(data)} samples" in msg


def test_load_refuses_pickled_arrays(saved, tmp_path):
    """Files are data: an object array (which would need pickle) is refused, not unpickled."""
    objects = np.array([{"a": 1}] * 23, dtype=object)
    msg = _load_error(_rewrite(saved, tmp_path / "p.npz", object_names=objects))
    assert "is not a tactile_manip dataset" in msg and "allow_pickle" not in msg


def test_load_plain_npy_file(tmp_path):
    path = tmp_path / "array.npz"
    with path.open("wb") as f:
        np.save(f, np.zeros(3))
    assert "not a dataset archive" in _load_error(path)


def test_randomised_sensors_are_recorded_per_sample():
    spec = ObjectSpec("cylinder", count=4, kwargs={"size_mm": 3.0})
    cfg = DatasetConfig(objects=[spec], randomise_spread=1.0, poses=PoseRanges(force_n=(2.0, 15.0)))
    d = generate(cfg, workers=1)
    names = d.provenance["sensor_param_names"]
    draws = d.extra("sensor_params")
    assert draws.shape == (4, len(names)) and "magnet.remanence_t" in names and "chip.noise_z_ut" in names
    jr = draws[:, names.index("magnet.remanence_t")]
    assert ((0.03 <= jr) & (jr <= 0.055)).all() and len(np.unique(jr)) == 4  # each press its own sensor
    forces = d.extra("force_n")
    assert ((2.0 <= forces) & (forces <= 15.0)).all()
    assert not generate(dataclasses.replace(cfg, randomise_spread=0.0), workers=1).has("sensor_params")


def test_a_recorded_sensor_is_rebuilt_from_its_values_and_the_press_repeats():
    # what benchmarks/angle_information.py relies on: sensor_params + pose + force give the same noise-free
    # field change as the press that made the sample
    spec = ObjectSpec("hex_bar", count=2, kwargs={"size_mm": 4.0})
    cfg = DatasetConfig(objects=[spec], randomise_spread=1.0, poses=PoseRanges(force_n=(2.0, 15.0)))
    d = generate(cfg, workers=1)
    names = d.provenance["sensor_param_names"]
    for i in range(2):
        params = with_values(SimParams(), dict(zip(names, map(float, d.extra("sensor_params")[i]))))
        assert list(randomised_values(params).values()) == pytest.approx(d.extra("sensor_params")[i], rel=1e-6)
        pose = IndenterPose(*map(float, d.extra("pose")[i]))
        pair = SensorPair(params, seed=cfg.sensor_seed)
        again = pair.press(make_indenter("hex_bar", size_mm=4.0), pose, float(d.extra("force_n")[i]),
                           np.random.default_rng(0), render_depth=False)
        # the reading without noise, drift and quantisation, against the recorded one: within a few sigma
        expected = again.field_clean_ut
        sigma = math.hypot(max(params.chip.noise_xy_ut, params.chip.noise_z_ut), params.chip.drift_ut)
        tolerance = 5 * sigma + 0.5
        assert np.abs(expected - d.readings[i]).max() < tolerance
        assert np.abs(again.field_change_ut).max() > 2 * tolerance  # a press well above the noise: it has teeth
    with pytest.raises(KeyError, match="'chip.nois_xy_ut'"):
        with_values(SimParams(), {"chip.nois_xy_ut": 2.0})


def test_presses_through_the_layer_are_flagged_or_redrawn():
    sharp = ObjectSpec("ridge", count=6, kwargs={"angle_deg": 60.0, "tip_radius_mm": 0.0})
    poses = PoseRanges(offset_mm=0.0, force_n=(12.0, 15.0))
    kept = generate(DatasetConfig(objects=[sharp], poses=poses), workers=1)
    assert kept.extra("bottomed_out").all()  # a knife edge at 12-15 N goes through the 2.5 mm layer
    assert (np.maximum(kept.extra("approach_mm"), kept.extra("skin_approach_mm")) >= 2.5).all()
    blunt = ObjectSpec("ridge", count=8, kwargs={"angle_deg": 70.0, "tip_radius_mm": 0.1})
    mixed = DatasetConfig(objects=[blunt], poses=PoseRanges(offset_mm=0.0, force_n=(2.0, 15.0)), seed=1)
    assert generate(mixed, workers=1).extra("bottomed_out").any()  # some of these presses go through
    redrawn = generate(dataclasses.replace(mixed, bottomed_out="redraw"), workers=1)
    assert not redrawn.extra("bottomed_out").any()
    assert (np.maximum(redrawn.extra("approach_mm"), redrawn.extra("skin_approach_mm")) < 2.5).all()
    with pytest.raises(ValueError, match="bottomed_out must be"):
        DatasetConfig(objects=[blunt], bottomed_out="drop")
