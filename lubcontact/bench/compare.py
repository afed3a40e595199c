"""Solver comparison reports: ``lubcontact compare [--set NAME ...] [--solvers ...] [--tolerances ...]``.

For every problem set (:mod:`lubcontact.problem_sets`), every registered
solver (:func:`lubcontact.solvers.methods`) and every tolerance, each
instance is solved ``repeats`` times; the report goes to
``<out>/<set>/report.md`` with PNG figures, ``results.csv`` and
``results.json`` (one row per instance, solver and tolerance).

Definitions (also written in each report):

- reference: Clarabel at tolerance ``1e-10`` (``clarabel``, the primal form,
  or ``clarabel-dual`` for local problems that have no primal form), run
  exactly like the solvers (fixed point on s with ``tol_fp = tol`` for
  Coulomb problems); exact velocities replace it where known (hard cases);
- velocity error: ``|v - v_ref| / |v_ref|`` (velocities of the step, or local
  velocities ``u = W r + q`` for FCLIB/Siconos problems);
- FCLIB error: MODEL.md section 6, on the normalised problem (unit-free);
- primary error: the FCLIB error for Coulomb problems (it needs no
  reference), the velocity error for convex (frictionless, gluey) ones;
- success at tolerance ``tol``: status ``converged`` and primary error
  ``<= slack x tol`` (slack 100 by default);
- shifted geometric mean of time (as in qpbenchmark):
  ``exp(mean log(t + 1 ms)) - 1 ms`` over instances, a failed solve counting
  as ``10 x`` the slowest solve of that instance and tolerance; reported
  relative to the best solver;
- time: wall-clock of the whole call, median of the repeats (min and max
  reported); set-up and solve times are the method's own split.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
import os
import platform
import shlex
import subprocess
import sys
import time
import warnings
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

import numpy as np

from . import problem_sets
from .problem_sets import COULOMB, Instance, ProblemSet, SetUnavailable
from ..problem.metrics import most_negative_gap, relative_error, scaled_coulomb_error
from .tables import format_table

# the first of these that accepts the problem (the primal form needs a StepProblem)
REFERENCE_METHODS = ("clarabel", "clarabel-dual")
REFERENCE_TOL = 1e-10
DEFAULT_TOLERANCES = (1e-2, 1e-4, 1e-6, 1e-8, 1e-10)
HEADLINE_TOL = 1e-6
MAX_OUTER = 100            # outer iterations of the fixed point on s
SUCCESS_SLACK = 100.0
TIME_SHIFT = 1e-3          # s, shift of the geometric mean
FAILURE_PENALTY = 10.0     # a failed solve counts as this many times the slowest solve
ERROR_FLOOR = 1e-16        # zero errors are drawn at this value on log axes
WARM = "+warm"
# statuses after which tighter tolerances cannot do better (an "inaccurate" loose solve can)
EXHAUSTED = ("max_iter", "diverged", "failed", "error")
PACKAGES = ("numpy", "scipy", "cvxpy", "clarabel", "osqp", "scs", "numba", "h5py", "matplotlib")


@dataclass(frozen=True)
class Variant:
    """A solver as compared: a registered method, cold or warm-started."""

    method: str
    warm: bool = False

    @property
    def label(self) -> str:
        return self.method + (WARM if self.warm else "")


# -- solving -------------------------------------------------------------------------------------
def run_once(instance: Instance, method: str, tol: float, warm: bool = False,
             max_iter: int | None = None):
    """One solve of ``instance`` as its mode says; returns ``(CoulombResult, wall seconds)``."""
    from ..solvers import SolveSettings

    settings = SolveSettings(method=method, tol=tol, max_iter=max_iter,
                             exact_coulomb=instance.mode == COULOMB, tol_fp=tol,
                             max_outer=MAX_OUTER)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = settings.solve(instance.problem, instance.warm_start if warm else None,
                                instance.warm_shift if warm else None)
    return result, time.perf_counter() - start


def measure(instance: Instance, variant: Variant, tol: float, reference, repeats: int,
            max_iter: int | None, slack: float) -> dict:
    """Solve ``repeats`` times; one result row (errors and iterations from the first solve)."""
    walls, setups, solves, signatures, first, message = [], [], [], [], None, ""
    for _ in range(repeats):
        try:
            result, wall = run_once(instance, variant.method, tol, variant.warm, max_iter)
        except Exception as exc:  # noqa: BLE001  (a solver's failure is a result to report)
            message = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
            break
        first = first or result
        walls.append(wall)
        split = instance.mode != COULOMB   # solve_coulomb reports the last inner solve's split only
        setups.append(result.setup_time if split else float("nan"))
        solves.append(result.solve_time if split else float("nan"))
        signatures.append((result.iterations, result.status, result.x.tobytes()))
        if result.status != "converged":
            break   # a failure is penalised, not timed: no repeats
    row = dict(instance=instance.name, group=instance.group, mode=instance.mode,
               n_contacts=instance.n_contacts, n_rows=instance.n_rows, solver=variant.label,
               method=variant.method, warm=variant.warm, tol=tol, repeats=len(walls))
    if first is None:
        return {**row, **_failed_metrics(), "status": "error", "message": message}
    row.update(status=first.status, iterations=int(first.iterations),
               outer_iterations=int(first.outer_iterations),
               time_s=float(np.median(walls)), time_min_s=float(np.min(walls)),
               time_max_s=float(np.max(walls)), setup_s=float(np.median(setups)),
               solve_s=float(np.median(solves)), residual=float(first.residual),
               reproducible=len(set(signatures)) == 1, message=message)
    row.update(_errors(instance, first, reference))
    row["error"] = row["fclib_error"] if instance.mode == COULOMB else row["velocity_error"]
    if instance.must_flag:
        row["success"] = bool(first.status != "converged" and np.all(np.isfinite(first.x)))
    else:
        row["success"] = bool(first.status == "converged" and row["error"] <= slack * tol)
    return row


def skipped(instance: Instance, variant: Variant, tol: float, failed_at: float) -> dict:
    """The row of a solve not run because the same solver failed at a looser tolerance."""
    return dict(instance=instance.name, group=instance.group, mode=instance.mode,
                n_contacts=instance.n_contacts, n_rows=instance.n_rows, solver=variant.label,
                method=variant.method, warm=variant.warm, tol=tol, repeats=0,
                **_failed_metrics(), status="skipped",
                message=f"not run: did not converge at the looser tol {failed_at:.0e}")


def _failed_metrics() -> dict:
    nan = float("nan")
    return dict(iterations=-1, outer_iterations=-1, time_s=nan, time_min_s=nan, time_max_s=nan,
                setup_s=nan, solve_s=nan, residual=nan, velocity_error=nan, fclib_error=nan,
                min_gap=nan, error=nan, success=False, reproducible=True)


def _target_velocities(instance: Instance, reference) -> np.ndarray | None:
    """Exact velocities when known, else the reference's (None when unusable or infeasible)."""
    if instance.must_flag:
        return None
    if instance.exact is not None:
        return instance.exact
    if reference is None or not np.all(np.isfinite(reference.velocities)):
        return None
    return reference.velocities


def _errors(instance: Instance, result, reference) -> dict:
    problem = instance.problem
    finite = bool(np.all(np.isfinite(result.x)) and np.all(np.isfinite(result.velocities)))
    target = _target_velocities(instance, reference)
    nan = float("nan")
    return dict(velocity_error=relative_error(result.velocities, target)
                if finite and target is not None else nan,
                fclib_error=scaled_coulomb_error(problem, result.x) if finite else nan,
                min_gap=most_negative_gap(problem, result.velocities) if finite else nan)


def reference_solve(instance: Instance, max_iter: int | None) -> tuple[object, dict]:
    """Clarabel at ``REFERENCE_TOL``; returns the result (None if it raised) and a summary row."""
    row = dict(instance=instance.name, group=instance.group, mode=instance.mode,
               n_contacts=instance.n_contacts, n_rows=instance.n_rows,
               warm_start=instance.warm_start is not None,
               errors_against="no solution (must flag)" if instance.must_flag else
               "exact velocities" if instance.exact is not None else "reference")
    nan = float("nan")
    try:
        method, result, wall = _first_accepted(instance, max_iter)
    except Exception as exc:  # noqa: BLE001
        return None, {**row, "reference_method": "none", "reference_status": f"error: {exc}",
                      "reference_time_s": nan, "reference_iterations": -1,
                      "reference_fclib_error": nan, "reference_exact_error": nan}
    row["reference_method"] = method
    exact_error = relative_error(result.velocities, instance.exact) \
        if instance.exact is not None and np.all(np.isfinite(result.velocities)) else nan
    return result, {**row, "reference_status": result.status, "reference_time_s": wall,
                    "reference_iterations": int(result.iterations),
                    "reference_fclib_error": scaled_coulomb_error(instance.problem, result.x)
                    if np.all(np.isfinite(result.x)) else nan,
                    "reference_exact_error": exact_error}


def _first_accepted(instance: Instance, max_iter: int | None):
    """``(method, result, wall)`` of the first reference method that accepts the problem."""
    from ..solvers import methods as registered

    candidates = [m for m in REFERENCE_METHODS if m in registered()]
    for method in candidates[:-1]:
        try:
            return (method, *run_once(instance, method, REFERENCE_TOL, max_iter=max_iter))
        except ValueError:
            continue
    return (candidates[-1], *run_once(instance, candidates[-1], REFERENCE_TOL, max_iter=max_iter))


def variants(methods: list[str], instances: list[Instance]) -> list[Variant]:
    """Cold variants of every method, plus warm ones when every instance has a warm start."""
    out = [Variant(m) for m in methods]
    if all(instance.warm_start is not None for instance in instances):
        out += [Variant(m, warm=True) for m in methods]
    return out


def warm_up(instance: Instance, methods: list[str]) -> None:
    """Solve once with each method so that JIT compilation and imports are not timed."""
    for method in methods:
        try:
            run_once(instance, method, 1e-4)
        except Exception:  # noqa: BLE001  (failures are measured and reported later)
            pass


def run_set(instances: list[Instance], methods: list[str], tolerances: list[float], repeats: int,
            max_iter: int | None = None, slack: float = SUCCESS_SLACK,
            log=None) -> tuple[list[dict], list[dict]]:
    """Measure every variant on every instance at every tolerance.

    Returns
    -------
    rows : list of dict
        One per instance, variant and tolerance (see :func:`measure`).
    references : list of dict
        One per instance: the reference's status, time and iterations.
    """
    warm_up(min(instances, key=lambda i: i.n_rows), methods)
    rows, references = [], []
    for instance in instances:
        reference, summary = reference_solve(instance, max_iter)
        references.append(summary)
        _log(log, f"{instance.name}: {instance.n_contacts} contacts, reference "
                  f"{summary['reference_status']} in {summary['reference_time_s']:.3g} s")
        for variant in variants(methods, instances):
            failed_at = None
            for tol in tolerances:
                if failed_at is None:
                    rows.append(measure(instance, variant, tol, reference, repeats, max_iter,
                                        slack))
                    failed_at = tol if rows[-1]["status"] in EXHAUSTED else None
                else:
                    rows.append(skipped(instance, variant, tol, failed_at))
            last = rows[-1]
            _log(log, f"  {variant.label:<18} tol {last['tol']:.0e}: {last['status']:<10} "
                      f"{last['iterations']:>6} it  {last['time_s']:.3g} s  error {last['error']:.2e}")
    return rows, references


def _log(log, text: str) -> None:
    if log is not None:
        print(text, file=log, flush=True)


# -- statistics ----------------------------------------------------------------------------------
def shifted_geometric_mean(times: np.ndarray, shift: float = TIME_SHIFT) -> float:
    """``exp(mean(log(t + shift))) - shift`` (seconds)."""
    times = np.asarray(times, dtype=float)
    return float(np.exp(np.mean(np.log(times + shift))) - shift)


def penalised_times(rows: list[dict], labels: list[str], tol: float) -> dict[str, np.ndarray]:
    """Per solver, the time on each instance at ``tol``; failures count ``FAILURE_PENALTY x`` the slowest."""
    at_tol = [r for r in rows if r["tol"] == tol]
    instances = sorted({r["instance"] for r in at_tol})
    table = {(r["solver"], r["instance"]): r for r in at_tol}
    out = {label: np.full(len(instances), np.nan) for label in labels}
    for k, name in enumerate(instances):
        measured = [table[(label, name)] for label in labels if (label, name) in table]
        slowest = max([r["time_s"] for r in measured if np.isfinite(r["time_s"])], default=1.0)
        for r in measured:
            ok = r["success"] and np.isfinite(r["time_s"])
            out[r["solver"]][k] = r["time_s"] if ok else FAILURE_PENALTY * slowest
    return out


def summary_rows(rows: list[dict], labels: list[str], tol: float) -> list[dict]:
    """Per solver at ``tol``: success rate, relative shifted geometric mean time, medians."""
    times = penalised_times(rows, labels, tol)
    means = {label: shifted_geometric_mean(t[np.isfinite(t)]) for label, t in times.items()}
    best = min(means.values())
    out = []
    for label in labels:
        mine = [r for r in rows if r["tol"] == tol and r["solver"] == label]
        iterations = np.array([r["iterations"] for r in mine if r["iterations"] >= 0])
        spread = [(r["time_max_s"] - r["time_min_s"]) / r["time_s"] for r in mine
                  if r["repeats"] > 1 and r["time_s"] > 0]
        out.append(dict(solver=label, success=np.mean([r["success"] for r in mine]),
                        time_sgm_rel=means[label] / best if best > 0 else float("nan"),
                        time_sgm_s=means[label],
                        median_error=_median([r["error"] for r in mine]),
                        median_iterations=float(np.median(iterations)) if iterations.size else -1,
                        timing_spread=float(np.median(spread)) if spread else float("nan"),
                        median_setup_s=_median([r["setup_s"] for r in mine]),
                        median_solve_s=_median([r["solve_s"] for r in mine]),
                        median_time_s=_median([r["time_s"] for r in mine]),
                        worst_gap=_finite(np.min, [r["min_gap"] for r in mine])))
    return out


def _finite(reduce, values: list[float]) -> float:
    """``reduce`` of the finite values (NaN when there are none)."""
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    return float(reduce(values)) if values.size else float("nan")


def _median(values: list[float]) -> float:
    """Median of the finite values (NaN when there are none)."""
    return _finite(np.median, values)


def success_table(rows: list[dict], labels: list[str], tolerances: list[float],
                  key: str) -> list[dict]:
    """One row per solver, one column per tolerance, of a :func:`summary_rows` field."""
    table = {label: {"solver": label} for label in labels}
    for tol in tolerances:
        for entry in summary_rows(rows, labels, tol):
            table[entry["solver"]][f"{tol:.0e}"] = entry[key]
    return list(table.values())


def performance_ratios(rows: list[dict], labels: list[str], tol: float) -> dict[str, np.ndarray]:
    """Dolan-More ratios ``t_s / min_s t_s`` per instance at ``tol`` (inf where the solve failed)."""
    at_tol = [r for r in rows if r["tol"] == tol]
    instances = sorted({r["instance"] for r in at_tol})
    table = {(r["solver"], r["instance"]): r for r in at_tol}
    times = np.full((len(labels), len(instances)), np.inf)
    for i, label in enumerate(labels):
        for k, name in enumerate(instances):
            r = table.get((label, name))
            if r is not None and r["success"] and np.isfinite(r["time_s"]):
                times[i, k] = r["time_s"]
    best = times.min(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratios = np.where(np.isfinite(best), times / best, np.inf)
    return {label: ratios[i] for i, label in enumerate(labels)}


# -- figures -------------------------------------------------------------------------------------
def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _styles(labels: list[str]) -> dict[str, dict]:
    colors = [f"C{k % 10}" for k in range(len(labels))]
    markers = "osD^v<>phX*"
    return {label: dict(color=colors[k], marker=markers[k // 10 % len(markers)] if k >= 10 else
                        markers[k % len(markers)], linestyle="--" if label.endswith(WARM) else "-")
            for k, label in enumerate(labels)}


def error_label(rows: list[dict]) -> str:
    modes = {r["mode"] for r in rows}
    if modes == {COULOMB}:
        return "FCLIB error (MODEL.md sec. 6, normalised, dimensionless)"
    if COULOMB in modes:
        return "error: FCLIB (Coulomb) or relative velocity error (dimensionless)"
    return "relative velocity error against Clarabel reference (dimensionless)"


def work_precision_figure(rows: list[dict], labels: list[str], tolerances: list[float],
                          path: Path, title: str) -> None:
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
            mine = [r for r in rows if r["solver"] == label and r["tol"] == tol]
            errors = np.array([r["error"] for r in mine], dtype=float)
            error = float(np.median(np.where(np.isfinite(errors), errors, np.inf)))
            if not np.isfinite(error):
                continue
            finite = times[tol][label][np.isfinite(times[tol][label])]
            points.append((max(error, ERROR_FLOOR), shifted_geometric_mean(finite), size,
                           all(r["success"] for r in mine)))
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


def performance_profile_figure(rows: list[dict], labels: list[str], tolerances: list[float],
                               path: Path, title: str) -> None:
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


def iterations_figure(rows: list[dict], labels: list[str], tol: float, path: Path,
                      title: str) -> None:
    """Iterations against problem size (force rows) at one tolerance."""
    plt = _pyplot()
    styles = _styles(labels)
    fig, ax = plt.subplots(figsize=(6.5, 4.4))
    for label in labels:
        style = styles[label]
        mine = [r for r in rows if r["solver"] == label and r["tol"] == tol and r["iterations"] >= 0]
        for k, group in enumerate(sorted({r["group"] for r in mine})):
            points = sorted((r["n_rows"], max(r["iterations"], 1), r["success"]) for r in mine
                            if r["group"] == group)
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


def _save(fig, path: Path) -> None:
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    _pyplot().close(fig)


# -- report --------------------------------------------------------------------------------------
def environment() -> dict:
    """Machine, versions and git state, for the report header."""
    versions = {}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "absent"
    try:
        commit = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=problem_sets.ROOT,
                                capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit = ""
    return dict(date=time.strftime("%Y-%m-%d %H:%M:%S %Z"), host=platform.node(),
                platform=platform.platform(), cpu=_cpu_name(), cpus=os.cpu_count(),
                usable_cpus=len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
                python=platform.python_version(), packages=versions, git=commit or "unknown",
                threads={k: os.environ.get(k, "unset") for k in
                         ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")})


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _block(text: str) -> str:
    return f"```\n{text}\n```"


def _tol_columns(tolerances: list[float]) -> list[str]:
    return ["solver"] + [f"{tol:.0e}" for tol in tolerances]


def report_text(problem_set: ProblemSet, rows: list[dict], references: list[dict],
                labels: list[str], tolerances: list[float], meta: dict) -> str:
    """The markdown report of one set."""
    env, headline = meta["environment"], meta["headline_tol"]
    lines = [f"# Solver comparison: set `{problem_set.name}`", "",
             f"{problem_set.description}.", "",
             f"- command: `{meta['command']}`",
             f"- date: {env['date']}; git {env['git']}",
             f"- machine: {env['cpu']}, {env['usable_cpus']} usable of {env['cpus']} CPUs, "
             f"{env['platform']}, Python {env['python']}",
             "- packages: " + ", ".join(f"{k} {v}" for k, v in env["packages"].items()),
             "- threads: " + ", ".join(f"{k}={v}" for k, v in env["threads"].items()),
             f"- seeds: {problem_set.seeds or 'none (deterministic or read from files)'}",
             f"- instances left out (--max-contacts): {', '.join(meta.get('left_out') or []) or 'none'}",
             f"- solvers: {', '.join(labels)}; tolerances: "
             f"{', '.join(f'{t:.0e}' for t in tolerances)}; {meta['repeats']} timed repeats per "
             "solve (median reported, min/max in the CSV), after one untimed warm-up solve per "
             "solver", "",
             "## Definitions", "",
             f"- Reference: `{REFERENCE_METHODS[0]}` at tol {REFERENCE_TOL:.0e}, or "
             f"`{REFERENCE_METHODS[1]}` where the first does not accept the problem (column "
             "`reference_method`), run exactly like the solvers; Coulomb problems: fixed point "
             "on s around every solver, "
             f"`tol_fp = tol`, at most {MAX_OUTER} outer iterations.",
             f"- Primary error: {error_label(rows)}. Velocity error: `|v - v_ref| / |v_ref|`. "
             "FCLIB error: MODEL.md section 6 on the normalised problem.",
             "  Where an instance has exact velocities (hard cases) they replace the reference.",
             f"- Success at tol: status `converged` and primary error <= {meta['slack']:g} x tol "
             "(for a problem without solution: a non-converged status with finite forces).",
             "- A solve that does not converge is not repeated; after `max_iter`, `diverged`, "
             "`failed` or an exception the solver is not run at tighter tolerances on that "
             "instance (status `skipped`, counted as failures).",
             f"- Time: wall-clock per call (set-up + solve + fixed point). Shifted geometric mean "
             f"with shift {TIME_SHIFT * 1e3:g} ms, a failed solve counting "
             f"{FAILURE_PENALTY:g} x the slowest solve of its instance; relative to the best.",
             f"- Most negative gap after the step: column `min_gap` of the CSV, in units of dt V "
             "(the normalised length).", ""]
    lines += _instance_section(references)
    lines += [f"## Headline (tol {headline:.0e})", "",
              _block(format_table(summary_rows(rows, labels, headline),
                                  ["solver", "success", "time_sgm_rel", "time_sgm_s",
                                   "median_error", "median_iterations", "timing_spread"])), "",
              "`timing_spread`: median over solves of (max - min) / median of the repeats "
              "(run-to-run noise).", "",
              "![work-precision](work_precision.png)", "",
              "## Success rate per tolerance", "",
              _block(format_table(success_table(rows, labels, tolerances, "success"),
                                  _tol_columns(tolerances), floats=".2f")), "",
              "## Shifted geometric mean of time, relative to the best", "",
              _block(format_table(success_table(rows, labels, tolerances, "time_sgm_rel"),
                                  _tol_columns(tolerances), floats=".3g")), "",
              "## Median error", "",
              _block(format_table(success_table(rows, labels, tolerances, "median_error"),
                                  _tol_columns(tolerances), floats=".2e")), "",
              "## Figures", "",
              "![performance profiles](performance_profile.png)", "",
              "![iterations against size](iterations.png)", ""]
    lines += [f"## Time split and feasibility (tol {headline:.0e}, medians over instances)", "",
              "Set-up (building the method's data, normalisation included) and solve (iterations) "
              "as the method reports them; empty for Coulomb problems, whose fixed point only "
              "has a wall time. `worst_gap`: the most negative gap after the step over all "
              "instances, in units of dt V (for local problems: most negative normal velocity / V).",
              "", _block(format_table(summary_rows(rows, labels, headline),
                                      ["solver", "median_setup_s", "median_solve_s",
                                       "median_time_s", "worst_gap"])), ""]
    lines += _warm_section(rows, labels, headline) + _problems_section(rows)
    lines += ["Raw results: `results.csv` (one row per instance, solver and tolerance) and "
              "`results.json` (the same with this header's metadata).", ""]
    return "\n".join(lines)


def _instance_section(references: list[dict]) -> list[str]:
    columns = ["instance", "group", "mode", "n_contacts", "n_rows", "reference_method",
               "reference_status",
               "reference_iterations", "reference_time_s", "reference_fclib_error"]
    if any(r["errors_against"] != "reference" for r in references):
        columns[5:5] = ["errors_against"]
        columns.append("reference_exact_error")
    lines = ["## Instances and reference", "", _block(format_table(references, columns)), ""]
    failed = [r["instance"] for r in references if r["reference_status"] != "converged"
              and r["errors_against"] == "reference"]
    if failed:
        lines += [f"**Clarabel did not converge on {len(failed)} instance(s): "
                  f"{', '.join(failed)}.** Velocity errors there are measured against its "
                  "unconverged (or missing) solution; the FCLIB error needs no reference.", ""]
    wrong = [f"{r['instance']} ({r['reference_exact_error']:.1e})" for r in references
             if r["reference_exact_error"] > 1e-6]
    if wrong:
        lines += [f"**Clarabel is off the exact velocities (relative error > 1e-6) on: "
                  f"{', '.join(wrong)}.** Errors there are measured against the exact answer.", ""]
    return lines


def _warm_section(rows: list[dict], labels: list[str], tol: float) -> list[str]:
    warm = [label for label in labels if label.endswith(WARM)]
    if not warm:
        return []
    table = []
    for label in warm:
        cold = label[: -len(WARM)]
        pick = {name: [r for r in rows if r["solver"] == name and r["tol"] == tol]
                for name in (cold, label)}
        its = {name: np.median([r["iterations"] for r in mine]) for name, mine in pick.items()}
        times = {name: np.median([r["time_s"] for r in mine]) for name, mine in pick.items()}
        table.append(dict(solver=cold, cold_iterations=its[cold], warm_iterations=its[label],
                          cold_time_s=times[cold], warm_time_s=times[label],
                          speedup=times[cold] / times[label] if times[label] > 0 else float("nan")))
    return [f"## Warm start (consecutive steps, tol {tol:.0e}, medians over steps)", "",
            "Warm start: the previous step's reference forces (and shift) matched by pair key.", "",
            _block(format_table(table, ["solver", "cold_iterations", "warm_iterations",
                                        "cold_time_s", "warm_time_s", "speedup"])), ""]


def _problems_section(rows: list[dict]) -> list[str]:
    messages = sorted({(r["solver"], r["message"]) for r in rows
                       if r["message"] and r["status"] != "skipped"})
    unstable = sorted({r["solver"] for r in rows if not r["reproducible"]})
    lines = []
    if messages:
        lines += ["## Solver errors (exceptions, counted as failures)", ""]
        lines += [f"- `{solver}`: {message}" for solver, message in messages] + [""]
    if unstable:
        lines += [f"**Not reproducible across repeats (iterations, status or forces differ): "
                  f"{', '.join(unstable)}.**", ""]
    else:
        lines += ["Every solve gave identical iterations, status and forces across its repeats.", ""]
    return lines


def write_outputs(out_dir: Path, problem_set: ProblemSet, rows: list[dict],
                  references: list[dict], labels: list[str], tolerances: list[float],
                  meta: dict) -> Path:
    """Write report.md, results.csv, results.json and the three figures; returns the report path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    with open(out_dir / "results.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    payload = dict(meta=meta, set=problem_set.name, description=problem_set.description,
                   seeds=problem_set.seeds, instances=references, results=rows)
    (out_dir / "results.json").write_text(json.dumps(payload, indent=1, default=_json_default))
    title = f"set {problem_set.name}"
    work_precision_figure(rows, labels, tolerances, out_dir / "work_precision.png", title)
    performance_profile_figure(rows, labels, tolerances, out_dir / "performance_profile.png", title)
    iterations_figure(rows, labels, meta["headline_tol"], out_dir / "iterations.png", title)
    path = out_dir / "report.md"
    path.write_text(report_text(problem_set, rows, references, labels, tolerances, meta))
    return path


def replot(folder: Path) -> Path:
    """Rewrite the report and figures of ``folder`` from its ``results.json`` (no solving)."""
    data = json.loads((Path(folder) / "results.json").read_text())
    problem_set = ProblemSet(data["set"], data["description"], build=list, seeds=data["seeds"])
    meta = data["meta"]
    return write_outputs(Path(folder), problem_set, data["results"], data["instances"],
                         meta["solvers"], meta["tolerances"], meta)


def _json_default(value):
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    raise TypeError(f"cannot serialise {type(value).__name__}")


# -- command line --------------------------------------------------------------------------------
def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="lubcontact compare", description=__doc__.split("\n")[0])
    p.add_argument("--set", dest="sets", action="append", metavar="NAME",
                   help=f"problem set (repeatable): {', '.join(problem_sets.SETS)}; default piles")
    p.add_argument("--solvers", nargs="+", metavar="METHOD",
                   help="registered methods (default: all of lubcontact.solvers.methods())")
    p.add_argument("--tolerances", nargs="+", type=float, metavar="TOL",
                   default=list(DEFAULT_TOLERANCES), help="default 1e-2 1e-4 1e-6 1e-8 1e-10")
    p.add_argument("--repeats", type=int, default=3, help="timed repeats per solve (default 3)")
    p.add_argument("--max-iter", type=int, default=None, help="iteration cap (method defaults)")
    p.add_argument("--slack", type=float, default=SUCCESS_SLACK,
                   help="success needs error <= slack x tol (default 100)")
    p.add_argument("--max-contacts", type=int, default=None, metavar="N",
                   help="leave out instances with more than N contacts (said in the report)")
    p.add_argument("--out", type=Path, default=Path("out/compare"), help="output folder")
    p.add_argument("--list", action="store_true", help="list the sets and exit")
    p.add_argument("--replot", type=Path, metavar="DIR",
                   help="rewrite report and figures from DIR/results.json, without solving")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    return p


def _check_args(args, available: list[str]) -> None:
    for name in args.sets:
        if name not in problem_sets.SETS:
            raise ValueError(f"--set: unknown set {name!r}; known: {', '.join(problem_sets.SETS)}")
    for method in args.solvers:
        if method not in available:
            raise ValueError(f"--solvers: unknown method {method!r}; registered: "
                             f"{', '.join(available)}")
    if args.repeats < 1:
        raise ValueError(f"--repeats: must be >= 1, got {args.repeats}")
    if not all(t > 0 and math.isfinite(t) for t in args.tolerances):
        raise ValueError(f"--tolerances: must be finite and > 0, got {args.tolerances}")


def compare_set(problem_set: ProblemSet, methods: list[str], tolerances: list[float],
                repeats: int, out_dir: Path, command: str, max_iter: int | None = None,
                slack: float = SUCCESS_SLACK, log=None, max_contacts: int | None = None) -> Path:
    """Build, measure and report one set; returns the report's path."""
    instances = problem_set.instances()
    left_out = [i.name for i in instances if max_contacts is not None and i.n_contacts > max_contacts]
    instances = [i for i in instances if i.name not in left_out]
    if not instances:
        raise SetUnavailable(f"every instance has more than {max_contacts} contacts")
    rows, references = run_set(instances, methods, tolerances, repeats, max_iter, slack, log)
    labels = [v.label for v in variants(methods, instances)]
    headline = HEADLINE_TOL if HEADLINE_TOL in tolerances else tolerances[len(tolerances) // 2]
    meta = dict(command=command, environment=environment(), repeats=repeats,
                tolerances=tolerances, solvers=labels, slack=slack, headline_tol=headline,
                reference=dict(methods=REFERENCE_METHODS, tol=REFERENCE_TOL, max_outer=MAX_OUTER),
                max_iter=max_iter, left_out=left_out)
    path = write_outputs(out_dir / problem_set.name, problem_set, rows, references, labels,
                         tolerances, meta)
    print(f"set {problem_set.name}: report written to {path}\n"
          f"headline, tol {headline:.0e}:\n" +
          format_table(summary_rows(rows, labels, headline),
                       ["solver", "success", "time_sgm_rel", "median_error", "median_iterations"]))
    return path


def main(argv: list[str] | None = None) -> int:
    from ..solvers import methods as registered

    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser().parse_args(argv)
    if args.list:
        for name, problem_set in problem_sets.SETS.items():
            print(f"{name:<18} {problem_set.description}")
        return 0
    if args.replot is not None:
        print(f"report rewritten: {replot(args.replot)}")
        return 0
    available = registered()
    args.sets = args.sets or ["piles"]
    args.solvers = args.solvers or available
    try:
        _check_args(args, available)
    except ValueError as exc:
        print(f"lubcontact compare: {exc}", file=sys.stderr)
        return 2
    command = shlex.join(["lubcontact", "compare", *argv])
    tolerances = sorted(set(args.tolerances), reverse=True)
    log = None if args.quiet else sys.stderr
    status = 0
    for name in args.sets:
        try:
            compare_set(problem_sets.SETS[name], args.solvers, tolerances, args.repeats,
                        args.out, command, args.max_iter, args.slack, log, args.max_contacts)
        except SetUnavailable as exc:
            print(f"lubcontact compare: skipping set {name!r}: {exc}", file=sys.stderr)
            status = 1
    return status
