"""Contact detection and Jacobians against brute force and finite differences."""
from dataclasses import replace

import numpy as np
import pytest

from lubcontact import GlueyLubrication, Grains, Inelastic, Scene, Simulation, find_contacts
from lubcontact.model.contacts import Contacts, contact_jacobian
from lubcontact.model.laws import PairState


def random_scene(dim, seed, n=60):
    rng = np.random.default_rng(seed)
    positions = rng.uniform(0.0, 8.0, (n, dim))
    radii = rng.uniform(0.3, 0.6, n)
    grains = Grains.create(positions, radii, masses=1.0, velocities=rng.normal(size=(n, dim)),
                           spins=rng.normal(size=(n, 1 if dim == 2 else 3)))
    normal = np.zeros(dim)
    normal[-1] = 1.0
    fixed = rng.uniform(0.0, 8.0, (10, dim))
    return Scene.create(grains, plane_points=np.zeros(dim), plane_normals=normal,
                        fixed_positions=fixed, fixed_radii=0.5, check_overlaps=False)


def brute_force_gaps(scene, d_max):
    g = scene.grains
    centres = np.vstack([g.positions, scene.fixed_positions])
    radii = np.concatenate([g.radii, scene.fixed_radii])
    found = {}
    n_total = len(radii)
    for b in range(g.count):
        for a in range(n_total):
            if a == b or (a < g.count and a > b):
                continue
            gap = np.linalg.norm(centres[b] - centres[a]) - radii[a] - radii[b]
            if gap < d_max:
                found[(a if a < g.count else a, b)] = gap
        gap = g.positions[b, -1] - g.radii[b]
        if gap < d_max:
            found[(n_total, b)] = gap
    return found


@pytest.mark.parametrize("far", [False, True])
@pytest.mark.parametrize("dim", [2, 3])
def test_cell_search_finds_exactly_the_brute_force_pairs(dim, far):
    """``far``: one grain 10^5 away, so that reach-wide cells would be 10^10 (10^15 in 3D) and
    the search widens them (``pair_search.CELLS_PER_GRAIN``)."""
    scene = random_scene(dim, seed=dim)
    if far:
        scene.grains.positions[7] += 1e5
    d_max = 0.2
    contacts = find_contacts(scene, d_max)
    expected = brute_force_gaps(scene, d_max)
    found = {(int(a), int(b)): gap for a, b, gap in zip(contacts.body_a, contacts.body_b, contacts.gaps)}
    assert found.keys() == expected.keys()
    for pair, gap in expected.items():
        assert found[pair] == pytest.approx(gap, abs=1e-12)
    assert np.all(np.diff(contacts.keys) > 0)
    np.testing.assert_allclose(np.linalg.norm(contacts.normals, axis=1), 1.0, rtol=1e-14)


@pytest.mark.parametrize("dim", [2, 3])
def test_normal_rows_are_the_time_derivative_of_the_gaps(dim):
    scene = random_scene(dim, seed=10 + dim)
    contacts = find_contacts(scene, 0.3)
    velocity = scene.grains.velocities.ravel()
    rate = contact_jacobian(contacts, np.zeros(0, dtype=int), rotations=False) @ velocity
    h = 1e-7
    moved = scene.copy()
    moved.grains.positions += h * scene.grains.velocities
    after = find_contacts(moved, 0.3)
    common, i, j = np.intersect1d(contacts.keys, after.keys, return_indices=True)
    assert common.size > 20
    np.testing.assert_allclose((after.gaps[j] - contacts.gaps[i]) / h, rate[i], atol=1e-5)


def test_tangential_rows_give_the_sliding_velocity_at_the_contact_point_2d():
    grains = Grains.create([[0.0, 0.0], [1.5, 0.0]], [0.5, 1.0], masses=1.0,
                           velocities=[[0.3, -0.2], [0.1, 0.7]], spins=[[2.0], [-1.0]])
    scene = Scene.create(grains, plane_points=[0.0, -1.0], plane_normals=[0.0, 1.0])
    contacts = find_contacts(scene, 0.1)
    assert contacts.count == 2                      # the plane-disk and the disk-disk contact
    v = np.concatenate([grains.velocities.ravel(), grains.spins.ravel()])
    rows = contact_jacobian(contacts, np.arange(contacts.count), rotations=True)[contacts.count:]
    assert rows.shape == (2, 6)

    def point_velocity(i, point):
        lever = point - grains.positions[i]
        return grains.velocities[i] + grains.spins[i, 0] * np.array([-lever[1], lever[0]])

    for c in range(contacts.count):
        n = contacts.normals[c]
        t = np.array([-n[1], n[0]])
        b = contacts.body_b[c]
        u = point_velocity(b, contacts.points[c])
        if contacts.body_a[c] < 2:
            u = u - point_velocity(contacts.body_a[c], contacts.points[c])
        assert rows[c] @ v == pytest.approx(u @ t, abs=1e-12)


def test_rolling_without_slipping_has_zero_tangential_velocity_in_3d():
    grains = Grains.create([[0.0, 0.0, 1.0]], 1.0, masses=1.0, velocities=[[2.0, -1.0, 0.0]],
                           spins=[[1.0, 2.0, 0.0]])      # v = omega x (r e_z)
    scene = Scene.create(grains, plane_points=[0.0, 0.0, 0.0], plane_normals=[0.0, 0.0, 1.0])
    contacts = find_contacts(scene, 0.1)
    v = np.concatenate([grains.velocities.ravel(), grains.spins.ravel()])
    rows = contact_jacobian(contacts, np.arange(1), rotations=True)[contacts.count:]
    np.testing.assert_allclose(rows @ v, 0.0, atol=1e-14)


@pytest.mark.parametrize("dim", [2, 3])
def test_contact_rows_of_a_subset_are_the_full_set_s_rows_in_canonical_form(dim):
    """``H`` with the tangential rows of some contacts is ``H`` of every contact restricted to
    the normal rows and those contacts' rows, in canonical form; the normal rows have no
    rotational entries and are ``H`` without rotations."""
    scene = random_scene(dim, seed=20 + dim)
    contacts = find_contacts(scene, 0.3)
    nc, nt = contacts.count, dim - 1
    every = contact_jacobian(contacts, np.arange(nc), rotations=True)
    which = np.flatnonzero(np.random.default_rng(dim).random(nc) < 0.4)
    some = contact_jacobian(contacts, which, rotations=True)
    assert some.shape == (nc + which.size * nt, every.shape[1]) and some.has_canonical_format
    tangential_rows = nc + (which[:, None] * nt + np.arange(nt)).ravel()
    assert (some - every[np.concatenate([np.arange(nc), tangential_rows])]).nnz == 0
    translations = scene.grains.count * dim
    assert every[:nc, translations:].nnz == 0
    normal_only = contact_jacobian(contacts, np.zeros(0, dtype=int), rotations=False)
    assert normal_only.shape == (nc, translations)
    assert (normal_only - every[:nc, :translations]).nnz == 0
    with pytest.raises(ValueError, match="rotations"):
        contact_jacobian(contacts, which, rotations=False)


def test_every_tangential_row_is_the_model_s_sliding_velocity_2d():
    """``u_T = t.(v_b - v_a) - r_b omega_b - r_a omega_a`` with ``t`` the normal turned by +90
    degrees, an obstacle ``a`` (fixed grain, plane) at rest, on every contact of a random scene."""
    scene = random_scene(2, seed=31)
    contacts = find_contacts(scene, 0.3)
    grains, n = scene.grains, scene.grains.count
    assert (contacts.body_a >= n).sum() > 5 and (contacts.body_a < n).sum() > 20
    v = np.concatenate([grains.velocities.ravel(), grains.spins.ravel()])
    rows = contact_jacobian(contacts, np.arange(contacts.count), rotations=True)[contacts.count:]
    expected = []
    for c in range(contacts.count):
        a, b = contacts.body_a[c], contacts.body_b[c]
        t = np.array([-contacts.normals[c, 1], contacts.normals[c, 0]])
        u = t @ grains.velocities[b] - contacts.radius_b[c] * grains.spins[b, 0]
        if a < n:
            u -= t @ grains.velocities[a] + contacts.radius_a[c] * grains.spins[a, 0]
        expected.append(u)
    np.testing.assert_allclose(rows @ v, expected, rtol=1e-13, atol=1e-13)


def swapped(contacts, pairs):
    """``contacts`` with the bodies of the grain pairs ``pairs`` swapped (``b < a``), their
    normals turned and radii exchanged: the same contacts, described from the other grain."""
    a, b = contacts.body_a.copy(), contacts.body_b.copy()
    a[pairs], b[pairs] = contacts.body_b[pairs], contacts.body_a[pairs]
    ra, rb = contacts.radius_a.copy(), contacts.radius_b.copy()
    ra[pairs], rb[pairs] = contacts.radius_b[pairs], contacts.radius_a[pairs]
    normals = contacts.normals.copy()
    normals[pairs] *= -1.0
    return Contacts(body_a=a, body_b=b, keys=contacts.keys, gaps=contacts.gaps, normals=normals,
                    points=contacts.points, radius_a=ra, radius_b=rb, n_grains=contacts.n_grains)


def test_a_contact_described_from_its_other_grain_has_the_same_rows_2d():
    """``u_n = n.(v_b - v_a)`` and, in 2D, ``u_T`` do not depend on which grain is ``b``."""
    scene = random_scene(2, seed=32)
    contacts = find_contacts(scene, 0.3)
    pairs = np.flatnonzero(contacts.body_a < scene.grains.count)[::2]
    assert pairs.size > 10
    every = np.arange(contacts.count)
    expected = contact_jacobian(contacts, every, rotations=True)
    turned = contact_jacobian(swapped(contacts, pairs), every, rotations=True)
    assert turned.has_canonical_format
    np.testing.assert_array_equal(turned.toarray(), expected.toarray())


def test_a_body_numbered_as_an_obstacle_gets_no_columns_on_either_side():
    """A hand-built contact whose ``b`` is an obstacle (``find_contacts`` never makes one) has
    ``a``'s entries only, none left unset."""
    contacts = find_contacts(random_scene(2, seed=33), 0.3)
    n, c = contacts.n_grains, np.flatnonzero(contacts.body_a < contacts.n_grains)[0]
    body_b = contacts.body_b.copy()
    body_b[c] = n + 1
    rows = contact_jacobian(replace(contacts, body_b=body_b), [c], rotations=True)
    a = contacts.body_a[c]
    normal, tangential = (rows.indices[rows.indptr[r]: rows.indptr[r + 1]] for r in (c, contacts.count))
    assert normal.tolist() == [2 * a, 2 * a + 1]            # the stored entries, as filled
    assert tangential.tolist() == [2 * a, 2 * a + 1, 2 * n + a]


def test_a_jacobian_beyond_32_bit_indices_is_refused_before_it_is_built():
    empty = np.zeros(0)
    contacts = Contacts(body_a=empty.astype(int), body_b=empty.astype(int),
                        keys=empty.astype(np.int64), gaps=empty, normals=np.zeros((0, 2)),
                        points=np.zeros((0, 2)), radius_a=empty, radius_b=empty, n_grains=2**30 - 1)
    with pytest.raises(ValueError, match="contacts: H of 0 contacts and 3221225469 unknowns"):
        contact_jacobian(contacts, np.zeros(0, dtype=int), rotations=True)
    assert contact_jacobian(contacts, np.zeros(0, dtype=int), rotations=False).shape == (0, 2**31 - 2)
    many = 2**28                                # entries: 12 per row at most in 3D, 2^31.6 in all
    zeros, index = np.broadcast_to(0.0, (many,)), np.broadcast_to(0, (many,))
    contacts = Contacts(body_a=index, body_b=index, keys=index, gaps=zeros,
                        normals=np.broadcast_to(0.0, (many, 3)), points=np.broadcast_to(0.0, (many, 3)),
                        radius_a=zeros, radius_b=zeros, n_grains=10)
    with pytest.raises(ValueError, match=f"contacts: H of {many} contacts and 60 unknowns"):
        contact_jacobian(contacts, np.zeros(0, dtype=int), rotations=True)


def test_frictionless_problems_have_no_rotational_unknowns():
    grains = Grains.create([[0.0, 0.5]], 0.5, masses=1.0)
    scene = Scene.create(grains, plane_points=[0.0, 0.0], plane_normals=[0.0, 1.0], gravity=[0, -1])
    report = Simulation(scene, Inelastic(), 0.01).step()
    assert report.problem.n_dof == 2 and report.problem.n_rows == 1


def test_gamma_is_kept_by_pair_identity_and_forgotten_when_the_pair_leaves():
    state = PairState.from_contacts(np.array([7, 3, 11]), np.array([-1.0, 0.0, -2.0]))
    np.testing.assert_array_equal(state.keys, [7, 11])
    np.testing.assert_array_equal(state.lookup(np.array([11, 3, 7, 99])), [-2.0, 0.0, -1.0, 0.0])
    # in a simulation: two grains glued, then the pair is pulled out of the candidate list
    grains = Grains.create([[0.0, 0.0], [1.0, 0.0]], 0.5, masses=1.0, velocities=[[1, 0], [-1, 0]])
    scene = Scene.create(grains, external_force=lambda t: np.array([[-5.0, 0], [5.0, 0]]) * (t > 0.05))
    sim = Simulation(scene, GlueyLubrication(), dt=0.01, d_max=0.05)
    key = sim.step().contacts.keys[0]
    assert sim.gamma_of([key])[0] == pytest.approx(-0.01 * 100.0)   # impulse of the impact (m v / dt)
    sim.run(60)
    assert find_contacts(sim.scene, 0.05).count == 0
    assert sim.gamma_of([key])[0] == 0.0


def test_a_centre_that_is_not_finite_is_refused_by_the_search():
    scene = random_scene(2, seed=5)
    scene.grains.positions[3, 1] = np.nan
    with pytest.raises(ValueError, match="positions"):
        find_contacts(scene, 0.2)


@pytest.mark.parametrize("dim", [2, 3])
def test_a_cluster_with_more_pairs_than_the_first_guess_has_every_pair(dim):
    """Forty grains overlapping one another: 780 pairs, beyond the search's first arrays (four a
    grain), which grow."""
    rng = np.random.default_rng(dim)
    grains = Grains.create(rng.uniform(0.0, 0.1, (40, dim)), 0.5, masses=1.0)
    contacts = find_contacts(Scene.create(grains, check_overlaps=False), 0.0)
    assert contacts.count == 40 * 39 // 2
    assert np.all(np.diff(contacts.keys) > 0)
    expected = [np.linalg.norm(grains.positions[b] - grains.positions[a]) - 1.0
                for a, b in zip(contacts.body_a, contacts.body_b)]
    np.testing.assert_allclose(contacts.gaps, expected, atol=1e-14)
