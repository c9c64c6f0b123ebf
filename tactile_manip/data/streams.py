"""The two streams of a probe log, read from files, and the contact condition on its labels.

A probe rig writes a timestamped sensor stream (time s, then x, y, z of each chip in firmware order, uT) and
a timestamped label stream (time s, then the stage's and load cell's columns). :func:`read_csv_table` reads
either as a float64 array (a first line that is not numbers is a header, and its names are returned);
:func:`read_reading_stream` also reads a ``tactile-manip record`` file (.tmrec) in place of the sensor CSV.
:func:`parse_comparison` parses a ``--contact`` condition like ``"z_mm < 145.1"`` without ``eval``.
"""

from __future__ import annotations

import operator
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tactile_manip.errors import DatasetError

RECORDING_SUFFIX = ".tmrec"
_OPS: dict[str, Callable[[np.ndarray, float], np.ndarray]] = {
    "<=": operator.le, ">=": operator.ge, "==": operator.eq, "!=": operator.ne, "<": operator.lt, ">": operator.gt}
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_COMPARISON = re.compile(rf"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(<=|>=|==|!=|<|>)\s*({_NUMBER})\s*$")


@dataclass(frozen=True)
class Comparison:
    """One comparison ``column OP value`` on a label column (OP one of < <= > >= == !=)."""

    column: str
    op: str
    value: float

    def __call__(self, values: np.ndarray) -> np.ndarray:
        """(n,) bool: which of ``values`` satisfy the comparison."""
        return _OPS[self.op](np.asarray(values, dtype=np.float64), self.value)

    def __str__(self) -> str:
        return f"{self.column} {self.op} {self.value:g}"


def parse_comparison(expression: str) -> Comparison:
    """``"z_mm < 145.1"`` -> Comparison("z_mm", "<", 145.1): exactly one ``NAME OP NUMBER``, nothing evaluated.

    Raises:
        DatasetError: anything else (two comparisons, a function call, a name on both sides), naming it.
    """
    m = _COMPARISON.match(str(expression))
    if m is None:
        raise DatasetError(f"contact condition {expression!r} is not one comparison NAME OP NUMBER with OP one of "
                           f"< <= > >= == != (e.g. \"z_mm < 145.1\")")
    return Comparison(column=m.group(1), op=m.group(2), value=float(m.group(3)))


def read_csv_table(path: str | Path, *, what: str) -> tuple[np.ndarray, list[str] | None]:
    """A comma-separated file of numbers -> (rows, columns) float64 and its header names (None without one).

    ``nan`` fields are kept (the caller skips and counts them); an empty or text field is an error.

    Raises:
        DatasetError: missing file, rows of different lengths, a field that is not a number, no rows.
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{what} {path}: no such file" if not path.is_dir() else f"{what} {path} is a directory")
    with path.open("r", errors="replace") as f:
        first = f.readline()
    header = None
    fields = [x.strip() for x in first.split(",")]
    if fields and fields[0] and not _is_number(fields[0]):
        header = fields
    try:
        table = np.loadtxt(path, delimiter=",", dtype=np.float64, ndmin=2, skiprows=1 if header else 0)
    except ValueError as e:
        raise DatasetError(f"{what} {path}: {str(e).splitlines()[0].split('; use')[0]}") from None
    if table.shape[0] == 0:
        raise DatasetError(f"{what} {path}: no rows")
    return table, header


def read_reading_stream(path: str | Path) -> tuple[np.ndarray, np.ndarray, dict]:
    """Sensor stream from a CSV (time s, then per-chip x, y, z) or a recording (.tmrec).

    Returns:
        (t_s (M,), values, info): values (M, V) from a CSV, or (M, R, C, 3) raw fields in uT on the
        recording's layout; info names the source, and for a recording its layout and clock.
    """
    path = Path(path)
    if path.suffix == RECORDING_SUFFIX:
        from tactile_manip.errors import RecordingError
        from tactile_manip.sensors.recording import read_recording

        try:
            rec = read_recording(path)
        except RecordingError as e:
            raise DatasetError(str(e)) from e
        if not len(rec):
            raise DatasetError(f"recording {path}: no frames")
        info = {"source": str(path), "kind": "recording", "layout": rec.layout_name,
                "clock": "time.monotonic() of the recording host"}
        return rec.t_host_s, rec.field_raw_ut(), info
    table, _ = read_csv_table(path, what="readings")
    return table[:, 0], table[:, 1:], {"source": str(path), "kind": "csv", "columns": int(table.shape[1])}


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
