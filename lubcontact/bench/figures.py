"""Figures of a comparison report: work-precision, performance profiles, iterations against size.

Each takes the rows of :func:`lubcontact.bench.runs.run_set` and writes one
PNG (matplotlib, Agg backend).
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .problem_sets import COULOMB
from .runs import WARM, Measurement
from .statistics import penalised_times, performance_ratios, scaling_exponents, shifted_geometric_mean

if TYPE_CHECKING:
    from matplotlib.figure import Figure

ERROR_FLOOR = 1e-16        # zero errors are drawn at this value on log axes


def _pyplot():  # noqa: ANN202  (matplotlib.pyplot, imported here to keep the import lazy)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _styles(labels: Sequence[str]) -> dict[str, dict]:
    colors = [f"C{k % 10}" for k in range(len(labels))]
    markers = "osD^v<>phX*"
    return {label: dict(color=colors[k], marker=markers[k // 10 % len(markers)] if k >= 10 else
                        markers[k % len(markers)], linestyle="--" if label.endswith(WARM) else "-")
            for k, label in enumerate(labels)}


def error_label(rows: Sequence[Measurement]) -> str:
    """What the primary error of ``rows`` is (FCLIB error, velocity error or both)."""
    modes = {r.mode for r in rows}
    if modes == {COULOMB}:
        return "FCLIB error (docs/guide/model.md sec. 6, normalised, dimensionless)"
    if COULOMB in modes:
        return "error: FCLIB (Coulomb) or relative velocity error (dimensionless)"
    return "relative velocity error against Clarabel reference (dimensionless)"


def work_precision_figure(rows: Sequence[Measurement], labels: Sequence[str],
                          tolerances: Sequence[float], path: Path, title: str) -> None:
    """Median error against the shifted geometric mean time, one curve per solver over tolerances.

    Every point covers every instance: times are penalised as in the tables,
    and a solve without forces (exception, skipped) counts as an infinite
    error, so that a point is left out when half the instances or more have none.
    """
    plt = _pyplot()
    styles = _styles(labels)
    fig, ax = plt.subplots(figsize=(7.0, 4.8))
    sizes = np.linspace(9, 4, len(tolerances))
    times = {tol: penalised_times(rows, labels, tol) for tol in tolerances}
    for label in labels:
        points = []
        for tol, size in zip(tolerances, sizes):
            mine = [r for r in rows if r.solver == label and r.tol == tol]
            errors = np.array([r.error for r in mine], dtype=float)
            error = float(np.median(np.where(np.isfinite(errors), errors, np.inf)))
            if not np.isfinite(error):
                continue
            finite = times[tol][label][np.isfinite(times[tol][label])]
            points.append((max(error, ERROR_FLOOR), shifted_geometric_mean(finite), size,
                           all(r.success for r in mine)))
        if not points:
            continue
        style = styles[label]
        ax.plot([p[0] for p in points], [p[1] for p in points], color=style["color"],
                linestyle=style["linestyle"], linewidth=1, label=label)
        for x, y, size, ok in points:
            ax.plot(x, y, marker=style["marker"], markersize=size, color=style["color"],
                    markerfacecolor=style["color"] if ok else "white", linestyle="none")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(f"median {error_label(rows)}")
    ax.set_ylabel("time per solve, shifted geom. mean,\nfailures penalised [s]")
    ax.set_title(f"{title}: tol {tolerances[0]:.0e} (large marker) to {tolerances[-1]:.0e}; "
                 f"open = not all solves succeeded; zero error drawn at {ERROR_FLOOR:.0e}",
                 fontsize=8)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=7, ncol=2, loc="best")
    _save(fig, path)


def performance_profile_figure(rows: Sequence[Measurement], labels: Sequence[str],
                               tolerances: Sequence[float], path: Path, title: str) -> None:
    """Dolan-More performance profiles, one panel per tolerance."""
    plt = _pyplot()
    styles = _styles(labels)
    fig, axes = plt.subplots(1, len(tolerances), figsize=(2.6 * len(tolerances) + 1, 3.4),
                             sharey=True, squeeze=False)
    for ax, tol in zip(axes[0], tolerances):
        ratios = performance_ratios(rows, labels, tol)
        finite = np.concatenate([r[np.isfinite(r)] for r in ratios.values()] + [np.ones(1)])
        tau = np.logspace(0, max(np.log10(finite.max()) * 1.05, 0.1), 200)
        for label, r in ratios.items():
            rho = (r[None, :] <= tau[:, None]).mean(axis=1) if r.size else np.zeros_like(tau)
            ax.step(tau, rho, where="post", color=styles[label]["color"],
                    linestyle=styles[label]["linestyle"], label=label, linewidth=1)
        ax.set_xscale("log")
        ax.set_xlabel("time ratio to the fastest, tau [-]")
        ax.set_title(f"tol {tol:.0e}", fontsize=9)
        ax.set_ylim(-0.02, 1.02)
        ax.grid(True, alpha=0.3)
    axes[0][0].set_ylabel("fraction of instances solved [-]")
    axes[0][-1].legend(fontsize=6, loc="lower right")
    fig.suptitle(f"{title}: Dolan-More performance profiles (success as in the report)", fontsize=9)
    _save(fig, path)


def iterations_figure(rows: Sequence[Measurement], labels: Sequence[str], tol: float, path: Path,
                      title: str) -> None:
    """Iterations against problem size (force rows) at one tolerance."""
    plt = _pyplot()
    styles = _styles(labels)
    fig, ax = plt.subplots(figsize=(6.5, 4.4))
    for label in labels:
        style = styles[label]
        mine = [r for r in rows if r.solver == label and r.tol == tol and r.iterations >= 0]
        for k, group in enumerate(sorted({r.group for r in mine})):
            points = sorted((r.n_rows, max(r.iterations, 1), r.success) for r in mine
                            if r.group == group)
            sizes, iterations, _ = zip(*points)
            ax.plot(sizes, iterations, color=style["color"], linestyle=style["linestyle"],
                    linewidth=0.8, label=label if k == 0 else None)
            for x, y, good in points:
                ax.plot(x, y, marker=style["marker"], color=style["color"], linestyle="none",
                        markerfacecolor=style["color"] if good else "white", markersize=5)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("problem size: force unknowns (contact rows) [-]")
    ax.set_ylabel("iterations (total inner iterations) [-]")
    ax.set_title(f"{title}: iterations at tol {tol:.0e}; lines join instances of one family, "
                 "open = failed", fontsize=8)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    _save(fig, path)


def _save(fig: Figure, path: Path) -> None:
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    _pyplot().close(fig)


def scaling_figure(rows: Sequence[dict], path: Path) -> None:
    """Time per step against the number of grains on log-log axes, one curve per model,
    friction and method (the rows of ``lubcontact bench flow``), each labelled with its fitted
    exponent (:func:`~lubcontact.bench.statistics.scaling_exponents`)."""
    plt = _pyplot()
    exponents = scaling_exponents(rows)
    labels = sorted({(row["model"], row["friction"], row["method"]) for row in rows})
    styles = _styles([" ".join(label) for label in labels])
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for label in labels:
        points = sorted((row["n_grains"], row["s_per_step"]) for row in rows
                        if (row["model"], row["friction"], row["method"]) == label)
        name = " ".join(label)
        if label in exponents:
            name += f": N^{exponents[label]:.2f}"
        ax.plot(*zip(*points), label=name, **styles[" ".join(label)])
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("free grains N [-]")
    ax.set_ylabel("time per step, median [s]")
    ax.set_title("developed inclined flow: one step (contacts, assembly, solve, update)", fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    _save(fig, path)
