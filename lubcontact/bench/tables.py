"""Text tables and solver comparisons shared by the demo, benchmarks and reports."""
from __future__ import annotations

import time
from typing import Iterable, Sequence

import numpy as np

from ..problem.metrics import relative_error
from ..problem.step import StepProblem
from ..solvers import solve


def format_table(rows: Iterable[dict], columns: Sequence[str], floats: str = ".3g") -> str:
    """A fixed-width text table of ``rows`` (dicts) restricted to ``columns``."""
    rows = list(rows)

    def cell(value) -> str:
        if isinstance(value, (float, np.floating)):
            return format(float(value), floats)
        return str(value)

    cells = [[cell(row.get(col, "")) for col in columns] for row in rows]
    widths = [max([len(col)] + [len(r[i]) for r in cells]) for i, col in enumerate(columns)]
    line = "  ".join(col.rjust(w) for col, w in zip(columns, widths))
    body = ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in cells]
    return "\n".join([line, "  ".join("-" * w for w in widths)] + body)


def compare_methods(problem: StepProblem, methods: Sequence[str], tol: float = 1e-6,
                    reference_velocities: np.ndarray | None = None) -> list[dict]:
    """Solve ``problem`` with each method; time, iterations and error against the reference.

    Parameters
    ----------
    problem : StepProblem
    methods : sequence of str
        Registered method names.
    tol : float
        Tolerance given to every method.
    reference_velocities : ndarray, optional
        Reference velocities; default: Clarabel at tol 1e-10 (polished).

    Returns
    -------
    list of dict
        One row per method: method, status, iterations, setup_s, solve_s, total_s,
        velocity_error, residual, min_gap.
    """
    if reference_velocities is None:
        reference_velocities = solve(problem, "clarabel", tol=1e-10).velocities
    rows = []
    for method in methods:
        start = time.perf_counter()
        result = solve(problem, method, tol=tol)
        total = time.perf_counter() - start
        gaps = problem.gaps_after(result.velocities)
        rows.append(dict(method=method, status=result.status, iterations=result.iterations,
                         setup_s=result.setup_time, solve_s=result.solve_time, total_s=total,
                         velocity_error=relative_error(result.velocities, reference_velocities),
                         residual=result.residual,
                         min_gap=float(gaps.min()) if gaps.size else 0.0))
    return rows
