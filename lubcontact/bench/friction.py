"""``lubcontact bench friction``: exact Coulomb friction by the fixed point on s.

Two parts, each printing a table.

External problems (default; skipped when ``--pile`` is given without
``--problems``): the Siconos 2D granular problems (667, 2020 and 7002
contacts, mu = 0.5), the FCLIB 3D local problems and the FCLIB global problem
``Box_Stacks`` (converted to local form), read from the benchmark-data folder
(``--data-dir``, else ``LUBCONTACT_DATA_DIR``, else the package data:
:func:`lubcontact.bench.problem_sets.data_dir`). A problem whose file is
missing is skipped with a line saying so. Each is solved by the fixed point
on s (:func:`lubcontact.solvers.coulomb.solve_coulomb`) around every method
of ``--methods`` (default: the fast ``apgd-jacobi`` and ``clarabel-direct``,
Clarabel on the conic form: the cvxpy ``clarabel`` needs a step problem),
with ``tol = --tol`` and ``tol_fp = --tol-fp`` (default ``--tol``).
Iterative (first-order) methods use inexact inner solves (``--forcing``),
``--anderson``, ``--max-iter`` and ``--joint``; the others (interior point,
QP) solve each inner problem to ``--tol`` with Anderson 5. The error is the
Siconos/FCLIB measure of docs/guide/model.md section 6
(:func:`lubcontact.problem.metrics.coulomb_error`) in the file's units
(``FCLIB error``) and on the normalised problem (``scaled err``: ``q`` of
unit rms, ``W`` of unit mean diagonal; it matters where ``|q|`` is far from
1, e.g. ``|q| ~ 4e-18`` in the 667-contact Siconos file). A failed method
still gets its row: its last forces, their errors and its status (``-`` when
the method raised).

Pile step (``--pile N``): one step of a frictional (Coulomb, mu = 0.3) pile
of N disks, timed for each method of ``--pile-methods`` with the fixed point
to ``--pile-tol`` (inner and outer), cold and warm-started from the previous
step's forces and shift (matched by pair key, as a simulation does):

- ``settling``: :func:`lubcontact.scenes.small.settling_pile` (seed 3) stepped
  ``PILE_STEPS`` times with ``dt = PILE_DT`` by a simulation with the fixed
  point around ``clarabel-direct`` (the construction of
  :func:`lubcontact.bench.problem_sets.simulated_steps`, with the faster
  Clarabel interface); the timed problem is the next step's. Grains are
  still falling onto the growing heap: many contacts, large velocities.
- ``deposited``: the first step of :func:`lubcontact.scenes.packing.deposit_pile`
  (seed 1), as in the ``frictional-piles`` comparison set: a pile at rest,
  every contact closed, not in equilibrium (the harder problem). Cold only.

Errors: relative velocity error ``|v - v_ref|_M / |U|_M`` against the
reference (:func:`lubcontact.bench.harness.solve_reference`: the fixed point
around ``clarabel``, cvxpy primal form, ``tol = 1e-9``, ``tol_fp = 1e-8``,
the defaults of a simulation; its own status is in its row: where it did not
converge, the error is only a distance to it), and the FCLIB error of the
normalised problem (``scaled err``, unit-free). At most ``--pile-max-outer``
outer iterations. Timings are single wall-clock runs of
:func:`lubcontact.bench.harness.timed_solve`, after an untimed warm-up.
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..problem.conic import ConicProblem
from ..problem.metrics import coulomb_error, scaled_coulomb_error, velocity_error
from ..solvers import SolveSettings
from ..solvers.coulomb import has_joint_phase
from .friction_problems import (
    EXTERNAL,
    ExternalProblem,
    PileStep,
    deposited_step,
    select_problems,
    settling_step,
)
from .harness import TimedSolve, iterative, solve_reference, timed_solve, warm_up
from .options import check_methods, data_folder, names, number, plain
from .problem_sets import DATA_DIR_ENV, FRICTION, PILE_DT, PILE_STEPS
from .tables import format_table

DEFAULT_METHODS = ("apgd-jacobi", "clarabel-direct")
"""The methods timed by default: the fastest iterative one and the fastest interior point."""
PILE_KINDS = ("settling", "deposited")
REFERENCE_TOL, REFERENCE_TOL_FP = 1e-9, 1e-8  # a simulation's defaults
EXTERNAL_COLUMNS = ("problem", "contacts", "dim", "method", "outer it", "inner it", "time s",
                    "FCLIB error", "scaled err", "status", "note")
PILE_COLUMNS = ("pile", "N", "contacts", "method", "start", "outer it", "inner it", "time s",
                "rel v err", "scaled err", "status", "note")


# -- solving -----------------------------------------------------------------------------------
def coulomb_settings(method: str, tol: float, tol_fp: float, max_outer: int, forcing: float,
                     anderson: int, max_iter: int | None = None, joint: int = 0) -> SolveSettings:
    """Exact Coulomb by the fixed point around ``method``.

    Inexact inner solves (``forcing``), ``anderson`` and ``max_iter`` apply to iterative
    (first-order) methods only, the joint phase (``joint`` of
    :func:`~lubcontact.solvers.coulomb.solve_coulomb`, passed when > 0) to the methods of
    :func:`~lubcontact.solvers.coulomb.has_joint_phase` (``newton-ac`` too); the others keep
    the fixed point's defaults.
    """
    start = {"joint": joint} if joint > 0 and has_joint_phase(method) else {}
    if not iterative(method):
        return SolveSettings(method=method, tol=tol, tol_fp=tol_fp, max_outer=max_outer,
                             options=start)
    options = dict(forcing=forcing, anderson=anderson, **start)
    return SolveSettings(method=method, tol=tol, max_iter=max_iter, tol_fp=tol_fp,
                         max_outer=max_outer, options=options)


@dataclass
class FrictionRow:
    """One fixed-point solve: a row of either table (:meth:`cells`).

    Attributes
    ----------
    name : str
        The external problem, or the pile snapshot (``settling``, ``deposited``).
    contacts : int
    method : str
        With ``(ref)`` for the reference.
    seconds : float
        Wall-clock time.
    status : str
        The fixed point's status, ``error`` when the method raised.
    outer_iterations, inner_iterations : int
        -1 when the method raised.
    fclib_error, scaled_error, velocity_error : float
        NaN when not measured.
    dim, n_grains : int
        Of an external problem, of a pile.
    start : str
        ``cold`` or ``warm``.
    note : str
        Why a solve failed (the exception, or the last inner status and change of s).
    """

    name: str
    contacts: int
    method: str
    seconds: float
    status: str
    outer_iterations: int = -1
    inner_iterations: int = -1
    fclib_error: float = float("nan")
    scaled_error: float = float("nan")
    velocity_error: float = float("nan")
    dim: int = 0
    n_grains: int = 0
    start: str = "cold"
    note: str = ""

    @classmethod
    def of(cls, timed: TimedSolve, problem: ConicProblem, name: str, method: str,
           **fields) -> FrictionRow:
        """The row of one timed solve of ``problem``, its scaled FCLIB error measured."""
        result = timed.result
        if result is None:
            return cls(name, problem.n_contacts, method, timed.seconds, "error",
                       note=timed.message, **fields)
        note = "" if result.success else \
            f"inner {result.inner_status}, last change of s {result.shift_change:.1e}"
        return cls(name, problem.n_contacts, method, timed.seconds, result.status,
                   int(result.outer_iterations), int(result.iterations),
                   scaled_error=scaled_coulomb_error(problem, result.forces), note=note, **fields)

    def cells(self) -> dict[str, object]:
        """The table cells, by column title (both tables' columns)."""
        failed = self.outer_iterations < 0
        return {"problem": self.name, "pile": self.name, "N": self.n_grains,
                "contacts": self.contacts, "dim": self.dim, "method": self.method,
                "start": self.start, "outer it": "-" if failed else self.outer_iterations,
                "inner it": "-" if failed else self.inner_iterations,
                "time s": f"{self.seconds:.3f}", "FCLIB error": _error(self.fclib_error),
                "scaled err": _error(self.scaled_error), "rel v err": _error(self.velocity_error),
                "status": self.status, "note": self.note}


def _error(value: float) -> str:
    return f"{value:.1e}" if np.isfinite(value) else "-"


# -- external problems -------------------------------------------------------------------------
def external_rows(problems: list[ExternalProblem], folder: Path, methods: list[str], tol: float,
                  max_outer: int, forcing: float, anderson: int, max_iter: int | None = None,
                  joint: int = 0, tol_fp: float | None = None,
                  out: Callable[[str], None] = print) -> list[FrictionRow]:
    """Solve each available problem with each method; one row per (problem, method).

    ``tol`` is the inner tolerance and, unless ``tol_fp`` is given, the
    fixed point's; the other options as in :func:`coulomb_settings`.
    """
    from ..io.readers import read_problem

    tol_fp = tol if tol_fp is None else tol_fp
    rows, warmed = [], False
    for entry in problems:
        path = folder / entry.path
        if not path.is_file():
            out(f"# {entry.name}: skipped, file {path} is missing")
            continue
        problem = read_problem(path)
        if not warmed:
            warm_up(problem, methods)
            warmed = True
        for method in methods:
            settings = coulomb_settings(method, tol, tol_fp, max_outer, forcing, anderson,
                                        max_iter, joint)
            timed = timed_solve(problem, settings)
            row = FrictionRow.of(timed, problem, entry.name, method, dim=problem.dim)
            if timed.result is not None:
                row.fclib_error = coulomb_error(problem, timed.result.forces)
            out(f"# {entry.name} {method}: {row.status}, error {_error(row.fclib_error)}, "
                f"{row.seconds:.3f} s")
            rows.append(row)
    return rows


# -- pile step ---------------------------------------------------------------------------------
def pile_rows(step: PileStep, methods: list[str], tol: float, max_outer: int, forcing: float,
              anderson: int, max_iter: int | None = None, joint: int = 0,
              out: Callable[[str], None] = print) -> list[FrictionRow]:
    """The reference row and one row per method and start (cold, warm); options as in
    :func:`coulomb_settings`, with ``tol_fp = tol``."""
    problem = step.problem
    out(f"# {step.label} N={step.n_grains}: {problem.n_contacts} contacts, {step.note}")
    warm_up(problem, methods)
    name, reference = solve_reference(problem, lambda m: SolveSettings(
        method=m, tol=REFERENCE_TOL, tol_fp=REFERENCE_TOL_FP, max_outer=max_outer))
    base = dict(n_grains=step.n_grains)
    rows = [FrictionRow.of(reference, problem, step.label, f"{name} (ref)", **base)]
    starts = [("cold", None, None)]
    if step.warm_start is not None:
        starts.append(("warm", step.warm_start, step.shift))
    for method in methods:
        settings = coulomb_settings(method, tol, tol, max_outer, forcing, anderson, max_iter, joint)
        for start, forces, shift in starts:
            timed = timed_solve(problem, settings, forces, shift)
            row = FrictionRow.of(timed, problem, step.label, method, start=start, **base)
            if timed.result is not None and reference.result is not None:
                row.velocity_error = velocity_error(problem, timed.result.velocities,
                                                    reference.result.velocities)
            out(f"# {step.label} {method} {start}: {row.status}, {row.seconds:.3f} s")
            rows.append(row)
    return rows


# -- command -----------------------------------------------------------------------------------
def parser() -> argparse.ArgumentParser:
    """The options of ``lubcontact bench friction``."""
    parser = argparse.ArgumentParser(prog="lubcontact bench friction", description=plain(__doc__),
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--problems", default=None,
                        help="external problems by name or file name, comma-separated globs "
                             f"(names: {', '.join(p.name for p in EXTERNAL)})")
    parser.add_argument("--methods", default=",".join(DEFAULT_METHODS),
                        help="methods around which the fixed point runs, comma separated")
    parser.add_argument("--tol", type=number(float, 0, above=True), default=1e-10,
                        help="inner tolerance and fixed-point tolerance (external problems)")
    parser.add_argument("--tol-fp", type=number(float, 0, above=True), default=None,
                        help="fixed-point tolerance of the external problems if not --tol")
    parser.add_argument("--max-outer", type=int, default=1000,
                        help="cap on the outer iterations of the fixed point")
    parser.add_argument("--forcing", type=float, default=1e-4,
                        help="iterative methods: inner tol = max(tol, forcing x last change)")
    parser.add_argument("--anderson", type=int, default=5,
                        help="iterative methods: Anderson memory of the fixed point (0: none)")
    parser.add_argument("--max-iter", type=int, default=None,
                        help="iterative methods: iteration cap of each inner solve (method default)")
    parser.add_argument("--joint", type=int, default=0,
                        help="iterative methods and newton-ac: the joint phase first, shift "
                             "updated every JOINT iterations inside one APGD run (0: none)")
    parser.add_argument("--quick", action="store_true",
                        help="the small external problems only (667-contact Siconos, "
                             "Box_Stacks, LMGC, local_problem_test)")
    parser.add_argument("--data-dir", "--folder", dest="data_dir", type=Path, default=None,
                        metavar="DIR",
                        help="benchmark-data folder (siconos-fc2d/, fclib-local/); default "
                             f"${DATA_DIR_ENV}, else the package data")
    parser.add_argument("--pile", type=int, default=None, metavar="N",
                        help="also time one step of a frictional pile of N grains "
                             "(alone unless --problems is given)")
    parser.add_argument("--pile-kinds", default=",".join(PILE_KINDS),
                        help=f"pile snapshots, comma separated: {', '.join(PILE_KINDS)}")
    parser.add_argument("--pile-methods", default=",".join(DEFAULT_METHODS),
                        help="methods timed on the pile step, comma separated")
    parser.add_argument("--pile-tol", type=number(float, 0, above=True), default=1e-6,
                        help="inner and fixed-point tolerance of the pile step")
    parser.add_argument("--pile-max-outer", type=int, default=100,
                        help="cap on the outer iterations of the fixed point on the pile step")
    parser.add_argument("--pile-steps", type=int, default=PILE_STEPS,
                        help="steps of the settling pile before the timed one")
    return parser


def _check(args: argparse.Namespace) -> None:
    """Raise ``ValueError`` (naming the option) for a bad argument."""
    check_methods("--methods", names(args.methods))
    check_methods("--pile-methods", names(args.pile_methods))
    kinds = set(names(args.pile_kinds)) - set(PILE_KINDS)
    if kinds:
        raise ValueError(f"--pile-kinds: unknown {', '.join(sorted(kinds))}; "
                         f"known: {', '.join(PILE_KINDS)}")
    if args.joint < 0:
        raise ValueError(f"--joint: must be >= 0, got {args.joint}")
    optional = [value for value in (args.max_iter, args.pile) if value is not None]
    if min([args.max_outer, args.pile_max_outer, args.pile_steps] + optional) < 1:
        raise ValueError("--max-outer, --max-iter, --pile-max-outer, --pile-steps and --pile "
                         "must be positive")


def main(argv: list[str] | None = None) -> int:
    """``lubcontact bench friction``: see the module docstring; 2 for bad arguments."""
    args = parser().parse_args(argv)
    patterns = names(args.problems)
    external = args.pile is None or bool(patterns)
    try:
        _check(args)
        problems = select_problems(patterns, args.quick) if external else []
        if external and not problems:
            raise ValueError(f"--problems: nothing matches {args.problems!r}")
        folder = data_folder(args.data_dir) if external else None
    except ValueError as exc:
        print(f"lubcontact bench friction: {exc}", file=sys.stderr)
        return 2
    if external:
        tol_fp = args.tol if args.tol_fp is None else args.tol_fp
        print(f"# external problems from {folder}: tol = {args.tol:g}, tol_fp = {tol_fp:g}, "
              f"max {args.max_outer} outer iterations, iterative methods with forcing "
              f"{args.forcing:g}, Anderson {args.anderson}, inner cap {args.max_iter or 'default'}, "
              f"joint {args.joint}")
        rows = external_rows(problems, folder, names(args.methods), args.tol, args.max_outer,
                             args.forcing, args.anderson, args.max_iter, args.joint, tol_fp)
        print(format_table([row.cells() for row in rows], EXTERNAL_COLUMNS))
    if args.pile is not None:
        print(f"\n# pile step: Coulomb mu = {FRICTION}, dt = {PILE_DT}, tol = tol_fp = "
              f"{args.pile_tol:g}, max {args.pile_max_outer} outer iterations, iterative methods "
              f"with forcing {args.forcing:g}, Anderson {args.anderson}, joint {args.joint}; "
              f"reference tol = {REFERENCE_TOL:g}, tol_fp = {REFERENCE_TOL_FP:g}")
        rows = []
        for kind in names(args.pile_kinds):
            step = (settling_step(args.pile, args.pile_steps) if kind == "settling"
                    else deposited_step(args.pile))
            rows += pile_rows(step, names(args.pile_methods), args.pile_tol, args.pile_max_outer,
                              args.forcing, args.anderson, args.max_iter, args.joint)
        print(format_table([row.cells() for row in rows], PILE_COLUMNS))
    return 0
