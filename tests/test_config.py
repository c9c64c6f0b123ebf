"""TOML -> typed dataclasses: a valid file loads, every kind of bad file is one ConfigError naming file and key;
simulator parameters: defaults, randomisation and their description."""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from checks import assert_one_line_message
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_manip.config import from_dict, load_config, to_dict
from tactile_manip.errors import ConfigError
from tactile_manip.sim.dataset import DatasetConfig, ObjectSpec, PoseRanges, _splits, load_dataset_config
from tactile_manip.boards import load_board
from tactile_manip.sim.params import (
    for_board,
    ChipParams,
    ContactParams,
    LayerParams,
    MagnetParams,
    SimParams,
    VbtsParams,
    describe,
    randomise,
)

ROOT = Path(__file__).resolve().parents[1]
SUPERMAG = ROOT / "configs" / "dataset" / "supermag.toml"
NOMINAL = for_board(load_board("supermag-4x4"))  # the simulator's parameters with the SuperMag board's figures
GROUPS = (LayerParams, ContactParams, VbtsParams, MagnetParams, ChipParams)


# ---------------------------------------------------------------- a valid file


def test_supermag_loads_into_typed_config():
    cfg = load_dataset_config(SUPERMAG)
    assert isinstance(cfg, DatasetConfig)
    assert len(cfg.objects) == 11
    assert sum(o.count for o in cfg.objects) == 7290
    assert [o.display_name for o in cfg.objects[:3]] == ["allen_key", "letter_r", "cylinder_3mm"]
    assert [o.split for o in cfg.objects] == ["trainval"] * 2 + ["test"] * 7 + ["trainval"] * 2
    assert cfg.objects[2].kwargs == {"size_mm": 3.0}
    assert cfg.objects[8].variants == 20 and cfg.objects[8].kwargs == {"seed": 1000}
    # the procedural training shapes come from other seeds than the procedural test shapes
    train_shapes = cfg.objects[9]
    assert train_shapes.display_name == "procedural_train" and train_shapes.kwargs == {"seed": 5000}
    assert train_shapes.variants == 400
    wide = cfg.objects[10]
    assert wide.display_name == "procedural_wide" and wide.kwargs == {"seed": 7000, "size_mm": 26.0}
    assert cfg.poses == PoseRanges(offset_mm=5.0, yaw_deg=(-180.0, 180.0), tilt_deg=2.0, force_n=(10.0, 11.0))
    assert isinstance(cfg.poses.yaw_deg, tuple)  # TOML arrays become the annotated tuples
    assert cfg.sim == SimParams()  # the file sets no [sim] table


def test_supermag_splits_match_the_paper():
    cfg = load_dataset_config(SUPERMAG)
    split = _splits(cfg)
    assert split.shape == (7290,)
    allen = split[:2025]
    assert (allen == "train").sum() == 1822 and (allen == "val").sum() == 203
    assert (allen[:1822] == "train").all()  # the validation tail is the last 203 presses
    assert ((split[:4050] == "train").sum(), (split[:4050] == "val").sum()) == (3644, 406)  # the paper's
    assert ((split == "train").sum(), (split == "val").sum(), (split == "test").sum()) == (6164, 686, 440)
    # the extra training families come after the test objects: the first 6090 samples are the old dataset
    assert (split[4050:4490] == "test").all() and (split[4490:] != "test").all()


def test_config_round_trips_through_plain_dicts():
    cfg = load_dataset_config(SUPERMAG)
    plain = to_dict(cfg)
    assert isinstance(plain["poses"]["yaw_deg"], list)
    assert from_dict(DatasetConfig, plain) == cfg


def test_nested_sim_table_overrides_defaults(tmp_path):
    path = _write(tmp_path, SUPERMAG.read_text() + "\n[sim.layer]\nskin_modulus_kpa = 150\n"
                                                   "[sim.vbts]\nlookup_table = \"sensor_2\"\n")
    cfg = load_dataset_config(path)
    assert cfg.sim.layer.skin_modulus_kpa == 150.0 and isinstance(cfg.sim.layer.skin_modulus_kpa, float)
    assert cfg.sim.vbts.lookup_table == "sensor_2"
    assert cfg.sim.chip.noise_xy_ut is None  # the board's figure, filled in when the dataset is simulated


# ---------------------------------------------------------------- bad files


def _write(tmp_path: Path, text: str, name: str = "cfg.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _supermag_with(old: str, new: str) -> str:
    text = SUPERMAG.read_text()
    assert old in text, f"fixture text {old!r} not in {SUPERMAG}"
    return text.replace(old, new, 1)


def _error(path: Path) -> str:
    with pytest.raises(ConfigError) as info:
        load_dataset_config(path)
    return assert_one_line_message(str(info.value), str(path))  # one line for the CLI


BAD_FILES = {
    "unknown top-level key": (lambda t: "colour = \"red\"\n" + t, ["colour", "allowed", "validation_fraction"]),
    "unknown nested key": (lambda t: t + "\n[sim.layer]\nskin_moduls_kpa = 150.0\n",
                           ["sim.layer.skin_moduls_kpa", "skin_modulus_kpa"]),
    "string for a float": (lambda t: t.replace("validation_fraction = 0.1", "validation_fraction = \"0.1\""),
                           ["validation_fraction", "number", "'0.1'"]),
    "float for an int": (lambda t: t.replace("\nseed = 0\n", "\nseed = 0.5\n"), ["seed", "integer", "0.5"]),
    "bool for a number": (lambda t: t.replace("randomise_spread = 0.0", "randomise_spread = true"),
                          ["randomise_spread", "number", "True"]),
    "bool for an int": (lambda t: t + "\n[sim.contact]\nmax_iterations = true\n",
                        ["sim.contact.max_iterations", "integer"]),
    "wrong Literal (nested table)": (lambda t: t + "\n[sim.vbts]\nlookup_table = \"sensor_9\"\n",
                                     ["sim.vbts.lookup_table", "sensor_9", "sensor_1", "sensor_2"]),
    "wrong Literal (array of tables)": (lambda t: t.replace("count = 2025", "count = 2025\nsplit = \"bogus\"", 1),
                                       ["objects[0].split", "bogus", "trainval"]),
    "negative count": (lambda t: t.replace("count = 2025", "count = -5", 1), ["objects[0]", "count", "-5"]),
    "negative modulus": (lambda t: t + "\n[sim.layer]\nvbts_modulus_kpa = -1\n",
                         ["sim.layer", "vbts_modulus_kpa", "-1"]),
    "nan": (lambda t: t + "\n[sim.layer]\nvbts_modulus_kpa = nan\n", ["sim.layer", "vbts_modulus_kpa", "nan"]),
    "inf": (lambda t: t + "\n[sim.magnet]\nchip_gap_mm = inf\n", ["sim.magnet", "chip_gap_mm", "inf"]),
    "nan in a pose range": (lambda t: t.replace("tilt_deg = 2.0", "tilt_deg = nan"), ["poses", "tilt_deg", "nan"]),
    "fraction out of range": (lambda t: t.replace("validation_fraction = 0.1", "validation_fraction = 1.0"),
                              ["validation_fraction", "1.0"]),
    "tuple of the wrong length": (lambda t: t.replace("force_n = [10.0, 11.0]", "force_n = [10.0]"),
                                  ["poses.force_n", "2 items"]),
    "scalar for a table": (lambda t: "sim = 3\n" + t, ["[sim] must be a table", "int"]),
    "scalar for kwargs": (lambda t: t.replace("kwargs = { size_mm = 3.0 }", "kwargs = 3", 1),
                          ["objects[2].kwargs", "must be a table"]),
    "infinite yaw range": (lambda t: t.replace("yaw_deg = [-180.0, 180.0]", "yaw_deg = [-inf, inf]"),
                           ["poses", "yaw_deg"]),
    "unknown object name": (lambda t: t.replace('name = "letter_r"', 'name = "letter_q"'),
                            ["objects[1]", "letter_q", "allen_key"]),
}


@pytest.mark.parametrize("case", list(BAD_FILES))
def test_bad_file_is_one_config_error_naming_file_and_key(tmp_path, case):
    edit, expected = BAD_FILES[case]
    text = edit(SUPERMAG.read_text())
    assert text != SUPERMAG.read_text(), "the edit did not apply"
    msg = _error(_write(tmp_path, text))
    for part in expected:
        assert part in msg, f"{part!r} not in {msg!r}"


def test_post_init_error_keeps_its_cause(tmp_path):
    with pytest.raises(ConfigError) as info:
        load_dataset_config(_write(tmp_path, SUPERMAG.read_text() + "\n[sim.layer]\nvbts_modulus_kpa = -1\n"))
    assert isinstance(info.value.__cause__, ValueError)
    assert isinstance(info.value, ValueError)  # the CLI turns ValueErrors into one line


def test_missing_file(tmp_path):
    path = tmp_path / "nope.toml"
    with pytest.raises(ConfigError, match="not found") as info:
        load_config(path, DatasetConfig)
    assert str(path) in str(info.value)
    assert isinstance(info.value.__cause__, FileNotFoundError)


def test_invalid_toml_syntax(tmp_path):
    path = _write(tmp_path, "seed = 0\n[poses\noffset_mm = 5.0\n")
    msg = _error(path)
    assert "not valid TOML" in msg and "line 2" in msg


def test_empty_objects_refused(tmp_path):
    msg = _error(_write(tmp_path, "seed = 1\n"))
    assert "objects" in msg


def test_from_dict_names_the_prefix_and_where():
    with pytest.raises(ConfigError, match=r"^here: unknown key\(s\) poses\.speed"):
        from_dict(PoseRanges, {"speed": 1.0}, where="here", prefix="poses")
    assert from_dict(ObjectSpec, {"name": "cylinder", "count": 3}) == ObjectSpec("cylinder", 3)


# ---------------------------------------------------------------- simulator parameters


def _rand_fields(params) -> list[tuple[str, float, dataclasses.Field]]:
    """(dotted name, value, field) of every randomisable leaf of a parameter tree."""
    out = []
    for f in dataclasses.fields(params):
        value = getattr(params, f.name)
        if dataclasses.is_dataclass(value):
            out += [(f"{f.name}.{n}", v, g) for n, v, g in _rand_fields(value)]
        elif f.metadata.get("rand") is not None:
            out.append((f.name, value, f))
    return out


def _shrunk(default: float, rand: tuple[float, float], log: bool, spread: float) -> tuple[float, float]:
    """The range ``randomise`` draws from at ``spread`` (in linear units)."""
    tf, inv = (math.log, math.exp) if log else (float, float)
    c = tf(default)
    ends = [inv(c + spread * (tf(r) - c)) for r in rand]
    return min(ends), max(ends)


def test_defaults_validate_and_lie_inside_their_randomisation_ranges():
    params = NOMINAL
    assert [type(getattr(params, f.name)) for f in dataclasses.fields(params)] == list(GROUPS)
    for group in GROUPS:
        group()  # each group validates its defaults on its own
    fields = _rand_fields(params)
    assert len(fields) >= 10
    for name, value, f in fields:
        lo, hi = f.metadata["rand"]
        assert lo <= value <= hi, f"{name} = {value} outside its randomisation range {(lo, hi)}"


@pytest.mark.parametrize("group, kwargs, match", [
    (LayerParams, {"vbts_modulus_kpa": -1.0}, "LayerParams.vbts_modulus_kpa = -1.0"),
    (LayerParams, {"skin_modulus_kpa": math.nan}, "LayerParams.skin_modulus_kpa must be a finite"),
    (ChipParams, {"noise_xy_ut": math.inf}, "ChipParams.noise_xy_ut must be a finite"),
    (MagnetParams, {"chip_gap_mm": 200.0}, r"MagnetParams.chip_gap_mm = 200.0 .*\(0.001, 100.0\)"),
    (ContactParams, {"pixel_mm": 0.0}, "ContactParams.pixel_mm"),
])
def test_refused_values_name_the_field(group, kwargs, match):
    with pytest.raises(ValueError, match=match):
        group(**kwargs)


def test_randomise_with_zero_spread_returns_the_defaults():
    params = NOMINAL
    assert randomise(params, np.random.default_rng(0), spread=0.0) == params


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), spread=st.sampled_from([0.25, 0.5, 1.0]))
def test_randomise_stays_inside_the_shrunk_ranges(seed, spread):
    base = NOMINAL
    drawn = dict((n, v) for n, v, _ in _rand_fields(randomise(base, np.random.default_rng(seed), spread=spread)))
    for name, default, f in _rand_fields(base):
        lo, hi = _shrunk(default, f.metadata["rand"], f.metadata["log"], spread)
        tol = 1e-12 * max(abs(lo), abs(hi), 1.0)
        assert lo - tol <= drawn[name] <= hi + tol, f"{name} = {drawn[name]} outside [{lo}, {hi}]"


def test_randomise_is_deterministic_per_seed_and_changes_every_randomisable_field():
    base = NOMINAL
    a = randomise(base, np.random.default_rng(3), spread=1.0)
    assert a == randomise(base, np.random.default_rng(3), spread=1.0)
    assert a != randomise(base, np.random.default_rng(4), spread=1.0)
    for (name, new, _), (_, old, _) in zip(_rand_fields(a), _rand_fields(base)):
        assert new != old, f"{name} was not drawn"
    # fields without a range keep their defaults
    assert a.chip.lsb_xy_ut == base.chip.lsb_xy_ut and a.vbts.lookup_table == base.vbts.lookup_table


@pytest.mark.parametrize("spread", [-0.1, 1.5, math.nan])
def test_randomise_refuses_bad_spread(spread):
    with pytest.raises(ValueError, match="spread"):
        randomise(NOMINAL, np.random.default_rng(0), spread=spread)


def test_describe_lists_every_field_with_a_source():
    params = SimParams()
    rows = describe(params)
    leaves = sum(len(dataclasses.fields(g)) for g in GROUPS)
    assert len(rows) == leaves
    names = [r["name"] for r in rows]
    assert len(set(names)) == len(names)
    assert {"layer.skin_modulus_kpa", "vbts.lookup_table", "magnet.transport", "chip.noise_z_ut"} <= set(names)
    for r in rows:
        assert isinstance(r["source"], str) and r["source"].strip(), f"{r['name']} has no source"
        assert r["unit"], f"{r['name']} has no unit"
        group, field = r["name"].split(".")
        assert r["value"] == getattr(getattr(params, group), field)
    assert dict((r["name"], r["rand"]) for r in rows)["layer.skin_modulus_kpa"] == (120.0, 300.0)


def test_supermag_file_parses_with_plain_tomllib():
    """The file is data: tomllib alone reads it, and the loader adds nothing a reader would not see."""
    raw = tomllib.loads(SUPERMAG.read_text())
    assert from_dict(DatasetConfig, raw) == load_dataset_config(SUPERMAG)


def test_config_differences_name_dotted_keys_and_stop_at_a_limit():
    from tactile_manip.config import config_differences

    saved = {"a": 1, "sim": {"layer": {"e_kpa": 200.0, "h_mm": 2.5}}, "objects": ["x"]}
    now = {"a": 1, "sim": {"layer": {"e_kpa": 150.0, "h_mm": 2.5}}, "objects": ["x", "y"], "new": True}
    assert config_differences(saved, now) == ["new: '<absent>' -> True", "objects: ['x'] -> ['x', 'y']",
                                              "sim.layer.e_kpa: 200.0 -> 150.0"]
    assert config_differences(saved, saved) == []
    many = config_differences({f"k{i}": i for i in range(20)}, {}, limit=3)
    assert len(many) == 4 and many[-1] == "..."


def test_a_byte_order_mark_is_read_past_and_other_bytes_are_named(tmp_path):
    """An editor's UTF-8 byte-order mark is no TOML error; a file that is not UTF-8 says which byte is not."""
    from tactile_manip.boards.load import load_board

    text = (Path(__file__).resolve().parents[1] / "tactile_manip" / "boards" / "eflesh.toml").read_bytes()
    marked = tmp_path / "mine.toml"
    marked.write_bytes(b"\xef\xbb\xbf" + text.replace(b'name = "eflesh"', b'name = "my-cube"', 1))
    assert load_board(marked).name == "my-cube"
    latin = tmp_path / "latin.toml"
    latin.write_bytes(b"# caf\xe9\n" + text)
    with pytest.raises(ConfigError, match=r"latin.toml: not a text \(UTF-8\) TOML file: byte 5 is not UTF-8"):
        load_board(latin)
