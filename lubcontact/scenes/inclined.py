"""The poster's granular-flow experiment: sedimentation, then flow down a rough incline.

Two scenes, both periodic along x (the flow direction) above a rough bed of
fixed grains resting on the plane ``y = 0``:

- :func:`sedimentation`: ``N`` polydisperse disks (radius ``r (1 +/- p)``)
  released on a loose jittered lattice and left to settle under buoyant gravity;
- :func:`inclined_flow`: a (settled) scene with gravity tilted by ``theta``, so
  that the layer flows towards ``+x``; the bed tilts with it.

Parameters come in two presets (:func:`poster_parameters` in SI units, and
:func:`dimensionless_parameters`) and two models (:data:`MODELS`): ``dry``
(Coulomb friction only) and ``gluey`` (gluey lubrication + Coulomb friction at
``gamma = gamma_min``); ``frictionless`` (inelastic, no friction) settles beds
quickly.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .. import checks
from ..model import laws
from ..model.laws import Law
from ..model.scene import Grains, Scene

MODELS = ("dry", "gluey", "frictionless")

PARTING_JITTER = 1e-3
"""Velocity jitter, relative to the rms grain speed, that parts the copies of a widened layer
(:func:`widen`): the benchmarks' widened flows and the widened runs of ``lubcontact run`` and
``sweep`` with ``--widen`` use it."""


@dataclass(frozen=True)
class FlowParameters:
    """Physical parameters of a flow experiment (one consistent unit system).

    Attributes
    ----------
    radius : float
        Mean grain radius ``r`` (length).
    polydispersity : float
        Radii are uniform in ``r (1 +/- polydispersity)``.
    grain_density, fluid_density : float
        ``rho_p`` and ``rho_f`` (mass / length^2 in 2D, per unit depth).
    gravity : float
        Magnitude of g (length / time^2).
    friction : float
        Coulomb coefficient ``mu``.
    viscosity, roughness : float
        ``eta`` and ``eps``: ``gamma_min = 6 pi eta r_eff^2 ln(eps / r_eff)``
        per contact (docs/guide/model.md section 1); used unless ``gamma_min`` is given.
    gamma_min : float or None
        One gamma floor for every contact (impulse), overriding eta and eps.
    units : str
        Name of the unit system, for reports (``"SI"`` or ``"dimensionless"``).
    """

    radius: float
    polydispersity: float = 0.2
    grain_density: float = 1.0
    fluid_density: float = 0.0
    gravity: float = 1.0
    friction: float = 0.3
    viscosity: float | None = None
    roughness: float | None = None
    gamma_min: float | None = None
    units: str = "dimensionless"

    def __post_init__(self):
        checks.positive_scalar("radius", self.radius)
        checks.require(0 <= self.polydispersity < 1, "polydispersity", "must be in [0, 1)",
                       self.polydispersity)
        checks.positive_scalar("grain_density", self.grain_density)
        checks.require(0 <= self.fluid_density < self.grain_density, "fluid_density",
                       "must be in [0, grain_density)", self.fluid_density)
        checks.positive_scalar("gravity", self.gravity)
        checks.nonnegative("friction", self.friction, shape=())
        checks.require(self.gamma_min is not None or
                       (self.viscosity is not None and self.roughness is not None),
                       "gamma_min", "give gamma_min or both viscosity and roughness", self.gamma_min)

    @property
    def reduced_gravity(self) -> float:
        """Buoyant acceleration ``g (1 - rho_f / rho_p)`` (length / time^2)."""
        return self.gravity * (1.0 - self.fluid_density / self.grain_density)

    @property
    def time_scale(self) -> float:
        """``sqrt(d / g')`` with ``d = 2 r`` the mean diameter (time)."""
        return float(np.sqrt(2.0 * self.radius / self.reduced_gravity))

    @property
    def velocity_scale(self) -> float:
        """``sqrt(g' d)`` (length / time)."""
        return float(np.sqrt(self.reduced_gravity * 2.0 * self.radius))

    def law(self, model: str) -> Law:
        """The contact law of ``model`` (``"dry"``, ``"gluey"`` or ``"frictionless"``)."""
        checks.require(model in MODELS, "model", f"must be one of {MODELS}", None)
        if model == "frictionless":
            return laws.Inelastic()
        glue = ({"gamma_min": self.gamma_min} if self.gamma_min is not None else
                {"viscosity": self.viscosity, "roughness": self.roughness})
        if model == "dry":
            return laws.Coulomb(self.friction)
        return laws.GlueyCoulomb(self.friction, **glue)

    def as_dict(self) -> dict:
        return asdict(self)


def poster_parameters() -> FlowParameters:
    """The poster's SI parameters: r = 1 mm +/- 20 %, eps = 1 um, water-like fluid, mu = 0.3."""
    return FlowParameters(radius=1e-3, polydispersity=0.2, grain_density=2500.0,
                          fluid_density=1500.0, gravity=9.81, friction=0.3, viscosity=1e-3,
                          roughness=1e-6, units="SI")


def dimensionless_parameters(glue: float = 0.5) -> FlowParameters:
    """Units r = 1, g' = 1, rho_p = 1 (grain mass ``pi r^2``), mu = 0.3.

    ``gamma_min = -glue x m sqrt(g' d)``: ``glue`` is the impulse a glued
    contact can store, in units of the momentum of a mean grain moving at the
    flow's velocity scale. In the poster's SI parameters this ratio is about
    1e-5 (lubrication saturates within one step there); the default 0.5 makes
    lubrication matter at the flow's time scale.
    """
    checks.positive_scalar("glue", glue)
    mass = np.pi
    return FlowParameters(radius=1.0, polydispersity=0.2, grain_density=1.0, fluid_density=0.0,
                          gravity=1.0, friction=0.3, gamma_min=-glue * mass * np.sqrt(2.0),
                          units="dimensionless")


PRESETS = {"poster": poster_parameters, "dimensionless": dimensionless_parameters}


def _polydisperse_radii(rng: np.random.Generator, count: int, params: FlowParameters) -> np.ndarray:
    return params.radius * (1.0 + params.polydispersity * rng.uniform(-1.0, 1.0, count))


def rough_bed(width: float, params: FlowParameters, rng: np.random.Generator
              ) -> tuple[np.ndarray, np.ndarray]:
    """A row of touching polydisperse fixed grains on ``y = 0`` spanning ``[0, width)``.

    Radii are drawn like the free grains', then scaled so that the row closes
    exactly on the period; centres sit at height ``r_k`` (resting on the
    plane), which makes the bed bumpy at the grain scale.

    Returns
    -------
    positions : ndarray, shape (F, 2)
    radii : ndarray, shape (F,)
    """
    count = max(3, int(round(width / (2.0 * params.radius))))
    radii = _polydisperse_radii(rng, count, params)
    radii *= width / (2.0 * radii.sum())
    x = np.cumsum(2.0 * radii) - radii
    return np.stack([x, radii], axis=1), radii


def sedimentation(n_grains: int, params: FlowParameters, *, width: float | None = None,
                  seed: int = 0, packing: float = 0.45) -> Scene:
    """Polydisperse disks released above a rough bed, periodic in x.

    Parameters
    ----------
    n_grains : int
        Number of free grains.
    params : FlowParameters
    width : float, optional
        Period along x (length); default ``40 r``.
    seed : int
        Seed of the radii, the bed and the lattice jitter.
    packing : float
        Area fraction of the initial loose lattice (the grains start apart).

    Returns
    -------
    Scene
        Gravity ``-g e_y``, buoyancy ``rho_f``; metadata records the parameters.
    """
    n_grains = int(checks.positive("n_grains", n_grains, shape=()))
    rng = np.random.default_rng(seed)
    r = params.radius
    width = 40.0 * r if width is None else checks.positive_scalar("width", width)
    checks.require(0 < packing <= 0.6, "packing", "must be in (0, 0.6]", packing)
    bed_positions, bed_radii = rough_bed(width, params, rng)
    radii = _polydisperse_radii(rng, n_grains, params)
    r_max = r * (1.0 + params.polydispersity)
    spacing = max(2.05 * r_max, float(np.sqrt(np.pi * r * r / packing)))
    columns = max(1, int(width // spacing))
    spacing = width / columns
    rows = int(np.ceil(n_grains / columns))
    ix, iy = np.meshgrid(np.arange(columns), np.arange(rows))
    base = 2.0 * bed_radii.max() + 0.5 * spacing + 0.1 * r_max   # clear of the bed after jitter
    centres = np.stack([(ix.ravel() + 0.5) * spacing, base + iy.ravel() * spacing],
                       axis=1)[:n_grains]
    room = 0.5 * (spacing - 2.0 * radii)[:, None]
    centres = centres + room * rng.uniform(-0.9, 0.9, (n_grains, 2))
    grains = Grains.create(centres, radii, densities=params.grain_density)
    return Scene.create(grains, plane_points=[0.0, 0.0], plane_normals=[0.0, 1.0],
                        fixed_positions=bed_positions, fixed_radii=bed_radii,
                        gravity=[0.0, -params.gravity], fluid_density=params.fluid_density,
                        period=width,
                        metadata={"name": "sedimentation", "seed": seed, "width": width,
                                  "angle_deg": 0.0, "bed_top": float(2.0 * bed_radii.max()),
                                  "params": params.as_dict()})


def tilted_gravity(gravity: float, angle_deg: float) -> np.ndarray:
    """Gravity of magnitude ``g`` tilted by ``angle_deg`` so that +x is downhill."""
    angle = np.radians(angle_deg)
    return gravity * np.array([np.sin(angle), -np.cos(angle)])


def inclined_flow(settled: Scene, angle_deg: float, *, keep_velocities: bool = False) -> Scene:
    """The settled bed tilted by ``angle_deg``: gravity ``g (sin theta, -cos theta)``.

    The frame is the incline's: x along the slope (periodic), y normal to it.
    Velocities and spins are reset to zero unless ``keep_velocities``.
    """
    checks.require(settled.period is not None, "settled", "needs a periodic scene", None)
    scene = settled.copy()
    tilt(scene, angle_deg)
    if not keep_velocities:
        scene.grains.velocities[:] = 0.0
        scene.grains.spins[:] = 0.0
    scene.metadata["name"] = "inclined_flow"
    return scene


def widen(layer: Scene, copies: int, *, jitter: float = 0.0, seed: int = 0) -> Scene:
    """``copies`` copies of a periodic layer side by side: the same layer, ``copies`` times wider.

    Each copy keeps the grains' state (positions shifted by a multiple of the
    period, velocities, spins, angles) and its part of the rough bed, so a
    developed flow stays a developed flow: the benchmarks and the 2000-grain
    runs build large flows this way instead of waiting for each size's onset.
    The copies are identical until the dynamics separate them, which ``jitter``
    starts.

    Parameters
    ----------
    layer : Scene
        A periodic scene (``period`` set), e.g. a flow of :func:`inclined_flow`.
    copies : int
        Number of copies, >= 1.
    jitter : float
        Each velocity component of the wide layer gets a normal deviate of this many times
        the velocities' rms (dimensionless, >= 0; 0: none), so that the copies part (a layer
        at rest, rms 0, is not jittered: its copies stay identical).
    seed : int
        Seed of that jitter (``np.random.default_rng``).

    Returns
    -------
    Scene
        Period ``copies x period``; ``metadata["width"]`` updated, ``metadata["copies"]`` set.
    """
    copies = int(checks.positive("copies", copies, shape=()))
    jitter = float(checks.nonnegative("jitter", jitter, shape=()))
    checks.require(layer.period is not None, "layer", "needs a periodic scene", None)
    period = float(layer.period)
    grains = layer.grains

    def tiled(points: np.ndarray) -> np.ndarray:
        offsets = np.zeros((copies, 1, points.shape[1]))
        offsets[:, 0, 0] = period * np.arange(copies)
        return (points[None, :, :] + offsets).reshape(-1, points.shape[1])

    def repeated(values: np.ndarray | None) -> np.ndarray | None:
        return None if values is None else np.tile(values, (copies,) + (1,) * (values.ndim - 1))

    wide = Grains.create(tiled(grains.positions), repeated(grains.radii),
                         masses=repeated(grains.masses), densities=repeated(grains.densities),
                         velocities=repeated(grains.velocities), spins=repeated(grains.spins),
                         inertias=repeated(grains.inertias))
    wide.angles[:] = repeated(grains.angles)
    if jitter:
        rms = float(np.sqrt(np.mean(np.sum(wide.velocities**2, axis=1))))
        wide.velocities += jitter * rms * np.random.default_rng(seed).standard_normal(wide.velocities.shape)
    metadata = dict(layer.metadata, width=copies * period,
                    copies=copies * int(layer.metadata.get("copies", 1)))
    return Scene.create(wide, plane_points=layer.planes.points, plane_normals=layer.planes.normals,
                        fixed_positions=tiled(layer.fixed_positions),
                        fixed_radii=repeated(layer.fixed_radii), gravity=layer.gravity,
                        fluid_density=layer.fluid_density,
                        external_force=repeated(layer.external_force)
                        if isinstance(layer.external_force, np.ndarray) else layer.external_force,
                        time=layer.time, overlap_tolerance=layer.overlap_tolerance,
                        check_overlaps=False,      # the layer's own pairs, repeated: nothing new
                        metadata=metadata, period=copies * period,
                        plane_velocity=layer.plane_velocity, fixed_velocity=layer.fixed_velocity)


def tilt(scene: Scene, angle_deg: float) -> None:
    """Turn ``scene``'s gravity, in place, to the incline ``angle_deg`` (degrees, in (-90, 90)):
    ``g (sin theta, -cos theta)`` with ``g`` its magnitude; the angle goes to its metadata."""
    angle = float(checks.as_array("angle_deg", angle_deg, shape=()))
    checks.require(-90 < angle < 90, "angle_deg", "must be in (-90, 90)", angle)
    scene.gravity = tilted_gravity(float(np.linalg.norm(scene.gravity)), angle)
    scene.metadata["angle_deg"] = angle


def time_step(params: FlowParameters, fraction: float = 0.01) -> float:
    """A time step ``fraction x sqrt(d / g')``."""
    return fraction * params.time_scale

