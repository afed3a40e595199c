"""Compiled (numba) kernels of the gradient methods, imported lazily.

Two APGD loops are compiled, each with the product ``W z`` fused with the
projection, the residual, the restart test and the extrapolation: the box case
(frictionless problems: every row in ``[lower, upper]``, with the active-set
bookkeeping, and resumable: it stops for the active-set finish and carries on
with its momentum), about twice as fast as the numpy loop on the 10^4-grain pile
(docs/benchmarks.md); and 2D friction cones (optionally with the Coulomb shift
updated inside, :func:`apgd_cone2d`), about 3x faster than the numpy loop on
the 1000-grain frictional settling pile; its projection also covers the 2D
UNION contacts of gluey + friction steps. The numpy loop remains the general
path (3D cones).

Both loops share the steps of APGD through small helpers (backtracking test,
residual record and stop, extrapolation with restart; the cone loop's start), inlined into the
loops by numba (``inline="always"``): as plain calls they made the box loop
about 20 % slower per iteration on the 1000-grain pile.
"""
from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def matvec(indptr, indices, values, x, out):
    """``out = W x`` for W in CSR arrays (each row's end carried to the next row's start)."""
    start = indptr[0]
    for i in range(out.size):
        end = indptr[i + 1]
        total = 0.0
        for k in range(start, end):
            total += values[k] * x[indices[k]]
        out[i] = total
        start = end


@numba.njit(cache=True, inline="always")
def apply_operator(indptr, indices, values, t_indptr, t_indices, t_values, scratch, x, out):
    """``out = W x``: from the rows of ``W`` (``t_indptr`` empty), or as ``F^T (F x)`` with the
    rows of ``F`` and of ``F^T`` (``W = F^T F``; ``scratch`` holds ``F x``). On a developed flow
    ``F`` has about a fifth of ``W``'s entries per row and the two products cost half of one."""
    if t_indptr.size == 0:
        matvec(indptr, indices, values, x, out)
    else:
        matvec(indptr, indices, values, x, scratch)
        matvec(t_indptr, t_indices, t_values, scratch, out)


@numba.njit(cache=True, inline="always")
def loop_arrays(indptr, indices, values, t_indptr, t_indices, t_values, scratch, z0, max_iter):
    """Work arrays of an APGD loop started at ``z0`` (the operator as in :func:`apply_operator`).

    Returns ``x_old = z0``, ``wx_old = W z0``, the extrapolated point ``y`` and
    ``wy`` (copies of them), the trial point ``x`` and ``wx`` (uninitialised),
    the best iterate (``z0``) and the residual history (length ``max_iter``).
    """
    x_old = z0.copy()
    wx_old = np.empty(z0.size)
    apply_operator(indptr, indices, values, t_indptr, t_indices, t_values, scratch, x_old, wx_old)
    return (x_old, wx_old, x_old.copy(), wx_old.copy(), np.empty(z0.size), np.empty(z0.size),
            z0.copy(), np.empty(max_iter))


@numba.njit(cache=True, inline="always")
def step_accepted(x, y, wx, wy, lipschitz):
    """Backtracking test of the step ``y -> x``: ``(x - y).W(x - y) <= L |x - y|^2``
    (to a relative 1e-12), with ``wx = W x`` and ``wy = W y``."""
    num = 0.0
    den = 0.0
    for i in range(x.size):
        d = x[i] - y[i]
        num += d * (wx[i] - wy[i])
        den += d * d
    return num <= lipschitz * den * (1.0 + 1e-12)


@numba.njit(cache=True, inline="always")
def record_residual(k, residual, x, history, best, best_residual, first, tol, divergence):
    """Store the residual of iteration ``k``, keep the best iterate and test the stop.

    Returns
    -------
    best_residual, first residual, code (0 converged, 2 diverged: non-finite or
    above ``divergence * max(first, 1)``, -1 go on).
    """
    history[k] = residual
    if first < 0.0:
        first = residual
    if residual < best_residual:
        best_residual = residual
        best[:] = x
    code = -1
    if residual <= tol:
        code = 0
    elif not np.isfinite(residual) or residual > divergence * max(first, 1.0):
        code = 2
    return best_residual, first, code


@numba.njit(cache=True, inline="always")
def extrapolate(theta, uphill, x, wx, x_old, wx_old, y, wy):
    """Nesterov step ``y = x + beta (x - x_old)`` (and ``wy``), restarted (``beta = 0``,
    ``theta = 1``) when ``uphill > 0``; moves ``x`` into ``x_old``. Returns the new ``theta``."""
    theta_new = 0.5 * (-theta * theta + theta * np.sqrt(theta * theta + 4.0))
    beta = theta * (1.0 - theta) / (theta * theta + theta_new)
    if uphill > 0.0:
        theta_new = 1.0
        beta = 0.0
    for i in range(x.size):
        y[i] = x[i] + beta * (x[i] - x_old[i])
        wy[i] = wx[i] + beta * (wx[i] - wx_old[i])
        x_old[i] = x[i]
        wx_old[i] = wx[i]
    return theta_new


@numba.njit(cache=True)
def apgd_box(indptr, indices, values, b, lower, upper, ratio, sign, x_old, wx_old, y, wy, active,
             theta, lipschitz, unchanged, first, tol, max_iter, stable, divergence):
    """APGD (restart, backtracking) on ``min 1/2 z.Wz + b.z, lower <= z <= upper``, resumable.

    Mirrors :func:`lubcontact.solvers.gradient_loops.run_apgd`. ``ratio`` maps the
    iteration variables to the Jacobi-scaled ones of the stopping measure;
    ``sign`` marks one-sided rows (+1 lower bound 0, -1 upper bound 0) for the
    active set. The loop state is the last iterate ``x_old`` and ``wx_old = W
    x_old``, the extrapolated point ``y`` and ``wy = W y``, the active set
    ``active`` of ``x_old`` (bool; arrays updated in place), ``theta``, the
    Lipschitz estimate, ``unchanged`` (iterations since ``active`` last changed,
    -1 before the first iteration) and ``first`` (the first residual, the scale
    of the divergence test; -1 before it): a call given the state a previous
    call stopped in continues its iterations exactly, momentum included. With
    ``stable > 0`` the loop stops with status 3 when the active set has just
    stayed unchanged for ``stable`` iterations, once per settled set (a set
    that stays settled does not stop the loop again).

    Returns
    -------
    best, best_residual, history, status (0 converged, 1 max_iter,
    2 diverged, 3 active set settled), iterations, products, and the state's
    scalars: theta, Lipschitz estimate, unchanged, first.
    """
    n = b.size
    rms = 1.0 / np.sqrt(max(n, 1))
    x = np.empty(n)
    wx = np.empty(n)
    best = x_old.copy()
    history = np.empty(max_iter)
    best_residual = np.inf
    products, status, iterations = 0, 1, max_iter
    for k in range(max_iter):
        while True:
            for i in range(n):
                x[i] = min(max(y[i] - (wy[i] + b[i]) / lipschitz, lower[i]), upper[i])
            matvec(indptr, indices, values, x, wx)
            products += 1
            if step_accepted(x, y, wx, wy, lipschitz):
                break
            lipschitz *= 2.0
        squares = 0.0
        uphill = 0.0
        changes = 0
        for i in range(n):
            g = wx[i] + b[i]
            scaled = x[i] * ratio[i]
            projected = min(max(scaled - g / ratio[i], lower[i]), upper[i])
            squares += (scaled - projected) ** 2
            uphill += (wy[i] + b[i]) * (x[i] - x_old[i])
            row_active = sign[i] == 0.0 or sign[i] * (x[i] - g) > 0.0
            if row_active != active[i]:
                changes += 1
                active[i] = row_active
        best_residual, first, code = record_residual(k, np.sqrt(squares) * rms, x, history, best,
                                                     best_residual, first, tol, divergence)
        if code >= 0:
            status, iterations = code, k + 1
            break
        theta = extrapolate(theta, uphill, x, wx, x_old, wx_old, y, wy)
        lipschitz *= 0.9
        unchanged = unchanged + 1 if changes == 0 else 0
        if stable > 0 and unchanged == stable:
            status, iterations = 3, k + 1
            break
    return (best, best_residual, history[:iterations], status, iterations, products, theta,
            lipschitz, unchanged, first)


@numba.njit(cache=True, inline="always")
def friction_cone_point(normal, tangent, mu):
    """Projection of ``(normal, tangent)`` onto the 2D friction cone ``{|t| <= mu n}``,
    with the floating-point operations of :func:`lubcontact.cones.project_friction_cone`
    (``size > 0`` where the boundary is reached: ``size = 0`` is inside or polar)."""
    size = np.sqrt(tangent * tangent)
    if size <= mu * normal and normal >= 0.0:
        return normal, tangent
    if mu * size <= -normal:
        return 0.0, 0.0
    scale = (normal + mu * size) / (1.0 + mu * mu)
    return scale, (mu * scale / size) * tangent


@numba.njit(cache=True)
def project_cones(x, lower, upper, cone_n, cone_t, cone_mu, cone_union, out):
    """``out = P_K(x)``: rows clipped to ``[lower, upper]``, then each 2D friction cone
    ``{|t| <= mu n}`` (normal row ``cone_n[c]``, tangential row ``cone_t[c]``) projected.

    A contact with ``cone_union[c]`` is a UNION contact: it goes to the nearer of its
    friction cone and the pulled half-line ``{n <= 0, t = 0}``, ties to the cone (as
    :class:`lubcontact.cones.ConeProjector`).
    """
    for i in range(x.size):
        out[i] = min(max(x[i], lower[i]), upper[i])
    for c in range(cone_n.size):
        normal = x[cone_n[c]]
        tangent = x[cone_t[c]]
        new_n, new_t = friction_cone_point(normal, tangent, cone_mu[c])
        if cone_union[c]:
            pull_n = min(normal, 0.0)
            d_cone = (new_n - normal) * (new_n - normal) + (new_t - tangent) * (new_t - tangent)
            d_pull = (pull_n - normal) * (pull_n - normal) + tangent * tangent
            if not d_cone <= d_pull:
                new_n, new_t = pull_n, 0.0
        out[cone_n[c]] = new_n
        out[cone_t[c]] = new_t


@numba.njit(cache=True)
def apgd_cone2d(indptr, indices, values, t_indptr, t_indices, t_values, scratch, b, base, lower,
                upper, cone_n, cone_t, cone_mu, cone_union, ratio, z0, tol, max_iter, lipschitz,
                divergence, every):
    """APGD (restart, backtracking) on ``min 1/2 z.Wz + b.z, z in K`` with 2D friction cones.

    ``W z`` is applied by :func:`apply_operator` (``W`` assembled, or ``F`` and ``F^T``).

    Mirrors :func:`lubcontact.solvers.gradient_loops.run_apgd` (no active-set
    bookkeeping), with :func:`project_cones` as the projection: contacts with
    ``cone_union`` are UNION contacts, projected onto the nearer piece in the
    steps and in the stopping measure alike (as the numpy loop's
    :meth:`~lubcontact.solvers.dual_data.DualData.residual`). With
    ``every > 0`` the problem is Coulomb's, not its convex relaxation: every
    ``every`` iterations the shift is updated from the current iterate,
    ``b_n = base_n + mu |g_T|`` on the cone contacts (``base``: the offset
    without shift, ``g = W z + b``), keeping the momentum (on the
    1000-grain settling pile, restarting it at each update stalled the residual
    at 2e-9; with updates every iteration and no restart it reached 1e-10);
    the stopping measure is then the natural residual with the shift
    consistent with the iterate (``g_n`` replaced by
    ``base_n + (W z)_n + mu |g_T|``), i.e. the modified (De Saxce) natural
    map of the Coulomb problem.

    Returns
    -------
    best, best_residual, history, status (0 converged, 1 max_iter, 2 diverged),
    iterations, products, last iterate, Lipschitz estimate, last offset ``b``.
    """
    n = b.size
    b = b.copy()
    rms = 1.0 / np.sqrt(max(n, 1))
    x_old, wx_old, y, wy, x, wx, best, history = loop_arrays(
        indptr, indices, values, t_indptr, t_indices, t_values, scratch, z0, max_iter)
    trial = np.empty(n)
    projected = np.empty(n)
    gradient = np.empty(n)
    best_residual, first = np.inf, -1.0
    products, theta, status, iterations = 1, 1.0, 1, max_iter
    for k in range(max_iter):
        while True:
            for i in range(n):
                trial[i] = y[i] - (wy[i] + b[i]) / lipschitz
            project_cones(trial, lower, upper, cone_n, cone_t, cone_mu, cone_union, x)
            apply_operator(indptr, indices, values, t_indptr, t_indices, t_values, scratch, x, wx)
            products += 1
            if step_accepted(x, y, wx, wy, lipschitz):
                break
            lipschitz *= 2.0
        for i in range(n):
            gradient[i] = wx[i] + b[i]
        if every > 0:
            for c in range(cone_n.size):
                gradient[cone_n[c]] = wx[cone_n[c]] + base[cone_n[c]] + cone_mu[c] * abs(
                    gradient[cone_t[c]])
        for i in range(n):
            trial[i] = x[i] * ratio[i] - gradient[i] / ratio[i]
        project_cones(trial, lower, upper, cone_n, cone_t, cone_mu, cone_union, projected)
        squares = 0.0
        uphill = 0.0
        for i in range(n):
            squares += (x[i] * ratio[i] - projected[i]) ** 2
            uphill += (wy[i] + b[i]) * (x[i] - x_old[i])
        best_residual, first, code = record_residual(k, np.sqrt(squares) * rms, x, history, best,
                                                     best_residual, first, tol, divergence)
        if code >= 0:
            status, iterations = code, k + 1
            break
        if every > 0 and (k + 1) % every == 0:
            for c in range(cone_n.size):
                b[cone_n[c]] = gradient[cone_n[c]] - wx[cone_n[c]]
        theta = extrapolate(theta, uphill, x, wx, x_old, wx_old, y, wy)
        lipschitz *= 0.9
    return best, best_residual, history[:iterations], status, iterations, products, x, lipschitz, b


@numba.njit(cache=True, inline="always")
def _row_product(indptr, indices, values, r, row):
    """``(W r)_row``."""
    total = 0.0
    for k in range(indptr[row], indptr[row + 1]):
        total += values[k] * r[indices[k]]
    return total


@numba.njit(cache=True, inline="always")
def local_coulomb_2d(a, c, c2, d, b_n, b_t, mu, unilateral, r_n, r_t):
    """Exact solution of one 2D contact's Coulomb law with the others frozen.

    The local velocity is ``u = [[a, c], [c2, d]] r + b``. Cases in turn: open
    (``b_n >= 0``, unilateral: ``r = 0``); stick (``u = 0``, ``r_n > 0``,
    ``|r_t| <= mu r_n``); pulled (bilateral only: ``u_n = 0``, ``r_t = 0``,
    ``r_n <= 0``); slide (``u_n = 0``, ``r_t = -s mu r_n`` with ``s u_t >= 0``).
    When none is consistent (a local matrix far from symmetric), one local
    Alart-Curnier projection step from ``(r_n, r_t)``. Returns ``(r_n, r_t)``.
    """
    if unilateral and b_n >= 0.0:
        return 0.0, 0.0
    det = a * d - c * c2
    if det > 0.0:
        n = (-b_n * d + c * b_t) / det
        t = (-a * b_t + c2 * b_n) / det
        if n > 0.0 and abs(t) <= mu * n:
            return n, t
    if not unilateral and a > 0.0 and -b_n / a <= 0.0:
        return -b_n / a, 0.0
    for s in (1.0, -1.0):
        denominator = a - s * mu * c
        if denominator > 0.0:
            n = -b_n / denominator
            if n >= 0.0:
                t = -s * mu * n
                if s * (c2 * n + d * t + b_t) >= 0.0:
                    return n, t
    u_n = a * r_n + c * r_t + b_n
    u_t = c2 * r_n + d * r_t + b_t
    n = r_n - u_n / a
    if unilateral:
        n = max(n, 0.0)
    radius = mu * max(n, 0.0)
    t = min(max(r_t - u_t / d, -radius), radius)
    return n, t


@numba.njit(cache=True, inline="always")
def _moved(indptr, indices, values, state, row, change, tracked):
    """After ``r_row`` changed by ``change``: with ``tracked``, ``state += change x (row of
    F^T)``, keeping ``state = F r`` (nothing to do when ``state`` is ``r`` itself)."""
    if tracked and change != 0.0:
        for k in range(indptr[row], indptr[row + 1]):
            state[indices[k]] += values[k] * change


@numba.njit(cache=True)
def gauss_seidel_2d(indptr, indices, values, q, lower, upper, box_rows, box_diagonal, cone_n,
                    cone_t, cone_mu, unilateral, local, r, state, tracked, sweeps):
    """``sweeps`` non-smooth Gauss-Seidel sweeps on ``W r + q`` in place of ``r`` (exact Coulomb).

    Each sweep visits the box rows (``r_i`` in ``[lower_i, upper_i]``: the
    clipped minimiser of row ``i`` with the others frozen) and then the 2D
    frictional contacts (rows ``cone_n[j]``, ``cone_t[j]``; ``local[j]`` the
    2x2 block ``W_nn, W_nt, W_tn, W_tt``; :func:`local_coulomb_2d`).

    A row of ``W r`` is read from ``(indptr, indices, values)`` and ``state``:
    the rows of ``W`` and ``r`` itself (``state`` is ``r``), or, with
    ``tracked``, the rows of ``F^T`` (``W = F^T F``) and ``state = F r`` (the
    velocities, updated after each change of ``r``): a row of ``F^T`` holds the
    few degrees of freedom of one contact's two bodies where a row of ``W``
    holds every contact sharing a body with it.
    """
    for _ in range(sweeps):
        for k in range(box_rows.size):
            i = box_rows[k]
            diagonal = box_diagonal[k]
            if diagonal <= 0.0:
                continue
            u = _row_product(indptr, indices, values, state, i) + q[i]
            new = min(max(r[i] - u / diagonal, lower[i]), upper[i])
            change = new - r[i]
            r[i] = new
            _moved(indptr, indices, values, state, i, change, tracked)
        for j in range(cone_n.size):
            n, t = cone_n[j], cone_t[j]
            a, c, c2, d = local[j, 0], local[j, 1], local[j, 2], local[j, 3]
            b_n = _row_product(indptr, indices, values, state, n) + q[n] - a * r[n] - c * r[t]
            b_t = _row_product(indptr, indices, values, state, t) + q[t] - c2 * r[n] - d * r[t]
            new_n, new_t = local_coulomb_2d(a, c, c2, d, b_n, b_t, cone_mu[j], unilateral[j],
                                            r[n], r[t])
            change_n, change_t = new_n - r[n], new_t - r[t]
            r[n], r[t] = new_n, new_t
            _moved(indptr, indices, values, state, n, change_n, tracked)
            _moved(indptr, indices, values, state, t, change_t, tracked)
