"""The hard-case suite runner: every registered solver on every hard case (``lubcontact check-hard``).

The cases live in :mod:`lubcontact.bench.cases.hard`; each solve goes through
the benchmark harness (:func:`lubcontact.bench.harness.timed_solve`) and is judged
in the units of the normalised problem (``StepProblem.normalized``: velocities
by the free-velocity scale ``V``, lengths by ``dt V``, forces by ``m_ref V / dt``):

- **error**: the larger of the velocity error (max norm, each degree of
  freedom in its scaled unit) and the error of ``g = [D + s, 0] + dt H v``
  (gaps after the step and tangential displacements, max norm, in ``dt V``),
  against the exact answer when the case has one, else the Clarabel reference
  (:func:`lubcontact.solvers.reference_method`: ``clarabel`` on these step
  problems, tol 1e-10);
- **properties** (with the final shift s for a fixed-point solve): no gap
  below ``-PROPERTY_TOL``; forces inside their cones to ``CONE_TOL``
  (relative to the largest force, at least 1); per-contact complementarity
  ``|lam_c . g_c| <= PROPERTY_TOL`` (same relative measure); kinetic energy
  not above the free velocity's (``ENERGY_TOL`` relative) when zero velocity
  is admissible (to ``PROPERTY_TOL``): the contacts then do no work, the step
  is a projection onto a convex set holding 0.

Verdicts: ``ok`` (converged, error and properties within tolerance),
``flagged`` (a non-converged status: acceptable, the caller is told),
``wrong`` (converged but outside tolerance: a finding), ``rejected`` (a
``ValueError`` for a problem the method does not support, e.g. non-convex
cones for a conic solver), ``crash`` (any other exception, or a non-finite
result).
"""
from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..problem.metrics import PROPERTY_TOL, scaled_velocity_error, solution_properties
from ..problem.step import StepProblem
from ..solvers import (
    CONVERGED,
    CoulombResult,
    SolveResult,
    SolveSettings,
    methods,
    reference_method,
)
from .harness import timed_solve
from .options import given_methods, names, number, plain

if TYPE_CHECKING:
    from .cases.hard import HardCase

REFERENCE_TOL = 1e-10
ERROR_TOL = 1e-6
#: against a frictional Clarabel reference that polishing could not refine (3D sliding
#: contacts, lubcontact/solvers/polish.py): its velocities are only as good as its gap
#: tolerance (docs/records/hard_cases.md)
FRICTION_ERROR_TOL = 1e-5
CONE_TOL = 1e-10
ENERGY_TOL = 1e-6
FIXED_POINT_TOL = 1e-10

OK, FLAGGED, WRONG, REJECTED, CRASH = "ok", "flagged", "wrong", "rejected", "crash"
VERDICTS = (OK, FLAGGED, WRONG, REJECTED, CRASH)


def load_cases() -> dict:
    """The hard cases (:mod:`lubcontact.bench.cases.hard`), by name."""
    from .cases.hard import CASES

    return CASES


@dataclass
class Cell:
    """One solver on one case."""

    case: str
    solver: str
    verdict: str
    status: str = ""
    error: float = float("nan")
    iterations: int = 0
    seconds: float = 0.0
    failed: list[str] = field(default_factory=list)
    message: str = ""
    properties: dict = field(default_factory=dict)


@dataclass
class Expected:
    """What a case's solves are compared with."""

    velocities: np.ndarray | None
    source: str                  # "exact", "reference" or "none"
    reference: CoulombResult | None


def case_settings(method: str, tol: float, max_iter: int | None = None,
                  fixed_point: bool = False) -> SolveSettings:
    """How a case is solved: the convex problem as given, or (``fixed_point``, frictional
    problems) exact Coulomb friction by the fixed point on s to ``FIXED_POINT_TOL``."""
    return SolveSettings(method=method, tol=tol, max_iter=max_iter, exact_coulomb=fixed_point,
                         tol_fp=FIXED_POINT_TOL)


def solve_case(problem: StepProblem, method: str, tol: float, max_iter: int | None = None,
               fixed_point: bool = False) -> CoulombResult:
    """One solve of a case (:func:`case_settings`), a fixed point started from ``s = 0`` as the
    time stepper does (``result.shift`` holds the final shift); exceptions propagate."""
    return case_settings(method, tol, max_iter, fixed_point).solve(problem)


def expected_for(case: HardCase, problem: StepProblem, fixed_point: bool = False) -> Expected:
    """The exact velocities when the case has them, else the Clarabel reference's."""
    if case.reference_fails and case.exact is None:
        raise ValueError(f"{case.name}: a case whose reference fails needs an exact answer")
    reference = solve_case(problem, reference_method(problem), REFERENCE_TOL,
                           fixed_point=fixed_point)
    if case.exact is not None:
        return Expected(np.asarray(case.exact(problem), dtype=float), "exact", reference)
    if reference.status == CONVERGED:
        return Expected(reference.velocities, "reference", reference)
    return Expected(None, "none", reference)


def properties(problem: StepProblem, result: SolveResult) -> dict[str, float]:
    """:func:`~lubcontact.problem.metrics.solution_properties` of a solve, measured with the
    shift it was solved with; each must stay below its tolerance (module docstring)."""
    return solution_properties(problem.with_shift(result.shift), result.forces, result.velocities)


def judge(case: HardCase, problem: StepProblem, expected: Expected, result: CoulombResult,
          seconds: float) -> Cell:
    """The verdict of one finished solve."""
    cell = Cell(case.name, result.method, OK, result.status, iterations=int(result.iterations),
                seconds=seconds)
    if not (np.all(np.isfinite(result.forces)) and np.all(np.isfinite(result.velocities))):
        cell.verdict, cell.message = CRASH, "non-finite forces or velocities"
        return cell
    if expected.velocities is not None:
        cell.error = scaled_velocity_error(problem, result.velocities, expected.velocities)
    cell.properties = properties(problem, result)
    tolerance = error_tolerance(problem, expected)
    limits = dict(penetration=PROPERTY_TOL, cone=CONE_TOL, complementarity=PROPERTY_TOL,
                  energy=ENERGY_TOL)
    cell.failed = [name for name, value in cell.properties.items() if not value <= limits[name]]
    if cell.error > tolerance:
        cell.failed.insert(0, "error")
    if case.must_flag:
        cell.failed.insert(0, "must_flag")
    if result.status != CONVERGED:
        cell.verdict = FLAGGED
    elif cell.failed:
        cell.verdict = WRONG
    return cell


def error_tolerance(problem: StepProblem, expected: Expected) -> float:
    """``ERROR_TOL``, or ``FRICTION_ERROR_TOL`` against an unpolished frictional Clarabel reference."""
    if expected.source == "reference" and problem.cones.has_friction \
            and not expected.reference.info.get("polished", False):
        return FRICTION_ERROR_TOL
    return ERROR_TOL


def run_case(case: HardCase, solvers: list[str], tol: float, max_iter: int | None,
             fixed_point: bool = False) -> list[Cell]:
    """Every solver of ``solvers`` on one case (see :func:`solve_case` for ``fixed_point``)."""
    problem = case.problem
    expected = {}
    cells = []
    for name in solvers:
        settings = case_settings(name, tol, max_iter, fixed_point)
        timed = timed_solve(problem, settings)
        if timed.result is not None:
            exact = settings.solves_exact_coulomb(problem)
            if exact not in expected:
                expected[exact] = expected_for(case, problem, exact)
            cells.append(judge(case, problem, expected[exact], timed.result, timed.seconds))
        else:
            cells.append(Cell(case.name, name, REJECTED if timed.rejected else CRASH,
                              message=timed.message))
    return cells


def run_suite(case_names: list[str] | None = None, solvers: list[str] | None = None,
              tol: float = 1e-9, max_iter: int | None = None,
              fixed_point: bool = False) -> list[Cell]:
    """Run the suite; ``None`` means every case / every registered method.

    With ``fixed_point`` only the frictional cases run, through the fixed point on s."""
    cases = load_cases()
    names = list(cases) if case_names is None else case_names
    unknown = [n for n in names if n not in cases]
    if unknown:
        raise ValueError(f"cases: unknown {unknown}; known: {', '.join(cases)}")
    solvers = methods() if solvers is None else solvers
    if fixed_point:
        names = [n for n in names if cases[n].problem.cones.has_friction]
    return [cell for name in names
            for cell in run_case(cases[name], solvers, tol, max_iter, fixed_point)]


# -- reporting ---------------------------------------------------------------------------------------
def cell_text(cell: Cell) -> str:
    """``verdict error/iterations`` (``status`` shown for flagged cells)."""
    if cell.verdict in (REJECTED, CRASH):
        return cell.verdict
    error = "-" if np.isnan(cell.error) else f"{cell.error:.0e}"
    label = cell.status if cell.verdict == FLAGGED else cell.verdict
    extra = "" if cell.verdict != WRONG else "!" + ",".join(cell.failed)
    return f"{label} {error}/{cell.iterations}{extra}"


def matrix(cells: list[Cell], markdown: bool = False) -> str:
    """The case x solver table."""
    cases = list(dict.fromkeys(c.case for c in cells))
    solvers = list(dict.fromkeys(c.solver for c in cells))
    by_key = {(c.case, c.solver): c for c in cells}
    marked = {name for name, case in load_cases().items() if case.reference_fails}
    rows = [["case"] + solvers] + [[case + ("*" if case in marked else "")] +
                                   [cell_text(by_key[case, s]) for s in solvers] for case in cases]
    if markdown:
        lines = ["| " + " | ".join(row) + " |" for row in rows]
        lines.insert(1, "|" + "---|" * len(rows[0]))
        return "\n".join(lines)
    widths = [max(len(row[k]) for row in rows) for k in range(len(rows[0]))]
    return "\n".join("  ".join(text.ljust(w) for text, w in zip(row, widths)).rstrip() for row in rows)


def summary(cells: list[Cell]) -> str:
    """Counts per verdict and the details of every wrong, rejected or crashed cell."""
    counts = {v: sum(c.verdict == v for c in cells) for v in VERDICTS}
    lines = [", ".join(f"{v}: {n}" for v, n in counts.items())]
    for cell in cells:
        if cell.verdict == WRONG:
            measures = ", ".join(f"{k} {v:.1e}" for k, v in cell.properties.items() if v > 0)
            lines.append(f"  wrong    {cell.case} / {cell.solver}: error {cell.error:.2e} "
                         f"(failed: {', '.join(cell.failed)}; {measures})")
        elif cell.verdict in (REJECTED, CRASH):
            lines.append(f"  {cell.verdict:<8} {cell.case} / {cell.solver}: {cell.message}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """``lubcontact check-hard``: print the case x solver matrix; exit 1 on a wrong or crashed cell."""
    parser = argparse.ArgumentParser(prog="lubcontact check-hard", description=plain(__doc__.splitlines()[0]))
    parser.add_argument("--cases", help="comma-separated case names (default: all)")
    parser.add_argument("--solvers", nargs="+", metavar="METHOD",
                        help="method names, space or comma separated (default: all registered)")
    parser.add_argument("--tol", type=number(float, 0, above=True), default=1e-9,
                        help="solver tolerance (default 1e-9)")
    parser.add_argument("--max-iter", type=int, default=None, help="iteration cap (method default)")
    parser.add_argument("--fixed-point", action="store_true",
                        help="frictional cases only, exact Coulomb by the fixed point on s from s = 0")
    parser.add_argument("--markdown", action="store_true", help="print the matrix as a markdown table")
    parser.add_argument("--list", action="store_true", help="list the cases and exit")
    args = parser.parse_args(argv)
    if args.list:
        for name, case in load_cases().items():
            print(f"{name}\n    hard:     {case.hard}\n    expected: {case.expected}")
        return 0
    try:
        solvers = None if args.solvers is None else given_methods("--solvers", args.solvers)
    except ValueError as exc:
        parser.error(f"argument {exc}")
    start = time.perf_counter()
    cells = run_suite(names(args.cases), solvers, args.tol, args.max_iter, args.fixed_point)
    print(matrix(cells, markdown=args.markdown))
    print()
    print(summary(cells))
    print(f"({len(cells)} solves in {time.perf_counter() - start:.1f} s; cell = verdict or status, "
          "scaled error / iterations; * = reference marked unreliable (reference_fails), "
          "checked against the exact answer)")
    return int(any(c.verdict in (WRONG, CRASH) for c in cells))
