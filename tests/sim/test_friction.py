"""Coulomb friction: laws, the fixed point on s, gluey + friction, against exact solutions."""
import numpy as np
import pytest

from lubcontact import Grains, Scene, Schedule, Simulation, find_contacts, scenes, solvers
from lubcontact.model.assemble import assemble
from lubcontact.model.laws import Coulomb, GlueyCoulomb
from lubcontact.problem.cones import ConeKind
from lubcontact.problem.metrics import coulomb_error, velocity_error
from lubcontact.solvers.coulomb import solve_coulomb
from lubcontact.solvers.reference import union_violation

FAST = "apgd"


def run(scene, law, dt, t_end, **options):
    sim = Simulation(scene, law, dt, d_max=0.05, **options)
    reports = []
    sim.run(int(round(t_end / dt)), callback=lambda s, report: reports.append(report))
    return sim.trajectory.arrays(), reports


def incline_frame(angle):
    downhill = np.array([np.cos(angle), -np.sin(angle)])
    normal = np.array([np.sin(angle), np.cos(angle)])
    return downhill, normal


def relative_error(value, exact):
    return np.max(np.abs(value - exact)) / np.max(np.abs(exact))


# -- laws ------------------------------------------------------------------------------------------
def test_coulomb_law_models_only_frictional_contacts():
    scene = scenes.settling_pile(12, seed=1)
    scene.grains.positions[:, 1] -= 0.1 * 0.5           # press the bottom row onto the floor
    contacts = find_contacts(scene, d_max=0.5)
    assert contacts.count > 3
    mu = np.where(contacts.body_a >= contacts.n_grains, 0.4, 0.0)      # friction on walls only
    cones = Coulomb(lambda c: mu).cones(contacts, np.zeros(contacts.count))
    np.testing.assert_array_equal(cones.tangential, np.flatnonzero(mu > 0))
    np.testing.assert_array_equal(cones.kinds, np.where(mu > 0, ConeKind.COULOMB, ConeKind.NONNEG))
    assert Coulomb(0.3).needs_rotation and not Coulomb(0.0).needs_rotation
    assert not Coulomb(0.0).cones(contacts, np.zeros(contacts.count)).has_friction
    with pytest.raises(ValueError, match="mu"):
        Coulomb(-0.1)
    with pytest.raises(ValueError, match="mu"):
        Coulomb(lambda c: np.full(c.count, -1.0)).cones(contacts, np.zeros(contacts.count))


def test_gluey_coulomb_cones_follow_the_glue_state():
    scene = scenes.two_grains(gap=0.0)
    contacts = find_contacts(scene, d_max=0.1)
    law = GlueyCoulomb(0.5, gamma_min=-1.0)
    kinds = {g: law.cones(contacts, np.array([g])) for g in (0.0, -0.5, -1.0)}
    assert kinds[0.0].kinds[0] == ConeKind.NONNEG and not kinds[0.0].has_friction
    assert kinds[-0.5].kinds[0] == ConeKind.FREE and not kinds[-0.5].has_friction
    assert kinds[-1.0].kinds[0] == ConeKind.UNION
    np.testing.assert_array_equal(kinds[-1.0].tangential, [0])
    assert not GlueyCoulomb(0.5).has_friction              # no roughness cap: never at gamma_min


# -- exact Coulomb solutions (docs/guide/model.md section 7) -------------------------------------------------
@pytest.mark.parametrize("mu, angle", [(0.5, np.pi / 4), (0.1, np.pi / 3)], ids=["rolling", "sliding"])
def test_disk_on_incline_matches_closed_form(mu, angle):
    dt, g, r, height = 1e-2, 1.0, 1.0, 0.05
    record, _ = run(scenes.disk_on_incline(angle, height=height), Coulomb(mu), dt, t_end=2.0,
                    solver=FAST, tol=1e-10)
    downhill, normal = incline_frame(angle)
    t = record["times"]
    along = record["velocities"][:, 0] @ downhill
    spin = record["spins"][:, 0, 0]
    position = (record["positions"][:, 0] - record["positions"][0, 0]) @ downhill
    t_imp = np.sqrt(2 * height / (g * np.cos(angle)))
    v_t, v_n = g * np.sin(angle) * t_imp, -g * np.cos(angle) * t_imp
    t2 = t - t_imp
    x_imp = g * np.sin(angle) * t_imp**2 / 2
    if np.tan(angle) <= 3 * mu:                          # rolling after impact
        exact_v = 2 / 3 * v_t + 2 / 3 * g * np.sin(angle) * t2
        exact_spin = -exact_v / r
        exact_x = x_imp + 2 / 3 * v_t * t2 + g * np.sin(angle) * t2**2 / 3
    else:                                                # sliding
        acceleration = g * (np.sin(angle) - mu * np.cos(angle))
        exact_v = v_t + mu * v_n + acceleration * t2
        exact_spin = (2 * mu * v_n - 2 * mu * g * np.cos(angle) * t2) / r
        exact_x = x_imp + (v_t + mu * v_n) * t2 + acceleration * t2**2 / 2
    after = t > t_imp + 2 * dt
    assert relative_error(along[after], exact_v[after]) <= 1e-3
    assert relative_error(spin[after], exact_spin[after]) <= 1e-3
    assert relative_error(position[after], exact_x[after]) <= 1e-2


def sliding_disk(mu_speed=2.0):
    grains = Grains.create([[0.0, 0.5]], 0.5, masses=1.0, velocities=[[mu_speed, 0.0]])
    return Scene.create(grains, plane_points=[0.0, 0.0], plane_normals=[0.0, 1.0], gravity=[0.0, -1.0])


def test_fixed_point_removes_dilatancy_of_a_sliding_disk():
    mu, dt = 0.3, 1e-2
    record, reports = run(sliding_disk(), Coulomb(mu), dt, t_end=1.0, tol_fp=1e-10, solver=FAST,
                          tol=1e-10)
    gaps = np.array([report.gaps_after[0] for report in reports])
    assert np.max(np.abs(gaps)) <= 1e-9
    assert all(report.result.fixed_point_converged for report in reports)
    speed = record["velocities"][:, 0, 0]
    np.testing.assert_allclose(speed, 2.0 - mu * record["times"], atol=1e-8)   # sliding all along


def test_convex_relaxation_lifts_by_mu_dt_slip():
    """Without the fixed point the sliding contact opens by ``mu dt |u_T|`` in one step."""
    mu, dt = 0.3, 1e-2
    record, reports = run(sliding_disk(), Coulomb(mu), dt, t_end=0.3, fixed_point=False)
    first = reports[0]
    slip = dt * (first.problem.jacobian[1] @ first.result.velocities)[0]        # dt u_T
    assert abs(slip) > 0.01
    assert first.gaps_after[0] == pytest.approx(mu * abs(slip), abs=1e-9)
    assert record["velocities"][1, 0, 1] == pytest.approx(mu * abs(slip) / dt, rel=1e-7)
    # and the disk keeps the normal velocity mu |u_T|: it takes off
    later = [report for report in reports[1:] if report.contacts.count]
    assert all(report.result.forces[0] < 1e-6 for report in later)
    assert record["positions"][-1, 0, 1] - 0.5 > 0.05


def test_a_native_coulomb_method_has_no_relaxation_to_fall_into():
    """newton-ac solves exact Coulomb itself: with fixed_point=False it still does (one native
    solve, checked at its own shift), where a convex method lifts the disk by mu dt |u_T|."""
    mu, dt = 0.3, 1e-2
    record, reports = run(sliding_disk(), Coulomb(mu), dt, t_end=0.3, fixed_point=False,
                          solver="newton-ac", tol=1e-10)
    assert all(report.result.status == "converged" for report in reports)
    assert all(report.result.outer_iterations == 1 for report in reports)
    assert np.max(np.abs([report.gaps_after[0] for report in reports])) <= 1e-9
    assert abs(record["positions"][-1, 0, 1] - 0.5) <= 1e-9


def test_fixed_point_reports_non_convergence():
    grains = Grains.create([[0.0, 0.5]], 0.5, masses=1.0, velocities=[[2.0, 0.0]])
    scene = Scene.create(grains, plane_points=[0.0, 0.0], plane_normals=[0.0, 1.0],
                         gravity=[0.0, -1.0])
    sim = Simulation(scene, Coulomb(0.5), 1e-2, d_max=0.05)
    contacts = find_contacts(sim.scene, 0.05)
    problem = assemble(sim.scene, contacts, sim.law.cones(contacts, np.zeros(contacts.count)), sim.dt,
                       rotations=sim.law.needs_rotation)
    capped = solve_coulomb(problem, "clarabel", max_outer=1)
    assert capped.status == solvers.MAX_ITER and not capped.fixed_point_converged
    assert capped.outer_iterations == 1 and capped.shift_change > 1e-3
    full = solve_coulomb(problem, "clarabel", tol_fp=1e-10)
    assert full.success and full.shift_change < 1e-10
    assert coulomb_error(problem.normalized(), full.forces / full.force_scale) < 1e-8
    assert coulomb_error(problem.normalized(), capped.forces / capped.force_scale) > 1e-4


# -- gluey + friction ------------------------------------------------------------------------------
def gluey_friction_closed_form(t, angle, mu, gamma_min, t_inv, g=1.0, r=1.0):
    """Velocity (downhill, normal) and spin of docs/guide/model.md section 7's gluey + friction disk
    (unit mass)."""
    sin, cos = np.sin(angle), np.cos(angle)
    t_friction = -gamma_min / (g * cos)
    t_unstick = t_inv - gamma_min / (g * cos)
    assert t_friction < t_inv < t_friction + g * sin * t_friction / (g * (3 * mu * cos - sin))
    friction_time = np.clip(t, t_friction, t_inv) - t_friction      # sliding with friction
    along = g * sin * np.minimum(t, t_inv) - mu * g * cos * friction_time \
        - g * sin * np.maximum(t - t_inv, 0.0)
    spin = -2 * mu * g * cos * friction_time / r
    normal = g * cos * np.maximum(t - t_unstick, 0.0)
    return along, normal, spin


def test_gluey_friction_disk_on_incline_with_force_reversed():
    angle, mu, gamma_min, t_inv, dt = np.pi / 4, 0.5, -1.4, 5.0, 1e-2
    scene = scenes.disk_on_incline(angle, height=0.05, t_inversion=t_inv)
    record, reports = run(scene, GlueyCoulomb(mu, gamma_min=gamma_min), dt, t_end=7.5, solver=FAST,
                          tol=1e-10)
    downhill, normal = incline_frame(angle)
    t = record["times"]
    along = record["velocities"][:, 0] @ downhill
    off = record["velocities"][:, 0] @ normal
    spin = record["spins"][:, 0, 0]
    exact_along, exact_off, exact_spin = gluey_friction_closed_form(t, angle, mu, gamma_min, t_inv)
    after = t > 0.5                                   # past the impact at t = 0.376
    assert relative_error(along[after], exact_along[after]) <= 1e-3
    assert relative_error(spin[after], exact_spin[after]) <= 1e-3
    assert relative_error(off[after], exact_off[after]) <= 1e-3
    kinds = [report.problem.cones.kinds[0] for report in reports if report.contacts.count]
    assert ConeKind.UNION in kinds and ConeKind.FREE in kinds


def test_branch_rule_flips_a_pulled_contact():
    """Reference on a UNION contact: the warm start suggests pushing, the optimum pulls."""
    normal = np.array([1.0, 1.0]) / np.sqrt(2.0)
    grains = Grains.create([normal], 1.0, masses=1.0)
    scene = Scene.create(grains, plane_points=[0.0, 0.0], plane_normals=normal,
                         external_force=[0.0, 1.0])                              # pulls away
    sim = Simulation(scene, GlueyCoulomb(0.5, gamma_min=-1.0), 1e-2, d_max=0.05)
    contacts = find_contacts(sim.scene, 0.05)
    problem = assemble(sim.scene, contacts, sim.law.cones(contacts, np.array([-1.0])), sim.dt,
                       rotations=sim.law.needs_rotation)
    assert problem.cones.kinds[0] == ConeKind.UNION
    pushed_guess = np.array([1.0, 0.0])
    reference = solvers.solve(problem, "clarabel", tol=1e-10, warm_start=pushed_guess)
    assert reference.success and reference.info["branch_rounds"] == 2
    assert reference.forces[0] < 0 and reference.forces[1] == pytest.approx(0.0, abs=1e-12)
    assert np.max(union_violation(problem.normalized(), reference.forces / reference.force_scale)) < 1e-7
    fast = solvers.solve(problem, FAST, tol=1e-10, warm_start=pushed_guess)
    np.testing.assert_allclose(fast.forces, reference.forces, rtol=1e-7, atol=1e-10)


def swirling_trio() -> Scene:
    """Three disks pushed together off-centre (they slide and spin), then pulled apart."""
    angles = np.pi / 2 + np.arange(3) * 2 * np.pi / 3
    radial = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    swirl = np.stack([-radial[:, 1], radial[:, 0]], axis=1)
    grains = Grains.create(0.5 / np.cos(np.pi / 6) * 1.02 * radial, 0.5, masses=1.0)
    push = -radial + 0.4 * swirl
    return Scene.create(grains, external_force=Schedule(times=(0.0, 0.6), values=(push, 0.5 * radial)))


def test_trio_with_glue_and_friction_clarabel_and_fast_agree():
    law = GlueyCoulomb(0.5, gamma_min=-0.05)
    runs = {method: run(swirling_trio(), law, 1e-2, t_end=1.2, solver=method, tol=1e-10)
            for method in ("clarabel", FAST)}
    (reference, ref_reports), (fast, _) = runs["clarabel"], runs[FAST]
    kinds = np.concatenate([report.problem.cones.kinds for report in ref_reports])
    assert {ConeKind.UNION, ConeKind.FREE} <= set(kinds.tolist())
    assert np.max(np.abs(reference["spins"])) > 0.05          # friction did act
    for field in ("positions", "velocities", "spins"):
        np.testing.assert_allclose(fast[field], reference[field], atol=1e-6, rtol=0)


# -- joint fixed point (shift updated inside APGD) ------------------------------------------------
@pytest.mark.parametrize("joint", [0, 1, 5])
def test_joint_fixed_point_matches_clarabel(settling_step, joint):
    """The joint phase solves Coulomb's problem inside APGD; the outer loop then checks it with
    the shift frozen (one inner solve accepting its warm start, one at the final tolerance)."""
    problem, reference = settling_step
    result = solve_coulomb(problem, "apgd-jacobi", tol=1e-9, tol_fp=1e-9, forcing=1e-4, joint=joint)
    assert result.success and result.fixed_point_converged
    assert velocity_error(problem, result.velocities, reference.velocities) <= 1e-6
    assert coulomb_error(problem.normalized(), result.forces / result.force_scale) <= 1e-7
    if joint:
        assert result.joint_iterations > 0 and result.outer_iterations == 2
        assert result.shift_change <= 1e-9
    else:
        assert result.joint_iterations == 0 and result.outer_iterations > 2


def test_joint_phase_stops_honestly_when_capped(settling_step):
    """A joint phase cut short leaves the outer loop to finish (or to report max_iter)."""
    problem, _ = settling_step
    capped = solve_coulomb(problem, "apgd-jacobi", tol=1e-9, tol_fp=1e-9, joint=1, max_iter=10,
                           max_outer=3)
    assert capped.status == solvers.MAX_ITER and not capped.fixed_point_converged
    assert coulomb_error(problem.normalized(), capped.forces / capped.force_scale) > 1e-7
