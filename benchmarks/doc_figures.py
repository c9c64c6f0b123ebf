"""The figures the docs quote in their prose, checked against the result files they come from.

    python -m benchmarks.doc_figures            # list every quoted figure, the text it expects and where
    python -m benchmarks.doc_figures --check    # exit 1, naming the page and the expected text, where a page
                                                # no longer says what its result file gives

The tables are generated (:mod:`benchmarks.results_tables`); a figure inside a sentence is written by hand, so
it is registered here instead: the page, the sentence with ``{}`` where each figure stands, and for each figure
the result file, the key path into it and the format. A re-run that moves a figure fails ``--check`` until the
sentence says the new value. White space (line breaks included) is compared loosely. CI runs ``--check``.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
FEWLABEL = "docs/results/contact/fewlabel_k.json"  # python -m benchmarks.fewlabel_k
DEPTH = "docs/results/benchmarks/depth.json"  # python -m benchmarks.bench_depth
SERVE = "docs/results/benchmarks/serve.json"  # python -m benchmarks.bench_serve --seconds 60
LAYOUT = "docs/results/eflesh/twin/chip_layout.json"  # python -m benchmarks.eflesh_chip_layout
TWIN = "docs/results/twin/twin_protocol.json"  # python -m benchmarks.twin_protocol
NO_LABELS = ("forward", "fitted, no labels/spatial")  # its zero-label row
SPATIAL, NORMAL = "runs/spatial_20250316_155729", "runs/normal_20250401_014340"


@dataclass(frozen=True)
class Value:
    """One figure: ``source`` (a JSON file under the repository), the key path into it (``/``-separated, or a tuple
    of keys where a key holds a ``/``), and the format of its text (e.g. ``.2f``)."""

    source: str
    path: str | tuple[str, ...]
    fmt: str = ".2f"

    def read(self, root: Path) -> Any:
        node = json.loads((root / self.source).read_text())
        for key in self.path.split("/") if isinstance(self.path, str) else self.path:
            node = node[key]
        return node

    def text(self, root: Path) -> str:
        return format(self.read(root), self.fmt)


@dataclass(frozen=True)
class Quote:
    """A sentence of ``page`` quoting ``values`` where its ``{}`` stand."""

    page: str
    sentence: str
    values: tuple[Value, ...]

    def expected(self, root: Path) -> str:
        return self.sentence.format(*(v.text(root) for v in self.values))


def _layout(name: str, label: str) -> Quote:
    """The row of your_board.md's table of chip layouts for layout ``name``."""
    rest = [Value(LAYOUT, f"layouts/{name}/rest/{run.split('/')[-1]}/rms_ut", ".0f") for run in (SPATIAL, NORMAL)]
    ev = [Value(LAYOUT, f"layouts/{name}/presses/{key}") for key in ("ev_fit_rows", "ev_test_tail")]
    return Quote("docs/your_board.md", f"| {label} | {{}}; {{}} | {{}}; {{}} |", (*rest, *ev))


def _few(run: str, k: str, method: str, seed: str | None = None, fmt: str = ".2f") -> Value:
    tail = f"per_seed/{seed}/{method}" if seed is not None else f"mean/{method}"
    return Value(FEWLABEL, f"{run}/{k}/{tail}", fmt)


QUOTES: tuple[Quote, ...] = (
    Quote("docs/ros2.md", "(estimate, four messages encoded and queued) p50 {} ms, p99 {} ms; to the last of its "
                          "messages handed to Zenoh p50 {} ms, p99 {} ms. Of that, the estimate alone is p50 {} ms "
                          "and publishing alone p50 {} ms (p99 {} ms).",
          (Value(SERVE, "latency/to_published_ms/p50"), Value(SERVE, "latency/to_published_ms/p99"),
           Value(SERVE, "latency/to_zenoh_ms/p50"), Value(SERVE, "latency/to_zenoh_ms/p99"),
           Value(SERVE, "latency/estimate_ms/p50"), Value(SERVE, "latency/publish_ms/p50"),
           Value(SERVE, "latency/publish_ms/p99"))),
    Quote("docs/ros2.md", "the slowest pad published {} readings per second (the simulated sensors ran at 125 Hz), "
                          "with {} gaps in the subscriber's sequence numbers over the 64 topics, {} messages dropped "
                          "and {} frames left untaken.",
          (Value(SERVE, "load/min_rate_hz", ".1f"), Value(SERVE, "load/total_gaps", "d"),
           Value(SERVE, "load/total_drops", "d"), Value(SERVE, "load/total_overflowed", "d"))),
    Quote("README.md", "eFlesh spatial run give {} mm (kNN on the same 25: {} mm; {} mm over two draws, 100 give {} mm), "
                       "against {} mm with all 3844",
          (_few(SPATIAL, "25", "ours", "0"), _few(SPATIAL, "25", "kNN", "0"), _few(SPATIAL, "25", "ours"),
           _few(SPATIAL, "100", "ours"), _few(SPATIAL, "all", "ours"))),
    Quote("README.md", "and 25 of the normal run {} N (kNN {} N; {} N over two draws)",
          (_few(NORMAL, "25", "ours", "0"), _few(NORMAL, "25", "kNN", "0"), _few(NORMAL, "25", "ours"))),
    Quote("docs/your_board.md", "25 labelled presses (seed 0) give {} mm 2-D position RMSE and {} N force RMSE on "
                                "the test rows, where `evaluate`'s kNN on the same 25 gives {} mm and {} N and its "
                                "MLP {} mm and {} N.",
          (_few(SPATIAL, "25", "ours", "0"), _few(NORMAL, "25", "ours", "0", ".3f"), _few(SPATIAL, "25", "kNN", "0"),
           _few(NORMAL, "25", "kNN", "0"), _few(SPATIAL, "25", "MLP", "0"), _few(NORMAL, "25", "MLP", "0"))),
    Quote("docs/your_board.md", "at K = 25 {} mm and {} N, kNN {} mm and {} N; 10 labels already give {} mm and {} N, "
                                "100 give {} mm and {} N",
          (_few(SPATIAL, "25", "ours"), _few(NORMAL, "25", "ours", fmt=".3f"), _few(SPATIAL, "25", "kNN"),
           _few(NORMAL, "25", "kNN"), _few(SPATIAL, "10", "ours", fmt=".1f"), _few(NORMAL, "10", "ours"),
           _few(SPATIAL, "100", "ours"), _few(NORMAL, "100", "ours"))),
    Quote("docs/perception.md", "a reading -> depth image p50 {} ms and a CPU-time p99 of {} ms on one thread, "
                                "against {} / {} ms for the four passes",
          (Value(DEPTH, "choices/none/p50_ms", ".1f"), Value(DEPTH, "choices/none/cpu_p99_ms", ".1f"),
           Value(DEPTH, "choices/rotations/p50_ms", ".1f"), Value(DEPTH, "choices/rotations/cpu_p99_ms", ".1f"))),
    Quote("README.md", "on the eFlesh development runs the fitted twin explains {} and {} of the held-out readings' "
                       "variance, where the best smooth map of the probe pose reaches {} and {}",
          tuple(Value(TWIN, path, ".3f") for path in (
              ("forward", "fitted, every label of the first 80 %/spatial", "test_ev"),
              ("forward", "fitted, every label of the first 80 %/normal", "test_ev"),
              ("limit", "spatial/sensor_post_baselines", "pose", "test_ev"),
              ("limit", "normal/sensor_post_baselines", "pose", "test_ev")))),
    Quote("README.md", "its places refitted on a smooth model of the real readings, places the spatial run's held-out "
                       "presses {} mm off (a contact network trained on its labels {} mm)",
          (Value(TWIN, (*NO_LABELS, "position_rmse_mm")), Value(TWIN, "contact/spatial/k/0/mean/twin"))),
    Quote("README.md", "with 25 labels {} mm and {} N on those runs today, with 10 labels {} mm against the "
                       "recipe's {} mm",
          (Value(TWIN, "contact/spatial/k/25/mean/twin"), Value(TWIN, "contact/normal/k/25/mean/twin"),
           Value(TWIN, "contact/spatial/k/10/mean/twin"), _few(SPATIAL, "10", "ours"))),
    Quote("docs/your_board.md", "At K = 25 (means of seeds 0 and 1): the spatial run's position {} mm ({} and {} mm;",
          tuple(Value(TWIN, f"contact/spatial/k/25/{tail}", ".3f") for tail in ("mean/twin", "per_seed/0/twin",
                                                                               "per_seed/1/twin"))),
    Quote("docs/your_board.md", "Its 961 test presses read backwards on it are {} mm RMS from the stage's positions",
          (Value(TWIN, (*NO_LABELS, "read_backwards_position_rmse_mm")),)),
    Quote("docs/your_board.md", "the models fitted on the first 80 %'s presses alone and the test presses placed on "
                                "them: **{} mm**",
          (Value(TWIN, (*NO_LABELS, "position_rmse_mm")),)),
    Quote("docs/your_board.md", "the contact network trained on those labels places the test presses **{} mm** off",
          (Value(TWIN, "contact/spatial/k/0/mean/twin"),)),
    _layout("former_file", "former board file (the AnySkin visualiser's turns)"),
    _layout("right_down_half_turn", "right and down chips half a turn"),
    _layout("mirror_image", "mirror image, or left-handed chips at the file's places"),
    _layout("upside_down", "the left-handed chips upside down, discs polarised -z: the board file"),
)


def _squeeze(text: str) -> str:
    return re.sub(r"\s+", " ", text)


def stale(root: Path = ROOT, quotes: tuple[Quote, ...] = QUOTES) -> list[str]:
    """One line per quote its page no longer holds: the page and the sentence it should hold."""
    problems, pages = [], {}
    for q in quotes:
        if q.page not in pages:
            pages[q.page] = _squeeze((root / q.page).read_text(encoding="utf-8"))
        try:
            expected = q.expected(root)
        except (OSError, KeyError, ValueError) as e:
            problems.append(f"{q.page}: cannot read a figure it quotes ({type(e).__name__}: {e})")
            continue
        if _squeeze(expected) not in pages[q.page]:
            problems.append(f"{q.page}: should say \"{expected}\" (from {', '.join(sorted({v.source for v in q.values}))})")
    return problems


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--check", action="store_true", help="exit 1 where a page no longer quotes its result file")
    p.add_argument("--root", default=str(ROOT), help="repository root (default: this checkout)")
    args = p.parse_args(argv)
    root = Path(args.root)
    if not args.check:
        for q in QUOTES:
            print(f"{q.page}: {q.expected(root)}")
        return 0
    problems = stale(root)
    for line in problems:
        print(line, file=sys.stderr)
    if problems:
        return 1
    print(f"doc_figures: {len(QUOTES)} quoted sentences match their result files")
    return 0


if __name__ == "__main__":
    sys.exit(main())
