"""Speed against error of every method and runtime: the harness behind ``tactile-manip bench``.

    python -m benchmarks.bench_report                         # full run into docs/results/benchmarks/report/
    python -m benchmarks.bench_report --quick --out /tmp/bench

Takes the options of ``tactile-manip bench`` (``tactile-manip bench --help``) and runs that command; the
harness lives in ``tactile_manip.bench`` so the installed command can use it. It measures; it asserts nothing.
"""

from __future__ import annotations

import sys

from tactile_manip.cli import main as cli_main


def main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if not any(a == "--out" or a.startswith("--out=") for a in args) and not {"-h", "--help"} & set(args):
        args += ["--out", "docs/results/benchmarks/report"]
    return cli_main(["bench", *args])


if __name__ == "__main__":
    raise SystemExit(main())
