"""Property-based fuzzing of what users hand the importer: probe-rig CSV logs of any shape and content.

The invariants, for every generated input: ``tactile-manip import`` either writes a dataset and exits 0, or
prints one error line and exits 2 having written nothing; never a traceback. Examples are derandomised and
bounded in number, so a run takes seconds and repeats exactly.
"""

from __future__ import annotations

import math
import os

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tactile_manip.cli import main

FUZZ = settings(max_examples=int(os.environ.get("TACTILE_MANIP_FUZZ_EXAMPLES", "80")), derandomize=True, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

_NUMBERS = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=32),
                     st.integers(min_value=-10**6, max_value=10**6),
                     st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -1.0, 1e30]))
_CELLS = st.one_of(_NUMBERS.map(repr), st.sampled_from(["", "x", "nan", "1,2", " ", "1e400", "0x10", "--"]))


def _csv(rows: list[list[str]]) -> str:
    return "".join(",".join(row) + "\n" for row in rows)


@st.composite
def _logs(draw):
    """A sensor log (time + 15 values, the five-chip board) and a label log (time, x, y), each mostly well formed
    with a few damaged cells, rows or headers."""
    n = draw(st.integers(min_value=0, max_value=40))
    t0 = draw(st.floats(min_value=-1e3, max_value=1e6, allow_nan=False))
    step = draw(st.sampled_from([0.008, 0.02, 0.0, -0.01]))
    width = draw(st.sampled_from([16, 16, 16, 15, 17, 1]))
    sensor = [[repr(t0 + i * step)] + [repr(draw(st.floats(-500, 500, allow_nan=False))) for _ in range(width - 1)]
              for i in range(n)]
    labels = [[repr(t0 + 0.04 * i), repr(float(i)), repr(float(-i))] for i in range(max(n // 2, 0))]
    for rows in (sensor, labels):
        for _ in range(draw(st.integers(min_value=0, max_value=3))):
            if rows and rows[0]:
                i = draw(st.integers(0, len(rows) - 1))
                j = draw(st.integers(0, len(rows[i]) - 1))
                rows[i][j] = draw(_CELLS)
    header = draw(st.sampled_from(["", "time_s,x_mm,y_mm\n", "time_s,x_mm,x_mm\n", "a,b\n", "\ufefftime_s,x_mm,y_mm\n"]))
    return _csv(sensor), header + _csv(labels)


@FUZZ
@given(logs=_logs(), baseline=st.sampled_from([None, "0.1", "nan", "1e9"]))
def test_import_of_any_probe_log_is_a_dataset_or_one_error_line(logs, baseline, tmp_path_factory, capsys):
    folder = tmp_path_factory.mktemp("fuzz")
    sensor, labels = logs
    (folder / "sensor.csv").write_text(sensor)
    (folder / "labels.csv").write_text(labels)
    out = folder / "d.npz"
    args = ["import", "--readings-csv", str(folder / "sensor.csv"), "--labels-csv", str(folder / "labels.csv"),
            "--label-columns", "time_s,x_mm,y_mm", "--targets", "x_mm,y_mm", "--board", "anyskin-5",
            "--out", str(out)]
    if baseline is not None:
        args += ["--baseline-s", baseline]
    capsys.readouterr()
    status = main(args)
    err = capsys.readouterr().err
    assert "Traceback" not in err
    if status == 0:
        assert out.is_file()
    else:
        assert status == 2, err
        lines = [line for line in err.splitlines() if line.strip()]
        assert lines and lines[-1].startswith("tactile-manip import: error: "), err
        assert sorted(p.name for p in folder.iterdir()) == ["labels.csv", "sensor.csv"]  # nothing written
