"""Solvers for conic problems: the registry, the reference (cvxpy + Clarabel) and fast methods.

Use :func:`solve` with a registered method name; :func:`methods` lists them
(``methods(kind="first-order")`` one family); :func:`register` adds one;
:func:`solve_coulomb` solves exact Coulomb friction by the fixed point on s
around any of them. This layer sees problems only (:mod:`lubcontact.problem`),
never grains.
"""
from . import direct  # noqa: F401  (clarabel-direct, osqp, scs)
from . import gradient  # noqa: F401  (pgd, apgd, bb, apgd-jacobi, apgd-as)
from . import reference  # noqa: F401  (registers the reference methods)
from .registry import (FIRST_ORDER, INTERIOR_POINT, KINDS, QP, SolverInfo, capable_methods,
                       methods, reference_method, register, solve, solver_info, unregister)
from .coulomb import solve_coulomb
from .settings import SolveSettings
from .result import (CONVERGED, DIVERGED, FAILED, INACCURATE, MAX_ITER, STATUSES, CoulombResult,
                     MethodOutput, SolverError, SolverWarning, SolveResult, check_status)

__all__ = ["solve", "solve_coulomb", "SolveSettings", "CoulombResult", "methods", "register", "unregister", "solver_info", "capable_methods", "reference_method",
           "SolverInfo", "FIRST_ORDER", "INTERIOR_POINT", "QP", "KINDS", "check_status",
           "MethodOutput", "SolveResult", "SolverError", "SolverWarning", "CONVERGED", "DIVERGED",
           "FAILED", "INACCURATE", "MAX_ITER", "STATUSES"]
