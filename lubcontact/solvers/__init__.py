"""Solvers for step problems: reference (cvxpy + Clarabel) and fast methods.

Use :func:`solve` with a registered method name; :func:`methods` lists them.
"""
from .registry import (CONVERGED, DIVERGED, FAILED, INACCURATE, MAX_ITER, STATUSES, SolveResult,
                   SolverError, SolverWarning, check_status, methods, register, solve)
from . import reference  # noqa: F401  (registers the reference methods)
from . import direct  # noqa: F401  (clarabel-direct, osqp, scs)
from . import gradient  # noqa: F401  (pgd, apgd, bb, apgd-jacobi, apgd-as)

__all__ = ["solve", "methods", "register", "check_status", "SolveResult", "SolverError",
           "SolverWarning", "CONVERGED", "DIVERGED", "FAILED", "INACCURATE", "MAX_ITER", "STATUSES"]
