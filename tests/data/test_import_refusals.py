"""``tactile-manip import`` of probe logs gives no silently wrong dataset: duplicate column names, backwards or
non-finite times and values beyond any reading are refused (one line, exit 2, nothing written); duplicate
times and the frames a damaged recording lost are printed and kept in the dataset's provenance."""

from __future__ import annotations

import numpy as np
import pytest
from checks import assert_one_line_error

from tactile_manip.cli import main
from tactile_manip.data import from_probe_logs, load_dataset
from tactile_manip.errors import DatasetError

COLUMNS = "time_s,x_mm,y_mm,z_mm"


def _rig(folder, *, n: int = 100, header: str | None = None):
    """sensor.csv (time + 15 values at 50 Hz) and labels.csv (time, x, y, z at 25 Hz, x = row, y = 100 + row)."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    t = 1000.0 + 0.02 * np.arange(n)
    sensor = np.column_stack([t, rng.normal(0, 50, (n, 15))])
    k = np.arange(n // 2, dtype=float)
    labels = np.column_stack([1000.0 + 0.04 * k + 0.003, k, 100.0 + k, 140.0 + 0.01 * k])
    return sensor, labels, header


def _write(folder, sensor, labels, header=None):
    np.savetxt(folder / "sensor.csv", sensor, delimiter=",")
    np.savetxt(folder / "labels.csv", labels, delimiter=",", header=header or "", comments="")
    return folder / "sensor.csv", folder / "labels.csv"


def _refused(capsys, tmp_path, args, *needles) -> str:
    out = tmp_path / "d.npz"
    assert main(["import", *map(str, args), "--out", str(out)]) == 2
    line = assert_one_line_error(capsys.readouterr().err, "import", *needles)
    assert not out.exists()
    return line


def test_a_label_column_named_twice_is_refused_naming_it(tmp_path, capsys):
    sensor, labels, _ = _rig(tmp_path)
    s, lab = _write(tmp_path, sensor, labels)
    _refused(capsys, tmp_path, ["--readings-csv", s, "--labels-csv", lab, "--label-columns", "time_s,x_mm,x_mm,z_mm",
                                "--targets", "x_mm"], "--label-columns", "'x_mm'", "twice")


def test_a_header_naming_a_column_twice_is_refused_naming_it(tmp_path, capsys):
    sensor, labels, _ = _rig(tmp_path)
    s, lab = _write(tmp_path, sensor, labels, header="time_s,x_mm,x_mm,z_mm")
    _refused(capsys, tmp_path, ["--readings-csv", s, "--labels-csv", lab, "--targets", "x_mm"],
             str(lab), "'x_mm'", "twice")
    with pytest.raises(DatasetError, match="names the column 'x_mm' twice"):
        from_probe_logs([s], [lab], targets=["x_mm"])


def test_targets_named_twice_on_the_command_line_are_refused(tmp_path, capsys):
    sensor, labels, _ = _rig(tmp_path)
    s, lab = _write(tmp_path, sensor, labels)
    _refused(capsys, tmp_path, ["--readings-csv", s, "--labels-csv", lab, "--label-columns", COLUMNS,
                                "--targets", "x_mm,y_mm,x_mm"], "--targets", "'x_mm'", "twice")


@pytest.mark.parametrize("stream", ["sensor", "labels"])
def test_time_going_backwards_is_refused_with_the_row(tmp_path, capsys, stream):
    sensor, labels, _ = _rig(tmp_path)
    table = sensor if stream == "sensor" else labels
    table[[20, 21]] = table[[21, 20]]  # two rows swapped: row 22 (1-based) is earlier than row 21
    s, lab = _write(tmp_path, sensor, labels)
    line = _refused(capsys, tmp_path, ["--readings-csv", s, "--labels-csv", lab, "--label-columns", COLUMNS,
                                       "--targets", "x_mm"], "time goes backwards at row 22", "row 21")
    assert str(s if stream == "sensor" else lab) in line


@pytest.mark.parametrize("stream, value", [("sensor", np.nan), ("sensor", np.inf), ("labels", np.nan)])
def test_a_non_finite_time_is_refused_with_the_row(tmp_path, capsys, stream, value):
    sensor, labels, _ = _rig(tmp_path)
    (sensor if stream == "sensor" else labels)[7, 0] = value
    s, lab = _write(tmp_path, sensor, labels)
    _refused(capsys, tmp_path, ["--readings-csv", s, "--labels-csv", lab, "--label-columns", COLUMNS,
                                "--targets", "x_mm"], "row 8", f"time {value}", "finite time")


def test_duplicate_times_are_printed_and_kept_in_the_provenance(tmp_path, capsys):
    sensor, labels, _ = _rig(tmp_path)
    sensor[11, 0] = sensor[10, 0]
    sensor[31, 0] = sensor[30, 0]
    labels[5, 0] = labels[4, 0]
    s, lab = _write(tmp_path, sensor, labels)
    out = tmp_path / "d.npz"
    assert main(["import", "--readings-csv", str(s), "--labels-csv", str(lab), "--label-columns", COLUMNS,
                 "--targets", "x_mm", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "repeated times: 2 sensor rows (first at row 12), 1 label row (first at row 6)" in text
    run = load_dataset(out).provenance["runs"][0]
    assert run["repeated_reading_times"] == 2 and run["repeated_label_times"] == 1


def test_a_value_beyond_any_reading_names_the_row_and_column_not_nan(tmp_path, capsys):
    sensor, labels, _ = _rig(tmp_path)
    sensor[:, 4] = 1e300  # every row: the message used to say "every sensor row has a NaN"
    s, lab = _write(tmp_path, sensor, labels)
    line = _refused(capsys, tmp_path, ["--readings-csv", s, "--labels-csv", lab, "--label-columns", COLUMNS,
                                       "--targets", "x_mm"], "row 1, column 5", "1e+300", "too large", "float32")
    assert "NaN" not in line


def test_an_infinite_value_is_not_called_a_nan(tmp_path, capsys):
    sensor, labels, _ = _rig(tmp_path)
    sensor[:, 3] = np.inf
    s, lab = _write(tmp_path, sensor, labels)
    _refused(capsys, tmp_path, ["--readings-csv", s, "--labels-csv", lab, "--label-columns", COLUMNS,
                                "--targets", "x_mm"], "every sensor row has a NaN or infinite value",
             "row 1, column 4")


def _damaged_recording(tmp_path):
    from tactile_manip.sensors.recording import RecordingWriter
    from tactile_manip.wire.anyskin import pack_frame

    rng = np.random.default_rng(8)
    fields = rng.normal(0, 200, (60, 5, 3)).astype(np.float32)
    t = 50.0 + 0.02 * np.arange(60)
    header = {"wire_format": "anyskin", "layout": "anyskin-5",
              "chip": {"lsb_xy_ut": 0.15, "lsb_z_ut": 0.242, "saturation_counts": 32767}}
    path = tmp_path / "rig" / "r.tmrec"
    path.parent.mkdir()
    with RecordingWriter(path, header) as w:
        for ti, f in zip(t, fields):
            w.write_frame(float(ti), pack_frame(np.full(5, 25.0), f))
    data = bytearray(path.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 200] = bytes(200)  # a bad sector in the middle: two or three frames gone
    path.write_bytes(bytes(data))
    labels = tmp_path / "labels.csv"
    k = np.arange(30, dtype=float)
    np.savetxt(labels, np.column_stack([t[::2] + 0.001, k, k, k]), delimiter=",")
    return path, labels


def test_a_damaged_recording_prints_and_records_what_it_lost(tmp_path, capsys):
    from tactile_manip.sensors.recording import read_recording

    path, labels = _damaged_recording(tmp_path)
    rec = read_recording(path)
    assert rec.skipped_bytes > 200 and len(rec) < 60
    out = tmp_path / "d.npz"
    assert main(["import", "--readings-csv", str(path), "--labels-csv", str(labels), "--label-columns", COLUMNS,
                 "--targets", "x_mm", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    lost = 60 - len(rec)
    assert (f"  recording {path}: {rec.skipped_bytes} damaged bytes skipped in 1 place (about {lost} frames, "
            f"at byte {rec.damage[0][0]})") in text
    info = load_dataset(out).provenance["runs"][0]["readings"]
    assert info["skipped_bytes"] == rec.skipped_bytes and info["damaged_places"] == 1
    assert info["frames_lost"] == lost and info["truncated_bytes"] == 0


def test_array_values_beyond_float32_are_refused_not_stored_as_inf(tmp_path, capsys):
    readings = np.zeros((6, 4, 4, 3))
    readings[2, 1, 1, 2] = 1e300
    np.save(tmp_path / "r.npy", readings)
    np.save(tmp_path / "i.npy", np.zeros((6, 8, 8), np.float32))
    out = tmp_path / "d.npz"
    assert main(["import", "--readings", str(tmp_path / "r.npy"), "--images", str(tmp_path / "i.npy"),
                 "--out", str(out)]) == 2
    assert_one_line_error(capsys.readouterr().err, "import", "readings: 1 values beyond float32's range",
                          "(2, 1, 1, 2)")
    assert not out.exists()


@pytest.mark.parametrize("option, value, needles", [
    ("--time-offset-s", "nan", ("--time-offset-s", "finite", "nan")),
    ("--tolerance-s", "inf", ("--tolerance-s", "(0, 10] s", "inf")),
    ("--tolerance-s", "0", ("--tolerance-s", "(0, 10] s")),
    ("--baseline-s", "nan", ("--baseline-s", "positive", "nan")),
    ("--baseline-s", "-1", ("--baseline-s", "positive")),
    ("--baseline-s", "1e9", ("a baseline of the first 1e+09 s", "100% of the run", "free pad at the start")),
])
def test_seconds_that_cannot_be_meant_are_refused_naming_the_option(option, value, needles, tmp_path, capsys):
    """A NaN clock shift is named as such (not blamed on the tolerance); an infinite tolerance would pair every
    row with a label however far; a baseline over the whole run would subtract its presses."""
    sensor, labels, _ = _rig(tmp_path)
    s, lab = _write(tmp_path, sensor, labels)
    _refused(capsys, tmp_path, ["--readings-csv", s, "--labels-csv", lab, "--label-columns", COLUMNS,
                                "--targets", "x_mm", option, value], *needles)


def test_complex_and_boolean_values_are_not_read_as_numbers():
    from tactile_manip.checks import check_array

    for bad in (np.ones((4, 4, 3), complex), np.ones((4, 4, 3), bool)):
        with pytest.raises(ValueError, match=f"reading: expected real numbers, got dtype {bad.dtype}"):
            check_array("reading", bad, shape=(4, 4, 3))
    assert check_array("reading", np.ones((4, 4, 3), np.int16), shape=(4, 4, 3)).dtype == np.float64
