"""Every shipped problem file is read: contact counts and dimensions from the file headers.

The 29 files of ``siconos-testdata`` (28 problems and their README), the three
``siconos-fc2d`` and the four ``fclib-local`` files: each gives a
:class:`LocalProblem` of the expected size (a global one also a
:class:`GlobalProblem` through ``read_global``) or the expected ``ValueError``.
Cross-checks between files that hold the same problem in two storages, or in
global and condensed (local) form, pin the format and sign conventions.
"""
from __future__ import annotations

import numpy as np
import pytest

from lubcontact import io
from lubcontact.bench import problem_sets
from lubcontact.io.siconos import contact_major_delassus
from lubcontact.problem import LocalProblem

DATA = problem_sets.data_dir()
TESTDATA = DATA / "siconos-testdata"

# file: (dim, contacts, degrees of freedom of a global problem or None for a local one)
TESTDATA_FILES = {
    "BoxesStack1-i100000-32.hdf5.dat": (3, 52, None),
    "Capsules-i122-1617.dat": (3, 296, None),
    "Confeti-ex03-Fc3D-SBM.dat": (3, 54, None),
    "FC2D_SliderCrankLagrangian00000.dat": (2, 2, None),
    "FC2D_SliderCrankLagrangian00001.dat": (2, 2, None),
    "FC3D_Example1.dat": (3, 3, None),
    "FC3D_Example1_SBM.dat": (3, 3, None),
    "FrictionContact3D_1c.dat": (3, 1, None),
    "FrictionContact3D_RR_1c.dat": (3, 1, None),
    "FrictionContactProblem00031.dat": (2, 11, None),
    "FrictionContactProblem00071.dat": (2, 89, None),
    "FrictionContactProblem00237.dat": (2, 376, None),
    "FrictionContactProblem00394.dat": (2, 6, None),
    "GFC3D_Example0.dat": (3, 1, 9),
    "GFC3D_Example00.dat": (3, 1, 3),
    "GFC3D_Example00_badly_scaled.dat": (3, 1, 3),
    "GFC3D_Example0_SBM.dat": (3, 1, 9),
    "GFC3D_Example1.dat": (3, 1, 3),
    "GFC3D_OneContact.dat": (3, 1, 39),
    "GFC3D_TwoRods1-condensed.dat": (3, 3, None),    # local despite its name: W 9 x 9, q, mu
    "GFC3D_TwoRods1.dat": (3, 3, 54),
    "NESpheres_10_1.dat": (3, 9, None),
    "OneObject-i1028-138.hdf5.dat": (3, 23, None),
    "Spheres-i099-356-679.hdf5": (3, 356, 12000),
    "gfc2d_granularflowonwall_00000_00117.dat": (2, 0, 900),
    "gfc2d_granularflowonwall_00069_00350.dat": (2, 69, 900),
    "gfc2d_granularflowonwall_00230_00206.dat": (2, 230, 9000),
    "spheres-in-a-box-98-i10000-256-10.hdf5": (3, 256, 588),
}
OTHER_FILES = {
    "siconos-fc2d/fc2d_granularflowonwall_00667_00000.dat": (2, 667, None),
    "siconos-fc2d/fc2d_granularflowonwall_02020_00213.dat": (2, 2020, None),
    "siconos-fc2d/fc2d_granularflowonwall_07002_00801.dat": (2, 7002, None),
    "fclib-local/Box_Stacks-i0122-82-5.hdf5": (3, 82, 450),
    "fclib-local/Capsules-i125-1213.hdf5": (3, 286, None),
    "fclib-local/LMGC_100_PR_PerioBox-i00361-60-03000.hdf5": (3, 60, None),
    "fclib-local/local_problem_test.hdf5": (3, 48, None),
}
EXPECTED = {**{f"siconos-testdata/{name}": value for name, value in TESTDATA_FILES.items()},
            **OTHER_FILES}


def test_the_tables_cover_every_shipped_file():
    shipped = {f"{path.parent.name}/{path.name}" for folder in ("siconos-testdata", "siconos-fc2d",
                                                                "fclib-local")
               for path in (DATA / folder).iterdir()}
    assert shipped == set(EXPECTED) | {"siconos-testdata/README.md"}
    assert len(list(TESTDATA.iterdir())) == 29


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_every_data_file_is_read(name):
    dim, contacts, dofs = EXPECTED[name]
    path = DATA / name
    problem = io.read_problem(path)
    assert isinstance(problem, LocalProblem)
    assert (problem.dim, problem.n_contacts, problem.n_rows) == (dim, contacts, dim * contacts)
    assert problem.name == (path.name.removesuffix(".dat") if path.suffix == ".dat" else path.stem)
    assert np.all(np.isfinite(problem.delassus.data)) and np.all(np.isfinite(problem.free_velocity))
    assert np.all(problem.cones.mu >= 0)
    if dofs is None:
        with pytest.raises(ValueError, match=rf"{path.name}.*local problem"):
            io.read_global(path)
        return
    record = io.read_global(path)
    assert (record.dim, record.n_contacts, record.n_dof) == (dim, contacts, dofs)
    assert record.M.shape == (dofs, dofs) and record.H.shape == (dofs, dim * contacts)
    local = record.to_local()
    assert abs(local.delassus - problem.delassus).max() == 0 if contacts else True
    np.testing.assert_array_equal(local.free_velocity, problem.free_velocity)


def test_the_readme_is_not_a_problem():
    with pytest.raises(ValueError, match=r"path: unknown problem format '\.md'.*README\.md"):
        io.read_problem(TESTDATA / "README.md")


def test_a_problem_without_contacts_is_empty():
    problem = io.read_problem(TESTDATA / "gfc2d_granularflowonwall_00000_00117.dat")
    assert problem.n_contacts == 0 and problem.delassus.shape == (0, 0)
    assert problem.free_velocity.shape == (0,)


@pytest.mark.parametrize("dense, sparse_block", [("FC3D_Example1.dat", "FC3D_Example1_SBM.dat"),
                                                 ("GFC3D_Example0.dat", "GFC3D_Example0_SBM.dat")])
def test_dense_and_sparse_block_files_hold_the_same_problem(dense, sparse_block):
    """Siconos ships these pairs: the dense reading (with its 'rows cols' line) matches SBM's."""
    first, second = io.read_problem(TESTDATA / dense), io.read_problem(TESTDATA / sparse_block)
    np.testing.assert_array_equal(first.delassus.toarray(), second.delassus.toarray())
    np.testing.assert_array_equal(first.free_velocity, second.free_velocity)
    np.testing.assert_array_equal(first.cones.mu, second.cones.mu)


def test_global_form_and_its_condensed_file_agree():
    """GFC3D_TwoRods1 (M, H, q, b) reduces to GFC3D_TwoRods1-condensed (W, q): q_loc = H^T M^-1 q + b."""
    record = io.read_global(TESTDATA / "GFC3D_TwoRods1.dat")
    condensed = io.read_problem(TESTDATA / "GFC3D_TwoRods1-condensed.dat")
    mass, jacobian = record.M.toarray(), record.H.toarray()
    assert np.abs(mass - mass.T).max() == 0 and np.abs(record.f).max() > 0
    delassus = jacobian.T @ np.linalg.solve(mass, jacobian)
    np.testing.assert_allclose(contact_major_delassus(condensed).toarray(), delassus, rtol=0,
                               atol=1e-6 * np.abs(delassus).max())
    q = condensed.to_contact_major(condensed.free_velocity)
    np.testing.assert_allclose(jacobian.T @ np.linalg.solve(mass, record.f) + record.w, q, rtol=0,
                               atol=1e-12 * np.abs(q).max())
    assert np.linalg.norm(-jacobian.T @ np.linalg.solve(mass, record.f) - q) > np.linalg.norm(q)
    np.testing.assert_allclose(record.to_local().delassus.toarray(), condensed.delassus.toarray(),
                               rtol=0, atol=1e-6 * np.abs(delassus).max())


def test_a_dense_global_problem_converts_with_its_full_mass_matrix():
    record = io.read_global(TESTDATA / "GFC3D_Example1.dat")
    np.testing.assert_array_equal(record.M.toarray(), [[106.5, 81.0, 126.5], [81.0, 91.5, 110.0],
                                                       [126.5, 110.0, 163.5]])
    np.testing.assert_array_equal(record.H.toarray(), np.eye(3))
    np.testing.assert_array_equal(record.w, [-2.5, -10.0, -5.5])
    problem = record.to_local()
    inverse = np.linalg.inv(record.M.toarray())
    np.testing.assert_allclose(contact_major_delassus(problem).toarray(), inverse, rtol=1e-12)
    np.testing.assert_allclose(problem.to_contact_major(problem.free_velocity), record.w, rtol=1e-12)


def test_delassus_diagnostics_report_asymmetry_and_definiteness():
    capsules = io.delassus_diagnostics(io.read_problem(TESTDATA / "Capsules-i122-1617.dat"))
    assert capsules["method"] == "dense" and capsules["n_rows"] == 888
    assert capsules["asymmetry"] > 0                     # real files need not be symmetric
    spheres = io.delassus_diagnostics(io.read_problem(TESTDATA / "Spheres-i099-356-679.hdf5"))
    assert spheres["asymmetry"] < 1e-14 and spheres["min_eigenvalue"] > 0     # W = H^T M^-1 H
    assert spheres["max_eigenvalue"] >= spheres["min_eigenvalue"]
    empty = io.delassus_diagnostics(io.read_problem(TESTDATA / "gfc2d_granularflowonwall_00000_00117.dat"))
    assert empty["n_rows"] == 0 and empty["asymmetry"] == 0.0


def test_delassus_diagnostics_of_a_large_problem_use_eigsh(monkeypatch):
    """Above the dense limit: shift-invert Lanczos and inertia give the dense eigenvalues."""
    from lubcontact.problem import global_form

    problem = io.read_problem(DATA / "siconos-fc2d/fc2d_granularflowonwall_00667_00000.dat")
    dense = io.delassus_diagnostics(problem)
    monkeypatch.setattr(global_form, "DENSE_EIGEN_LIMIT", 1000)
    sparse = io.delassus_diagnostics(problem)
    assert (dense["method"], sparse["method"], sparse["converged"]) == ("dense", "eigsh", True)
    for key in ("min_eigenvalue", "max_eigenvalue"):
        assert abs(sparse[key] - dense[key]) <= 1e-9 * dense["max_eigenvalue"], key
    assert dense["relative_min_eigenvalue"] > 0.01                   # this one is well conditioned


def test_delassus_diagnostics_find_a_negative_eigenvalue_far_below_zero(monkeypatch):
    from lubcontact.problem import global_form

    rng = np.random.default_rng(3)
    basis, _ = np.linalg.qr(rng.normal(size=(40, 40)))
    values = np.concatenate([[-5.0], np.zeros(9), rng.uniform(1, 100, 30)])
    matrix = (basis * values) @ basis.T
    problem = LocalProblem.from_contact_major(matrix, np.zeros(40), np.full(20, 0.3), 2)
    monkeypatch.setattr(global_form, "DENSE_EIGEN_LIMIT", 10)
    report = io.delassus_diagnostics(problem)
    assert report["method"] == "eigsh" and report["converged"]
    assert report["min_eigenvalue"] == pytest.approx(-5.0, rel=1e-8)
    assert report["max_eigenvalue"] == pytest.approx(values.max(), rel=1e-8)
