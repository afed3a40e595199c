"""``newton-ac``'s first try: a small 2D exact-Coulomb step normalised with its dense forms at once.

A small system's step (a 2D problem on the compiled lane with friction cones, warm-started from
the previous step) takes ``newton-ac``'s dense lane, which builds the normalised problem's dense
``W``. The general path (:func:`~lubcontact.solvers.coulomb.solve_native_coulomb`) normalises a
copy of the problem (to leave no cache on the caller's) and lets ``W`` be built lazily, through
the copy's dense Jacobian, in two compiled calls and their caches. :func:`first_try` normalises
the problem with its dense forms built in one compiled call (``StepProblem.normalized(dense=True)``:
the same arrays, nothing cached on the caller's problem) and runs ``newton-ac`` on it, whole:
its output is the general path's by construction, and ``solve_native_coulomb`` takes it as its
first pass's (the shift, the pieces of UNION contacts and the check that follow are its own).
On steps of settling piles of 4 to 40 grains a solve took 0.80-0.94 of its time without it
(docs/records/benchmarks.md, "newton-ac's first try on small steps").
"""
from __future__ import annotations

import time

import numpy as np

from ..problem.conic import ConicProblem
from ..problem.step import StepProblem
from . import newton
from .registry import register_first_try
from .result import MethodOutput


@register_first_try("newton-ac")
def first_try(problem: ConicProblem, *, tol: float, max_iter: int | None = None,
              warm_start: np.ndarray | None = None, **options) -> tuple[StepProblem, MethodOutput] | None:
    """``newton-ac`` on a small warm-started 2D step, normalised with its dense forms at once.

    Parameters
    ----------
    problem : ConicProblem
        In physical units, with friction; its shift is ignored, as by the general path.
    tol : float
        The FCLIB error to reach, > 0.
    max_iter : int, optional
        The cap on Newton iterations (``newton-ac``'s default when None).
    warm_start : ndarray, shape (n_rows,), optional
        Initial forces (physical units); without one there is no first try.
    **options
        ``newton-ac``'s other options (``fallback``, ``joint``), passed on.

    Returns
    -------
    (StepProblem, MethodOutput) or None
        The normalised problem (without shift) and ``newton-ac``'s output on it; None, before
        any work, where the problem is not such a step (a local problem, one already normalised,
        3D cones, no friction cone, more rows than the small compiled lane takes, no warm start).
    """
    cones = problem.cones
    if warm_start is None or not isinstance(problem, StepProblem) or problem.scaling is not None \
            or not cones.has_friction or not all(newton.lanes(problem)):
        return None
    clock = time.perf_counter()
    unshifted = problem if not problem.shift.any() else problem.with_shift(np.zeros(cones.count))
    scaled = unshifted.normalized(dense=True)   # none cached on the caller's problem
    normalise_time = time.perf_counter() - clock
    if max_iter is not None:
        options["max_iter"] = max_iter
    output = newton.newton_alart_curnier(scaled, tol=tol, warm_start=warm_start / scaled.scaling.force,
                                         **options)
    output.setup_time += normalise_time           # counted as set-up, as by the general path
    return scaled, output
