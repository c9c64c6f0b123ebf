"""Probe logs -> labelled presses: matching by time, what is dropped and counted, units, contact conditions,
chronological and held-out-run splits, recordings in place of the sensor CSV."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_manip.data import from_probe_logs, load_dataset, save_dataset
from tactile_manip.data.streams import Comparison, parse_comparison
from tactile_manip.errors import DatasetError
from tactile_manip.boards import load_board

LABELS = ["time_s", "x_mm", "y_mm", "z_mm", "force_gf"]


def _rig(rng, *, t0: float = 1000.0, seconds: float = 20.0, sensor_hz: float = 50.0, label_hz: float = 25.0):
    """A rig's two streams: labels at ``label_hz`` (every 4th load-cell value missing, -1), sensor rows at
    ``sensor_hz`` whose 15 values are a known function of the label nearest in time."""
    t_l = t0 + np.arange(0.0, seconds, 1.0 / label_hz) + 0.002
    n_l = len(t_l)
    labels = np.column_stack([t_l, rng.uniform(-10, 10, n_l), rng.uniform(-10, 10, n_l),
                              rng.uniform(140, 146, n_l), rng.uniform(0, 1500, n_l)])
    labels[::4, 4] = -1.0
    t_r = t0 + np.arange(0.0, seconds, 1.0 / sensor_hz)
    values = rng.normal(0, 50, (len(t_r), 15))
    return np.column_stack([t_r, values]), labels


def _nearest_usable(labels: np.ndarray, t: np.ndarray, column: int, *, force_used: bool = False) -> np.ndarray:
    """Column ``column`` of the label row nearest each time; with the force used, among rows that have one."""
    usable = labels[labels[:, 4] != -1] if force_used else labels
    return usable[np.abs(usable[:, 0][None, :] - t[:, None]).argmin(axis=1), column]


def test_each_sensor_row_takes_the_nearest_label_row_that_has_a_reading():
    rng = np.random.default_rng(0)
    sensor, labels = _rig(rng)
    data = from_probe_logs([sensor], [labels], label_columns=LABELS, targets=["x_mm", "force_n"], missing=-1)
    run = data.provenance["runs"][0]
    assert run["missing_labels"] == int(np.sum(labels[:, 4] == -1)) and run["unmatched"] == 0
    assert len(data) == len(sensor) and data.target_names == ("x_mm", "force_n")
    # one label row per sample: the nearest with a reading in every used column (x_mm and force_gf)
    np.testing.assert_allclose(data.target("x_mm"), _nearest_usable(labels, sensor[:, 0], 1, force_used=True),
                               rtol=1e-6)
    np.testing.assert_allclose(data.target("force_n"),
                               _nearest_usable(labels, sensor[:, 0], 4, force_used=True) * 9.80665e-3, rtol=1e-5)
    np.testing.assert_allclose(data.extra("time_s"), sensor[:, 0])
    # chip-major values land on the layout's cells, turned into pad axes
    expected = load_board("anyskin-5").readings_from_chips(sensor[:, 1:].reshape(-1, 5, 3))
    np.testing.assert_array_equal(data.readings, expected)
    assert data.readings.shape == (len(sensor), 3, 3, 3) and data.provenance["layout"] == "anyskin-5"
    assert not data.readings[:, 0, 0].any()  # a corner no chip feeds


def test_missing_applies_only_to_the_columns_used():
    rng = np.random.default_rng(1)
    sensor, labels = _rig(rng)
    labels[5, 1] = -1.0  # x_mm of -1 is a stage position, not "no reading", when only force is used
    data = from_probe_logs([sensor], [labels], label_columns=LABELS, targets=["force_n"], missing=-1)
    assert data.provenance["runs"][0]["missing_labels"] == int(np.sum(labels[:, 4] == -1))
    per_column = from_probe_logs([sensor], [labels], label_columns=LABELS, targets=["x_mm", "force_n"],
                                 missing={"force_gf": -1})
    assert per_column.provenance["runs"][0]["missing_labels"] == int(np.sum(labels[:, 4] == -1))
    with pytest.raises(DatasetError, match=r"missing values given for \['load_gf'\]"):
        from_probe_logs([sensor], [labels], label_columns=LABELS, targets=["x_mm"], missing={"load_gf": -1})


def test_unmatched_rows_nan_rows_and_gaps_are_dropped_and_counted():
    rng = np.random.default_rng(2)
    sensor, labels = _rig(rng)
    gap = (labels[:, 0] > 1005.0) & (labels[:, 0] < 1008.0)  # 3 s without labels
    labels = labels[~gap]
    sensor[[3, 7], 5] = np.nan
    data = from_probe_logs([sensor], [labels], label_columns=LABELS, targets=["x_mm"])
    run = data.provenance["runs"][0]
    tol = run["tolerance_s"]
    assert tol == pytest.approx(3 * 0.04)
    t_gap_lo, t_gap_hi = labels[labels[:, 0] < 1005.0, 0].max(), labels[labels[:, 0] > 1008.0, 0].min()
    t = sensor[:, 0]
    far = (t - t_gap_lo > tol) & (t_gap_hi - t > tol)
    assert run["unmatched"] == int(far.sum()) > 0 and run["nan_readings"] == 2
    assert run["label_gaps"]["count"] == 1 and run["label_gaps"]["longest_s"] == pytest.approx(t_gap_hi - t_gap_lo)
    assert run["reading_gaps"]["count"] == 0
    assert len(data) == len(sensor) - 2 - int(far.sum()) == run["samples"]


def test_contact_keeps_the_rows_that_satisfy_it_or_becomes_the_in_contact_target():
    rng = np.random.default_rng(3)
    sensor, labels = _rig(rng)
    z = _nearest_usable(labels, sensor[:, 0], 3)
    kept = from_probe_logs([sensor], [labels], label_columns=LABELS, contact="z_mm < 145.1", targets=["x_mm", "y_mm"])
    assert len(kept) == int(np.sum(z < 145.1)) and kept.provenance["runs"][0]["non_contact"] == int(np.sum(z >= 145.1))
    assert (kept.extra("label_z_mm") < 145.1).all() and kept.provenance["contact_use"] == "filter"
    flagged = from_probe_logs([sensor], [labels], label_columns=LABELS, contact="z_mm < 145.1",
                              targets=["x_mm", "in_contact"])
    assert len(flagged) == len(sensor)
    np.testing.assert_array_equal(flagged.target("in_contact"), (z < 145.1).astype(np.float32))
    with pytest.raises(DatasetError, match="'in_contact' needs a contact condition"):
        from_probe_logs([sensor], [labels], label_columns=LABELS, targets=["in_contact"])


def test_chronological_split_is_the_first_80_percent_of_each_runs_kept_rows_in_time_order():
    rng = np.random.default_rng(4)
    (s1, l1), (s2, l2) = _rig(rng), _rig(rng, t0=5000.0, seconds=10.0)
    order = rng.permutation(len(s1))  # rows written out of order would take other rows' labels: refused
    with pytest.raises(DatasetError, match="run a readings: time goes backwards at row"):
        from_probe_logs([s1[order], s2], [l1, l2], label_columns=LABELS, targets=["x_mm"], run_names=["a", "b"])
    data = from_probe_logs([s1, s2], [l1, l2], label_columns=LABELS, contact="z_mm < 145.1",
                           targets=["x_mm"], run_names=["a", "b"])
    for g, name in enumerate(["a", "b"]):
        idx = np.flatnonzero(data.groups == g)
        n = len(idx)
        assert data.provenance["runs"][g]["name"] == name
        assert np.all(np.diff(data.extra("time_s")[idx]) > 0)
        assert data.split[idx].tolist() == ["train"] * int(0.8 * n) + ["test"] * (n - int(0.8 * n))
    val = from_probe_logs([s1], [l1], label_columns=LABELS, targets=["x_mm"], val_fraction=0.1)
    n = len(val)
    assert val.split.tolist() == ["train"] * (int(0.8 * n) - int(0.1 * n)) + ["val"] * int(0.1 * n) + \
        ["test"] * (n - int(0.8 * n))


def test_held_out_run_split_by_name_or_index(tmp_path):
    rng = np.random.default_rng(5)
    (s1, l1), (s2, l2) = _rig(rng), _rig(rng, t0=5000.0)
    kw = dict(label_columns=LABELS, targets=["x_mm"], split="held_out_run", run_names=["a", "b"])
    by_name = from_probe_logs([s1, s2], [l1, l2], held_out_run="b", **kw)
    by_index = from_probe_logs([s1, s2], [l1, l2], held_out_run=1, **kw)
    np.testing.assert_array_equal(by_name.split, by_index.split)
    assert set(by_name.split[by_name.groups == 1]) == {"test"} and set(by_name.split[by_name.groups == 0]) == {"train"}
    assert by_name.provenance["held_out_run"] == "b"
    with pytest.raises(DatasetError, match="held-out run 'c' is not a run"):
        from_probe_logs([s1, s2], [l1, l2], held_out_run="c", **kw)
    back = load_dataset(save_dataset(tmp_path / "d", by_name))
    assert back.provenance["runs"][1]["name"] == "b" and back.target_names == ("x_mm",)


def test_linear_matching_interpolates_targets_between_usable_rows():
    t_l = np.array([0.0, 0.1, 0.2, 0.3])
    labels = {"time_s": t_l, "force_gf": np.array([0.0, -1.0, 200.0, 300.0])}
    sensor = (np.array([0.05, 0.1, 0.25]), np.zeros((3, 5, 3)))
    near = from_probe_logs([sensor], [labels], targets=["force_n"], missing=-1)
    lin = from_probe_logs([sensor], [labels], targets=["force_n"], missing=-1, match="linear")
    g = 9.80665e-3
    np.testing.assert_allclose(near.target("force_n"), np.array([0.0, 0.0, 200.0]) * g, atol=1e-6)
    np.testing.assert_allclose(lin.target("force_n"), np.array([50.0, 100.0, 250.0]) * g, rtol=1e-5)
    assert lin.provenance["runs"][0]["interpolated"] == 3


def test_streams_on_different_clocks_are_refused():
    rng = np.random.default_rng(6)
    sensor, labels = _rig(rng)
    sensor[:, 0] -= 999.0  # a monotonic clock against Unix time
    with pytest.raises(DatasetError, match="never overlap"):
        from_probe_logs([sensor], [labels], label_columns=LABELS, targets=["x_mm"])
    ok = from_probe_logs([sensor], [labels], label_columns=LABELS, targets=["x_mm"], time_offset_s=999.0)
    assert len(ok) == len(sensor)


@pytest.mark.parametrize("kwargs, problem", [
    (dict(targets=["depth_mm"]), "target 'depth_mm' is not among the label columns"),
    (dict(targets=["x_mm"], contact="q_mm < 1"), "column 'q_mm' is not among the label columns"),
    (dict(targets=["x_mm"], label_columns=LABELS[:4]), "5 columns, but the label columns name 4"),
    (dict(targets=["x_mm"], label_columns=["t"] + LABELS[1:]), "no 'time_s' column"),
    (dict(targets=["x_mm"], layout="supermag-4x4"), "16 columns, expected 49"),
    (dict(targets=["x_mm"], layout="reskin"), "unknown board 'reskin'"),
    (dict(targets=["x_mm"], split="random"), "split must be one of chronological, held_out_run"),
])
def test_bad_inputs_are_one_error_naming_the_problem(kwargs, problem):
    rng = np.random.default_rng(7)
    sensor, labels = _rig(rng)
    kwargs.setdefault("label_columns", LABELS)
    with pytest.raises(DatasetError, match=problem):
        from_probe_logs([sensor], [labels], **kwargs)


@pytest.mark.parametrize("text, parsed", [
    ("z_mm < 145.1", Comparison("z_mm", "<", 145.1)), ("force_gf>=-1e2", Comparison("force_gf", ">=", -100.0)),
    ("  x_mm != .5 ", Comparison("x_mm", "!=", 0.5)), ("z_mm==145", Comparison("z_mm", "==", 145.0)),
])
def test_one_comparison_parses(text, parsed):
    assert parse_comparison(text) == parsed


@pytest.mark.parametrize("text", ["z_mm < 145.1 and x_mm > 0", "z_mm < 145.1 < 150", "145.1 > z_mm", "z_mm <",
                                  "z_mm < y_mm", "__import__('os').system('true')", "z_mm = 3", "z_mm < 1;", ""])
def test_anything_but_one_comparison_is_refused_naming_it(text):
    with pytest.raises(DatasetError, match="is not one comparison NAME OP NUMBER") as e:
        parse_comparison(text)
    assert repr(text) in str(e.value)


def test_a_recording_works_in_place_of_the_sensor_csv(tmp_path):
    from tactile_manip.sensors.recording import RecordingWriter
    from tactile_manip.wire.anyskin import pack_frame

    rng = np.random.default_rng(8)
    fields = rng.normal(0, 200, (40, 5, 3)).astype(np.float32)
    t = 50.0 + 0.02 * np.arange(40)
    header = {"wire_format": "anyskin", "layout": "anyskin-5",
              "chip": {"lsb_xy_ut": 0.15, "lsb_z_ut": 0.242, "saturation_counts": 32767}}
    with RecordingWriter(tmp_path / "r.tmrec", header) as w:
        for ti, f in zip(t, fields):
            w.write_frame(float(ti), pack_frame(np.full(5, 25.0), f))
    labels = {"time_s": t[::2] + 0.001, "x_mm": np.arange(20.0)}
    data = from_probe_logs([tmp_path / "r.tmrec"], [labels], targets=["x_mm"], baseline_s=0.1)
    assert len(data) == 40 and data.provenance["runs"][0]["readings"]["kind"] == "recording"
    raw = load_board("anyskin-5").readings_from_chips(fields)
    np.testing.assert_allclose(data.readings, raw - raw[t <= t[0] + 0.1].mean(axis=0), atol=1e-3)
    with pytest.raises(DatasetError, match="recorded with layout anyskin-5, not supermag-4x4"):
        from_probe_logs([tmp_path / "r.tmrec"], [labels], targets=["x_mm"], layout="supermag-4x4")
