"""Fixtures shared by test folders."""
import pytest

from lubcontact import Simulation, find_contacts, scenes
from lubcontact.model.assemble import assemble
from lubcontact.model.laws import Coulomb
from lubcontact.solvers.coulomb import solve_coulomb


def settling_pile_problem(steps):
    """The step problem of a 60-grain frictional settling pile (mu = 0.3, seed 3, dt 0.05) after
    ``steps`` steps of ``apgd-jacobi``'s exact Coulomb."""
    sim = Simulation(scenes.settling_pile(60, seed=3), Coulomb(0.3), 0.05, solver="apgd-jacobi",
                     tol=1e-8, tol_fp=1e-6, on_failure="ignore")
    sim.run(steps)
    contacts = find_contacts(sim.scene, sim.d_max)
    cones = sim.law.cones(contacts, sim.state.pairs.lookup(contacts.keys))
    return assemble(sim.scene, contacts, cones, sim.dt, rotations=sim.law.needs_rotation)


@pytest.fixture(scope="session")
def settling_step():
    """The 31st step of a 60-grain frictional settling pile (mu = 0.3), with Clarabel's fixed point."""
    problem = settling_pile_problem(30)
    reference = solve_coulomb(problem, "clarabel", tol=1e-10, tol_fp=1e-10, max_outer=500)
    assert reference.success and problem.n_contacts >= 30
    return problem, reference
