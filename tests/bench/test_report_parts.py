"""The report's pure parts: the Pareto front, the table cells, training notes, model specs, timings."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tactile_manip.bench.candidates import parse_model_spec, training_note
from tactile_manip.bench.machine import other_load
from tactile_manip.bench.report import fronts, markdown_table, pareto_front
from tactile_manip.bench.timing import TimingBudget, batch_throughput, single_reading_ms
from tactile_manip.perception.reconstruct import Reconstructor


def test_pareto_front_keeps_only_points_no_faster_point_beats() -> None:
    # (latency, PSNR): c is slower and worse than b; d is slowest but best
    pts = [(1.0, 10.0), (3.0, 20.0), (4.0, 15.0), (9.0, 25.0)]
    assert pareto_front(pts, higher_is_better=True) == [0, 1, 3]
    # the same points with an error (lower is better): only the fastest, whose error is lowest, survives
    assert pareto_front(pts, higher_is_better=False) == [0]


def test_pareto_front_of_ties_keeps_the_better_of_equal_latencies_once() -> None:
    assert pareto_front([(2.0, 5.0), (2.0, 7.0), (2.0, 7.0)], higher_is_better=True) == [1]
    assert pareto_front([], higher_is_better=True) == []


def test_fronts_use_only_one_thread_rows_with_a_value() -> None:
    rows = [{"method": "a", "runtime": "numpy", "latency_p50_ms": 1.0, "psnr_db": 15.0, "angle_p95_deg": 80.0},
            {"method": "m", "runtime": "onnxruntime 1 thread", "latency_p50_ms": 3.0, "psnr_db": 20.0,
             "angle_p95_deg": 7.0},
            {"method": "m", "runtime": "onnxruntime 2 threads", "latency_p50_ms": 0.1, "psnr_db": 30.0,
             "angle_p95_deg": 1.0},
            {"method": "p", "runtime": "onnxruntime 1 thread", "latency_p50_ms": 90.0, "psnr_db": None,
             "angle_p95_deg": None}]
    assert fronts(rows) == {"psnr_db": ["a", "m"], "angle_p95_deg": ["a", "m"]}


def test_table_marks_an_untrained_model_and_missing_trials() -> None:
    row = {"method": "paper", "runtime": "onnxruntime 1 thread", "training": "untrained", "parameters": 45_728_290,
           "file_mb": 183.0, "latency_p50_ms": 100.0, "latency_p99_ms": 120.0, "throughput_rps": 10.0,
           "pose_p50_ms": 101.0, "pose_p99_ms": 125.0, "untrained": True}
    line = markdown_table([row]).splitlines()[2]
    assert line.count("n/a (untrained)") == 4  # PSNR, SSIM, angle, trials
    assert "45.73 M" in line and "100.00 / 120.00" in line
    assert line.count("|") == 13


def test_training_note_reads_the_run_history(tmp_path) -> None:
    model = tmp_path / "model.onnx"
    (tmp_path / "history.json").write_text(json.dumps(
        {"epochs_run": 1, "history": [{"epoch": 1, "batches": 4, "epoch_fraction": 0.0714}]}))
    assert training_note(model, {}) == "4 optimizer steps (7% of an epoch)"
    (tmp_path / "history.json").write_text(json.dumps(
        {"epochs_run": 8, "history": [{"epoch": 8, "batches": 56, "epoch_fraction": 1.0}]}))
    assert training_note(model, {}) == "8 epochs"
    (tmp_path / "history.json").unlink()
    assert training_note(model, {"train_config": {"epochs": 28}}) == "28 epochs (config)"
    assert training_note(model, {}) == "unknown"


def test_model_spec_needs_name_and_path_and_finds_the_checkpoint(tmp_path) -> None:
    (tmp_path / "best.pt").write_bytes(b"")
    entry = parse_model_spec(f"mine={tmp_path / 'model.onnx'}")
    assert entry.name == "mine" and entry.checkpoint == tmp_path / "best.pt"
    assert parse_model_spec("x=elsewhere/model.onnx").checkpoint is None
    for bad in ("nopath", "=a.onnx", "x=", "two words=a.onnx"):
        with pytest.raises(ValueError):
            parse_model_spec(bad)


class _Clock:
    """A stand-in for the ``time`` module in bench.timing: ``perf_counter`` reads a clock that only the fake
    reconstructor advances, so the timings are exact whatever else the machine is doing."""

    def __init__(self) -> None:
        self.now_s = 0.0

    def perf_counter(self) -> float:
        return self.now_s


class _Timed(Reconstructor):
    """Takes ``delay_s`` per call plus ``per_reading_s`` per reading of fake time (``first_s`` for the first
    call instead, when given); counts its calls; outputs zeros."""

    output_shape = (4, 4)

    def __init__(self, clock: _Clock, delay_s: float, per_reading_s: float = 0.0, first_s: float | None = None):
        self.clock, self.delay_s, self.per_reading_s, self.first_s = clock, delay_s, per_reading_s, first_s
        self.calls = 0

    def _run(self, fields_ut):
        first = self.calls == 0 and self.first_s is not None
        self.clock.now_s += self.first_s if first else self.delay_s + self.per_reading_s * len(fields_ut)
        self.calls += 1
        return np.zeros((len(fields_ut), 4, 4), np.float32), None


@pytest.fixture
def clock(monkeypatch) -> _Clock:
    from tactile_manip.bench import timing

    fake = _Clock()
    monkeypatch.setattr(timing, "time", fake)
    return fake


def test_timings_stop_at_the_time_budget_but_not_before_min_calls(clock) -> None:
    readings = np.zeros((3, 4, 4, 3), np.float32)
    budget = TimingBudget(max_calls=1000, min_calls=5, max_seconds=0.05, warmup=1, batch=8, batch_rounds=3)
    slow_rec = _Timed(clock, 0.02)
    slow = single_reading_ms(slow_rec, readings, budget)
    # 0.05 s are spent after 3 timed calls, but 5 are the minimum; plus the warm-up call
    assert slow["latency_calls"] == 5 and slow_rec.calls == 6
    assert slow["latency_p50_ms"] == pytest.approx(20.0) and slow["latency_p99_ms"] == pytest.approx(20.0)
    budget = TimingBudget(max_calls=1000, min_calls=5, max_seconds=0.51)
    assert single_reading_ms(_Timed(clock, 0.02), readings, budget)["latency_calls"] == 26  # 26 x 20 ms > 0.51 s
    fast = single_reading_ms(_Timed(clock, 1e-4), readings, TimingBudget(max_calls=50, max_seconds=10.0))
    assert fast["latency_calls"] == 50  # the call cap, long before the time budget


def test_throughput_drops_the_warm_up_batch_unless_it_alone_exceeds_the_budget(clock) -> None:
    readings = np.zeros((3, 4, 4, 3), np.float32)
    quick_rec = _Timed(clock, 0.0, 1e-4, first_s=1.0)  # a slow first batch (allocation), then 0.8 ms per batch
    quick = batch_throughput(quick_rec, readings, TimingBudget(batch=8, batch_rounds=3, max_seconds=10.0))
    assert quick["warm"] and quick["batch_rounds"] == 3 and quick["batch"] == 8 and quick_rec.calls == 4
    assert quick["throughput_rps"] == pytest.approx(1e4)  # 8 readings per 0.8 ms: the warm-up is not counted
    slow_rec = _Timed(clock, 0.06)
    slow = batch_throughput(slow_rec, readings, TimingBudget(batch=8, batch_rounds=3, max_seconds=0.05))
    assert not slow["warm"] and slow["batch_rounds"] == 1 and slow_rec.calls == 1
    assert slow["throughput_rps"] == pytest.approx(8 / 0.06)  # then the warm-up batch is the measurement


def test_other_load_is_the_busy_time_not_spent_by_this_process() -> None:
    start = {"busy_s": 100.0, "steal_s": 1.0, "own_s": 10.0, "wall_s": 0.0}
    end = {"busy_s": 130.0, "steal_s": 1.0, "own_s": 30.0, "wall_s": 10.0}
    load = other_load(start, end)
    assert load["other_processes_cores"] == pytest.approx(1.0) and load["steal_share"] == 0.0
    assert other_load(None, end) is None and other_load(end, end) is None


def test_pose_table_compares_each_runtime_with_the_paper_preset_on_the_same_runtime() -> None:
    from tactile_manip.bench.report import pose_table

    def row(method, runtime, p50, pair=None, share=None):
        return {"method": method, "runtime": runtime, "pose_p50_ms": p50, "pose_p99_ms": p50 * 1.5,
                "pose_pair_p50_ms": pair, "pose_pair_p99_ms": None if pair is None else pair * 1.5,
                "postprocess_share": share}

    rows = [row("compact", "onnxruntime 1 thread", 2.0, 3.5, 0.21), row("compact", "onnxruntime 2 threads", 1.5),
            row("paper", "onnxruntime 1 thread", 100.0, 190.0, 0.01), {"method": "x", "runtime": "numpy"}]
    lines = pose_table(rows).splitlines()
    assert len(lines) == 5  # header, rule, three rows with a pose latency
    assert lines[2] == "| compact | onnxruntime 1 thread | 2.00 / 3.00 | 3.50 / 5.25 | 21% | 50x |"
    assert lines[3].endswith("| - | - | - |")  # no paper row on two threads: no ratio
    assert lines[4].endswith("| 1% | - |")


REFERENCES = "experiments/model_variants/bench.toml"
RESEARCH = "experiments/speed_reports/research_candidates.toml"


def test_the_bench_measures_the_default_model_and_its_references_from_their_file() -> None:
    from pathlib import Path

    from tactile_manip.bench.candidates import candidates_file, default_models

    root = Path(__file__).resolve().parents[2]
    assert [e.name for e in default_models(root)] == ["supermag"]
    entries = candidates_file(root / REFERENCES, root, default_models(root))
    assert [e.name for e in entries] == ["supermag", "fast", "compact", "robust"]
    assert all(e.path.is_file() and e.checkpoint is None for e in entries)   # nothing under runs/


def test_shipped_code_names_no_path_under_experiments() -> None:
    """The package finds only what it ships; a study's files reach it as arguments (``--candidates``)."""
    from pathlib import Path

    package = Path(__file__).resolve().parents[2] / "tactile_manip"
    offenders = [p.relative_to(package).as_posix() for p in sorted(package.rglob("*.py"))
                 if "experiments/" in p.read_text()]
    assert offenders == []


def test_default_models_include_the_decoder_candidates_on_one_thread_only(tiny_model, tmp_path) -> None:
    from pathlib import Path

    from tactile_manip.bench.candidates import ModelEntry, default_models, model_candidates

    root = Path(__file__).resolve().parents[2]
    from tactile_manip.bench.candidates import candidates_file

    references = candidates_file(root / REFERENCES, root, default_models(root))
    entries = {e.name: e for e in candidates_file(root / RESEARCH, root, references)}
    configs = sorted(p.stem for p in (root / "experiments" / "decoder_candidates").glob("decoder_*.toml"))
    assert configs and all(entries[c].runtimes == ("ort-1",) for c in configs)
    assert entries[configs[0]].untrained_preset.endswith(f"{configs[0]}.toml")  # timed untrained until trained
    assert entries["fast"].runtimes is None and entries["compact"].runtimes is None
    default = entries["supermag"]  # the default model, first; no torch row: its checkpoint has no angle head
    assert next(iter(entries)) == "supermag" and default.path == root / "models" / "supermag.onnx"
    assert default.symmetrized and default.checkpoint is None and default.runtimes is None
    assert entries["robust"].runtimes == ("ort-1",)  # the fast model's graph: its latency is the fast row's
    for run in ("fast_full", "fast40_full"):  # full-recipe runs: measured when trained, never exported untrained
        assert entries[run].runtimes == ("ort-1",) and entries[run].untrained_preset is None
    assert "fast_b48_full" not in entries  # the shipped model's own recipe is the "fast" row, not listed twice
    notes: list[str] = []
    entry = ModelEntry("candidate", tiny_model, runtimes=("ort-1",))
    found = model_candidates(entry, tmp_path, runtimes=("ort-1", "ort-all", "ort-int8"), notes=notes)
    assert [c.runtime for c in found] == ["onnxruntime 1 thread"]
    assert model_candidates(entry, tmp_path, runtimes=("ort-all",), notes=notes) == []


def test_a_candidates_file_adds_models_and_names_what_it_cannot_read(tmp_path) -> None:
    from pathlib import Path

    from tactile_manip.bench.candidates import ModelEntry, candidates_file
    from tactile_manip.errors import ConfigError

    (tmp_path / "configs").mkdir()
    for stem in ("mine_a", "mine_b"):
        (tmp_path / "configs" / f"{stem}.toml").write_text(f'preset = "fast"\nepochs = {len(stem)}\n')
    (tmp_path / "configs" / "same.toml").write_text('preset = "fast"\nepochs = 1\n')
    (tmp_path / "recipe.toml").write_text('# a copy with other comments\npreset = "fast"\nepochs = 1\n')
    good = tmp_path / "candidates.toml"
    good.write_text('[checkpoints]\nbase = "runs/base/best.pt"\n\n'
                    '[[model]]\nname = "big"\npath = "runs/big/model.onnx"\nuntrained = "paper"\n\n'
                    '[[runs]]\nconfigs = "configs/*.toml"\nsuffix = "_run"\nunless_recipe_of = "recipe.toml"\n')
    base = [ModelEntry("base", tmp_path / "base.onnx")]
    entries = {e.name: e for e in candidates_file(good, tmp_path, base)}
    assert list(entries) == ["base", "big", "mine_a_run", "mine_b_run"]  # same.toml is recipe.toml's values
    assert entries["base"].checkpoint == tmp_path / "runs" / "base" / "best.pt"
    assert entries["big"].untrained_preset == "paper" and entries["big"].checkpoint is None
    assert entries["mine_a_run"].path == tmp_path / "runs" / "mine_a" / "model.onnx"
    assert entries["mine_a_run"].runtimes == ("ort-1",) and entries["mine_a_run"].untrained_preset is None
    for text, problem in (('[[model]]\nname = "x"\npath = "x.onnx"\nthreads = 2\n', r"unknown key\(s\) threads"),
                          ('[checkpoints]\nnobody = "a.pt"\n', "names 'nobody', not one of the models"),
                          ('[[model]]\nname = "x"\n', "needs a name and a path"),
                          ('[bench]\n', r"unknown key\(s\) bench in the file")):
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        with pytest.raises(ConfigError, match=problem):
            candidates_file(bad, tmp_path, base)
    with pytest.raises(ConfigError, match="cannot read the bench candidates"):
        candidates_file(tmp_path / "missing.toml", tmp_path)
    assert Path(good).is_file()


def test_the_bench_refuses_a_model_named_twice_before_measuring(tmp_path, capsys) -> None:
    from checks import assert_one_line_error

    from tactile_manip.cli import main

    extra = tmp_path / "candidates.toml"
    extra.write_text('[[model]]\nname = "supermag"\npath = "models/supermag.onnx"\n')
    assert main(["bench", "--out", str(tmp_path / "b"), "--candidates", str(extra), "--quick"]) == 2
    assert_one_line_error(capsys.readouterr().err, "bench", "named more than once: supermag")
    assert not (tmp_path / "b").exists()
