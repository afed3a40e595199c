"""The Siconos peer (lubcontact.solvers.siconos_peer): absent, broken, and, where installed, solving.

Without Siconos (CI) the peer must say so and register nothing, and a worker
that crashes or hangs must come back as ``failed`` with its stderr. With
Debian's ``python3-siconos`` (the system interpreter), every registered
method is checked on one 3D (FCLIB) and one 2D (Siconos) file against the
FCLIB error and against lubcontact's own exact-Coulomb solve; those tests are
skipped, with the probe's reason, where Siconos is absent: the peer is optional.
"""
from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from lubcontact.io import read_problem
from lubcontact.problem import ConeKind
from lubcontact.problem.cones import Cones
from lubcontact.problem.local import LocalProblem
from lubcontact.problem.metrics import coulomb_error, coulomb_shift, relative_error, scaled_coulomb_error
from lubcontact.solvers import CONVERGED, FAILED, methods, solve, solve_coulomb, solver_info
from lubcontact.solvers import siconos_peer as peer

DATA = Path(__file__).resolve().parents[2] / "lubcontact" / "bench" / "data"
BOX_STACKS = DATA / "fclib-local" / "Box_Stacks-i0122-82-5.hdf5"          # 3D, 82 contacts
GRANULAR_2D = DATA / "siconos-fc2d" / "fc2d_granularflowonwall_00667_00000.dat"   # 2D, 667
FILES = {"box-stacks-3d": BOX_STACKS, "granular-2d": GRANULAR_2D}
NAMES = ("siconos-nsgs", "siconos-nsn-ac", "siconos-prox", "siconos-desaxce-fp")


@pytest.fixture
def interpreter(monkeypatch):
    """Point the peer at another interpreter for one test (the probe cache is cleared around it)."""
    def use(path: str) -> None:
        monkeypatch.setenv(peer.PYTHON_ENV, path)
        peer.clear_probe_cache()

    yield use
    peer.clear_probe_cache()


def small_problem(dim: int = 3) -> LocalProblem:
    """Two contacts in FCLIB layout: one pressed and sliding, one separating."""
    W = np.eye(2 * dim) + 0.1 * np.ones((2 * dim, 2 * dim))
    q = np.zeros(2 * dim)
    q[0], q[1], q[dim] = -1.0, 0.5, 0.3
    return LocalProblem.from_contact_major(W, q, [0.3, 0.5], dim)


# -- without Siconos ---------------------------------------------------------------------------
def test_missing_interpreter_means_unavailable_with_a_reason_and_nothing_registered(interpreter, tmp_path):
    peer.unregister_siconos()        # another test's command (compare) may have registered them
    interpreter(str(tmp_path / "no-such-python"))
    status = peer.siconos_status()
    assert not peer.siconos_available()
    assert not status.available and "not found" in status.reason and peer.PYTHON_ENV in status.reason
    before = methods()
    assert peer.register_siconos() == []
    assert methods() == before and not any(name.startswith("siconos-") for name in methods())


def test_an_interpreter_without_siconos_is_unavailable(interpreter):
    interpreter(sys.executable)                 # this environment: numpy 2, no siconos.numerics
    status = peer.siconos_status()
    assert not status.available and "cannot import siconos.numerics" in status.reason
    assert peer.available_methods(status) == []


def test_probe_is_cached_per_interpreter_and_never_run_at_import(interpreter, tmp_path):
    marker = tmp_path / "ran"
    spy = tmp_path / "spy-python"
    spy.write_text(f"#!/bin/sh\ntouch {marker}\nexit 1\n")
    spy.chmod(spy.stat().st_mode | stat.S_IXUSR)
    environment = {**os.environ, peer.PYTHON_ENV: str(spy)}
    subprocess.run([sys.executable, "-c", "import lubcontact.solvers.siconos_peer, lubcontact.solvers"],
                   check=True, env=environment)
    assert not marker.exists()                       # importing probes nothing
    interpreter(str(spy))
    first = peer.siconos_status()
    assert marker.exists() and not first.available
    marker.unlink()
    assert peer.siconos_status() is first and not marker.exists()     # cached


def test_a_crashing_worker_is_failed_with_its_stderr(interpreter):
    interpreter(sys.executable)                 # the worker runs, then cannot import siconos
    problem = small_problem().normalized()
    out = peer.solve_with_siconos(problem, "nsgs-2d", "nsgs", tol=1e-8)
    assert out.status == FAILED and out.iterations == 0
    assert np.array_equal(out.forces, np.zeros(problem.n_rows))
    assert "status 1" in out.info["message"] and "siconos" in out.info["stderr"]


def test_a_hanging_worker_is_killed_and_failed(tmp_path):
    hang = tmp_path / "hang"
    hang.write_text("#!/bin/sh\necho stuck >&2\nexec sleep 30\n")
    hang.chmod(hang.stat().st_mode | stat.S_IXUSR)
    layout = peer.SiconosLayout.of(small_problem())
    out = peer.run_worker(layout.delassus, layout.free_velocity, layout.mu, 3, "nsgs", tol=1e-8,
                          timeout=0.5, python=str(hang))
    assert not out["ok"] and "timed out after 0.5 s" in out["message"]
    assert out["worker_wall_s"] < 10


def test_bad_input_names_the_field():
    layout = peer.SiconosLayout.of(small_problem())
    with pytest.raises(ValueError, match="tol"):
        peer.run_worker(layout.delassus, layout.free_velocity, layout.mu, 3, "nsgs", tol=0.0)
    with pytest.raises(ValueError, match="W"):
        peer.run_worker(sp.eye(5), layout.free_velocity, layout.mu, 3, "nsgs", tol=1e-8)
    with pytest.raises(ValueError, match="dim"):
        peer.run_worker(layout.delassus, layout.free_velocity, layout.mu, 4, "nsgs", tol=1e-8)
    with pytest.raises(ValueError, match="rho"):
        peer.solve_with_siconos(small_problem().normalized(), "nsgs-2d", "nsgs", tol=1e-8, rho=0.1)
    with pytest.raises(ValueError, match="criterion"):
        peer.solve_with_siconos(small_problem().normalized(), "nsgs-2d", "nsgs", tol=1e-8,
                                criterion="own")


# -- the layout sent to Siconos (no Siconos needed) ----------------------------------------------
@pytest.mark.parametrize("dim", [2, 3])
def test_layout_is_fclibs_contact_major_form_with_the_shift_removed(dim):
    problem = small_problem(dim).with_shift(np.array([0.2, 0.0]))
    layout = peer.SiconosLayout.of(problem)
    contact_major = problem.to_contact_major
    assert layout.dim == dim and layout.padded.size == 0
    assert np.allclose(layout.free_velocity, contact_major(problem.free_velocity))   # q, not q + s
    x = np.arange(problem.n_rows, dtype=float)
    assert np.allclose(layout.delassus @ contact_major(x), contact_major(problem.delassus @ x))
    assert np.array_equal(layout.to_siconos(x)[layout.rows], x)
    assert np.array_equal(layout.mu, problem.cones.mu)


def test_2d_embedded_in_3d_and_frictionless_contacts_are_padded_decoupled():
    layout = peer.SiconosLayout.of(small_problem(2), dim=3)
    assert layout.dim == 3 and list(layout.padded) == [2, 5]
    padded = layout.delassus[layout.padded]
    assert np.allclose(padded.toarray()[:, layout.padded], np.eye(2) * layout.delassus.diagonal()[0])
    assert padded.nnz == 2 and np.all(layout.free_velocity[layout.padded] == 0)
    cones = Cones(kinds=np.array([ConeKind.NONNEG, ConeKind.COULOMB], dtype=np.int8),
                  mu=np.array([0.0, 0.4]), tangential=np.array([1]), tangent_dim=2)
    frictionless = LocalProblem(delassus=sp.eye(4) * 2.0, free_velocity=[-1.0, -1.0, 0.2, 0.1],
                                cones=cones)
    layout = peer.SiconosLayout.of(frictionless)
    assert list(layout.rows) == [0, 3, 4, 5] and list(layout.padded) == [1, 2]
    assert np.array_equal(layout.mu, [0.0, 0.4])


def test_contacts_siconos_cannot_express_are_refused():
    problem = small_problem()
    cones = problem.cones
    union = Cones(kinds=np.array([ConeKind.UNION, ConeKind.COULOMB], dtype=np.int8), mu=cones.mu,
                  tangential=cones.tangential, tangent_dim=cones.tangent_dim)
    with pytest.raises(ValueError, match="cones: Siconos solves COULOMB and NONNEG contacts only, got UNION"):
        peer.SiconosLayout.of(problem.with_cones(union))
    with pytest.raises(ValueError, match="dim"):
        peer.SiconosLayout.of(problem, dim=2)


# -- with Siconos ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def registered():
    """The registered Siconos methods (skip, with the probe's reason, where Siconos is absent)."""
    peer.clear_probe_cache()
    status = peer.siconos_status()
    if not status.available:
        pytest.skip(f"Siconos peer absent (optional): {status.reason}")
    names = peer.register_siconos()
    yield names
    peer.unregister_siconos()


@pytest.fixture(scope="module")
def problems():
    return {key: read_problem(path) for key, path in FILES.items()}


@pytest.fixture(scope="module")
def references(problems):
    """lubcontact's exact Coulomb solution of each file (fixed point around apgd-jacobi)."""
    out = {}
    for key, problem in problems.items():
        result = solve_coulomb(problem, "apgd-jacobi", tol=1e-10, tol_fp=1e-9, max_iter=100000)
        assert result.status == CONVERGED
        out[key] = result
    return out


def test_every_method_of_this_build_is_registered_with_its_capabilities(registered):
    assert registered == list(NAMES)          # Debian 12's siconos 4.4 has all four
    assert peer.register_siconos() == registered             # idempotent
    assert all(peer.is_peer_method(name) for name in registered) and not peer.is_peer_method("apgd")
    for name in registered:
        info = solver_info(name)
        assert info.kind == "first-order" and info.cones == peer.SICONOS_CONES
        assert info.second_order and info.warm_start and not info.polishing and not info.step_only


@pytest.mark.parametrize("key", sorted(FILES))
@pytest.mark.parametrize("name", NAMES)
def test_each_method_solves_exact_coulomb_and_agrees_with_lubcontact(registered, problems, references,
                                                                     key, name):
    problem, reference = problems[key], references[key]
    result = solve_coulomb(problem, name, tol=1e-10, max_iter=100000)
    assert result.status == CONVERGED, result.info.get("message")
    assert result.outer_iterations == 1 and result.fixed_point_converged
    error = coulomb_error(problem, result.forces)
    assert error <= 1e-8 and scaled_coulomb_error(problem, result.forces) <= 1e-8
    assert result.info["siconos_info"] == 0 and result.info["siconos_error"] < 1e-10
    assert result.info["padding_force"] < 1e-12             # 2D in 3D: the extra direction stays 0
    assert result.info["dim"] == (2 if key == "granular-2d" and name == "siconos-nsgs" else 3)
    assert np.allclose(result.shift, coulomb_shift(problem, result.forces))
    # agreement at FCLIB-error level: the local velocities u = W r + q coincide; the forces of
    # the hyperstatic box stack are not unique (they differ by ~10%), those of the 2D flow are
    assert relative_error(result.velocities, reference.velocities) < 1e-8
    if key == "granular-2d":
        assert relative_error(result.forces, reference.forces) < 1e-8
    assert result.solve_time > 0 and result.setup_time > 0
    assert result.info["process_overhead_s"] > 0


def test_a_solve_is_deterministic_and_a_warm_start_at_the_solution_costs_at_most_one_iteration(
        registered, problems):
    problem = problems["box-stacks-3d"]
    first = solve_coulomb(problem, "siconos-nsgs", tol=1e-10)
    again = solve_coulomb(problem, "siconos-nsgs", tol=1e-10)
    assert np.array_equal(first.forces, again.forces) and first.iterations == again.iterations
    warm = solve_coulomb(problem, "siconos-prox", tol=1e-10, warm_start=first.forces)
    assert warm.status == CONVERGED and warm.iterations <= 1
    assert solve_coulomb(problem, "siconos-nsgs", tol=1e-10, warm_start=first.forces).iterations <= 1


def test_the_fixed_point_runs_a_native_coulomb_peer_once_from_any_shift(registered, problems):
    """A peer that solves exact Coulomb is not iterated on s: one solve, checked at its own
    shift s* = mu |u_T(r*)| (from s = 0 the relaxed check would have downgraded it to
    ``inaccurate``: sliding contacts leave a residual of order mu |u_T| there)."""
    problem = problems["box-stacks-3d"]
    assert solver_info("siconos-nsgs").native_coulomb
    result = solve_coulomb(problem, "siconos-nsgs", tol=1e-10, tol_fp=1e-9)
    assert result.status == CONVERGED and result.outer_iterations == 1
    assert coulomb_error(problem, result.forces) <= 1e-8
    # s* as the fixed point takes it (W r + b on the normalised problem) and as coulomb_shift
    # gives it (from the problem's own units): the same to round-off of the largest shift
    # (contacts at rest have shifts mu |u_T| of 1e-20 to 1e-14, 2.7e-4 the largest)
    expected = coulomb_shift(problem.with_shift(np.zeros(problem.n_contacts)), result.forces)
    np.testing.assert_allclose(result.shift, expected, rtol=1e-12, atol=1e-13 * np.abs(expected).max())

def test_the_fclib_criterion_resumes_siconos_until_fclibs_error_is_met(registered):
    """Siconos divides its residual by max(|q|, |r|, |u|), FCLIB by 1 + |q|: its test stops short."""
    problem = read_problem(DATA / "fclib-local" / "LMGC_100_PR_PerioBox-i00361-60-03000.hdf5")
    own = solve_coulomb(problem, "siconos-nsgs", tol=1e-10, criterion="siconos")
    assert own.status == CONVERGED and own.info["siconos_calls"] == 1
    assert own.info["siconos_error"] < 1e-10 < scaled_coulomb_error(problem, own.forces)
    fclib = solve_coulomb(problem, "siconos-nsgs", tol=1e-10)
    assert fclib.status == CONVERGED and fclib.info["siconos_calls"] == 2
    assert fclib.info["siconos_tol"] < 1e-10 and fclib.iterations > own.iterations
    assert scaled_coulomb_error(problem, fclib.forces) <= 1e-10
    assert fclib.info["fclib_error"] == pytest.approx(scaled_coulomb_error(problem, fclib.forces), rel=1e-6)


def test_siconos_nonconvergence_is_reported_not_hidden(registered, problems):
    problem = problems["box-stacks-3d"]
    capped = solve(problem, "siconos-nsgs", tol=1e-14, max_iter=3)
    assert capped.status == "max_iter" and capped.iterations == 3
    assert capped.info["siconos_info"] != 0 and "returned info=" in capped.info["message"]
    # Siconos' own DSFP step (rho = 1) does not converge on the normalised problem
    stalled = solve(problem, "siconos-desaxce-fp", tol=1e-10, max_iter=2000, rho=1.0)
    assert stalled.status == "max_iter" and stalled.info["siconos_error"] > 1e-2


def test_frictionless_contacts_are_solved_through_padded_rows(registered):
    cones = Cones(kinds=np.array([ConeKind.NONNEG, ConeKind.COULOMB], dtype=np.int8),
                  mu=np.array([0.0, 0.4]), tangential=np.array([1]), tangent_dim=2)
    problem = LocalProblem(delassus=np.eye(4) * 2.0 + 0.1, free_velocity=[-1.0, -1.0, 0.6, 0.1],
                           cones=cones)
    for name in registered:
        result = solve_coulomb(problem, name, tol=1e-12)
        assert result.status == CONVERGED, (name, result.info.get("message"))
        assert coulomb_error(problem, result.forces) <= 1e-10
