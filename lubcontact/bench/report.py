"""The written outputs of ``lubcontact compare``: report text, CSV, JSON, figures, replot.

:func:`write_outputs` writes ``report.md`` (header with the command, machine,
versions and git state; definitions; tables; figures), ``results.csv`` (one
row per instance, solver and tolerance), ``results.json`` (the same with the
header's metadata and the reference rows) and the three figures of
:mod:`lubcontact.bench.figures`; :func:`replot` rewrites them from a
``results.json`` without solving.
"""
from __future__ import annotations

import csv
import json
import os
import platform
import subprocess
import time
from collections.abc import Sequence
from dataclasses import asdict, fields
from importlib import metadata
from pathlib import Path

import numpy as np

from ..cli import BLAS_THREADS
from .figures import error_label, iterations_figure, performance_profile_figure, work_precision_figure
from .problem_sets import ProblemSet
from .runs import WARM, Measurement, ReferenceRow
from .statistics import FAILURE_PENALTY, TIME_SHIFT, success_table, summary_rows
from .tables import format_table

PACKAGES = ("numpy", "scipy", "cvxpy", "clarabel", "osqp", "scs", "numba", "h5py", "matplotlib")


def environment() -> dict:
    """Machine, versions and git state, for the report header."""
    versions = {}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "absent"
    try:
        commit = subprocess.run(["git", "describe", "--always", "--dirty"],
                                cwd=Path(__file__).resolve().parent,
                                capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit = ""
    return dict(date=time.strftime("%Y-%m-%d %H:%M:%S %Z"), host=platform.node(),
                platform=platform.platform(), cpu=_cpu_name(), cpus=os.cpu_count(),
                usable_cpus=len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
                python=platform.python_version(), packages=versions, git=commit or "unknown",
                threads={k: os.environ.get(k, "unset") for k in BLAS_THREADS})


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


def _tol_columns(tolerances: Sequence[float]) -> list[str]:
    return ["solver"] + [f"{tol:.0e}" for tol in tolerances]


def report_text(problem_set: ProblemSet, rows: Sequence[Measurement],
                references: Sequence[ReferenceRow], labels: Sequence[str],
                tolerances: Sequence[float], meta: dict) -> str:
    """The markdown report of one set (``meta`` as :func:`lubcontact.bench.compare.compare_set` writes it)."""
    env, headline, reference = meta["environment"], meta["headline_tol"], meta["reference"]
    candidates = ", ".join(f"`{m}`" for m in reference["methods"])
    lines = [f"# Solver comparison: set `{problem_set.name}`", "",
             f"{problem_set.description}.", "",
             f"- command: `{meta['command']}`",
             f"- date: {env['date']}; git {env['git']}",
             f"- machine: {env['cpu']}, {env['usable_cpus']} usable of {env['cpus']} CPUs, "
             f"{env['platform']}, Python {env['python']}",
             "- packages: " + ", ".join(f"{k} {v}" for k, v in env["packages"].items()),
             "- threads: " + ", ".join(f"{k}={v}" for k, v in env["threads"].items()),
             f"- seeds: {problem_set.seeds or 'none (deterministic or read from files)'}",
             *([f"- problems read from: {meta['data_dir']}"] if meta.get("data_dir") else []),
             *([f"- peers: {meta['peers']}"] if meta.get("peers") else []),
             f"- instances left out (--max-contacts): {', '.join(meta.get('left_out') or []) or 'none'}",
             f"- solvers: {', '.join(labels)}; tolerances: "
             f"{', '.join(f'{t:.0e}' for t in tolerances)}; {meta['repeats']} timed repeats per "
             "solve (median reported, min/max in the CSV), after one untimed warm-up solve per "
             "solver", "",
             "## Definitions", "",
             f"- Reference: {candidates} at tol {reference['tol']:.0e} (column "
             "`reference_method`: `clarabel`, the primal form, on step problems, `clarabel-dual` "
             "on local problems, which have no primal form), run exactly like the solvers; "
             "Coulomb problems: fixed point on s around every solver, "
             f"`tol_fp = tol`, at most {reference['max_outer']} outer iterations.",
             f"- Primary error: {error_label(rows)}. Velocity error: `|v - v_ref| / |v_ref|`. "
             "FCLIB error: docs/guide/model.md section 6 on the normalised problem.",
             "  Where an instance has exact velocities (hard cases) they replace the reference.",
             f"- Success at tol: status `converged` and primary error <= {meta['slack']:g} x tol "
             "(for a problem without solution: a non-converged status with finite forces).",
             "- A solve that does not converge is not repeated; after `max_iter`, `diverged`, "
             "`failed` or an exception the solver is not run at tighter tolerances on that "
             "instance (status `skipped`, counted as failures).",
             f"- Time: wall-clock per call (set-up + solve + fixed point). Shifted geometric mean "
             f"with shift {TIME_SHIFT * 1e3:g} ms, a failed solve counting "
             f"{FAILURE_PENALTY:g} x the slowest solve of its instance; relative to the best.",
             "- Most negative gap after the step: column `min_gap` of the CSV, in units of dt V "
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
              "as the method reports them, summed over the inner solves of Coulomb's fixed point "
              "(its joint phase, which builds the matrices, counted as solve). `worst_gap`: the "
              "most negative gap after the step over all "
              "instances, in units of dt V (for local problems: most negative normal velocity / V).",
              "", _block(format_table(summary_rows(rows, labels, headline),
                                      ["solver", "median_setup_s", "median_solve_s",
                                       "median_time_s", "worst_gap"])), ""]
    lines += _warm_section(rows, labels, headline) + _problems_section(rows)
    lines += ["Raw results: `results.csv` (one row per instance, solver and tolerance) and "
              "`results.json` (the same with this header's metadata).", ""]
    return "\n".join(lines)


def _instance_section(references: Sequence[ReferenceRow]) -> list[str]:
    columns = ["instance", "group", "mode", "n_contacts", "n_rows", "reference_method",
               "reference_status",
               "reference_iterations", "reference_time_s", "reference_fclib_error"]
    if any(r.errors_against != "reference" for r in references):
        columns[5:5] = ["errors_against"]
        columns.append("reference_exact_error")
    lines = ["## Instances and reference", "", _block(format_table(references, columns)), ""]
    failed = [r.instance for r in references if r.reference_status != "converged"
              and r.errors_against == "reference"]
    if failed:
        lines += [f"**The reference did not converge on {len(failed)} instance(s): "
                  f"{', '.join(failed)}.** Velocity errors there are measured against its "
                  "unconverged (or missing) solution; the FCLIB error needs no reference.", ""]
    wrong = [f"{r.instance} ({r.reference_exact_error:.1e})" for r in references
             if r.reference_exact_error > 1e-6]
    if wrong:
        lines += [f"**The reference is off the exact velocities (relative error > 1e-6) on: "
                  f"{', '.join(wrong)}.** Errors there are measured against the exact answer.", ""]
    return lines


def _warm_section(rows: Sequence[Measurement], labels: Sequence[str], tol: float) -> list[str]:
    warm = [label for label in labels if label.endswith(WARM)]
    if not warm:
        return []
    table = []
    for label in warm:
        cold = label[: -len(WARM)]
        pick = {name: [r for r in rows if r.solver == name and r.tol == tol]
                for name in (cold, label)}
        its = {name: np.median([r.iterations for r in mine]) for name, mine in pick.items()}
        times = {name: np.median([r.time_s for r in mine]) for name, mine in pick.items()}
        table.append(dict(solver=cold, cold_iterations=its[cold], warm_iterations=its[label],
                          cold_time_s=times[cold], warm_time_s=times[label],
                          speedup=times[cold] / times[label] if times[label] > 0 else float("nan")))
    return [f"## Warm start (consecutive steps, tol {tol:.0e}, medians over steps)", "",
            "Warm start: the previous step's reference forces (and shift) matched by pair key.", "",
            _block(format_table(table, ["solver", "cold_iterations", "warm_iterations",
                                        "cold_time_s", "warm_time_s", "speedup"])), ""]


def _problems_section(rows: Sequence[Measurement]) -> list[str]:
    messages = sorted({(r.solver, r.message) for r in rows if r.message and r.status != "skipped"})
    unstable = sorted({r.solver for r in rows if not r.reproducible})
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


def write_outputs(out_dir: Path, problem_set: ProblemSet, rows: Sequence[Measurement],
                  references: Sequence[ReferenceRow], labels: Sequence[str],
                  tolerances: Sequence[float], meta: dict) -> Path:
    """Write report.md, results.csv, results.json and the three figures; returns the report path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    with open(out_dir / "results.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=[f.name for f in fields(Measurement)])
        writer.writeheader()
        writer.writerows(asdict(row) for row in rows)
    payload = dict(meta=meta, set=problem_set.name, description=problem_set.description,
                   seeds=problem_set.seeds, instances=[asdict(r) for r in references],
                   results=[asdict(r) for r in rows])
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
    rows = [Measurement(**row) for row in data["results"]]
    references = [ReferenceRow(**row) for row in data["instances"]]
    return write_outputs(Path(folder), problem_set, rows, references, meta["solvers"],
                         meta["tolerances"], meta)


def _json_default(value: object) -> object:
    """JSON form of numpy scalars (the only non-native values in rows and metadata)."""
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    raise TypeError(f"cannot serialise {type(value).__name__}")
