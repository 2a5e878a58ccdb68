"""The plain-text tables every benchmark prints."""

from __future__ import annotations

from collections.abc import Sequence


def print_table(title: str | None, header: Sequence[str], rows: Sequence[Sequence[object]]) -> None:
    """Print `title` (if any), then `rows` under `header`, columns right-aligned, floats
    to 3 significant digits."""
    if title:
        print(f"\n{title}")
    cells = [list(header)]
    cells += [[f"{c:.3g}" if isinstance(c, float) else str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    for j, r in enumerate(cells):
        print("  " + "  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)))
        if j == 0:
            print("  " + "  ".join("-" * w for w in widths))
