"""``lubcontact bench friction``: exact Coulomb friction by the fixed point on s.

Two parts, each printing a table.

External problems (default; skipped when ``--pile`` is given without
``--problems``): the Siconos 2D granular problems (667, 2020 and 7002
contacts, mu = 0.5), the FCLIB 3D local problems and the FCLIB global problem
``Box_Stacks`` (converted to local form), read in place from the shared
benchmarks folder (:data:`lubcontact.problem_sets.BENCHMARKS`, or
``--folder``). A problem whose file is missing is skipped with a line saying
so. Each is solved by :func:`lubcontact.fixed_point.solve_coulomb` around
every method of ``--methods`` (default: the fast ``apgd-jacobi`` and
``clarabel-direct``, Clarabel on the conic form: the cvxpy ``clarabel`` needs
a step problem), with ``tol = --tol`` and ``tol_fp = --tol-fp`` (default ``--tol``). Iterative methods use inexact
inner solves (``--forcing``) and ``--anderson``; interior-point methods
(Clarabel, SCS, OSQP) solve each inner problem to ``--tol`` with Anderson 5.
The error is the Siconos/FCLIB measure of MODEL.md section 6
(:func:`lubcontact.fixed_point.coulomb_error`) in the file's units
(``FCLIB error``) and on the normalised problem (``scaled err``: ``q`` of unit
rms, ``W`` of unit mean diagonal; it matters where ``|q|`` is far from 1, e.g.
``|q| ~ 4e-18`` in the 667-contact Siconos file). A failed method still gets
its row: its last forces, their errors and its status (``-`` when the method
raised).

Pile step (``--pile N``): one step of a frictional (Coulomb, mu = 0.3) pile
of N disks, timed for each method of ``--pile-methods`` with the fixed point
to ``--pile-tol`` (inner and outer), cold and warm-started from the previous
step's forces and shift (matched by pair key, as a simulation does):

- ``settling``: :func:`lubcontact.scenes.settling_pile` (seed 3) stepped
  ``PILE_STEPS`` times with ``dt = PILE_DT`` by a simulation with the fixed
  point around ``clarabel-direct`` (the construction of
  :func:`lubcontact.problem_sets.simulated_steps`, with the faster Clarabel
  interface); the timed problem is the next step's. Grains are still falling
  onto the growing heap: many contacts, large velocities.
- ``deposited``: the first step of :func:`lubcontact.packing.deposit_pile`
  (seed 1), as in the ``frictional-piles`` comparison set: a pile at rest,
  every contact closed, not in equilibrium (the harder problem). Cold only.

Errors: relative velocity error ``|v - v_ref|_M / |U|_M`` against the fixed
point around ``clarabel`` (cvxpy primal form, ``tol = 1e-9``, ``tol_fp = 1e-8``,
the defaults of a simulation; its own status is in its row: where it did not
converge, the error is only a distance to it), and the FCLIB error of the
normalised problem (``scaled err``, unit-free). At most ``--pile-max-outer``
outer iterations. Timings are single wall-clock runs (compiled kernels loaded
before timing).
"""
from __future__ import annotations

import argparse
import fnmatch
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .problem_sets import BENCHMARKS, FRICTION, PILE_DT, PILE_STEPS
from .tables import format_table

INTERIOR_METHODS = ("clarabel", "clarabel-dual", "clarabel-direct", "osqp", "scs")
DEFAULT_METHODS = ("apgd-jacobi", "clarabel-direct")
PILE_KINDS = ("settling", "deposited")
SETTLING_SEED, DEPOSITED_SEED = 3, 1          # the seeds of the comparison sets
REFERENCE = dict(method="clarabel", tol=1e-9, tol_fp=1e-8)
EXTERNAL_COLUMNS = ("problem", "contacts", "dim", "method", "outer it", "inner it", "time s",
                    "FCLIB error", "scaled err", "status", "note")
PILE_COLUMNS = ("pile", "N", "contacts", "method", "start", "outer it", "inner it", "time s",
                "rel v err", "scaled err", "status", "note")


@dataclass(frozen=True)
class ExternalProblem:
    """An external problem file.

    Attributes
    ----------
    name : str
        Short label (the table's ``problem`` column).
    path : str
        Relative to the benchmarks folder.
    quick : bool
        Part of the ``--quick`` subset (seconds in all).
    """

    name: str
    path: str
    quick: bool


EXTERNAL = (
    ExternalProblem("fc2d-00667", "siconos-fc2d/fc2d_granularflowonwall_00667_00000.dat", True),
    ExternalProblem("fc2d-02020", "siconos-fc2d/fc2d_granularflowonwall_02020_00213.dat", False),
    ExternalProblem("fc2d-07002", "siconos-fc2d/fc2d_granularflowonwall_07002_00801.dat", False),
    ExternalProblem("local_problem_test", "fclib-local/local_problem_test.hdf5", True),
    ExternalProblem("LMGC_PerioBox", "fclib-local/LMGC_100_PR_PerioBox-i00361-60-03000.hdf5", True),
    ExternalProblem("Capsules", "fclib-local/Capsules-i125-1213.hdf5", False),
    ExternalProblem("Box_Stacks", "fclib-local/Box_Stacks-i0122-82-5.hdf5", True),
)


# -- solving -----------------------------------------------------------------------------------
def fixed_point_options(method: str, forcing: float, anderson: int,
                        max_iter: int | None = None, joint: int = 0) -> dict:
    """Fixed-point options: inexact inner solves, ``max_iter`` and the joint phase
    (``joint`` of :func:`~lubcontact.fixed_point.solve_coulomb`, passed when > 0) for
    iterative methods only.
    """
    if method in INTERIOR_METHODS:
        return {}
    options = dict(forcing=forcing, anderson=anderson, max_iter=max_iter)
    if joint > 0:
        options["joint"] = joint
    return options


def timed_coulomb(problem, method: str, tol: float, tol_fp: float, max_outer: int,
                  warm_start: np.ndarray | None = None, shift: np.ndarray | None = None,
                  **options):
    """``solve_coulomb`` timed; returns ``(SolveResult or None, wall seconds, message)``.

    A method that raises is a result to report: ``None`` and the exception's
    first line as message.
    """
    from ..solvers.coulomb import solve_coulomb

    start = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = solve_coulomb(problem, method, tol=tol, tol_fp=tol_fp, max_outer=max_outer,
                                   warm_start=warm_start, shift=shift, **options)
    except Exception as exc:  # noqa: BLE001  (a solver's failure is a result to report)
        text = str(exc).splitlines()[0] if str(exc) else ""
        return None, time.perf_counter() - start, f"{type(exc).__name__}: {text}"
    return result, time.perf_counter() - start, ""


def load_kernels(problem, methods) -> None:
    """Untimed short solve per iterative method, so that compiled kernels are loaded."""
    from ..solvers import solve

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for method in methods:
            if method not in INTERIOR_METHODS:
                solve(problem, method, tol=1e-2, max_iter=5)


def outcome(result, wall: float, message: str) -> dict:
    """The table cells shared by both parts."""
    if result is None:
        return {"outer it": "-", "inner it": "-", "time s": f"{wall:.3f}", "status": "error",
                "note": message}
    note = ""
    if not result.success:
        note = f"inner {result.inner_status}, last change of s {result.shift_change:.1e}"
    return {"outer it": result.outer_iterations, "inner it": result.iterations,
            "time s": f"{wall:.3f}", "status": result.status, "note": note}


def _error(value: float) -> str:
    return f"{value:.1e}" if np.isfinite(value) else "-"


# -- external problems -------------------------------------------------------------------------
def select_problems(patterns: list[str] | None, quick: bool) -> list[ExternalProblem]:
    """The problems whose name or file name matches one of ``patterns`` (globs)."""
    chosen = [p for p in EXTERNAL if p.quick or not quick]
    if not patterns:
        return chosen
    return [p for p in chosen
            if any(fnmatch.fnmatch(p.name, pat) or fnmatch.fnmatch(Path(p.path).name, pat)
                   for pat in patterns)]


def external_rows(problems: list[ExternalProblem], folder: Path, methods: list[str], tol: float,
                  max_outer: int, forcing: float, anderson: int, max_iter: int | None = None,
                  joint: int = 0, tol_fp: float | None = None, out=print) -> list[dict]:
    """Solve each available problem with each method; one row per (problem, method).

    ``tol`` is the inner tolerance and, unless ``tol_fp`` is given, the fixed point's.
    """
    tol_fp = tol if tol_fp is None else tol_fp
    from ..problem.metrics import coulomb_error, scaled_coulomb_error
    from ..io.readers import read_problem

    rows, loaded = [], False
    for entry in problems:
        path = folder / entry.path
        if not path.is_file():
            out(f"# {entry.name}: skipped, file {path} is missing")
            continue
        problem = read_problem(path)
        if not loaded:
            load_kernels(problem, methods)
            loaded = True
        for method in methods:
            options = fixed_point_options(method, forcing, anderson, max_iter, joint)
            result, wall, message = timed_coulomb(problem, method, tol, tol_fp, max_outer,
                                                  **options)
            row = dict(problem=entry.name, contacts=problem.n_contacts, dim=problem.dim,
                       method=method, **outcome(result, wall, message))
            if result is not None:
                row["FCLIB error"] = _error(coulomb_error(problem, result.forces))
                row["scaled err"] = _error(scaled_coulomb_error(problem, result.forces))
            out(f"# {entry.name} {method}: {row['status']}, error {row.get('FCLIB error', '-')}, "
                f"{row['time s']} s")
            rows.append(row)
    return rows


# -- pile step ---------------------------------------------------------------------------------
@dataclass
class PileStep:
    """A frictional step problem of a pile and the warm start a simulation would give it.

    Attributes
    ----------
    label : str
        ``settling`` or ``deposited``.
    n_grains : int
    problem : StepProblem
        Coulomb cones (mu = FRICTION) on every contact.
    warm_start : ndarray, shape (n_rows,), or None
        Previous step's forces matched by pair key (None: no previous step).
    shift : ndarray, shape (nc,), or None
        Previous step's shift ``s`` matched by pair key.
    note : str
        How it was built.
    """

    label: str
    n_grains: int
    problem: object
    warm_start: np.ndarray | None
    shift: np.ndarray | None
    note: str


def settling_step(n_grains: int, steps: int = PILE_STEPS, dt: float = PILE_DT,
                  seed: int = SETTLING_SEED) -> PileStep:
    """The step after ``steps`` steps of a frictional settling pile (module docstring)."""
    from ..sim.simulation import Simulation
    from ..model.laws import Coulomb
    from ..scenes.small import settling_pile
    from ..solvers import CONVERGED

    start = time.perf_counter()
    sim = Simulation(settling_pile(n_grains, seed=seed), Coulomb(FRICTION), dt,
                     solver="clarabel-direct", tol=1e-8, tol_fp=1e-6, on_failure="ignore")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim.run(steps)
    failed = sum(status != CONVERGED for status in sim.trajectory.status)
    _, _, problem, forces, shift = sim.next_problem()
    speed = float(np.max(np.linalg.norm(sim.scene.grains.velocities, axis=1)))
    note = (f"settling_pile({n_grains}, seed={seed}) after {steps} steps of dt = {dt:g} "
            f"(fixed point around clarabel-direct, {failed} steps not converged, "
            f"{time.perf_counter() - start:.1f} s), max speed {speed:.2f}")
    return PileStep("settling", n_grains, problem, forces, shift, note)


def deposited_step(n_grains: int, dt: float = PILE_DT, seed: int = DEPOSITED_SEED) -> PileStep:
    """The first step of a deposited frictional pile (module docstring)."""
    from ..model.laws import Coulomb
    from ..scenes.packing import deposit_pile
    from .problem_sets import snapshot

    problem = snapshot(deposit_pile(n_grains, seed=seed), Coulomb(FRICTION), dt)
    return PileStep("deposited", n_grains, problem, None, None,
                    f"deposit_pile({n_grains}, seed={seed}), first step of dt = {dt:g}")


def pile_rows(step: PileStep, methods: list[str], tol: float, max_outer: int, forcing: float,
              anderson: int, max_iter: int | None = None, joint: int = 0,
              out=print) -> list[dict]:
    """The reference row and one row per method and start (cold, warm)."""
    from ..problem.metrics import scaled_coulomb_error, velocity_error

    problem = step.problem
    out(f"# {step.label} N={step.n_grains}: {problem.n_contacts} contacts, {step.note}")
    load_kernels(problem, methods)
    reference, wall, message = timed_coulomb(problem, REFERENCE["method"], REFERENCE["tol"],
                                             REFERENCE["tol_fp"], max_outer)
    base = dict(pile=step.label, N=step.n_grains, contacts=problem.n_contacts)
    rows = [dict(base, method=f"{REFERENCE['method']} (ref)", start="cold",
                 **outcome(reference, wall, message))]
    rows[0]["scaled err"] = _error(scaled_coulomb_error(problem, reference.forces)
                                    if reference is not None else np.nan)
    starts = [("cold", None, None)]
    if step.warm_start is not None:
        starts.append(("warm", step.warm_start, step.shift))
    for method in methods:
        options = fixed_point_options(method, forcing, anderson, max_iter, joint)
        for start, forces, shift in starts:
            result, wall, message = timed_coulomb(problem, method, tol, tol, max_outer,
                                                  warm_start=forces, shift=shift, **options)
            row = dict(base, method=method, start=start, **outcome(result, wall, message))
            if result is not None:
                row["scaled err"] = _error(scaled_coulomb_error(problem, result.forces))
                if reference is not None:
                    row["rel v err"] = _error(velocity_error(problem, result.velocities,
                                                             reference.velocities))
            out(f"# {step.label} {method} {start}: {row['status']}, {row['time s']} s")
            rows.append(row)
    return rows


# -- command -----------------------------------------------------------------------------------
def parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="lubcontact bench friction", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--problems", default=None,
                        help="external problems by name or file name, comma-separated globs "
                             f"(names: {', '.join(p.name for p in EXTERNAL)})")
    parser.add_argument("--methods", default=",".join(DEFAULT_METHODS),
                        help="methods around which the fixed point runs, comma separated")
    parser.add_argument("--tol", type=float, default=1e-10,
                        help="inner tolerance and fixed-point tolerance (external problems)")
    parser.add_argument("--tol-fp", type=float, default=None,
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
                        help="iterative methods: joint phase of the fixed point, shift updated "
                             "every JOINT iterations inside the solver (0: none)")
    parser.add_argument("--quick", action="store_true",
                        help="the small external problems only (667-contact Siconos, "
                             "Box_Stacks, LMGC, local_problem_test)")
    parser.add_argument("--folder", type=Path, default=BENCHMARKS,
                        help="benchmarks folder (siconos-fc2d/, fclib-local/)")
    parser.add_argument("--pile", type=int, default=None, metavar="N",
                        help="also time one step of a frictional pile of N grains "
                             "(alone unless --problems is given)")
    parser.add_argument("--pile-kinds", default=",".join(PILE_KINDS),
                        help=f"pile snapshots, comma separated: {', '.join(PILE_KINDS)}")
    parser.add_argument("--pile-methods", default=",".join(DEFAULT_METHODS),
                        help="methods timed on the pile step, comma separated")
    parser.add_argument("--pile-tol", type=float, default=1e-6,
                        help="inner and fixed-point tolerance of the pile step")
    parser.add_argument("--pile-max-outer", type=int, default=100,
                        help="cap on the outer iterations of the fixed point on the pile step")
    parser.add_argument("--pile-steps", type=int, default=PILE_STEPS,
                        help="steps of the settling pile before the timed one")
    return parser


def _names(text: str) -> list[str]:
    return [item.strip() for item in text.split(",") if item.strip()]


def _check(cli: argparse.ArgumentParser, args) -> None:
    from ..solvers import methods as registered

    for option in ("methods", "pile_methods"):
        unknown = sorted(set(_names(getattr(args, option))) - set(registered()))
        if unknown:
            cli.error(f"--{option.replace('_', '-')}: unknown {', '.join(unknown)}; "
                      f"registered: {', '.join(registered())}")
    kinds = set(_names(args.pile_kinds)) - set(PILE_KINDS)
    if kinds:
        cli.error(f"--pile-kinds: unknown {', '.join(sorted(kinds))}; known: {', '.join(PILE_KINDS)}")
    for option in ("tol", "pile_tol"):
        if not getattr(args, option) > 0:
            cli.error(f"--{option.replace('_', '-')}: must be > 0, got {getattr(args, option)}")
    if args.tol_fp is not None and not args.tol_fp > 0:
        cli.error(f"--tol-fp: must be > 0, got {args.tol_fp}")
    if args.joint < 0:
        cli.error(f"--joint: must be >= 0, got {args.joint}")
    optional = [value for value in (args.max_iter, args.pile) if value is not None]
    if min([args.max_outer, args.pile_max_outer, args.pile_steps] + optional) < 1:
        cli.error("--max-outer, --max-iter, --pile-max-outer, --pile-steps and --pile must be "
                  "positive")


def main(argv: list[str] | None = None) -> int:
    """``lubcontact bench friction``: see the module docstring."""
    cli = parser()
    args = cli.parse_args(argv)
    _check(cli, args)
    patterns = _names(args.problems) if args.problems else None
    if args.pile is None or patterns:
        problems = select_problems(patterns, args.quick)
        if not problems:
            cli.error(f"--problems: nothing matches {args.problems!r}")
        tol_fp = args.tol if args.tol_fp is None else args.tol_fp
        print(f"# external problems from {args.folder}: tol = {args.tol:g}, tol_fp = {tol_fp:g}, "
              f"max {args.max_outer} outer iterations, iterative methods with forcing "
              f"{args.forcing:g}, Anderson {args.anderson}, inner cap {args.max_iter or 'default'}, "
              f"joint {args.joint}")
        rows = external_rows(problems, args.folder, _names(args.methods), args.tol,
                             args.max_outer, args.forcing, args.anderson, args.max_iter,
                             args.joint, tol_fp)
        print(format_table(rows, EXTERNAL_COLUMNS))
    if args.pile is not None:
        print(f"\n# pile step: Coulomb mu = {FRICTION}, dt = {PILE_DT}, tol = tol_fp = "
              f"{args.pile_tol:g}, max {args.pile_max_outer} outer iterations, iterative methods "
              f"with forcing {args.forcing:g}, Anderson {args.anderson}, joint {args.joint}; "
              f"reference {REFERENCE}")
        rows = []
        for kind in _names(args.pile_kinds):
            step = (settling_step(args.pile, args.pile_steps) if kind == "settling"
                    else deposited_step(args.pile))
            rows += pile_rows(step, _names(args.pile_methods), args.pile_tol, args.pile_max_outer,
                              args.forcing, args.anderson, args.max_iter, args.joint)
        print(format_table(rows, PILE_COLUMNS))
    return 0
