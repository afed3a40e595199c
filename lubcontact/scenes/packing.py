"""2D granular piles at rest, built geometrically (no time stepping).

:func:`deposit_pile` drops polydisperse disks one at a time between two walls
and lets each one roll down over the disks already placed until it rests on
two supports (floor, wall or disks), the classical sequential "drop and roll"
deposition. Every disk ends exactly tangent to its supports, so the pile is
*at rest*: zero velocities, closed contacts (gaps at rounding level), and
each disk is stable on its own supports. The assembly as a whole is not a
static equilibrium for frictionless disks: loads from above push many grains
out of their pockets, so the first step of such a pile opens a large part of
its contacts (a genuine complementarity problem, not a trivial one).

:func:`settle_pile` starts from such a pile and runs the dynamics
(inelastic, frictionless) until the grains are at rest: a static
equilibrium whose closed contacts carry load and stay closed in the next
step. Settled piles are cached as compressed ``.npz`` files (``out/cache``).

The construction loops over grains in Python (it runs once, outside any
solver); each placement only uses vectorised operations over the disks in a
vertical strip.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .. import checks
from ..io.files import save_npz
from ..model.scene import Grains, Scene

_MAX_MOVES = 1000


def _check_pile(n_grains: int, radius: float, polydispersity: float) -> tuple[int, float]:
    if int(n_grains) < 1:
        raise ValueError(f"n_grains: must be >= 1, got {n_grains}")
    if not 0.0 <= polydispersity < 1.0:
        raise ValueError(f"polydispersity: must be in [0, 1), got {polydispersity}")
    if not radius > 0:
        raise ValueError(f"radius: must be > 0, got {radius}")
    return int(n_grains), float(radius)


def deposit_pile(n_grains: int, radius: float = 0.5, polydispersity: float = 0.2,
                 width: float | None = None, g: float = 1.0, seed: int = 0) -> Scene:
    """A 2D pile of ``n_grains`` disks at rest on a floor between two walls.

    Parameters
    ----------
    n_grains : int
        Number of disks (>= 1).
    radius : float
        Mean radius (length); radii are uniform in ``radius (1 +/- polydispersity)``.
    polydispersity : float
        In ``[0, 1)``.
    width : float, optional
        Distance between the walls; default ``2 radius sqrt(n_grains)``
        (a pile about as tall as wide).
    g : float
        Gravity (length / time^2), pointing to ``-y``.
    seed : int
        Seed of the radii and drop abscissae (the pile is deterministic).

    Returns
    -------
    Scene
        Floor ``y = 0``, walls ``x = 0`` and ``x = width``, unit density,
        zero velocities.
    """
    n_grains, radius = _check_pile(n_grains, radius, polydispersity)
    width = 2.0 * radius * np.sqrt(n_grains) if width is None else float(width)
    if not width > 2.0 * radius * (1.0 + polydispersity):
        raise ValueError(f"width: must exceed the largest diameter, got {width}")
    rng = np.random.default_rng(seed)
    radii = radius * (1.0 + polydispersity * rng.uniform(-1.0, 1.0, n_grains))
    drops = rng.uniform(0.0, 1.0, n_grains)
    centres = np.zeros((n_grains, 2))
    for i in range(n_grains):
        r = radii[i]
        x0 = r + drops[i] * (width - 2.0 * r)
        centres[i] = _place(centres[:i], radii[:i], r, x0, width)
    return _box_pile(centres, radii, width, g, {"name": "deposit_pile", "seed": seed})


def _box_pile(centres: np.ndarray, radii: np.ndarray, width: float, g: float,
              metadata: dict) -> Scene:
    """Unit-density disks on the floor ``y = 0`` between walls ``x = 0`` and ``x = width``."""
    grains = Grains.create(centres, radii, densities=1.0)
    return Scene.create(grains, plane_points=[[0.0, 0.0], [0.0, 0.0], [width, 0.0]],
                        plane_normals=[[0.0, 1.0], [1.0, 0.0], [-1.0, 0.0]], gravity=[0.0, -g],
                        metadata=dict(metadata, width=width))


def tile_pile(pile: Scene, copies: int) -> Scene:
    """``copies`` copies of a box pile side by side in one box ``copies`` times wider.

    Parameters
    ----------
    pile : Scene
        A pile made by :func:`deposit_pile` or :func:`settle_pile` (its
        ``metadata["width"]`` is the distance between its walls).
    copies : int
        Number of copies (>= 1). The inner walls are removed; disks that
        touched them do not overlap their new neighbours (their centres
        are a radius from the old wall).

    Returns
    -------
    Scene
        Zero velocities; ``metadata`` records ``tiles``.
    """
    copies = int(checks.positive("copies", copies, shape=()))
    width = float(pile.metadata["width"])
    shift = np.zeros((copies, 1, 2))
    shift[:, 0, 0] = width * np.arange(copies)
    centres = (pile.grains.positions[None, :, :] + shift).reshape(-1, 2)
    radii = np.tile(pile.grains.radii, copies)
    g = float(np.linalg.norm(pile.gravity))
    return _box_pile(centres, radii, copies * width, g, dict(pile.metadata, tiles=copies))


def _place(centres: np.ndarray, radii: np.ndarray, r: float, x0: float, width: float) -> np.ndarray:
    """Final centre of a disk of radius ``r`` dropped at abscissa ``x0``."""
    position = np.array([x0, np.inf])
    support = _fall(centres, radii, r, position, exclude=-1)
    direction = 0.0
    for _ in range(_MAX_MOVES):
        if support < 0:                               # on the floor
            return position
        if direction == 0.0:
            direction = 1.0 if position[0] >= centres[support, 0] else -1.0
        hit, position = _roll(centres, radii, r, position, support, direction, width)
        if hit == "fall":
            support = _fall(centres, radii, r, position, exclude=support)
            direction = 0.0
        elif hit in ("floor", "wall"):
            return position
        else:
            other = int(hit)
            low, high = sorted((centres[support, 0], centres[other, 0]))
            if low <= position[0] <= high:
                return position
            support = other                          # keep rolling, same direction
    raise RuntimeError(f"deposit_pile: a disk found no rest after {_MAX_MOVES} moves")


def _fall(centres: np.ndarray, radii: np.ndarray, r: float, position: np.ndarray, exclude: int) -> int:
    """Drop vertically from ``position`` (in place); return the support (-1: floor)."""
    x = position[0]
    reach = r + radii
    near = np.abs(centres[:, 0] - x) < reach
    if 0 <= exclude:
        near[exclude] = False
    best, height = -1, r
    if np.any(near):
        index = np.flatnonzero(near)
        y = centres[index, 1] + np.sqrt(reach[index] ** 2 - (centres[index, 0] - x) ** 2)
        y[y > position[1] + 1e-12] = -np.inf            # only what lies below
        k = int(np.argmax(y))
        if y[k] > height:
            best, height = int(index[k]), float(y[k])
    position[1] = height
    return best


def _roll(centres: np.ndarray, radii: np.ndarray, r: float, position: np.ndarray, support: int,
          direction: float, width: float) -> tuple[str, np.ndarray]:
    """Roll on ``support`` towards ``direction`` until the first obstacle or the equator.

    Returns ``(hit, position)`` with hit ``"floor"``, ``"wall"``, ``"fall"``
    (reached the equator of the support with nothing in the way) or the index
    of the disk hit.
    """
    c = centres[support]
    big = r + radii[support]
    start = np.arctan2(position[1] - c[1], position[0] - c[0])
    end = 0.0 if direction > 0 else np.pi
    # progress along the path: 0 at start, grows while rolling down
    def progress(theta: float) -> float:
        return direction * (start - theta)
    limit = progress(end)
    best_s, best_hit = limit, "fall"
    # floor: c_y + big sin(theta) = r
    s_floor = (r - c[1]) / big
    if -1.0 <= s_floor <= 1.0:
        theta = np.arcsin(s_floor) if direction > 0 else np.pi - np.arcsin(s_floor)
        s = progress(theta)
        if 0.0 <= s < best_s:
            best_s, best_hit = s, "floor"
    # wall the disk rolls towards
    wall_x = width - r if direction > 0 else r
    cos_wall = (wall_x - c[0]) / big
    if -1.0 <= cos_wall <= 1.0:
        s = progress(np.arccos(cos_wall))
        if 0.0 <= s < best_s:
            best_s, best_hit = s, "wall"
    # other disks: intersections of circle(c, big) with circle(c_k, r + r_k)
    reach = r + radii
    distance = np.hypot(centres[:, 0] - c[0], centres[:, 1] - c[1])
    near = (distance < big + reach) & (distance > np.abs(big - reach))
    near[support] = False
    if np.any(near):
        k = np.flatnonzero(near)
        base = np.arctan2(centres[k, 1] - c[1], centres[k, 0] - c[0])
        half = np.arccos(np.clip((big**2 + distance[k] ** 2 - reach[k] ** 2) / (2 * big * distance[k]),
                                 -1.0, 1.0))
        thetas = np.concatenate([base - half, base + half])
        s = np.mod(direction * (start - thetas), 2.0 * np.pi)
        s[s > 2.0 * np.pi - 1e-9] = 0.0                  # touching now counts as progress 0
        owners = np.concatenate([k, k])
        ahead = (s > 1e-12) & (s < best_s)
        if np.any(ahead):
            j = int(np.argmin(np.where(ahead, s, np.inf)))
            best_s, best_hit = float(s[j]), str(int(owners[j]))
    theta = start - direction * best_s
    new = c + big * np.array([np.cos(theta), np.sin(theta)])
    if best_hit == "wall":
        new[0] = wall_x
    elif best_hit == "floor":
        new[1] = r
    return best_hit, new


def settle_pile(n_grains: int, seed: int = 0, *, tiles: int = 1, dt: float = 0.04,
                speed_tol: float = 1e-6, max_steps: int = 20000, solver: str = "apgd-as",
                max_iter: int = 2000, fallback_solver: str = "clarabel-direct",
                switch_speed: float = 1e-2, cache: str | None = "out/cache",
                progress: Callable[[str], None] | None = print) -> tuple[Scene, dict]:
    """A deposited pile (:func:`deposit_pile`) settled by the dynamics until at rest.

    The pile is stepped with inelastic frictionless contacts (walls and
    floor, time step ``dt``) until the largest grain speed of a step falls
    below ``speed_tol x g dt`` or ``max_steps`` steps were taken. The
    returned scene has zero velocities (the residual speeds are reported in
    ``info``). Deterministic for given arguments.

    Parameters
    ----------
    n_grains, seed : int
        As in :func:`deposit_pile` (default radius, polydispersity, width, ``g = 1``).
    tiles : int
        With ``tiles > 1`` (``n_grains`` a multiple of it) the pile starts as
        :func:`tile_pile` of the settled pile of ``n_grains / tiles`` grains
        (same seed and options) instead of a deposit: a box ``tiles`` times
        wider than tall where only the disks near the removed inner walls
        move, much cheaper to settle for large N than a deposit's collapse.
    dt : float
        Time step of the settling run (units of ``sqrt(r / g)``). A rest
        state is an equilibrium whatever the step that reached it; a larger
        step dissipates more per unit time (inelastic implicit steps): at
        N = 100, 0.01, 0.02 and 0.04 reached rest in 1537, 676 and 204
        steps. Contacts are detected within ``0.25 x`` the smallest radius
        so that none is missed at this step.
    speed_tol : float
        Rest threshold on the largest grain speed, in units of ``g dt``.
    max_steps : int
        Step cap; ``info["at_rest"]`` tells whether the threshold was met.
    solver, max_iter, fallback_solver : str, int, str
        The collapse (largest speed of the last step at least ``switch_speed
        x g dt``) is stepped with ``fallback_solver``: its steps are hard for
        a gradient method. The nearly-at-rest tail is stepped with ``solver``
        (cheap there) capped at ``max_iter`` iterations, a step it does not
        solve being re-solved by ``fallback_solver``.
    switch_speed : float
        Speed (units of ``g dt``) below which ``solver`` takes over.
    cache : str or None
        Folder of compressed ``pile_<N>_<seed>...npz`` files (created on
        demand; ``out/`` is not committed); None disables the cache. The
        file name encodes every option. Every 100 steps the state is written
        to ``<name>.partial.npz`` and an interrupted run resumes from it. A
        step that neither method solves raises.
    progress : callable or None
        Receives a progress line every 100 steps.

    Returns
    -------
    (Scene, dict)
        The settled pile and ``info``: ``steps``, ``max_speed`` (last step,
        length/time), ``at_rest``, ``seconds``.
    """
    tiles = int(checks.positive("tiles", tiles, shape=()))
    if n_grains % tiles:
        raise ValueError(f"n_grains: must be a multiple of tiles={tiles}, got {n_grains}")
    settling = dict(dt=dt, speed_tol=speed_tol, max_steps=max_steps, solver=solver,
                    max_iter=max_iter, fallback_solver=fallback_solver,
                    switch_speed=switch_speed)
    if tiles == 1:
        scene = deposit_pile(n_grains, seed=seed)
    else:
        base, _ = settle_pile(n_grains // tiles, seed, cache=cache, progress=progress, **settling)
        scene = tile_pile(base, tiles)
    path = None
    if cache is not None:
        tiling = "" if tiles == 1 else f"_tiles{tiles}"
        path = Path(cache) / (f"pile_{int(n_grains)}_{seed}{tiling}_dt{dt:g}_v{speed_tol:g}_"
                              f"cap{max_steps}_{fallback_solver}{switch_speed:g}{solver}"
                              f"{max_iter}.npz")
    return _settle(scene, path, f"settle_pile N={n_grains}", progress, **settling)


def _settle(scene: Scene, path: Path | None, label: str, progress: Callable[[str], None] | None, *,
            dt: float, speed_tol: float, max_steps: int, solver: str, max_iter: int,
            fallback_solver: str, switch_speed: float) -> tuple[Scene, dict]:
    """Step ``scene`` until at rest (see :func:`settle_pile`), cached at ``path``."""
    from ..model.laws import Inelastic
    from ..sim.simulation import Simulation
    from ..solvers import SolveSettings

    if path is not None and path.exists():
        with np.load(path) as stored:
            scene.grains.positions[:] = stored["positions"]
            return scene, {key: stored[key].item() for key in _SETTLE_INFO}
    g = float(np.linalg.norm(scene.gravity))
    partial = None if path is None else path.with_suffix(".partial.npz")
    steps, elapsed, speed = _resume_settling(scene, partial)
    simulation = Simulation(scene, Inelastic(), dt, solver=solver, on_failure="fallback",
                            fallback_solver=fallback_solver,
                            d_max=0.25 * float(scene.grains.radii.min()), keep_trajectory=False)
    collapse = SolveSettings(method=fallback_solver)
    tail = SolveSettings(method=solver, max_iter=max_iter)
    start = time.perf_counter() - elapsed
    while steps < max_steps and speed >= speed_tol * g * dt:
        report = simulation.step(tail if speed < switch_speed * g * dt else collapse)
        steps += 1
        speed = float(np.max(np.linalg.norm(simulation.scene.grains.velocities, axis=1)))
        if steps % 100 == 0:
            _save_settling(partial, simulation.scene, steps, time.perf_counter() - start, speed)
            if progress is not None:
                progress(f"{label}: step {steps}, max speed {speed:.2e}, "
                         f"{report.contacts.count} contacts, {time.perf_counter() - start:.0f} s")
    settled = simulation.scene
    settled.grains.velocities[:] = 0.0
    settled.time = 0.0
    info = {"steps": steps, "max_speed": speed, "at_rest": bool(speed < speed_tol * g * dt),
            "seconds": time.perf_counter() - start}
    if path is not None:
        save_npz(path, compressed=True, positions=settled.grains.positions, **info)
        partial.unlink(missing_ok=True)
    return settled, info


def _save_settling(partial: Path | None, scene: Scene, steps: int, seconds: float,
                   speed: float) -> None:
    """Write the settling state so that an interrupted run resumes (atomic rename)."""
    if partial is not None:
        save_npz(partial, compressed=True, positions=scene.grains.positions,
                 velocities=scene.grains.velocities, steps=steps, seconds=seconds,
                 max_speed=speed)


def _resume_settling(scene: Scene, partial: Path | None) -> tuple[int, float, float]:
    """Load an interrupted settling run into ``scene``; returns (steps, seconds, max speed)."""
    if partial is None or not partial.exists():
        return 0, 0.0, np.inf
    with np.load(partial) as stored:
        scene.grains.positions[:] = stored["positions"]
        scene.grains.velocities[:] = stored["velocities"]
        return int(stored["steps"]), float(stored["seconds"]), float(stored["max_speed"])


_SETTLE_INFO = ("steps", "max_speed", "at_rest", "seconds")
