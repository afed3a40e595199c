"""``nsgs``: non-smooth Gauss-Seidel with exact local Coulomb solves (2D), as in Siconos' NSGS.

Contact by contact, with the others' forces frozen, each 2D frictional contact
gets the exact solution of its own Coulomb law (open, stick, pulled for UNION
contacts, slide: :func:`.kernels.local_coulomb_2d`) and each other row its
clipped minimiser; a sweep visits every contact once. This solves exact
Coulomb itself (the law is local, no shift ``s``: ``native_coulomb``), UNION
contacts as in ``newton-ac`` (bilateral normal row, friction while pushed).
It needs no factorisation and no regular Jacobian, so it goes on where
Newton methods stall (degenerate contacts, rank-deficient ``W``), at the
price of many sweeps on jammed piles: it is the robust, slow end of the
family. On a step problem (``W = F^T F`` with ``F = dt M^-1/2 H^T``) a sweep reads each
contact's velocity from the velocities ``F r``, updated after each change: a row of ``F^T``
holds the degrees of freedom of the contact's two bodies (3 each with rotations), where a row
of ``W`` holds every contact sharing a body with it (about 4x the entries on a developed flow).
Stopping test (:func:`_settled`), every :data:`CHECK_EVERY` sweeps: the FCLIB error
(:func:`~lubcontact.problem.metrics.coulomb_error`) and the estimated distance still to go of
the velocities.
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from ..problem.conic import ConicProblem
from ..problem.metrics import coulomb_error
from .compiled_apgd import csr_arrays
from .dual_data import dense_csr_arrays, is_small
from .registry import ALL_CONES, FIRST_ORDER, register
from .result import CONVERGED, DIVERGED, MAX_ITER, MethodOutput

CHECK_EVERY = 10
"""Sweeps between two evaluations of the FCLIB error (one costs about one sweep)."""
SWEEPS_AHEAD = 1e4
"""Cap on the sweeps still to go that the stopping test (:func:`_settled`) assumes: a change
at round-off level, whose ratio between checks is about 1, still stops the sweeps."""


@register("nsgs", kind=FIRST_ORDER, cones=ALL_CONES, second_order=False, warm_start=True,
          native_coulomb=True,
          description="Non-smooth Gauss-Seidel, exact local Coulomb solves (2D, as Siconos' NSGS).")
def nonsmooth_gauss_seidel(problem: ConicProblem, *, tol: float, max_iter: int = 20_000,
                           warm_start: np.ndarray | None = None) -> MethodOutput:
    """Sweeps until the FCLIB error is below ``tol`` (module docstring).

    Parameters
    ----------
    problem : ConicProblem
        Normalised, 2D (tangent dimension 1); read as the Coulomb problem with
        ``q = b - [s, 0]`` (its shift is ignored).
    tol : float
        Stop when the FCLIB error is below it.
    max_iter : int
        Cap on sweeps.
    warm_start : ndarray, shape (n_rows,), optional
        Initial forces (scaled), projected onto the box rows' bounds; zero otherwise.

    Returns
    -------
    MethodOutput
        ``iterations``: sweeps; ``residual_history``: the FCLIB error at each
        check; ``info["error"]``: the last one.
    """
    start = time.perf_counter()
    cones = problem.cones
    nc = cones.count
    small = is_small(problem)                 # W dense: no sparse set-up (dual_data)
    W = problem.dense_delassus if small else problem.delassus.tocsr()
    q = problem.offset.copy()
    q[:nc] -= problem.shift
    unshifted = problem.with_shift(np.zeros(nc))
    projector = cones.projector
    sweeps = Sweeps(W, q, projector.lower, projector.upper, projector.friction_normal,
                    projector.planar_tangent, projector.friction_mu, ~projector.friction_union,
                    factor=None if small else problem.delassus_factor,
                    factor_transpose=None if small else problem.delassus_factor_transpose)
    box = sweeps.contact < 0
    forces = np.zeros(problem.n_rows) if warm_start is None else \
        np.array(warm_start, dtype=float)
    forces[box] = np.clip(forces[box], projector.lower[box], projector.upper[box])
    setup_time = time.perf_counter() - start
    history = [coulomb_error(unshifted, forces)]
    velocity = W @ forces + q
    count, status, changes = 0, MAX_ITER, [np.inf, np.inf]
    while not _settled(history[-1], changes, velocity, tol) and count < max_iter:
        batch = min(CHECK_EVERY, max_iter - count)
        forces = sweeps(forces, batch)
        count += batch
        previous, velocity = velocity, W @ forces + q
        changes = [changes[1], float(np.max(np.abs(velocity - previous), initial=0.0))]
        history.append(coulomb_error(unshifted, forces))
        if not np.isfinite(history[-1]):
            status = DIVERGED
            break
    if _settled(history[-1], changes, velocity, tol):
        status = CONVERGED
    return MethodOutput(forces, status, count, setup_time=setup_time,
                        solve_time=time.perf_counter() - start - setup_time,
                        residual_history=np.asarray(history), info={"error": history[-1]})


def _settled(error: float, changes: list[float], velocity: np.ndarray, tol: float) -> bool:
    """The stopping test: FCLIB error below ``tol``, and the distance still to go of the local
    velocities ``W r + q`` below ``tol`` times their largest value, estimated from their largest
    change ``c`` over the last :data:`CHECK_EVERY` sweeps and the contraction ``q`` between the
    last two such changes as ``c q / (1 - q)`` (the factor capped by :data:`SWEEPS_AHEAD`).

    Gauss-Seidel creeps on ill-conditioned contacts (a grain in a 1e-3 wedge: 11 630 sweeps to
    FCLIB error 7.7e-10, still 1.4e-6 from the solution in velocity): the FCLIB error alone
    stopped it there. Velocities, not forces: on a hyperstatic pile the forces are not unique
    and the sweeps can move them along the null space of ``W`` without changing any velocity.
    """
    previous, change = changes
    if not error <= tol or not np.isfinite(change):
        return False
    ahead = SWEEPS_AHEAD / CHECK_EVERY
    rate = min(change / previous, ahead / (1.0 + ahead)) if previous > 0 else ahead / (1.0 + ahead)
    scale = max(1.0, float(np.max(np.abs(velocity), initial=0.0)))
    return change * rate / (1.0 - rate) <= tol * scale


def contact_blocks(W: np.ndarray | sp.csr_matrix, diagonal: np.ndarray, cone_n: np.ndarray,
                   cone_t: np.ndarray) -> np.ndarray:
    """Each 2D frictional contact's block of ``W``, ``[W_nn, W_nt, W_tn, W_tt]``, shape (nf, 4),
    as :func:`~.kernels.gauss_seidel_2d` takes them (``W`` dense or sparse, ``diagonal`` its
    diagonal; ``cone_n``, ``cone_t`` the contacts' normal and tangential rows, shape (nf,))."""
    if cone_n.size == 0:
        return np.zeros((0, 4))
    return np.stack([diagonal[cone_n], np.asarray(W[cone_n, cone_t]).ravel(),
                     np.asarray(W[cone_t, cone_n]).ravel(), diagonal[cone_t]], axis=1)


class Sweeps:
    """Gauss-Seidel sweeps (:func:`~.kernels.gauss_seidel_2d`) over all or some rows of a 2D
    problem, the other rows' forces frozen: each box row among them (bounds ``lower < upper``)
    and each frictional contact one of whose rows is among them, in row order. ``nsgs`` sweeps
    every row; newton-ac's proximal loop sweeps the rows where the FCLIB error concentrates
    (:meth:`~.newton.AlartCurnier.swept`).

    Parameters
    ----------
    W : ndarray or scipy.sparse.csr_matrix, shape (n, n)
    q, lower, upper : ndarray, shape (n,)
        The offset without the shift, and the box bounds.
    cone_n, cone_t : ndarray of int, shape (nf,)
        Each frictional contact's normal and tangential row.
    mu : ndarray, shape (nf,)
    unilateral : ndarray of bool, shape (nf,)
        COULOMB (True) or UNION (False) contacts.
    factor, factor_transpose : scipy.sparse.csr_matrix, optional
        ``F`` and ``F^T`` with ``W = F^T F`` (a step problem's ``L``): the sweeps then read a
        row's velocity from the velocities ``F r`` (a row of ``F^T`` holds the degrees of
        freedom of one contact's two bodies, where a row of ``W`` holds every contact sharing
        a body with it: about 4x the entries on a developed flow), else from the rows of ``W``.
        Sweeps over some rows compute ``F r`` only where those rows read it.
    diagonal : ndarray, shape (n,), optional
        ``W``'s diagonal, where the caller has it (a sparse ``W``'s costs a pass over its
        entries); taken from ``W`` otherwise.
    """

    def __init__(self, W: np.ndarray | sp.csr_matrix, q: np.ndarray, lower: np.ndarray,
                 upper: np.ndarray, cone_n: np.ndarray, cone_t: np.ndarray, mu: np.ndarray,
                 unilateral: np.ndarray, factor: sp.csr_matrix | None = None,
                 factor_transpose: sp.csr_matrix | None = None,
                 diagonal: np.ndarray | None = None):
        self.W, self.q, self.lower, self.upper = W, q, lower, upper
        self.cone_n, self.cone_t = cone_n.astype(np.int64), cone_t.astype(np.int64)
        self.mu, self.unilateral = mu.astype(float), unilateral
        self.diagonal = W.diagonal() if diagonal is None else diagonal
        self.contact = np.full(q.size, -1, dtype=np.int64)      # each row's contact, or -1
        self.contact[self.cone_n] = self.contact[self.cone_t] = np.arange(cone_n.size)
        self.blocks = contact_blocks(W, self.diagonal, self.cone_n, self.cone_t)
        self.box_rows = np.flatnonzero((self.contact < 0) & (lower < upper))
        self.factor = factor
        self.factor_rows = None if factor is None else csr_arrays(factor)
        read = W if factor is None else factor_transpose
        self.rows = dense_csr_arrays(read) if isinstance(read, np.ndarray) else csr_arrays(read)

    def __call__(self, forces: np.ndarray, sweeps: int, rows: np.ndarray | None = None
                 ) -> np.ndarray:
        """The forces (shape (n,)) after ``sweeps`` sweeps from ``forces`` over ``rows`` (sorted;
        None: every row)."""
        from .kernels import factor_rows_state, gauss_seidel_2d

        if rows is None:
            cones, box_rows = slice(None), self.box_rows
        else:
            contact = self.contact[rows]
            cones = np.unique(contact[contact >= 0])
            box_rows = rows[(contact < 0) & (self.lower[rows] < self.upper[rows])]
        cone_n, cone_t = self.cone_n[cones], self.cone_t[cones]
        swept = np.array(forces, dtype=float)
        # F r from the forces at each call: the updates inside carry no drift over the sweeps
        if self.factor is None:
            state = swept
        elif rows is None:
            state = self.factor @ swept
        else:                  # only where the swept rows read it (np.empty: the rest unread)
            state = np.empty(self.factor.shape[0])
            factor_rows_state(*self.factor_rows, *self.rows[:2], swept,
                              np.concatenate((box_rows, cone_n, cone_t)), state)
        gauss_seidel_2d(*self.rows, self.q, self.lower, self.upper, box_rows,
                        self.diagonal[box_rows], cone_n, cone_t, self.mu[cones],
                        self.unilateral[cones], self.blocks[cones], swept, state,
                        self.factor is not None, sweeps)
        return swept
