"""Readers of external frictional problems (lubcontact.io) and solving them exactly.

Small files written here check each format (shapes, values, symmetry, mu,
spacedim, the layout permutation) and the errors on bad input; the Siconos and
FCLIB files that ship with the package (``lubcontact/bench/data``, found by
:func:`lubcontact.bench.problem_sets.data_dir`) are read and solved by the fixed
point on s to the FCLIB error of MODEL.md section 6. The data always ships: a
missing file is a failure, never a skip. The last tests check how ``data_dir``
picks the folder (override, ``LUBCONTACT_DATA_DIR``, package data).
"""
from __future__ import annotations

import re
import shutil

import h5py
import numpy as np
import pytest
import scipy.sparse as sp

from lubcontact import io
from lubcontact.bench import problem_sets
from lubcontact.problem.metrics import coulomb_error
from lubcontact.solvers.coulomb import solve_coulomb

# Two 2D contacts in contact-major layout (normal, tangent per contact).
W2 = np.array([[4.0, 1.0, 0.5, 0.0],
               [1.0, 3.0, 0.0, 0.2],
               [0.5, 0.0, 5.0, 1.0],
               [0.0, 0.2, 1.0, 2.0]])
Q2 = np.array([-1.0, 0.5, 2.0, -0.3])
MU2 = np.array([0.3, 0.5])
OURS2 = [0, 2, 1, 3]          # [normals, tangents] from contact-major

DATA = problem_sets.data_dir()
SICONOS = DATA / "siconos-fc2d"
FCLIB = DATA / "fclib-local"


# -- writers of the file formats (test side) -------------------------------------------------
def siconos_text(matrix: np.ndarray, q, mu, dim: int, storage: int = 2,
                 size_line: bool = False) -> str:
    """A Siconos ``frictionContact_printInFile`` file (cs_print listing for storage 2).

    For storage 0, ``size_line`` adds the ``rows\tcols`` line Siconos'
    ``NM_write_in_file`` writes before the dense values (older files lack it).
    """
    n = matrix.shape[0]
    lines = [str(dim), str(len(mu)), str(storage), str(n), str(n)]
    if storage == 0 and size_line:
        lines.append(f"{n}\t{n}")
    if storage == 2:
        csc = sp.csc_matrix(matrix)
        lines += ["2", "CSparse Version 3.1.9, May 4, 2016.  Copyright (c) Timothy A. Davis",
                  f"{n}-by-{n}, nzmax: {csc.nnz} nnz: {csc.nnz}, 1-norm: 1"]
        for j in range(n):
            start, stop = csc.indptr[j], csc.indptr[j + 1]
            lines.append(f"    col {j} : locations {start} to {stop - 1}")
            lines += [f"      {i} : {v:g}" for i, v in zip(csc.indices[start:stop],
                                                         csc.data[start:stop])]
    else:
        lines += [f"{v:.17g}" for v in matrix.ravel(order="F")]
    lines += [" ".join(f"{v:g}" for v in q), " ".join(f"{v:g}" for v in mu)]
    return "\n".join(lines) + "\n"


def write_matrix(group, name: str, matrix, storage: str) -> None:
    """An FCLIB matrix group: ``csc`` (nz = -1), ``csr`` (nz = -2) or ``triplet``."""
    sub = group.create_group(name)
    m, n = matrix.shape
    if storage == "triplet":
        coo = sp.coo_matrix(matrix)
        p, i, x, nz = coo.col, coo.row, coo.data, coo.nnz
    else:
        compressed = sp.csc_matrix(matrix) if storage == "csc" else sp.csr_matrix(matrix)
        p, i, x, nz = compressed.indptr, compressed.indices, compressed.data, \
            -1 if storage == "csc" else -2
    for key, value in (("m", [m]), ("n", [n]), ("nz", [nz]), ("p", p), ("i", i)):
        sub.create_dataset(key, data=np.asarray(value, dtype=np.int32))
    sub.create_dataset("x", data=np.asarray(x, dtype=float))


def write_fclib_local(path, matrix, q, mu, dim, storage="csr"):
    with h5py.File(path, "w") as handle:
        group = handle.create_group("fclib_local")
        write_matrix(group, "W", matrix, storage)
        group.create_dataset("vectors/q", data=q)
        group.create_dataset("vectors/mu", data=mu)
        group.create_dataset("spacedim", data=np.array([dim], dtype=np.int32))


def write_fclib_global(path, mass, jacobian, f, w, mu, dim):
    with h5py.File(path, "w") as handle:
        group = handle.create_group("fclib_global")
        write_matrix(group, "M", mass, "triplet")
        write_matrix(group, "H", jacobian, "csc")
        group.create_dataset("vectors/f", data=f)
        group.create_dataset("vectors/w", data=w)
        group.create_dataset("vectors/mu", data=mu)
        group.create_dataset("spacedim", data=np.array([dim], dtype=np.int32))


def check_small_2d(problem):
    assert problem.n_contacts == 2 and problem.dim == 2 and problem.n_rows == 4
    W = problem.delassus.toarray()
    np.testing.assert_allclose(W, W2[np.ix_(OURS2, OURS2)], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(W, W.T)
    np.testing.assert_allclose(problem.free_velocity, Q2[OURS2], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(problem.cones.mu, MU2)
    np.testing.assert_array_equal(problem.to_contact_major(problem.free_velocity), Q2)


# -- Siconos .dat ----------------------------------------------------------------------------
@pytest.mark.parametrize("storage", [2, 0])
def test_siconos_small_problem(tmp_path, storage):
    path = tmp_path / "two.dat"
    path.write_text(siconos_text(W2, Q2, MU2, 2, storage))
    problem = io.read_problem(path)
    check_small_2d(problem)
    assert problem.name == "two"


def test_siconos_dense_as_siconos_writes_it(tmp_path):
    """NM_write_in_file: storage, rows, columns, then 'rows\tcols' again, then the values."""
    path = tmp_path / "real.dat"
    text = siconos_text(W2, Q2, MU2, 2, storage=0, size_line=True)
    assert text.splitlines()[5] == "4\t4"
    path.write_text(text)
    check_small_2d(io.read_problem(path))
    real = io.read_problem(SICONOS.parent / "siconos-testdata" / "FC2D_SliderCrankLagrangian00000.dat")
    assert (real.n_contacts, real.dim) == (2, 2)


@pytest.mark.parametrize("edit, field", [
    (lambda lines: ["4"] + lines[1:], "dim"),
    (lambda lines: lines[:3] + ["5"] + lines[4:], "W"),
    (lambda lines: lines[:2] + ["7"] + lines[3:], "storage"),
    (lambda lines: lines[:-1], "mu"),
    (lambda lines: lines[:-1] + ["0.3 -0.5"], "mu"),
    (lambda lines: lines[:-2] + ["1 2 x 4", lines[-1]], "q"),
    (lambda lines: lines[:8] + lines[9:], "W"),
])
def test_siconos_bad_input_names_the_field(tmp_path, edit, field):
    lines = siconos_text(W2, Q2, MU2, 2).splitlines()
    path = tmp_path / "bad.dat"
    path.write_text("\n".join(edit(lines)) + "\n")
    with pytest.raises(ValueError, match=rf"\b{field}\b"):
        io.read_problem(path)


def test_missing_file_and_unknown_format(tmp_path):
    for name in ("absent.dat", "absent.hdf5"):
        with pytest.raises(FileNotFoundError, match="absent"):
            io.read_problem(tmp_path / name)
    with pytest.raises(ValueError, match="path: unknown problem format '.txt'"):
        io.read_problem(tmp_path / "problem.txt")


def test_siconos_2020_file():
    problem = io.read_problem(SICONOS / "fc2d_granularflowonwall_02020_00213.dat")
    assert (problem.n_contacts, problem.dim, problem.delassus.shape) == (2020, 2, (4040, 4040))
    np.testing.assert_array_equal(problem.cones.mu, np.full(2020, 0.5))
    assert abs(problem.delassus - problem.delassus.T).max() == 0.0


def test_siconos_667_solved_by_the_fast_fixed_point():
    """The 667-contact problem has |q| ~ 4e-18: the error is checked on the normalised problem."""
    problem = io.read_problem(SICONOS / "fc2d_granularflowonwall_00667_00000.dat")
    result = solve_coulomb(problem, "apgd-jacobi", tol=1e-10, tol_fp=1e-10, max_outer=300,
                           forcing=1e-4, anderson=5)
    assert result.status == "converged"
    scaled = problem.normalized()
    forces = result.forces / scaled.scaling.force
    assert coulomb_error(scaled, forces) <= 1e-8
    assert coulomb_error(problem, result.forces) <= 1e-8
    normal = forces[: problem.n_contacts]
    assert np.count_nonzero(normal > 1e-6 * normal.max()) > 100       # a real, loaded problem


@pytest.mark.slow
def test_siconos_2020_solved_by_the_fast_fixed_point():
    problem = io.read_problem(SICONOS / "fc2d_granularflowonwall_02020_00213.dat")
    result = solve_coulomb(problem, "apgd-jacobi", tol=1e-9, tol_fp=1e-9, max_outer=300,
                           forcing=1e-4, anderson=5)
    assert result.status == "converged"
    assert coulomb_error(problem, result.forces) <= 1e-8


# -- FCLIB local -----------------------------------------------------------------------------
@pytest.mark.parametrize("storage", ["csc", "csr", "triplet"])
def test_fclib_local_small_problem(tmp_path, storage):
    path = tmp_path / "two.hdf5"
    write_fclib_local(path, W2, Q2, MU2, 2, storage)
    check_small_2d(io.read_problem(path))


def test_fclib_local_3d_layout(tmp_path):
    rng = np.random.default_rng(0)
    a = rng.normal(size=(6, 6))
    matrix, q, mu = a @ a.T + np.eye(6), rng.normal(size=6), np.array([0.1, 0.7])
    path = tmp_path / "three.h5"
    write_fclib_local(path, matrix, q, mu, 3)
    problem = io.read_problem(path)
    order = [0, 3, 1, 2, 4, 5]
    assert (problem.n_contacts, problem.dim, problem.cones.tangent_dim) == (2, 3, 2)
    np.testing.assert_allclose(problem.delassus.toarray(), matrix[np.ix_(order, order)], atol=1e-14)
    np.testing.assert_array_equal(problem.free_velocity, q[order])
    np.testing.assert_array_equal(problem.cones.mu, mu)


@pytest.mark.parametrize("change, field", [
    ("drop q", "vectors/q"),
    ("mu", "mu"),
    ("spacedim", "spacedim"),
    ("nz", "nz"),
    ("short q", "q"),
    ("no group", "neither an fclib_local nor an fclib_global"),
])
def test_fclib_bad_input_names_the_field(tmp_path, change, field):
    path = tmp_path / "bad.hdf5"
    write_fclib_local(path, W2, Q2, MU2, 2)
    with h5py.File(path, "r+") as handle:
        group = handle["fclib_local"]
        if change == "drop q":
            del group["vectors/q"]
        elif change == "mu":
            group["vectors/mu"][0] = -0.1
        elif change == "spacedim":
            group["spacedim"][0] = 4
        elif change == "nz":
            group["W/nz"][0] = -3
        elif change == "short q":
            del group["vectors/q"]
            group.create_dataset("vectors/q", data=Q2[:3])
        else:
            del handle["fclib_local"]
    with pytest.raises(ValueError, match=rf"(?<!\w){re.escape(field)}\b"):
        io.read_problem(path)


def test_fclib_local_problem_solved_by_the_fast_fixed_point():
    problem = io.read_problem(FCLIB / "LMGC_100_PR_PerioBox-i00361-60-03000.hdf5")
    assert (problem.n_contacts, problem.dim) == (60, 3)
    result = solve_coulomb(problem, "apgd-jacobi", tol=1e-10, tol_fp=1e-10, max_outer=100)
    assert result.status == "converged"
    assert coulomb_error(problem, result.forces) <= 1e-8


# -- FCLIB global ----------------------------------------------------------------------------
def test_global_to_local_with_a_full_mass_matrix():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(5, 5))
    mass = a @ a.T + 5 * np.eye(5)
    jacobian, f, w = rng.normal(size=(5, 4)), rng.normal(size=5), rng.normal(size=4)
    delassus, q = io.global_to_local(sp.csr_matrix(mass), sp.csr_matrix(jacobian), f, w)
    np.testing.assert_allclose(delassus.toarray(), jacobian.T @ np.linalg.solve(mass, jacobian),
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(q, jacobian.T @ np.linalg.solve(mass, f) + w, rtol=1e-12)
    with pytest.raises(ValueError, match="M: expected shape"):
        io.global_to_local(sp.eye(4), sp.csr_matrix(jacobian), f, w)
    with pytest.raises(ValueError, match="w: expected shape"):
        io.global_to_local(sp.csr_matrix(mass), sp.csr_matrix(jacobian), f, w[:3])


def test_fclib_global_small_problem(tmp_path):
    mass = np.diag([2.0, 3.0, 4.0, 5.0])
    jacobian = np.array([[1.0, 0.0, 0.0, 1.0],
                         [0.0, 1.0, 1.0, 0.0],
                         [0.5, 0.0, 1.0, 0.0],
                         [0.0, 0.3, 0.0, 1.0]])
    f, w = np.array([1.0, -2.0, 0.5, 0.0]), np.array([0.1, 0.0, -0.2, 0.3])
    path = tmp_path / "global.hdf5"
    write_fclib_global(path, mass, jacobian, f, w, MU2, 2)
    problem = io.read_problem(path)
    delassus = jacobian.T @ np.linalg.solve(mass, jacobian)
    np.testing.assert_allclose(problem.delassus.toarray(), delassus[np.ix_(OURS2, OURS2)],
                               atol=1e-14)
    np.testing.assert_allclose(problem.free_velocity,
                               (jacobian.T @ np.linalg.solve(mass, f) + w)[OURS2], atol=1e-14)
    np.testing.assert_array_equal(problem.cones.mu, MU2)


def test_box_stacks_global_round_trip():
    """W read from M and H equals the Delassus matrix assembled here from the raw arrays."""
    path = FCLIB / "Box_Stacks-i0122-82-5.hdf5"
    problem = io.read_problem(path)
    with h5py.File(path, "r") as handle:
        group = handle["fclib_global"]

        def triplets(name):
            m, n, nz = (int(group[f"{name}/{key}"][0]) for key in ("m", "n", "nz"))
            assert nz >= 0                               # triplet storage in this file
            rows, cols = group[f"{name}/i"][:nz], group[f"{name}/p"][:nz]
            dense = np.zeros((m, n))
            np.add.at(dense, (rows, cols), group[f"{name}/x"][:nz])
            return dense

        mass, jacobian = triplets("M"), triplets("H")
        f, w, mu = (group[f"vectors/{key}"][()] for key in ("f", "w", "mu"))
    delassus = jacobian.T @ np.linalg.solve(mass, jacobian)
    assert (problem.n_contacts, problem.dim) == (82, 3)
    back = problem.to_contact_major
    W = np.array([back(column) for column in problem.delassus.toarray().T]).T
    W = np.array([back(row) for row in W])
    np.testing.assert_allclose(W, delassus, rtol=0, atol=1e-12 * np.abs(delassus).max())
    np.testing.assert_allclose(back(problem.free_velocity),
                               jacobian.T @ np.linalg.solve(mass, f) + w, rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(problem.cones.mu, mu)
    result = solve_coulomb(problem, "apgd-jacobi", tol=1e-10, tol_fp=1e-10, max_outer=100)
    assert result.status == "converged"
    assert coulomb_error(problem, result.forces) <= 1e-8


# -- the packaged data and data_dir ------------------------------------------------------------
SHIPPED = {
    "siconos-fc2d": ["fc2d_granularflowonwall_00667_00000.dat",
                     "fc2d_granularflowonwall_02020_00213.dat",
                     "fc2d_granularflowonwall_07002_00801.dat"],
    "fclib-local": ["Box_Stacks-i0122-82-5.hdf5", "Capsules-i125-1213.hdf5",
                    "LMGC_100_PR_PerioBox-i00361-60-03000.hdf5", "local_problem_test.hdf5"],
    "siconos-testdata": ["README.md", "FrictionContact3D_1c.dat", "GFC3D_TwoRods1.dat",
                         "Spheres-i099-356-679.hdf5"],
}


def test_the_benchmark_data_ships_with_the_package(monkeypatch):
    monkeypatch.delenv(problem_sets.DATA_DIR_ENV, raising=False)
    root = problem_sets.data_dir()
    assert root == problem_sets.PACKAGE_DATA
    assert root.parent.name == "bench" and (root / "README.md").is_file()
    for folder, names in SHIPPED.items():
        for name in names:
            assert problem_sets.benchmark_file(folder, name) == root / folder / name
    assert len(list((root / "siconos-testdata").iterdir())) == 29     # 28 problems + README
    with pytest.raises(problem_sets.SetUnavailable, match=r"'fclib-local' has no file 'absent\.hdf5'"):
        problem_sets.benchmark_file("fclib-local", "absent.hdf5")


def test_data_dir_honours_the_environment_and_the_override(tmp_path, monkeypatch):
    from_env, explicit = tmp_path / "env", tmp_path / "explicit"
    (from_env / "fclib-local").mkdir(parents=True)
    (explicit / "fclib-local").mkdir(parents=True)
    name = "LMGC_100_PR_PerioBox-i00361-60-03000.hdf5"
    shutil.copy(FCLIB / name, from_env / "fclib-local" / name)
    shutil.copy(FCLIB / "local_problem_test.hdf5", explicit / "fclib-local")

    monkeypatch.setenv("LUBCONTACT_DATA_DIR", str(from_env))
    assert problem_sets.data_dir() == from_env
    assert problem_sets.data_dir(explicit) == explicit              # the override wins
    assert problem_sets.data_dir(str(explicit)) == explicit
    fclib = problem_sets.SETS["fclib"]
    assert [i.name for i in fclib.instances()] == [name.removesuffix(".hdf5")]
    assert [i.name for i in fclib.instances(data=explicit)] == ["local_problem_test"]
    missing = r"no problem files \(\*\.dat\) in benchmark folder 'siconos-fc2d'"
    with pytest.raises(problem_sets.SetUnavailable, match=missing):
        problem_sets.SETS["siconos-fc2d"].instances()
    with pytest.raises(problem_sets.SetUnavailable, match=r"'siconos-fc2d' has no file 'x\.dat'"):
        problem_sets.benchmark_file("siconos-fc2d", "x.dat")

    monkeypatch.setenv("LUBCONTACT_DATA_DIR", "")                   # empty: unset
    assert problem_sets.data_dir() == problem_sets.PACKAGE_DATA


def test_data_dir_rejects_a_non_directory(tmp_path, monkeypatch):
    monkeypatch.delenv(problem_sets.DATA_DIR_ENV, raising=False)
    a_file = tmp_path / "problems.dat"
    a_file.write_text("2\n")
    for bad in (a_file, tmp_path / "absent", str(a_file)):
        with pytest.raises(ValueError, match=r"^data_dir: not a directory: .*(problems\.dat|absent)"):
            problem_sets.data_dir(bad)
    monkeypatch.setenv("LUBCONTACT_DATA_DIR", str(a_file))
    with pytest.raises(ValueError, match=r"data_dir: not a directory: .*LUBCONTACT_DATA_DIR"):
        problem_sets.data_dir()
    with pytest.raises(ValueError, match="data_dir"):
        problem_sets.SETS["fclib"].instances()
