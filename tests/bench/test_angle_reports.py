"""The angle bound's and the angle ablation's report parts: shares per force band and per object."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.angle_ablation import bound_shares, markdown
from benchmarks.angle_information import POSE_NUISANCES, SENSOR_NUISANCES, summarise


def _info(label: str, force_n: float, angle_gain: float, rng: np.random.Generator) -> dict:
    """One press whose reading moves with the angle by ``angle_gain`` and with each nuisance at random."""
    jac = rng.normal(size=(48, 1 + len(POSE_NUISANCES) + len(SENSOR_NUISANCES)))
    jac[:, 0] *= angle_gain
    return {"label": label, "force_n": force_n, "jacobian": jac.tolist(), "white_var": [1.0] * 48,
            "drift_var": 0.5, "noise_xy_ut": float(rng.uniform(1, 10)), "saturated": [False] * 48}


def test_the_bound_has_a_row_per_object_only_where_there_are_several() -> None:
    rng = np.random.default_rng(0)
    # the flat bar's angle moves the reading a hundredth as much: its share within 5 deg must be the smaller
    infos = ([_info("cylinder_3mm", 3.0 + i, 1.0, rng) for i in range(6)]
             + [_info("flat_bar_7x2mm", 3.0 + i, 0.01, rng) for i in range(4)])
    rows = summarise(infos)["one frame"]
    assert rows["cylinder_3mm"]["presses"] == 6 and rows["flat_bar_7x2mm"]["presses"] == 4
    assert rows["flat_bar_7x2mm"]["pose_sensor_within_5"] < rows["cylinder_3mm"]["pose_sensor_within_5"]
    # the whole is the presses' mean of its objects
    whole = (6 * rows["cylinder_3mm"]["pose_within_5"] + 4 * rows["flat_bar_7x2mm"]["pose_within_5"]) / 10
    assert math.isclose(rows["all"]["pose_within_5"], whole, rel_tol=1e-12)
    single = summarise([_info("cylinder_3mm", 3.0 + i, 1.0, rng) for i in range(3)])["one frame"]
    assert "cylinder_3mm" not in single and set(single) >= {"all", "2-5 N"}


def test_the_ablation_lists_the_bound_per_object_beside_each_route() -> None:
    bound = {"bounds": {"one frame": {
        "all": {"pose_sensor_within_5": 0.9}, "2-5 N": {"pose_sensor_within_5": 0.8},
        "chip noise low third": {"pose_sensor_within_5": 0.95},
        "cylinder_3mm": {"pose_sensor_within_5": 0.99}, "flat_bar_7x2mm": {"pose_sensor_within_5": 0.87}}}}
    shares = bound_shares(bound)
    assert shares["by_force"] == {"2-5 N": 0.8}
    assert shares["by_object"] == {"cylinder_3mm": 0.99, "flat_bar_7x2mm": 0.87}  # not the noise terciles
    route = {"within_5": 0.92, "within_2": 0.8, "median_deg": 0.7, "by_force": {"2-5 N": 0.75},
             "by_object": {"cylinder_3mm": 0.99, "flat_bar_7x2mm": 0.82}, "reliability": []}
    text = markdown({"presses": 10, "data": "d.npz", "results": {"default: head": route}, "bound": shares})
    objects = text.split("Within 5 deg per object:")[1]
    assert "| Cramer-Rao bound (pose and sensor unknown) | 99% | 87% |" in objects
    assert "| default: head | 99% | 82% |" in objects
    # an older bound report has no rows per object: the table then lists the routes alone
    old = markdown({"presses": 10, "data": "d.npz", "results": {"default: head": route},
                    "bound": {"all": 0.9, "by_force": {"2-5 N": 0.8}}})
    assert "Cramer-Rao" not in old.split("Within 5 deg per object:")[1]


def test_the_ablation_shows_the_spread_of_the_fresh_chip_draws() -> None:
    route = {"within_5": 0.92, "within_2": 0.8, "median_deg": 0.7, "by_force": {"2-5 N": 0.78},
             "by_object": {"cylinder_3mm": 0.99}, "reliability": [], "draws": 8,
             "within_5_range": [0.915, 0.932], "within_5_at_2_5_n_range": [0.754, 0.804]}
    text = markdown({"presses": 10, "data": "d.npz", "results": {"default: head, fresh chip draws": route}})
    assert "| default: head, fresh chip draws | 8 | 91.5%-93.2% | 75.4%-80.4% |" in text
    recorded = dict(route)
    for key in ("draws", "within_5_range", "within_5_at_2_5_n_range"):
        recorded.pop(key)
    assert "fresh chip draws" not in markdown({"presses": 10, "data": "d.npz", "results": {"default: head": recorded}})


def test_fresh_draws_read_the_clean_field_through_new_chips_and_tared_ones_without_drift(monkeypatch) -> None:
    import dataclasses

    import benchmarks.angle_ablation as ablation
    from tactile_manip.learning.noise import ChipNoise
    from tactile_manip.perception import load_reconstructor, wrap_axial
    from tactile_manip.shipped import shipped_model
    from tactile_manip.sim.dataset import DatasetConfig, ObjectSpec, PoseRanges, generate

    spec = ObjectSpec("hex_bar", count=6, kwargs={"size_mm": 4.0})
    data = generate(DatasetConfig(objects=[spec], randomise_spread=1.0, validation_fraction=0.0,
                                  poses=PoseRanges(force_n=(2.0, 15.0))), workers=1)
    idx = np.arange(len(data.readings))
    yaw, force, names = data.extra("pose")[idx, 2], data.extra("force_n")[idx], data.objects(idx)
    path = str(shipped_model())
    seen, recorded = [], ChipNoise.of

    def quiet(data, idx, provenance):  # the chips without noise: every draw is the clean field
        chips = recorded(data, idx, provenance)
        seen.append(chips)
        return dataclasses.replace(chips, noise_ut=np.zeros_like(chips.noise_ut))

    monkeypatch.setattr(ChipNoise, "of", staticmethod(quiet))
    rows = ablation.fresh_draws(ablation.head_axes([path]), path, data, idx, 3, yaw, force, names)
    drifting, tared = rows["fresh chip draws (mean of 3)"], rows["fresh chip draws, tared (mean of 3)"]
    model = load_reconstructor(path)
    still = dataclasses.replace(seen[0], noise_ut=np.zeros_like(seen[0].noise_ut),
                                drift_ut=np.zeros_like(seen[0].drift_ut))
    clean, _ = model.angle_head.axes(still.draw(np.random.default_rng(0)))  # the clean field, quantised
    clean_err = np.degrees(np.abs(wrap_axial(clean - yaw)))
    on_clean = float(np.mean(clean_err <= 5))
    # tared and noise-free: each of the 3 draws is the clean field, so its errors are the clean field's, every time
    assert tared["within_5"] == tared["within_5_range"][0] == tared["within_5_range"][1] == on_clean
    assert tared["median_deg"] == pytest.approx(float(np.median(clean_err)), abs=1e-9)
    assert drifting["median_deg"] != pytest.approx(float(np.median(clean_err)), abs=1e-6)  # drift moves the angles
    assert tared["presses"] == drifting["presses"] == len(idx) and tared["draws"] == 3
    # with drift the draws differ (the drift is drawn afresh), and the mean lies within their range
    assert seen[0].drift_ut.min() > 0
    assert drifting["within_5_range"][0] <= drifting["within_5"] <= drifting["within_5_range"][1]


def test_heads_read_as_one_average_their_doubled_angle_vectors(monkeypatch) -> None:
    import types

    import benchmarks.angle_ablation as ablation

    def fake(angle_deg: float, kappa: float):
        head = types.SimpleNamespace(axes=lambda fields: (np.full(len(fields), math.radians(angle_deg)),
                                                          np.full(len(fields), kappa)))
        return types.SimpleNamespace(angle_head=head, checked=lambda r: r)

    models = {"a": fake(10.0, 2.0), "b": fake(20.0, 2.0), "across": fake(100.0, 2.0), "wrap": fake(-85.0, 2.0),
              "near": fake(89.0, 2.0), "bare": types.SimpleNamespace(angle_head=None)}
    monkeypatch.setattr(ablation, "load_reconstructor", lambda path, threads=2: models[path])
    readings = np.zeros((3, 4, 4, 3))
    angle, kappa = ablation.head_axes(["a", "b"])(readings)
    assert np.allclose(np.degrees(angle), 15.0) and np.allclose(kappa, 2.0 * math.cos(math.radians(10.0)))
    # heads a quarter turn apart cancel: no concentration left
    _, kappa = ablation.head_axes(["a", "across"])(readings)
    assert np.allclose(kappa, 0.0, atol=1e-12)
    # axes either side of the +-90 deg wrap average across it, not through 0
    angle, _ = ablation.head_axes(["wrap", "near"])(readings)
    assert np.allclose(np.degrees(np.abs(angle)), 88.0)
    # one head is read as itself
    angle, kappa = ablation.head_axes(["b"])(readings)
    assert np.allclose(np.degrees(angle), 20.0) and np.allclose(kappa, 2.0)
    assert ablation.head_axes(["a", "bare"]) is None


def test_the_bound_differentiates_the_reading_as_recorded_less_the_sensors_own_baseline() -> None:
    # a recorded reading is the field less the drawn sensor's own unloaded reading, so a sensor parameter moves
    # it only through the press. Differentiating the absolute field instead would let the bound read the magnet's
    # strength and the chip gap off the baseline, which no estimator of a recorded reading sees.
    from benchmarks.angle_information import _information, shape_sizes
    from tactile_manip.sim.objects import IndenterPose
    from tactile_manip.sim.pair import SensorPair
    from tactile_manip.boards import load_board
    from tactile_manip.sim.params import for_board, with_values
    from tactile_manip.sim.shapes import make_indenter

    params = {"magnet.remanence_t": 0.04, "magnet.chip_gap_mm": 1.2, "layer.skin_modulus_kpa": 180.0}
    job = {"index": 0, "label": "hex_bar_4mm", "kind": "hex_bar", "kwargs": {"size_mm": 4.0}, "sensor_seed": 0,
           "params": params, "pose": [1.0, -0.5, 0.4, 0.0, 0.0], "force_n": 4.0, "saturated": [[[False] * 3] * 4] * 4}
    jac = np.asarray(_information(job)["jacobian"])
    assert jac.shape == (48, 1 + len(POSE_NUISANCES) + len(SENSOR_NUISANCES) + len(shape_sizes("hex_bar", {})))
    # the remanence's column against the recorded clean field of the press on two sensors either side
    rod, pose = make_indenter("hex_bar", size_mm=4.0), IndenterPose(1.0, -0.5, 0.4)
    clean = [SensorPair(with_values(for_board(load_board("supermag-4x4")), params | {"magnet.remanence_t": 0.04 * (1 + s)}), seed=0)
             .press(rod, pose, 4.0, np.random.default_rng(0), render_depth=False).field_clean_ut.ravel()
             for s in (0.02, -0.02)]
    column = jac[:, 1 + len(POSE_NUISANCES) + SENSOR_NUISANCES.index("magnet.remanence_t")]
    assert np.abs(column).max() > 100  # uT per T: the press moves with the magnet's strength
    np.testing.assert_allclose(column, (clean[0] - clean[1]) / (0.04 * 0.04), rtol=1e-3, atol=1e-2)
    # off the pad nothing touches: no parameter moves the recorded reading
    off = _information(job | {"pose": [60.0, 0.0, 0.4, 0.0, 0.0]})
    assert np.abs(np.asarray(off["jacobian"])).max() == 0.0
