"""The measurements of ``lubcontact compare``: every variant on every instance at every tolerance.

Each instance gets one reference solve (:func:`reference_solve`) and, per
variant (a method, cold or warm-started) and tolerance, one
:class:`Measurement`: ``repeats`` timed solves through
:func:`~lubcontact.bench.harness.timed_solve`, errors and iterations from
the first. A solver that exhausts itself (``max_iter``, ``diverged``,
``failed``, an exception) is not run at tighter tolerances on that instance:
its rows there are ``skipped``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TextIO

import numpy as np

from ..problem.metrics import most_negative_gap, relative_error, scaled_coulomb_error
from ..solvers import CONVERGED, CoulombResult, SolveSettings
from .harness import TimedSolve, solve_reference, timed_solve, warm_up
from .problem_sets import COULOMB, Instance

REFERENCE_TOL = 1e-10
MAX_OUTER = 100            # outer iterations of the fixed point on s
SUCCESS_SLACK = 100.0
WARM = "+warm"
ERROR, SKIPPED = "error", "skipped"
# statuses after which tighter tolerances cannot do better (an "inaccurate" loose solve can)
EXHAUSTED = ("max_iter", "diverged", "failed", ERROR)
NAN = float("nan")


@dataclass(frozen=True)
class Variant:
    """A solver as compared: a registered method, cold or warm-started."""

    method: str
    warm: bool = False

    @property
    def label(self) -> str:
        return self.method + (WARM if self.warm else "")


@dataclass
class Measurement:
    """One result row: an instance solved by a variant at one tolerance.

    The measured fields keep their failure values (NaN, -1, ``success = False``)
    for a solve that raised (status ``error``) or was not run (``skipped``).

    Attributes
    ----------
    instance, group, mode, n_contacts, n_rows
        The instance (:class:`~lubcontact.bench.problem_sets.Instance`).
    solver, method, warm
        The variant: its label, method and start.
    tol : float
    repeats : int
        Timed solves done (a solve that does not converge is not repeated).
    status : str
        The first solve's status, ``error`` or ``skipped``.
    iterations, outer_iterations : int
        Total inner iterations and fixed-point iterations of the first solve.
    time_s, time_min_s, time_max_s : float
        Median, min and max wall-clock seconds of the repeats.
    setup_s, solve_s : float
        The method's own split (medians; summed over the inner solves of Coulomb's fixed point).
    residual : float
        Natural-map residual (normalised units).
    velocity_error, fclib_error, min_gap, error : float
        Errors of the first solve; ``error`` is the primary one (module
        docstring of :mod:`lubcontact.bench.compare`).
    success : bool
    reproducible : bool
        Identical iterations, status and forces across the repeats.
    message : str
        The exception of a failed solve, or why it was skipped.
    """

    instance: str
    group: str
    mode: str
    n_contacts: int
    n_rows: int
    solver: str
    method: str
    warm: bool
    tol: float
    repeats: int = 0
    status: str = ERROR
    iterations: int = -1
    outer_iterations: int = -1
    time_s: float = NAN
    time_min_s: float = NAN
    time_max_s: float = NAN
    setup_s: float = NAN
    solve_s: float = NAN
    residual: float = NAN
    velocity_error: float = NAN
    fclib_error: float = NAN
    min_gap: float = NAN
    error: float = NAN
    success: bool = False
    reproducible: bool = True
    message: str = ""

    @classmethod
    def of(cls, instance: Instance, variant: Variant, tol: float, **measured) -> Measurement:
        """The row of ``instance``, ``variant`` and ``tol`` with the ``measured`` fields."""
        return cls(instance=instance.name, group=instance.group, mode=instance.mode,
                   n_contacts=instance.n_contacts, n_rows=instance.n_rows, solver=variant.label,
                   method=variant.method, warm=variant.warm, tol=tol, **measured)


@dataclass
class ReferenceRow:
    """The reference solve of one instance (one row of the report's instance table)."""

    instance: str
    group: str
    mode: str
    n_contacts: int
    n_rows: int
    warm_start: bool
    errors_against: str
    reference_method: str = "none"
    reference_status: str = ERROR
    reference_time_s: float = NAN
    reference_iterations: int = -1
    reference_fclib_error: float = NAN
    reference_exact_error: float = NAN


def settings_for(instance: Instance, method: str, tol: float,
                 max_iter: int | None) -> SolveSettings:
    """How every solver is run on ``instance``: fixed point on s with ``tol_fp = tol`` for
    Coulomb instances, one convex solve otherwise."""
    return SolveSettings(method=method, tol=tol, max_iter=max_iter,
                         exact_coulomb=instance.mode == COULOMB, tol_fp=tol, max_outer=MAX_OUTER)


def run_once(instance: Instance, method: str, tol: float, warm: bool = False,
             max_iter: int | None = None) -> TimedSolve:
    """One timed solve of ``instance`` (warm-started from its ``warm_start`` and ``warm_shift``)."""
    return timed_solve(instance.problem, settings_for(instance, method, tol, max_iter),
                       instance.warm_start if warm else None, instance.warm_shift if warm else None)


def measure(instance: Instance, variant: Variant, tol: float, reference: TimedSolve | None,
            repeats: int, max_iter: int | None, slack: float) -> Measurement:
    """Solve ``repeats`` times; one row (errors and iterations from the first solve).

    ``reference`` is the instance's reference solve (None or failed: no
    velocity error unless the instance has exact velocities).
    """
    walls, setups, solves, signatures, first, message = [], [], [], [], None, ""
    for _ in range(repeats):
        timed = run_once(instance, variant.method, tol, variant.warm, max_iter)
        if timed.result is None:
            message = timed.message
            break
        result = timed.result
        first = first or result
        walls.append(timed.seconds)
        setups.append(result.setup_time)         # summed over a fixed point's inner solves
        solves.append(result.solve_time)
        signatures.append((result.iterations, result.status, result.x.tobytes()))
        if result.status != CONVERGED:
            break   # a failure is penalised, not timed: no repeats
    if first is None:
        return Measurement.of(instance, variant, tol, message=message)
    row = Measurement.of(instance, variant, tol, repeats=len(walls), status=first.status,
                         iterations=int(first.iterations),
                         outer_iterations=int(first.outer_iterations),
                         time_s=float(np.median(walls)), time_min_s=float(np.min(walls)),
                         time_max_s=float(np.max(walls)), setup_s=float(np.median(setups)),
                         solve_s=float(np.median(solves)), residual=float(first.residual),
                         reproducible=len(set(signatures)) == 1, message=message,
                         **_errors(instance, first, reference))
    row.error = row.fclib_error if instance.mode == COULOMB else row.velocity_error
    if instance.must_flag:
        row.success = bool(first.status != CONVERGED and np.all(np.isfinite(first.x)))
    else:
        row.success = bool(first.status == CONVERGED and row.error <= slack * tol)
    return row


def skipped(instance: Instance, variant: Variant, tol: float, failed_at: float) -> Measurement:
    """The row of a solve not run because the same solver failed at a looser tolerance."""
    return Measurement.of(instance, variant, tol, status=SKIPPED,
                          message=f"not run: did not converge at the looser tol {failed_at:.0e}")


def _target_velocities(instance: Instance, reference: TimedSolve | None) -> np.ndarray | None:
    """Exact velocities when known, else the reference's (None when unusable or infeasible)."""
    if instance.must_flag:
        return None
    if instance.exact is not None:
        return instance.exact
    if reference is None or reference.result is None \
            or not np.all(np.isfinite(reference.result.velocities)):
        return None
    return reference.result.velocities


def _errors(instance: Instance, result: CoulombResult,
            reference: TimedSolve | None) -> dict[str, float]:
    """Velocity error, FCLIB error and most negative gap of a result (NaN when not finite)."""
    problem = instance.problem
    finite = bool(np.all(np.isfinite(result.x)) and np.all(np.isfinite(result.velocities)))
    target = _target_velocities(instance, reference)
    return dict(velocity_error=relative_error(result.velocities, target)
                if finite and target is not None else NAN,
                fclib_error=scaled_coulomb_error(problem, result.x) if finite else NAN,
                min_gap=most_negative_gap(problem, result.velocities) if finite else NAN)


def reference_solve(instance: Instance, max_iter: int | None) -> tuple[TimedSolve, ReferenceRow]:
    """The reference at ``REFERENCE_TOL`` (:func:`~lubcontact.bench.harness.solve_reference`),
    run like the solvers; returns the solve and its summary row."""
    row = ReferenceRow(instance=instance.name, group=instance.group, mode=instance.mode,
                       n_contacts=instance.n_contacts, n_rows=instance.n_rows,
                       warm_start=instance.warm_start is not None,
                       errors_against="no solution (must flag)" if instance.must_flag else
                       "exact velocities" if instance.exact is not None else "reference")
    method, timed = solve_reference(
        instance.problem, lambda m: settings_for(instance, m, REFERENCE_TOL, max_iter))
    result = timed.result
    if result is None:
        row.reference_status = f"error: {timed.message}"
        return timed, row
    row.reference_method, row.reference_status = method, result.status
    row.reference_time_s, row.reference_iterations = timed.seconds, int(result.iterations)
    if np.all(np.isfinite(result.x)):
        row.reference_fclib_error = scaled_coulomb_error(instance.problem, result.x)
    if instance.exact is not None and np.all(np.isfinite(result.velocities)):
        row.reference_exact_error = relative_error(result.velocities, instance.exact)
    return timed, row


def variants(methods: list[str], instances: list[Instance]) -> list[Variant]:
    """Cold variants of every method, plus warm ones when every instance has a warm start."""
    out = [Variant(m) for m in methods]
    if all(instance.warm_start is not None for instance in instances):
        out += [Variant(m, warm=True) for m in methods]
    return out


def run_set(instances: list[Instance], methods: list[str], tolerances: list[float], repeats: int,
            max_iter: int | None = None, slack: float = SUCCESS_SLACK,
            log: TextIO | None = None) -> tuple[list[Measurement], list[ReferenceRow]]:
    """Measure every variant on every instance at every tolerance.

    Returns
    -------
    rows : list of Measurement
        One per instance, variant and tolerance (see :func:`measure`).
    references : list of ReferenceRow
        One per instance: the reference's status, time and iterations.
    """
    warm_up(min(instances, key=lambda i: i.n_rows).problem, methods)
    rows, references = [], []
    for instance in instances:
        reference, summary = reference_solve(instance, max_iter)
        references.append(summary)
        _log(log, f"{instance.name}: {instance.n_contacts} contacts, reference "
                  f"{summary.reference_status} in {summary.reference_time_s:.3g} s")
        for variant in variants(methods, instances):
            failed_at = None
            for tol in tolerances:
                if failed_at is None:
                    rows.append(measure(instance, variant, tol, reference, repeats, max_iter,
                                        slack))
                    failed_at = tol if rows[-1].status in EXHAUSTED else None
                else:
                    rows.append(skipped(instance, variant, tol, failed_at))
            last = rows[-1]
            _log(log, f"  {variant.label:<18} tol {last.tol:.0e}: {last.status:<10} "
                      f"{last.iterations:>6} it  {last.time_s:.3g} s  error {last.error:.2e}")
    return rows, references


def _log(log: TextIO | None, text: str) -> None:
    if log is not None:
        print(text, file=log, flush=True)
