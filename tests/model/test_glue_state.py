"""The glue state update: what glues a contact.

With the poster's fluid (eta = 1e-3 Pa s, eps = 1 um) |gamma_min| is of order
1e-8 N s/m while the snapping tolerance ``state_rtol dt max|lambda|`` grows with
the step's largest force. Once that tolerance passed |gamma_min|, the update
snapped every contact within it of the floor, unpushed and open ones included,
to gamma_min: open contacts became bilateral UNION contacts that the next step
had to close at once (the failed gluey flow steps of docs/records/poster-experiment.md).
A solve converged to its tolerance may also leave a small force on a contact that ends the
step open; read as a push, it glued that contact with its gap (a 400-grain gluey flow).
"""
from __future__ import annotations

import numpy as np

from lubcontact import Simulation, find_contacts
from lubcontact.bench.cases.builders import floor_scene
from lubcontact.model.laws import GlueyCoulomb

GAMMA_MIN = -1e-9
DT = 0.01
GAP = 0.01                      # hovering grains: open floor contacts, within the search distance


def _scene():
    """One grain thrown at the floor (a large force), two hovering at rest above it."""
    positions = [[0.0, 0.5], [2.0, 0.5 + GAP], [4.0, 0.5 + GAP]]
    velocities = [[0.0, -100.0], [0.0, 0.0], [0.0, 0.0]]
    return floor_scene(positions, 0.5, masses=1.0, velocities=velocities, gravity=0.0)


def test_a_floor_within_the_snapping_tolerance_glues_only_pushed_contacts():
    law = GlueyCoulomb(0.3, GAMMA_MIN)
    contacts = find_contacts(_scene(), 0.05)
    gamma = np.array([0.0, 0.0, GAMMA_MIN])
    forces = np.array([1e4, 1e-10, 0.0])      # impact, solver noise on an open contact, idle
    tol = law.state_rtol * DT * 1e4
    assert tol > 2 * abs(GAMMA_MIN)          # the case under test
    new = law.update_gamma(contacts, gamma, forces, DT, force_scale=1.0)
    np.testing.assert_array_equal(new, [GAMMA_MIN, 0.0, GAMMA_MIN])


def test_hovering_grains_stay_unglued_and_at_rest_beside_an_impact():
    sim = Simulation(_scene(), GlueyCoulomb(0.3, GAMMA_MIN), DT, solver="clarabel")
    sim.step()
    keys = find_contacts(sim.scene, sim.d_max).keys
    np.testing.assert_array_equal(sim.gamma_of(keys), [GAMMA_MIN, 0.0, 0.0])
    sim.step()                                # unglued open contacts exert no pull
    np.testing.assert_allclose(sim.scene.grains.velocities[1:], 0.0, atol=1e-9)
    np.testing.assert_allclose(sim.scene.grains.positions[1:, 1], 0.5 + GAP, atol=1e-12)


def test_a_force_left_on_a_contact_that_ends_the_step_open_does_not_glue_it():
    law = GlueyCoulomb(0.3, GAMMA_MIN)
    contacts = find_contacts(_scene(), 0.05)
    force_unit, length_unit = 2.0, 1e-3
    forces = np.array([4e-6, 0.5, -0.5]) * force_unit       # noise on an open contact, push, pull
    gaps_after = np.array([5e-2, 1e-12, 0.0]) * length_unit
    gamma = np.array([0.0, 0.0, GAMMA_MIN])
    assert DT * forces[0] > law.state_rtol * DT * force_unit   # above the snapping tolerance
    new = law.update_gamma(contacts, gamma, forces, DT, force_unit, gaps_after=gaps_after,
                           length_scale=length_unit)
    np.testing.assert_array_equal(new, [0.0, GAMMA_MIN, 0.0])
    without_gaps = law.update_gamma(contacts, gamma, forces, DT, force_unit)
    assert without_gaps[0] < 0.0                               # what the gaps prevent
