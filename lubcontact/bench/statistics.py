"""Statistics of comparison rows: shifted geometric means, penalised times, summaries, ratios.

All functions take the rows of :func:`lubcontact.bench.runs.run_set`
(:class:`~lubcontact.bench.runs.Measurement`) and the solver labels to cover.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .runs import Measurement

TIME_SHIFT = 1e-3          # s, shift of the geometric mean
FAILURE_PENALTY = 10.0     # a failed solve counts as this many times the slowest solve


@dataclass
class SolverSummary:
    """One solver at one tolerance, over every instance (:func:`summary_rows`).

    Attributes
    ----------
    solver : str
    success : float
        Fraction of successful solves.
    time_sgm_rel, time_sgm_s : float
        Shifted geometric mean of the penalised times, relative to the best
        solver and in seconds.
    median_error, median_iterations : float
        Medians over instances (NaN, or -1 for iterations, when none).
    timing_spread : float
        Median of ``(max - min) / median`` over repeated solves.
    median_setup_s, median_solve_s, median_time_s : float
    worst_gap : float
        Most negative gap after the step over instances.
    """

    solver: str
    success: float
    time_sgm_rel: float
    time_sgm_s: float
    median_error: float
    median_iterations: float
    timing_spread: float
    median_setup_s: float
    median_solve_s: float
    median_time_s: float
    worst_gap: float


def shifted_geometric_mean(times: np.ndarray, shift: float = TIME_SHIFT) -> float:
    """``exp(mean(log(t + shift))) - shift`` (seconds)."""
    times = np.asarray(times, dtype=float)
    return float(np.exp(np.mean(np.log(times + shift))) - shift)


def penalised_times(rows: Sequence[Measurement], labels: Sequence[str],
                    tol: float) -> dict[str, np.ndarray]:
    """Per solver, the time on each instance at ``tol``; failures count ``FAILURE_PENALTY x`` the slowest."""
    at_tol = [r for r in rows if r.tol == tol]
    instances = sorted({r.instance for r in at_tol})
    table = {(r.solver, r.instance): r for r in at_tol}
    out = {label: np.full(len(instances), np.nan) for label in labels}
    for k, name in enumerate(instances):
        measured = [table[(label, name)] for label in labels if (label, name) in table]
        slowest = max([r.time_s for r in measured if np.isfinite(r.time_s)], default=1.0)
        for r in measured:
            ok = r.success and np.isfinite(r.time_s)
            out[r.solver][k] = r.time_s if ok else FAILURE_PENALTY * slowest
    return out


def summary_rows(rows: Sequence[Measurement], labels: Sequence[str],
                 tol: float) -> list[SolverSummary]:
    """Per solver at ``tol``: success rate, relative shifted geometric mean time, medians."""
    times = penalised_times(rows, labels, tol)
    means = {label: shifted_geometric_mean(t[np.isfinite(t)]) for label, t in times.items()}
    best = min(means.values())
    out = []
    for label in labels:
        mine = [r for r in rows if r.tol == tol and r.solver == label]
        iterations = np.array([r.iterations for r in mine if r.iterations >= 0])
        spread = [(r.time_max_s - r.time_min_s) / r.time_s for r in mine
                  if r.repeats > 1 and r.time_s > 0]
        out.append(SolverSummary(
            solver=label, success=float(np.mean([r.success for r in mine])),
            time_sgm_rel=means[label] / best if best > 0 else float("nan"),
            time_sgm_s=means[label], median_error=_median([r.error for r in mine]),
            median_iterations=float(np.median(iterations)) if iterations.size else -1,
            timing_spread=float(np.median(spread)) if spread else float("nan"),
            median_setup_s=_median([r.setup_s for r in mine]),
            median_solve_s=_median([r.solve_s for r in mine]),
            median_time_s=_median([r.time_s for r in mine]),
            worst_gap=_finite(np.min, [r.min_gap for r in mine])))
    return out


def _finite(reduce: Callable[[np.ndarray], float], values: list[float]) -> float:
    """``reduce`` of the finite values (NaN when there are none)."""
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    return float(reduce(values)) if values.size else float("nan")


def _median(values: list[float]) -> float:
    """Median of the finite values (NaN when there are none)."""
    return _finite(np.median, values)


def success_table(rows: Sequence[Measurement], labels: Sequence[str], tolerances: Sequence[float],
                  key: str) -> list[dict]:
    """One row per solver, one column per tolerance (``"1e-06"``), of a :class:`SolverSummary` field."""
    table = {label: {"solver": label} for label in labels}
    for tol in tolerances:
        for entry in summary_rows(rows, labels, tol):
            table[entry.solver][f"{tol:.0e}"] = getattr(entry, key)
    return list(table.values())


def performance_ratios(rows: Sequence[Measurement], labels: Sequence[str],
                       tol: float) -> dict[str, np.ndarray]:
    """Dolan-More ratios ``t_s / min_s t_s`` per instance at ``tol`` (inf where the solve failed)."""
    at_tol = [r for r in rows if r.tol == tol]
    instances = sorted({r.instance for r in at_tol})
    table = {(r.solver, r.instance): r for r in at_tol}
    times = np.full((len(labels), len(instances)), np.inf)
    for i, label in enumerate(labels):
        for k, name in enumerate(instances):
            r = table.get((label, name))
            if r is not None and r.success and np.isfinite(r.time_s):
                times[i, k] = r.time_s
    best = times.min(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratios = np.where(np.isfinite(best), times / best, np.inf)
    return {label: ratios[i] for i, label in enumerate(labels)}


def power_law_exponent(sizes: Sequence[float], times: Sequence[float]) -> float:
    """Exponent ``a`` of the least-squares fit ``time = c size^a`` on log-log axes.

    Parameters
    ----------
    sizes, times : sequence of float, length k >= 2
        Positive sizes (at least two distinct) and times.

    Returns
    -------
    float
        The slope of ``log time`` against ``log size``.

    Raises
    ------
    ValueError
        For fewer than two distinct sizes, or a size or time that is not positive.
    """
    sizes, times = np.asarray(sizes, dtype=float), np.asarray(times, dtype=float)
    if sizes.shape != times.shape or np.unique(sizes).size < 2:
        raise ValueError(f"sizes: need at least two distinct sizes with a time each, got {sizes}")
    if not (np.all(sizes > 0) and np.all(times > 0)):
        raise ValueError(f"times: sizes and times must be > 0, got {sizes}, {times}")
    return float(np.polyfit(np.log(sizes), np.log(times), 1)[0])


def scaling_exponents(rows: Sequence[dict], keys: Sequence[str] = ("model", "friction", "method"),
                      size: str = "n_grains", time: str = "s_per_step") -> dict[tuple, float]:
    """:func:`power_law_exponent` of each curve of ``rows`` (rows grouped by ``keys``) that has
    two sizes or more."""
    curves: dict[tuple, list[tuple[float, float]]] = {}
    for row in rows:
        curves.setdefault(tuple(row[key] for key in keys), []).append((row[size], row[time]))
    return {label: power_law_exponent(*zip(*points)) for label, points in curves.items()
            if len({n for n, _ in points}) >= 2}
