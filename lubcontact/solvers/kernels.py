"""Compiled (numba) kernels of the gradient methods, nsgs and newton-ac, imported lazily.

Two APGD loops are compiled, each with the product ``W z`` fused with the
projection, the residual, the restart test and the extrapolation: the box case
(frictionless problems: every row in ``[lower, upper]``, with the active-set
bookkeeping, and resumable: it stops for the active-set finish and carries on
with its momentum), about twice as fast as the numpy loop on the 10^4-grain pile
(docs/records/benchmarks.md); and 2D friction cones (optionally with the Coulomb shift
updated inside, :func:`apgd_cone2d`), about 3x faster than the numpy loop on
the 1000-grain frictional settling pile; its projection also covers the 2D
UNION contacts of gluey + friction steps. The numpy loop remains the general
path (3D cones).

Both loops share the steps of APGD through small helpers (backtracking test,
residual record and stop, extrapolation with restart; the cone loop's start), inlined into the
loops by numba (``inline="always"``): as plain calls they made the box loop
about 20 % slower per iteration on the 1000-grain pile.

The non-smooth Gauss-Seidel sweeps of ``nsgs`` (:func:`gauss_seidel_2d`) and the Newton phase
of ``newton-ac`` on 2D problems (:func:`newton_phase_2d`, last section) are here too: numba's
cache does not see a change in another module's function that a cached kernel inlines, so the
kernels that share pieces (:func:`friction_cone_point`) live in one file.
"""
from __future__ import annotations

import numba
import numpy as np
from numba import types
from numba.np.linalg import _LAPACK, F_INT_nptype

# LAPACK's dgesv as numba's own np.linalg.solve calls it (numba's private bindings to scipy's
# LAPACK: a public ctypes binding would stop numba caching the kernels that use it), without
# np.linalg.solve's exception on a singular matrix, which a compiled kernel cannot catch
_GESV = _LAPACK().numba_xgesv(types.float64)
_LAPACK_INT = F_INT_nptype
_DOUBLE = ord("d")


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


@numba.njit(cache=True)
def add_columns(indptr, indices, values, change, rows, out):
    """``out += W change`` for a symmetric ``W`` in CSR arrays and a ``change`` (n,) that is zero
    but on the rows ``rows``: column ``i`` of ``W`` read as its row ``i``, so that the cost is
    that of those rows, not of a product (the few rows local sweeps move)."""
    for i in rows:
        moved = change[i]
        for k in range(indptr[i], indptr[i + 1]):
            out[indices[k]] += values[k] * moved


@numba.njit(cache=True)
def factor_rows_state(indptr, indices, values, t_indptr, t_indices, x, rows, out):
    """``out[d] = (F x)[d]`` at the degrees of freedom ``d`` that the rows ``rows`` of ``F^T``
    hold, ``F`` by its rows (``indptr``, ``indices``, ``values``) and ``F^T`` by its rows'
    pattern (``t_indptr``, ``t_indices``); the other entries of ``out`` are left as they are.
    Each such ``d`` once, summed in ``F``'s row order (a product's bits): the velocities that
    local Gauss-Seidel sweeps over ``rows`` read and update
    (:class:`~lubcontact.solvers.gauss_seidel.Sweeps`), without a product with all of ``F``."""
    done = np.zeros(out.size, dtype=np.bool_)
    for i in rows:
        for e in range(t_indptr[i], t_indptr[i + 1]):
            d = t_indices[e]
            if done[d]:
                continue
            done[d] = True
            total = 0.0
            for k in range(indptr[d], indptr[d + 1]):
                total += values[k] * x[indices[k]]
            out[d] = total


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


@numba.njit(cache=True)
def factor_rows_product(indptr, indices, values, t_indptr, t_indices, t_values, scratch, x, rows):
    """``(W x)[rows]`` with ``W = F^T F`` (the arguments as :func:`apply_operator` takes them
    with the factor): ``F x``, then the rows ``rows`` of ``F^T`` (short: a contact row's degrees
    of freedom)."""
    matvec(indptr, indices, values, x, scratch)
    out = np.empty(rows.size)
    for a in range(rows.size):
        i = rows[a]
        total = 0.0
        for k in range(t_indptr[i], t_indptr[i + 1]):
            total += t_values[k] * scratch[t_indices[k]]
        out[a] = total
    return out


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
def sufficient_decrease(num, den, lipschitz):
    """Backtracking test of a step ``y -> x``: ``(x - y).W(x - y) <= L |x - y|^2`` (to a
    relative 1e-12), given ``num = (x - y).W(x - y)`` and ``den = |x - y|^2``."""
    return num <= lipschitz * den * (1.0 + 1e-12)


@numba.njit(cache=True, inline="always")
def step_sums(x, y, wx, wy, b, x_old):
    """The sums of an APGD step ``y -> x``, in one pass: ``(x - y).W(x - y)`` and ``|x - y|^2``
    (the backtracking test, :func:`sufficient_decrease`), and ``(W y + b).(x - x_old)`` (the restart
    test, uphill when positive)."""
    num = 0.0
    den = 0.0
    uphill = 0.0
    for i in range(x.size):
        d = x[i] - y[i]
        num += d * (wx[i] - wy[i])
        den += d * d
        uphill += (wy[i] + b[i]) * (x[i] - x_old[i])
    return num, den, uphill


@numba.njit(cache=True, inline="always")
def record_residual(k, residual, x, history, best, best_residual, first, tol, divergence):
    """Store the ``k``-th residual (of an iteration or a check), keep the best iterate and test
    the stop.

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
def extrapolate(theta, uphill, x, wx, x_old, wx_old, y, wy, move):
    """Nesterov step ``y = x + beta (x - x_old)`` (and ``wy``), restarted (``beta = 0``,
    ``theta = 1``) when ``uphill > 0``; with ``move``, copies ``x`` into ``x_old`` (and ``wx``
    into ``wx_old``; a caller that swaps the arrays instead passes False). Returns the new
    ``theta``."""
    theta_new = 0.5 * (-theta * theta + theta * np.sqrt(theta * theta + 4.0))
    beta = theta * (1.0 - theta) / (theta * theta + theta_new)
    if uphill > 0.0:
        theta_new = 1.0
        beta = 0.0
    for i in range(x.size):
        y[i] = x[i] + beta * (x[i] - x_old[i])
        wy[i] = wx[i] + beta * (wx[i] - wx_old[i])
        if move:
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
            step = 1.0 / lipschitz
            for i in range(n):
                x[i] = min(max(y[i] - (wy[i] + b[i]) * step, lower[i]), upper[i])
            matvec(indptr, indices, values, x, wx)
            products += 1
            num, den, uphill = step_sums(x, y, wx, wy, b, x_old)
            if sufficient_decrease(num, den, lipschitz):
                break
            lipschitz *= 2.0
        squares = 0.0
        changes = 0
        for i in range(n):
            g = wx[i] + b[i]
            scaled = x[i] * ratio[i]
            projected = min(max(scaled - g / ratio[i], lower[i]), upper[i])
            squares += (scaled - projected) ** 2
            row_active = sign[i] == 0.0 or sign[i] * (x[i] - g) > 0.0
            if row_active != active[i]:
                changes += 1
                active[i] = row_active
        best_residual, first, code = record_residual(k, np.sqrt(squares) * rms, x, history, best,
                                                     best_residual, first, tol, divergence)
        if code >= 0:
            status, iterations = code, k + 1
            break
        theta = extrapolate(theta, uphill, x, wx, x_old, wx_old, y, wy, True)
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
    (``size > 0`` where the boundary is reached: ``size = 0`` is inside or polar; ``|t|``,
    which is its ``sqrt(t * t)`` unless ``t * t`` under- or overflows)."""
    size = abs(tangent)
    if size <= mu * normal and normal >= 0.0:
        return normal, tangent
    if mu * size <= -normal:
        return 0.0, 0.0
    scale = (normal + mu * size) / (1.0 + mu * mu)
    return scale, (mu * scale / size) * tangent


@numba.njit(cache=True, inline="always")
def cone_point(normal, tangent, mu, union):
    """Projection of ``(normal, tangent)`` onto a 2D friction cone (:func:`friction_cone_point`)
    or, for a UNION contact (``union``), onto the nearer of that cone and the pulled half-line
    ``{n <= 0, t = 0}``, ties to the cone (as :class:`lubcontact.cones.ConeProjector`)."""
    new_n, new_t = friction_cone_point(normal, tangent, mu)
    if union:
        pull_n = min(normal, 0.0)
        d_cone = (new_n - normal) * (new_n - normal) + (new_t - tangent) * (new_t - tangent)
        d_pull = (pull_n - normal) * (pull_n - normal) + tangent * tangent
        if not d_cone <= d_pull:
            return pull_n, 0.0
    return new_n, new_t


@numba.njit(cache=True)
def project_cones(x, lower, upper, cone_n, cone_t, cone_mu, cone_union, out):
    """``out = P_K(x)``: rows clipped to ``[lower, upper]``, then each 2D friction cone
    ``{|t| <= mu n}`` (normal row ``cone_n[c]``, tangential row ``cone_t[c]``) projected by
    :func:`cone_point` (``cone_union[c]``: a UNION contact)."""
    for i in range(x.size):
        out[i] = min(max(x[i], lower[i]), upper[i])
    for c in range(cone_n.size):
        out[cone_n[c]], out[cone_t[c]] = cone_point(x[cone_n[c]], x[cone_t[c]], cone_mu[c],
                                                    cone_union[c])


@numba.njit(cache=True, inline="always")
def projected_step(y, wy, b, lipschitz, lower, upper, box_rows, cone_n, cone_t, cone_mu,
                   cone_union, x):
    """``x = P_K(y - (W y + b) / L)`` as :func:`project_cones` gives it, in one pass over the
    rows and without the trial point as a vector: the rows ``box_rows`` (those in no cone)
    clipped, each cone's two rows projected by :func:`cone_point`. ``1 / L`` multiplies, as in
    every APGD loop: a division in this branchy pass cost 7 % of an iteration at 10^5 grains."""
    step = 1.0 / lipschitz
    for k in range(box_rows.size):
        i = box_rows[k]
        x[i] = min(max(y[i] - (wy[i] + b[i]) * step, lower[i]), upper[i])
    for c in range(cone_n.size):
        n, t = cone_n[c], cone_t[c]
        x[n], x[t] = cone_point(y[n] - (wy[n] + b[n]) * step, y[t] - (wy[t] + b[t]) * step,
                                cone_mu[c], cone_union[c])


@numba.njit(cache=True, inline="always")
def natural_residual_squares(x, wx, b, base, shifted, ratio, lower, upper, box_rows, cone_n,
                             cone_t, cone_mu, cone_union):
    """``|D x - P_K(D x - D^-1 g)|^2`` with ``D = diag(ratio)`` and ``g = W x + b`` (``wx = W
    x``), row by row without vectors; with ``shifted`` the cones' normal rows of ``g`` are
    ``base_n + (W x)_n + mu |g_t|`` (the shift consistent with ``x``)."""
    squares = 0.0
    for k in range(box_rows.size):
        i = box_rows[k]
        scaled = x[i] * ratio[i]
        projected = min(max(scaled - (wx[i] + b[i]) / ratio[i], lower[i]), upper[i])
        squares += (scaled - projected) ** 2
    for c in range(cone_n.size):
        n, t = cone_n[c], cone_t[c]
        g_t = wx[t] + b[t]
        g_n = wx[n] + base[n] + cone_mu[c] * abs(g_t) if shifted else wx[n] + b[n]
        scaled_n, scaled_t = x[n] * ratio[n], x[t] * ratio[t]
        p_n, p_t = cone_point(scaled_n - g_n / ratio[n], scaled_t - g_t / ratio[t], cone_mu[c],
                              cone_union[c])
        squares += (scaled_n - p_n) ** 2 + (scaled_t - p_t) ** 2
    return squares


@numba.njit(cache=True)
def apgd_cone2d(indptr, indices, values, t_indptr, t_indices, t_values, scratch, b, base, lower,
                upper, box_rows, cone_n, cone_t, cone_mu, cone_union, ratio, z0, tol, max_iter,
                lipschitz, divergence, every, check_every, streaming):
    """APGD (restart, backtracking) on ``min 1/2 z.Wz + b.z, z in K`` with 2D friction cones.

    ``W z`` is applied by :func:`apply_operator` (``W`` assembled, or ``F`` and ``F^T``).

    Mirrors :func:`lubcontact.solvers.gradient_loops.run_apgd` (no active-set
    bookkeeping; with ``check_every = 1`` the same stops), with :func:`project_cones` as the
    projection: contacts with
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

    The stopping measure is evaluated at the first and last iterations and
    every ``check_every`` iterations between: the history holds those
    residuals only, and the best iterate is the best of them.

    With ``streaming`` (problems whose vectors do not stay in the cache: the loop is bound by
    the bytes it moves) the iterates are the same, each stage passing over the rows once:
    the step by :func:`projected_step` (``box_rows``: the rows in no cone), the stopping measure
    by :func:`natural_residual_squares` (the same value, summed in another order), and the new
    iterate's arrays swapped with the last one's instead of copied. Without it the step and
    the measure are vectorised passes through work vectors, faster while they stay in the
    cache (docs/records/benchmarks.md).

    Returns
    -------
    best, best_residual, history (one residual per check), status (0 converged,
    1 max_iter, 2 diverged), iterations, products, Lipschitz estimate, last offset ``b``.
    """
    n = b.size
    b = b.copy()
    rms = 1.0 / np.sqrt(max(n, 1))
    x_old, wx_old, y, wy, x, wx, best, history = loop_arrays(
        indptr, indices, values, t_indptr, t_indices, t_values, scratch, z0, max_iter)
    work = 0 if streaming else n
    trial = np.empty(work)
    projected = np.empty(work)
    gradient = np.empty(work)
    best_residual, first = np.inf, -1.0
    products, theta, status, iterations, checks = 1, 1.0, 1, max_iter, 0
    for k in range(max_iter):
        while True:
            if streaming:
                projected_step(y, wy, b, lipschitz, lower, upper, box_rows, cone_n, cone_t,
                               cone_mu, cone_union, x)
            else:
                step = 1.0 / lipschitz
                for i in range(n):
                    trial[i] = y[i] - (wy[i] + b[i]) * step
                project_cones(trial, lower, upper, cone_n, cone_t, cone_mu, cone_union, x)
            apply_operator(indptr, indices, values, t_indptr, t_indices, t_values, scratch, x, wx)
            products += 1
            num, den, uphill = step_sums(x, y, wx, wy, b, x_old)
            if sufficient_decrease(num, den, lipschitz):
                break
            lipschitz *= 2.0
        if k == 0 or k == max_iter - 1 or (k + 1) % check_every == 0:
            if streaming:
                squares = natural_residual_squares(x, wx, b, base, every > 0, ratio, lower,
                                                   upper, box_rows, cone_n, cone_t, cone_mu,
                                                   cone_union)
            else:
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
                for i in range(n):
                    squares += (x[i] * ratio[i] - projected[i]) ** 2
            best_residual, first, code = record_residual(checks, np.sqrt(squares) * rms, x,
                                                         history, best, best_residual, first,
                                                         tol, divergence)
            checks += 1
            if code >= 0:
                status, iterations = code, k + 1
                break
        if every > 0 and (k + 1) % every == 0:
            for c in range(cone_n.size):
                b[cone_n[c]] = base[cone_n[c]] + cone_mu[c] * abs(wx[cone_t[c]] + b[cone_t[c]])
        if streaming:                   # each call with a constant flag: a loop without a branch
            theta = extrapolate(theta, uphill, x, wx, x_old, wx_old, y, wy, False)
            x, x_old = x_old, x
            wx, wx_old = wx_old, wx
        else:
            theta = extrapolate(theta, uphill, x, wx, x_old, wx_old, y, wy, True)
        lipschitz *= 0.9
    return best, best_residual, history[:checks], status, iterations, products, lipschitz, b


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
    holds every contact sharing a body with it. After ``r_i`` changes by ``delta``, with
    ``tracked``, ``state += delta x (row i of F^T)`` keeps ``state = F r`` (nothing to do when
    ``state`` is ``r`` itself).

    The products with a row and the updates are written out in the loops: compiled helpers
    called per row with the arrays as arguments, even inlined, made a sweep four times as long
    (2.2 against 0.52 ms at 51 800 rows, a 12 000-grain gluey step).
    """
    for _ in range(sweeps):
        for k in range(box_rows.size):
            i = box_rows[k]
            diagonal = box_diagonal[k]
            if diagonal <= 0.0:
                continue
            u = 0.0                                             # (W r)_i
            for e in range(indptr[i], indptr[i + 1]):
                u += values[e] * state[indices[e]]
            new = min(max(r[i] - (u + q[i]) / diagonal, lower[i]), upper[i])
            change = new - r[i]
            r[i] = new
            if tracked and change != 0.0:
                for e in range(indptr[i], indptr[i + 1]):
                    state[indices[e]] += values[e] * change
        for j in range(cone_n.size):
            n, t = cone_n[j], cone_t[j]
            a, c, c2, d = local[j, 0], local[j, 1], local[j, 2], local[j, 3]
            u_n = u_t = 0.0                                     # (W r)_n, (W r)_t
            for e in range(indptr[n], indptr[n + 1]):
                u_n += values[e] * state[indices[e]]
            for e in range(indptr[t], indptr[t + 1]):
                u_t += values[e] * state[indices[e]]
            b_n = u_n + q[n] - a * r[n] - c * r[t]
            b_t = u_t + q[t] - c2 * r[n] - d * r[t]
            new_n, new_t = local_coulomb_2d(a, c, c2, d, b_n, b_t, cone_mu[j], unilateral[j],
                                            r[n], r[t])
            change_n, change_t = new_n - r[n], new_t - r[t]
            r[n], r[t] = new_n, new_t
            if tracked and change_n != 0.0:
                for e in range(indptr[n], indptr[n + 1]):
                    state[indices[e]] += values[e] * change_n
            if tracked and change_t != 0.0:
                for e in range(indptr[t], indptr[t + 1]):
                    state[indices[e]] += values[e] * change_t


# -- newton-ac: the Newton phase of a 2D problem ---------------------------------------------
# On a problem of a few tens of rows a Newton iteration written with numpy is some forty array
# calls (the Alart-Curnier residual, the rows of the generalised Jacobian, the LU of the Newton
# system's block, the line search's residuals, the FCLIB error), 100-300 us, where the arithmetic
# takes a few. newton_phase_2d runs the iterations of one phase (newton._newton_phase), and the
# proximal loop's solved subproblems after it (newton.CHAINED_SUBPROBLEMS), with the same rules:
# the regularisations of a singular active block, the non-monotone Armijo line search, the
# steepest-descent direction where Newton's gives no decrease, the stopping tests and the best
# iterate. Its formulas are those of newton.AlartCurnier and metrics.coulomb_error written per row
# for 2D contacts (one tangential row each); the tests hold each to its numpy twin. Its Newton
# system is reduced to the rows of diag(rho) (W + sigma I) (fold_sliding_rows_2d: the sliding rows
# eliminated, as on the sparse lane, where reduced_newton_system_2d assembles that system and
# sparse_jacobian_rows_2d the Jacobian's rows, for the steepest-descent direction).
#
# Arguments (n rows, nf frictional contacts; AlartCurnier's attributes, normalised units):
# W (n, n), the dense Delassus matrix (indptr, indices, data: its CSR arrays on the sparse
# lane); q (n,), the offset without the shift; rho (n,), the step of each row; lower, upper
# (n,), the box bounds; box (n,) bool, the box rows; cone_n, cone_t (nf,), the normal and
# tangential row of each frictional contact; cone_mu (nf,); unilateral (nf,) bool (COULOMB;
# False: UNION, a bilateral normal row); sigma, center (n,), the proximal weight and centre;
# q_scale, 1 + |q|; forces, velocity (W r + q), phi, y: (n,).

FAILED_CODE, MAX_ITER_CODE, CONVERGED_CODE = 0, 1, 2
"""Status codes of :func:`newton_phase_2d` (``newton.FAILED``, ``MAX_ITER``, ``CONVERGED``)."""


@numba.njit(cache=True)
def contact_steps(diagonal, tangential, tangent_dim):
    """Each row's step ``rho = 1 / W_nn`` of its contact, ``W_nn`` floored at ``1e-12`` of the
    largest (normal rows, then ``tangent_dim`` rows per contact of ``tangential``), and the
    median ``W_nn`` (1 without contacts), from the normal rows' diagonal of ``W``, shape (nc,)
    (:func:`~lubcontact.solvers.newton.contact_steps`; in numpy its dozen array operations took
    15 us of a 6-contact solve, line by line over settling steps, against 5 us compiled)."""
    count = diagonal.size
    largest = 0.0
    for contact in range(count):
        largest = max(largest, diagonal[contact])
    floor = 1e-12 * (largest if largest > 0 else 1.0)
    rho = np.empty(count + tangential.size * tangent_dim)
    for contact in range(count):
        rho[contact] = 1.0 / max(diagonal[contact], floor)
    row = count
    for contact in tangential:
        for _ in range(tangent_dim):
            rho[row] = rho[contact]
            row += 1
    if count == 0:
        return rho, 1.0
    middle = count // 2               # the median by a partition: 0.32 ms at 25 000 contacts, 1.5 sorted
    parted = np.partition(diagonal, middle)
    typical = parted[middle] if count % 2 else 0.5 * (parted[:middle].max() + parted[middle])
    return rho, typical


@numba.njit(cache=True)
def product_2d(W, indptr, indices, values, x, offset, out):
    """``out = W x + offset``, ``W`` (n x n) dense, or by its rows in CSR arrays where
    ``indptr`` is not empty (:func:`compressed_rows`: the same sums, the zeros left out; a
    130-row ``W`` of a 40-grain pile, 6 % full, took 1.5 us against 12 us dense)."""
    if indptr.size == 0:
        for i in range(x.size):
            total = offset[i]
            for j in range(x.size):
                total += W[i, j] * x[j]
            out[i] = total
        return
    for i in range(x.size):
        total = offset[i]
        for e in range(indptr[i], indptr[i + 1]):
            total += values[e] * x[indices[e]]
        out[i] = total


@numba.njit(cache=True)
def compressed_rows(W):
    """The entries of a dense ``W`` (n x n) that are not zero, by rows: CSR arrays ``(indptr,
    indices, values)``, the indices 32-bit unsigned (as
    :func:`~lubcontact.solvers.compiled_apgd.csr_arrays` gives them)."""
    n = W.shape[0]
    indptr = np.zeros(n + 1, dtype=np.uint32)
    indices = np.empty(n * n, dtype=np.uint32)
    values = np.empty(n * n)
    count = 0
    for i in range(n):
        for j in range(n):
            if W[i, j] != 0.0:
                indices[count], values[count] = j, W[i, j]
                count += 1
        indptr[i + 1] = count
    return indptr, indices[:count].copy(), values[:count].copy()


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
def coulomb_residual_2d(forces, velocity, lower, upper, cone_n, cone_t, cone_mu, unilateral):
    """The vector whose norm is :func:`~lubcontact.problem.metrics.coulomb_error` of an unshifted
    problem (divided by ``1 + |q|``), from its velocity ``W r + q``, shape (n,): per row ``r``
    less its projection after the step by the velocity (de Saxce's for a frictional contact).
    A UNION contact (not ``unilateral``) is measured on its pushed piece where ``r_n >= 0``, on
    the pulled one (``n <= 0``, ``t = 0``) elsewhere."""
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
    return difference


@numba.njit(cache=True)
def coulomb_error_2d(forces, velocity, lower, upper, cone_n, cone_t, cone_mu, unilateral,
                     q_scale):
    """:func:`~lubcontact.problem.metrics.coulomb_error` of an unshifted problem from its
    velocity ``W r + q`` (:func:`coulomb_residual_2d`'s norm); ``q_scale`` is ``1 + |q|``."""
    difference = coulomb_residual_2d(forces, velocity, lower, upper, cone_n, cone_t, cone_mu,
                                     unilateral)
    total = 0.0
    for i in range(difference.size):
        total += difference[i] * difference[i]
    return np.sqrt(total) / q_scale


@numba.njit(cache=True)
def largest_squares(values, count):
    """The ``count`` rows of ``values`` (n,) with the largest squares and the share of the sum
    of squares they hold: ``(rows, share)``, the rows unsorted (``count`` <= n; among equal
    squares at the edge, those the pass meets first, but for the evictions of a heap). A
    min-heap of the rows kept, in one pass: ``np.argpartition`` on the squares took 0.9 ms on the
    60 000 rows of a 10 000-grain gluey step."""
    rows = np.empty(count, dtype=np.int64)
    heap = np.empty(count)
    total = 0.0
    for i in range(values.size):
        square = values[i] * values[i]
        total += square
        if i < count:                        # sift up
            k = i
            while k > 0:
                parent = (k - 1) // 2
                if heap[parent] <= square:
                    break
                heap[k], rows[k] = heap[parent], rows[parent]
                k = parent
            heap[k], rows[k] = square, i
        elif square > heap[0]:               # replaces the least kept; sift down
            k = 0
            while True:
                child = 2 * k + 1
                if child >= count:
                    break
                if child + 1 < count and heap[child + 1] < heap[child]:
                    child += 1
                if heap[child] >= square:
                    break
                heap[k], rows[k] = heap[child], rows[child]
                k = child
            heap[k], rows[k] = square, i
    kept = 0.0
    for k in range(count):
        kept += heap[k]
    return rows, kept / total if total > 0.0 else 1.0


@numba.njit(cache=True)
def neighbourhood(indptr, indices, seeds, hops):
    """The rows within ``hops`` steps of the rows ``seeds`` in the pattern of a square matrix
    (CSR arrays ``indptr``, ``indices``; a step from row ``i`` reaches the columns of its
    entries), the seeds included, sorted."""
    n = indptr.size - 1
    inside = np.zeros(n, dtype=np.bool_)
    reached = np.empty(n, dtype=np.int64)
    count = 0
    for s in seeds:
        if not inside[s]:
            inside[s], reached[count] = True, s
            count += 1
    start = 0
    for _ in range(hops):
        end = count
        for k in range(start, end):
            i = reached[k]
            for e in range(indptr[i], indptr[i + 1]):
                j = indices[e]
                if not inside[j]:
                    inside[j], reached[count] = True, j
                    count += 1
        start = end
    return np.sort(reached[:count])


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
def is_plain_row(i, first_col, first_val, second_col):
    """Whether row ``i`` of ``G``, whose entries are ``first_val`` at ``first_col`` and one at
    ``second_col`` (or none where it is negative; :func:`generalised_jacobian_2d`'s arrays at
    ``i``), is the identity's, so that row ``i`` of ``J`` is a row of ``diag(rho) (W + sigma I)``:
    a box row inside its bounds, a pushed normal row or a sticking tangential row. Scalars, not
    the arrays: a compiled call per row with array arguments took ten times the loop's own time
    (0.54 against 0.06 ms over 25 600 active rows)."""
    return first_col == i and first_val == 1.0 and second_col < 0


@numba.njit(cache=True)
def plain_rows_2d(lower, upper, box, cone_n, cone_t, cone_mu, unilateral, y):
    """How many rows of ``J`` at ``y`` are rows of ``diag(rho) (W + sigma I)`` (:func:`is_plain_row`),
    without assembling them (the count of :func:`sparse_jacobian_rows_2d`)."""
    rows, first_col, first_val, second_col, _ = generalised_jacobian_2d(
        lower, upper, box, cone_n, cone_t, cone_mu, unilateral, y)
    plain = 0
    for i in rows:
        if is_plain_row(i, first_col[i], first_val[i], second_col[i]):
            plain += 1
    return plain


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
    ``(rows, J_indptr, J_indices, J_data, plain)``, the active rows (m,), the CSR arrays of
    their rows of ``J`` (m x n), columns unsorted in each row, and how many of them are rows of
    ``diag(rho) (W + sigma I)`` (:func:`is_plain_row`). A row of ``J`` is ``e_i`` plus at most
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
    count = plain = 0
    for a in range(m):
        i = rows[a]
        if is_plain_row(i, first_col[i], first_val[i], second_col[i]):
            plain += 1
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
    return rows, J_indptr, J_indices[:count], J_data[:count], plain


@numba.njit(cache=True)
def transposed_pattern(size, pointers, indices):
    """The pattern of the transpose of a square sparse matrix of ``size`` rows in compressed
    arrays (``pointers``, ``indices``: CSR gives CSC, and back), by a counting sort, the indices
    of each new row sorted and 32-bit: ``(pointers, indices)``."""
    count = pointers[size]
    new_pointers = np.zeros(size + 1, dtype=np.int32)
    for k in range(count):
        new_pointers[indices[k] + 1] += 1
    for a in range(size):
        new_pointers[a + 1] += new_pointers[a]
    filled = new_pointers[:-1].astype(np.int64)
    new_indices = np.empty(count, dtype=np.int32)
    for a in range(size):                       # in order: each new row's indices sorted
        for k in range(pointers[a], pointers[a + 1]):
            new_indices[filled[indices[k]]] = a
            filled[indices[k]] += 1
    return new_pointers, new_indices


@numba.njit(cache=True)
def fold_sliding_rows_2d(rows, first_col, first_val, second_col, second_val, phi):
    """Which active rows of a 2D Newton system ``J d = -phi`` are kept and which fold
    (:func:`reduced_newton_system_2d`), from :func:`generalised_jacobian_2d`'s arrays, and where
    each column of ``W`` goes in the reduced system.

    Returns
    -------
    tuple
        ``(kept, target, factor, outer, base, sliding, normal, slope)``: the plain rows (m,),
        sorted; per column ``j`` of ``W`` (n,): ``target``, the block's column it adds to (its
        own place in ``kept``, its normal row's for a sliding row, ``m`` (no column) for an
        identity row), ``factor``, what it is multiplied by there (1, ``mu s``, 0), and
        ``outer``, the known direction it multiplies on the right-hand side (0 for a kept row,
        ``base`` otherwise); the direction on the other rows (n,) ``base``: ``-phi`` on
        identity rows, ``c_t`` on the sliding rows ``sliding``, whose normal rows are
        ``normal`` and whose folded coefficients ``mu s`` are ``slope``. The maps let the
        builders add every entry of a row of ``W`` without a branch on its column's kind: with
        branches, half of them mispredicted, the sparse block took twice as long (2.4 against
        1.3 ms for 20 500 kept rows of a 12 000-grain gluey step). ``target`` is 32-bit, as the
        block's columns are: at 10^5 grains the block read a column's target at random places
        of 420 000, and with 64-bit targets it took 20 against 17 ms (docs/records/benchmarks.md,
        "the reduced block's column maps in 32 bits").
    """
    n = phi.size
    base = -phi
    position = np.full(n, -1)               # place in kept, or -1
    n_kept = n_sliding = 0
    for i in rows:
        if not is_plain_row(i, first_col[i], first_val[i], second_col[i]):
            base[i] = -phi[i] + second_val[i] * phi[second_col[i]]
            n_sliding += 1
        else:
            position[i] = n_kept
            n_kept += 1
    kept = np.empty(n_kept, dtype=np.int64)
    sliding = np.empty(n_sliding, dtype=np.int64)
    normal = np.empty(n_sliding, dtype=np.int64)
    slope = np.empty(n_sliding)
    target = np.full(n, n_kept, dtype=np.int32)
    factor = np.zeros(n)
    outer = base.copy()
    b = 0
    for i in rows:
        if position[i] >= 0:
            kept[position[i]] = i
            target[i], factor[i], outer[i] = position[i], 1.0, 0.0
        else:
            if position[second_col[i]] < 0:         # a sliding contact's normal row is plain
                raise ValueError("a sliding tangential row's normal row is not plain")
            sliding[b], normal[b], slope[b] = i, second_col[i], second_val[i]
            target[i], factor[i] = position[second_col[i]], second_val[i]
            b += 1
    return kept, target, factor, outer, base, sliding, normal, slope


@numba.njit(cache=True)
def reduced_block_2d(indptr, indices, data, rho, sigma, kept, target, factor, outer, hop_ptr,
                     hop_idx, back_ptr, back_idx, last_into, last_factor, last_slot, last_kept,
                     last_ptr, last_col, last_val):
    """The block ``B`` of the 2D Newton system ``J d = -phi`` reduced to its plain rows
    (:func:`is_plain_row`), with ``W`` in CSR form, from :func:`fold_sliding_rows_2d`'s
    ``kept``, ``target`` and ``factor``; each row taken from the last block's where none of the
    columns of ``W`` that it reads changed its fold.

    A 2D sliding tangential row ``t`` of a contact whose normal row is ``n`` has ``G``'s entries
    0 at ``(t, t)`` and ``mu s`` (``s`` the sliding sign) at ``(t, n)``; its normal row is plain
    (pushed, or bilateral), so ``J_t - mu s J_n = e_t - mu s e_n`` and ``d_t = mu s d_n + c_t``
    with ``c_t = -phi_t + mu s phi_n``: its column folds into the normal's. Every kept row is
    ``rho_i (W + sigma I)_i``: the block has ``W``'s entries on the kept rows, each folded
    column adding its sliding partner's (a contact's two rows of ``W`` share a pattern, but for
    entries that the product forming ``W`` left out as exact zeros: contacts at right angles on
    one grain), and its diagonal always stored. The right-hand side is
    ``-phi_i - rho_i (W outer)_i`` on the kept rows (:func:`fold_sliding_rows_2d`'s ``outer``,
    zero on them); where every row is read from ``W`` (below) ``(W outer)[kept]`` is read with
    them, else it is taken through ``W``'s factor (:func:`factor_rows_product`): on a dense dry
    flow reading the kept rows of ``W`` for it took twice as long.

    The rows of ``B`` without ``rho`` and ``sigma`` (``F``: ``W``'s kept rows, folded) are kept
    between calls (the ``last_`` arrays; empty at the first). Row ``i`` of ``F`` reads the
    columns ``j`` of ``W``'s row ``i``; it is the last one, its columns renumbered, where each
    such column folds into the same row with the same factor as at the last call. The rows that
    may read a changed column ``j`` are found in two hops: ``j``'s entries in ``hop`` (the rows
    of ``L^T``: the degrees of freedom of ``j``'s contact, ``W = L^T L``), then theirs in
    ``back`` (the rows of ``L``): rows of ``W``'s pattern and more, so no exact zero of ``W`` is
    missed. With ``hop_ptr`` empty every row is read from ``W`` and nothing is kept for the next
    call (``into`` and ``slot`` empty; ``B``'s values written at once in ``F``'s place, ``sigma``
    first in the diagonal's sum, as in the former kernel, which read every row): where most
    rows change from one Newton iteration to the next (gluey flows), the bookkeeping cost more
    than the rows saved (docs/records/benchmarks.md, "the reduced block's rows reused").

    Returns
    -------
    tuple
        ``(row_ptr, columns, values, outside)``: ``B`` (m x m) in CSR arrays, 32-bit, each row's
        columns once, its diagonal first, the others in ``W``'s order (the factorisation's
        permutation sorts them: :func:`permuted_columns`; transposed to CSC here first, the
        block took 0.42 ms more at 12 000 grains, 7 ms at 10^5); ``(W outer)[kept]`` (m,;
        empty where the rows are reused); then the state for the next call,
        ``(into, slot, folded)``: per column of ``W`` (n,) the system's row it folds into
        (-1 for none), per row its place in ``kept`` (-1 for none), and ``F``'s values (``F``
        has ``B``'s ``row_ptr`` and ``columns``). Where no row is read from ``W`` and ``kept``
        is the last call's, ``F``'s arrays are the last ones.
    """
    n, m = target.size, kept.size
    reuse = hop_ptr.size > 0
    slot = np.full(n if reuse else 0, -1, dtype=np.int32)
    into = np.full(n if reuse else 0, -1, dtype=np.int32)
    if reuse:
        for a in range(m):
            slot[kept[a]] = a
        for j in range(n):
            if target[j] < m:
                into[j] = kept[target[j]]
    fresh = np.ones(n, dtype=np.bool_)      # the rows read from W
    same_rows = False                       # kept as at the last call
    if reuse and last_into.size == n:
        fresh[:] = False
        for j in range(n):
            if into[j] != last_into[j] or factor[j] != last_factor[j]:
                for e in range(hop_ptr[j], hop_ptr[j + 1]):
                    k = hop_idx[e]
                    for f in range(back_ptr[k], back_ptr[k + 1]):
                        fresh[back_idx[f]] = True
        same_rows = last_kept.size == m
        for a in range(m):
            i = kept[a]
            fresh[i] = fresh[i] or last_slot[i] < 0
            same_rows = same_rows and last_kept[a] == i
    capacity = 0
    any_fresh = False
    for i in kept:
        if fresh[i]:
            capacity += indptr[i + 1] - indptr[i] + 1
            any_fresh = True
        else:
            capacity += last_ptr[last_slot[i] + 1] - last_ptr[last_slot[i]]
    shared = same_rows and not any_fresh    # F's arrays are the last ones
    if shared:
        row_ptr, columns, folded = last_ptr, last_col, last_val
    else:
        row_ptr = np.zeros(m + 1, dtype=np.int32)
        columns = np.empty(capacity, dtype=np.int32)
        folded = np.empty(capacity)
    scratch = np.zeros(m + 1)               # the last: where an identity row's entries go
    seen = np.full(m + 1, -1, dtype=np.int32)
    pattern = np.empty(m + 1, dtype=np.int32)
    # the last block's columns renumbered: a gather in an array of the last block's size
    renumbered = np.empty(0 if same_rows or not reuse else last_kept.size, dtype=np.int32)
    for c in range(renumbered.size):
        renumbered[c] = slot[last_kept[c]]
    outside = np.zeros(0 if reuse else m)
    count = 0
    for a in range(m):
        i = kept[a]
        if fresh[i]:
            seen[a], pattern[0] = a, a          # the diagonal, always stored
            seen[m] = a                         # never a column of the block
            if not reuse:                       # B's values at once: F is not kept
                scratch[a] = sigma
            size = 1
            total = 0.0
            for k in range(indptr[i], indptr[i + 1]):
                j = indices[k]
                if not reuse:
                    total += data[k] * outer[j]
                column = target[j]
                pattern[size] = column
                size += seen[column] != a
                seen[column] = a
                scratch[column] += data[k] * factor[j]
            scale = rho[i] if not reuse else 1.0
            for k in range(size):
                column = pattern[k]
                columns[count + k], folded[count + k] = column, scale * scratch[column]
                scratch[column] = 0.0
            if not reuse:
                outside[a] = total
        else:
            if shared:
                continue
            start = last_ptr[last_slot[i]]
            size = last_ptr[last_slot[i] + 1] - start
            for k in range(size):
                column = last_col[start + k]
                columns[count + k] = column if same_rows else renumbered[column]
                folded[count + k] = last_val[start + k]
        count += size
        row_ptr[a + 1] = count
    if not shared:
        # the buffers hold a row of W for each row read from it (four times the block on a
        # dense dry flow), and the factorisations kept hold the block
        columns, folded = columns[:count].copy(), folded[:count].copy()
    if not reuse:
        return row_ptr, columns, folded, outside, into, slot, folded
    values = np.empty(folded.size)
    for a in range(m):
        scale, first = rho[kept[a]], row_ptr[a]
        values[first] = scale * (folded[first] + sigma)
        for k in range(first + 1, row_ptr[a + 1]):
            values[k] = scale * folded[k]
    return row_ptr, columns, values, outside, into, slot, folded


@numba.njit(cache=True)
def carried_order(indptr, indices, rows, ordered_rows, positions, limit, partner):
    """The elimination order of ``factorisations.Factorisations`` carried to a block (its compressed
    pattern ``indptr``, ``indices``, by rows or by columns: symmetric; its rows ``rows`` of the
    system, sorted) from an ordered block (its rows ``ordered_rows``, sorted, at ``positions``
    in its order: a permutation of ``0 .. ordered_rows.size - 1``, SuperLU's ``perm_c``; a
    place beyond would write past the keys' counts, unchecked): the old rows in their order,
    each new row just after its contact's other row where that one is old (``partner``: per row
    of the system the other row of its contact, -1 for none; a row beyond its size has none),
    else just after the last of its old neighbours, one with neither at the end, ties by row.
    ``(order, True)``, ``order`` a permutation of ``0 .. m - 1`` (the block's rows); or
    ``(empty, False)`` when more than ``limit`` rows are new. By a counting sort on the keys
    ``2 p`` (an old row at ``p``) and ``2 p + 1`` (a new row after it): no comparison sort."""
    m, size = rows.size, ordered_rows.size
    key = np.empty(m, dtype=np.int64)
    new = 0
    k = 0
    for a in range(m):                          # both sorted: one merge
        while k < size and ordered_rows[k] < rows[a]:
            k += 1
        if k < size and ordered_rows[k] == rows[a]:
            key[a] = 2 * positions[k]
        else:
            key[a] = -1
            new += 1
    if new > limit:
        return np.empty(0, dtype=np.int64), False
    end = 2 * size
    old_key = key.copy()
    for a in range(m):
        if old_key[a] < 0:
            other = np.int64(partner[rows[a]]) if rows[a] < partner.size else -1
            found = np.searchsorted(ordered_rows, other) if other >= 0 else size
            if found < size and ordered_rows[found] == other:   # its contact's other row is old
                key[a] = 2 * positions[found] + 1
                continue
            last = -1
            for e in range(indptr[a], indptr[a + 1]):
                last = max(last, old_key[indices[e]])
            key[a] = last + 1 if last >= 0 else end
    start = np.zeros(end + 2, dtype=np.int64)
    for a in range(m):
        start[key[a] + 1] += 1
    for b in range(end + 1):
        start[b + 1] += start[b]
    order = np.empty(m, dtype=np.int64)
    for a in range(m):                          # in row order: stable
        order[start[key[a]]] = a
        start[key[a]] += 1
    return order, True


@numba.njit(cache=True)
def permuted_columns(indptr, indices, data, order):
    """``A[order][:, order]`` of a square ``A`` given by its rows (CSR arrays ``indptr``,
    ``indices``, ``data``; ``order`` a permutation of its rows) as CSC arrays with sorted 32-bit
    row indices (SuperLU's), and ``|A|_inf`` (the largest row sum of ``|a_ij|``, the static LU's
    backward error's scale): ``(pointers, indices, values, norm)``. One counting sort: the rows
    read in their new order write each column's entries in increasing row. Before, the block
    was transposed to CSC, permuted by a sort by new row then one by new column, and its norm
    taken by a ``bincount``: 1.86 ms a block against 1.19 (the median of 20 rounds over the 43
    blocks of three 12 000-grain gluey steps)."""
    m = order.size
    renumber = np.empty(m, dtype=np.int64)
    for c in range(m):
        renumber[order[c]] = c
    pointers = np.zeros(m + 1, dtype=np.int32)
    for e in range(indptr[m]):
        pointers[renumber[indices[e]] + 1] += 1
    for c in range(m):
        pointers[c + 1] += pointers[c]
    filled = pointers[:-1].astype(np.int64)
    rows = np.empty(indptr[m], dtype=np.int32)
    values = np.empty(indptr[m])
    norm = 0.0
    for r in range(m):                          # new row r, in order: each column's rows sorted
        i = order[r]
        total = 0.0
        for e in range(indptr[i], indptr[i + 1]):
            column = renumber[indices[e]]
            rows[filled[column]], values[filled[column]] = r, data[e]
            filled[column] += 1
            total += abs(data[e])
        norm = max(norm, total)
    return pointers, rows, values, norm


@numba.njit(cache=True)
def symmetrised_pattern(indptr, indices):
    """The part above the diagonal of ``A + A^T``'s pattern, ``A`` square in compressed arrays:
    column ``k`` holds the rows ``i < k`` with an entry at ``(i, k)`` or ``(k, i)``, once each
    (what :func:`~lubcontact.solvers.ordering.approximate_minimum_degree` reads)."""
    n = indptr.size - 1
    return grouped_pattern(indptr, indices, np.arange(n), n)


@numba.njit(cache=True)
def grouped_pattern(indptr, indices, group, n_groups):
    """The part above the diagonal of the pattern of ``A + A^T``'s groups of rows, ``A`` square in
    compressed arrays, ``group`` each row's group (``0 .. n_groups - 1``): column ``h`` holds the
    groups ``g < h`` with an entry of ``A + A^T`` in a row of one and a column of the other,
    once each (what :func:`~lubcontact.solvers.ordering.grouped_minimum_degree` reads;
    :func:`symmetrised_pattern`: a group a row)."""
    n = indptr.size - 1
    pointers = np.zeros(n_groups + 1, dtype=np.int64)
    for j in range(n):                                  # entry (r, j) goes to column max(g_r, g_j)
        g = group[j]
        for e in range(indptr[j], indptr[j + 1]):
            h = group[indices[e]]
            if h != g:
                pointers[max(h, g) + 1] += 1
    for k in range(n_groups):
        pointers[k + 1] += pointers[k]
    rows = np.empty(pointers[n_groups], dtype=np.int64)
    filled = pointers[:-1].copy()
    for j in range(n):
        g = group[j]
        for e in range(indptr[j], indptr[j + 1]):
            h = group[indices[e]]
            if h != g:
                column = max(h, g)
                rows[filled[column]] = min(h, g)
                filled[column] += 1
    mark = np.full(n_groups, -1, dtype=np.int64)
    count = 0
    for k in range(n_groups):                           # each group once: compacted in place
        start, pointers[k] = pointers[k], count
        for e in range(start, filled[k]):
            if mark[rows[e]] != k:
                mark[rows[e]] = k
                rows[count] = rows[e]
                count += 1
    pointers[n_groups] = count
    return pointers, rows[:count]


@numba.njit(cache=True)
def contact_groups(rows, partner):
    """The rows of a block (``rows``: rows of the system, sorted) grouped by contact: a row and
    its contact's other row (``partner``: per row of the system, -1 for none; a row beyond its
    size has none) in one group where both are in the block, every other row a group of its
    own. Returns ``(group, weights)``: each row's group (m,), numbered in the order of their
    first rows, and the rows in each group (int32)."""
    m = rows.size
    group = np.empty(m, dtype=np.int64)
    weights = np.zeros(m, dtype=np.int32)
    count = 0
    for a in range(m):
        other = np.int64(partner[rows[a]]) if rows[a] < partner.size else -1
        b = np.searchsorted(rows, other) if 0 <= other < rows[a] else m
        if b < m and rows[b] == other:                  # its contact's other row came first
            group[a] = group[b]
        else:
            group[a] = count
            count += 1
        weights[group[a]] += 1
    return group, weights[:count].copy()


@numba.njit(cache=True)
def static_pattern(indptr, indices):
    """Patterns that hold ``L`` and ``U`` in ``A = L U`` without pivoting, ``A`` square in
    compressed arrays: ``L``'s is the Cholesky factor's of ``A + A^T``'s pattern, ``U``'s its
    transpose. The reduced Newton blocks are symmetric in pattern but where ``W`` stores an
    entry and not its mirror (a product that came out exactly 0: contacts at right angles on
    one grain, a lattice). Column ``j`` of ``L`` holds ``j``, the rows below it of column ``j``
    and of row ``j`` of ``A``, and the rows but ``j`` of its children's columns in the
    elimination tree, each once: one pass over the columns in order, each reading its
    children's columns written before it, its parent the least row below ``j`` it holds (the
    tree found on the way: a pass of its own before, by Liu's algorithm, made them 1.5-1.6x
    slower, 2.5-2.6 against 1.55-1.7 ms on 12 000-grain gluey blocks; walking the tree's row
    subtrees twice instead, to count then to place, which sorts the rows, took a fifth longer
    than that pass: docs/records/benchmarks.md). Returns ``(L_indptr, L_indices, U_indptr,
    U_indices, paired)``, CSC: ``L``'s diagonal first in each column, then its parent (the
    least row below the diagonal) but in the second column of a pair, the other rows unordered
    (the factorisation and the solves scatter a column whatever its order); ``U``'s rows sorted,
    its diagonal last; ``paired`` (n,) True at the first column ``j`` of each pair ``j, j + 1``
    whose rows below ``j + 1`` are the same, in the same order (a supernode of two columns, as a
    contact's two rows ordered together make: :func:`contact_groups`), found on the way: column
    ``j + 1`` takes its child ``j``'s rows first, and holds no others. The pairs do not overlap
    (a pair's second column is no pair's first)."""
    n = indptr.size - 1
    row_ptr, row_idx = transposed_pattern(n, indptr, indices)
    first_child = np.full(n, -1, dtype=np.int64)          # each column's children, in order
    last_child = np.full(n, -1, dtype=np.int64)
    next_child = np.full(n, -1, dtype=np.int64)
    lower_ptr = np.zeros(n + 1, dtype=np.int64)
    lower_idx = np.empty(2 * (indptr[n] + n), dtype=np.uint32)   # unsigned: no wrap-around checks
    mark = np.full(n, -1, dtype=np.int64)
    paired = np.zeros(n, dtype=np.bool_)
    size = 0
    for j in range(n):
        most = size + 1 + indptr[j + 1] - indptr[j] + row_ptr[j + 1] - row_ptr[j]
        c = first_child[j]
        while c != -1:
            most += lower_ptr[c + 1] - lower_ptr[c]
            c = next_child[c]
        if most > lower_idx.size:                       # room for this column at worst
            grown = np.empty(max(2 * lower_idx.size, most), dtype=np.uint32)
            grown[:size] = lower_idx[:size]
            lower_idx = grown
        mark[j] = j
        lower_idx[size] = j
        size += 1
        parent = n
        at = -1                                         # where the parent is written
        # a child j - 1 first (j is right after its diagonal, but where j - 1 ends a pair): a
        # pair's rows line up
        before = j - 1 if j > 0 and last_child[j] == j - 1 and not (j > 1 and paired[j - 2]) else -1
        if before >= 0:
            for q in range(lower_ptr[before] + 2, lower_ptr[j]):
                i = np.int64(lower_idx[q])
                mark[i], lower_idx[size] = j, i
                if i < parent:
                    parent, at = i, size
                size += 1
        for e in range(indptr[j], indptr[j + 1]):           # column j of A, then row j
            i = np.int64(indices[e])
            if i > j and mark[i] != j:
                mark[i], lower_idx[size] = j, i
                if i < parent:
                    parent, at = i, size
                size += 1
        for e in range(row_ptr[j], row_ptr[j + 1]):
            i = np.int64(row_idx[e])
            if i > j and mark[i] != j:
                mark[i], lower_idx[size] = j, i
                if i < parent:
                    parent, at = i, size
                size += 1
        c = first_child[j]
        while c != -1:
            if c != before:
                for q in range(lower_ptr[c] + 1, lower_ptr[c + 1]):
                    i = np.int64(lower_idx[q])
                    if i != j and mark[i] != j:
                        mark[i], lower_idx[size] = j, i
                        if i < parent:
                            parent, at = i, size
                        size += 1
            c = next_child[c]
        lower_ptr[j + 1] = size
        # with nothing but j - 1's rows (L_j holds at least those), j - 1 and j are a pair
        if before >= 0:
            paired[before] = size - lower_ptr[j] == lower_ptr[j] - lower_ptr[before] - 1
        if at >= 0 and not (j > 0 and paired[j - 1]):  # the parent right after the diagonal
            lower_idx[at], lower_idx[lower_ptr[j] + 1] = lower_idx[lower_ptr[j] + 1], parent
        if parent < n:                                  # j joins its parent's children
            if first_child[parent] == -1:
                first_child[parent] = j
            else:
                next_child[last_child[parent]] = j
            last_child[parent] = j
    if size >= 2**31:
        raise ValueError("static_pattern: more than 2^31 entries in L (32-bit pointers of U)")
    lower_idx = lower_idx[:size].copy()
    upper_ptr, upper_idx = transposed_pattern(n, lower_ptr, lower_idx)
    return lower_ptr, lower_idx, upper_ptr, upper_idx, paired


@numba.njit(cache=True)
def static_lu(indptr, indices, data, lower_ptr, lower_idx, upper_ptr, upper_idx, paired):
    """``A = L U`` without pivoting on the patterns of :func:`static_pattern` (left-looking:
    column ``j`` of ``U`` by the triangular solve with the columns of ``L`` before it, in
    increasing order; the two columns of a pair, ``paired``, in one pass over their rows: on the
    blocks of 10 000-grain gluey steps ordered by contacts, 0.85 of the time with one pass a
    column, docs/records/benchmarks.md, "the static LU by pairs of columns"; ``paired`` is
    trusted as :func:`static_pattern` gives it: a pair's rows below its second column the same,
    in the same order). Returns
    ``(L_values, U_values, failed)``: ``failed`` is the first column whose pivot is below
    ``1e-14`` times ``A``'s largest entry in magnitude, or -1."""
    n = indptr.size - 1
    lower_val = np.empty(lower_idx.size)
    upper_val = np.empty(upper_idx.size)
    work = np.zeros(n)
    largest = 0.0
    for e in range(indptr[n]):
        largest = max(largest, abs(data[e]))
    for j in range(n):
        for e in range(indptr[j], indptr[j + 1]):
            work[indices[e]] += data[e]                 # entries stored twice summed
        last = upper_ptr[j + 1] - 1                     # U's diagonal
        e = upper_ptr[j]
        while e < last:
            k = upper_idx[e]
            if paired[k] and e + 1 < last:              # k + 1 is next: its rows are k's
                first, second = lower_ptr[k], lower_ptr[k + 1]
                value = work[k]
                following = work[k + 1] - lower_val[first + 1] * value if value != 0.0 else work[k + 1]
                upper_val[e], upper_val[e + 1] = value, following
                work[k], work[k + 1] = 0.0, 0.0
                if value != 0.0 or following != 0.0:
                    for q in range(1, lower_ptr[k + 2] - second):
                        work[lower_idx[second + q]] -= (lower_val[first + 1 + q] * value
                                                        + lower_val[second + q] * following)
                e += 2
                continue
            value = work[k]
            upper_val[e], work[k] = value, 0.0
            if value != 0.0:
                for q in range(lower_ptr[k] + 1, lower_ptr[k + 1]):
                    work[lower_idx[q]] -= lower_val[q] * value
            e += 1
        pivot = work[j]
        upper_val[last], work[j] = pivot, 0.0
        if not abs(pivot) > 1e-14 * largest:
            return lower_val, upper_val, j
        lower_val[lower_ptr[j]] = 1.0
        for q in range(lower_ptr[j] + 1, lower_ptr[j + 1]):
            lower_val[q] = work[lower_idx[q]] / pivot
            work[lower_idx[q]] = 0.0
    return lower_val, upper_val, -1


@numba.njit(cache=True)
def static_lu_solve(lower_ptr, lower_idx, lower_val, upper_ptr, upper_idx, upper_val, rhs):
    """``x`` with ``L U x = rhs`` from :func:`static_lu`'s factors (``L`` unit lower, its
    diagonal first in each column; ``U``'s diagonal last)."""
    n = rhs.size
    x = rhs.copy()
    for j in range(n):
        value = x[j]
        if value != 0.0:
            for q in range(lower_ptr[j] + 1, lower_ptr[j + 1]):
                x[lower_idx[q]] -= lower_val[q] * value
    for j in range(n - 1, -1, -1):
        last = upper_ptr[j + 1] - 1
        x[j] /= upper_val[last]
        value = x[j]
        if value != 0.0:
            for e in range(upper_ptr[j], last):
                x[upper_idx[e]] -= upper_val[e] * value
    return x


@numba.njit(cache=True)
def lu_solve(transposed, rhs):
    """``A x = rhs`` by LAPACK's LU with partial pivoting (``gesv``), given ``transposed`` =
    ``A^T`` in C order (``A`` in LAPACK's column order), which it may overwrite; ``(x, ok)`` with
    ``ok`` False where a pivot is exactly zero.

    LAPACK is 2-6x faster than a plain compiled LU from 50 to 300 rows (35 against 120 us at
    100 rows, 475 against 2 860 at 300; docs/records/benchmarks.md)."""
    m = rhs.size
    x = rhs.copy()
    if m == 0:
        return x, True
    transposed = np.ascontiguousarray(transposed)   # LAPACK reads the memory: C order, no strides
    pivots = np.empty(m, dtype=_LAPACK_INT)
    info = _GESV(_DOUBLE, m, 1, transposed.ctypes, m, pivots.ctypes, x.ctypes, m)
    return x, info == 0


@numba.njit(cache=True)
def static_block_solve(row_ptr, columns, values, rhs, order, backward_error):
    """``B x = rhs``, ``B`` (m x m) by its rows (CSR arrays, as :func:`reduced_block_2d` gives
    it), by the LU without pivoting of ``B[order][:, order]`` (``order`` a permutation of its
    rows; :func:`permuted_columns`, :func:`static_pattern`, :func:`static_lu`): ``(x, ok)``,
    ``ok`` False where a pivot is below :func:`static_lu`'s bound or the solve's normwise
    backward error ``|B x - rhs|_inf / (|B|_inf |x|_inf + |rhs|_inf)`` is above
    ``backward_error`` (as :class:`~lubcontact.solvers.factorisations.StaticLU` checks it)."""
    m = rhs.size
    x = np.zeros(m)
    pointers, rows, entries, norm = permuted_columns(row_ptr, columns, values, order)
    lower_ptr, lower_idx, upper_ptr, upper_idx, paired = static_pattern(pointers, rows)
    lower_val, upper_val, failed = static_lu(pointers, rows, entries, lower_ptr, lower_idx,
                                             upper_ptr, upper_idx, paired)
    if failed >= 0:
        return x, False
    permuted = np.empty(m)
    for c in range(m):
        permuted[c] = rhs[order[c]]
    solved = static_lu_solve(lower_ptr, lower_idx, lower_val, upper_ptr, upper_idx, upper_val,
                             permuted)
    for c in range(m):
        x[order[c]] = solved[c]
    return x, solve_is_accurate(pointers, rows, entries, norm, solved, permuted, backward_error)


@numba.njit(cache=True)
def solve_is_accurate(pointers, rows, values, norm, x, rhs, bound):
    """Whether ``x`` solves ``A x = rhs`` with a normwise backward error ``|A x - rhs|_inf /
    (|A|_inf |x|_inf + |rhs|_inf)`` of at most ``bound``, ``A`` square in CSC arrays and
    ``norm`` its ``|A|_inf``: the test of a static LU's solve (no pivoting: small pivots can
    amplify rounding where a pivoting LU would not; an ill-conditioned block's residual is
    large either way)."""
    residual = -rhs
    for c in range(x.size):
        for e in range(pointers[c], pointers[c + 1]):
            residual[rows[e]] += values[e] * x[c]
    largest = solution = given = 0.0
    for i in range(x.size):
        largest = max(largest, abs(residual[i]))
        solution = max(solution, abs(x[i]))
        given = max(given, abs(rhs[i]))
    return largest <= bound * (norm * solution + given)


@numba.njit(cache=True)
def reduced_dense_block_2d(W, rho, sigma, phi, kept, target, factor, outer):
    """The block and right-hand side of :func:`reduced_newton_system_2d` with ``W`` dense:
    ``(transposed, rhs)``, ``B^T`` (m x m, C order: ``B`` in LAPACK's column order, as
    :func:`lu_solve` takes it) and ``rhs`` (m,), from :func:`fold_sliding_rows_2d`'s arrays."""
    n, m = phi.size, kept.size
    transposed = np.zeros((m + 1, m))       # the last row: where an identity row's entries go
    rhs = np.empty(m)
    for a in range(m):
        i = kept[a]
        outside = 0.0                           # W_i base on the columns not kept
        for j in range(n):
            weight = W[i, j]
            outside += weight * outer[j]
            transposed[target[j], a] += rho[i] * (weight * factor[j])
        transposed[a, a] += rho[i] * sigma
        rhs[a] = -phi[i] - rho[i] * outside
    return transposed[:m], rhs


@numba.njit(cache=True)
def newton_direction_2d(W, w_arrays, rho, lower, upper, box, cone_n, cone_t, cone_mu, unilateral,
                        sigma, y, phi, regularisations, places, backward_error):
    """:func:`~lubcontact.solvers.newton._newton_direction` at ``y`` on a small problem, the
    system reduced to its plain rows as on the sparse lane (:func:`reduced_block_2d`; a block
    ``delta``-regularised is shifted on those rows only): ``(direction, ok)``. ``W`` is given
    dense, and by its rows (``w_arrays``, :func:`compressed_rows`) with ``places`` (n,), each
    row's place in an elimination order of ``W``; both empty on the smallest problems.

    With them, the block is assembled from ``W``'s rows and solved by
    :func:`static_block_solve` with its rows in that order (a principal block eliminated in the
    order of the whole has no more fill than the whole); by LAPACK's dense LU
    (:func:`reduced_dense_block_2d`, :func:`lu_solve`) where that fails or without them."""
    rows, first_col, first_val, second_col, second_val = generalised_jacobian_2d(
        lower, upper, box, cone_n, cone_t, cone_mu, unilateral, y)
    kept, target, factor, outer, direction, sliding, normal, slope = fold_sliding_rows_2d(
        rows, first_col, first_val, second_col, second_val, phi)
    m = kept.size
    order = np.empty(m if places.size else 0, dtype=np.int64)
    if places.size:                             # the kept rows by their place
        position = np.full(places.size, -1, dtype=np.int64)
        for a in range(m):
            position[places[kept[a]]] = a
        count = 0
        for p in range(places.size):
            if position[p] >= 0:
                order[count] = position[p]
                count += 1
    solved_any = m == 0
    for delta in regularisations:
        if solved_any:
            break
        ok = False
        if order.size:
            hops, last, last_values = np.empty(0, dtype=np.uint32), \
                np.empty(0, dtype=np.int32), np.empty(0)   # every row read, none kept
            row_ptr, columns, values, outside, _, _, _ = reduced_block_2d(
                *w_arrays, rho, sigma, kept, target, factor, outer, hops, hops, hops, hops,
                last, last_values, last, np.empty(0, dtype=np.int64), last, last, last_values)
            rhs = np.empty(m)
            for a in range(m):
                values[row_ptr[a]] += delta      # the diagonal, first in each row
                rhs[a] = -phi[kept[a]] - rho[kept[a]] * outside[a]
            solved, ok = static_block_solve(row_ptr, columns, values, rhs, order, backward_error)
        if not ok:
            transposed, rhs = reduced_dense_block_2d(W, rho, sigma, phi, kept, target, factor,
                                                     outer)       # lu_solve overwrites it
            for a in range(m):
                transposed[a, a] += delta
            solved, ok = lu_solve(transposed, rhs)
        if ok and np.all(np.isfinite(solved)):
            direction[kept] = solved
            solved_any = True
    if not solved_any:
        return direction, False
    for b in range(sliding.size):
        direction[sliding[b]] += slope[b] * direction[normal[b]]
    return direction, True


@numba.njit(cache=True, inline="always")
def steepest_descent_2d(W, rho, lower, upper, box, cone_n, cone_t, cone_mu, unilateral, sigma, y,
                        phi):
    """The steepest-descent direction ``-J^T phi`` of the merit ``|phi|^2 / 2`` at ``y`` (``J``'s
    inactive rows the identity's, its active rows :func:`jacobian_rows_2d`'s) and its slope
    ``|J^T phi|^2``: :func:`newton_phase_2d`'s step where Newton's direction is not taken."""
    n = phi.size
    rows, J = jacobian_rows_2d(W, rho, lower, upper, box, cone_n, cone_t, cone_mu, unilateral,
                               sigma, y)
    gradient = phi.copy()
    gradient[rows] = 0.0
    for a in range(rows.size):
        weight = phi[rows[a]]
        for j in range(n):
            gradient[j] += J[a, j] * weight
    slope = 0.0
    for j in range(n):
        slope += gradient[j] * gradient[j]
    return -gradient, slope


@numba.njit(cache=True, inline="always")
def backtracked_2d(W, w_arrays, rho, lower, upper, cone_n, cone_t, cone_mu, unilateral, sigma,
                   center, forces, velocity, direction, slope, reference, armijo, max_halvings,
                   trial, trial_velocity, trial_phi, trial_y, change, zeros):
    """:func:`newton_phase_2d`'s line search along ``direction`` (decrease rate ``slope`` of the
    merit): from the full step, halved until the merit is at most ``reference - armijo alpha
    slope`` (the non-monotone Armijo bound), at most ``max_halvings`` trials. Whether a trial
    passed; the last one's forces, velocity ``v + alpha W d``, ``phi`` and ``y`` in ``trial``,
    ``trial_velocity``, ``trial_phi`` and ``trial_y`` (``change`` holds ``W d``; ``zeros``, n
    zeros, the product's offset)."""
    if not slope > 0.0:
        return False
    n = forces.size
    product_2d(W, *w_arrays, direction, zeros, change)      # a trial's velocity: v + alpha W d
    alpha = 1.0
    for _ in range(max_halvings):
        for j in range(n):
            trial[j] = forces[j] + alpha * direction[j]
            trial_velocity[j] = velocity[j] + alpha * change[j]
        value = alart_curnier_2d(rho, lower, upper, cone_n, cone_t, cone_mu, unilateral, sigma,
                                 center, trial, trial_velocity, trial_phi, trial_y)
        if value <= reference - armijo * alpha * slope:
            return True
        alpha *= 0.5
    return False


@numba.njit(cache=True)
def newton_phase_2d(W, w_arrays, q, rho, lower, upper, box, cone_n, cone_t, cone_mu, unilateral,
                    sigma, center, q_scale, forces, tol, max_iter, inner_tol, regularisations,
                    places, backward_error, memory, armijo, max_halvings, total_iter, chain_until,
                    decrease, sigma_floor, reduction):
    """Newton iterations from ``forces`` until the FCLIB error is below ``tol``, ``|phi| <=
    inner_tol``, a failed line search or ``max_iter`` (:func:`newton._newton_phase`); then, while
    the subproblem was solved (``|phi| <= inner_tol``), the proximal loop's next subproblems in
    the same call, by its rule after a solved one (:func:`newton._proximal_newton`): centred at
    the last iterate, the weight divided by ``decrease`` down to ``sigma_floor``, ``inner_tol``
    ``reduction`` times the centre's FCLIB error times ``q_scale``; each of at most ``max_iter``
    iterations, until ``total_iter`` iterations in all, the FCLIB error below ``tol``, one not
    solved or ``chain_until`` iterations (0: one subproblem). A next subproblem solved at its
    centre, with no iteration to make, is left to the proximal loop.

    Returns
    -------
    tuple
        ``(best, best_error, last, last_error, iterations, gradient_steps, code, history,
        solved, sigma, subproblems, centre_error, overall, overall_error)``: the last
        subproblem's best iterate and its FCLIB error, the last iterate and its error, the
        iterations, the steepest-descent steps, a status code (:data:`CONVERGED_CODE`, ...),
        the FCLIB error of each iterate (the start first), whether the last subproblem was
        solved, its weight, the subproblems, the FCLIB error at the last one's centre, and the
        best iterate of all and its error.

    ``W``, ``w_arrays``, ``places`` and ``backward_error``: as :func:`newton_direction_2d`
    takes them (the products ``W x`` by :func:`product_2d`, by rows where ``w_arrays`` holds
    them).
    """
    n = forces.size
    forces, center = forces.copy(), center.copy()
    phi, y, velocity = np.empty(n), np.empty(n), np.empty(n)
    product_2d(W, *w_arrays, forces, q, velocity)
    merit = alart_curnier_2d(rho, lower, upper, cone_n, cone_t, cone_mu, unilateral, sigma,
                             center, forces, velocity, phi, y)
    recent = np.full(memory, -np.inf)
    recent[0] = merit
    count = 1
    error = coulomb_error_2d(forces, velocity, lower, upper, cone_n, cone_t, cone_mu, unilateral,
                             q_scale)
    total_iter = max(total_iter, max_iter)
    history = np.empty(total_iter + 1)
    history[0] = error
    best, best_error = forces.copy(), error
    overall, overall_error = forces.copy(), error
    centre_error = error
    iterations = gradient_steps = subproblem_iterations = 0
    subproblems = 1
    code = MAX_ITER_CODE
    trial, trial_phi, trial_y = np.empty(n), np.empty(n), np.empty(n)
    change, trial_velocity, zeros = np.empty(n), np.empty(n), np.zeros(n)
    while True:
        while error > tol and subproblem_iterations < max_iter and iterations < total_iter \
                and np.sqrt(2.0 * merit) > inner_tol:
            iterations += 1
            subproblem_iterations += 1
            reference = recent.max()
            direction, ok = newton_direction_2d(W, w_arrays, rho, lower, upper, box, cone_n, cone_t,
                                                cone_mu, unilateral, sigma, y, phi, regularisations,
                                                places, backward_error)
            accepted = ok and backtracked_2d(W, w_arrays, rho, lower, upper, cone_n, cone_t, cone_mu,
                                             unilateral, sigma, center, forces, velocity, direction,
                                             2.0 * merit, reference, armijo, max_halvings, trial,
                                             trial_velocity, trial_phi, trial_y, change, zeros)
            if not accepted:                    # steepest descent
                direction, slope = steepest_descent_2d(W, rho, lower, upper, box, cone_n, cone_t,
                                                       cone_mu, unilateral, sigma, y, phi)
                gradient_steps += 1
                accepted = backtracked_2d(W, w_arrays, rho, lower, upper, cone_n, cone_t, cone_mu,
                                          unilateral, sigma, center, forces, velocity, direction,
                                          slope, reference, armijo, max_halvings, trial,
                                          trial_velocity, trial_phi, trial_y, change, zeros)
            if not accepted:
                code = FAILED_CODE
                break
            forces[:] = trial
            product_2d(W, *w_arrays, forces, q, velocity)            # W r afresh: no drift
            merit = alart_curnier_2d(rho, lower, upper, cone_n, cone_t, cone_mu, unilateral, sigma,
                                     center, forces, velocity, phi, y)
            recent[count % memory] = merit        # the last `memory` merits, in a ring
            count += 1
            error = coulomb_error_2d(forces, velocity, lower, upper, cone_n, cone_t, cone_mu,
                                     unilateral, q_scale)
            history[iterations] = error
            if error < best_error:
                best[:], best_error = forces, error
            if error < overall_error:
                overall[:], overall_error = forces, error
        if code == FAILED_CODE or error <= tol or not np.sqrt(2.0 * merit) <= inner_tol \
                or iterations >= min(total_iter, chain_until):
            break
        next_sigma, next_tol = max(sigma / decrease, sigma_floor), reduction * error * q_scale
        center[:] = forces
        next_merit = alart_curnier_2d(rho, lower, upper, cone_n, cone_t, cone_mu, unilateral,
                                      next_sigma, center, forces, velocity, phi, y)
        if not np.sqrt(2.0 * next_merit) > next_tol:
            break
        sigma, merit, inner_tol = next_sigma, next_merit, next_tol
        recent[:] = -np.inf
        recent[0] = merit
        count = 1
        best[:], best_error, centre_error = forces, error, error
        subproblem_iterations = 0
        subproblems += 1
    recorded = iterations if code == FAILED_CODE else iterations + 1   # a failed one: no iterate
    if best_error <= tol:
        code = CONVERGED_CODE
    return (best, best_error, forces, error, iterations, gradient_steps, code,
            history[:recorded], np.sqrt(2.0 * merit) <= inner_tol, sigma, subproblems,
            centre_error, overall, overall_error)
