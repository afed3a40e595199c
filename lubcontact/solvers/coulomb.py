"""Exact Coulomb friction: the fixed point on the shift ``s`` (docs/guide/model.md section 5).

The convex relaxation of Coulomb's law (a second-order cone on the forces, its
dual cone on ``g = W lam + b``) makes a sliding contact separate at the rate
``mu |u_T|`` (dilatancy). Shifting the normal rows by ``s_c = mu_c |g_T,c|``
(De Saxce's change of variable) removes it: at a fixed point
``s = mu |g_T(s)|`` the relaxed optimality conditions are exactly Coulomb's
law. This module iterates

    solve the convex problem with s frozen  ->  s <- mu |g_T(s)|

around any registered solver (through :func:`lubcontact.solvers.solve`), each
inner solve warm-started from the previous one.

Which contacts get a shift: every COULOMB contact; a UNION contact (gluey +
friction at gamma_min) only on its pushed piece (``lam_n >= 0``): on the
pulled piece it is frictionless and bilateral, and a shift would move it.

UNION contacts and the shift. The shift enters the linear term of the
problem, ``lam_n s``, on both pieces of a union, while the exact law wants it
on the pushed piece only (``s max(lam_n, 0)``). Projecting onto the union
with a shift therefore has spurious minimisers (a contact pulled *into* its
neighbour by ``s``). The fixed point thus fixes each UNION contact on one
piece during an inner solve (a convex problem, for every solver), shift on
the pushed piece only, and updates the pieces with the shift, by the branch
rule of docs/records/friction.md: a pushed contact whose normal force vanishes while
its unshifted normal gap rate is opening (``D + dt u_n > 0``) is flipped to
pulled; a pulled contact whose force vanishes while closing is flipped to
pushed. Initial pieces: the sign of the warm start's normal force (pushed
without one). The fixed point has converged when the shift has and no
contact flipped in the last round.

Stopping rule, with ``L`` the length unit of the normalised problem
(``problem.normalized().scaling.length``, i.e. ``dt V``) and the rms norm
over the ``nc`` contacts, ``|x|_rms = |x|_2 / sqrt(nc)``::

    change = |s_new - s_old|_rms / L / (1 + |s_new|_rms / L)  <  tol_fp

The rms norm matches the fast solvers' stopping measure (an rms residual): a
max norm would compare the worst contact's inner-solve noise with ``tol_fp``
and stall on large piles. Keep ``tol_fp`` above the inner accuracy ``tol``.

The tangential rows of ``g`` are ``dt u_T`` for a step problem and ``u_T`` for
a local (FCLIB) problem, so the same formula covers both.
"""
from __future__ import annotations

import time

import numpy as np

from .. import checks
from ..problem.cones import ConeKind
from ..problem.conic import ConicProblem
from ..problem.metrics import coulomb_shift
from .compiled_apgd import joint_applies, joint_coulomb_apgd
from .registry import FIRST_ORDER, accepting_solver, checked, solve, solver_info
from .result import CONVERGED, DIVERGED, FAILED, MAX_ITER, CoulombResult, MethodOutput

JOINT_MAX_ITER = 20_000
"""The fixed point's joint phase's iteration cap where ``max_iter`` is not given."""


def solve_coulomb(problem: ConicProblem, method: str = "clarabel", *, tol: float = 1e-9, tol_fp: float = 1e-8,
                  max_outer: int = 50, warm_start: np.ndarray | None = None,
                  shift: np.ndarray | None = None, max_iter: int | None = None,
                  anderson: int = 5, forcing: float = 0.0, joint: int = 0,
                  **options) -> CoulombResult:
    """Solve a frictional problem exactly by the fixed point on ``s``.

    Parameters
    ----------
    problem : ConicProblem
        In physical units; its own ``shift`` is ignored (replaced by ``shift``).
    method : str
        Any registered solver (see :func:`lubcontact.solvers.methods`).
    tol : float
        Tolerance of each inner solve.
    tol_fp : float
        Tolerance on the relative change of ``s`` (see the module docstring).
    max_outer : int
        Cap on the outer iterations (inner solves).
    warm_start : ndarray, shape (n_rows,), optional
        Initial forces (physical units) for the first inner solve.
    shift : ndarray, shape (nc,), optional
        Initial shift (e.g. the previous step's, matched by pair); default 0
        (the first inner solve is then the convex relaxation).
    max_iter : int, optional
        Iteration cap of each inner solve.
    anderson : int
        Memory of the Anderson acceleration of the map ``s -> mu |g_T(s)|``
        (0: plain fixed point). Accelerated shifts are clipped at 0; the
        stopping test is always on the plain map's change.
    forcing : float
        Inexact inner solves: the inner tolerance is
        ``max(tol, forcing x previous change)`` (0: always ``tol``).
    joint : int
        If > 0 and the problem is 2D with friction cones: before the outer
        loop, solve Coulomb's problem jointly inside one Jacobi-scaled APGD run
        that updates the shift from its iterate every ``joint`` iterations
        (:func:`lubcontact.solvers.kernels.apgd_cone2d`), to ``tol`` on the
        modified natural map and at most ``max_iter`` iterations (default
        :data:`JOINT_MAX_ITER`); its forces and shift then start the outer loop, whose tests
        are unchanged (the inner solves check the joint result with the shift frozen). 1 to 5
        worked best on the 1000-grain settling pile (2 outer iterations and 760 APGD
        iterations to ``tol = 1e-6`` instead of 27 and 5400). 0: no joint phase. A method
        that solves exact Coulomb itself (``native_coulomb``) is given ``joint`` as an option
        when it is > 0 and the method has one (:func:`has_joint_phase`; ``newton-ac``: the
        joint phase before its Newton phases).
    **options
        Passed to the inner solver.

    Returns
    -------
    CoulombResult
        The last inner solve with the fixed point's record (shift, outer
        iterations, last changes, branch flips); ``status`` is ``converged``
        only if the fixed point and the last inner solve converged
        (``max_iter`` when the outer loop ran out, the inner status when an
        inner solve failed); ``setup_time`` (normalising included) and
        ``solve_time`` summed over the inner solves (the joint phase, which
        builds the matrices the inner solves then share, in ``solve_time``). The problem is
        normalised once: outer iterations change only the shift of the prepared
        problem (``W`` is not rebuilt).
    """
    if max_iter is not None:                # before any path: the joint phase takes it as is
        max_iter = checks.integer("max_iter", max_iter, minimum=1)
    if solver_info(method).native_coulomb and problem.cones.has_friction:
        if joint and has_joint_phase(method):
            options["joint"] = joint
        return solve_native_coulomb(problem, method, tol=tol, max_iter=max_iter,
                                    warm_start=warm_start, max_outer=max_outer, **options)
    tol_fp = checks.positive_scalar("tol_fp", tol_fp)
    max_outer = checks.integer("max_outer", max_outer, minimum=1)
    nc = problem.cones.count
    current = np.zeros(nc) if shift is None else checks.as_array("shift", shift, shape=(nc,)).copy()
    if not problem.cones.has_friction:
        result = solve(problem.with_shift(current), method, tol=tol, max_iter=max_iter,
                       warm_start=warm_start, **options)
        return CoulombResult.single(result)
    clock = time.perf_counter()
    normalized = problem.normalized()           # set up once: only the shift changes below
    setup_time, solve_time = time.perf_counter() - clock, 0.0
    length, force_unit = normalized.scaling.length, normalized.scaling.force
    accelerator = _Anderson(anderson)
    branches = _Branches(problem, warm_start, threshold=max(1e3 * tol, 1e-7))
    forces, inner, history = warm_start, 0, []
    joint_iterations = 0
    convex = branches.problem()
    if joint > 0 and joint_applies(convex.cones):
        clock = time.perf_counter()
        scaled = branches.on(normalized).with_shift(branches.restrict(current) / length)
        joined, joint_iterations = joint_coulomb_apgd(
            scaled, None if forces is None else forces / force_unit, tol,
            JOINT_MAX_ITER if max_iter is None else max_iter, joint)
        solve_time += time.perf_counter() - clock
        forces = joined * force_unit
        current = coulomb_shift(convex, forces)
        normalized.keep_matrices(scaled)
        inner += joint_iterations
    shift_change = force_change = np.inf
    converged = False
    for outer in range(1, max_outer + 1):  # noqa: B007  (false positive: read after the loop, as the count)
        convex = branches.problem()
        used = branches.restrict(current)
        inner_tol = tol if forcing == 0 else max(tol, forcing * min(shift_change, 1.0))
        scaled = branches.on(normalized).with_shift(used / length)
        result = solve(convex.with_shift(used), method, tol=inner_tol, max_iter=max_iter,
                       warm_start=forces, normalized=scaled, **options)
        # the matrices the method built (W, its factor or its dense form, as it needs), kept for
        # the next outer iterations' copies: built once, and only those the method uses (the
        # first-order methods of a large problem apply F^T F and never assemble W)
        normalized.keep_matrices(scaled)
        inner += result.iterations
        setup_time, solve_time = setup_time + result.setup_time, solve_time + result.solve_time
        if forces is not None:
            force_change = _relative_change(result.forces / force_unit, forces / force_unit)
        forces = result.forces
        if not result.success:
            break
        mapped = coulomb_shift(convex, forces)
        shift_change = _relative_change(mapped / length, used / length)
        history.append(shift_change)
        flipped = branches.update(convex.with_shift(used), forces, length, force_unit)
        if shift_change < tol_fp and inner_tol <= tol and not flipped:
            converged = True
            break
        current = length * accelerator.step(used / length, mapped / length)
        if flipped:
            accelerator.restart()
    status = CONVERGED if converged else (result.status if not result.success else MAX_ITER)
    return CoulombResult(**{**vars(result), "status": status, "iterations": inner,
                            "setup_time": setup_time, "solve_time": solve_time},
                         outer_iterations=outer, shift_change=shift_change,
                         force_change=force_change, inner_status=result.status,
                         fixed_point_converged=converged, shift_history=np.asarray(history),
                         pulled=branches.pulled_contacts, branch_flips=branches.flips,
                         joint_iterations=joint_iterations)


def solve_native_coulomb(problem: ConicProblem, method: str, *, tol: float = 1e-9,
                         max_iter: int | None = None, warm_start: np.ndarray | None = None,
                         max_outer: int = 50, **options) -> CoulombResult:
    """Exact Coulomb by a method that solves it natively (``native_coulomb``).

    The method solves the Coulomb problem of ``problem`` (``q = b`` without
    the shift) once, giving ``r*``; its forces then go through the check of every
    result (:func:`~lubcontact.solvers.registry.checked`) at the shift
    ``s* = mu |u_T(r*)|``, where the convex problem's natural residual is
    Coulomb's. ``s*`` is a fixed point of ``s -> mu |g_T(s)|`` by construction
    (``g_T`` does not depend on ``s``): shift change 0.

    UNION contacts (gluey + friction at gamma_min): a method that accepts
    UNION solves the union law itself, once; its forces' signs then give each
    contact's piece (pulled where ``lam_n < 0``) for the check at ``s*``. For
    a method that accepts only both pieces (COULOMB and NONPOS) they are fixed
    on a piece, as in :func:`solve_coulomb`: solve with the pieces fixed, flip
    the contacts the branch rule says are on the wrong piece, re-solve from
    the last forces, until no contact flips (at most ``max_outer`` solves;
    ``outer_iterations`` counts them).

    A method with a first try (:func:`~lubcontact.solvers.registry.register_first_try`) is given
    the problem first, once the arguments are checked (not with options the method does not
    take, which its call then refuses, nor, for a method that needs the pieces fixed, with UNION
    contacts): where it answers, its normalised problem and output are the first pass's, and
    everything after (the shift, the pieces, the check) is the same.

    Returns
    -------
    CoulombResult
        ``converged`` only when the method converged, the check passed and no
        contact was left to flip; ``diverged`` with zero forces where the forces are not
        finite or their ``s*`` is not (forces so large that their velocities overflow);
        ``setup_time`` (normalising included) and ``solve_time`` summed over the method's calls.
    """
    info = solver_info(method)
    tol = checks.positive_scalar("tol", tol)
    if max_iter is not None:
        max_iter = checks.integer("max_iter", max_iter, minimum=1)
    max_outer = checks.integer("max_outer", max_outer, minimum=1)
    if warm_start is not None:
        warm_start = checks.as_array("warm_start", warm_start, shape=(problem.n_rows,))
    branches = _Branches(problem, warm_start, threshold=max(1e3 * tol, 1e-7))
    native_union = ConeKind.UNION in info.cones
    if not branches.convex and not native_union and not {ConeKind.COULOMB, ConeKind.NONPOS} <= info.cones:
        raise ValueError(f"method: {method!r} cannot solve this problem: UNION contacts need "
                         "both pieces (COULOMB and NONPOS contacts)")
    accepting_solver(method, problem if native_union else branches.on(problem))   # before solving
    first = None
    if info.first_try is not None and (native_union or branches.convex) \
            and not options.keys() - info.parameters:
        first = info.first_try(problem, tol=tol, max_iter=max_iter, warm_start=warm_start, **options)
    clock = time.perf_counter()
    if first is None:
        # a copy: no cache on the caller's problem
        unshifted = problem.with_shift(np.zeros(problem.cones.count))
        scaled = unshifted.normalized()
        setup_time = time.perf_counter() - clock
    else:               # (no piece flips where a first try answers: convex cones, or UNION taken)
        unshifted, (scaled, first_output) = problem, first
        setup_time = 0.0                            # normalising is in the first try's output
    solve_time = 0.0
    force, length = scaled.scaling.force, scaled.scaling.length
    start = None if warm_start is None else warm_start / force
    kwargs = dict(options, tol=tol)
    if max_iter is not None:
        kwargs["max_iter"] = max_iter
    iterations, settled = 0, False
    for outer in range(1, max_outer + 1):  # noqa: B007
        clock = time.perf_counter()
        out = first_output if first is not None and outer == 1 else \
            info.function(scaled if native_union else branches.on(scaled), warm_start=start, **kwargs)
        setup, solving = out.times(time.perf_counter() - clock)
        setup_time, solve_time = setup_time + setup, solve_time + solving
        iterations += out.iterations
        shift, gradient = np.zeros(problem.cones.count), None
        if out.status == FAILED or not np.isfinite(out.forces).all():
            prepared, settled = branches.on(scaled), True
            break
        if native_union and not branches.convex:     # each contact's piece from its force's sign
            branches.pulled = problem.cones.pulled(out.forces)
        # s* from the normalised problem the method solved: on a small one through the dense W
        # it built (W r + b, one product; g(v(r)) takes two through H), 3 % of a 35-contact solve
        prepared = branches.on(scaled)
        dense = prepared.__dict__.get("dense_delassus")
        with np.errstate(over="ignore", invalid="ignore"):
            gradient = None if dense is None else dense @ out.forces + prepared.offset
            found = branches.restrict(coulomb_shift(prepared, out.forces, gradient) * length)
        if not np.isfinite(found).all():     # forces too large for their velocities: as
            out = MethodOutput(np.zeros_like(out.forces), DIVERGED, out.iterations,  # non-finite
                               out.setup_time, out.solve_time, out.residual_history, out.info)
            settled, gradient = True, None
            break
        shift = found
        if gradient is not None:                 # g at the shift s*: W r + b + [s*, 0]
            gradient[: problem.n_contacts] += shift / length
        start = out.forces
        if native_union or not branches.update(branches.on(unshifted).with_shift(shift), out.forces * force,
                                               length, force):
            settled = True
            break
    # checked on the pieces the forces were solved on (not those of a last flip: max_outer), at
    # s*, through the dense W where the method built one (no copy of the problem at s*)
    if gradient is not None:
        result = checked(out, prepared, method, shift, 0.0, 0.0, constraint=gradient)
    else:
        result = checked(out, prepared.with_shift(shift / length), method, shift, 0.0, 0.0)
    status = result.status if settled else MAX_ITER
    return CoulombResult(**{**vars(result), "status": status, "iterations": iterations,
                            "setup_time": setup_time, "solve_time": solve_time},
                         outer_iterations=outer, shift_change=0.0, inner_status=result.status,
                         fixed_point_converged=status == CONVERGED, shift_history=np.zeros(outer),
                         pulled=branches.pulled_contacts, branch_flips=branches.flips,
                         joint_iterations=out.info.get("joint_iterations", 0))


def has_joint_phase(method: str) -> bool:
    """Whether exact Coulomb by ``method`` is meant to start with the joint phase: a first-order
    method (the fixed point's joint phase), or a native Coulomb method with a ``joint`` option
    of its own (``newton-ac``), to which :func:`solve_coulomb` passes it (Siconos' solvers have
    none). The fixed point runs the joint phase before any other method's outer loop too when
    given ``joint``; the benchmarks give it to these methods only."""
    info = solver_info(method)
    if info.native_coulomb:
        return "joint" in info.parameters
    return info.kind == FIRST_ORDER


def _relative_change(new: np.ndarray, old: np.ndarray) -> float:
    """``|new - old|_rms / (1 + |new|_rms)`` (0 for empty vectors)."""
    if new.size == 0:
        return 0.0
    root = np.sqrt(new.size)
    return float(np.linalg.norm(new - old) / root / (1.0 + np.linalg.norm(new) / root))


class _Anderson:
    """Anderson acceleration (type II) of a fixed point ``x = F(x)``, kept in ``x >= 0``.

    With the last ``memory + 1`` pairs ``(x_i, F(x_i))`` and residuals
    ``f_i = F(x_i) - x_i``, the next iterate is ``F(x_k) - dF gamma`` with
    ``gamma`` the least-squares solution of ``df gamma = f_k`` (differences of
    consecutive pairs). The history restarts when the residual grows past
    ten times the smallest seen, a safeguard against a poor extrapolation.
    """

    def __init__(self, memory: int):
        self.memory = int(checks.nonnegative("anderson", memory, shape=()))
        self.points: list[np.ndarray] = []
        self.images: list[np.ndarray] = []
        self.best = np.inf

    def restart(self) -> None:
        self.points, self.images, self.best = [], [], np.inf

    def step(self, point: np.ndarray, image: np.ndarray) -> np.ndarray:
        if self.memory == 0:
            return image
        size = float(np.linalg.norm(image - point))
        if size > 10.0 * self.best:
            self.restart()
        self.best = min(self.best, size)
        self.points = (self.points + [point])[-(self.memory + 1):]
        self.images = (self.images + [image])[-(self.memory + 1):]
        if len(self.points) < 2:
            return image
        images = np.array(self.images).T
        residuals = images - np.array(self.points).T
        gamma = np.linalg.lstsq(np.diff(residuals, axis=1), residuals[:, -1], rcond=1e-12)[0]
        return np.maximum(image - np.diff(images, axis=1) @ gamma, 0.0)


class _Branches:
    """The piece (pushed or pulled) on which each UNION contact is fixed (module docstring).

    Parameters
    ----------
    problem : StepProblem or LocalProblem
    warm_start : ndarray or None
        Initial forces: a negative normal force starts a UNION contact pulled.
    threshold : float
        Normalised level below which a normal force counts as zero and above
        which a gap rate counts as opening or closing.
    """

    def __init__(self, problem: ConicProblem, warm_start: np.ndarray | None, threshold: float):
        self.base = problem
        self.union = problem.cones.mask(ConeKind.UNION)
        self.convex = problem.cones.is_convex
        self.pulled = np.zeros(problem.cones.count, dtype=bool)
        if warm_start is not None and not self.convex:
            self.pulled = problem.cones.pulled(warm_start)
        self.threshold = threshold
        self.flips: list[int] = []

    @property
    def pulled_contacts(self) -> np.ndarray:
        return np.zeros(0, dtype=int) if self.convex else np.flatnonzero(self.pulled)

    def problem(self) -> ConicProblem:
        """The convex problem with every UNION contact on its current piece."""
        return self.on(self.base)

    def on(self, problem: ConicProblem) -> ConicProblem:
        """``problem`` (the base problem or its normalised form) with the current pieces."""
        if self.convex:
            return problem
        return problem.with_cones(problem.cones.with_branches(self.pulled))

    def restrict(self, shift: np.ndarray) -> np.ndarray:
        """No shift on pulled contacts."""
        return shift if self.convex else np.where(self.pulled, 0.0, shift)

    def update(self, convex: ConicProblem, forces: np.ndarray, length: float, force_unit: float) -> bool:
        """Flip the contacts inconsistent with the union; returns whether any flipped."""
        if self.convex:
            return False
        nc = convex.cones.count
        normal = forces[:nc] / force_unit
        opening = (convex.gradient(forces)[:nc] - convex.shift) / length      # (D + dt u_n) / L
        idle = np.abs(normal) <= self.threshold
        flip = self.union & idle & np.where(self.pulled, opening < -self.threshold,
                                            opening > self.threshold)
        self.flips.append(int(np.count_nonzero(flip)))
        self.pulled ^= flip
        return bool(flip.any())
