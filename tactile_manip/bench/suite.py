"""The speed-vs-error run: every candidate through the same readings, timings, accuracy and trials.

Candidates are measured one at a time (each model is loaded, measured and dropped, so the paper preset and
its torch twin are never in memory together). Accuracy is computed once per group of candidates that run
the same numbers and shared after a check that their outputs agree; a candidate that fails is recorded in
the notes and the run goes on.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tactile_manip.bench import accuracy, timing
from tactile_manip.bench.candidates import (BASELINE_NAMES, RUNTIMES, Candidate, ModelEntry, baseline_candidates,
                                            model_candidates)
from tactile_manip.bench.machine import cpu_counters, library_versions, load_average, machine_info, other_load
from tactile_manip.bench.report import fronts
from tactile_manip.bench.timing import TimingBudget

SHARE_TOLERANCE_MM = 1e-3  # outputs this close give the same PSNR/SSIM/angles to every printed digit


@dataclass(frozen=True)
class BenchSettings:
    """How much the report measures.

    Attributes:
        per_object: readings per unseen test object (None: the whole test split).
        trials: presentations of the rod scene per method (0: no trials).
        timing: the timing budget of each measurement.
        parity_readings: readings on which outputs are compared before accuracy is shared.
        quick: a quick run (recorded in the report).
    """

    per_object: int | None = None
    trials: int = 30
    timing: TimingBudget = field(default_factory=TimingBudget)
    parity_readings: int = 32
    quick: bool = False

    def __post_init__(self) -> None:
        if self.per_object is not None and self.per_object < 1:
            raise ValueError(f"per_object must be >= 1 or None, got {self.per_object}")
        if self.trials < 0 or self.parity_readings < 1:
            raise ValueError(f"trials must be >= 0 and parity_readings >= 1, got {self.trials}, {self.parity_readings}")

    @classmethod
    def quick_settings(cls) -> BenchSettings:
        """About 4 minutes on two cores (the paper preset takes most): 3 readings per object, 6 trials, 1 s timings."""
        return cls(per_object=3, trials=6, quick=True, parity_readings=8,
                   timing=TimingBudget(max_calls=60, min_calls=10, max_seconds=1.0, warmup=2, batch_rounds=2))


@dataclass
class _Shared:
    """Accuracy of one group of candidates, and the outputs the others are checked against."""

    metrics: dict[str, Any]
    trials: dict[str, Any] | None
    reference: np.ndarray
    source: str


def run_bench(*, settings: BenchSettings, models: Sequence[ModelEntry], baselines: Sequence[str] = BASELINE_NAMES,
              runtimes: Sequence[str] = RUNTIMES, data_path: str | Path | None = "data/supermag.npz",
              dataset_config: str | Path = "configs/dataset/supermag.toml", scene_path: str | Path | None = None,
              methods: Sequence[str] | None = None, log: Callable[[str], None] = lambda s: None) -> dict[str, Any]:
    """Measure every candidate and return the report (a JSON-ready dict; see :mod:`tactile_manip.bench.report`).

    ``methods`` keeps only those method names (a model's symmetrized method is ``<name>_sym``); ``log`` gets
    one line per step.

    Raises:
        ValueError: an unknown runtime or method name.
    """
    start, counters = time.perf_counter(), cpu_counters()
    _check_names(runtimes, RUNTIMES, "runtimes")
    if methods:
        known = list(baselines) + [n for e in models for n in (e.name, f"{e.name}_sym")]
        _check_names(methods, known, "methods")
    report: dict[str, Any] = {"machine": machine_info(), "libraries": library_versions(),
                              "settings": asdict(settings), "share_tolerance_mm": SHARE_TOLERANCE_MM, "notes": []}
    scene = _trial_scene(scene_path, settings.trials, report["notes"])  # a bad scene fails before any work
    data, report["readings"] = accuracy.load_readings(data_path, dataset_config, per_object=settings.per_object)
    log(f"bench: {report['readings']['readings']} readings ({report['readings']['source']})")
    if scene is not None:
        name = str(scene_path or "reorient_sim: the six rods of configs/scenes/reorient_sim.toml, built in")
        report["trials"] = {"scene": name, "trials": scene.trials, "seed": scene.seed,
                            "tolerance_deg": scene.tolerance_deg}
    with tempfile.TemporaryDirectory(prefix="tactile-bench-") as tmp:
        candidates = _candidates(models, baselines, tuple(runtimes), set(methods or ()), Path(tmp), report["notes"])
        report["rows"] = _measure_all(candidates, data, scene, scene_path, settings, report["notes"], log)
    report["pareto"] = fronts(report["rows"])
    report["seconds"] = time.perf_counter() - start
    report["machine"]["during_run"] = other_load(counters, cpu_counters())
    report["machine"]["load_average_end"] = load_average()
    return report


def _check_names(names: Sequence[str], known: Sequence[str], what: str) -> None:
    unknown = sorted(set(names) - set(known))
    if unknown:
        raise ValueError(f"unknown {what} {unknown}; known: {', '.join(known)}")


def _candidates(models: Sequence[ModelEntry], baselines: Sequence[str], runtimes: tuple[str, ...], wanted: set[str],
                workdir: Path, notes: list[str]) -> list[Candidate]:
    """The baselines and every model's runtimes, kept to ``wanted`` methods (all when empty)."""
    out = baseline_candidates(tuple(b for b in baselines if not wanted or b in wanted))
    for entry in models:
        if wanted and not wanted & {entry.name, f"{entry.name}_sym"}:
            continue
        try:
            found = model_candidates(entry, workdir, runtimes=runtimes, notes=notes)
        except Exception as e:  # noqa: BLE001 - a corrupt model file is a note, not the end of the report
            notes.append(f"{entry.name}: skipped ({type(e).__name__}: {e})")
            continue
        out += [c for c in found if not wanted or c.method in wanted]
    return out


def _measure_all(candidates: Sequence[Candidate], data, scene, scene_path, settings: BenchSettings, notes: list[str],
                 log: Callable[[str], None]) -> list[dict[str, Any]]:
    """One row per candidate, in order; a candidate that fails is a note."""
    test = data.indices("test")
    readings = data.readings[test]
    rods = readings[accuracy.rod_mask(data, test)]
    rods = rods if len(rods) else readings
    rows, shared = [], {}
    for cand in candidates:
        t0 = time.perf_counter()
        try:
            rows.append(_measure(cand, data, readings, rods, scene, scene_path, settings, shared))
        except Exception as e:  # noqa: BLE001 - one broken candidate must not lose the others' figures
            notes.append(f"{cand.method} on {cand.runtime}: failed ({type(e).__name__}: {e})")
            log(f"bench: {cand.method} / {cand.runtime}: FAILED {type(e).__name__}: {e}")
            continue
        log(f"bench: {cand.method} / {cand.runtime}: {time.perf_counter() - t0:.1f} s")
    return rows


def _trial_scene(scene_path: str | Path | None, trials: int, notes: list[str]):
    if trials == 0:
        return None
    try:
        import roboticstoolbox  # noqa: F401 - the kinematic twin of the trials
    except ImportError:
        notes.append("trials not run: the kinematic twin needs roboticstoolbox-python "
                     '(pip install -e ".[trials]")')
        return None
    return accuracy.load_trial_scene(scene_path, trials)


def _measure(cand: Candidate, data, readings: np.ndarray, rods: np.ndarray, scene, scene_path,
             settings: BenchSettings, shared: dict[str, _Shared]) -> dict[str, Any]:
    rec = cand.build(cand.threads)
    budget = settings.timing
    row: dict[str, Any] = {"method": cand.method, "runtime": cand.runtime, "threads": cand.threads,
                           "training": cand.training, "parameters": cand.parameters, "file_mb": cand.file_mb,
                           "path": cand.path, "untrained": cand.untrained}
    t0 = time.perf_counter()
    row |= timing.single_reading_ms(rec, readings, budget)
    row |= timing.batch_throughput(rec, readings, budget)
    row |= timing.pose_latency_ms(rec, rods, budget)
    row["seconds"] = {"timing": round(time.perf_counter() - t0, 2)}
    if cand.untrained:
        row["accuracy_from"] = "n/a (untrained: latency only)"
        return row
    probe = readings[: settings.parity_readings]
    group = shared.get(cand.accuracy_key)
    if group is not None:
        row["parity_max_abs_mm"] = _max_diff(rec, probe, group.reference)
        if row["parity_max_abs_mm"] <= SHARE_TOLERANCE_MM:
            row |= group.metrics
            row["trials"], row["accuracy_from"] = group.trials, group.source
            return row
    t0 = time.perf_counter()
    metrics, predictions = accuracy.image_accuracy(data, _accuracy_reconstructor(cand, rec, probe),
                                                   f"{cand.method} ({cand.runtime})")
    t1 = time.perf_counter()
    trials = None
    if scene is not None:
        trials = accuracy.trial_success(scene, cand.method, spec=cand.trial_spec,
                                        reconstructor=None if cand.trial_spec else rec, scene_path=scene_path)
    row["seconds"] |= {"accuracy": round(t1 - t0, 2), "trials": round(time.perf_counter() - t1, 2)}
    row |= metrics
    row["trials"], row["accuracy_from"] = trials, "own"
    if group is None:
        shared[cand.accuracy_key] = _Shared(metrics, trials, predictions[: len(probe)], f"{cand.method} {cand.runtime}")
    return row


def _max_diff(rec, probe: np.ndarray, reference: np.ndarray) -> float:
    return float(np.abs(rec.reconstruct_batch(probe) - reference).max())


def _accuracy_reconstructor(cand: Candidate, rec, probe: np.ndarray):
    """``rec``, or the same model on all cores when that gives the same outputs (accuracy passes are long,
    and the thread count changes no output)."""
    if not cand.accuracy_threads or cand.accuracy_threads == cand.threads:
        return rec
    fast = cand.build(cand.accuracy_threads)
    return fast if _max_diff(fast, probe, rec.reconstruct_batch(probe)) <= SHARE_TOLERANCE_MM else rec
