"""Reference methods called through the solvers' own Python APIs (no cvxpy).

Registered names:

- ``clarabel-direct``: Clarabel on the dual problem, ``direct_solve_method="qdldl"``;
- ``osqp``: OSQP (problems without second-order cones: frictionless, or 2D
  friction written as two half-planes);
- ``scs``: SCS.

All three use the conic form built by :func:`conic_form` from the normalised
problem::

    min 1/2 x^T W x + b^T x   s.t.  A x + s = c,  s in K_zero x K_nonneg x K_soc

with the rows of each contact kind: tangential rows of frictionless contacts
are zero (``x_t = 0``, zero cone); NONNEG ``x_n >= 0`` and NONPOS
``-x_n >= 0`` (nonnegative cone); a friction cone ``|x_t| <= mu x_n`` is
either two half-planes ``mu x_n -+ x_t >= 0`` (2D, ``polyhedral``: a QP) or
a second-order cone ``(mu x_n, x_t)``; a friction contact with ``mu = 0``
also gets ``x_n >= 0``. FREE contacts have no row. Non-convex (UNION)
contacts are rejected.
"""
from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..problem.cones import ConeKind
from ..problem.conic import ConicProblem
from ..problem.global_form import convexified
from .polish import polish as polish_active_set
from .polish import polished_status
from .registry import CONVEX_CONES, FIRST_ORDER, INTERIOR_POINT, QP, register
from .result import CONVERGED, FAILED, INACCURATE, MAX_ITER, MethodOutput


@dataclass
class ConicForm:
    """``min 1/2 x.Px + q.x  s.t.  A x + s = c``, ``s`` in zero x nonneg x SOC cones.

    ``P`` is the upper triangle of W (CSC); rows of ``A`` are ordered zero
    cone, nonnegative cone, then the second-order cones of size ``soc_size``.
    ``repair`` describes what was done to a ``W`` read from a file that is not
    symmetric positive semi-definite (:func:`~lubcontact.problem.global_form.convexified`;
    empty for a step problem, whose ``W = L^T L``).
    """

    P: sp.csc_matrix
    q: np.ndarray
    A: sp.csc_matrix
    c: np.ndarray
    zero: int
    nonneg: int
    soc_count: int
    soc_size: int
    repair: dict


def _repair_info(form: ConicForm) -> dict:
    """``{"data_repair": ...}`` when the solver saw a repaired ``W``, else nothing."""
    return {"data_repair": form.repair} if form.repair.get("repaired") else {}


def conic_form(problem: ConicProblem, polyhedral: bool | None = None) -> ConicForm:
    """The conic data of a (normalised) convex problem.

    Parameters
    ----------
    polyhedral : bool, optional
        Write 2D friction cones as two half-planes; default: True in 2D.

    Raises
    ------
    ValueError
        For UNION contacts, or ``polyhedral=True`` with ``tangent_dim != 1``.
    """
    repair = {}
    if problem.delassus_factor is None:          # W given by a file: symmetric PSD for the solver
        problem, repair = convexified(problem)
    cones = problem.cones
    cones._require_convex()
    dim_t, nc, n = cones.tangent_dim, cones.count, problem.n_rows
    if polyhedral is None:
        polyhedral = dim_t == 1
    if polyhedral and dim_t != 1 and cones.has_friction:
        raise ValueError(f"polyhedral: friction cones are polyhedral only in 2D, tangent_dim={dim_t}")
    coulomb = np.flatnonzero(cones.mask(ConeKind.COULOMB)[cones.tangential]) if cones.has_friction \
        else np.zeros(0, dtype=int)
    cone_contacts = cones.tangential[coulomb]
    mu = cones.mu[cone_contacts]
    t_rows = nc + coulomb[:, None] * dim_t + np.arange(dim_t)           # (m, dim_t)
    free_t = np.ones(n - nc, dtype=bool)
    free_t[(t_rows - nc).ravel()] = False
    blocks_zero = [_rows(np.flatnonzero(free_t) + nc, 1.0, n)]
    blocks_nonneg = [_rows(np.flatnonzero(cones.mask(ConeKind.NONNEG)), -1.0, n),
                     _rows(np.flatnonzero(cones.mask(ConeKind.NONPOS)), 1.0, n),
                     _rows(cone_contacts[mu == 0], -1.0, n)]
    soc_count = 0
    if polyhedral:
        for sign in (1.0, -1.0):             # mu x_n - sign x_t >= 0
            blocks_nonneg.append(_combine(cone_contacts, -mu, t_rows[:, 0], sign, n))
    elif cone_contacts.size:
        soc_count = cone_contacts.size
        blocks_soc = [_rows(cone_contacts, 0.0, n, values=-mu)]
        blocks_soc += [_rows(t_rows[:, j], -1.0, n) for j in range(dim_t)]
        # interleave: per contact (mu x_n, x_t...) consecutive
        stacked = sp.vstack(blocks_soc).tocsr()
        order = (np.arange(dim_t + 1)[None, :] * soc_count + np.arange(soc_count)[:, None]).ravel()
        blocks_soc = [stacked[order]]
    zero = sp.vstack(blocks_zero)
    nonneg = sp.vstack(blocks_nonneg)
    parts = [zero, nonneg] + (blocks_soc if soc_count else [])
    A = sp.csc_matrix(sp.vstack(parts))
    return ConicForm(P=sp.triu(problem.delassus, format="csc"), q=np.asarray(problem.offset, float),
                     A=A, c=np.zeros(A.shape[0]), zero=zero.shape[0], nonneg=nonneg.shape[0],
                     soc_count=soc_count, soc_size=dim_t + 1, repair=repair)


def _rows(columns: np.ndarray, value: float, n: int, values: np.ndarray | None = None) -> sp.csr_matrix:
    """One row per entry of ``columns`` with ``value`` (or ``values``) in that column."""
    data = np.full(columns.size, value) if values is None else values
    return sp.csr_matrix((data, (np.arange(columns.size), columns)), shape=(columns.size, n))


def _combine(normal_rows: np.ndarray, normal_values: np.ndarray, tangent_rows: np.ndarray,
             tangent_value: float, n: int) -> sp.csr_matrix:
    m = normal_rows.size
    rows = np.concatenate([np.arange(m), np.arange(m)])
    cols = np.concatenate([normal_rows, tangent_rows])
    data = np.concatenate([normal_values, np.full(m, tangent_value)])
    return sp.csr_matrix((data, (rows, cols)), shape=(m, n))


@register("clarabel-direct", kind=INTERIOR_POINT, cones=CONVEX_CONES, warm_start=False,
          polishing=True)
def clarabel_direct(problem: ConicProblem, *, tol: float = 1e-10, max_iter: int = 200,
                    warm_start: np.ndarray | None = None,
                    polyhedral: bool | None = None, polish: bool = True) -> MethodOutput:
    """Clarabel on :func:`conic_form` (``warm_start`` is ignored: interior point).

    The solution is polished on its active set (:mod:`lubcontact.solvers.polish`,
    as the cvxpy ``clarabel`` does, with the same status rule:
    :func:`~lubcontact.solvers.polish.polished_status`) unless ``polish=False``; the polishing
    time is part of ``solve_time`` and also in ``info["polish_time"]``.
    """
    import clarabel

    start = time.perf_counter()
    form = conic_form(problem, polyhedral)
    cones = []
    if form.zero:
        cones.append(clarabel.ZeroConeT(form.zero))
    if form.nonneg:
        cones.append(clarabel.NonnegativeConeT(form.nonneg))
    cones += [clarabel.SecondOrderConeT(form.soc_size)] * form.soc_count
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = tol
    settings.tol_ktratio = min(1e-6, tol)
    settings.max_iter = max_iter
    settings.direct_solve_method = "qdldl"
    solver = clarabel.DefaultSolver(form.P, form.q, form.A, form.c, cones, settings)
    built = time.perf_counter()
    solution = solver.solve()
    done = time.perf_counter()
    raw = str(solution.status)
    status = {"Solved": CONVERGED, "AlmostSolved": INACCURATE, "MaxIterations": MAX_ITER}.get(raw, FAILED)
    forces = np.asarray(solution.x, dtype=float) if status != FAILED else np.full(problem.n_rows, np.nan)
    polished = False
    if polish and status != FAILED:
        forces, polished = polish_active_set(problem, forces)
        status = polished_status(status, problem, forces, polished, tol)
    polish_time = time.perf_counter() - done
    return MethodOutput(forces=forces, status=status, iterations=int(solution.iterations),
                        setup_time=built - start, solve_time=done - built + polish_time,
                        info={"raw_status": raw, "polished": polished, "polish_time": polish_time,
                              **_repair_info(form)})


@contextlib.contextmanager
def _silenced_stdout() -> Iterator[None]:
    """Send what C code writes to file descriptor 1 to ``/dev/null`` for the block
    (a no-op where standard output has no descriptor, e.g. some notebooks)."""
    try:
        descriptor = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):
        yield
        return
    sys.stdout.flush()
    saved = os.dup(descriptor)
    try:
        with open(os.devnull, "w") as sink:
            os.dup2(sink.fileno(), descriptor)
            try:
                yield
            finally:
                _flush_c_streams()
    finally:
        os.dup2(saved, descriptor)
        os.close(saved)


def _flush_c_streams() -> None:
    """``fflush(NULL)``: empty the C library's buffers while they still go to ``/dev/null``."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):
        pass


@register("osqp", kind=QP, cones=CONVEX_CONES, second_order=False)
def osqp_method(problem: ConicProblem, *, tol: float = 1e-10, max_iter: int = 100000,
                warm_start: np.ndarray | None = None, polish: bool = True) -> MethodOutput:
    """OSQP on the polyhedral :func:`conic_form` (raises ValueError for 3D friction)."""
    import osqp

    start = time.perf_counter()
    form = conic_form(problem, polyhedral=True)
    lower = np.concatenate([form.c[: form.zero], np.full(form.nonneg, -np.inf)])
    solver = osqp.OSQP()
    solver.setup(form.P, form.q, form.A, lower, form.c, eps_abs=tol, eps_rel=tol, max_iter=max_iter,
                 polishing=polish, verbose=False)
    if warm_start is not None:
        solver.warm_start(x=np.asarray(warm_start, dtype=float))
    built = time.perf_counter()
    with _silenced_stdout():             # OSQP's C code prints its polishing notes
        result = solver.solve(raise_error=False)
    done = time.perf_counter()
    raw = str(result.info.status)
    status = CONVERGED if raw == "solved" else INACCURATE if "inaccurate" in raw else \
        MAX_ITER if "maximum iterations" in raw else FAILED
    forces = np.asarray(result.x, dtype=float) if status != FAILED else np.full(problem.n_rows, np.nan)
    return MethodOutput(forces=forces, status=status, iterations=int(result.info.iter),
                        setup_time=built - start, solve_time=done - built,
                        info={"raw_status": raw, **_repair_info(form)})


@register("scs", kind=FIRST_ORDER, cones=CONVEX_CONES)
def scs_method(problem: ConicProblem, *, tol: float = 1e-10, max_iter: int = 100000,
               warm_start: np.ndarray | None = None, polyhedral: bool | None = None) -> MethodOutput:
    """SCS on :func:`conic_form` (``warm_start`` seeds the primal variable).

    The returned forces are projected onto their cones (SCS's iterates satisfy
    the cone constraints only to its tolerance). A problem whose conic form
    has no row (every contact FREE: an equality-constrained QP with no
    inequality) gets one empty equality row ``0 = 0``, which SCS requires.
    """
    import scs

    start = time.perf_counter()
    form = conic_form(problem, polyhedral)
    rows, zero = form.A, form.zero
    if rows.shape[0] == 0:               # only FREE contacts: SCS needs a row, add 0 = 0
        rows, zero = sp.csc_matrix((1, problem.n_rows)), 1
    data = {"P": form.P, "A": rows, "b": np.zeros(rows.shape[0]), "c": form.q}
    cone = {"z": zero, "l": form.nonneg, "q": [form.soc_size] * form.soc_count}
    solver = scs.SCS(data, cone, eps_abs=tol, eps_rel=tol, max_iters=max_iter, verbose=False)
    built = time.perf_counter()
    guess = {"x": np.asarray(warm_start, dtype=float)} if warm_start is not None else {}
    result = solver.solve(warm_start=bool(guess), **guess)
    done = time.perf_counter()
    raw = result["info"]["status"]
    status = CONVERGED if raw == "solved" else INACCURATE if "inaccurate" in raw else FAILED
    if status == INACCURATE and result["info"]["iter"] >= max_iter:
        status = MAX_ITER
    forces = np.full(problem.n_rows, np.nan)
    if status != FAILED:                 # SCS leaves forces up to ~1e-10 outside their cones
        forces = problem.cones.project(np.asarray(result["x"], dtype=float))
    return MethodOutput(forces=forces, status=status, iterations=int(result["info"]["iter"]),
                        setup_time=built - start, solve_time=done - built,
                        info={"raw_status": raw, **_repair_info(form)})
