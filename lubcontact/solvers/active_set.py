"""Exact finish on an active set (frictionless problems): :class:`ActiveSetFinish` and
:func:`finish_exactly`.

A stopping rule is not an accuracy: where ``W`` is badly conditioned (mass
ratio 1e6, a settled pile) ``r <= 1e-9`` (the stopping measure of
:mod:`.dual_data`) still left velocity errors of 1e-6 to 1e-5. So on
frictionless problems every ``converged`` result of the gradient methods is
finished exactly (:func:`finish_exactly`): one sparse LDL^T solve on the
active set of the best iterate, accepted only when it passes the sign and
complementarity checks (``info["exact_finish"]``); the finish solves count
as iterations.

``apgd-as`` (:mod:`.gradient`) also tries the exact solve during the
iterations: once the active set settles, the equality-constrained system
``W_AA x_A = -b_A`` is solved by a sparse LDL^T factorisation (qdldl),
checked, and corrected by primal-dual active-set rounds.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..problem.cones import Cones
from .dual_data import DENSE_LIMIT, DualData, ResidualTracker, dense_lu, dense_lu_solve
from .result import CONVERGED

MAX_FINISH_ATTEMPTS = 4
"""Finish attempts of one ``apgd-as`` solve (the initial guess's included) before it goes on as
``apgd-jacobi``. At exact rest the first attempt succeeds; off it (radii moved by 5e-7, gaps of
~1e-6) every attempt can fail, and 4 attempts (at most 12 factorisations; the exact finish of
a converged result, :func:`finish_exactly`, may add one more) cost 1.07x
``apgd-jacobi``'s time on a settled 1000-grain pile, where unbounded attempts that restarted the
loop ran into ``max_iter``."""


class ActiveSetFinish:
    """Exact solve on an identified active set (frictionless problems).

    Active rows: FREE contacts, and one-sided contacts whose force would stay
    off the bound after a gradient step (``sigma (z - g) > 0`` with ``sigma =
    +1`` for NONNEG, ``-1`` for NONPOS). On ``A`` the problem is the linear
    system ``W_AA z_A = -b_A`` (``z = 0`` off ``A``). It is solved by a sparse
    LDL^T factorisation (qdldl) of ``W`` with the inactive rows and columns
    replaced by the identity, so that every active set shares one sparsity
    pattern: the ordering and symbolic analysis are done once per solve and
    each new active set costs a numeric refactorisation only. Up to
    :data:`~.dual_data.DENSE_LIMIT` rows, ``W`` is kept dense instead and each
    active block is factorised by a dense LU (LAPACK), which skips the sparse
    set-up that dominated small solves. ``delta`` = 1e-12 x the largest
    diagonal is added on the active diagonal (singular hyperstatic blocks
    factor) and one step of iterative refinement removes it.

    An attempt (:meth:`solve`) returns a candidate that satisfies every sign
    and complementarity condition (projected, and kept as ``exact``);
    otherwise primal-dual active-set rounds replace ``A`` by the candidate's
    active set, up to ``max_rounds`` factorisations, and an attempt whose
    rounds do not settle returns None: the iterations carry on from their own
    iterate, with their momentum. During the iterations (``apgd-as``) an
    attempt is made each time the active set has just stayed unchanged for
    ``stable_iterations`` iterations, at most ``max_attempts`` times
    (:attr:`exhausted`).

    Parameters
    ----------
    data : DualData
        The problem (its ``W_it`` is assembled here).
    cones : Cones
        Its cones, all frictionless.
    stable_iterations : int
        Attempt once the active set has not changed for this many iterations.
    max_rounds : int
        Factorisations per attempt.
    max_attempts : int
        Attempts during the iterations (:data:`MAX_FINISH_ATTEMPTS`).
    """

    def __init__(self, data: DualData, cones: Cones, stable_iterations: int = 5,
                 max_rounds: int = 3, max_attempts: int = MAX_FINISH_ATTEMPTS) -> None:
        projector = cones.projector               # sigma from the box: +1 [0, inf), -1 (-inf, 0]
        self.sign = (projector.lower == 0.0) - (projector.upper == 0.0).astype(float)
        self.data = data
        self.stable_iterations = stable_iterations
        self.max_rounds = max_rounds
        self.max_attempts = max_attempts
        self.previous: np.ndarray | None = None
        self.unchanged = 0
        self.attempts = 0
        self.solves = 0
        self.tried: set[int] = set()
        self.exact: np.ndarray | None = None
        self._factor = None
        self._dense = None
        if data.offset.size <= DENSE_LIMIT:
            dense = data.assembled().toarray() if data.dense is None else data.dense.copy()
            diagonal = dense.ravel()[:: dense.shape[0] + 1]       # a view: the diagonal in place
            diagonal += 1e-12 * max(float(diagonal.max(initial=0.0)), 1e-300)
            self._dense = dense
            return
        matrix = data.assembled()
        diagonal = matrix.diagonal()
        delta = 1e-12 * max(float(diagonal.max()), 1e-300) if diagonal.size else 1e-12
        upper = sp.triu(matrix, format="csc")
        upper = sp.csc_matrix(upper + delta * sp.identity(upper.shape[0], format="csc"))
        self._upper = upper
        self._rows = upper.indices
        self._cols = np.repeat(np.arange(upper.shape[1]), np.diff(upper.indptr))
        self._diagonal = self._rows == self._cols

    @property
    def exhausted(self) -> bool:
        """True once ``max_attempts`` attempts are spent: the iterations go on without finish
        attempts (``apgd-jacobi``) to their own stopping test."""
        return self.attempts >= self.max_attempts

    def active(self, z: np.ndarray, gradient: np.ndarray) -> np.ndarray:
        """Rows that stay off their bound after a gradient step from ``z``: bool, shape (n,)
        (``z`` and ``gradient = W_it z + b_it`` of shape (n,))."""
        return (self.sign == 0.0) | (self.sign * (z - gradient) > 0.0)

    def closed_rows(self, threshold: float = 1e-6) -> np.ndarray:
        """Initial guess without a warm start: contacts closed or closing under free motion
        (bool, shape (n,)).

        A one-sided row is guessed active when its free-motion gap ``b_i``
        (gap plus one step of free relative motion) does not open beyond
        ``threshold x max |b|``.
        """
        offset = self.data.offset
        level = threshold * float(np.max(np.abs(offset))) if offset.size else 0.0
        return (self.sign == 0.0) | (self.sign * offset <= level)

    def __call__(self, k: int, z: np.ndarray, gradient: np.ndarray) -> np.ndarray | None:
        """APGD callback (:func:`.gradient_loops.run_apgd`): an attempt when the active set has
        just stayed unchanged for ``stable_iterations`` iterations (once per settled set), until
        :attr:`exhausted`; returns the exact solution, shape (n,), or None (the loop goes on)."""
        if self.exhausted:
            return None
        active = self.active(z, gradient)
        if self.previous is not None and np.array_equal(active, self.previous):
            self.unchanged += 1
        else:
            self.unchanged = 0
        self.previous = active
        if self.unchanged != self.stable_iterations:
            return None
        return self.solve(active)

    def solve(self, active: np.ndarray) -> np.ndarray | None:
        """One attempt: PDAS rounds from ``active`` (each starting set tried once); see the
        class docstring.

        Parameters
        ----------
        active : ndarray of bool, shape (n,)
            The starting active set.

        Returns
        -------
        ndarray, shape (n,), or None
            The checked exact solution (also kept as ``exact``), or None (set tried
            before, singular factorisation, rounds that did not settle).
        """
        key = hash(active.tobytes())
        if key in self.tried:
            return None
        self.tried.add(key)
        self.attempts += 1
        data = self.data
        slack = 1e-12 * (1.0 + float(np.max(np.abs(data.offset))))
        for _ in range(self.max_rounds):
            candidate = self._solve_on(active)
            self.solves += 1
            if candidate is None:
                return None
            gradient = data.product(candidate) + data.offset
            margin = 1e-12 * (1.0 + float(np.max(np.abs(candidate))))
            wrong_sign = active & (self.sign * candidate < -margin)
            violated = ~active & (self.sign * gradient < -slack)
            if not (wrong_sign.any() or violated.any()):
                self.exact = data.project(candidate)
                return self.exact
            active = (active & ~wrong_sign) | violated
        return None

    def _solve_on(self, active: np.ndarray) -> np.ndarray | None:
        """``W_AA z_A = -b_A`` (``z = 0`` off ``A``) with one step of iterative refinement;
        None when the factorisation fails or the solution is not finite."""
        rhs = np.where(active, -self.data.offset, 0.0)
        if self._dense is not None:
            rows = np.flatnonzero(active)
            solution = np.zeros_like(rhs)
            if rows.size == 0:
                return solution
            factors = dense_lu(self._dense.take(rows, 0).take(rows, 1))   # a copy; np.ix_ costs 10 us more
            if factors is None:
                return None
            solution[rows] = dense_lu_solve(factors, rhs[rows])
            product = self.data.product(solution)
            solution[rows] += dense_lu_solve(factors, rhs[rows] - product[rows])
            return solution if np.isfinite(solution).all() else None
        import qdldl

        upper = self._upper
        both = active[self._rows] & active[self._cols]
        values = np.where(both, upper.data, np.where(self._diagonal, 1.0, 0.0))
        matrix = sp.csc_matrix((values, upper.indices, upper.indptr), shape=upper.shape)
        try:
            if self._factor is None:
                self._factor = qdldl.Solver(matrix, upper=True)
            else:
                self._factor.update(matrix, upper=True)
        except ValueError:
            return None
        solution = self._factor.solve(rhs)
        product = self.data.product(np.where(active, solution, 0.0))
        solution = solution + self._factor.solve(np.where(active, rhs - product, 0.0))
        if not np.isfinite(solution).all():
            return None
        return np.where(active, solution, 0.0)



def finish_exactly(data: DualData, cones: Cones, tracker: ResidualTracker, status: str,
                   finish: ActiveSetFinish | None = None) -> dict:
    """Replace a converged best iterate by the exact solution on its active set.

    The residual test does not bound the velocity error when ``W`` is badly
    conditioned (docs/records/hard_cases.md, finding 5): at ``r <= 1e-9`` the
    velocities were still 2e-6 off at a mass ratio of 1e6 and 6e-6 off on the
    settled 1000-grain pile. On frictionless problems the active set of a
    converged iterate is (almost always) the optimal one, so one
    :class:`ActiveSetFinish` solve from it gives the solution to rounding,
    checked by its sign and complementarity conditions. The tracker's best
    iterate is replaced only by such a checked solution; problems with friction
    cones, non-converged runs and best iterates that already are an exact
    solve are left as they are.

    Parameters
    ----------
    data : DualData
        The problem iterated on (vectors of shape (n,)).
    cones : Cones
        Its cones.
    tracker : ResidualTracker
        The run's tracker; its best iterate (and history) is updated in place.
    status : str
        Status of the run.
    finish : ActiveSetFinish, optional
        The run's finish (``apgd-as``), to reuse its factorisation; a new one otherwise.

    Returns
    -------
    dict
        ``exact_finish`` (True when the returned forces are a checked exact
        solve, False when the attempt failed the checks; absent when not
        attempted), ``finish_solves`` (LDL^T solves of this call).
    """
    if status != CONVERGED or cones.has_friction or tracker.best is None:
        return {}
    finish = finish if finish is not None else ActiveSetFinish(data, cones)
    if finish.exact is not None and np.array_equal(finish.exact, tracker.best):
        return {"exact_finish": True, "finish_solves": 0}
    solves = finish.solves
    finish.exact = None
    best = tracker.best
    finish.solve(finish.active(best, data.product(best) + data.offset))
    if finish.exact is not None:
        residual = data.residual(finish.exact, data.product(finish.exact) + data.offset)
        tracker.history.append(residual)
        tracker.best, tracker.best_residual = finish.exact, residual
    return {"exact_finish": finish.exact is not None, "finish_solves": finish.solves - solves}

