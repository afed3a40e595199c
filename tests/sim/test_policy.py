"""Non-convergence policies of the time stepper: raise (state untouched), warn, fallback."""
from dataclasses import replace

import numpy as np
import pytest

from lubcontact import GlueyLubrication, Simulation, SolverError, scenes
from lubcontact.solvers import SolverWarning, SolveSettings


def starved(on_failure, **kwargs):
    """A settling pile whose fast solver gets a single iteration: it cannot converge."""
    sim = Simulation(scenes.settling_pile(60, seed=2), GlueyLubrication(), dt=0.05, solver="apgd",
                     tol=1e-9, solver_options={"max_iter": 1}, on_failure=on_failure, **kwargs)
    return sim


def run_until(sim, condition, steps=60):
    for _ in range(steps):
        report = sim.step()
        if condition(report):
            return report
    raise AssertionError("condition never met")


def test_raise_stops_before_the_state_changes():
    sim = starved("raise")
    with pytest.raises(SolverError, match="max_iter"):
        for _ in range(60):
            before = (sim.scene.grains.positions.copy(), sim.scene.time, sim.steps_done)
            sim.step()
    np.testing.assert_array_equal(sim.scene.grains.positions, before[0])
    assert (sim.scene.time, sim.steps_done) == before[1:]


def test_warn_applies_the_best_iterate_and_warns():
    sim = starved("warn")
    with pytest.warns(SolverWarning, match="max_iter"):
        report = run_until(sim, lambda r: r.result.status != "converged")
    assert report.result.status == "max_iter"
    assert np.all(np.isfinite(sim.scene.grains.positions))


def test_fallback_resolves_the_step_with_the_reference():
    sim = starved("fallback")
    report = run_until(sim, lambda r: "fallback_from" in r.result.info)
    assert report.result.status == "converged" and report.result.method == "clarabel"
    assert report.result.info["fallback_from"][:2] == ("apgd", "max_iter")
    assert report.gaps_after.min() >= -1e-9


def test_a_step_beyond_max_residual_is_solved_again_before_it_fails():
    """With ``ignore`` (the flow runner's policy) a solve above ``max_residual`` is re-solved
    once by the reference before the step fails (a gluey 2000-grain descent stopped on such a
    step, newton-ac's residual 1.2e-2, that Clarabel's fixed point solves to 4.4e-4); a solve
    between the tolerance and ``max_residual`` is applied as it is."""
    sim = starved("ignore", max_residual=1e-12)
    report = run_until(sim, lambda r: "fallback_from" in r.result.info)
    assert report.result.status == "converged" and report.result.method == "clarabel"
    method, status, residual = report.result.info["fallback_from"]
    assert (method, status) == ("apgd", "max_iter") and residual > 1e-12
    loose = starved("ignore", max_residual=1e3)
    report = run_until(loose, lambda r: r.result.status != "converged")
    assert report.result.method == "apgd" and "fallback_from" not in report.result.info


def test_the_max_residual_re_solve_keeps_raise_and_warn_and_names_both_solves(monkeypatch):
    """``raise`` still raises at the first unconverged step; ``warn`` warns about the re-solve;
    a re-solve that fails too raises naming the step's solver and the fallback's."""
    with pytest.raises(SolverError, match="apgd: status max_iter"):
        run_until(starved("raise", max_residual=1e-12), lambda r: False)
    with pytest.warns(SolverWarning, match="solved again by clarabel"):
        report = run_until(starved("warn", max_residual=1e-12),
                           lambda r: "fallback_from" in r.result.info)
    assert report.result.method == "clarabel"
    solve = SolveSettings.solve

    def fallback_fails(self, *args, **kwargs):         # the re-solve ends far off too
        result = solve(self, *args, **kwargs)
        return replace(result, status="inaccurate", residual=0.5) \
            if self.method == "apgd-jacobi" else result
    monkeypatch.setattr(SolveSettings, "solve", fallback_fails)
    both = starved("ignore", max_residual=1e-2, fallback_solver="apgd-jacobi")
    with pytest.raises(SolverError, match=r"^apgd: status max_iter, residual .*; solved again "
                                          r"by apgd-jacobi: status inaccurate"):
        run_until(both, lambda r: False)


def test_the_step_re_solves_by_the_residual_per_row_not_the_2_norm():
    """The stepper's re-solve rule reads the residual per row: a bound between a step's
    residual per row and its 2-norm applies the step as it is (the 2-norm would re-solve it)."""
    first = run_until(starved("ignore"), lambda r: r.result.status != "converged")
    per_row, norm = first.result.residual_per_row, first.result.residual
    assert norm > 2 * per_row
    bounded = starved("ignore", max_residual=np.sqrt(per_row * norm))
    report = run_until(bounded, lambda r: r.result.status != "converged")
    assert "fallback_from" not in report.result.info and report.result.method == "apgd"
    assert report.result.residual == norm


def test_fixed_point_options_reach_only_frictional_steps():
    """``joint`` is an option of the fixed point on s: frictionless steps must not receive it,
    and frictionless and frictional runs with it match the runs without it."""
    from lubcontact.model.laws import Coulomb, Inelastic

    for law in (Inelastic(), Coulomb(0.3)):
        runs = []
        for options in ({}, {"joint": 5}):
            sim = Simulation(scenes.settling_pile(30, seed=2), law, 0.05, solver="apgd-jacobi",
                             tol=1e-9, solver_options=options)
            sim.run(20)
            runs.append(sim.scene.grains.velocities.copy())
        speed = np.abs(runs[0]).max()
        np.testing.assert_allclose(runs[1], runs[0], rtol=0, atol=1e-6 * speed)


def test_max_residual_bounds_the_residual_per_row_whatever_the_size():
    """The bound was on the residual's 2-norm, which grows as sqrt(rows) for the same per-row
    accuracy: it stopped 2000-grain beds at rest (9 000 rows) on steps at 1.2e-4 per row that a
    100-grain run would apply. The same per-row figure is now judged alike at both sizes."""
    from lubcontact.solvers.result import SolveResult, check_status

    def unconverged(n_rows, per_row):
        return SolveResult(x=np.zeros(n_rows), velocities=np.zeros(3), status="max_iter",
                           iterations=10, residual=per_row * np.sqrt(n_rows), method="newton-ac")

    for n_rows in (400, 9000):
        check_status(unconverged(n_rows, 1.2e-4), "ignore", max_residual=1e-3)      # applied
        with pytest.raises(SolverError, match="per row"):
            check_status(unconverged(n_rows, 2e-3), "ignore", max_residual=1e-3)
    assert unconverged(9000, 1.2e-4).residual_per_row == pytest.approx(1.2e-4)
