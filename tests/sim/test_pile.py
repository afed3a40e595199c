"""A settling pile: primal and dual Clarabel solves agree on every step, no penetration."""
import numpy as np
import pytest

from lubcontact import GlueyLubrication, Inelastic, Simulation, scenes, solve


@pytest.mark.parametrize("law", [Inelastic(), GlueyLubrication()], ids=["inelastic", "gluey"])
def test_primal_and_dual_agree_on_every_step_of_a_settling_pile(law):
    scene = scenes.settling_pile(n_grains=200, seed=3)
    sim = Simulation(scene, law, dt=0.05)
    worst = {"velocity": 0.0, "gap": np.inf, "contacts": 0, "glued": 0}

    def compare(_, report):
        problem = report.problem
        if problem.n_contacts == 0:
            return
        primal = report.result                   # the simulation's solver: clarabel, primal form
        dual = solve(problem, "clarabel-dual", tol=1e-10)
        assert primal.status == dual.status == "converged"
        error = np.linalg.norm(primal.velocities - dual.velocities) / np.linalg.norm(dual.velocities)
        worst["velocity"] = max(worst["velocity"], error)
        worst["gap"] = min(worst["gap"], report.gaps_after.min())
        worst["contacts"] = max(worst["contacts"], problem.n_contacts)
        worst["glued"] = max(worst["glued"], int(np.count_nonzero(report.gamma < 0)))
        # the forces recovered from the primal's multipliers give back its velocities
        np.testing.assert_allclose(problem.velocity(primal.forces), primal.velocities,
                                   atol=1e-7 * np.abs(dual.velocities).max())

    sim.run(80, callback=compare)
    assert worst["contacts"] > 150              # the pile really has formed
    assert worst["velocity"] <= 1e-7
    assert worst["gap"] >= -1e-8
    if isinstance(law, GlueyLubrication):
        assert worst["glued"] > 50
