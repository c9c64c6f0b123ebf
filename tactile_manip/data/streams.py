"""The two streams of a probe log, read from files, and the contact condition on its labels.

A probe rig writes a timestamped sensor stream (time s, then x, y, z of each chip in firmware order, uT) and
a timestamped label stream (time s, then the stage's and load cell's columns). :func:`read_csv_table` reads
either as a float64 array (a first line that is not numbers is a header, and its names are returned);
:func:`read_reading_stream` also reads a ``tactile-manip record`` file (.tmrec) in place of the sensor CSV.
:func:`reading_stream` and :func:`label_stream` take any of the forms :func:`~tactile_manip.data.probe_logs.
from_probe_logs` accepts (files, arrays, mappings) to the readings on a board layout's cells and named label
columns.
:func:`parse_comparison` parses a ``--contact`` condition like ``"z_mm < 145.1"`` without ``eval``.
"""

from __future__ import annotations

import operator
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.errors import DatasetError

RECORDING_SUFFIX = ".tmrec"
TIME_COLUMN = "time_s"
BASELINE_SHARE = 0.25  # a baseline window longer than this share of a run takes in its presses
ReadingStream = str | Path | np.ndarray | tuple  # a file, a (M, 1 + V) array, or (t_s, values)
LabelStream = str | Path | np.ndarray | Mapping  # a CSV file, a (L, K) array, or {column: (L,) array}
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
        recording's layout; info names the source, and for a recording its layout, clock and what its damage
        lost (``skipped_bytes``, ``damaged_places`` and their ``damage_at_bytes``, ``truncated_bytes``, about
        how many ``frames_lost``).
    """
    path = Path(path)
    if path.suffix == RECORDING_SUFFIX:
        from tactile_manip.errors import RecordingError
        from tactile_manip.logs.recording import read_recording

        try:
            rec = read_recording(path)
        except RecordingError as e:
            raise DatasetError(str(e)) from e
        if not len(rec):
            raise DatasetError(f"recording {path}: no frames")
        info = {"source": str(path), "kind": "recording", "layout": rec.layout_name,
                "clock": "time.monotonic() of the recording host", "frames": len(rec),
                "skipped_bytes": rec.skipped_bytes, "damaged_places": rec.damaged_records,
                "damage_at_bytes": [at for at, _ in rec.damage], "truncated_bytes": rec.truncated_bytes,
                "frames_lost": rec.frames_lost}
        return rec.t_host_s, rec.field_raw_ut(), info
    table, _ = read_csv_table(path, what="readings")
    return table[:, 0], table[:, 1:], {"source": str(path), "kind": "csv", "columns": int(table.shape[1])}


def board_layout(layout: Any):
    """A ``Board`` from its name (or itself); DatasetError naming the known layouts."""
    from tactile_manip.boards import Board, load_board

    if isinstance(layout, Board):
        return layout
    try:
        return load_board(str(layout))
    except ValueError as e:
        raise DatasetError(str(e)) from None


def reading_stream(item: ReadingStream, board: Any, offset_s: float, baseline_s: float | None,
                   run: str) -> tuple[np.ndarray, np.ndarray, dict]:
    """(t_s (M,), readings (M, R, C, 3) float32 on the layout, info)."""
    if isinstance(item, (str, Path)):
        t, values, info = read_reading_stream(item)
    elif isinstance(item, tuple):
        if len(item) != 2:
            raise DatasetError(f"run {run}: a sensor stream pair is (t_s, values), got {len(item)} items")
        t, values, info = np.asarray(item[0], np.float64), np.asarray(item[1], np.float64), {"kind": "arrays"}
    else:
        table = np.asarray(item, np.float64)
        if table.ndim != 2:
            raise DatasetError(f"run {run}: a sensor stream array is (M, 1 + values), got shape {table.shape}")
        t, values, info = table[:, 0], table[:, 1:], {"kind": "array", "columns": int(table.shape[1])}
    where = info.get("source", f"run {run} readings")
    if values.ndim == 4:  # a recording: already cells of its own layout
        if info.get("layout") not in (None, board.name):
            raise DatasetError(f"{where}: recorded with layout {info['layout']}, not {board.name}")
        readings = values.astype(np.float32)
    else:
        flat = values.reshape(len(values), -1) if values.ndim == 3 else values
        if flat.ndim != 2 or flat.shape[1] != 3 * board.n_chips:
            if info["kind"] == "arrays":
                raise DatasetError(f"{where}: values of shape {values.shape}, expected (M, {3 * board.n_chips}) or "
                                   f"(M, {board.n_chips}, 3): x, y, z of each chip of layout {board.name}")
            raise DatasetError(f"{where}: {flat.shape[1] + 1} columns, expected {1 + 3 * board.n_chips}: time (s), "
                               f"then x, y, z of each of the {board.n_chips} chips of layout {board.name}")
        _check_values(flat, where, table=info["kind"] != "arrays")
        readings = board.readings_from_chips(flat.reshape(len(flat), board.n_chips, 3))
    if len(t) != len(readings):
        raise DatasetError(f"{where}: {len(t)} times for {len(readings)} readings")
    check_times(t, where)
    t = t + float(offset_s)
    if baseline_s is not None:
        span_s = float(np.nanmax(t) - np.nanmin(t))
        if baseline_s > BASELINE_SHARE * span_s:
            raise DatasetError(f"{where}: a baseline of the first {baseline_s:g} s would take in "
                               f"{min(baseline_s / span_s, 1.0) if span_s > 0 else 1.0:.0%} of the run's {span_s:.3g} s, "
                               "presses and all; "
                               f"the baseline is the free pad at the start: give at most "
                               f"{BASELINE_SHARE * span_s:.3g} s (a few seconds before the first press)")
        first = np.isfinite(t) & (t <= np.nanmin(t) + baseline_s) & np.isfinite(readings).all(axis=(1, 2, 3))
        if not first.any():
            raise DatasetError(f"{where}: no finite reading in the first {baseline_s:g} s to take a baseline from")
        readings = readings - readings[first].mean(axis=0, dtype=np.float64).astype(np.float32)
        info = dict(info, baseline_rows=int(first.sum()))
    return t, readings, info


def label_stream(item: LabelStream, columns: Sequence[str] | None,
                 run: str) -> tuple[dict[str, np.ndarray], dict]:
    """{column: (L,) float64} with a ``time_s`` column, and info."""
    if isinstance(item, Mapping):
        labels = {str(k): np.asarray(v, np.float64).reshape(-1) for k, v in item.items()}
        info = {"kind": "mapping"}
        where = f"run {run} labels"
    else:
        header = None
        if isinstance(item, (str, Path)):
            table, header = read_csv_table(item, what="labels")
            info, where = {"source": str(item), "kind": "csv"}, f"labels {item}"
        else:
            table, info, where = np.asarray(item, np.float64), {"kind": "array"}, f"run {run} labels"
            if table.ndim != 2:
                raise DatasetError(f"{where}: expected a (rows, columns) array, got shape {table.shape}")
        names = list(columns) if columns is not None else header
        if names is None:
            raise DatasetError(f"{where}: no header; name its columns (label columns, e.g. time_s,x_mm,y_mm,z_mm)")
        twice = [n for i, n in enumerate(names) if n in names[:i]]
        if twice:  # a dict by name would keep the last of them: another column's data under the first's name
            named_by = "the label columns name" if columns is not None else "its header names"
            raise DatasetError(f"{where}: {named_by} the column {twice[0]!r} twice ({','.join(names)}): give each "
                               f"column its own name")
        if table.shape[1] != len(names):
            raise DatasetError(f"{where}: {table.shape[1]} columns, but the label columns name {len(names)} "
                               f"({','.join(names)})")
        labels = {n: table[:, i] for i, n in enumerate(names)}
    if TIME_COLUMN not in labels:
        raise DatasetError(f"{where}: no {TIME_COLUMN!r} column among {','.join(labels)} (label times in s)")
    lengths = {len(v) for v in labels.values()}
    if len(lengths) != 1:
        raise DatasetError(f"{where}: columns of different lengths {sorted(lengths)}")
    check_times(labels[TIME_COLUMN], where)
    return labels, info


def check_times(t_s: np.ndarray, where: str) -> None:
    """Refuse a stream's times (M,) s that are not finite or go backwards, naming the row (1-based data rows).

    Both streams are matched by time: a row out of order would take another row's label, so it is refused rather
    than sorted. Repeated times pass (the caller counts them).

    Raises:
        DatasetError: ``where``, the row and its time.
    """
    t = np.asarray(t_s, dtype=np.float64)
    bad = ~np.isfinite(t)
    if bad.any():
        i = int(np.argmax(bad))
        count = int(bad.sum())
        raise DatasetError(f"{where}: row {i + 1} has time {float(t[i])}: every row needs a finite time (s) "
                           f"({count} {'row does' if count == 1 else 'rows do'} not)")
    back = np.diff(t) < 0
    if back.any():
        i = int(np.argmax(back))
        count = int(back.sum())
        raise DatasetError(f"{where}: time goes backwards at row {i + 2} ({t[i + 1]:.6f} s, after {t[i]:.6f} s at "
                           f"row {i + 1}; {count} backward step{'s' if count > 1 else ''} in all): rows are matched "
                           "by time, so they must be in time order; sort them or fix the clock")


def _check_values(flat: np.ndarray, where: str, *, table: bool) -> None:
    """Refuse finite values (M, V) too large for float32 (they would become inf) and rows that are all NaN or inf.

    ``table``: the values are columns 2.. of a table whose column 1 is the time (named so); else value indices.
    """
    def place(r: int, c: int) -> str:
        return f"row {r + 1}, column {c + 2}" if table else f"row {r + 1}, value {c}"

    with np.errstate(invalid="ignore"):
        huge = np.isfinite(flat) & (np.abs(flat) > np.finfo(np.float32).max)
    if huge.any():
        r, c = (int(i) for i in np.argwhere(huge)[0])
        raise DatasetError(f"{where}: {place(r, c)} holds {flat[r, c]:g}: too large to be a reading (beyond "
                           f"float32's range, +-3.4e38, it would overflow to inf; {int(huge.sum())} such values)")
    bad = ~np.isfinite(flat)
    if len(flat) and bad.any(axis=1).all():
        r, c = (int(i) for i in np.argwhere(bad)[0])
        raise DatasetError(f"{where}: every sensor row has a NaN or infinite value (first: {place(r, c)}, "
                           f"{flat[r, c]}): no reading to match")


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
