"""Scene model: grains, obstacles and external forces, for any dimension.

A scene holds the *state* of the free grains (positions, velocities, spins,
orientations) together with what does not move: planes and fixed grains.
Everything is stored as arrays; the dimension ``dim`` (2 or 3) is read off the
shape of the positions and never hard-coded.

Units are whatever the user chooses, as long as they are consistent (SI or
dimensionless). Forces are per unit depth in 2D.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Union

import numpy as np
from numpy.typing import ArrayLike

from .. import checks
from .geometry import close_pairs, smaller_radius

ForceLike = Union[None, np.ndarray, "Schedule", Callable[[float], np.ndarray]]


def n_rotations(dim: int) -> int:
    """Number of rotational degrees of freedom of a body in dimension ``dim``."""
    return 1 if dim == 2 else 3


def ball_volume(radii: np.ndarray, dim: int) -> np.ndarray:
    """Area of a disk (2D, per unit depth) or volume of a sphere (3D)."""
    return np.pi * radii**2 if dim == 2 else 4.0 / 3.0 * np.pi * radii**3


def ball_inertia(masses: np.ndarray, radii: np.ndarray, dim: int) -> np.ndarray:
    """Moment of inertia of a uniform disk ``m r^2 / 2`` or sphere ``2 m r^2 / 5``."""
    return (0.5 if dim == 2 else 0.4) * masses * radii**2


@dataclass(frozen=True)
class Schedule:
    """Piecewise-constant external force in time.

    ``values[k]`` applies for ``times[k] <= t < times[k+1]`` (the last value
    for ever after). Each value is broadcast to the grains' shape ``(N, dim)``.

    Parameters
    ----------
    times : sequence of float, shape (K,)
        Increasing switching times; ``times[0]`` is usually 0.
    values : sequence of array_like, length K
        Force in each interval (force units; per grain or one vector for all).
    """

    times: tuple
    values: tuple

    def __post_init__(self):
        times = checks.as_array("Schedule.times", self.times, shape=(None,))
        checks.require(len(times) == len(self.values) and len(times) > 0, "Schedule.values",
                       f"needs one value per switching time ({len(times)})", len(self.values))
        checks.require(bool(np.all(np.diff(times) > 0)), "Schedule.times", "must increase", times)
        values = tuple(checks.as_array(f"Schedule.values[{k}]", v) for k, v in enumerate(self.values))
        object.__setattr__(self, "times", tuple(times))
        object.__setattr__(self, "values", values)

    def __call__(self, t: float) -> np.ndarray:
        k = max(0, int(np.searchsorted(self.times, t, side="right")) - 1)
        return self.values[k]


@dataclass
class Grains:
    """Free grains (disks in 2D, spheres in 3D), all as arrays.

    Attributes
    ----------
    positions : ndarray, shape (N, dim)
        Centres (length).
    radii : ndarray, shape (N,)
        Radii (length), > 0.
    masses : ndarray, shape (N,)
        Masses (mass), > 0. Inertia uses the grain density ``rho_p``.
    inertias : ndarray, shape (N,)
        Moments of inertia (mass length^2), > 0.
    velocities : ndarray, shape (N, dim)
        Translational velocities (length / time).
    spins : ndarray, shape (N, 1) in 2D or (N, 3) in 3D
        Angular velocities (1 / time).
    angles : ndarray, shape (N, 1) in 2D or (N, 3) in 3D
        Accumulated rotation (rotation vector, radians); used for display.
    densities : ndarray, shape (N,) or None
        Grain densities ``rho_p``; needed for buoyancy.
    """

    positions: np.ndarray
    radii: np.ndarray
    masses: np.ndarray
    inertias: np.ndarray
    velocities: np.ndarray
    spins: np.ndarray
    angles: np.ndarray
    densities: np.ndarray | None = None

    @classmethod
    def create(cls, positions: ArrayLike, radii: ArrayLike, *, masses: ArrayLike | None = None,
               densities: ArrayLike | None = None, velocities: ArrayLike | None = None,
               spins: ArrayLike | None = None, inertias: ArrayLike | None = None) -> Grains:
        """Build and validate grains; masses come from ``masses`` or ``densities``.

        Raises
        ------
        ValueError
            On wrong shapes, non-finite values, non-positive radius, mass or
            density, or when neither masses nor densities are given.
        """
        positions = checks.as_array("positions", positions, shape=(None, None))
        n, dim = positions.shape
        checks.require(n > 0, "positions", "at least one grain is needed, got 0 grains")
        checks.require(dim in (2, 3), "positions", "dimension must be 2 or 3", dim)
        radii = checks.positive("radii", checks.per_item("radii", radii, n))
        if densities is not None:
            densities = checks.positive("densities", checks.per_item("densities", densities, n))
        if masses is None:
            checks.require(densities is not None, "masses", "give masses or densities", None)
            masses = densities * ball_volume(radii, dim)
        masses = checks.positive("masses", checks.per_item("masses", masses, n))
        if inertias is None:
            inertias = ball_inertia(masses, radii, dim)
        inertias = checks.positive("inertias", checks.per_item("inertias", inertias, n))
        nrot = n_rotations(dim)
        velocities = np.zeros((n, dim)) if velocities is None else velocities
        if spins is None:
            spins = np.zeros((n, nrot))
        elif np.size(spins) == n * nrot:            # (n,) is accepted for disks
            spins = np.reshape(spins, (n, nrot))
        return cls(positions=positions.copy(), radii=radii.copy(), masses=masses,
                   inertias=inertias,
                   velocities=checks.as_array("velocities", velocities, shape=(n, dim)).copy(),
                   spins=checks.as_array("spins", spins, shape=(n, nrot)).copy(),
                   angles=np.zeros((n, nrot)), densities=densities)

    @property
    def count(self) -> int:
        return self.positions.shape[0]

    @property
    def dim(self) -> int:
        return self.positions.shape[1]

    def copy(self) -> Grains:
        return replace(self, **{k: (None if v is None else v.copy())
                                for k, v in vars(self).items()})


@dataclass
class Planes:
    """Fixed half-spaces: grains stay on the side the unit normal points to.

    Attributes
    ----------
    points : ndarray, shape (P, dim)
        A point on each plane (length).
    normals : ndarray, shape (P, dim)
        Unit normals, pointing into the region where grains live.
    """

    points: np.ndarray
    normals: np.ndarray

    @classmethod
    def create(cls, points: ArrayLike, normals: ArrayLike, dim: int) -> Planes:
        """Validate planes given as one vector each (or a single vector for one plane).

        Raises
        ------
        ValueError
            Naming ``planes.points`` or ``planes.normals`` (the ``plane_points`` and
            ``plane_normals`` of :meth:`Scene.create`) for vectors of another
            dimension than the grains', unequal counts, non-finite or zero normals.
        """
        points = _vectors("planes.points", points, dim)
        normals = _vectors("planes.normals", normals, dim)
        checks.require(normals.shape == points.shape, "planes.normals",
                       f"expected one normal per point ({points.shape[0]}), got {normals.shape[0]}")
        lengths = np.linalg.norm(normals, axis=1)
        checks.require(bool(np.all(lengths > 0)), "planes.normals", "must be non-zero", normals)
        return cls(points=points, normals=normals / lengths[:, None])

    @property
    def count(self) -> int:
        return self.points.shape[0]


def _prescribed(field: str, value: ForceLike) -> ForceLike:
    """A prescribed velocity as stored: arrays validated, schedules and callables as given."""
    if isinstance(value, (np.ndarray, list, tuple)):
        return checks.as_array(field, value)
    checks.require(value is None or callable(value), field,
                   "must be an array, a Schedule or a callable f(t)")
    return value


def _vectors(field: str, value: ArrayLike, dim: int) -> np.ndarray:
    """Vectors of dimension ``dim`` as an array of shape (count, dim); one vector may be flat."""
    arr = np.asarray(value, dtype=float)
    if arr.size == 0:
        return np.zeros((0, dim))
    arr = arr.reshape(1, -1) if arr.ndim == 1 else arr
    checks.require(arr.ndim == 2 and arr.shape[1] == dim, field,
                   f"expected vectors of dimension {dim} (that of the grains), got shape "
                   f"{np.shape(value)}")
    return checks.as_array(field, arr, shape=(None, dim))


def inclined_plane_normal(angle: float, dim: int = 2) -> np.ndarray:
    """Unit normal of a plane through the origin tilted by ``angle`` (rad) about z.

    The downhill direction is ``+x`` rotated by ``-angle``: with gravity along
    ``-y``, a grain slides towards increasing x.
    """
    normal = np.zeros(dim)
    normal[0], normal[1] = np.sin(angle), np.cos(angle)
    return normal


@dataclass
class Scene:
    """Everything a simulation needs: grains, obstacles, forces, time.

    Attributes
    ----------
    grains : Grains
        The free grains (state is updated in place by the integrator).
    planes : Planes
        Fixed half-spaces.
    fixed_positions, fixed_radii : ndarray, shapes (F, dim), (F,)
        Fixed grains (for rough beds).
    gravity : ndarray, shape (dim,)
        Gravitational acceleration (length / time^2).
    fluid_density : float
        ``rho_f``; the weight of a grain is ``(rho_p - rho_f) V g`` when grain
        densities are known, ``m g`` otherwise.
    external_force : None, array, Schedule or callable t -> array
        Extra force on the grains, broadcast to (N, dim).
    time : float
        Current time.
    overlap_tolerance : float
        Largest initial overlap allowed, as a fraction of the smaller radius
        of the pair (default 1e-6).
    period : float or None
        Length ``L`` of the periodic direction x, or None (not periodic). When
        set, x lives in ``[0, L)``: contacts see periodic images (a pair keeps
        its key across the boundary) and :meth:`wrap_positions` folds the
        centres back after each step.
    plane_velocity, fixed_velocity : array_like, Schedule, callable or None
        Prescribed velocities of the planes and of the fixed grains (moving
        walls, a driven bed): an array broadcast to shape (P, dim) or
        (F, dim), a :class:`Schedule` of such values, or ``f(t)`` returning
        one; None: at rest. Obstacles have no unknowns: the simulation moves
        them by ``dt`` times this velocity each step, and contacts see it in
        their relative velocity (:meth:`obstacle_velocities`).
    """

    grains: Grains
    planes: Planes
    fixed_positions: np.ndarray
    fixed_radii: np.ndarray
    gravity: np.ndarray
    fluid_density: float = 0.0
    external_force: ForceLike = None
    time: float = 0.0
    overlap_tolerance: float = 1e-6
    metadata: dict = field(default_factory=dict)
    period: float | None = None
    plane_velocity: ForceLike = None
    fixed_velocity: ForceLike = None

    @classmethod
    def create(cls, grains: Grains, *, plane_points: ArrayLike = (), plane_normals: ArrayLike = (),
               fixed_positions: ArrayLike | None = None, fixed_radii: ArrayLike | None = None,
               gravity: ArrayLike | None = None, fluid_density: float = 0.0,
               external_force: ForceLike = None, time: float = 0.0,
               overlap_tolerance: float = 1e-6, check_overlaps: bool = True,
               metadata: dict | None = None, period: float | None = None,
               plane_velocity: ForceLike = None, fixed_velocity: ForceLike = None) -> Scene:
        """Validate and assemble a scene.

        Raises
        ------
        ValueError
            On wrong shapes or non-finite values, a negative fluid density or
            overlap tolerance, buoyancy without grain densities, a non-positive
            period, or an initial overlap deeper than ``overlap_tolerance``.
        """
        dim = grains.dim
        planes = Planes.create(plane_points, plane_normals, dim)
        if fixed_positions is None:
            checks.require(fixed_radii is None, "fixed_positions", "required with fixed_radii")
            fixed_positions, fixed_radii = np.zeros((0, dim)), np.zeros(0)
        checks.require(fixed_radii is not None, "fixed_radii", "required with fixed_positions")
        fixed_positions = checks.as_array("fixed_positions", fixed_positions, shape=(None, dim))
        fixed_radii = checks.positive("fixed_radii", np.broadcast_to(fixed_radii, (len(fixed_positions),))
                                      if np.ndim(fixed_radii) == 0 else fixed_radii,
                                      shape=(len(fixed_positions),))
        gravity = np.zeros(dim) if gravity is None else gravity
        gravity = checks.as_array("gravity", gravity, shape=(dim,))
        fluid_density = float(checks.nonnegative("fluid_density", fluid_density, shape=()))
        checks.require(fluid_density == 0 or grains.densities is not None, "fluid_density",
                       "buoyancy needs grain densities", fluid_density)
        overlap_tolerance = float(checks.nonnegative("overlap_tolerance", overlap_tolerance, shape=()))
        if isinstance(external_force, (np.ndarray, list, tuple)):
            external_force = checks.as_array("external_force", external_force)
        scene = cls(grains=grains, planes=planes, fixed_positions=fixed_positions.copy(),
                    fixed_radii=np.array(fixed_radii, dtype=float), gravity=gravity,
                    fluid_density=fluid_density, external_force=external_force,
                    time=float(checks.as_array("time", time, shape=())),
                    overlap_tolerance=overlap_tolerance, metadata=dict(metadata or {}),
                    period=None if period is None else checks.positive_scalar("period", period),
                    plane_velocity=_prescribed("plane_velocity", plane_velocity),
                    fixed_velocity=_prescribed("fixed_velocity", fixed_velocity))
        if scene.period is not None:
            scene.fixed_positions[:, 0] = np.mod(scene.fixed_positions[:, 0], scene.period)
            scene.wrap_positions()
        scene.external_forces()  # validates the shapes of the external force and of
        scene.obstacle_velocities()  # the prescribed velocities once
        if check_overlaps:
            scene.check_overlaps()
        return scene

    @property
    def dim(self) -> int:
        return self.grains.dim

    def weights(self) -> np.ndarray:
        """Buoyant weight of each grain, shape (N, dim)."""
        g = self.grains
        if g.densities is None:
            effective = g.masses
        else:
            effective = g.masses * (1.0 - self.fluid_density / g.densities)
        return effective[:, None] * self.gravity[None, :]

    def external_forces(self, t: float | None = None) -> np.ndarray:
        """Total external force on each grain at time ``t`` (default: now), shape (N, dim)."""
        t = self.time if t is None else t
        force = self.weights()
        extra = self.external_force
        if extra is not None:
            value = extra(t) if callable(extra) else extra
            try:
                value = np.broadcast_to(np.asarray(value, dtype=float), force.shape)
            except ValueError as exc:
                raise ValueError(f"external_force: cannot broadcast shape {np.shape(value)} "
                                 f"to grains shape {force.shape}") from exc
            if not np.all(np.isfinite(value)):
                raise ValueError(f"external_force: non-finite value at t={t}")
            force = force + value
        return force

    def obstacle_velocities(self, t: float | None = None) -> np.ndarray:
        """Prescribed velocity of every obstacle at time ``t`` (default: now).

        Returns
        -------
        ndarray, shape (F + P, dim)
            Fixed grains first, then planes (the global body order after the
            free grains: body ``N + k`` is row ``k``).
        """
        n_fixed = len(self.fixed_radii)
        if self.fixed_velocity is None and self.plane_velocity is None:   # obstacles at rest:
            return np.zeros((n_fixed + self.planes.count, self.dim))      # a step asks 4 times
        t = self.time if t is None else t
        parts = []
        for name, value, count in (("fixed_velocity", self.fixed_velocity, n_fixed),
                                   ("plane_velocity", self.plane_velocity, self.planes.count)):
            shape = (count, self.dim)
            if value is None:
                parts.append(np.zeros(shape))
                continue
            value = value(t) if callable(value) else value
            try:
                value = np.broadcast_to(np.asarray(value, dtype=float), shape)
            except ValueError:
                raise ValueError(f"{name}: cannot broadcast shape {np.shape(value)} to {shape}") \
                    from None
            if not np.all(np.isfinite(value)):
                raise ValueError(f"{name}: non-finite value at t={t}")
            parts.append(value)
        return np.vstack(parts)

    def move_obstacles(self, dt: float, t: float | None = None) -> None:
        """Advance the planes and fixed grains by ``dt`` times their velocity at time ``t``."""
        velocity = self.obstacle_velocities(t)
        n_fixed = len(self.fixed_radii)
        if not np.any(velocity):
            return
        self.fixed_positions += dt * velocity[:n_fixed]
        self.planes.points += dt * velocity[n_fixed:]
        if self.period is not None and n_fixed:
            self.fixed_positions[:, 0] = np.mod(self.fixed_positions[:, 0], self.period)

    def wrap_positions(self) -> None:
        """Fold the grains' x coordinates into ``[0, period)`` (no-op when not periodic)."""
        if self.period is not None:
            x = self.grains.positions[:, 0]
            x[:] = np.mod(x, self.period)
            x[x >= self.period] = 0.0       # mod of a tiny negative number can round up to L

    def deep_overlaps(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Pairs overlapping by more than ``overlap_tolerance`` x the smaller radius.

        Returns
        -------
        body_a, body_b, keys, gaps, smaller : ndarray, shape (k,) each
            The pairs (global body numbers and pair keys, as contacts number
            them), their (negative) gaps and smaller radii.
        """
        a, b, keys, gaps, _, radius_a = close_pairs(
            np.vstack([self.grains.positions, self.fixed_positions]),
            np.concatenate([self.grains.radii, self.fixed_radii]), self.grains.count, 0.0,
            self.period, self.planes.points, self.planes.normals)
        smaller = smaller_radius(radius_a, self.grains.radii[b])
        deep = gaps < -self.overlap_tolerance * smaller
        return a[deep], b[deep], keys[deep], gaps[deep], smaller[deep]

    def check_overlaps(self) -> None:
        """Raise ``ValueError`` if any initial overlap exceeds the tolerance."""
        a, b, _, gaps, smaller = self.deep_overlaps()
        if gaps.size:
            c = int(np.argmin(gaps))
            raise ValueError(
                f"positions: initial overlap {-gaps[c]:.3e} between body "
                f"{a[c]} and grain {b[c]} exceeds overlap_tolerance "
                f"{self.overlap_tolerance} x radius {smaller[c]:.3e}")

    def copy(self) -> Scene:
        """A copy whose arrays (grains, planes, fixed grains) are its own."""
        planes = Planes(points=self.planes.points.copy(), normals=self.planes.normals.copy())
        return replace(self, grains=self.grains.copy(), planes=planes,
                       fixed_positions=self.fixed_positions.copy(), metadata=dict(self.metadata))
