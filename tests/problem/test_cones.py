"""Projections onto the contact force sets: closed forms and properties (hypothesis)."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lubcontact.problem.cones import ConeKind, Cones, project_dual_friction_cone, project_friction_cone

CONVEX_KINDS = (ConeKind.NONNEG, ConeKind.FREE, ConeKind.NONPOS, ConeKind.COULOMB)
ALL_KINDS = CONVEX_KINDS + (ConeKind.UNION,)


@st.composite
def cones_and_points(draw, kinds=CONVEX_KINDS, count=2):
    """A random product of force sets (2D or 3D) and ``count`` random force vectors."""
    tangent_dim = draw(st.sampled_from([1, 2]))
    n = draw(st.integers(1, 6))
    chosen = np.array(draw(st.lists(st.sampled_from(kinds), min_size=n, max_size=n)), dtype=np.int8)
    mu = np.array(draw(st.lists(st.sampled_from([0.0, 0.3, 1.0, 2.5]), min_size=n, max_size=n)))
    friction = (chosen == ConeKind.COULOMB) | (chosen == ConeKind.UNION)
    extra = np.array(draw(st.lists(st.booleans(), min_size=n, max_size=n)))
    tangential = np.flatnonzero(friction | extra)        # also frictionless contacts with T rows
    cones = Cones(kinds=chosen, mu=mu, tangential=tangential, tangent_dim=tangent_dim)
    values = st.floats(-10.0, 10.0, allow_nan=False)
    points = [np.array(draw(st.lists(values, min_size=cones.n_rows, max_size=cones.n_rows)))
              for _ in range(count)]
    return cones, points


def in_cone(cones, x, atol=1e-9):
    """Membership test written independently of the projection."""
    normal, tangential = cones.split(x)
    ok = True
    for c, kind in enumerate(cones.kinds):
        t = tangential[list(cones.tangential).index(c)] if c in cones.tangential else np.zeros(0)
        slip = np.linalg.norm(t)
        if kind == ConeKind.NONNEG:
            ok &= normal[c] >= -atol and slip <= atol
        elif kind == ConeKind.NONPOS:
            ok &= normal[c] <= atol and slip <= atol
        elif kind == ConeKind.FREE:
            ok &= slip <= atol
        elif kind == ConeKind.COULOMB:
            ok &= slip <= cones.mu[c] * normal[c] + atol and normal[c] >= -atol
        else:
            ok &= (slip <= cones.mu[c] * normal[c] + atol and normal[c] >= -atol) or \
                (normal[c] <= atol and slip <= atol)
    return ok


@settings(max_examples=100, deadline=None)
@given(cones_and_points(kinds=ALL_KINDS))
def test_projection_lands_in_the_set_and_is_idempotent(case):
    cones, (x, _) = case
    p = cones.project(x)
    assert in_cone(cones, p)
    np.testing.assert_allclose(cones.project(p), p, atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(cones_and_points())
def test_projection_is_non_expansive_on_convex_sets(case):
    cones, (x, y) = case
    assert np.linalg.norm(cones.project(x) - cones.project(y)) <= np.linalg.norm(x - y) * (1 + 1e-12) + 1e-12


@settings(max_examples=100, deadline=None)
@given(cones_and_points())
def test_moreau_decomposition(case):
    """``x = P_K(x) + P_K°(x)`` with orthogonal parts, the polar part in the polar cone."""
    cones, (x, z) = case
    p, q = cones.project(x), cones.project_polar(x)
    np.testing.assert_allclose(p + q, x, atol=1e-10)
    assert abs(p @ q) <= 1e-9 * (1 + x @ x)
    # q is in the polar cone: its inner product with any element of K is <= 0
    assert q @ cones.project(z) <= 1e-9 * (1 + np.linalg.norm(q) * np.linalg.norm(z))


@settings(max_examples=100, deadline=None)
@given(cones_and_points())
def test_projection_is_the_nearest_point_among_sampled_members(case):
    """No member of K (projections of random points) is nearer to x than P_K(x)."""
    cones, (x, y) = case
    best = np.linalg.norm(x - cones.project(x))
    for scale in (0.5, 1.0, 2.0):
        assert best <= np.linalg.norm(x - cones.project(scale * y)) + 1e-12


@settings(max_examples=100, deadline=None)
@given(cones_and_points(kinds=(ConeKind.UNION,)))
def test_union_projection_is_the_nearer_piece(case):
    cones, (x, _) = case
    p = cones.project(x)
    pushed = cones.with_branches(np.zeros(cones.count, dtype=bool)).project(x)
    pulled = cones.with_branches(np.ones(cones.count, dtype=bool)).project(x)
    for c in range(cones.count):
        rows = cones_rows(cones, c)
        d = [np.linalg.norm(x[rows] - q[rows]) for q in (p, pushed, pulled)]
        assert d[0] == pytest.approx(min(d[1], d[2]), abs=1e-12)


def cones_rows(cones, c):
    rows = [c]
    if c in cones.tangential:
        k = list(cones.tangential).index(c)
        rows += list(cones.count + k * cones.tangent_dim + np.arange(cones.tangent_dim))
    return rows


# -- closed-form values --------------------------------------------------------------------------
def friction_2d(mu):
    return Cones(kinds=np.array([ConeKind.COULOMB], dtype=np.int8), mu=np.array([mu]),
                 tangential=np.array([0]), tangent_dim=1)


@pytest.mark.parametrize("x, expected", [
    ([1.0, 0.2], [1.0, 0.2]),            # inside
    ([-1.0, 0.2], [0.0, 0.0]),           # polar cone: apex
    ([0.0, 0.0], [0.0, 0.0]),            # apex itself
    ([0.0, 1.0], [0.4, 0.2]),            # onto the boundary: (n + mu |t|)/(1 + mu^2) (1, mu)
    ([1.0, -2.0], [1.6, -0.8]),
])
def test_friction_cone_2d_closed_form(x, expected):
    np.testing.assert_allclose(friction_2d(0.5).project(np.array(x)), expected, atol=1e-15)


def test_friction_cone_3d_closed_form():
    # |t| = 5 along (3, 4)/5, mu = 1, n = 1: scale = (1 + 5)/2 = 3 -> (3, 3 * (0.6, 0.8))
    new_n, new_t = project_friction_cone(np.array([1.0]), np.array([[3.0, 4.0]]), np.array([1.0]))
    np.testing.assert_allclose(new_n, [3.0])
    np.testing.assert_allclose(new_t, [[1.8, 2.4]])


def test_friction_cone_with_zero_mu_is_the_nonnegative_normal_half_line():
    new_n, new_t = project_friction_cone(np.array([2.0, -1.0, 0.0]), np.array([[1.0], [0.0], [3.0]]),
                                         np.zeros(3))
    np.testing.assert_array_equal(new_n, [2.0, 0.0, 0.0])
    np.testing.assert_array_equal(new_t, [[0.0], [0.0], [0.0]])


def test_dual_cone_closed_form_and_zero_mu_half_space():
    # dual of |t| <= 2 n is 2 |t| <= n; (0, 1): scale = (0 + 1)/(1 + 4) -> (2/5, 1/5)
    new_n, new_t = project_dual_friction_cone(np.array([0.0, -1.0]), np.array([[1.0], [3.0]]),
                                              np.array([2.0, 0.0]))
    np.testing.assert_allclose(new_n, [0.4, 0.0])
    np.testing.assert_allclose(new_t, [[0.2], [3.0]])


def test_frictionless_kinds_and_tangential_rows_of_frictionless_contacts():
    cones = Cones(kinds=np.array([ConeKind.NONNEG, ConeKind.FREE, ConeKind.NONPOS], dtype=np.int8),
                  mu=np.zeros(3), tangential=np.array([1]), tangent_dim=1)
    x = np.array([-2.0, -3.0, 4.0, 5.0])
    np.testing.assert_array_equal(cones.project(x), [0.0, -3.0, 0.0, 0.0])
    np.testing.assert_array_equal(cones.project_polar(x), [-2.0, 0.0, 4.0, 5.0])


def test_cones_without_tangential_rows_project_whatever_the_empty_list_s_dtype():
    """A contact list without tangential rows given as an empty float array (``np.array([])``)
    is a box: the projector's friction contacts are empty index arrays (it indexed with the
    float array, an IndexError)."""
    cones = Cones(kinds=np.array([ConeKind.NONNEG, ConeKind.NONPOS], dtype=np.int8),
                  mu=np.zeros(2), tangential=np.array([]), tangent_dim=1)
    np.testing.assert_array_equal(cones.project(np.array([-1.0, 2.0])), [0.0, 0.0])
    assert cones.projector.friction_normal.size == 0


def test_union_picks_the_pull_piece_below_the_cone():
    cones = Cones(kinds=np.array([ConeKind.UNION], dtype=np.int8), mu=np.array([0.5]),
                  tangential=np.array([0]), tangent_dim=1)
    np.testing.assert_array_equal(cones.project(np.array([-3.0, 0.5])), [-3.0, 0.0])
    np.testing.assert_allclose(cones.project(np.array([2.0, 0.5])), [2.0, 0.5])


def test_polar_projection_rejects_union_contacts():
    cones = Cones(kinds=np.array([ConeKind.UNION], dtype=np.int8), mu=np.array([0.5]),
                  tangential=np.array([0]), tangent_dim=1)
    with pytest.raises(ValueError, match="UNION"):
        cones.project_polar(np.zeros(2))


def test_union_natural_residual_is_measured_on_the_piece_of_the_force():
    """A force on the edge of the pushed cone, stationary there (``lam - grad`` lies along the
    outward normal), whose step ``lam - grad`` lands nearer the pulled half-line: the residual
    on the union (2.73 here) would call an optimal point wrong; on its piece it is zero."""
    cones = Cones(kinds=np.array([ConeKind.UNION], dtype=np.int8), mu=np.array([0.5]),
                  tangential=np.array([0]), tangent_dim=1)
    forces = np.array([1.0, 0.5])                      # |lam_t| = mu lam_n: the cone's edge
    outward = np.array([-0.5, 1.0]) / np.sqrt(1.25)
    gradient = -6.0 * outward
    step = forces - gradient
    assert np.linalg.norm(step - cones.project(step)) < np.linalg.norm(step - forces)
    np.testing.assert_allclose(np.linalg.norm(forces - cones.project(step)), 2.73, atol=0.01)
    assert cones.natural_residual(forces, gradient) < 1e-12
    pulled = np.array([-1.0, 0.0])                     # pulled piece: lam_t = 0, any slip
    assert cones.natural_residual(pulled, np.array([0.0, 2.0])) < 1e-12
    assert cones.natural_residual(pulled, np.array([1.0, 0.0])) == pytest.approx(1.0)


def test_same_as_compares_every_field_bit_for_bit():
    def cones(kinds=(ConeKind.COULOMB, ConeKind.NONNEG), mu=(0.3, 0.0), tangential=(0,), dim=1):
        return Cones(kinds=np.array(kinds, dtype=np.int8), mu=np.array(mu),
                     tangential=np.array(tangential, dtype=int), tangent_dim=dim)

    base = cones()
    assert base.same_as(cones()) and cones().same_as(base)
    assert not base.same_as(cones(kinds=(ConeKind.COULOMB, ConeKind.NONPOS)))
    assert not base.same_as(cones(mu=(0.3, 1e-300)))
    assert not base.same_as(cones(tangential=(1,)))
    assert not base.same_as(cones(dim=2))
    assert not base.same_as(cones(kinds=(ConeKind.COULOMB,), mu=(0.3,)))      # fewer contacts
    assert not base.same_as(cones(mu=(0.3, -0.0)))                 # bit for bit: -0.0 is not 0.0
    wide = Cones(kinds=base.kinds, mu=base.mu, tangential=np.array([0], dtype=np.int32), tangent_dim=1)
    assert not base.same_as(wide)                                  # rows of another width
    boxes = [Cones(kinds=np.array([ConeKind.NONNEG], dtype=np.int8), mu=np.zeros(1), tangential=rows,
                   tangent_dim=1) for rows in (np.array([]), np.zeros(0, dtype=int), np.zeros(0, dtype=int))]
    assert not boxes[0].same_as(boxes[1]) and boxes[1].same_as(boxes[2])      # no rows: the dtype tells
