"""How a step's problem is solved: one :class:`SolveSettings` value, one :meth:`~SolveSettings.solve`.

Every caller (the time stepper, ``compare``, ``check-hard``, ``bench
friction``) solves through it, so the rule "exact Coulomb by the fixed point
on s when the problem has friction and ``exact_coulomb`` is set (one native
solve for a method that solves exact Coulomb itself, whatever
``exact_coulomb`` says), else one convex solve" is written once.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import checks
from ..problem.conic import ConicProblem
from .coulomb import solve_coulomb
from .registry import methods, solve, solver_info
from .result import CoulombResult

FIXED_POINT_OPTIONS = ("joint", "forcing", "anderson")
"""Options of :func:`~lubcontact.solvers.solve_coulomb` itself, never passed to a convex solve."""


@dataclass(frozen=True)
class SolveSettings:
    """Method, tolerances and the exact-Coulomb choice for solving step problems.

    Attributes
    ----------
    method : str
        A registered method (:func:`~lubcontact.solvers.methods`).
    tol : float
        Tolerance of each (inner) solve, > 0.
    max_iter : int or None
        Iteration cap of each (inner) solve (the method's default when None).
    exact_coulomb : bool
        Solve frictional problems exactly by the fixed point on s
        (:func:`~lubcontact.solvers.solve_coulomb`); False solves the convex
        relaxation once (sliding contacts then separate by ``mu dt |u_T|``).
        A method that solves exact Coulomb itself (``native_coulomb``, e.g.
        ``newton-ac``) has no relaxation: it solves exact Coulomb either way.
    tol_fp : float
        Tolerance of the fixed point on s (relative change of s), > 0.
    max_outer : int
        Cap on the fixed point's outer iterations, >= 1.
    options : dict
        Extra keyword arguments of the method (a ``max_iter`` given here
        moves to the field); ``joint``, ``forcing`` and ``anderson`` go to
        the fixed point only (``joint`` also to a native Coulomb method that has the option,
        ``newton-ac``: :func:`~lubcontact.solvers.coulomb.has_joint_phase`).
    """

    method: str = "clarabel"
    tol: float = 1e-9
    max_iter: int | None = None
    exact_coulomb: bool = True
    tol_fp: float = 1e-8
    max_outer: int = 50
    options: dict = field(default_factory=dict)

    def __post_init__(self):
        options = dict(self.options)
        if "max_iter" in options:                    # accepted among the method's options too
            checks.require(self.max_iter is None, "max_iter", "given both as a field and an option")
            object.__setattr__(self, "max_iter", options.pop("max_iter"))
        object.__setattr__(self, "options", options)
        checks.require(self.method in methods(), "solver",
                       f"must be a registered method ({', '.join(methods())}), got {self.method!r}")
        checks.positive_scalar("tol", self.tol)
        checks.positive_scalar("tol_fp", self.tol_fp)
        checks.require(isinstance(self.max_outer, (int, np.integer)) and self.max_outer >= 1,
                       "max_outer", "must be an integer >= 1", self.max_outer)
        checks.require(self.max_iter is None or (isinstance(self.max_iter, (int, np.integer))
                                                 and self.max_iter >= 1),
                       "max_iter", "must be None or an integer >= 1", self.max_iter)

    def solves_exact_coulomb(self, problem: ConicProblem) -> bool:
        """Whether :meth:`solve` gives ``problem`` exact Coulomb friction: it has friction, and
        ``exact_coulomb`` is set or the method solves exact Coulomb itself (``native_coulomb``
        in :class:`~lubcontact.solvers.SolverInfo`: such a method has no relaxation)."""
        return problem.cones.has_friction and (self.exact_coulomb
                                               or solver_info(self.method).native_coulomb)

    @property
    def convex_options(self) -> dict:
        """``options`` without the fixed point's own."""
        return {k: v for k, v in self.options.items() if k not in FIXED_POINT_OPTIONS}

    def solve(self, problem: ConicProblem, warm_start: np.ndarray | None = None,
              shift: np.ndarray | None = None) -> CoulombResult:
        """Solve ``problem`` as these settings say.

        Parameters
        ----------
        problem : ConicProblem
            In physical units.
        warm_start : ndarray, shape (n_rows,), optional
            Initial forces.
        shift : ndarray, shape (nc,), optional
            Initial shift of the fixed point on s (e.g. the previous step's);
            ignored by a convex solve, which keeps the problem's own shift.

        Returns
        -------
        CoulombResult
            The fixed point's result, or one convex solve recorded as one outer iteration.
        """
        if self.solves_exact_coulomb(problem):
            return solve_coulomb(problem, self.method, tol=self.tol, tol_fp=self.tol_fp,
                                 max_outer=self.max_outer, max_iter=self.max_iter,
                                 warm_start=warm_start, shift=shift, **self.options)
        result = solve(problem, self.method, tol=self.tol, max_iter=self.max_iter,
                       warm_start=warm_start, **self.convex_options)
        return CoulombResult.single(result)
