"""``tactile-manip params``: every simulator parameter with its default, unit, source and range."""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--markdown", action="store_true", help="print a markdown table")


def run(args: argparse.Namespace) -> int:
    from tactile_manip.boards import DEFAULT_BOARD, load_board
    from tactile_manip.sim.params import describe, for_board

    rows = describe(for_board(load_board(DEFAULT_BOARD)))  # the board's figures filled in: the SuperMag pad's
    if args.markdown:
        print("| parameter | default | unit | randomisation | source |\n|---|---|---|---|---|")
        for r in rows:
            rand = "" if r["rand"] is None else f"{r['rand'][0]:g} - {r['rand'][1]:g}"
            print(f"| `{r['name']}` | {r['value']} | {r['unit']} | {rand} | {r['source']} |")
        return 0
    for r in rows:
        rand = "fixed" if r["rand"] is None else f"{r['rand'][0]:g}..{r['rand'][1]:g}"
        print(f"{r['name']:<28} {str(r['value']):>10} {r['unit']:<12} {rand:<12} {r['source']}")
    return 0
