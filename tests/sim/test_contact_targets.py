"""Simulated presses carry contact targets: the centre of pressure of the patch (not the object's origin),
the skin's indentation, the force and the contact flag; the contact configs load and generate."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from tactile_manip.sim.dataset import (SIM_TARGETS, DatasetConfig, ObjectSpec, PoseRanges, generate,
                                       load_dataset_config, sample_targets)
from tactile_manip.sim.objects import IndenterPose
from tactile_manip.sim.pair import SensorPair
from tactile_manip.sim.shapes import make_indenter

ROOT = Path(__file__).resolve().parents[2]


def _rods(**poses) -> DatasetConfig:
    return DatasetConfig(seed=3, images=False, poses=PoseRanges(**{"tilt_deg": 0.0, "force_n": (2.0, 15.0), **poses}),
                         objects=[ObjectSpec(name="cylinder", count=8, kwargs={"size_mm": 6.0}),
                                  ObjectSpec(name="letter_r", count=4, split="test")])


def test_targets_are_the_centre_of_pressure_depth_and_force():
    data = generate(_rods(), workers=1)
    assert data.target_names == SIM_TARGETS and not data.has_images
    rods = data.objects() == "cylinder"
    pose = data.extra("pose")[rods]
    x, y = data.target("x_mm")[rods], data.target("y_mm")[rods]
    # an untilted rod presses symmetrically about its axis: the centre of pressure lies on the axis line
    across = -(x - pose[:, 0]) * np.sin(pose[:, 2]) + (y - pose[:, 1]) * np.cos(pose[:, 2])
    assert np.abs(across).max() < 0.1  # the contact grid is 0.25 mm: a turned rod is resolved to a fraction of it
    # ... and along the axis it is the middle of the chord the pad cuts, not the rod's origin
    along = (x - pose[:, 0]) * np.cos(pose[:, 2]) + (y - pose[:, 1]) * np.sin(pose[:, 2])
    assert np.abs(along).max() > 0.5
    np.testing.assert_array_equal(data.target("force_n"), data.extra("force_n"))
    np.testing.assert_array_equal(data.target("depth_mm"), np.minimum(data.extra("skin_approach_mm"), 2.5))
    assert (data.target("in_contact") == data.extra("contact")).all()
    assert (data.target("force_n") >= 2.0).all() and (data.target("force_n") <= 15.0).all()
    # the letter "R" (off-centre relief): its centre of pressure is not its origin either
    r = data.objects() == "letter_r"
    offset = np.hypot(data.target("x_mm")[r] - data.extra("pose")[r, 0], data.target("y_mm")[r] - data.extra("pose")[r, 1])
    assert offset.max() > 0.5


def test_a_press_off_the_pad_has_zero_targets():
    pair, rod = SensorPair(), make_indenter("cylinder", size_mm=3.0)
    rng = np.random.default_rng(0)
    off = pair.press(rod, IndenterPose(x_mm=0.0, y_mm=13.0), 5.0, rng, render_depth=False)
    on = pair.press(rod, IndenterPose(x_mm=0.0, y_mm=2.0), 5.0, rng, render_depth=False)
    assert not off.contact and sample_targets(off) == [0.0] * len(SIM_TARGETS)
    x, y, depth, force, flag = sample_targets(on)
    assert abs(y - 2.0) < 0.1 and abs(x) < 0.1 and depth > 0 and force == 5.0 and flag == 1.0
    deep = pair.press(make_indenter("ridge", angle_deg=30.0, tip_radius_mm=0.0), IndenterPose(), 15.0, rng,
                      render_depth=False)
    assert deep.bottomed_out and deep.skin_approach_mm > 2.5 and sample_targets(deep)[2] == 2.5


@pytest.mark.parametrize("name", ["contact_probe", "contact_unseen"])
def test_the_contact_configs_load_and_generate_targets(name):
    cfg = load_dataset_config(ROOT / "configs" / "dataset" / f"{name}.toml")
    assert cfg.poses.force_n == (2.0, 15.0) and not cfg.images
    assert cfg.randomise_spread == (1.0 if name == "contact_unseen" else 0.0)
    tiny = cfg.scaled(1e-4)  # one press per object
    if name == "contact_unseen":
        tiny = dataclasses.replace(tiny, objects=tiny.objects[:1] + tiny.objects[-1:])
    data = generate(tiny, workers=1)
    assert data.target_names == SIM_TARGETS and set(data.split) >= {"test"}
    if name == "contact_unseen":
        assert data.has("sensor_params")


def test_the_patch_centroid_is_stored_beside_the_centre_of_pressure():
    data = generate(_rods(tilt_deg=2.0), workers=1)
    centroid = data.extra("contact_centroid_mm")
    assert centroid.shape == (len(data), 2) and np.isfinite(centroid).all()
    rods = data.objects() == "cylinder"
    pose = data.extra("pose")[rods]
    # both lie on the rod's axis line (a tilt about the axis shifts them by a fraction of the 6 mm rod)
    dx, dy = centroid[rods, 0] - pose[:, 0], centroid[rods, 1] - pose[:, 1]
    across = -dx * np.sin(pose[:, 2]) + dy * np.cos(pose[:, 2])
    assert np.abs(across).max() < 1.0
    # a tilt along the rod loads one end more: the pressure's centre leaves the patch's centroid
    cop = np.c_[data.target("x_mm"), data.target("y_mm")][rods]
    assert np.hypot(*(cop - centroid[rods]).T).max() > 0.2


def test_an_untilted_rod_along_x_has_both_centres_on_its_axis_at_the_pad_middle():
    pair, rod = SensorPair(), make_indenter("cylinder", size_mm=6.0)
    s = pair.press(rod, IndenterPose(x_mm=0.0, y_mm=1.5), 8.0, np.random.default_rng(0), render_depth=False)
    # the patch and its pressure are symmetric about x = 0 and about the axis y = 1.5
    np.testing.assert_allclose(s.pressure.area_centroid_mm, (0.0, 1.5), atol=0.05)
    np.testing.assert_allclose(s.pressure.centroid_mm, (0.0, 1.5), atol=0.05)
