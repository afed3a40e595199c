"""``lubcontact bench solvers``: every method on the step problems of 2D piles at rest.

For each size N it builds a polydisperse pile at rest: by default settled by
the dynamics (:func:`lubcontact.scenes.packing.settle_pile`, cached under
``out/cache``; ``--tiles k`` starts it from k settled piles of N/k grains
side by side, cheaper to settle for large N), with ``--pile deposited`` as
deposited (:func:`lubcontact.scenes.packing.deposit_pile`: zero velocities,
closed contacts, not in equilibrium); its step problem with inelastic
frictionless contacts (``dry``) and the same with a fraction of the closed
contacts glued (``glued``: FREE cones). Each is solved with every method
(default: every registered method but the symbolic references), iterative
(first-order) methods to ``--tol``, the others (interior point, QP) to
``--reference-tol``, each solve timed once by
:func:`lubcontact.bench.harness.timed_solve` after an untimed warm-up.
Errors are measured against the reference
(:func:`lubcontact.bench.harness.solve_reference`: ``clarabel`` through
cvxpy at ``--reference-tol``, polished on its active set):

- relative velocity error ``|v - v_ref|_M / |U|_M`` (mass-weighted norms,
  relative to the free velocity, i.e. in units of ``g dt`` for a pile at rest);
- most negative gap after the step, ``min(D + dt u_n)``, in units of the
  mean radius.

It then advances the pile one step with the reference velocities and solves
the next step's problem cold and warm-started from each method's forces
(matched by pair key), for the methods that use a warm start, to compare
iteration counts.

``--condition`` also prints the condition number of the Delassus matrix on
the reference's loaded rows (:func:`~lubcontact.problem.metrics.active_condition`),
which sets how many iterations the gradient methods need on the pile.
"""
from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..problem.cones import ConeKind
from ..problem.metrics import active_condition, velocity_error
from ..problem.step import StepProblem
from ..solvers import CONVERGED, INTERIOR_POINT, SolveSettings, solver_info
from ..solvers import methods as registered
from .harness import TimedSolve, iterative, reference_distrust, solve_reference, timed_solve, warm_up
from .options import check_methods, counts, names, number, plain
from .pile_problems import PILES, PileCase, matched_forces, next_step_problem, pile_cases

BASELINE = "clarabel-direct"
"""The method the best iterative one is compared with in the summary."""


def default_methods() -> list[str]:
    """Every registered method but the symbolic references, non-iterative ones first.

    The symbolic references are the interior-point methods that polish their
    result and accept the non-convex union (``clarabel`` and ``clarabel-dual``,
    through cvxpy: slow on large piles); the reference of the benchmark is
    always run.
    """
    def symbolic(name: str) -> bool:
        info = solver_info(name)
        return info.kind == INTERIOR_POINT and info.polishing and ConeKind.UNION in info.cones

    return sorted((m for m in registered() if not symbolic(m)), key=iterative)


@dataclass
class PileRow:
    """One timed solve on a pile: one printed line (:meth:`text`, :data:`HEADER`).

    Attributes
    ----------
    n_grains, n_contacts : int
    pile : str
        ``dry`` or ``glued``.
    method : str
        The method, with ``(ref)``, ``cold`` or ``warm`` where it applies.
    setup_s, solve_s, seconds : float
        The method's own split and the wall-clock time of the call.
    iterations : int
    status : str
        The solve's status, ``error`` when the method raised.
    error : float
        Relative velocity error ``|v - v_ref|_M / |U|_M``.
    min_gap : float
        Most negative gap after the step, in mean radii.
    note : str
        ``(next step)``, or the exception of a failed solve.
    """

    n_grains: int
    n_contacts: int
    pile: str
    method: str
    setup_s: float
    solve_s: float
    seconds: float
    iterations: int
    status: str
    error: float
    min_gap: float
    note: str = ""

    @classmethod
    def of(cls, case: PileCase, problem: StepProblem, method: str, timed: TimedSolve,
           reference_velocities: np.ndarray | None, note: str = "") -> PileRow:
        """The row of one timed solve of ``problem`` (``case``'s or its next step's)."""
        result, nan = timed.result, float("nan")
        if result is None:
            return cls(case.n_grains, problem.n_contacts, case.label, method, nan, nan,
                       timed.seconds, -1, "error", nan, nan, f"{note} {timed.message}".strip())
        radius = float(np.mean(case.scene.grains.radii))
        error = 0.0 if reference_velocities is None else \
            velocity_error(problem, result.velocities, reference_velocities)
        return cls(case.n_grains, problem.n_contacts, case.label, method, result.setup_time,
                   result.solve_time, timed.seconds, int(result.iterations), result.status,
                   error, float(problem.gaps_after(result.velocities).min()) / radius, note)

    def text(self) -> str:
        return (f"{self.n_grains:>6d} {self.n_contacts:>6d} {self.pile:<5} {self.method:<16} "
                f"{self.setup_s:>8.3f} {self.solve_s:>8.3f} {self.seconds:>8.3f} "
                f"{self.iterations:>6d} {self.status:<9} {self.error:>9.1e} {self.min_gap:>9.1e} "
                f"{self.note}")


HEADER = (f"{'N':>6} {'nc':>6} {'pile':<5} {'method':<16} {'setup s':>8} {'solve s':>8} "
          f"{'total s':>8} {'iter':>6} {'status':<9} {'rel v err':>9} {'min gap/r':>9}")


@dataclass
class CaseResult:
    """The measurements of one case (:func:`run_case`).

    Attributes
    ----------
    case : PileCase
    rows : dict
        Method -> its row on the case's step.
    warm_iterations : dict
        Method -> (cold, warm) iterations on the next step.
    product_s : float
        Median time of one scipy sparse product ``W x`` on the case's step (s).
    """

    case: PileCase
    rows: dict[str, PileRow] = field(default_factory=dict)
    warm_iterations: dict[str, tuple[int, int]] = field(default_factory=dict)
    product_s: float = float("nan")


def product_seconds(matrix: sp.spmatrix, repeats: int = 50) -> float:
    """Median wall-clock time of one scipy sparse product ``matrix @ x`` (s), after one untimed.

    Parameters
    ----------
    matrix : scipy.sparse matrix, shape (n, n)
    repeats : int
        Timed products.
    """
    x = np.ones(matrix.shape[1])
    matrix @ x
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        matrix @ x
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def _reference(problem: StepProblem, tol: float) -> tuple[str, TimedSolve]:
    """The reference solve of a pile step; raises RuntimeError when it fails."""
    method, timed = solve_reference(problem, lambda m: SolveSettings(method=m, tol=tol,
                                                                     exact_coulomb=False))
    if timed.result is None:
        raise RuntimeError(f"reference {method} failed: {timed.message}")
    return method, timed


def run_case(case: PileCase, methods: list[str], tol: float, reference_tol: float,
             max_iter: int | None, warm: bool, out: Callable[[str], None] = print,
             condition: bool = False) -> CaseResult:
    """Solve one case with every method; print one row each (module docstring).

    Parameters
    ----------
    case : PileCase
    methods : list of str
        Registered methods.
    tol, reference_tol : float
        Tolerance of the iterative (first-order) methods, and of the others
        and the reference.
    max_iter : int, optional
        Iteration cap (method defaults when None).
    warm : bool
        Also solve the next step cold and warm-started, with every method
        that uses a warm start.
    out : callable
        Receives each printed line.
    condition : bool
        Also print :func:`~lubcontact.problem.metrics.active_condition` of the reference solution.
    """
    problem = case.problem
    radius = float(np.mean(case.scene.grains.radii))
    method, reference = _reference(problem, reference_tol)
    reference_velocities = reference.result.velocities
    out(PileRow.of(case, problem, f"{method} (ref)", reference, None).text())
    distrust = reference_distrust(reference.result)
    if distrust:
        out(f"# {case.label} N={case.n_grains}: reference NOT trusted ({distrust}): the 'rel v "
            "err' below are distances to it, not errors")
    reference_gaps = problem.gaps_after(reference_velocities)
    closed = np.abs(problem.gaps) <= 1e-9 * radius
    opening = closed & (reference_gaps > 1e-9 * radius)
    out(f"# {case.label} N={case.n_grains}: {np.count_nonzero(opening)} of "
        f"{np.count_nonzero(closed)} closed contacts open in the step")
    if condition:
        value, count = active_condition(problem, reference.result.x)
        out(f"# {case.label} N={case.n_grains}: cond(W_AA) = {value:.2e} on {count} loaded rows")

    def settings(name: str) -> SolveSettings:
        return SolveSettings(method=name, tol=tol if iterative(name) else reference_tol,
                             max_iter=max_iter, exact_coulomb=False)

    measured = CaseResult(case, product_s=product_seconds(problem.delassus))
    forces = {}
    for name in methods:
        timed = timed_solve(problem, settings(name))
        measured.rows[name] = PileRow.of(case, problem, name, timed, reference_velocities)
        out(measured.rows[name].text())
        if timed.result is not None:
            forces[name] = timed.result.forces
    if not warm:
        return measured
    following = next_step_problem(case, reference_velocities)
    _, next_reference = _reference(following, reference_tol)
    for name in methods:
        if not solver_info(name).warm_start or name not in forces:
            continue
        guess = matched_forces(problem.keys, forces[name][: problem.n_contacts], following)
        pair = []
        for label, start in (("cold", None), ("warm", guess)):
            timed = timed_solve(following, settings(name), warm_start=start)
            row = PileRow.of(case, following, f"{name} {label}", timed,
                             next_reference.result.velocities, "(next step)")
            out(row.text())
            pair.append(row.iterations)
        measured.warm_iterations[name] = tuple(pair)
    return measured


def summarise(measured: CaseResult, accuracy: float, out: Callable[[str], None] = print) -> None:
    """Best iterative method against :data:`BASELINE`; per-iteration cost of each first-order
    method (its solve time over its iterations) against one scipy product ``W x``; warm against
    cold iterations."""
    case, rows = measured.case, measured.rows
    if BASELINE in rows:
        fast = {m: row for m, row in rows.items()
                if iterative(m) and row.status == CONVERGED and row.error <= accuracy}
        baseline = rows[BASELINE].seconds
        if fast:
            best = min(fast, key=lambda m: fast[m].seconds)
            out(f"   N={case.n_grains} {case.label}: best fast method {best} "
                f"{fast[best].seconds:.3f} s = {fast[best].seconds / baseline:.3f} x {BASELINE} "
                f"({baseline:.3f} s)")
        else:
            out(f"   N={case.n_grains} {case.label}: no fast method reached {accuracy:g}")
    for method, row in rows.items():
        if iterative(method) and row.iterations > 0 and math.isfinite(row.solve_s):
            per_iteration = row.solve_s / row.iterations
            out(f"   N={case.n_grains} {case.label}: {method} per iteration "
                f"{per_iteration * 1e6:.1f} us = {per_iteration / measured.product_s:.2f} x one scipy "
                f"product W x ({measured.product_s * 1e6:.1f} us)")
    for method, (cold, warm) in measured.warm_iterations.items():
        out(f"   N={case.n_grains} {case.label}: {method} next step warm/cold iterations "
            f"{warm}/{cold} = {warm / max(cold, 1):.2f}")


def solvers_main(argv: list[str] | None = None) -> int:
    """``lubcontact bench solvers``: see the module docstring."""
    parser = argparse.ArgumentParser(prog="lubcontact bench solvers", description=plain(__doc__),
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", nargs="+", default=["100", "1000", "10000"],
                        help="grain counts, space or comma separated (default: 100 1000 10000)")
    parser.add_argument("--methods", default=None,
                        help="methods to compare, comma separated (default: every registered "
                             f"method but the symbolic references: {','.join(default_methods())})")
    parser.add_argument("--glued-fraction", type=float, default=0.3,
                        help="fraction of closed contacts glued in the 'glued' pile (0: skip it)")
    parser.add_argument("--tol", type=number(float, 0, above=True), default=1e-8,
                        help="tolerance of the iterative (first-order) methods")
    parser.add_argument("--reference-tol", type=number(float, 0, above=True), default=1e-10,
                        help="tolerance of the reference and of the interior-point and QP methods")
    parser.add_argument("--max-iter", type=int, default=None, help="iteration cap (method default)")
    parser.add_argument("--accuracy", type=float, default=1e-6,
                        help="relative velocity error a fast method must reach in the summary")
    parser.add_argument("--dt", type=float, default=0.01, help="time step (units of sqrt(r/g))")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--pile", choices=PILES, default="settled",
                        help="settled by the dynamics (cached in out/cache) or deposited")
    parser.add_argument("--tiles", type=int, default=1,
                        help="settled piles built from this many settled copies side by side "
                             "(settle_pile(tiles=...)); every size must be a multiple")
    parser.add_argument("--no-warm", action="store_true", help="skip the next-step re-solves")
    parser.add_argument("--condition", action="store_true",
                        help="print cond(W_AA) on the reference's loaded rows (active_condition)")
    args = parser.parse_args(argv)
    try:
        sizes = counts("--sizes", args.sizes)
    except ValueError as exc:
        parser.error(f"argument {exc}")
    methods = default_methods() if args.methods is None else names(args.methods)
    try:
        check_methods("--methods", methods)
    except ValueError as exc:
        parser.error(str(exc))
    if args.tiles < 1 or any(n % args.tiles for n in sizes):
        parser.error(f"--tiles: must be >= 1 and divide every size, got {args.tiles}")
    print(HEADER)
    measured = []
    for n in sizes:
        cases = pile_cases(n, args.glued_fraction, args.dt, args.seed, args.pile, args.tiles)
        if n == sizes[0]:
            warm_up(cases[0].problem, methods)
        for case in cases:
            measured.append(run_case(case, methods, args.tol, args.reference_tol, args.max_iter,
                                     not args.no_warm, condition=args.condition))
    print("\nsummary")
    for result in measured:
        summarise(result, args.accuracy)
    return 0
