"""Active-set polishing of an interior-point solution (frictionless and frictional problems).

An interior-point method stops on a duality gap ``eps``; for the strongly
convex primal this only bounds the velocity error by about ``sqrt(eps)``, and
worse where strict complementarity fails (a friction contact at the cone apex:
zero force and zero slip, or sliding under zero normal force). Once the
active set is known, the solution is the minimiser of the dual objective on
a linear subspace of forces, which a linear solve gives to machine precision.

Each contact is in one of four states:

- ``OPEN``: zero force (every row inactive);
- ``HELD``: the normal row only is active (a pressed NONNEG, pulled NONPOS or
  FREE contact, or a friction contact with ``mu = 0``): ``g_n = 0``;
- ``STICK`` (friction): every row active, ``g_c = 0``;
- ``SLIDE`` (friction): ``lam_T = mu lam_n d`` with a fixed unit direction
  ``d``, one unknown and one equation ``g_n + mu d . g_T = 0``.

The forces on the active set are ``lam = P y`` (``P`` maps the free force
components of the active contacts to the rows), and the optimality
condition on that set is ``P^T g(P y) = 0``, i.e. (``W = L^T L``)
``(L P)^T (L P) y = -P^T b``: a sparse symmetric system, solved by one
LDL^T factorisation (per proximal weight tried) and a few refinement steps
(:func:`_solve_on`). The
velocities are unique even where ``L P`` is rank-deficient (redundant
contacts); the forces are then the solution closest to the input's.

Then the states are corrected (at most ``max_rounds`` times; each condition with an
allowance for rounding, ``ROUNDING``): a held or sliding contact whose normal force changes
sign opens; a sticking contact
whose force leaves the cone slides along its force; a sliding contact whose
slip points along its force sticks; an open contact whose ``g_c`` leaves the
velocity cone ``K_c*`` is closed (held, or sticking). The polished forces are
accepted only when no correction is left (every force in its cone, every
``g_c`` of an open contact in ``K_c*``) and the natural residual decreases.

In 2D the sliding direction is a sign and the sliding state is exact. In 3D
the direction of a sliding contact is an unknown too: after the solve with
the direction of the interior-point force, Newton's method on the exact
conditions (:func:`_slide_newton`) aligns force and slip. (Realigning the
direction with the slip and solving again diverged on
``tetrahedron_3d_friction``: the residual grew 1.6x per round.) If a 3D
sliding contact is still misaligned, polishing gives up (input returned).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..problem.cones import ConeKind, Cones
from ..problem.conic import ConicProblem
from .result import CONVERGED, INACCURATE, MAX_ITER, residual_per_row

OPEN, HELD, STICK, SLIDE = 0, 1, 2, 3
#: relative size of the rounding allowed in the velocity conditions (per row, ``1 + |b|``) and
#: in the force conditions (of ``max(max |lam|, 1)``)
ROUNDING = 1e-12

PROXIMAL_WEIGHTS = (1e-12, 1e-6)
"""``delta`` of the active-set solve (:func:`_solve_on`), relative to the largest diagonal entry
of ``G``: the rounds of :func:`polish` run at the first weight, and again at the second where
the first's answer is not accepted. The refinement converges where ``G``'s eigenvalues are well
above ``delta``. Along the null space of ``G`` (contacts whose rows are dependent), a step moves
the forces by the residual's component there divided by ``delta``. That component is zero at
the exact solution and the interior point's inaccuracy at its forces. These moves change no
velocity, so the refinement takes them, but they can change the contacts' states.

At 1e-12 alone, a component of 1.8e-12 moved the normal forces of two pairs of sticking
contacts from 3e-3 to 7e-3 down to -0.3. This was on a 10 000-grain gluey step's reference
(42 125 rows; the pairs' block of ``G`` had two null directions). The pairs then cycled between
sticking and open, and the polish gave up, keeping Clarabel's residual of 1.3e-5. On the last
convex problems of the references of six such steps (three beds), the polish was accepted on
none at 1e-12, on two at 1e-8 and on all six at 1e-6, with residuals of 1.8e-14 to 5.9e-10.

At 1e-6 alone, a badly conditioned problem loses its polish: on ``mass_ratio_1e6_sandwich``
(``W``'s eigenvalues 0.25 and 1e6, the small one 5e-7 of the diagonal, below the weight) each
refinement removes a third of the error along it, and rounding in the stiff direction stops the
refinement after one step. Hence 1e-12 first (docs/records/benchmarks.md, "a reference to trust
at 10 000 grains")."""


@dataclass
class _Layout:
    """Where each contact's force components are, and its kind of condition.

    ``sign``: +1 (NONNEG, friction), -1 (NONPOS), 0 (FREE); ``friction``:
    contacts with a cone of positive ``mu`` and tangential rows; ``t_rows``:
    their tangential rows (nc, tangent_dim), -1 elsewhere; ``mu`` (nc,).
    """

    sign: np.ndarray
    friction: np.ndarray
    t_rows: np.ndarray
    mu: np.ndarray

    @classmethod
    def of(cls, cones: Cones) -> _Layout:
        nc, dim = cones.count, cones.tangent_dim
        sign = np.where(cones.mask(ConeKind.NONPOS), -1.0,
                        np.where(cones.mask(ConeKind.FREE), 0.0, 1.0))
        t_rows = np.full((nc, dim), -1, dtype=int)
        friction = np.zeros(nc, dtype=bool)
        if cones.has_friction:
            coulomb = np.flatnonzero(cones.mask(ConeKind.COULOMB)[cones.tangential])
            contacts = cones.tangential[coulomb]
            t_rows[contacts] = nc + coulomb[:, None] * dim + np.arange(dim)
            friction[contacts] = cones.mu[contacts] > 0
        return cls(sign=sign, friction=friction, t_rows=t_rows, mu=np.asarray(cones.mu, float))


def polish(problem: ConicProblem, forces: np.ndarray, threshold: float = 1e-7,
           max_rounds: int = 8) -> tuple[np.ndarray, bool]:
    """Refine ``forces`` of a convex normalised problem on their active set.

    The rounds (module docstring) run at each proximal weight of :data:`PROXIMAL_WEIGHTS` in
    turn, from ``forces`` each time, until one's answer is accepted.

    Parameters
    ----------
    problem : ConicProblem
        Normalised problem with convex cones (UNION contacts: branch fixed first).
    forces : ndarray, shape (n_rows,)
        A near-optimal solution (scaled units).
    threshold : float
        Relative force level (of ``max |lam|``) below which a contact counts as open.
    max_rounds : int
        Active-set solves allowed at each weight (module docstring). Polishing also gives up
        as soon as a round changes the state of as many contacts as the round
        before (the set is not settling: e.g. on a hyperstatic frictional
        1000-grain pile, whose sticking forces are not unique, the changes
        went 270, 249, 753: three solves, 0.09 s, instead of eight, 0.15 s,
        for a polish that fails anyway).

    Returns
    -------
    (ndarray, bool)
        The polished forces and whether polishing was accepted (otherwise the
        input forces are returned unchanged).
    """
    cones = problem.cones
    if forces.size == 0 or not cones.is_convex or not np.all(np.isfinite(forces)):
        return forces, False
    layout = _Layout.of(cones)
    start = _initial_states(problem, layout, forces, threshold)
    before = problem.natural_residual(forces)
    for weight in PROXIMAL_WEIGHTS:
        polished = _rounds(problem, layout, forces, start, max_rounds, weight, before)
        if polished is not None:
            return polished, True
    return forces, False


def _rounds(problem: ConicProblem, layout: _Layout, forces: np.ndarray,
            start: tuple[np.ndarray, np.ndarray], max_rounds: int, weight: float,
            before: float) -> np.ndarray | None:
    """The rounds of :func:`polish` at one proximal ``weight`` (:data:`PROXIMAL_WEIGHTS`) from
    the states and sliding directions ``start`` read from ``forces`` (not modified): the
    polished forces, or None where they are not accepted (``before``: the natural residual of
    ``forces``, which an accepted answer must lower)."""
    state, direction = start
    previous_changes = state.size + 1
    for _ in range(max_rounds):
        candidate = _solve_on(problem, layout, forces, state, direction, weight)
        if layout.t_rows.shape[1] > 1 and np.any(state == SLIDE):
            candidate, direction = _slide_newton(problem, layout, candidate, state, direction)
        try:
            new_state, direction, changed = _corrected(problem, layout, candidate, state, direction)
        except _Misaligned:
            return None
        if not changed:
            return candidate if problem.natural_residual(candidate) < before else None
        changes = int(np.count_nonzero(new_state != state))
        if changes >= previous_changes:              # the active set is not settling: give up
            return None
        state, previous_changes = new_state, changes
    return None


def polished_status(status: str, problem: ConicProblem, forces: np.ndarray, accepted: bool,
                    tol: float) -> str:
    """An interior point's status after :func:`polish`: ``converged`` where it stopped short of
    ``tol`` but the polish of its answer was accepted and meets ``tol``; else ``status``.

    Parameters
    ----------
    status : str
        The interior point's own status. ``inaccurate`` (Clarabel's ``AlmostSolved``) and
        ``max_iter`` (out of iterations) are the ones that can change.
    problem : ConicProblem
        The normalised problem that was polished.
    forces : ndarray, shape (n_rows,)
        The forces :func:`polish` returned.
    accepted : bool
        Whether the polish was accepted.
    tol : float
        The interior point's tolerance, which the polished forces' natural residual per row
        (its rms over the rows, :func:`~lubcontact.solvers.result.residual_per_row`) must meet.

    Returns
    -------
    str
        ``converged`` or ``status``.

    An accepted polish has found the active set on which every force lies in its cone and every
    open contact's velocity in the dual cone; its residual, measured independently of the
    interior point, then says whether the answer meets ``tol``. On a 10 000-grain gluey step's
    reference, Clarabel's fixed point on s stopped after four outer iterations because an inner
    solve ended ``inaccurate``, though its polished answer's residual was 1.7e-12 per row
    (docs/records/benchmarks.md, "a reference to trust at 10 000 grains").
    """
    if status in (INACCURATE, MAX_ITER) and accepted and \
            residual_per_row(problem.natural_residual(forces), forces.size) <= tol:
        return CONVERGED
    return status


def _components(problem: ConicProblem, layout: _Layout,
                vector: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normal part (nc,) and tangential part (nc, tangent_dim; zeros where none) of a row vector."""
    tangential = np.where(layout.t_rows >= 0, vector[np.maximum(layout.t_rows, 0)], 0.0)
    return vector[: problem.n_contacts], tangential


def _initial_states(problem: ConicProblem, layout: _Layout, forces: np.ndarray,
                    threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """States read from a near-optimal solution: open below ``threshold x max(max |lam|, 1)``;
    a friction contact sticks when its force is farther inside the cone than its slip.

    The force level has a floor of 1, the force unit of the normalised problem (the force
    that changes the velocity by the free-velocity scale in one step): when every contact is
    open, ``max |lam|`` is the interior point's noise, and a level relative to it classed
    noise as pressed contacts (forces of 1e-10 to 1e-8 were left in place)."""
    scale = max(float(np.max(np.abs(forces))), 1.0)
    normal, tangential = _components(problem, layout, forces)
    _, slip = _components(problem, layout, problem.gradient(forces))
    closed = (layout.sign == 0) | (layout.sign * normal > threshold * scale)
    state = np.where(closed, HELD, OPEN)
    norm_t, norm_slip = np.linalg.norm(tangential, axis=1), np.linalg.norm(slip, axis=1)
    inside = layout.mu * normal - norm_t > norm_slip
    state[layout.friction & closed] = np.where(inside, STICK, SLIDE)[layout.friction & closed]
    direction = _unit(tangential, fallback=-slip)
    state[(state == SLIDE) & ~np.any(direction != 0, axis=1)] = STICK
    return state, direction


def _unit(vectors: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """Rows of ``vectors`` normalised (``fallback`` rows where a row is zero; zero if both are)."""
    chosen = np.where(np.linalg.norm(vectors, axis=1)[:, None] > 0, vectors, fallback)
    norm = np.linalg.norm(chosen, axis=1, keepdims=True)
    return np.divide(chosen, norm, out=np.zeros_like(chosen), where=norm > 0)


def _active_basis(problem: ConicProblem, layout: _Layout, forces: np.ndarray, state: np.ndarray,
                  direction: np.ndarray) -> tuple[sp.csc_matrix, np.ndarray]:
    """``P`` (n_rows x k) and the coordinates ``y`` of ``forces`` in it (module docstring)."""
    closed = np.flatnonzero(state != OPEN)
    stick = np.flatnonzero(state == STICK)
    slide = np.flatnonzero(state == SLIDE)
    dim = layout.t_rows.shape[1]
    normal_column = np.zeros(problem.n_contacts, dtype=int)
    normal_column[closed] = np.arange(closed.size)
    rows = [closed, layout.t_rows[slide].ravel(), layout.t_rows[stick].ravel()]
    cols = [np.arange(closed.size), np.repeat(normal_column[slide], dim),
            closed.size + np.arange(stick.size * dim)]
    values = [np.ones(closed.size), (layout.mu[slide, None] * direction[slide]).ravel(),
              np.ones(stick.size * dim)]
    basis = sp.csc_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(problem.n_rows, closed.size + stick.size * dim))
    coordinates = np.concatenate([forces[closed], forces[layout.t_rows[stick].ravel()]])
    return basis, coordinates


def _solve_on(problem: ConicProblem, layout: _Layout, forces: np.ndarray, state: np.ndarray,
              direction: np.ndarray, weight: float, refinements: int = 4) -> np.ndarray:
    """Forces of the active set that make every active condition hold (module docstring).

    ``G = (L P)^T (L P)`` plus ``delta = weight max diag G`` (:data:`PROXIMAL_WEIGHTS`) is
    factorised once (LDL^T, qdldl), and ``y <- y - (G + delta I)^-1 P^T g(P y)`` is repeated
    (proximal-point refinement: ``delta`` leaves no trace where ``G``'s eigenvalues are well
    above it, and components of ``y`` in and near the null space of ``G``, which do not change
    velocities, or barely, keep their values from ``forces``).
    """
    import qdldl

    basis, coordinates = _active_basis(problem, layout, forces, state, direction)
    if basis.shape[1] == 0:
        return np.zeros_like(forces)
    gram = sp.triu(_active_gram(problem, basis), format="csc")
    delta = weight * max(float(gram.diagonal().max()), 1e-300)
    solver = qdldl.Solver(sp.csc_matrix(gram + delta * sp.identity(gram.shape[0], format="csc")),
                          upper=True)
    residual = basis.T @ problem.gradient(basis @ coordinates)
    for _ in range(refinements):
        step = solver.solve(residual)
        trial = coordinates - step
        trial_residual = basis.T @ problem.gradient(basis @ trial)
        if not np.linalg.norm(trial_residual) < np.linalg.norm(residual):
            break
        coordinates, residual = trial, trial_residual
    return basis @ coordinates


def _active_gram(problem: ConicProblem, basis: sp.spmatrix) -> sp.spmatrix:
    """``P^T W P``: as ``(L P)^T (L P)`` where a factor ``W = L^T L`` exists, else from ``W``
    (local problems: :class:`~lubcontact.problem.local.LocalProblem` has no factor)."""
    factor = problem.delassus_factor
    if factor is None:
        return sp.csr_matrix(basis.T @ problem.delassus @ basis)
    scaled = sp.csr_matrix(factor @ basis)                              # L P, n_dof x k
    return scaled.T @ scaled


def _corrected(problem: ConicProblem, layout: _Layout, candidate: np.ndarray, state: np.ndarray,
               direction: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """The states after one solve (module docstring) and whether any changed.

    A force condition is broken only beyond rounding (:data:`ROUNDING` of ``max(max |lam|,
    1)``), as a velocity condition is: a contact that touches with zero force (gap and force
    both zero) was solved with a force of -2e-16 against a largest of 7.3 on a 537-contact
    pile, opened, and two more such contacts opened in the next round, so the polish gave up
    as not settling at a natural residual of 5e-15 (docs/records/benchmarks.md, "the polish's
    rounding")."""
    normal, tangential = _components(problem, layout, candidate)
    g_n, g_t = _components(problem, layout, problem.gradient(candidate))
    b_n, b_t = _components(problem, layout, problem.offset)
    allowance = ROUNDING * (1 + np.abs(b_n) + np.linalg.norm(b_t, axis=1))
    force_allowance = ROUNDING * max(float(np.abs(candidate).max(initial=0.0)), 1.0)
    new_state, new_direction = state.copy(), direction.copy()
    friction, one_sided = layout.friction, ~layout.friction & (layout.sign != 0)
    # frictionless and mu = 0 contacts
    new_state[one_sided & (state == HELD) & (layout.sign * normal < -force_allowance)] = OPEN
    new_state[one_sided & (state == OPEN) & (layout.sign * g_n < -allowance)] = HELD
    # friction contacts
    norm_t, norm_slip = np.linalg.norm(tangential, axis=1), np.linalg.norm(g_t, axis=1)
    leaves = friction & (state == STICK) & (norm_t > layout.mu * normal + force_allowance)
    new_state[leaves] = SLIDE
    new_direction[leaves] = _unit(tangential[leaves], fallback=np.zeros_like(tangential[leaves]))
    sliding = friction & (state == SLIDE)
    along = np.sum(direction * g_t, axis=1)
    new_state[sliding & (along > allowance)] = STICK
    new_state[friction & (state != OPEN) & (normal < -force_allowance)] = OPEN
    new_state[friction & (state == OPEN) & (g_n - layout.mu * norm_slip < -allowance)] = STICK
    changed = bool(np.any(new_state != state))
    across = np.linalg.norm(g_t - along[:, None] * direction, axis=1) > allowance
    if not changed and np.any(sliding & across):
        raise _Misaligned
    return new_state, new_direction, changed


def _slide_newton(problem: ConicProblem, layout: _Layout, forces: np.ndarray, state: np.ndarray,
                  direction: np.ndarray, iterations: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """3D sliding contacts: Newton's method on the exact conditions of the active set.

    Unknowns: the forces of the active rows (every row of a sticking or
    sliding contact, the normal row of a held one) and one ``kappa >= 0`` per
    sliding contact; equations: ``g = 0`` on held and sticking rows, and per
    sliding contact ``g_T + kappa lam_T = 0``, ``g_n - mu^2 kappa lam_n = 0``
    (slip opposite to the force, on the boundary of ``K_c*``) and
    ``|lam_T| = mu lam_n``. Started from the fixed-direction solution
    ``forces``; ``1e-12 max diag W`` on the force block keeps redundant
    contacts factorisable. Returns the forces and the sliding directions
    ``lam_T / |lam_T|`` (``kappa < 0`` is left for the state corrections), or
    the input unchanged when Newton does not converge (e.g. a sliding contact
    whose normal force vanishes: the corrections then open it).
    """
    slide = np.flatnonzero(state == SLIDE)
    if np.any(forces[slide] <= ROUNDING * np.max(np.abs(forces))):
        return forces, direction                     # (nearly) singular: the corrections open these
    slide_t = layout.t_rows[slide]                                    # (s, dim)
    mu = layout.mu[slide]
    rows = np.zeros(problem.n_rows, dtype=bool)
    rows[np.flatnonzero(state != OPEN)] = True
    rows[layout.t_rows[(state == STICK) | (state == SLIDE)].ravel()] = True
    active = np.flatnonzero(rows)
    position = np.full(problem.n_rows, -1)
    position[active] = np.arange(active.size)
    delassus = problem.delassus[active][:, active]
    delta = 1e-12 * max(float(delassus.diagonal().max()), 1e-300)
    lam = forces.copy()
    slip = -np.sum(direction[slide] * problem.gradient(lam)[slide_t], axis=1)
    kappa = np.maximum(slip, 0.0) / np.maximum(np.linalg.norm(lam[slide_t], axis=1), 1e-300)

    def conditions(lam: np.ndarray, kappa: np.ndarray) -> np.ndarray:
        g = problem.gradient(lam)
        g[slide_t] += kappa[:, None] * lam[slide_t]
        g[slide] -= mu**2 * kappa * lam[slide]
        return np.concatenate([g[active], np.linalg.norm(lam[slide_t], axis=1) - mu * lam[slide]])

    value = conditions(lam, kappa)
    for _ in range(iterations):
        jacobian = _newton_matrix(delassus, delta, position, slide, slide_t, mu, lam, kappa)
        with warnings.catch_warnings():              # a singular Jacobian gives NaN: stop there
            warnings.simplefilter("ignore", spla.MatrixRankWarning)
            step = spla.spsolve(jacobian, -value)
        if not np.all(np.isfinite(step)):
            break
        trial_lam, trial_kappa = lam.copy(), kappa + step[active.size:]
        trial_lam[active] += step[: active.size]
        trial = conditions(trial_lam, trial_kappa)
        if not np.linalg.norm(trial) < np.linalg.norm(value):
            break
        lam, kappa, value = trial_lam, trial_kappa, trial
    if not np.linalg.norm(value) <= ROUNDING * (1 + np.linalg.norm(problem.offset)):
        return forces, direction                     # not converged: the state corrections decide
    new_direction = direction.copy()
    new_direction[slide] = _unit(lam[slide_t], fallback=direction[slide])
    return lam, new_direction


def _newton_matrix(delassus: sp.csr_matrix, delta: float, position: np.ndarray, slide: np.ndarray,
                   slide_t: np.ndarray, mu: np.ndarray, lam: np.ndarray,
                   kappa: np.ndarray) -> sp.csc_matrix:
    """Jacobian of :func:`_slide_newton`'s conditions (forces block, then kappa)."""
    n_active, count, dim = delassus.shape[0], slide.size, slide_t.shape[1]
    diagonal = np.full(n_active, delta)
    diagonal[position[slide_t].ravel()] += np.repeat(kappa, dim)
    diagonal[position[slide]] -= mu**2 * kappa
    tangent = lam[slide_t]
    unit = _unit(tangent, fallback=np.zeros_like(tangent))
    columns = np.concatenate([np.repeat(np.arange(count), dim), np.arange(count)])
    coupling_rows = np.concatenate([position[slide_t].ravel(), position[slide]])
    coupling = sp.csc_matrix((np.concatenate([tangent.ravel(), -mu**2 * lam[slide]]),
                              (coupling_rows, columns)), shape=(n_active, count))
    cone = sp.csc_matrix((np.concatenate([unit.ravel(), -mu]), (columns, coupling_rows)),
                         shape=(count, n_active))
    return sp.csc_matrix(sp.bmat([[delassus + sp.diags(diagonal), coupling], [cone, None]]))


class _Misaligned(Exception):
    """A 3D sliding contact whose slip is not opposite to its fixed force direction."""
