"""The hard cases: named step problems that stress a solver's numerics.

Each :class:`HardCase` says what makes it hard, what a correct solver must
return and, where it is known in closed form, the exact velocities after the
step (``exact``). All cases are dimensionless (``g = 1``, radius 0.5 unless
said otherwise, natural time ``sqrt(r / g)``). ``lubcontact check-hard`` and
``tests/test_hard_cases.py`` run every registered solver on every case.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike

from lubcontact import GlueyLubrication, Grains, Inelastic, Law, Scene, StepProblem, solve
from lubcontact.model.laws import GlueyCoulomb
from lubcontact.model.scene import inclined_plane_normal
from lubcontact.problem.metrics import coulomb_shift

from .builders import ExplicitFriction, floor_scene, hexagonal_box, loose_pile, pyramid, scene_problem

NATURAL_TIME = np.sqrt(0.5)         # sqrt(r / g) for r = 0.5, g = 1


@dataclass(frozen=True)
class HardCase:
    """One hard step problem.

    Attributes
    ----------
    name : str
    hard : str
        What makes it hard.
    expected : str
        The behaviour a correct solver shows.
    build : callable () -> StepProblem
    exact : callable (StepProblem) -> ndarray (n_dof,), optional
        Exact velocities after the step, when known.
    reference_fails : bool
        Clarabel (``clarabel``, tol 1e-10) is known to be wrong here while
        reporting convergence (docs/records/hard_cases.md, findings); such a case must
        have ``exact``. Every case with ``exact`` is checked against it, never
        against Clarabel.
    must_flag : bool
        The problem has no solution (primal infeasible, dual unbounded): every
        method must return a non-converged status.
    """

    name: str
    hard: str
    expected: str
    build: Callable[[], StepProblem]
    exact: Callable[[StepProblem], np.ndarray] | None = None
    reference_fails: bool = False
    must_flag: bool = False

    @cached_property
    def problem(self) -> StepProblem:
        return self.build()


# -- exact answers --------------------------------------------------------------------------------
def _at_rest(problem: StepProblem) -> np.ndarray:
    return np.zeros(problem.n_dof)


def _translations(values: ArrayLike, rotations: int = 0) -> Callable[[StepProblem], np.ndarray]:
    """Exact answer given per grain (translations), with ``rotations`` zero spins per grain."""
    values = np.asarray(values, dtype=float)
    return lambda problem: np.concatenate([values.ravel(), np.zeros(values.shape[0] * rotations)])


# -- mass and radius ratios -----------------------------------------------------------------------
def _mass_ratio_collision() -> StepProblem:
    positions = [[0.0, 0.0], [1.0, 0.0], [0.0, 3.0], [1.0, 3.0]]
    grains = Grains.create(positions, 0.5, masses=[1e6, 1.0, 1.0, 1e6],
                           velocities=[[1.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 0.0]])
    return scene_problem(Scene.create(grains), Inelastic(), 0.01)


def _mass_ratio_sandwich() -> StepProblem:
    scene = floor_scene([[0.0, 0.5], [0.0, 1.5]], 0.5, masses=[1.0, 1e6])
    return scene_problem(scene, Inelastic(), 0.01 * NATURAL_TIME)


def _pebble_on_boulder(law: Law) -> StepProblem:
    boulder, pebble, angle = 1.0, 0.01, np.radians(20.0)
    centre = np.array([0.0, boulder])
    on_top = centre + (boulder + pebble) * np.array([np.sin(angle), np.cos(angle)])
    scene = floor_scene([centre, on_top], [boulder, pebble], densities=1.0)
    return scene_problem(scene, law, 0.01 * np.sqrt(pebble))


def _heavy_on_light_stack() -> StepProblem:
    light = [[0.5, 0.5 + k] for k in range(6)]
    positions = light + [[0.5, 6.5]] + [[3.0, 0.5 + k] for k in range(6)]
    masses = [1.0] * 6 + [1e4] + [1.0] * 6
    return scene_problem(floor_scene(positions, 0.5, masses=masses), Inelastic(), 0.01 * NATURAL_TIME)


# -- friction coefficients ------------------------------------------------------------------------
def _pyramid_scene() -> Scene:
    centres = pyramid(4)
    velocities = 0.3 * np.random.default_rng(7).normal(size=centres.shape)
    return floor_scene(centres, 0.5, masses=1.0, velocities=velocities)


def _frictionless_pyramid_answer(problem: StepProblem) -> np.ndarray:
    """mu = 0 must give the frictionless velocities and untouched (zero) spins."""
    frictionless = scene_problem(_pyramid_scene(), Inelastic(), 0.01)
    translations = solve(frictionless, "clarabel", tol=1e-10).velocities
    return np.concatenate([translations, np.zeros(problem.n_dof - translations.size)])


# -- over-constrained packings and wedges ---------------------------------------------------------
def _hexagonal_box(law: Law, lid: bool) -> StepProblem:
    centres, width, top = hexagonal_box(6, 6)
    scene = floor_scene(centres, 0.5, masses=1.0, walls=(0.0, width), lid=top if lid else None)
    return scene_problem(scene, law, 0.01 * NATURAL_TIME)


def _wedge_planes(law: Law, half_angle: float = 1e-3) -> StepProblem:
    radius = 1.0
    normals = [[np.cos(half_angle), np.sin(half_angle)], [-np.cos(half_angle), np.sin(half_angle)]]
    grains = Grains.create([[0.0, radius / np.sin(half_angle)]], radius, masses=1.0)
    scene = Scene.create(grains, plane_points=np.zeros((2, 2)), plane_normals=normals,
                         gravity=[0.0, -1.0])
    return scene_problem(scene, law, 0.01)


def _wedge_grains(half_angle: float = 1e-3) -> StepProblem:
    grains = Grains.create([[0.0, 2.0 * np.sin(half_angle)]], 1.0, masses=1.0)
    x = 2.0 * np.cos(half_angle)
    scene = Scene.create(grains, fixed_positions=[[-x, 0.0], [x, 0.0]], fixed_radii=1.0,
                         gravity=[0.0, -1.0])
    return scene_problem(scene, Inelastic(), 0.01)


def _hexagonal_box_glued() -> StepProblem:
    centres, width, _ = hexagonal_box(6, 6)
    scene = floor_scene(centres, 0.5, masses=1.0, walls=(0.0, width))
    law, dt = GlueyLubrication(), 0.01 * NATURAL_TIME
    count = scene_problem(scene, law, dt).n_contacts
    return scene_problem(scene, law, dt, gamma=np.full(count, -0.5))


def _glued_between_walls() -> StepProblem:
    scene = floor_scene([[0.0, 0.51]], 0.5, masses=1.0, lid=1.02)
    return scene_problem(scene, GlueyLubrication(), 0.01, d_max=0.05, gamma=[-0.5, -0.5])


# -- glued chains -----------------------------------------------------------------------------------
CHAIN_FREE, CHAIN_ANCHORED, CHAIN_DT = 40, 100, 0.01


def _glued_chain(count: int, anchored: bool) -> StepProblem:
    positions = np.stack([0.5 + np.arange(count), np.zeros(count)], axis=1)
    pull = np.zeros((count, 2))
    pull[-1, 0] = 1.0
    grains = Grains.create(positions, 0.5, masses=1.0)
    planes = dict(plane_points=[[0.0, 0.0]], plane_normals=[[1.0, 0.0]]) if anchored else {}
    scene = Scene.create(grains, external_force=pull, **planes)
    contacts = count - 1 + int(anchored)
    return scene_problem(scene, GlueyLubrication(), CHAIN_DT, gamma=np.full(contacts, -1.0))


# -- gluey states -------------------------------------------------------------------------------------
GAMMA_MIN, GAMMA_NEAR = -1.0, 1e-9
#: per grain (one floor contact each): gamma, free velocity (x, y)
GAMMA_STATES = [
    (0.0, (0.3, -1.0)),                  # unglued, pushed: stops
    (0.0, (0.3, 1.0)),                   # unglued, pulled: leaves
    (-GAMMA_NEAR, (0.3, 1.0)),           # glued within the snapping tolerance of 0: held
    (-0.5, (0.0, -1.0)),                 # glued: held
    (GAMMA_MIN + GAMMA_NEAR, (0.3, 1.0)),  # glued just above gamma_min: held, frictionless
    (GAMMA_MIN, (0.0, -1.0)),            # at gamma_min, pushed, no slip: cone apex
    (GAMMA_MIN, (0.3, 1.0)),             # at gamma_min, pulled: bilateral, frictionless
    (GAMMA_MIN, (0.3, -1.0)),            # at gamma_min, pushed while sliding: rolls (mu = 0.5)
]


def _gamma_states(law: Law) -> StepProblem:
    count = len(GAMMA_STATES)
    positions = np.stack([2.0 * np.arange(count), np.full(count, 0.5)], axis=1)
    velocities = [v for _, v in GAMMA_STATES]
    scene = floor_scene(positions, 0.5, masses=1.0, velocities=velocities, gravity=0.0)
    return scene_problem(scene, law, 0.01, gamma=np.array([g for g, _ in GAMMA_STATES]))


def _gamma_states_exact(friction: bool) -> Callable[[StepProblem], np.ndarray]:
    held_x = [0.3, 0.3, 0.3, 0.0, 0.3, 0.0, 0.3, 0.3]
    velocities = np.stack([held_x, [0.0, 1.0, 0, 0, 0, 0, 0, 0]], axis=1)
    if not friction:
        return _translations(velocities)
    velocities[7, 0] = 0.2                         # rolling: v = 2/3 U_t, spin = -v / r
    spins = np.zeros(len(GAMMA_STATES))
    spins[7] = -0.2 / 0.5
    return lambda problem: np.concatenate([velocities.ravel(), spins])


# -- cone apex ----------------------------------------------------------------------------------------
def _cone_apex(dim: int) -> StepProblem:
    positions = np.zeros((3, dim))
    positions[:, 0] = [0.0, 2.0, 4.0]
    positions[:, 1] = 0.5
    velocities = np.zeros((3, dim))
    velocities[1, 0] = 1.0                         # sliding with zero normal force
    velocities[2, 1] = -1.0                        # pushed with zero slip
    if dim == 3:
        velocities[1, 2] = 0.5
    scene = floor_scene(positions, 0.5, masses=1.0, velocities=velocities, gravity=0.0)
    problem = scene_problem(scene, ExplicitFriction(0.5), 0.01)
    # the shift of exact Coulomb friction at the solution (zero forces): s = mu dt |u_T(U)|
    return problem.with_shift(coulomb_shift(problem, np.zeros(problem.n_rows)))


def _cone_apex_exact(dim: int) -> Callable[[StepProblem], np.ndarray]:
    velocities = np.zeros((3, dim))
    velocities[1, 0] = 1.0
    if dim == 3:
        velocities[1, 2] = 0.5
    return _translations(velocities, rotations=1 if dim == 2 else 3)


# -- time steps, contact counts, overlap --------------------------------------------------------------
def _loose_pile(dt_over_natural: float, law: Law) -> StepProblem:
    centres, radii, velocities = loose_pile(15, seed=4)
    scene = floor_scene(centres, radii, densities=1.0, velocities=velocities)
    return scene_problem(scene, law, dt_over_natural * NATURAL_TIME)


def _zero_contacts() -> StepProblem:
    scene = floor_scene([[0.0, 10.0]], 0.5, masses=1.0, velocities=[[0.2, -1.0]])
    return scene_problem(scene, Inelastic(), 0.01)


SINGLE_NORMAL = inclined_plane_normal(np.pi / 6)
SINGLE_GAP, SINGLE_DT = 0.05, 0.1
SINGLE_FREE = -1.0 * SINGLE_NORMAL + 0.5 * np.array([SINGLE_NORMAL[1], -SINGLE_NORMAL[0]])


def _single_contact() -> StepProblem:
    grains = Grains.create([(0.5 + SINGLE_GAP) * SINGLE_NORMAL], 0.5, masses=1.0,
                           velocities=[SINGLE_FREE])
    scene = Scene.create(grains, plane_points=[0.0, 0.0], plane_normals=SINGLE_NORMAL)
    return scene_problem(scene, Inelastic(), SINGLE_DT, d_max=0.1)


def _single_contact_exact(problem: StepProblem) -> np.ndarray:
    normal_speed = max(SINGLE_FREE @ SINGLE_NORMAL, -SINGLE_GAP / SINGLE_DT)
    return SINGLE_FREE + (normal_speed - SINGLE_FREE @ SINGLE_NORMAL) * SINGLE_NORMAL


# Scene's default overlap_tolerance x radius, less 1e-6 of it: at exactly the limit the rounding
# of |x_j - x_i| - r_i - r_j decides whether Scene.create accepts the scene
OVERLAP, OVERLAP_DT = (1.0 - 1e-6) * 1e-6 * 0.5, 0.01


def _overlap_at_limit() -> StepProblem:
    positions = [[0.0, 3.0], [1.0 - OVERLAP, 3.0], [5.0, 0.5 - OVERLAP]]
    grains = Grains.create(positions, 0.5, masses=[1.0, 3.0, 1.0])
    scene = Scene.create(grains, plane_points=[0.0, 0.0], plane_normals=[0.0, 1.0])
    return scene_problem(scene, Inelastic(), OVERLAP_DT)


def _overlap_exact(problem: StepProblem) -> np.ndarray:
    closing = OVERLAP / OVERLAP_DT                 # relative normal speed that closes the overlap
    return np.array([-0.75 * closing, 0.0, 0.25 * closing, 0.0, 0.0, closing])


def _tetrahedron_3d() -> StepProblem:
    r = 0.5
    base = np.array([[0.0, r, 0.0], [2 * r, r, 0.0], [r, r, np.sqrt(3.0) * r]])
    top = base.mean(axis=0) + [0.0, 2 * r * np.sqrt(2.0 / 3.0), 0.0]
    centres = np.vstack([base, top])
    velocities = 0.3 * np.random.default_rng(11).normal(size=centres.shape)
    scene = floor_scene(centres, r, masses=1.0, velocities=velocities)
    return scene_problem(scene, ExplicitFriction(0.3), 0.01 * NATURAL_TIME)


def _chain_exact(problem: StepProblem) -> np.ndarray:
    velocities = np.zeros((CHAIN_FREE, 2))
    velocities[:, 0] = CHAIN_DT / CHAIN_FREE        # F dt / (N m): the chain moves as one body
    return velocities.ravel()


CASES: dict[str, HardCase] = {case.name: case for case in [
    HardCase("mass_ratio_1e6_collision",
             "two touching pairs with masses 1e6 : 1 (heavy hits light, light hits heavy); "
             "the scaled Delassus diagonal spans 6 decades",
             "perfectly inelastic impacts: each pair moves at its centre-of-mass velocity",
             _mass_ratio_collision,
             _translations([[1e6 / (1e6 + 1), 0.0]] * 2 + [[1.0 / (1e6 + 1), 0.0]] * 2)),
    HardCase("mass_ratio_1e6_sandwich",
             "a 1e6-mass grain resting on a unit-mass grain on the floor: W has condition ~1e6",
             "everything stays at rest", _mass_ratio_sandwich, _at_rest),
    HardCase("radius_ratio_100",
             "a pebble (r = 0.01) on a boulder (r = 1) 20 degrees off the top, densities equal "
             "(mass ratio 1e4), dt = 0.01 sqrt(r_pebble / g)",
             "boulder held by the floor; the pebble slides along the boulder without penetrating",
             lambda: _pebble_on_boulder(Inelastic())),
    HardCase("radius_ratio_100_friction", "the pebble on the boulder with mu = 0.5 (2D friction cones)",
             "the pebble sticks or rolls; forces inside the cones",
             lambda: _pebble_on_boulder(ExplicitFriction(0.5))),
    HardCase("heavy_on_light_stack",
             "a 1e4-mass grain on a column of unit grains next to a column of unit grains: "
             "contact forces from 1 to 1e4 in one problem",
             "everything stays at rest", _heavy_on_light_stack, _at_rest),
    HardCase("mu_zero_friction",
             "a 10-disk pyramid with random velocities, friction written with mu = 0: "
             "degenerate cones (norm of lam_T <= 0 x lam_n) (tangential rows that must vanish)",
             "the frictionless answer, spins untouched", lambda: scene_problem(
                 _pyramid_scene(), ExplicitFriction(0.0), 0.01), _frictionless_pyramid_answer),
    HardCase("mu_ten", "the same pyramid with mu = 10: wide cones, nearly sticking everywhere",
             "forces inside the cones, no penetration",
             lambda: scene_problem(_pyramid_scene(), ExplicitFriction(10.0), 0.01)),
    HardCase("hex_box_jammed",
             "33 disks in a hexagonal packing filling a box: 89 contacts for 66 unknowns, "
             "rank-deficient W, forces not unique",
             "everything stays at rest (velocities are unique, forces are not)",
             lambda: _hexagonal_box(Inelastic(), lid=False), _at_rest),
    HardCase("hex_box_lid_friction",
             "the hexagonal packing closed by a lid, mu = 0.3: every grain over-constrained, "
             "3 rows per contact",
             "everything stays at rest", lambda: _hexagonal_box(ExplicitFriction(0.3), lid=True),
             _at_rest),
    HardCase("hex_box_glued",
             "the hexagonal packing with every contact glued: 89 equality rows for 66 unknowns "
             "(H rank-deficient) and gaps that are zero only to rounding (+/- 2e-16)",
             "everything stays at rest", _hexagonal_box_glued, _at_rest),
    HardCase("glued_infeasible",
             "a disk glued to the floor and to a lid, 0.01 from each: both gaps cannot close "
             "(primal infeasible, dual unbounded)",
             "no method converges: every status is non-converged, forces finite",
             _glued_between_walls, must_flag=True),
    HardCase("wedge_planes",
             "a disk wedged in a V of half-angle 1e-3 rad: near-antiparallel normals, "
             "W nearly singular, forces ~500 m g",
             "the disk stays at rest", lambda: _wedge_planes(Inelastic()), _at_rest),
    HardCase("wedge_planes_friction", "the narrow V with mu = 0.3",
             "the disk stays at rest", lambda: _wedge_planes(ExplicitFriction(0.3)), _at_rest),
    HardCase("wedge_grains",
             "a disk wedged between two fixed disks whose normals are 1e-3 rad from antiparallel",
             "the disk stays at rest", _wedge_grains, _at_rest),
    HardCase("glued_chain_free",
             f"{CHAIN_FREE} disks glued in a line (bilateral), pulled at one end: "
             "tridiagonal W with condition ~N^2",
             "the chain moves as one body at F dt / (N m)",
             lambda: _glued_chain(CHAIN_FREE, anchored=False), _chain_exact),
    HardCase("glued_chain_anchored",
             f"{CHAIN_ANCHORED} glued disks, the first glued to a wall, pulled at the other end",
             "nothing moves", lambda: _glued_chain(CHAIN_ANCHORED, anchored=True), _at_rest),
    HardCase("gamma_states_gluey_coulomb",
             "gamma exactly 0, 1e-9 below 0, inside, 1e-9 above gamma_min and at gamma_min "
             "(GlueyCoulomb mu = 0.5): NONNEG, FREE and non-convex UNION contacts, pushed and pulled",
             "unglued: one-sided; glued: held; at gamma_min: Coulomb when pushed (the slipping "
             "disk rolls, v = 2/3 U_t), bilateral frictionless when pulled",
             lambda: _gamma_states(GlueyCoulomb(0.5, GAMMA_MIN)), _gamma_states_exact(True)),
    HardCase("gamma_states_lubricated",
             "the same gamma states with GlueyLubrication (at gamma_min: bilateral)",
             "unglued: one-sided; every glued contact held, tangential motion free",
             lambda: _gamma_states(GlueyLubrication(GAMMA_MIN)), _gamma_states_exact(False)),
    HardCase("cone_apex_2d",
             "frictional contacts with exactly zero normal force and/or exactly zero slip: "
             "the apex of the cone, where the projection is not differentiable",
             "exact Coulomb (the problem carries the fixed point's shift s = mu dt norm(u_T)): "
             "the sliding disk keeps its velocity, the pushed one stops, nothing spins",
             lambda: _cone_apex(2), _cone_apex_exact(2), reference_fails=True),
    HardCase("cone_apex_3d", "the cone apex with spheres (second-order cones)",
             "as in 2D", lambda: _cone_apex(3), _cone_apex_exact(3), reference_fails=True),
    HardCase("dt_tiny", "a 15-disk loose pile with random velocities at dt = 1e-6 sqrt(r/g): "
             "gaps ~1e5 times the step's travel", "almost every contact inactive",
             lambda: _loose_pile(1e-6, Inelastic())),
    HardCase("dt_large", "the loose pile at dt = 0.1 sqrt(r/g): most gaps close within the step",
             "many contacts active, no penetration", lambda: _loose_pile(0.1, Inelastic())),
    HardCase("dt_large_friction", "the loose pile at dt = 0.1 sqrt(r/g) with mu = 0.3",
             "forces inside the cones, no penetration",
             lambda: _loose_pile(0.1, ExplicitFriction(0.3))),
    HardCase("zero_contacts", "no contact at all: empty force vector", "v = U",
             _zero_contacts, lambda problem: problem.free_velocity.copy()),
    HardCase("single_contact",
             "one disk approaching a 30 degree incline that it reaches within the step",
             "v_n = max(U_n, -D / dt), tangential velocity kept", _single_contact,
             _single_contact_exact),
    HardCase("overlap_at_limit",
             "a pair and a disk on the floor overlapping by the allowed 1e-6 r (less 1e-12 r, "
             "below the rounding of the overlap check): D < 0",
             "the overlap closes in one step with momentum conserved", _overlap_at_limit,
             _overlap_exact),
    HardCase("tetrahedron_3d_friction",
             "four spheres in a tetrahedron on the floor, random velocities, mu = 0.3 "
             "(3D second-order cones)", "forces inside the cones, no penetration", _tetrahedron_3d),
]}
