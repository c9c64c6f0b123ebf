"""``import --labelled K``: a rig owner's handful of labelled presses. K training rows keep their labels, the
other training rows become the 'unlabelled' split with NaN targets and label columns, validation and test are
untouched, and whatever trains on the 'train' split sees exactly K presses."""

from __future__ import annotations

import numpy as np
import pytest
from checks import assert_one_line_error

from tactile_manip.cli import main
from tactile_manip.data import PairedDataset, from_probe_logs, load_dataset
from tactile_manip.errors import DatasetError

COLUMNS = ["time_s", "x_mm", "y_mm", "z_mm"]


def _logs(n: int = 200):
    rng = np.random.default_rng(0)
    t = 1000.0 + 0.02 * np.arange(n)
    sensor = np.column_stack([t, rng.normal(0, 50, (n, 15))])
    labels = np.column_stack([t + 0.001, np.arange(n, dtype=float), rng.uniform(-5, 5, n), np.full(n, 140.0)])
    return sensor, labels


def _import(labelled=None, seed=0) -> PairedDataset:
    sensor, labels = _logs()
    return from_probe_logs([sensor], [labels], targets=["x_mm", "y_mm"], label_columns=COLUMNS,
                           labelled=labelled, seed=seed)


def test_k_training_rows_keep_their_labels_and_the_rest_are_unlabelled_readings():
    full, few = _import(), _import(labelled=25, seed=3)
    counts = few.describe()["splits"]
    assert counts == {"train": 25, "val": 0, "test": 40, "unlabelled": 135}
    test = full.split == "test"
    np.testing.assert_array_equal(few.split[test], full.split[test])                   # test untouched
    np.testing.assert_array_equal(few.targets[test], full.targets[test])
    np.testing.assert_array_equal(few.readings, full.readings)                         # every reading stays
    kept = few.indices("train")
    np.testing.assert_array_equal(few.targets[kept], full.targets[kept])
    hidden = few.indices("unlabelled")
    assert np.isnan(few.targets[hidden]).all()
    for name in ("label_x_mm", "label_y_mm", "label_z_mm"):                            # no label leaks back
        assert np.isnan(few.extras[name][hidden]).all() and np.isfinite(few.extras[name][kept]).all()
    assert few.provenance["labelled"] == {"presses": 25, "seed": 3, "of_training_rows": 160}


def test_the_draw_follows_the_seed_and_zero_keeps_no_training_label():
    a, b, c = _import(labelled=25, seed=0), _import(labelled=25, seed=0), _import(labelled=25, seed=1)
    np.testing.assert_array_equal(a.indices("train"), b.indices("train"))
    assert not np.array_equal(a.indices("train"), c.indices("train"))
    none = _import(labelled=0)
    assert len(none.indices("train")) == 0 and len(none.indices("unlabelled")) == 160


@pytest.mark.parametrize("labelled", [161, -1, 2.5, True])
def test_more_labels_than_training_rows_are_refused(labelled):
    with pytest.raises(DatasetError, match=r"--labelled .*: keep labels on 0 to 160 presses"):
        _import(labelled=labelled)


def test_nan_targets_only_where_labels_were_held_back(tmp_path):
    few = _import(labelled=10)
    path = tmp_path / "few.npz"
    from tactile_manip.data import save_dataset
    save_dataset(path, few)
    assert load_dataset(path).fingerprint() == few.fingerprint()
    targets = few.targets.copy()
    targets[few.indices("test")[0], 0] = np.nan
    with pytest.raises(DatasetError, match="NaN or infinite"):
        PairedDataset(readings=few.readings, images=None, split=few.split, channels=few.channels, targets=targets,
                      target_names=few.target_names)


def test_the_cli_holds_back_labels_and_refuses_too_many_in_one_line(tmp_path, capsys):
    sensor, labels = _logs()
    np.savetxt(tmp_path / "sensor.csv", sensor, delimiter=",")
    np.savetxt(tmp_path / "states.csv", labels, delimiter=",")
    args = ["import", "--readings-csv", str(tmp_path / "sensor.csv"), "--labels-csv", str(tmp_path / "states.csv"),
            "--label-columns", ",".join(COLUMNS), "--targets", "x_mm,y_mm", "--board", "eflesh", "--seed", "1"]
    assert main([*args, "--labelled", "25", "--out", str(tmp_path / "few.npz")]) == 0
    printed = capsys.readouterr().out
    assert "(25 train / 0 val / 40 test, 135 more training presses without their labels (--labelled 25, seed 1))" \
        in printed
    assert load_dataset(tmp_path / "few.npz").describe()["splits"]["train"] == 25
    assert main([*args, "--labelled", "161", "--out", str(tmp_path / "many.npz")]) == 2
    assert_one_line_error(capsys.readouterr().err, "import", "--labelled 161: keep labels on 0 to 160 presses")
    assert not (tmp_path / "many.npz").exists()


def test_labelled_belongs_to_probe_logs(tmp_path, capsys):
    np.save(tmp_path / "r.npy", np.zeros((4, 4, 4, 3)))
    np.save(tmp_path / "i.npy", np.zeros((4, 8, 8)))
    assert main(["import", "--readings", str(tmp_path / "r.npy"), "--images", str(tmp_path / "i.npy"),
                 "--labelled", "2", "--out", str(tmp_path / "d.npz")]) == 2
    assert_one_line_error(capsys.readouterr().err, "import", "--labelled go with probe logs")


@pytest.mark.parametrize("labelled, counts", [(160, "(160 train / 0 val / 40 test, 0 more training presses"),
                                              (0, "(0 train / 0 val / 40 test, 160 more training presses")])
def test_the_ends_of_the_labelled_range_import_and_say_what_they_hold(labelled, counts, tmp_path, capsys):
    """Every training row labelled (no 'unlabelled' split at all), or none: both are inside the range, so both
    import and print their counts."""
    sensor, labels = _logs()
    np.savetxt(tmp_path / "sensor.csv", sensor, delimiter=",")
    np.savetxt(tmp_path / "states.csv", labels, delimiter=",")
    assert main(["import", "--readings-csv", str(tmp_path / "sensor.csv"), "--labels-csv",
                 str(tmp_path / "states.csv"), "--label-columns", ",".join(COLUMNS), "--targets", "x_mm,y_mm",
                 "--board", "eflesh", "--labelled", str(labelled), "--out", str(tmp_path / "d.npz")]) == 0
    out, err = capsys.readouterr()
    assert counts in out and "Traceback" not in err
    assert len(load_dataset(tmp_path / "d.npz").indices("train")) == labelled
