"""SimulationState: a checkpoint is the state as arrays, and a restored run continues bit for bit."""
import numpy as np
import pytest

from lubcontact import (
    Coulomb,
    GlueyCoulomb,
    GlueyLubrication,
    Grains,
    Inelastic,
    Scene,
    Simulation,
    SimulationState,
    SolverWarning,
    scenes,
)
from lubcontact.problem.cones import ConeKind, Cones


def _simulation():
    return Simulation(scenes.settling_pile(40, seed=5), GlueyLubrication(gamma_min=-2.0), dt=0.05,
                      solver="apgd", tol=1e-8)


def test_a_restored_state_continues_bit_for_bit(tmp_path):
    straight = _simulation()
    straight.run(30)
    np.savez(tmp_path / "state.npz", **straight.state.to_arrays())
    straight.run(10)

    with np.load(tmp_path / "state.npz") as data:
        state = SimulationState.from_arrays(dict(data))
    resumed = _simulation()
    resumed.restore(state)
    assert resumed.steps_done == 30 and resumed.state.previous is not None
    assert np.count_nonzero(resumed.state.pairs.gamma < 0) > 0       # glue state travelled
    resumed.run(10)
    a, b = straight.scene.grains, resumed.scene.grains
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.velocities, b.velocities)
    assert straight.scene.time == resumed.scene.time
    assert np.array_equal(straight.state.pairs.gamma, resumed.state.pairs.gamma)


def test_the_state_keeps_the_time_without_drift():
    sim = _simulation()
    sim.run(7)
    assert sim.steps_done == 7 and sim.scene.time == sim.state.start_time + 7 * 0.05


@pytest.mark.parametrize("law", [Inelastic(), GlueyLubrication(gamma_min=-1.0), Coulomb(0.3)],
                         ids=["inelastic", "gluey", "coulomb"])
def test_a_free_spin_is_carried_by_every_law(law):
    """Frictionless laws model no rotation: a spin is carried unchanged (it used to be zeroed)."""
    grains = Grains.create(positions=[[0.0, 5.0]], radii=0.5, masses=1.0, spins=[2.0])
    scene = Scene.create(grains, plane_points=[0.0, 0.0], plane_normals=[0.0, 1.0],
                         gravity=[0.0, -1.0])
    sim = Simulation(scene, law, dt=0.01)
    sim.run(3)
    assert sim.scene.grains.spins[0, 0] == 2.0
    assert sim.scene.grains.angles[0, 0] == pytest.approx(0.06)


def test_verification_inside_a_run_records_every_kth_step():
    sim = Simulation(scenes.settling_pile(40, seed=5), GlueyLubrication(gamma_min=-2.0), dt=0.05,
                     solver="apgd-as", tol=1e-9, verify_every=5, verify_tol=1e-7)
    sim.run(20)
    steps = [step for step, _ in sim.trajectory.verifications]
    assert steps == [5, 10, 15, 20]
    for _, report in sim.trajectory.verifications:
        assert report.passed, report.text()
        assert report.reference["status"] == "converged"
        assert report.velocity_error <= 1e-7 and report.coulomb_error <= 1e-7


def test_a_failed_verification_warns_and_is_recorded():
    """A starved fast solver (5 iterations) is caught by the cross-check, not applied silently."""
    sim = Simulation(scenes.settling_pile(40, seed=5), GlueyLubrication(gamma_min=-2.0), dt=0.05,
                     solver="apgd", tol=1e-9, solver_options={"max_iter": 5}, on_failure="ignore",
                     verify_every=1)
    sim.run(14)                                     # the pile has landed: contacts carry load
    with pytest.warns(SolverWarning, match="fails verification against clarabel"):
        sim.step()
    step, report = sim.trajectory.verifications[-1]
    assert step == 15 and not report.passed and report.worst


def test_a_step_whose_cones_are_unchanged_reuses_the_last_step_s_and_moves_as_before(monkeypatch):
    """``Simulation._step_cones``: on a settling gluey + frictional pile the step's cones are
    the last step's object where they hold the same sets (what a solve derives from them is not
    built again), a new object where they do not, some of those with as many contacts (glue
    states that changed: a test of the sets, not of their count); the trajectory is the same to
    the bit as with a new object every step."""
    def run(reuse):
        if not reuse:
            monkeypatch.setattr(Simulation, "_step_cones", lambda self, cones: cones)
        sim = Simulation(scenes.settling_pile(10, seed=1), GlueyCoulomb(0.3, gamma_min=-0.05), 0.02,
                         solver="newton-ac", tol=1e-8, keep_trajectory=False)
        reports = [sim.step() for _ in range(80)]
        monkeypatch.undo()
        return sim, [report.problem.cones for report in reports]

    sim, cones = run(reuse=True)
    pairs = list(zip(cones, cones[1:]))
    reused = [now is before for before, now in pairs]
    changed = [not now.same_as(before) for before, now in pairs]
    assert sum(reused) >= 40 and all(was_reused != was_changed
                                     for was_reused, was_changed in zip(reused, changed))
    assert any(now.count == before.count and not now.same_as(before) for before, now in pairs)
    fresh, fresh_cones = run(reuse=False)
    assert not any(now is before for before, now in zip(fresh_cones, fresh_cones[1:]))
    a, b = sim.scene.grains, fresh.scene.grains
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.velocities, b.velocities)


def test_a_law_that_writes_into_its_last_arrays_gets_new_cones():
    """A law that refills one coefficient array in place each step (against ``Law.cones``'s
    rule) is not handed the last step's cones, whose derived projection would hold the earlier
    coefficients: each step's cones with contacts are new, and the projection reads this
    step's."""
    class Refilled(Coulomb):
        def __init__(self):
            super().__init__(0.3)
            self.buffer = np.zeros(0)
            self.steps = 0

        def cones(self, contacts, gamma):
            if self.buffer.size != contacts.count:
                self.buffer = np.zeros(contacts.count)
            self.steps += 1
            self.buffer[:] = 0.05 if self.steps % 2 else 0.8
            return Cones(kinds=np.full(contacts.count, ConeKind.COULOMB, dtype=np.int8),
                         mu=self.buffer, tangential=np.arange(contacts.count), tangent_dim=1)

    sim = Simulation(scenes.settling_pile(6, seed=1), Refilled(), 0.02, solver="newton-ac",
                     tol=1e-8, keep_trajectory=False)
    cones = [sim.step().problem.cones for _ in range(20)]
    assert not any(now is before for before, now in zip(cones, cones[1:]) if now.count)
    last = cones[-1]
    assert last.count and np.array_equal(last.projector.friction_mu, last.mu)
