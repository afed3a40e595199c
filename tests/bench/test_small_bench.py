"""``lubcontact bench small`` and the state each timed method starts from."""
import numpy as np
import pytest

from lubcontact.bench import flow_steps, small_steps
from lubcontact.model.laws import Coulomb
from lubcontact.scenes.small import settling_pile
from lubcontact.sim.simulation import Simulation
from lubcontact.solvers import siconos_peer


@pytest.fixture(autouse=True)
def _no_peer_left_registered():
    """bench small registers the Siconos peer when installed: unregister it after each test."""
    yield
    siconos_peer.unregister_siconos()


def _positions(sim: Simulation) -> np.ndarray:
    return sim.scene.grains.positions.copy()


@pytest.mark.parametrize("timed", [
    lambda sim: small_steps.time_steps(sim, "apgd-jacobi", 3, 1e-8, exact=False),
    lambda sim: flow_steps.time_method(sim, "apgd-jacobi", 3, 1e-8, friction="relaxation"),
])
def test_a_timed_method_leaves_the_simulation_where_it_was(timed):
    """Each method of a benchmark is timed from the same state: before the fix the restored
    state was the stepped object itself, so the next method started 4 steps later."""
    sim = Simulation(settling_pile(6, seed=1), Coulomb(0.3), 0.02, solver="apgd-jacobi",
                     tol=1e-8, fixed_point=False, keep_trajectory=False)
    sim.run(20)
    before, steps, time = _positions(sim), sim.steps_done, sim.scene.time
    timed(sim)
    assert sim.steps_done == steps and sim.scene.time == time
    assert np.array_equal(_positions(sim), before)


def test_bench_small_prints_a_row_per_size_law_and_method(capsys, tmp_path):
    out = tmp_path / "rows.json"
    assert small_steps.main(["--sizes", "4", "--laws", "frictionless,exact", "--methods",
                             "apgd-as,nsgs", "--steps", "4", "--settle", "40",
                             "--json", str(out)]) == 0
    text = capsys.readouterr().out
    rows = [line.split() for line in text.splitlines()[-4:]]
    assert [(row[1], row[2]) for row in rows] == [("frictionless", "apgd-as"),
                                                  ("frictionless", "nsgs"),
                                                  ("exact", "apgd-as"), ("exact", "nsgs")]
    # steps with contacts, solved: iterations, and the method's own solve a part of the whole
    assert all(row[-1] == "converged" and float(row[3]) > 0 and float(row[-2]) > 0 for row in rows)
    assert all(0 < float(row[5]) < float(row[4]) for row in rows)
    assert out.exists()


def test_bench_small_times_siconos_own_solve_beside_the_worker_process(capsys):
    """With Siconos installed, its 2D Gauss-Seidel is a method of bench small: converged, and its
    ``method_us`` (Siconos' own solve, timed in its worker) a small part of ``solve_us``, which
    holds the worker's process; skipped where the peer is absent (CI)."""
    status = siconos_peer.siconos_status()
    if not status.available:
        pytest.skip(f"Siconos absent: {status.reason}")
    assert small_steps.main(["--sizes", "4", "--laws", "frictionless,exact", "--methods",
                             "siconos-nsgs", "--steps", "3", "--settle", "40"]) == 0
    captured = capsys.readouterr()
    row = captured.out.splitlines()[-1].split()
    assert row[:3] == ["4", "exact", "siconos-nsgs"] and row[-1] == "converged"
    assert float(row[3]) > 0 and float(row[-2]) > 0          # contacts, Siconos' sweeps
    assert 0 < 10 * float(row[5]) < float(row[4])
    # Siconos takes no gluey (FREE) contacts: that law is skipped, saying so in one line
    assert ("lubcontact bench small: siconos-nsgs skipped on the frictionless law: FREE contacts "
            "are not supported") in captured.err.splitlines()


def test_a_native_coulomb_method_is_skipped_on_the_relaxation_saying_why(capsys):
    """``newton-ac`` solves exact Coulomb itself: its relaxation row would repeat the exact one,
    so bench small skips it with one line on standard error (as bench flow does)."""
    assert small_steps.main(["--sizes", "4", "--laws", "relaxation,exact", "--methods",
                             "newton-ac,apgd-jacobi", "--steps", "2", "--settle", "40"]) == 0
    captured = capsys.readouterr()
    rows = [line.split()[1:3] for line in captured.out.splitlines()[-3:]]
    assert rows == [["relaxation", "apgd-jacobi"], ["exact", "newton-ac"], ["exact", "apgd-jacobi"]]
    assert ("lubcontact bench small: newton-ac skipped on the relaxation law: it solves exact "
            "Coulomb itself, it has no relaxation") in captured.err.splitlines()


def test_a_peer_method_without_siconos_is_a_one_line_error(monkeypatch, capsys, tmp_path):
    """``--methods siconos-nsgs`` where Siconos is absent: one line naming the flag and why."""
    siconos_peer.unregister_siconos()
    monkeypatch.setenv(siconos_peer.PYTHON_ENV, str(tmp_path / "no-such-python"))
    siconos_peer.clear_probe_cache()
    try:
        with pytest.raises(SystemExit):
            small_steps.main(["--methods", "siconos-nsgs", "--sizes", "3"])
    finally:
        siconos_peer.clear_probe_cache()
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert "--methods" in last and "'siconos-nsgs' need Siconos" in last


@pytest.mark.parametrize("flag, value", [("--laws", "sticky"), ("--methods", "newton"),
                                         ("--sizes", "0")])
def test_bad_flags_are_one_line_errors(flag, value, capsys):
    with pytest.raises(SystemExit):
        small_steps.main([flag, value])
    assert flag in capsys.readouterr().err.strip().splitlines()[-1]
