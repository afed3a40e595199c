"""Fixed-width text tables for the demo, the benchmarks and the reports."""
from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np


def format_table(rows: Iterable[Mapping[str, Any] | Any], columns: Sequence[str],
                 floats: str = ".3g") -> str:
    """A fixed-width text table of ``rows`` restricted to ``columns``.

    Parameters
    ----------
    rows : iterable of dict or dataclass instances
        One per line; a missing column is left empty.
    columns : sequence of str
        Keys (or field names), in order; also the header.
    floats : str
        Format of float cells.
    """
    rows = [row if isinstance(row, Mapping) else vars(row) for row in rows]

    def cell(value: object) -> str:
        if isinstance(value, (float, np.floating)):
            return format(float(value), floats)
        return str(value)

    cells = [[cell(row.get(col, "")) for col in columns] for row in rows]
    widths = [max([len(col)] + [len(r[i]) for r in cells]) for i, col in enumerate(columns)]
    line = "  ".join(col.rjust(w) for col, w in zip(columns, widths))
    body = ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in cells]
    return "\n".join([line, "  ".join("-" * w for w in widths)] + body)
