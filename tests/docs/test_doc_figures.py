"""The figures the docs quote in their prose are those of the result files (benchmarks/doc_figures.py)."""

import json
import shutil

from benchmarks import doc_figures as df


def test_every_quoted_figure_matches_its_result_file():
    assert df.stale() == []


def test_a_moved_result_names_the_page_and_the_sentence_it_needs(tmp_path):
    for q in df.QUOTES:
        for path in (q.page, *(v.source for v in q.values)):
            (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(df.ROOT / path, tmp_path / path)
    results = json.loads((tmp_path / df.FEWLABEL).read_text())
    results["runs"]["normal_20250401_014340"]["25"]["per_seed"]["0"]["ours"] = 0.4444
    (tmp_path / df.FEWLABEL).write_text(json.dumps(results))
    problems = df.stale(tmp_path)
    assert problems and all(p.split(":")[0] in ("README.md", "docs/your_board.md") for p in problems)
    assert any("and 25 of the normal run 0.44 N" in p for p in problems)
    assert df.main(["--check", "--root", str(tmp_path)]) == 1


def test_a_key_that_holds_a_slash_is_given_as_a_tuple_of_keys(tmp_path):
    (tmp_path / "r.json").write_text(json.dumps({"forward": {"fitted, no labels/spatial": {"mm": 1.234}}}))
    assert df.Value("r.json", ("forward", "fitted, no labels/spatial", "mm")).text(tmp_path) == "1.23"
    try:  # split at every "/", the same path as a string misses the key
        df.Value("r.json", "forward/fitted, no labels/spatial/mm").read(tmp_path)
    except KeyError as e:
        assert "fitted, no labels" in str(e)
    else:
        raise AssertionError("a string path split a key that holds a slash")
