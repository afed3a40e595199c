"""Writers: every format written, read back, identical; step problems in FCLIB/Siconos form.

Text (Siconos ``.dat``) is written with ``repr`` floats, HDF5 stores the
doubles: both round trips are exact, so the arrays read back are identical and
so are the forces a deterministic solver returns on them. A step problem
written globally reads back as its own ``W`` and ``b`` (up to the row order),
and its solutions map across (``lubcontact.problem.global_form``).
"""
from __future__ import annotations

import dataclasses
import re

import h5py
import numpy as np
import pytest
import scipy.sparse as sp

from lubcontact import io
from lubcontact.bench import problem_sets
from lubcontact.bench.cases.builders import floor_scene, pyramid, scene_problem
from lubcontact.io.siconos import contact_major_delassus
from lubcontact.model.laws import Coulomb, Inelastic
from lubcontact.problem import ConeKind, Cones, LocalProblem
from lubcontact.problem.metrics import coulomb_error
from lubcontact.solvers.coulomb import solve_coulomb

DATA = problem_sets.data_dir()


# -- problems ----------------------------------------------------------------------------------
def random_local(dim: int, nc: int, seed: int, symmetric: bool = True) -> LocalProblem:
    """A sparse-ish contact-major W (some zero blocks), awkward floats, mu including 0."""
    rng = np.random.default_rng(seed)
    n = dim * nc
    factor = rng.normal(size=(n, n)) * (rng.uniform(size=(n, n)) < 0.3)
    matrix = factor @ factor.T + np.eye(n) / 3.0
    blocks = np.kron(rng.uniform(size=(nc, nc)) < 0.5, np.ones((dim, dim)))
    blocks = np.maximum(blocks, blocks.T) + np.kron(np.eye(nc), np.ones((dim, dim)))
    matrix = matrix * (blocks > 0) * np.exp(rng.normal(size=(n, n)) * 3)
    if symmetric:
        matrix = (matrix + matrix.T) / 2
    q = rng.normal(size=n) * 10.0 ** rng.integers(-20, 5, size=n)
    mu = rng.uniform(0, 1, nc)
    mu[0] = 0.0
    return LocalProblem.from_contact_major(sp.csr_matrix(matrix), q, mu, dim, name=f"random{dim}d")


def random_global(dim: int, nc: int, n_dof: int, seed: int, diagonal: bool = True) -> io.GlobalProblem:
    rng = np.random.default_rng(seed)
    m = dim * nc
    if diagonal:
        mass = sp.diags(rng.uniform(0.1, 10, n_dof) / 7.0)
    else:
        a = rng.normal(size=(n_dof, n_dof))
        mass = sp.csr_matrix(a @ a.T + n_dof * np.eye(n_dof))
    jacobian = sp.random(n_dof, m, density=0.3, random_state=seed) / 3.0
    return io.GlobalProblem(M=mass, H=jacobian, f=rng.normal(size=n_dof) / 7, w=rng.normal(size=m) / 3,
                            mu=rng.uniform(0, 1, nc), dim=dim, name=f"global{dim}d")


def step_problem(kind: str):
    rng = np.random.default_rng(4)
    if kind == "3d":
        centres = np.array([[0, 0.5, 0], [1.0, 0.5, 0], [0, 0.5, 1.0], [1, 0.5, 1], [0.5, 1.2075, 0.5]])
        law = Coulomb(0.4)
    else:
        centres = pyramid(3)
        law = Inelastic() if kind == "2d-frictionless" else Coulomb(0.3)
    scene = floor_scene(centres, 0.5, masses=rng.uniform(0.5, 2, len(centres)),
                        velocities=rng.normal(size=centres.shape))
    return scene_problem(scene, law, 0.01, d_max=0.05)


def same_local(first: LocalProblem, second: LocalProblem) -> None:
    assert (first.dim, first.n_contacts) == (second.dim, second.n_contacts)
    np.testing.assert_array_equal(first.delassus.toarray(), second.delassus.toarray())
    np.testing.assert_array_equal(first.free_velocity, second.free_velocity)
    np.testing.assert_array_equal(first.cones.mu, second.cones.mu)


def same_global(first: io.GlobalProblem, second: io.GlobalProblem) -> None:
    assert (first.dim, first.n_contacts, first.n_dof) == (second.dim, second.n_contacts, second.n_dof)
    for key in ("M", "H"):
        one, two = getattr(first, key), getattr(second, key)
        assert one.shape == two.shape and (one != two).nnz == 0, key
    for key in ("f", "w", "mu"):
        np.testing.assert_array_equal(getattr(first, key), getattr(second, key))


def same_forces(first: LocalProblem, second: LocalProblem) -> None:
    """A deterministic solver gives bitwise the same forces on both."""
    one = solve_coulomb(first, "apgd-jacobi", tol=1e-10, tol_fp=1e-10, max_outer=100)
    two = solve_coulomb(second, "apgd-jacobi", tol=1e-10, tol_fp=1e-10, max_outer=100)
    assert one.status == two.status
    np.testing.assert_array_equal(one.forces, two.forces)


# -- Siconos's line-by-line reading of a CSparse listing (CSparseMatrix_new_from_file) ------------
def check_csparse_lines(text: str) -> int:
    """Every compressed-column listing follows the line discipline of Siconos' reader.

    After the origin line come a version line and the size line; then each
    column is one ``col j : locations a to b`` line (7 words) and ``b - a + 1``
    lines of exactly ``i : x``, ``x`` at most 32 characters (``%32le``).
    Returns the number of listings checked.
    """
    lines = text.splitlines()
    found = 0
    for k, line in enumerate(lines):
        if not line.startswith("CSparse"):
            continue
        found += 1
        assert lines[k - 1].split() == ["2"]                       # origin: compressed columns
        size = re.match(r"(\d+)-by-(\d+), nzmax: (\d+) nnz: (\d+), 1-norm: ", lines[k + 1])
        assert size, lines[k + 1]
        columns, nnz = int(size.group(2)), int(size.group(4))
        row = k + 2
        for j in range(columns):
            words = lines[row].split()
            assert len(words) == 7 and words[:4] == ["col", str(j), ":", "locations"], lines[row]
            first, last = int(words[4]), int(words[6])
            for entry in lines[row + 1: row + 2 + last - first]:
                words = entry.split()
                assert len(words) == 3 and words[1] == ":" and len(words[2]) <= 32, entry
            row += 2 + last - first
        assert last + 1 == nnz if columns else True
    return found


# -- Siconos local ---------------------------------------------------------------------------------
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("storage", [0, 1, 2])
def test_siconos_local_round_trip(tmp_path, dim, storage):
    problem = random_local(dim, 5, seed=dim + 10 * storage)
    path = io.write_siconos(problem, tmp_path / "problem.dat", storage=storage)
    text = path.read_text()
    assert text.splitlines()[:3] == [str(dim), "5", str(storage)]
    assert check_csparse_lines(text) == (storage == 2)
    back = io.read_problem(path)
    assert back.name == "problem"
    same_local(problem, back)
    same_forces(problem, back)


def test_siconos_default_storage_is_dense_when_small(tmp_path):
    small, large = random_local(3, 4, seed=1), random_local(2, 40, seed=2)
    assert io.write_siconos(small, tmp_path / "small.dat").read_text().splitlines()[2] == "0"
    assert io.write_siconos(large, tmp_path / "large.dat").read_text().splitlines()[2] == "2"
    lines = (tmp_path / "small.dat").read_text().splitlines()
    assert lines[5] == "12\t12"                                     # Siconos' second size line
    same_local(large, io.read_problem(tmp_path / "large.dat"))


def test_siconos_writes_nonsymmetric_and_empty_problems(tmp_path):
    problem = random_local(3, 4, seed=5, symmetric=False)
    assert abs(problem.delassus - problem.delassus.T).max() > 0
    for storage in (0, 1, 2):
        same_local(problem, io.read_problem(io.write_siconos(problem, tmp_path / f"{storage}.dat",
                                                             storage=storage)))
    empty = LocalProblem.from_contact_major(sp.csr_matrix((0, 0)), [], [], 3)
    for storage in (0, 1, 2):
        back = io.read_problem(io.write_siconos(empty, tmp_path / f"empty{storage}.dat", storage=storage))
        assert back.n_contacts == 0 and back.dim == 3


# -- Siconos global --------------------------------------------------------------------------------
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("storage", [0, 2])
def test_siconos_global_round_trip(tmp_path, dim, storage):
    record = random_global(dim, 3, 11, seed=dim + storage, diagonal=storage == 0)
    path = io.write_siconos(record, tmp_path / "global.dat", storage=storage)
    assert check_csparse_lines(path.read_text()) == (2 if storage == 2 else 0)
    back = io.read_global(path)
    same_global(record, back)
    local = io.read_problem(path)
    same_local(record.to_local(), local)
    same_forces(local, back.to_local())


def test_a_global_problem_with_an_n_by_n_mass_matrix_is_recognised(tmp_path):
    """M has the size of W (n_dof = dim nc): the second matrix header tells the files apart."""
    record = random_global(3, 2, 6, seed=7)
    back = io.read_global(io.write_siconos(record, tmp_path / "square.dat", storage=0))
    same_global(record, back)
    with pytest.raises(ValueError, match=r"local\.dat: a local problem"):
        io.read_global(io.write_siconos(record.to_local(), tmp_path / "local.dat"))


# -- FCLIB -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("dim", [2, 3])
def test_fclib_local_round_trip_with_solution_and_metadata(tmp_path, dim):
    problem = random_local(dim, 6, seed=20 + dim)
    forces = solve_coulomb(problem, "apgd-jacobi", tol=1e-10, tol_fp=1e-10, max_outer=100).forces
    metadata = dict(description="a test problem", math_info="", numberOfInvolvedDS=7, step=1e-3)
    path = io.write_fclib_local(problem, tmp_path / "local.hdf5", solution=forces, metadata=metadata)
    back = io.read_problem(path)
    same_local(problem, back)
    same_forces(problem, back)
    solution = io.read_fclib_solution(path)
    assert set(solution) == {"r", "u"}
    np.testing.assert_array_equal(solution["r"], problem.to_contact_major(forces))
    np.testing.assert_array_equal(solution["u"], problem.to_contact_major(problem.velocity(forces)))
    assert io.read_fclib_metadata(path) == dict(title=f"random{dim}d", **metadata)
    with h5py.File(path) as handle:                      # FCLIB's own layout and types
        group = handle["fclib_local"]
        assert group["spacedim"].dtype == np.int32 and group["spacedim"][()].tolist() == [dim]
        assert group["W/nz"][()].tolist() == [-2] and group["W/p"].dtype == np.int32
        assert group["W/nzmax"][()].tolist() == [group["W/x"].shape[0]]


@pytest.mark.parametrize("dim", [2, 3])
def test_fclib_global_round_trip_with_solution(tmp_path, dim):
    record = random_global(dim, 4, 13, seed=30 + dim, diagonal=dim == 2)
    forces = np.random.default_rng(dim).uniform(size=dim * 4)
    path = io.write_fclib_global(record.M, record.H, record.f, record.w, record.mu,
                                 tmp_path / "global.h5", solution=forces)
    back = io.read_global(path)
    same_global(record, back)
    same_local(record.to_local(), io.read_problem(path))
    solution = io.read_fclib_solution(path)
    np.testing.assert_array_equal(solution["r"], forces)
    velocity = np.linalg.solve(record.M.toarray(), record.H @ forces + record.f)
    np.testing.assert_allclose(solution["v"], velocity, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(solution["u"], record.H.T @ velocity + record.w, rtol=1e-12, atol=1e-14)
    with h5py.File(path) as handle:
        assert [handle[f"fclib_global/{key}/nz"][()].tolist() for key in "MH"] == [[-1], [-1]]


def test_fclib_global_needs_dim_without_contacts(tmp_path):
    with pytest.raises(ValueError, match="dim: cannot infer spacedim"):
        io.write_fclib_global(sp.eye(3), sp.csr_matrix((3, 0)), np.ones(3), [], [], tmp_path / "x.h5")
    path = io.write_fclib_global(sp.eye(3), sp.csr_matrix((3, 0)), np.ones(3), [], [],
                                 tmp_path / "x.h5", dim=2)
    assert io.read_problem(path).n_contacts == 0


# -- the shipped files, written back ---------------------------------------------------------------
REAL_LOCAL = ["siconos-testdata/Capsules-i122-1617.dat", "siconos-testdata/FrictionContact3D_1c.dat",
              "siconos-testdata/FrictionContactProblem00031.dat",
              "siconos-testdata/OneObject-i1028-138.hdf5.dat",
              "siconos-fc2d/fc2d_granularflowonwall_00667_00000.dat",
              "fclib-local/LMGC_100_PR_PerioBox-i00361-60-03000.hdf5"]
REAL_GLOBAL = ["siconos-testdata/GFC3D_TwoRods1.dat", "siconos-testdata/GFC3D_Example1.dat",
               "siconos-testdata/gfc2d_granularflowonwall_00069_00350.dat",
               "siconos-testdata/gfc2d_granularflowonwall_00000_00117.dat",
               "siconos-testdata/Spheres-i099-356-679.hdf5", "fclib-local/Box_Stacks-i0122-82-5.hdf5"]


@pytest.mark.parametrize("name", REAL_LOCAL)
def test_real_local_problems_written_back(tmp_path, name):
    problem = io.read_problem(DATA / name)
    for storage in (0, 1, 2) if problem.n_rows <= 200 else (1, 2):
        same_local(problem, io.read_problem(io.write_siconos(problem, tmp_path / f"s{storage}.dat",
                                                             storage=storage)))
    back = io.read_problem(io.write_fclib_local(problem, tmp_path / "f.hdf5"))
    same_local(problem, back)
    if problem.n_rows <= 200:
        same_forces(problem, back)


@pytest.mark.parametrize("name", REAL_GLOBAL)
def test_real_global_problems_written_back(tmp_path, name):
    record = io.read_global(DATA / name)
    same_global(record, io.read_global(io.write_siconos(record, tmp_path / "s.dat")))
    path = io.write_fclib_global(record.M, record.H, record.f, record.w, record.mu, tmp_path / "f.hdf5",
                                 dim=record.dim)
    same_global(record, io.read_global(path))
    same_local(io.read_problem(DATA / name), io.read_problem(path))


# -- step problems ----------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["2d", "3d", "2d-frictionless"])
def test_a_step_problem_is_a_global_problem(tmp_path, kind):
    """The local form of the written global problem is the step's own W and b, re-ordered."""
    step = step_problem(kind)
    dim, nc = step.cones.tangent_dim + 1, step.n_contacts
    record = io.global_from_step(step)
    assert (record.dim, record.n_contacts, record.n_dof) == (dim, nc, step.n_dof)
    np.testing.assert_array_equal(record.M.diagonal(), step.mass)
    # E: our rows -> contact-major rows; the step's W and b re-ordered, no scaling
    expansion = _expansion(step)
    delassus = (expansion @ step.delassus @ expansion.T).toarray()
    offset = expansion @ step.offset
    local = record.to_local()
    scale = np.abs(delassus).max()
    np.testing.assert_allclose(contact_major_delassus(local).toarray(), delassus, rtol=0,
                               atol=1e-14 * scale)
    np.testing.assert_allclose(local.to_contact_major(local.free_velocity), offset, rtol=0,
                               atol=1e-14 * np.abs(offset).max())
    direct = io.local_from_step(step)
    np.testing.assert_allclose(direct.delassus.toarray(), local.delassus.toarray(), rtol=0,
                               atol=1e-14 * scale)
    np.testing.assert_array_equal(direct.cones.mu, record.mu)
    if kind == "2d-frictionless":
        assert np.all(record.mu == 0) and np.all(contact_major_delassus(local).toarray()[1::2] == 0)
    # written and read back, globally (FCLIB and Siconos) and locally
    reference = solve_coulomb(step, "clarabel", tol=1e-10)
    path = io.write_fclib(step, tmp_path / "step.hdf5", solution=reference)
    same_global(record, io.read_global(path))
    same_global(record, io.read_global(io.write_siconos(step, tmp_path / "step.dat")))
    same_local(direct, io.read_problem(io.write_siconos(direct, tmp_path / "local.dat")))
    solution = io.read_fclib_solution(path)
    forces = io.step_forces_to_local(step, reference.forces, contact_major=True)
    np.testing.assert_array_equal(solution["r"], forces)
    velocity = step.velocity(reference.forces)
    np.testing.assert_allclose(solution["v"], velocity, rtol=1e-12, atol=1e-12 * np.abs(velocity).max())
    g = step.gradient(reference.forces)                     # the constraint values (zero shift)
    np.testing.assert_allclose(solution["u"], expansion @ g, rtol=0, atol=1e-12 * np.abs(g).max())
    # the same Coulomb solution, measured alike, from the step and from its local form
    local_forces = io.step_forces_to_local(step, reference.forces)
    assert coulomb_error(direct, local_forces) == pytest.approx(coulomb_error(step, reference.forces),
                                                                rel=1e-6, abs=1e-14)
    result = solve_coulomb(direct, "clarabel-dual", tol=1e-10)
    assert result.status == "converged"
    np.testing.assert_allclose(result.forces, local_forces, rtol=0,
                               atol=1e-6 * np.abs(local_forces).max())


def _expansion(step) -> sp.csr_matrix:
    """E built column by column through the public force map."""
    return sp.csr_matrix(np.column_stack([io.step_forces_to_local(step, column, contact_major=True)
                                          for column in np.eye(step.n_rows)]))


@pytest.mark.parametrize("kind", [ConeKind.UNION, ConeKind.FREE, ConeKind.NONPOS])
def test_cones_fclib_cannot_express_are_refused(tmp_path, kind):
    step = step_problem("2d")
    kinds = step.cones.kinds.copy()
    kinds[2] = kind
    cones = Cones(kinds=kinds, mu=step.cones.mu, tangential=step.cones.tangential,
                  tangent_dim=step.cones.tangent_dim)
    gluey = dataclasses.replace(step, cones=cones)
    for convert in (io.global_from_step, io.local_from_step):
        with pytest.raises(ValueError, match=rf"cones: contact 2 is {kind.name}.*Coulomb cones only"):
            convert(gluey)
    with pytest.raises(ValueError, match="cones: contact 2"):
        io.write_fclib(gluey, tmp_path / "gluey.hdf5")
    assert not (tmp_path / "gluey.hdf5").exists()
