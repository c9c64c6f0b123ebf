"""The committed result tables (docs/results/tables/, README's headline) are what the result files give."""

import json
import shutil
from pathlib import Path

import pytest

from benchmarks import results_tables as rt

ROOT = Path(__file__).resolve().parents[2]


def test_committed_tables_match_the_result_files():
    diffs = rt.stale(ROOT)
    assert not diffs, "stale tables; run `python -m benchmarks.results_tables`:\n" + "\n".join(diffs.values())


@pytest.fixture()
def copy(tmp_path):
    """The result files, tables and README in a scratch root."""
    paths = {rt.TABLE1_DEFAULT, rt.TABLE1_DEFAULT.replace("results.json", "table.md"), rt.TABLE1, rt.TABLE1_MD, rt.TABLE1_ROBUST, rt.NETWORK_LATENCY, rt.BENCH, rt.INFORMATION, rt.README,
             rt.BENCH.replace("report.json", "report.md"), rt.BENCH_DEFAULT, rt.BENCH_DEFAULT.replace(".json", ".md"),
             rt.TABLE1_ROBUST.replace(".json", ".md"), *rt.ABLATIONS.values(),
             *(p.replace(".json", ".md") for p in rt.ABLATIONS.values()), *rt.SINGLE_FRAMES, *rt.CALIBRATIONS.values(),
             *(run.summary for run in rt.TRIAL_RUNS), *(rt._readable(run.summary, ROOT) for run in rt.TRIAL_RUNS),
             rt.FEWLABEL, rt.DEPTH, rt.DEPTH.replace(".json", ".md"), *(f"{rt.TABLES_DIR}/{name}" for name in rt.TABLES)}
    for path in paths:
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / path, tmp_path / path)
    return tmp_path


def test_the_copy_is_current(copy):
    assert rt.stale(copy) == {}


def test_check_fails_with_a_diff_when_a_result_changes(copy, capsys):
    results = json.loads((copy / rt.TABLE1_DEFAULT).read_text())   # the default model's evaluation
    row = next(r for r in results["results"] if r["method"] == rt.DEFAULT_EVAL)
    row["psnr_db_mean"] = 30.0
    (copy / rt.TABLE1_DEFAULT).write_text(json.dumps(results))
    assert rt.main(["--check", "--root", str(copy)]) == 1
    out, err = capsys.readouterr()
    assert any(line.startswith("+| depth image of") and "| 30.00 dB / " in line for line in out.splitlines())
    assert "README.md" in err and "docs/results/tables/headline.md" in err and "models.md" in err
    assert rt.main(["--root", str(copy)]) == 0  # regenerate: then the check passes
    assert rt.main(["--check", "--root", str(copy)]) == 0


def test_check_fails_when_a_table_is_edited_by_hand(copy, capsys):
    table = copy / rt.TABLES_DIR / "trials.md"
    lines = table.read_text().splitlines(keepends=True)
    row = next(i for i, line in enumerate(lines) if line.startswith("| `"))  # the first method's row
    lines[row] = lines[row].replace(" |", " (edited) |", 1)
    table.write_text("".join(lines))
    assert rt.main(["--check", "--root", str(copy)]) == 1
    out = capsys.readouterr().out
    assert f"-{lines[row]}" in out and f"+{lines[row].replace(' (edited) |', ' |', 1)}" in out


def test_trial_summary_in_markdown_reads_like_its_json(copy):
    run = rt.MAIN_JOB
    from_json = rt.trial_results(copy, run)
    md = rt.TrialRun(run.scene, run.summary.replace(".json", ".md"), run.models)
    (copy / md.summary).write_text((ROOT / md.summary).read_text())
    from_md = rt.trial_results(copy, md)
    assert from_md.keys() == from_json.keys()
    for m, r in from_json.items():
        assert (from_md[m].successes, from_md[m].n) == (r.successes, r.n)
        assert from_md[m].median_deg == pytest.approx(r.median_deg, abs=0.005)
        assert from_md[m].wilson == pytest.approx(r.wilson, abs=0.05)


def test_missing_markers_are_an_error(copy, capsys):
    readme = copy / rt.README
    readme.write_text(readme.read_text().replace(rt.README_START, ""))
    assert rt.main(["--check", "--root", str(copy)]) == 2
    assert "no <!-- tables:headline:start -->" in capsys.readouterr().err


def test_every_method_names_its_model(copy, capsys):
    results = json.loads((copy / rt.TABLE1).read_text())
    next(r for r in results["results"] if r["method"].startswith("SuperMag compact"))["method"] = "SuperMag tiny"
    (copy / rt.TABLE1).write_text(json.dumps(results))
    assert rt.main(["--check", "--root", str(copy)]) == 2
    assert "'SuperMag tiny' is not in EVAL_MODELS" in capsys.readouterr().err
