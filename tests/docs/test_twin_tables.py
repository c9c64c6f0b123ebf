"""The twin's contact tables in docs/your_board.md are those the twin's benchmark wrote (twin_protocol.md)."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _tables(text: str) -> dict[str, str]:
    """Each run's contact table (its header line to the blank line after it), by the run's caption."""
    out = {}
    for caption in ("normal_20250401_014340: test RMSE, N (normal force)",
                    "spatial_20250316_155729: test RMSE, mm (2-D position)"):
        start = text.index("| K | twin", text.index(caption))
        end = text.find("\n\n", start)
        out[caption] = text[start:end if end >= 0 else len(text)].strip()
    return out


def test_your_board_quotes_the_twin_s_contact_tables_as_the_benchmark_wrote_them():
    page = (ROOT / "docs/your_board.md").read_text(encoding="utf-8")
    report = (ROOT / "docs/results/twin/twin_protocol.md").read_text(encoding="utf-8")
    assert _tables(page) == _tables(report)
