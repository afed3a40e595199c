"""Obstacles with a prescribed velocity: a lifting floor, a conveyor belt, squeezing plates."""
import pytest

from lubcontact import Coulomb, Grains, Inelastic, Scene, Schedule, Simulation, SolverWarning


def _disk_on_floor(**scene):
    grains = Grains.create(positions=[[0.0, 0.5]], radii=0.5, masses=1.0)
    return Scene.create(grains, plane_points=[0.0, 0.0], plane_normals=[0.0, 1.0],
                        gravity=[0.0, -1.0], **scene)


def test_a_rising_floor_carries_the_disk():
    sim = Simulation(_disk_on_floor(plane_velocity=[0.0, 1.0]), Inelastic(), dt=0.01,
                     solver="apgd-as")
    sim.run(100)
    assert sim.scene.planes.points[0, 1] == pytest.approx(1.0)            # the floor moved 100 dt
    assert sim.scene.grains.velocities[0, 1] == pytest.approx(1.0, abs=1e-9)
    assert sim.scene.grains.positions[0, 1] == pytest.approx(1.5, abs=1e-8)
    assert sim.trajectory.min_gap[-1] >= -1e-9


def test_a_conveyor_belt_spins_a_disk_up_to_rolling():
    """Belt at V = 1 under a disk at rest (mu = 0.5, g = 1, r = 0.5): friction mu m g slides it
    until v + omega r = V at t* = V / (3 mu g); then it rolls with v = V / 3, omega = 2 V / (3 r)."""
    belt, mu, dt = 1.0, 0.5, 4e-3
    sim = Simulation(_disk_on_floor(plane_velocity=[belt, 0.0]), Coulomb(mu), dt=dt,
                     solver="apgd", tol=1e-10, tol_fp=1e-10)
    sim.run(250)                                                          # t = 1 > t* = 2/3
    v, omega = sim.scene.grains.velocities[0, 0], sim.scene.grains.spins[0, 0]
    assert v == pytest.approx(belt / 3, abs=2e-3)
    assert omega == pytest.approx(2 * belt / (3 * 0.5), abs=4e-3)
    assert v + omega * 0.5 == pytest.approx(belt, abs=1e-8)               # no slip at the belt
    assert abs(sim.scene.grains.positions[0, 1] - 0.5) <= 1e-8            # no lift-off


def test_a_piston_launches_the_disk_when_it_stops():
    """The floor rises at 1 until t = 0.5 and stops; the disk leaves it with v = 1 and flies:
    v(t) = 1 - (t - 0.5), y(t) = 1 + (t - 0.5) - (t - 0.5)^2 / 2 (g = 1)."""
    piston = Schedule(times=(0.0, 0.5), values=([0.0, 1.0], [0.0, 0.0]))
    sim = Simulation(_disk_on_floor(plane_velocity=piston), Inelastic(), dt=2e-3, solver="apgd-as")
    sim.run(250)
    assert sim.scene.planes.points[0, 1] == pytest.approx(0.5)
    sim.run(250)
    assert sim.scene.planes.points[0, 1] == pytest.approx(0.5)            # stopped
    assert sim.scene.grains.velocities[0, 1] == pytest.approx(0.5, abs=2e-3)
    assert sim.scene.grains.positions[0, 1] == pytest.approx(1.375, abs=2e-3)
    assert sim.trajectory.contact_count[-1] == 0                          # in flight


def test_prescribed_velocities_are_checked():
    with pytest.raises(ValueError, match="plane_velocity: cannot broadcast"):
        _disk_on_floor(plane_velocity=[1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="fixed_velocity"):
        _disk_on_floor(fixed_velocity="fast")


def test_a_fast_grain_hitting_a_pile_is_always_a_candidate_contact():
    """A grain at speed 20 moves 1.0 per step (dt = 0.05), twenty times d_max = 0.05, into a
    3-grain pile. The search distance of each step covers the step (Simulation.search_distance):
    no pair is missed, nothing overlaps, and the grain stops on the pile (inelastic)."""
    grains = Grains.create(positions=[[-2.0, 0.5], [1.6, 0.5], [2.6, 0.5], [2.1, 1.3670]], radii=0.5,
                           masses=1.0, velocities=[[20.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    scene = Scene.create(grains)
    sim = Simulation(scene, Inelastic(), dt=0.05, d_max=0.05, solver="clarabel")
    assert sim.search_distance() == pytest.approx(1.5 * 0.05 * 2 * 20.0)
    sim.run(6)
    assert sim.trajectory.missed_contacts == []
    assert min(sim.trajectory.min_gap) >= -1e-9
    assert sim.scene.grains.velocities[0, 0] < 20.0 / 3        # it hit the pile and gave it momentum
    settled = Simulation(Scene.create(Grains.create(positions=[[0.0, 0.5]], radii=0.5, masses=1.0)),
                         Inelastic(), dt=0.05, d_max=0.05)
    assert settled.search_distance() == 0.05                    # at rest: d_max, not wider


def test_a_pair_missed_by_a_force_the_speed_bound_cannot_see_is_reported():
    """An external force of 400 takes a grain at rest to speed 20 within one step: the speed bound
    (current speeds and gravity) cannot foresee it; the step says so instead of staying silent."""
    grains = Grains.create(positions=[[0.0, 0.5], [1.6, 0.5]], radii=0.5, masses=1.0)
    scene = Scene.create(grains, external_force=[[400.0, 0.0], [0.0, 0.0]])
    sim = Simulation(scene, Inelastic(), dt=0.05, d_max=0.05, solver="apgd-as")
    with pytest.warns(SolverWarning, match="pairs overlapped that were not candidate contacts"):
        sim.step()
    (step, count, depth), = sim.trajectory.missed_contacts
    assert (step, count) == (1, 1) and depth == pytest.approx(0.8)   # 1.0 - 0.6 gap = 0.4, r 0.5
