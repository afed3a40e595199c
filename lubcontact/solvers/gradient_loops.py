"""The numpy loops of the projected-gradient methods: :func:`run_pgd`, :func:`run_apgd`,
:func:`run_bb`.

Each iterates on a :class:`~.dual_data.DualData` from a starting point in K
and stops on the rule of :mod:`.dual_data` (through a
:class:`~.dual_data.ResidualTracker`, which keeps the best iterate). They
apply ``W z`` through :meth:`~.dual_data.DualData.product`, so that they
work with the assembled and the matrix-free operator and with every cone;
:mod:`.compiled_apgd` runs APGD faster on boxes and 2D friction cones.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .dual_data import DualData, ResidualTracker, initial_lipschitz, largest_eigenvalue
from .result import MAX_ITER


def run_pgd(data: DualData, z: np.ndarray, tol: float, max_iter: int,
            power_iterations: int = 30) -> tuple[ResidualTracker, str, int]:
    """Projected gradient with step ``1 / L``.

    Parameters
    ----------
    data : DualData
        The problem iterated on.
    z : ndarray, shape (n,)
        Starting iterate (in K).
    tol : float
        Stopping tolerance on the residual (:class:`.dual_data.ResidualTracker`).
    max_iter : int
        Iteration cap.
    power_iterations : int
        Power iterations of the estimate of ``L`` (:func:`.dual_data.largest_eigenvalue`).

    Returns
    -------
    tracker : ResidualTracker
        Best iterate and residual history.
    status : str
    iterations : int
    """
    tracker = ResidualTracker(data, tol)
    step = 1.0 / (1.01 * largest_eigenvalue(data, z.size, power_iterations))
    product = data.product(z)
    status = None
    for k in range(1, max_iter + 1):
        z = data.project(z - step * (product + data.offset))
        product = data.product(z)
        status = tracker.record(z, product + data.offset)
        if status:
            return tracker, status, k
    return tracker, MAX_ITER, max_iter


def run_apgd(data: DualData, z: np.ndarray, tol: float, max_iter: int,
             callback: Callable | None = None) -> tuple[ResidualTracker, str, int, np.ndarray]:
    """APGD with adaptive restart and backtracking (Mazhar et al. 2015).

    One product ``W z`` per iteration (plus one per backtracking step): the
    product at the extrapolated point is a combination of stored products.

    Parameters
    ----------
    data : DualData
        The problem iterated on.
    z : ndarray, shape (n,)
        Starting iterate (in K).
    tol : float
        Stopping tolerance on the residual (:class:`.dual_data.ResidualTracker`).
    max_iter : int
        Iteration cap.
    callback : callable, optional
        ``callback(k, z, gradient)`` after iteration ``k`` may return a
        replacement iterate (shape (n,)), a status string to stop with, or None.

    Returns
    -------
    tracker : ResidualTracker
        Best iterate and residual history.
    status : str
    iterations : int
    z : ndarray, shape (n,)
        The last iterate.
    """
    tracker = ResidualTracker(data, tol)
    x_old = z.copy()
    wx_old = data.product(z)
    lipschitz = initial_lipschitz(data, z, wx_old)
    y, wy = z.copy(), wx_old.copy()
    theta = 1.0
    for k in range(1, max_iter + 1):
        gradient_y = wy + data.offset
        while True:
            x = data.project(y - gradient_y * (1.0 / lipschitz))    # as the compiled loops
            wx = data.product(x)
            d = x - y
            if d @ (wx - wy) <= lipschitz * (d @ d) * (1.0 + 1e-12):
                break
            lipschitz *= 2.0
        gradient_x = wx + data.offset
        status = tracker.record(x, gradient_x)
        if status:
            return tracker, status, k, x
        if callback is not None:
            replaced = callback(k, x, gradient_x)
            if isinstance(replaced, str):
                return tracker, replaced, k, x
            if replaced is not None:
                x = replaced
                wx = data.product(x)
                status = tracker.record(x, wx + data.offset)
                if status:
                    return tracker, status, k, x
                x_old, wx_old, y, wy, theta = x, wx, x.copy(), wx.copy(), 1.0
                continue
        theta_new = 0.5 * (-theta * theta + theta * np.sqrt(theta * theta + 4.0))
        beta = theta * (1.0 - theta) / (theta * theta + theta_new)
        if gradient_y @ (x - x_old) > 0.0:          # restart: momentum points uphill
            y, wy, theta_new = x.copy(), wx.copy(), 1.0
        else:
            y = x + beta * (x - x_old)
            wy = wx + beta * (wx - wx_old)
        x_old, wx_old, theta = x, wx, theta_new
        lipschitz *= 0.9
    return tracker, MAX_ITER, max_iter, x_old


def run_bb(data: DualData, z: np.ndarray, tol: float, max_iter: int, memory: int = 10,
           gamma: float = 1e-4) -> tuple[ResidualTracker, str, int]:
    """Spectral projected gradient (SPG, alternating BB1/BB2 steps, non-monotone GLL search).

    Parameters
    ----------
    data : DualData
        The problem iterated on.
    z : ndarray, shape (n,)
        Starting iterate (in K).
    tol : float
        Stopping tolerance on the residual (:class:`.dual_data.ResidualTracker`).
    max_iter : int
        Iteration cap.
    memory : int
        Objective values the non-monotone (GLL) test compares with.
    gamma : float
        Sufficient-decrease constant of the line search.

    Returns
    -------
    tracker : ResidualTracker
        Best iterate and residual history.
    status : str
    iterations : int
    """
    tracker = ResidualTracker(data, tol)
    wz = data.product(z)
    gradient = wz + data.offset
    values = [data.objective(z, wz)]
    step = 1.0 / max(float(np.max(np.abs(data.product(np.ones_like(z))))), 1e-12)
    step_min, step_max = 1e-10, 1e10
    for k in range(1, max_iter + 1):
        d = data.project(z - step * gradient) - z
        wd = data.product(d)
        slope = float(gradient @ d)
        curvature = float(d @ wd)
        reference = max(values[-memory:])
        value = values[-1]
        length = 1.0
        if value + slope + 0.5 * curvature > reference + gamma * slope and curvature > 0:
            length = min(1.0, -slope / curvature)
        z = z + length * d
        wz = wz + length * wd
        gradient = wz + data.offset
        values.append(value + length * slope + 0.5 * length * length * curvature)
        status = tracker.record(z, gradient)
        if status:
            return tracker, status, k
        s_s = length * length * float(d @ d)
        s_y = length * length * curvature
        if s_y <= 0.0:
            step = step_max
        elif k % 2:
            step = s_s / s_y                                                   # BB1
        else:
            step = s_y / (length * length * float(wd @ wd))                    # BB2
        step = min(step_max, max(step_min, step))
    return tracker, MAX_ITER, max_iter

