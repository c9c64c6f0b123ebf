"""Shared pieces of the benchmark harnesses: the machine description and the report writer."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tactile_manip.bench.machine import machine_info

__all__ = ["machine_info", "publish"]


def publish(report: dict[str, Any], out: str | Path, markdown: Callable[[dict[str, Any]], str]) -> None:
    """Print the report's markdown table and write it as JSON to ``out``."""
    print(markdown(report))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"\nwrote {out}")
