"""``tactile-manip import`` of probe logs: the commands a user types, on synthetic logs and on the two real
eFlesh runs; every bad input is one line, exit 2, nothing written."""

from __future__ import annotations

import numpy as np
import pytest
from checks import assert_one_line_error

from tactile_manip.cli import main
from tactile_manip.data import load_dataset

SPATIAL = "spatial_20250316_155729"
NORMAL = "normal_20250401_014340"


def _write_rig(folder, rng, *, t0: float = 1000.0, n: int = 200, nan_rows=(), chips: int = 5):
    """sensor.csv (time + 3 * chips values at 50 Hz) and states.csv (time, x, y, z, force_gf at 25 Hz)."""
    folder.mkdir(parents=True, exist_ok=True)
    t = t0 + 0.02 * np.arange(n)
    sensor = np.column_stack([t, rng.normal(0, 50, (n, 3 * chips))])
    sensor[list(nan_rows), 2] = np.nan
    t_l = t0 + 0.04 * np.arange(n // 2) + 0.003
    force = rng.uniform(0, 1000, n // 2)
    force[1::2] = -1
    states = np.column_stack([t_l, rng.uniform(0, 30, n // 2), rng.uniform(0, 30, n // 2),
                              rng.uniform(141, 146, n // 2), force])
    np.savetxt(folder / "sensor.csv", sensor, delimiter=",")
    np.savetxt(folder / "states.csv", states, delimiter=",")
    return folder / "sensor.csv", folder / "states.csv"


def _import(sensor, states, out, *extra) -> int:
    return main(["import", "--readings-csv", str(sensor), "--labels-csv", str(states),
                 "--label-columns", "time_s,x_mm,y_mm,z_mm,force_gf", "--out", str(out), *extra])


def test_two_runs_with_nan_rows_print_a_summary_per_run(tmp_path, capsys):
    rng = np.random.default_rng(0)
    s1, l1 = _write_rig(tmp_path / "run_a", rng, nan_rows=(4, 9, 10))
    s2, l2 = _write_rig(tmp_path / "run_b", rng, t0=9000.0)
    out = tmp_path / "d.npz"
    assert main(["import", "--readings-csv", str(s1), "--labels-csv", str(l1), "--readings-csv", str(s2),
                 "--labels-csv", str(l2), "--label-columns", "time_s,x_mm,y_mm,z_mm,force_gf", "--missing", "-1",
                 "--contact", "z_mm < 145.1", "--targets", "x_mm,y_mm,force_n", "--layout", "anyskin-5",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "run run_a: 200 sensor rows, 100 label rows (50 without a reading, not matched)" in text
    assert "NaN readings skipped 3" in text and "run run_b: 200 sensor rows" in text
    data = load_dataset(out)
    assert data.target_names == ("x_mm", "y_mm", "force_n") and not data.has_images
    assert sorted(set(data.groups.tolist())) == [0, 1] and (data.extra("label_z_mm") < 145.1).all()
    runs = data.provenance["runs"]
    assert [r["name"] for r in runs] == ["run_a", "run_b"] and runs[0]["nan_readings"] == 3
    assert sum(r["samples"] for r in runs) == len(data) and f"wrote {out}: {len(data)} labelled presses" in text
    held = tmp_path / "held.npz"
    assert main(["import", "--readings-csv", str(s1), "--labels-csv", str(l1), "--readings-csv", str(s2),
                 "--labels-csv", str(l2), "--label-columns", "time_s,x_mm,y_mm,z_mm,force_gf",
                 "--targets", "x_mm", "--split", "held-out-run", "--held-out-run", "run_a", "--out", str(held)]) == 0
    h = load_dataset(held)
    assert set(h.split[h.groups == 0]) == {"test"} and set(h.split[h.groups == 1]) == {"train"}


def _bad_cases(tmp_path, rng):
    sensor, states = _write_rig(tmp_path / "ok", rng)
    other_clock, _ = _write_rig(tmp_path / "mono", rng, t0=12.0)
    narrow, _ = _write_rig(tmp_path / "narrow", rng, chips=4)
    not_numpy = tmp_path / "readings.npy"
    not_numpy.write_text("1.0,2.0\n")
    cols = "time_s,x_mm,y_mm,z_mm,force_gf"
    base = ["--label-columns", cols]
    return [
        (["--readings-csv", other_clock, "--labels-csv", states, *base, "--targets", "x_mm"], "never overlap"),
        (["--readings-csv", sensor, "--labels-csv", states, "--label-columns", "time_s,x_mm,y_mm,z_mm,load",
          "--targets", "force_n"], "target 'force_n' is not among the label columns time_s,x_mm,y_mm,z_mm,load"),
        (["--readings-csv", narrow, "--labels-csv", states, *base, "--targets", "x_mm"],
         "13 columns, expected 16: time (s), then x, y, z of each of the 5 chips of layout anyskin-5"),
        (["--readings-csv", sensor, "--labels-csv", states, "--label-columns", "time_s,x_mm,y_mm,z_mm",
          "--targets", "x_mm"], "5 columns, but the label columns name 4"),
        (["--readings-csv", sensor, "--labels-csv", states, *base, "--targets", "x_mm", "--contact",
          "z_mm < 145.1 or x_mm > 3"], "'z_mm < 145.1 or x_mm > 3' is not one comparison"),
        (["--readings-csv", sensor, "--labels-csv", states, *base, "--targets", "x_mm", "--contact", "z_mm"],
         "'z_mm' is not one comparison"),
        (["--readings", not_numpy, "--images", not_numpy], "not a numpy file"),
        (["--readings-csv", sensor, *base, "--targets", "x_mm"], "one --labels-csv per --readings-csv"),
        (["--readings-csv", sensor, "--labels-csv", states, *base], "--targets is required"),
        (["--readings-csv", sensor, "--labels-csv", states, *base, "--targets", "x_mm", "--missing", "force=x"],
         "--missing: expected a number or COLUMN=NUMBER"),
    ]


def test_bad_input_is_one_line_exit_2_and_nothing_written(tmp_path, capsys):
    rng = np.random.default_rng(1)
    out = tmp_path / "d.npz"
    for args, problem in _bad_cases(tmp_path, rng):
        assert main(["import", *map(str, args), "--out", str(out)]) == 2, problem
        assert_one_line_error(capsys.readouterr().err, "import", problem)
        assert not out.exists() and not list(tmp_path.glob("*.partial"))


def test_a_ragged_csv_names_the_file_and_row(tmp_path, capsys):
    rng = np.random.default_rng(2)
    sensor, states = _write_rig(tmp_path, rng)
    lines = sensor.read_text().splitlines()
    lines[7] = ",".join(lines[7].split(",")[:-1])
    sensor.write_text("\n".join(lines) + "\n")
    assert _import(sensor, states, tmp_path / "d.npz", "--targets", "x_mm") == 2
    assert_one_line_error(capsys.readouterr().err, "import",
                          f"readings {sensor}: the number of columns changed from 16 to 15 at row 8")


def test_a_header_row_names_the_label_columns(tmp_path, capsys):
    rng = np.random.default_rng(3)
    sensor, states = _write_rig(tmp_path, rng)
    states.write_text("time_s,x_mm,y_mm,z_mm,force_gf\n" + states.read_text())
    out = tmp_path / "d.npz"
    assert main(["import", "--readings-csv", str(sensor), "--labels-csv", str(states), "--targets", "force_n",
                 "--missing", "force_gf=-1", "--out", str(out)]) == 0
    assert load_dataset(out).target_names == ("force_n",)


# --- the real eFlesh runs, imported with the commands docs/contact.md gives ---------------------------------
def test_eflesh_spatial_run(eflesh_dir, tmp_path, capsys):
    run = eflesh_dir / SPATIAL
    out = tmp_path / "spatial.npz"
    assert main(["import", "--readings-csv", str(run / "sensor_post_baselines.csv"), "--labels-csv",
                 str(run / "states.csv"), "--label-columns", "time_s,x_mm,y_mm,z_mm", "--contact", "z_mm < 145.1",
                 "--targets", "x_mm,y_mm", "--layout", "anyskin-5", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"run {SPATIAL}: 4805 sensor rows, 4805 label rows (0 without a reading, not matched)" in text
    data = load_dataset(out)
    r = data.provenance["runs"][0]
    assert (r["unmatched"], r["nan_readings"], r["non_contact"], r["samples"]) == (0, 0, 0, 4805)
    assert r["median_match_dt_s"] < 0.005  # sensor row i and state row i are about 1.6 ms apart
    assert (r["train"], r["val"], r["test"]) == (3844, 0, 961)
    x, y = data.target("x_mm"), data.target("y_mm")
    assert len(np.unique(np.rint(x))) == len(np.unique(np.rint(y))) == 31  # the 31 x 31 grid at 1 mm pitch
    assert data.readings.shape == (4805, 3, 3, 3) and data.provenance["layout"] == "anyskin-5"
    np.testing.assert_allclose(data.readings[0, 1, 1, 2], 216.83203, rtol=1e-6)  # chip 1 (centre) z, row 1


def test_eflesh_normal_force_run(eflesh_dir, tmp_path, capsys):
    run = eflesh_dir / NORMAL
    out = tmp_path / "normal.npz"
    assert main(["import", "--readings-csv", str(run / "sensor_post_baselines.csv"), "--labels-csv",
                 str(run / "states.csv"), "--label-columns", "time_s,x_mm,y_mm,z_mm,force_gf", "--missing", "-1",
                 "--targets", "force_n", "--layout", "anyskin-5", "--out", str(out)]) == 0
    data = load_dataset(out)
    r = data.provenance["runs"][0]
    # 1740 load-cell rows are -1 (no reading): every sensor row takes the nearest row that has one
    assert (r["missing_labels"], r["unmatched"], r["samples"]) == (1740, 0, 3600)
    assert (r["train"], r["val"], r["test"]) == (2880, 0, 720)
    assert r["label_gaps"]["count"] == 19  # pauses of about 1.1 s in both streams
    f = data.target("force_n")
    assert f.min() == 0.0 and f.max() == pytest.approx(3482.78 * 9.80665e-3, rel=1e-5)
    assert "non_contact" not in r  # no contact condition: rows at 0 N stay, as in the published protocol
