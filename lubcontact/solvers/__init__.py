"""Solvers for conic problems: the registry, the reference (cvxpy + Clarabel) and fast methods.

Use :func:`solve` with a registered method name; :func:`methods` lists them
(``methods(kind="first-order")`` one family); :func:`register` adds one;
:class:`SolveSettings` says how a step is solved (exact Coulomb by
:func:`solve_coulomb`, the fixed point on s, or the convex relaxation);
:func:`~lubcontact.solvers.verify.verify` judges any candidate solution.
This layer sees problems only (:mod:`lubcontact.problem`), never grains.
"""
from . import (
    direct,  # noqa: F401  (registers clarabel-direct, osqp, scs)
    gauss_seidel,  # noqa: F401  (registers nsgs)
    gradient,  # noqa: F401  (registers pgd, apgd, bb, apgd-jacobi, apgd-as)
    newton,  # noqa: F401  (registers newton-ac)
    newton_first_try,  # noqa: F401  (newton-ac's first try on small 2D steps)
    reference,  # noqa: F401  (registers clarabel, clarabel-dual)
)
from .coulomb import solve_coulomb
from .registry import (
    CONVEX_CONES,
    FIRST_ORDER,
    INTERIOR_POINT,
    KINDS,
    NEWTON,
    QP,
    SolverInfo,
    capable_methods,
    methods,
    reference_method,
    register,
    register_first_try,
    solve,
    solver_info,
    unregister,
)
from .result import (
    CONVERGED,
    DIVERGED,
    FAILED,
    INACCURATE,
    MAX_ITER,
    STATUSES,
    CoulombResult,
    MethodOutput,
    SolverError,
    SolveResult,
    SolverWarning,
    check_status,
)
from .settings import SolveSettings

__all__ = ["solve", "solve_coulomb", "SolveSettings", "CoulombResult", "methods", "register",
    "register_first_try", "unregister", "solver_info", "capable_methods", "reference_method", "SolverInfo",
    "FIRST_ORDER", "INTERIOR_POINT", "QP", "NEWTON", "KINDS", "check_status", "MethodOutput",
    "SolveResult", "SolverError", "SolverWarning", "CONVERGED", "DIVERGED", "FAILED",
    "INACCURATE", "MAX_ITER", "STATUSES", "CONVEX_CONES"]
