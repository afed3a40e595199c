"""Periodic boundaries along x: ghost images, pair keys across the boundary, wrapping."""
import numpy as np
import pytest

from lubcontact import GlueyLubrication, Grains, Scene, Simulation, find_contacts


def random_layer(shift: float = 0.0, period: float = 12.0, seed: int = 3) -> Scene:
    """Disks on a jittered grid spanning the whole period, over a row of fixed grains."""
    rng = np.random.default_rng(seed)
    ix, iy = np.meshgrid(np.arange(12), np.arange(4))
    centres = np.stack([ix.ravel() + 0.5, iy.ravel() * 1.05 + 1.6], axis=1)
    centres += rng.uniform(-0.01, 0.01, centres.shape)
    centres[:, 0] += shift
    radii = rng.uniform(0.47, 0.48, len(centres))
    bed = np.stack([np.arange(12) + 0.25 + shift, np.full(12, 0.5)], axis=1)
    return Scene.create(Grains.create(centres, radii, densities=1.0), fixed_positions=bed,
                        fixed_radii=0.5, gravity=[0.0, -1.0], period=period)


def test_contacts_invariant_under_periodic_shift():
    """Translating everything along x (mod L) changes no key, gap or normal."""
    reference = find_contacts(random_layer(), d_max=0.1)
    for shift in (0.3, 5.77, 11.9, -0.49):
        shifted = find_contacts(random_layer(shift), d_max=0.1)
        np.testing.assert_array_equal(shifted.keys, reference.keys)
        np.testing.assert_allclose(shifted.gaps, reference.gaps, atol=1e-12)
        np.testing.assert_allclose(shifted.normals, reference.normals, atol=1e-12)
    # the layer closes on itself: 12 columns -> the 11 inner neighbours plus the one across x = 0
    row = reference.keys[(reference.body_a < 12) & (reference.body_b < 12)]
    assert row.size == 12


@pytest.mark.parametrize("reaches", [2.05, 2.9, 3.5, 7.3])
def test_periodic_search_finds_exactly_the_minimum_image_pairs(reaches):
    """Every pair within ``d_max`` by the minimum image along x, found once, on periods of
    ``reaches`` contact reaches (2 r_max + d_max): under three, two cells tile the period and
    one of them is a neighbour on both sides."""
    rng = np.random.default_rng(int(10 * reaches))
    d_max, radii = 0.1, rng.uniform(0.3, 0.5, 40)
    period = reaches * (2.0 * radii.max() + d_max)
    centres = np.stack([rng.uniform(-period, 2.0 * period, 40), rng.uniform(0.0, 6.0, 40)], axis=1)
    scene = Scene.create(Grains.create(centres, radii, masses=1.0), period=period,
                         check_overlaps=False)
    contacts = find_contacts(scene, d_max)
    expected = {}
    for a in range(40):
        for b in range(a + 1, 40):
            delta = centres[b] - centres[a]
            delta[0] -= period * np.round(delta[0] / period)
            gap = np.linalg.norm(delta) - radii[a] - radii[b]
            if gap < d_max:
                expected[(a, b)] = gap
    found = {(int(a), int(b)): gap for a, b, gap in zip(contacts.body_a, contacts.body_b,
                                                        contacts.gaps)}
    assert len(expected) > 10 and found.keys() == expected.keys()
    for pair, gap in expected.items():
        assert found[pair] == pytest.approx(gap, abs=1e-12)
    assert np.all(np.diff(contacts.keys) > 0)


def test_pair_across_boundary_has_inside_key_and_gap():
    radii = [0.5, 0.5]
    inside = Scene.create(Grains.create([[4.0, 1.0], [5.02, 1.0]], radii, masses=1.0), period=10.0)
    across = Scene.create(Grains.create([[9.6, 1.0], [0.62, 1.0]], radii, masses=1.0), period=10.0)
    a, b = find_contacts(inside, d_max=0.1), find_contacts(across, d_max=0.1)
    assert a.count == b.count == 1
    assert a.keys[0] == b.keys[0]
    assert b.gaps[0] == pytest.approx(0.02, abs=1e-12)
    np.testing.assert_allclose(b.normals[0], [1.0, 0.0], atol=1e-12)
    # without the period the two grains are 9 apart
    assert find_contacts(Scene.create(Grains.create([[9.6, 1.0], [0.62, 1.0]], radii, masses=1.0)),
                         d_max=0.1).count == 0


def test_period_too_short_for_the_contact_reach():
    scene = Scene.create(Grains.create([[0.5, 1.0], [1.5, 1.0]], 0.5, masses=1.0), period=2.1)
    with pytest.raises(ValueError, match="period"):
        find_contacts(scene, d_max=0.1)
    with pytest.raises(ValueError, match="period"):
        Scene.create(Grains.create([[0.5, 1.0]], 0.5, masses=1.0), period=-1.0)


def test_glued_pair_crossing_the_boundary_keeps_contact_and_gamma():
    """Two disks pressed together (force F each) drift across x = L at speed 1.

    The contact is glued from the first step; its gamma must fall by exactly
    ``F dt`` per step, crossing included, and the pair keeps one key.
    """
    period, force, dt = 8.0, 0.5, 0.05
    grains = Grains.create([[6.9, 1.0], [7.9, 1.0]], 0.5, masses=1.0, velocities=[[1.0, 0], [1.0, 0]])
    push = np.array([[force, 0.0], [-force, 0.0]])
    scene = Scene.create(grains, external_force=push, period=period)
    sim = Simulation(scene, GlueyLubrication(), dt, d_max=0.05)
    keys, gammas, straddled = set(), [], False
    for _ in range(50):                      # 2.5 time units: both grains cross x = 8
        report = sim.step()
        assert report.contacts.count == 1
        keys.add(int(report.contacts.keys[0]))
        gammas.append(report.gamma[0])
        x = sim.scene.grains.positions[:, 0]
        assert np.all((x >= 0) & (x < period))          # positions are wrapped
        straddled |= bool(x[1] < x[0])
    assert straddled and len(keys) == 1
    # the impact costs nothing (equal velocities); then F dt per step
    np.testing.assert_allclose(gammas, -force * dt * np.arange(1, 51), rtol=1e-6)
    np.testing.assert_allclose(sim.scene.grains.velocities, [[1.0, 0.0], [1.0, 0.0]], atol=1e-7)


def test_widened_layer_repeats_every_contact_and_its_step():
    """Three copies of a periodic layer: three times the contacts with the same gaps, and one
    step moves each copy as the layer alone moves (the copies stay identical)."""
    from lubcontact import Coulomb
    from lubcontact.scenes.inclined import widen

    layer = random_layer()
    layer.grains.velocities[:] = np.random.default_rng(1).normal(0.0, 0.1, layer.grains.velocities.shape)
    wide = widen(layer, 3)
    assert wide.period == 3 * layer.period and wide.grains.count == 3 * layer.grains.count
    assert wide.fixed_radii.size == 3 * layer.fixed_radii.size and wide.metadata["copies"] == 3
    alone, tiled = find_contacts(layer, d_max=0.1), find_contacts(wide, d_max=0.1)
    assert tiled.count == 3 * alone.count
    np.testing.assert_allclose(np.sort(tiled.gaps), np.sort(np.tile(alone.gaps, 3)), atol=1e-12)
    runs = [Simulation(scene, Coulomb(0.3), 0.05, solver="clarabel", d_max=0.1)
            for scene in (layer, wide)]
    for sim in runs:
        sim.step()
    n = layer.grains.count
    for copy in range(3):
        np.testing.assert_allclose(runs[1].scene.grains.velocities[copy * n:(copy + 1) * n],
                                   runs[0].scene.grains.velocities, atol=1e-7)


def test_widen_rejects_a_scene_without_period():
    from lubcontact.scenes.inclined import widen

    box = Scene.create(Grains.create([[1.0, 1.0]], [0.5], masses=1.0))
    with pytest.raises(ValueError, match="layer"):
        widen(box, 2)
    with pytest.raises(ValueError, match="copies"):
        widen(random_layer(), 0)
