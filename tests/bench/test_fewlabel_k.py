"""The K benchmark's table and plot, for both runs or one (``--run``), from a report (no training here)."""

from __future__ import annotations

import pytest

from benchmarks.fewlabel_k import RUNS, main, markdown, plot


def _report(runs):
    rows = {"10": {"mean": {"ours": 3.4, "kNN": 11.0, "MLP": 7.7}}, "25": {"mean": {"ours": 2.0, "kNN": 7.1, "MLP": 4.7}},
            "all": {"mean": {"ours": 0.48, "kNN": 1.19, "MLP": 0.82}}}
    return {"seeds": [0, 1], "runs": {run: rows for run in runs}, "train_presses": {run: 3844 for run in runs}}


@pytest.mark.parametrize("runs", [list(RUNS), list(RUNS)[1:]], ids=["both", "one"])
def test_the_table_and_the_plot_are_drawn_for_each_run_asked(runs, tmp_path) -> None:
    report = _report(runs)
    text = markdown(report)
    assert [line.split(":")[0].strip() for line in text.splitlines() if ": test RMSE" in line] == runs
    assert "| 25 | 2.000 | 7.100 | 4.700 |" in text
    plot(report, tmp_path / "k.png")
    assert (tmp_path / "k.png").stat().st_size > 1000


def test_an_unknown_run_is_refused_by_the_command_line(capsys) -> None:
    with pytest.raises(SystemExit) as stop:
        main(["--runs", "nowhere", "--run", "shear_20250401_000000"])
    assert stop.value.code == 2 and "invalid choice" in capsys.readouterr().err
