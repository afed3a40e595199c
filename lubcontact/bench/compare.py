"""Solver comparison reports: ``lubcontact compare [--set NAME ...] [--solvers ...] [--tolerances ...]``.

For every problem set (:mod:`lubcontact.bench.problem_sets`), every
registered solver (:func:`lubcontact.solvers.methods`) and every tolerance,
each instance is solved ``repeats`` times (:mod:`lubcontact.bench.runs`);
the report goes to ``<out>/<set>/report.md`` with PNG figures,
``results.csv`` and ``results.json`` (one row per instance, solver and
tolerance; :mod:`lubcontact.bench.report`).

Definitions (also written in each report):

- reference: the registry's :func:`lubcontact.solvers.reference_method`
  (``clarabel``, the primal form, or ``clarabel-dual`` for local problems
  that have no primal form) at tolerance ``1e-10``, run exactly like the solvers (fixed point on s with
  ``tol_fp = tol`` for Coulomb problems); exact velocities replace it where
  known (hard cases);
- velocity error: ``|v - v_ref| / |v_ref|`` (velocities of the step, or local
  velocities ``u = W r + q`` for FCLIB/Siconos problems);
- FCLIB error: docs/guide/model.md section 6, on the normalised problem (unit-free);
- primary error: the FCLIB error for Coulomb problems (it needs no
  reference), the velocity error for convex (frictionless, gluey) ones;
- success at tolerance ``tol``: status ``converged`` and primary error
  ``<= slack x tol`` (slack 100 by default);
- shifted geometric mean of time (as in qpbenchmark):
  ``exp(mean log(t + 1 ms)) - 1 ms`` over instances, a failed solve counting
  as ``10 x`` the slowest solve of that instance and tolerance; reported
  relative to the best solver (:mod:`lubcontact.bench.statistics`);
- time: wall-clock of the whole call, median of the repeats (min and max
  reported); set-up and solve times are the method's own split.

The external problems (sets ``siconos-fc2d``, ``fclib``) are read from
``--data-dir``, else ``LUBCONTACT_DATA_DIR``, else the package data
(:func:`lubcontact.bench.problem_sets.data_dir`).
"""
from __future__ import annotations

import argparse
import math
import shlex
import sys
from pathlib import Path
from typing import TextIO

from ..solvers import methods as registered
from ..solvers import reference_method
from ..solvers.siconos_peer import available_methods, register_siconos, siconos_status
from . import problem_sets
from .options import data_folder, given_methods, plain
from .problem_sets import PACKAGE_DATA, ProblemSet, SetUnavailable
from .report import environment, replot, write_outputs
from .runs import MAX_OUTER, REFERENCE_TOL, SUCCESS_SLACK, run_set, variants
from .statistics import summary_rows
from .tables import format_table

DEFAULT_TOLERANCES = (1e-2, 1e-4, 1e-6, 1e-8, 1e-10)
HEADLINE_TOL = 1e-6


def parser() -> argparse.ArgumentParser:
    """The options of ``lubcontact compare``."""
    p = argparse.ArgumentParser(prog="lubcontact compare", description=plain(__doc__.split("\n")[0]))
    p.add_argument("--set", dest="sets", action="append", metavar="NAME",
                   help=f"problem set (repeatable): {', '.join(problem_sets.SETS)}; default piles")
    p.add_argument("--solvers", nargs="+", metavar="METHOD",
                   help="registered methods, space or comma separated (default: all of "
                        "lubcontact.solvers.methods())")
    p.add_argument("--tolerances", nargs="+", type=float, metavar="TOL",
                   default=list(DEFAULT_TOLERANCES), help="default 1e-2 1e-4 1e-6 1e-8 1e-10")
    p.add_argument("--repeats", type=int, default=3, help="timed repeats per solve (default 3)")
    p.add_argument("--max-iter", type=int, default=None, help="iteration cap (method defaults)")
    p.add_argument("--slack", type=float, default=SUCCESS_SLACK,
                   help="success needs error <= slack x tol (default 100)")
    p.add_argument("--max-contacts", type=int, default=None, metavar="N",
                   help="leave out instances with more than N contacts (said in the report)")
    p.add_argument("--data-dir", type=Path, default=None, metavar="DIR",
                   help="folder of the external problems (siconos-fc2d/, fclib-local/); default "
                        f"${problem_sets.DATA_DIR_ENV}, else the package data")
    p.add_argument("--out", type=Path, default=Path("out/compare"), help="output folder")
    p.add_argument("--list", action="store_true", help="list the sets and exit")
    p.add_argument("--replot", type=Path, metavar="DIR",
                   help="rewrite report and figures from DIR/results.json, without solving")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    return p


def _check_args(args: argparse.Namespace) -> None:
    """Raise ``ValueError`` (naming the option) for a bad argument."""
    for name in args.sets:
        if name not in problem_sets.SETS:
            raise ValueError(f"--set: unknown set {name!r}; known: {', '.join(problem_sets.SETS)}")
    if args.repeats < 1:
        raise ValueError(f"--repeats: must be >= 1, got {args.repeats}")
    if args.max_iter is not None and args.max_iter < 1:
        raise ValueError(f"--max-iter: must be >= 1, got {args.max_iter}")
    if not all(t > 0 and math.isfinite(t) for t in args.tolerances):
        raise ValueError(f"--tolerances: must be finite and > 0, got {args.tolerances}")


def compare_set(problem_set: ProblemSet, methods: list[str], tolerances: list[float],
                repeats: int, out_dir: Path, command: str, max_iter: int | None = None,
                slack: float = SUCCESS_SLACK, log: TextIO | None = None,
                max_contacts: int | None = None, data: Path | None = None) -> Path:
    """Build, measure and report one set; returns the report's path.

    Parameters
    ----------
    problem_set : ProblemSet
    methods : list of str
        Registered methods (warm variants are added for sequences).
    tolerances : list of float
        From loose to tight.
    repeats : int
        Timed solves per instance, variant and tolerance.
    out_dir : Path
        The report goes to ``out_dir / problem_set.name``.
    command : str
        The command line, written in the report.
    max_iter : int, optional
        Iteration cap of every solve.
    slack : float
        Success needs ``error <= slack x tol``.
    log : text stream, optional
        Progress lines.
    max_contacts : int, optional
        Leave out instances with more contacts.
    data : Path, optional
        Folder of the external problems (:func:`~lubcontact.bench.problem_sets.data_dir`).

    Raises
    ------
    SetUnavailable
        The set's sources are missing, or every instance is left out.
    """
    instances = problem_set.instances(data)
    left_out = [i.name for i in instances if max_contacts is not None and i.n_contacts > max_contacts]
    instances = [i for i in instances if i.name not in left_out]
    if not instances:
        raise SetUnavailable(f"every instance has more than {max_contacts} contacts")
    rows, references = run_set(instances, methods, tolerances, repeats, max_iter, slack, log)
    labels = [v.label for v in variants(methods, instances)]
    headline = HEADLINE_TOL if HEADLINE_TOL in tolerances else tolerances[len(tolerances) // 2]
    meta = dict(command=command, environment=environment(), repeats=repeats,
                tolerances=tolerances, solvers=labels, slack=slack, headline_tol=headline,
                reference=dict(methods=sorted({reference_method(i.problem) for i in instances}),
                               tol=REFERENCE_TOL, max_outer=MAX_OUTER),
                max_iter=max_iter, left_out=left_out,
                data_dir=_shown(data_folder(data)) if problem_set.reads_data else None,
                peers=_peers())
    path = write_outputs(out_dir / problem_set.name, problem_set, rows, references, labels,
                         tolerances, meta)
    print(f"set {problem_set.name}: report written to {path}\n"
          f"headline, tol {headline:.0e}:\n" +
          format_table(summary_rows(rows, labels, headline),
                       ["solver", "success", "time_sgm_rel", "median_error", "median_iterations"]))
    return path


def _shown(folder: Path) -> str:
    """The data folder as a report shows it: the package's own by name, a user's in full."""
    return "the package data (lubcontact/bench/data)" if folder == PACKAGE_DATA else str(folder)


def _peers() -> str:
    """The optional peers, as the report states them: present (with methods) or absent (why)."""
    status = siconos_status()
    if status.available:
        return f"Siconos numerics {status.siconos_version}: {', '.join(available_methods(status))}"
    return f"Siconos numerics absent ({status.reason}); docs/guide/siconos-peer.md installs it"


def main(argv: list[str] | None = None) -> int:
    """``lubcontact compare``: 0 on success, 1 when a set was skipped, 2 for bad arguments."""
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser().parse_args(argv)
    if args.list:
        for name, problem_set in problem_sets.SETS.items():
            print(f"{name:<18} {problem_set.description}")
        return 0
    if args.replot is not None:
        print(f"report rewritten: {replot(args.replot)}")
        return 0
    args.sets = args.sets or ["piles"]
    register_siconos()                   # the field's reference library, when installed
    try:
        args.solvers = registered() if args.solvers is None else given_methods("--solvers", args.solvers)
        _check_args(args)
        data = data_folder(args.data_dir)
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
                        args.out, command, args.max_iter, args.slack, log, args.max_contacts, data)
        except SetUnavailable as exc:
            print(f"lubcontact compare: skipping set {name!r}: {exc}", file=sys.stderr)
            status = 1
    return status
