"""Labelled presses from a probe rig's logs: a sensor stream and a label stream per run, matched by time.

:func:`from_probe_logs` turns each run's two streams into samples: every sensor row takes the label row
nearest in time, among the label rows that have a reading in every column used (``missing`` marks "no
reading", e.g. -1 where a load cell sent nothing). A sensor row whose nearest usable label is farther than
``tolerance_s`` (default 3x the median period of the usable labels) is unmatched and dropped; a sensor row
with a NaN or infinite value is skipped. Both are counted, with the gaps in either stream longer than the
tolerance and the rows whose time repeats the row before, per run in ``provenance["runs"]``. Times that are
not finite or go backwards, and streams whose clocks never overlap, are refused.

``contact`` (one comparison such as ``"z_mm < 145.1"``) keeps the rows that satisfy it; when ``in_contact``
is one of the targets, every row is kept and the comparison becomes that 0/1 target instead. The default
split is chronological per run, the published protocol of the eFlesh characterisation: of each run's kept
rows in time order, the first 80 % train and the last 20 % test (rows dropped by ``contact`` are dropped
before the split). ``split="held_out_run"`` makes one whole run the test split.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.data.dataset import UNLABELLED, PairedDataset
from tactile_manip.data.spec import ChannelSpec
from tactile_manip.data.streams import (TIME_COLUMN, Comparison, LabelStream, ReadingStream, board_layout,
                                        label_stream, parse_comparison, reading_stream)
from tactile_manip.data.targets import CONTACT_FLAG, target_from_label
from tactile_manip.errors import DatasetError
from tactile_manip.version import code_version

PROBE_SPLITS = ("chronological", "held_out_run")
MATCHES = ("nearest", "linear")
DEFAULT_LAYOUT = "anyskin-5"
TOLERANCE_PERIODS = 3.0   # default matching tolerance, in median periods of the usable label rows



def from_probe_logs(readings: Sequence[ReadingStream], labels: Sequence[LabelStream], *, targets: Sequence[str],
                    label_columns: Sequence[str] | None = None, layout: Any = DEFAULT_LAYOUT,
                    contact: str | Comparison | None = None, missing: float | Mapping[str, float] | None = None,
                    tolerance_s: float | None = None, match: str = "nearest", split: str = "chronological",
                    test_fraction: float = 0.2,
                    val_fraction: float = 0.0, held_out_run: int | str | None = None,
                    run_names: Sequence[str] | None = None, time_offset_s: float = 0.0,
                    baseline_s: float | None = None, labelled: int | None = None, seed: int = 0,
                    provenance: dict[str, Any] | None = None) -> PairedDataset:
    """A targets-only :class:`PairedDataset` of labelled presses, one run (group) per pair of streams.

    Args:
        readings: per run, the sensor stream: a CSV or recording path, a (M, 1 + 3 * chips) array (time s,
            then chip-major x, y, z in uT), or a pair (t_s (M,), values (M, 3 * chips) or (M, chips, 3)).
        labels: per run, the label stream: a CSV path, a (L, K) array named by ``label_columns``, or a mapping
            {column: (L,) array}. Column names carry units (``_s``, ``_mm``, ``_n``, ``_gf``, ``_kgf``); one is
            ``time_s``.
        targets: label columns that become targets, by their name or their name in target units
            (``force_gf`` -> ``force_n``, in newtons); ``in_contact`` for the ``contact`` flag.
        label_columns: names of the label columns (required for arrays and CSVs without a header).
        layout: board layout name (``anyskin-5``, ``supermag-4x4``) or a ``Board``: the chips' order and
            the (R, C) cells their readings are stored on.
        contact: one comparison on a label column (``"z_mm < 145.1"``), in that column's units.
        missing: the value meaning "no reading" in every used column, or {column: value}.
        tolerance_s: largest sensor-to-label time difference matched, s (default 3 median label periods).
        match: "nearest" (each sensor row takes the nearest usable label row: the published protocol) or
            "linear" (targets interpolated in time between the usable label rows on either side, where both
            are within the tolerance; the contact condition still reads the nearest row).
        split: "chronological" (per run: first rows train, last ``test_fraction`` test) or "held_out_run".
        test_fraction / val_fraction: shares of each run's rows (chronological; val sits just before test);
            with held_out_run, val_fraction is the end of each training run.
        held_out_run: index or name of the test run for ``split="held_out_run"``.
        run_names: one name per run (default: the folder of each readings file, else run0, run1, ...).
        time_offset_s: added to every sensor time (to put both streams on one clock).
        baseline_s: subtract from each run's readings the mean of its first ``baseline_s`` seconds (pad free
            then); None keeps readings as given (probe-log CSVs are usually baseline-subtracted already).
        labelled: keep the labels of this many training rows, drawn at random with ``seed`` from all runs' training
            rows (a rig owner's handful of labelled presses); the other training rows become the ``unlabelled``
            split: their readings stay, their targets and label columns are NaN. Validation and test rows keep
            their labels. None keeps every label.

    Raises:
        DatasetError: one line naming the run, file or column and what is wrong.
    """
    board = board_layout(layout)
    if len(readings) != len(labels) or not readings:
        raise DatasetError(f"one label stream per sensor stream: got {len(readings)} sensor and {len(labels)} label "
                           f"streams")
    if match not in MATCHES:
        raise DatasetError(f"match must be one of {', '.join(MATCHES)}, got {match!r}")
    _check_seconds(time_offset_s=time_offset_s, tolerance_s=tolerance_s, baseline_s=baseline_s)
    if split not in PROBE_SPLITS:
        raise DatasetError(f"split must be one of {', '.join(PROBE_SPLITS)}, got {split!r}")
    for name, f in (("test_fraction", test_fraction), ("val_fraction", val_fraction)):
        if not 0.0 <= f < 1.0:
            raise DatasetError(f"{name} must be in [0, 1), got {f}")
    cond = parse_comparison(contact) if isinstance(contact, str) else contact
    names = _run_names(readings, run_names)
    plan = _TargetPlan(tuple(targets), cond)
    runs = [_Run(names[i], *reading_stream(readings[i], board, time_offset_s, baseline_s, names[i]),
                 *label_stream(labels[i], label_columns, names[i]), plan, cond, missing, tolerance_s, match)
            for i in range(len(readings))]
    split_arr = _split(runs, split, test_fraction, val_fraction, held_out_run)
    prov = {"source": "tactile_manip.data.from_probe_logs", "code_version": code_version(),
            "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "layout": board.name,
            "board": board.record, "targets": plan.describe(), "contact": None if cond is None else str(cond),
            "contact_use": None if cond is None else ("target" if plan.flag else "filter"),
            "missing": missing if not isinstance(missing, Mapping) else dict(missing),
            "split": split, "test_fraction": test_fraction, "val_fraction": val_fraction,
            "held_out_run": None if split != "held_out_run" else names[_run_index(held_out_run, names)],
            "match": match, "time_offset_s": time_offset_s, "baseline_s": baseline_s, "runs": [r.report for r in runs],
            **(provenance or {})}
    extras = {"time_s": np.concatenate([r.time_s for r in runs])}
    for col in sorted(set.intersection(*[set(r.labels) for r in runs]) - {TIME_COLUMN}):
        extras[f"label_{col}"] = np.concatenate([r.labels[col] for r in runs]).astype(np.float32)
    targets = np.concatenate([r.targets for r in runs]).astype(np.float32)
    if labelled is not None:
        split_arr, prov["labelled"] = hold_back_labels(split_arr, targets, extras, labelled, seed)
    return PairedDataset(readings=np.concatenate([r.readings for r in runs]), images=None, split=split_arr,
                         channels=ChannelSpec(), groups=np.concatenate([np.full(len(r), i, np.int64)
                                                                       for i, r in enumerate(runs)]),
                         extras=extras, provenance=prov, targets=targets, target_names=plan.names)


MAX_TOLERANCE_S = 10.0  # a sensor row matched to a label farther than this in time is no pair of one press


def _check_seconds(*, time_offset_s: float, tolerance_s: float | None, baseline_s: float | None) -> None:
    """Refuse a non-finite clock shift, a matching tolerance that is not a short positive time, and a baseline
    window that is not a positive time (each checked on its own, so the message names the value at fault)."""
    if not _finite(time_offset_s):
        raise DatasetError(f"time_offset_s (--time-offset-s) must be a finite number of seconds, got {time_offset_s}")
    if tolerance_s is not None and not (_finite(tolerance_s) and 0.0 < tolerance_s <= MAX_TOLERANCE_S):
        raise DatasetError(f"tolerance_s (--tolerance-s) must be in (0, {MAX_TOLERANCE_S:g}] s: a sensor row is "
                           f"paired with a label at most that far in time; got {tolerance_s}")
    if baseline_s is not None and not (_finite(baseline_s) and baseline_s > 0.0):
        raise DatasetError(f"baseline_s (--baseline-s) must be a positive number of seconds, got {baseline_s}")


def _finite(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool) and bool(
        np.isfinite(value))


def hold_back_labels(split: np.ndarray, targets: np.ndarray, extras: dict[str, np.ndarray], labelled: int,
                     seed: int) -> tuple[np.ndarray, dict[str, Any]]:
    """Keep the labels of ``labelled`` training rows drawn at random with ``seed``; the other training rows become
    ``unlabelled``, with NaN in ``targets`` and every ``label_*`` extra (changed in place). Returns the new split
    and what the provenance records.

    Raises:
        DatasetError: ``labelled`` is not a whole number from 0 to the number of training rows.
    """
    train = np.flatnonzero(split == "train")
    if isinstance(labelled, bool) or not isinstance(labelled, (int, np.integer)) or not 0 <= labelled <= len(train):
        raise DatasetError(f"--labelled {labelled}: keep labels on 0 to {len(train)} presses (the training rows); "
                           f"got {labelled}")
    keep = np.random.default_rng(seed).choice(train, size=int(labelled), replace=False)
    hide = np.setdiff1d(train, keep)
    out = split.astype(f"U{len(UNLABELLED)}")
    out[hide] = UNLABELLED
    targets[hide] = np.nan
    for name in [k for k in extras if k.startswith("label_")]:
        extras[name][hide] = np.nan
    return out, {"presses": int(labelled), "seed": int(seed), "of_training_rows": int(len(train))}


class _TargetPlan:
    """Which label column feeds each target and by what factor (gram-force -> newtons)."""

    def __init__(self, targets: tuple[str, ...], cond: Comparison | None) -> None:
        if not targets:
            raise DatasetError("no targets: name the label columns to learn (e.g. x_mm,y_mm or force_n)")
        self.flag = CONTACT_FLAG in targets
        if self.flag and cond is None:
            raise DatasetError(f"target {CONTACT_FLAG!r} needs a contact condition (e.g. \"z_mm < 145.1\") to "
                               f"say which rows touch")
        self.requested = targets
        self.names = tuple(target_from_label(t)[0] for t in targets)
        twice = sorted({n for n in self.names if self.names.count(n) > 1})
        if twice:
            raise DatasetError(f"targets {list(targets)} name {twice} more than once")

    def sources(self, columns: Sequence[str], run: str) -> dict[str, tuple[str, float]]:
        """target name -> (label column, factor), for the columns of one run's label stream."""
        out = {}
        for want, name in zip(self.requested, self.names):
            if want == CONTACT_FLAG:
                continue
            found = [c for c in columns if c == want or _target_name(c) == name]
            if not found:
                raise DatasetError(f"run {run}: target {want!r} is not among the label columns {','.join(columns)}"
                                   f" (a target is a label column, or one in gf/kgf named in N: force_gf -> force_n)")
            out[name] = (found[0], target_from_label(found[0])[1])
        return out

    def describe(self) -> dict[str, str]:
        return {n: r for n, r in zip(self.names, self.requested)}


class _Run:
    """One run's streams matched by time: its readings, targets, times and the counts of what was dropped."""

    def __init__(self, name: str, t_r: np.ndarray, values: np.ndarray, r_info: dict, labels: dict[str, np.ndarray],
                 l_info: dict, plan: _TargetPlan, cond: Comparison | None, missing: Any,
                 tolerance_s: float | None, match: str) -> None:
        sources = plan.sources(list(labels), name)
        used = sorted({c for c, _ in sources.values()} | ({cond.column} if cond is not None else set()))
        for col in used:
            if col not in labels:
                raise DatasetError(f"run {name}: contact condition column {col!r} is not among the label columns "
                                   f"{','.join(labels)}")
        unknown = sorted(set(missing) - set(labels)) if isinstance(missing, Mapping) else []
        if unknown:
            raise DatasetError(f"run {name}: missing values given for {unknown}, which are not among the label "
                               f"columns {','.join(labels)}")
        report: dict[str, Any] = {"name": name, "readings": r_info, "labels": l_info, "reading_rows": len(t_r),
                                  "label_rows": len(labels[TIME_COLUMN])}
        # both streams are in time order (streams.check_times); a repeated time is kept and counted
        for stream, t in (("reading", t_r), ("label", labels[TIME_COLUMN])):
            repeated = np.flatnonzero(np.diff(t) == 0) + 1
            report[f"repeated_{stream}_times"] = int(len(repeated))
            report[f"first_repeated_{stream}_row"] = int(repeated[0]) + 1 if len(repeated) else None
        # label rows: a usable time and a reading in every used column
        t_l = labels[TIME_COLUMN]
        usable = np.isfinite(t_l)
        for col in used:
            usable &= np.isfinite(labels[col]) & ~_is_missing(labels[col], col, missing)
        report["missing_labels"] = int((~usable).sum())
        if usable.sum() < 2:
            raise DatasetError(f"run {name}: {int(usable.sum())} label rows have a reading in {','.join(used)}; "
                               f"matching needs at least 2")
        lab_idx = np.flatnonzero(usable)
        t_lab = t_l[lab_idx]
        # sensor rows: finite values (the times are finite and in order)
        finite = np.isfinite(values.reshape(len(values), -1)).all(axis=1)
        report["nan_readings"] = int((~finite).sum())
        keep = np.flatnonzero(finite)
        t_s = t_r[keep]
        if not len(t_s):
            raise DatasetError(f"run {name}: every sensor row has a NaN or infinite value")
        if t_s[-1] < t_lab[0] or t_s[0] > t_lab[-1]:
            raise DatasetError(f"run {name}: the sensor stream (t = {t_s[0]:.3f} .. {t_s[-1]:.3f} s) and the label "
                               f"stream (t = {t_lab[0]:.3f} .. {t_lab[-1]:.3f} s) never overlap: stamp both with "
                               f"one clock (or shift the sensor's with a time offset)")
        period = float(np.median(np.diff(t_lab)))
        tol = TOLERANCE_PERIODS * period if tolerance_s is None else float(tolerance_s)
        if not tol > 0:
            raise DatasetError(f"run {name}: matching tolerance {tol:g} s must be > 0 (label times repeat?)")
        nearest, dt = _nearest(t_lab, t_s)
        matched = np.abs(dt) <= tol
        report |= {"tolerance_s": tol, "label_period_s": period, "unmatched": int((~matched).sum()),
                   "reading_gaps": _gaps(t_s, tol), "label_gaps": _gaps(t_lab, tol),
                   "median_match_dt_s": float(np.median(np.abs(dt[matched]))) if matched.any() else None}
        if not matched.any():
            raise DatasetError(f"run {name}: no sensor row has a label within {tol:g} s")
        report["p90_match_dt_s"] = float(np.percentile(np.abs(dt[matched]), 90)) if matched.any() else None
        rows, pos = keep[matched], nearest[matched]
        flag = None
        if cond is not None:
            hit = cond(labels[cond.column][lab_idx[pos]])
            report["non_contact"] = 0 if plan.flag else int((~hit).sum())
            if plan.flag:
                flag = hit.astype(np.float32)
            else:
                rows, pos = rows[hit], pos[hit]
        lab = lab_idx[pos]
        if not len(rows):
            raise DatasetError(f"run {name}: no row satisfies the contact condition {cond}")
        self.name, self.report = name, report
        self.readings = values[rows]
        self.time_s = t_r[rows].astype(np.float64)
        self.labels = {c: v[lab] for c, v in labels.items()}
        between = _bracketed(t_lab, t_r[rows], tol) if match == "linear" else None
        report["interpolated"] = 0 if between is None else int(between.sum())
        cols = []
        for target in plan.names:
            if target == CONTACT_FLAG:
                cols.append(flag)
                continue
            src, factor = sources[target]
            value = labels[src][lab]
            if between is not None:  # the label at the sensor row's time, between the usable rows around it
                value = np.where(between, np.interp(t_r[rows], t_lab, labels[src][lab_idx]), value)
            cols.append(value * factor)
        self.targets = np.stack(cols, axis=1).astype(np.float32)
        report["samples"] = len(rows)

    def __len__(self) -> int:
        return len(self.time_s)


def _target_name(column: str) -> str | None:
    """The target a label column would become (None for the time and for columns without a unit)."""
    if column == TIME_COLUMN:
        return None
    try:
        return target_from_label(column)[0]
    except DatasetError:
        return None


def _nearest(t_lab: np.ndarray, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of the nearest of the sorted ``t_lab`` for each of ``t_s``, and t_s minus that time."""
    right = np.clip(np.searchsorted(t_lab, t_s), 1, len(t_lab) - 1)
    left = right - 1
    take_left = np.abs(t_s - t_lab[left]) <= np.abs(t_lab[right] - t_s)
    idx = np.where(take_left, left, right)
    return idx, t_s - t_lab[idx]


def _bracketed(t_lab: np.ndarray, t_s: np.ndarray, tol: float) -> np.ndarray:
    """(n,) bool: a usable label row on each side of each of ``t_s``, both within ``tol``."""
    right = np.searchsorted(t_lab, t_s)
    inside = (right > 0) & (right < len(t_lab))
    r = np.clip(right, 1, len(t_lab) - 1)
    return inside & (t_s - t_lab[r - 1] <= tol) & (t_lab[r] - t_s <= tol)


def _gaps(t: np.ndarray, tol: float) -> dict[str, float]:
    d = np.diff(t)
    big = d > tol
    return {"count": int(big.sum()), "longest_s": float(d.max(initial=0.0)), "seconds": float(d[big].sum())}


def _is_missing(values: np.ndarray, column: str, missing: Any) -> np.ndarray:
    if missing is None:
        return np.zeros(len(values), bool)
    value = missing.get(column) if isinstance(missing, Mapping) else missing
    return np.zeros(len(values), bool) if value is None else values == float(value)


def _run_names(readings: Sequence[ReadingStream], names: Sequence[str] | None) -> list[str]:
    if names is not None:
        out = [str(n) for n in names]
        if len(out) != len(readings) or len(set(out)) != len(out):
            raise DatasetError(f"run names {out}: need {len(readings)} distinct names, one per run")
        return out
    folders = [Path(r).resolve().parent.name if isinstance(r, (str, Path)) else "" for r in readings]
    if all(folders) and len(set(folders)) == len(folders):
        return folders
    return [f"run{i}" for i in range(len(readings))]


def _run_index(run: int | str | None, names: list[str]) -> int:
    if run is None:
        raise DatasetError(f"a held-out-run split needs the run to hold out (index 0..{len(names) - 1} or one of "
                           f"{', '.join(names)})")
    if isinstance(run, str) and run in names:
        return names.index(run)
    try:
        i = int(run)
    except ValueError:
        i = -1
    if not 0 <= i < len(names):
        raise DatasetError(f"held-out run {run!r} is not a run: give an index 0..{len(names) - 1} or one of "
                           f"{', '.join(names)}")
    return i


def _split(runs: list[_Run], split: str, test_fraction: float, val_fraction: float,
           held_out_run: int | str | None) -> np.ndarray:
    parts = []
    held = _run_index(held_out_run, [r.name for r in runs]) if split == "held_out_run" else None
    if held is not None and len(runs) < 2:
        raise DatasetError("a held-out-run split needs at least two runs")
    for i, run in enumerate(runs):
        n = len(run)
        out = np.full(n, "train", dtype="U5")
        if i == held:
            out[:] = "test"
        else:
            n_fit = n if held is not None else int((1.0 - test_fraction) * n)  # published: int(0.8 * n) train
            n_val = int(val_fraction * n)
            out[n_fit:] = "test"
            out[max(n_fit - n_val, 0):n_fit] = "val"
        run.report |= {s: int(np.sum(out == s)) for s in ("train", "val", "test")}
        parts.append(out)
    split_arr = np.concatenate(parts)
    if not np.any(split_arr == "train"):
        raise DatasetError(f"the {split} split leaves no row to train on")
    return split_arr
