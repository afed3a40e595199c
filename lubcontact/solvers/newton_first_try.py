"""``newton-ac``'s first try: a small 2D exact-Coulomb step by its first Newton call alone.

A small system's step (a 2D problem on the compiled lane with friction cones, warm-started from
the previous step) is the common case of exact Coulomb by ``newton-ac``: the first call of its
first strategy (:func:`~.newton.first_call`: the proximal loop's first pass from the warm start)
converges on almost every step (197-200 of 200 captured steps of settling piles of 4 to 40
grains). Around that call the layers the first try leaves out (:func:`~.newton.newton_alart_curnier`
and :func:`~.newton._strategies` in full, and in
:func:`~lubcontact.solvers.coulomb.solve_native_coulomb` a copy of the problem to normalise)
spent a tenth to a sixth of a solve at 7-66 contacts (docs/records/benchmarks.md, "newton-ac's
first try on small steps").

:func:`first_try` normalises the problem with its dense ``W`` built at once
(``StepProblem.normalized(dense=True)``, the same arrays), builds the
:class:`~.newton.AlartCurnier` function and makes that call. Where it converged, the general path
would have returned this output from it: :func:`~.newton._strategies` stops at a converged
strategy, and on a small problem with friction cones nothing runs before it (no plain try, no
joint phase) and nothing after (no finish, no fallback). ``solve_native_coulomb`` then takes the
output as its first pass's, and the shift, the pieces of UNION contacts and the check that
follow are its own. Elsewhere the first try returns None and the general path solves the step
from the start, repeating the first call: such a step cost 1.35-1.65 times a solve without the
first try. Settling piles had 0-3 of them in 200 steps; a developed 40-grain flow had 8 % of
them, and there the first try gained nothing beyond the runs' spread.
"""
from __future__ import annotations

import time

import numpy as np

from ..problem.conic import ConicProblem
from ..problem.step import StepProblem
from . import newton
from .registry import register_first_try
from .result import CONVERGED, MethodOutput


@register_first_try("newton-ac")
def first_try(problem: ConicProblem, *, tol: float, max_iter: int | None = None,
              warm_start: np.ndarray | None = None, **options) -> tuple[StepProblem, MethodOutput] | None:
    """``newton-ac`` on a small warm-started 2D step, by its first call alone (module docstring).

    Parameters
    ----------
    problem : ConicProblem
        In physical units, with friction; its shift is ignored, as by the general path.
    tol : float
        The FCLIB error to reach, > 0.
    max_iter : int, optional
        The cap on Newton iterations (:data:`~.newton.MAX_ITERATIONS` when None).
    warm_start : ndarray, shape (n_rows,), optional
        Initial forces (physical units); without one (or with zero forces) there is no first try.
    **options
        ``newton-ac``'s other options (``fallback``, ``joint``), checked as it checks them
        (:func:`~.newton.checked_options`): neither acts before its first strategy has run, nor
        after a converged one.

    Returns
    -------
    (StepProblem, MethodOutput) or None
        The normalised problem (without shift) and ``newton-ac``'s converged output on it, the
        general path's; None where the problem is not such a step (a local problem, one already
        normalised, 3D cones, no friction cone, more rows than the small compiled lane takes, no
        warm start or zero forces) or the first call did not converge.
    """
    newton.checked_options(**options)
    cones = problem.cones
    if warm_start is None or not isinstance(problem, StepProblem) or problem.scaling is not None \
            or not cones.has_friction or not all(newton.lanes(problem)):
        return None
    clock = time.perf_counter()
    unshifted = problem if not problem.shift.any() else problem.with_shift(np.zeros(cones.count))
    scaled = unshifted.normalized(dense=True)   # none cached on the caller's problem
    forces = warm_start / scaled.scaling.force
    if not forces.any():
        return None
    function = newton.AlartCurnier(scaled)
    setup_time = time.perf_counter() - clock
    phase = newton.first_call(function, scaled, forces, tol,
                              newton.MAX_ITERATIONS if max_iter is None else max_iter)
    if phase.status != CONVERGED:
        return None
    return scaled, newton.method_output(function, phase.forces, CONVERGED, phase.iterations,
                                        phase.history, newton.phase_info(phase, 0), clock,
                                        setup_time)
