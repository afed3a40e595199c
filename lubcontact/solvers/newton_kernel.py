"""One Newton phase of ``newton-ac`` in one compiled call: small 2D problems (the dense lane).

On a problem of a few tens of rows a Newton iteration written with numpy is some forty array
calls (the Alart-Curnier residual, the rows of the generalised Jacobian, the LU of the active
block, the line search's residuals, the FCLIB error), 100-300 us, where the arithmetic takes a
few. :func:`newton_phase_2d` runs the iterations of one phase
(:func:`lubcontact.solvers.newton._newton_phase`) with the same rules: the regularisations of
a singular active block, the non-monotone Armijo line search, the steepest-descent direction
where Newton's gives no decrease, the stopping tests and the best iterate. Its formulas are
those of :class:`~lubcontact.solvers.newton.AlartCurnier` and
:func:`~lubcontact.problem.metrics.coulomb_error` written per row, for 2D contacts (one
tangential row each); the tests hold each to its numpy twin.
"""
from __future__ import annotations

import numba
import numpy as np

from .kernels import friction_cone_point

FAILED_CODE, MAX_ITER_CODE, CONVERGED_CODE = 0, 1, 2
"""Status codes of :func:`newton_phase_2d` (``newton.FAILED``, ``MAX_ITER``, ``CONVERGED``)."""


@numba.njit(cache=True)
def product_2d(W, x, offset, out):
    """``out = W x + offset`` for a dense ``W`` (shape (n, n))."""
    n = x.size
    for i in range(n):
        total = offset[i]
        for j in range(n):
            total += W[i, j] * x[j]
        out[i] = total


@numba.njit(cache=True)
def alart_curnier_2d(rho, lower, upper, cone_n, cone_t, cone_mu, unilateral, sigma, center,
                     forces, velocity, phi, y):
    """``phi`` and ``y`` of :meth:`AlartCurnier.residual` at ``forces`` whose velocity ``W r + q``
    is ``velocity``, in place; returns the merit ``|phi|^2 / 2``."""
    n = forces.size
    for i in range(n):
        y[i] = forces[i] - rho[i] * velocity[i]
        if sigma != 0.0:
            y[i] -= (rho[i] * sigma) * (forces[i] - center[i])
        phi[i] = forces[i] - min(max(y[i], lower[i]), upper[i])
    for c in range(cone_n.size):
        normal, tangent = cone_n[c], cone_t[c]
        y_n, y_t = y[normal], y[tangent]
        radius = cone_mu[c] * max(y_n, 0.0)
        size = abs(y_t)
        scale = min(1.0, radius / size) if size > 0.0 else 1.0
        phi[normal] = forces[normal] - (max(y_n, 0.0) if unilateral[c] else y_n)
        phi[tangent] = forces[tangent] - scale * y_t
    merit = 0.0
    for i in range(n):
        merit += phi[i] * phi[i]
    return 0.5 * merit


@numba.njit(cache=True)
def coulomb_error_2d(forces, velocity, lower, upper, cone_n, cone_t, cone_mu, unilateral,
                     q_scale):
    """:func:`~lubcontact.problem.metrics.coulomb_error` of an unshifted problem from its
    velocity ``W r + q``; ``q_scale`` is ``1 + |q|``. A UNION contact (not ``unilateral``) is
    measured on its pushed piece where ``r_n >= 0``, on the pulled one (``n <= 0``, ``t = 0``)
    elsewhere."""
    n = forces.size
    difference = np.empty(n)
    for i in range(n):
        difference[i] = forces[i] - min(max(forces[i] - velocity[i], lower[i]), upper[i])
    for c in range(cone_n.size):
        normal, tangent = cone_n[c], cone_t[c]
        r_n, r_t = forces[normal], forces[tangent]
        u_n, u_t = velocity[normal], velocity[tangent]
        if unilateral[c] or r_n >= 0.0:
            new_n, new_t = friction_cone_point(r_n - (u_n + cone_mu[c] * np.sqrt(u_t * u_t)),
                                               r_t - u_t, cone_mu[c])
        else:
            new_n, new_t = min(r_n - u_n, 0.0), 0.0
        difference[normal] = r_n - new_n
        difference[tangent] = r_t - new_t
    total = 0.0
    for i in range(n):
        total += difference[i] * difference[i]
    return np.sqrt(total) / q_scale


@numba.njit(cache=True)
def generalised_jacobian_2d(lower, upper, box, cone_n, cone_t, cone_mu, unilateral, y):
    """The nonzeros of ``G``, the generalised Jacobian of the projection at ``y``
    (:meth:`AlartCurnier.jacobian`): in 2D at most two per row.

    Returns
    -------
    tuple
        ``(rows, first_col, first_val, second_col, second_val)``: the rows where ``G`` is not
        zero (active), shape (m,), and per row of ``y`` (shape (n,) each) the columns and
        values of its entries, column -1 where there is none.
    """
    n = y.size
    first_col = np.full(n, -1)
    first_val = np.zeros(n)
    second_col = np.full(n, -1)
    second_val = np.zeros(n)
    for i in range(n):
        if box[i] and lower[i] < y[i] < upper[i]:
            first_col[i], first_val[i] = i, 1.0
    for c in range(cone_n.size):
        normal, tangent = cone_n[c], cone_t[c]
        y_n, y_t = y[normal], y[tangent]
        pushed = y_n > 0.0
        if pushed and unilateral[c]:
            first_col[normal], first_val[normal] = normal, 1.0
        radius = cone_mu[c] * max(y_n, 0.0)
        size = abs(y_t)
        if pushed and size > radius and radius > 0.0:       # sliding
            t = y_t / size
            first_col[tangent], first_val[tangent] = tangent, (radius / size) * (1.0 - t * t)
            second_col[tangent], second_val[tangent] = normal, cone_mu[c] * t
        elif pushed and size <= radius:                      # sticking
            first_col[tangent], first_val[tangent] = tangent, 1.0
    return np.flatnonzero(first_col >= 0), first_col, first_val, second_col, second_val


@numba.njit(cache=True)
def jacobian_rows_2d(W, rho, lower, upper, box, cone_n, cone_t, cone_mu, unilateral, sigma, y):
    """The rows of ``J = I - G + G diag(rho) (W + sigma I)`` where ``G`` is not zero, ``W``
    dense: ``(rows, J_A)``, the active rows' indices (m,) and their rows of ``J``, shape
    (m, n)."""
    rows, first_col, first_val, second_col, second_val = generalised_jacobian_2d(
        lower, upper, box, cone_n, cone_t, cone_mu, unilateral, y)
    n = y.size
    J = np.zeros((rows.size, n))
    for a in range(rows.size):
        i = rows[a]
        J[a, i] += 1.0
        for column, value in ((first_col[i], first_val[i]), (second_col[i], second_val[i])):
            if column < 0:
                continue
            J[a, column] -= value
            weight = value * rho[column]
            for j in range(n):
                J[a, j] += weight * W[column, j]
            J[a, column] += weight * sigma
    return rows, J


@numba.njit(cache=True)
def sparse_jacobian_rows_2d(indptr, indices, data, rho, lower, upper, box, cone_n, cone_t,
                            cone_mu, unilateral, sigma, y):
    """:func:`jacobian_rows_2d` with ``W`` in CSR form (``indptr``, ``indices``, ``data``):
    ``(rows, J_indptr, J_indices, J_data)``, the active rows (m,) and the CSR arrays of their
    rows of ``J`` (m x n), columns unsorted in each row. A row of ``J`` is ``e_i`` plus at most
    two rows of ``W`` scaled, so it is accumulated in a dense scratch row over the union of
    their patterns (an entry of ``G`` that is exactly 0, as on a sliding tangential row, adds
    nothing)."""
    rows, first_col, first_val, second_col, second_val = generalised_jacobian_2d(
        lower, upper, box, cone_n, cone_t, cone_mu, unilateral, y)
    n, m = y.size, rows.size
    capacity = 0
    for a in range(m):
        i = rows[a]
        capacity += 3                                        # e_i and G's own columns
        for column in (first_col[i], second_col[i]):
            if column >= 0:
                capacity += indptr[column + 1] - indptr[column]
    J_indptr = np.zeros(m + 1, dtype=np.int64)
    J_indices = np.empty(capacity, dtype=np.int64)
    J_data = np.empty(capacity)
    scratch = np.zeros(n)
    seen = np.full(n, -1)
    pattern = np.empty(n, dtype=np.int64)
    count = 0
    for a in range(m):
        i = rows[a]
        seen[i], scratch[i], pattern[0] = a, 1.0, i          # the identity's entry
        size = 1
        for column, value in ((first_col[i], first_val[i]), (second_col[i], second_val[i])):
            if column < 0 or value == 0.0:
                continue
            if seen[column] != a:
                seen[column], scratch[column], pattern[size] = a, 0.0, column
                size += 1
            scratch[column] -= value
            weight = value * rho[column]
            for k in range(indptr[column], indptr[column + 1]):
                j = indices[k]
                if seen[j] != a:
                    seen[j], scratch[j], pattern[size] = a, 0.0, j
                    size += 1
                scratch[j] += weight * data[k]
            scratch[column] += weight * sigma
        for k in range(size):
            J_indices[count + k] = pattern[k]
            J_data[count + k] = scratch[pattern[k]]
        count += size
        J_indptr[a + 1] = count
    return rows, J_indptr, J_indices[:count], J_data[:count]


@numba.njit(cache=True)
def lu_solve(matrix, rhs):
    """``matrix x = rhs`` by an LU with partial pivoting, ``matrix`` overwritten; ``(x, ok)``
    with ``ok`` False where a pivot is exactly zero (as LAPACK's ``getrf`` reports)."""
    m = rhs.size
    x = rhs.copy()
    for k in range(m):
        pivot = k
        for i in range(k + 1, m):
            if abs(matrix[i, k]) > abs(matrix[pivot, k]):
                pivot = i
        if matrix[pivot, k] == 0.0:
            return x, False
        if pivot != k:
            for j in range(m):
                matrix[k, j], matrix[pivot, j] = matrix[pivot, j], matrix[k, j]
            x[k], x[pivot] = x[pivot], x[k]
        for i in range(k + 1, m):
            factor = matrix[i, k] / matrix[k, k]
            if factor != 0.0:
                for j in range(k + 1, m):
                    matrix[i, j] -= factor * matrix[k, j]
                x[i] -= factor * x[k]
    for k in range(m - 1, -1, -1):
        total = x[k]
        for j in range(k + 1, m):
            total -= matrix[k, j] * x[j]
        x[k] = total / matrix[k, k]
    return x, True


@numba.njit(cache=True)
def newton_direction_2d(rows, J, phi, regularisations):
    """:func:`~lubcontact.solvers.newton._newton_direction` on the dense rows ``J`` (active
    rows ``rows``): ``(direction, ok)``."""
    n, m = phi.size, rows.size
    direction = -phi
    if m == 0:
        return direction, True
    inactive = np.ones(n, dtype=np.bool_)
    inactive[rows] = False
    rhs = np.empty(m)
    for a in range(m):
        total = -phi[rows[a]]
        for j in range(n):
            if inactive[j]:
                total -= J[a, j] * direction[j]
        rhs[a] = total
    for delta in regularisations:
        block = np.empty((m, m))
        for a in range(m):
            for b in range(m):
                block[a, b] = J[a, rows[b]]
            block[a, a] += delta
        solved, ok = lu_solve(block, rhs)
        if ok and np.all(np.isfinite(solved)):
            direction[rows] = solved
            return direction, True
    return direction, False


@numba.njit(cache=True)
def newton_phase_2d(W, q, rho, lower, upper, box, cone_n, cone_t, cone_mu, unilateral, sigma,
                    center, q_scale, forces, tol, max_iter, inner_tol, regularisations, memory,
                    armijo, max_halvings):
    """Newton iterations from ``forces`` until the FCLIB error is below ``tol``, ``|phi| <=
    inner_tol``, a failed line search or ``max_iter`` (:func:`newton._newton_phase`).

    Returns
    -------
    tuple
        ``(best, best_error, last, last_error, iterations, gradient_steps, code, history,
        solved)``: the best iterate and its FCLIB error, the last iterate and its error, the
        iterations, the steepest-descent steps, a status code (:data:`CONVERGED_CODE`, ...),
        the FCLIB error of each iterate (the start first) and whether ``|phi| <= inner_tol``.
    """
    n = forces.size
    forces = forces.copy()
    phi, y, velocity = np.empty(n), np.empty(n), np.empty(n)
    product_2d(W, forces, q, velocity)
    merit = alart_curnier_2d(rho, lower, upper, cone_n, cone_t, cone_mu, unilateral, sigma,
                             center, forces, velocity, phi, y)
    recent = np.full(memory, -np.inf)
    recent[0] = merit
    count = 1
    error = coulomb_error_2d(forces, velocity, lower, upper, cone_n, cone_t, cone_mu, unilateral,
                             q_scale)
    history = np.empty(max_iter + 1)
    history[0] = error
    best, best_error = forces.copy(), error
    iterations = gradient_steps = 0
    code = MAX_ITER_CODE
    trial, trial_phi, trial_y = np.empty(n), np.empty(n), np.empty(n)
    change, trial_velocity, no_offset = np.empty(n), np.empty(n), np.zeros(n)
    while error > tol and iterations < max_iter and np.sqrt(2.0 * merit) > inner_tol:
        iterations += 1
        rows, J = jacobian_rows_2d(W, rho, lower, upper, box, cone_n, cone_t, cone_mu,
                                   unilateral, sigma, y)
        reference = recent.max()
        accepted = False
        for attempt in range(2):            # Newton's direction, then steepest descent
            if attempt == 0:
                direction, ok = newton_direction_2d(rows, J, phi, regularisations)
                if not ok:
                    continue
                slope = 2.0 * merit
            else:
                gradient = phi.copy()
                gradient[rows] = 0.0
                for a in range(rows.size):
                    weight = phi[rows[a]]
                    for j in range(n):
                        gradient[j] += J[a, j] * weight
                direction = -gradient
                slope = 0.0
                for j in range(n):
                    slope += gradient[j] * gradient[j]
                gradient_steps += 1
            if not slope > 0.0:
                continue
            product_2d(W, direction, no_offset, change)     # a trial's velocity: v + alpha W d
            alpha = 1.0
            for _ in range(max_halvings):
                for j in range(n):
                    trial[j] = forces[j] + alpha * direction[j]
                    trial_velocity[j] = velocity[j] + alpha * change[j]
                value = alart_curnier_2d(rho, lower, upper, cone_n, cone_t, cone_mu, unilateral,
                                         sigma, center, trial, trial_velocity, trial_phi, trial_y)
                if value <= reference - armijo * alpha * slope:
                    accepted = True
                    break
                alpha *= 0.5
            if accepted:
                break
        if not accepted:
            code = FAILED_CODE
            break
        forces[:] = trial
        product_2d(W, forces, q, velocity)                   # W r afresh: no drift
        merit = alart_curnier_2d(rho, lower, upper, cone_n, cone_t, cone_mu, unilateral, sigma,
                                 center, forces, velocity, phi, y)
        if count < memory:
            recent[count] = merit
            count += 1
        else:
            recent[:-1] = recent[1:]
            recent[-1] = merit
        error = coulomb_error_2d(forces, velocity, lower, upper, cone_n, cone_t, cone_mu,
                                 unilateral, q_scale)
        history[iterations] = error
        if error < best_error:
            best[:], best_error = forces, error
    if best_error <= tol:
        code = CONVERGED_CODE
    return (best, best_error, forces, error, iterations, gradient_steps, code,
            history[:iterations + 1], np.sqrt(2.0 * merit) <= inner_tol)
