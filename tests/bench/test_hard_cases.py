"""Every registered solver on every hard case (lubcontact/bench/cases/hard.py; docs/records/hard_cases.md).

Each (case, solver) cell must be ``ok`` (converged, within tolerance of the
exact answer or the Clarabel reference, properties hold), ``flagged`` (a
non-converged status, finite forces), or ``rejected`` with a ValueError for
a problem outside the method's domain (non-convex cones for a conic solver,
3D friction for a QP solver). Known findings (a solver converged but wrong)
are listed in ``FINDINGS`` with the measured error and fail as ``xfail``
(non-strict: a fix shows up as XPASS) until their owners fix them.
"""
from __future__ import annotations

import ctypes
import time
import warnings
from functools import cache

import numpy as np
import pytest

from lubcontact import GlueyLubrication, Grains, Inelastic, Scene, Simulation, find_contacts, methods, solve
from lubcontact.bench.cases.builders import floor_scene, hexagonal_box
from lubcontact.bench.cases.hard import GAMMA_MIN, GAMMA_NEAR, GAMMA_STATES
from lubcontact.bench.hard import (
    CRASH,
    FLAGGED,
    OK,
    REJECTED,
    WRONG,
    Cell,
    case_settings,
    expected_for,
    judge,
    load_cases,
    main,
    matrix,
    run_case,
    solve_case,
)
from lubcontact.model.laws import Coulomb, GlueyCoulomb, PairState
from lubcontact.problem.metrics import scaled_velocity_error
from lubcontact.solvers import (
    CONVERGED,
    STATUSES,
    MethodOutput,
    SolverError,
    SolverWarning,
    register,
    unregister,
)

CASES = load_cases()

#: (case, solver) -> what is wrong, measured with ``lubcontact check-hard`` (tol 1e-9); empty
#: since f66f4e7 (gradient methods finished exactly on their active set) and 828a769 (polishing)
FINDINGS: dict[tuple[str, str], str] = {}


def _outside_domain(problem, method: str) -> bool:
    """Problems a method may legitimately reject with a ValueError: non-convex (UNION) cones for
    the single-solve conic and QP methods, second-order (3D) friction cones for the QP method and
    the 2D Gauss-Seidel method."""
    cones = problem.cones
    if method in ("clarabel-direct", "osqp", "scs") and not cones.is_convex:
        return True
    return method in ("osqp", "nsgs") and cones.has_friction and cones.tangent_dim > 1


@cache
def _expected(name: str, fixed_point: bool = False):
    return expected_for(CASES[name], CASES[name].problem, fixed_point)


def test_suite_size_and_descriptions():
    assert len(CASES) >= 15
    for name, case in CASES.items():
        assert case.hard and case.expected, name
        assert case.problem.n_dof > 0, name
        assert case.exact is not None or not case.reference_fails, name


@pytest.mark.parametrize("solver", methods())
@pytest.mark.parametrize("name", list(CASES))
def test_hard_case(name, solver):
    _check(CASES[name], solver, fixed_point=False)


#: frictional cases with exact answers: exact Coulomb by the fixed point on s from s = 0 must reach
#: them (``lubcontact check-hard --fixed-point`` runs every frictional case, mu_ten included)
FIXED_POINT_CASES = [n for n, c in CASES.items() if c.exact is not None and c.problem.cones.has_friction]


@pytest.mark.parametrize("solver", methods())
@pytest.mark.parametrize("name", FIXED_POINT_CASES)
def test_hard_case_fixed_point(name, solver):
    _check(CASES[name], solver, fixed_point=True)


def _check(case, solver: str, fixed_point: bool) -> None:
    """The assertions on one cell (module docstring)."""
    name = case.name
    cell = _run(case, solver, fixed_point)
    assert cell.verdict != CRASH, cell.message
    if cell.verdict == REJECTED:
        if (name, solver) in FINDINGS:
            pytest.xfail(FINDINGS[name, solver])
        assert _outside_domain(case.problem, solver), f"{solver} rejected {name}: {cell.message}"
        assert ":" in cell.message                 # the message names the offending field
        return
    assert cell.status in STATUSES
    if cell.verdict == FLAGGED:
        assert cell.status != CONVERGED
        return
    if cell.verdict == WRONG and (name, solver) in FINDINGS:
        pytest.xfail(FINDINGS[name, solver])
    assert cell.verdict == OK, (f"{solver} on {name}: converged but error {cell.error:.2e}, "
                                f"failed {cell.failed}, {cell.properties}")


def _run(case, solver: str, fixed_point: bool) -> Cell:
    """One solve judged against the cached expectation (the reference solve is cached)."""
    problem = case.problem
    start = time.perf_counter()
    try:
        result = solve_case(problem, solver, 1e-9, fixed_point=fixed_point)
    except ValueError as exc:
        return Cell(case.name, solver, REJECTED, message=str(exc))
    assert np.all(np.isfinite(result.forces)) and np.all(np.isfinite(result.velocities))
    exact = case_settings(solver, 1e-9, fixed_point=fixed_point).solves_exact_coulomb(problem)
    return judge(case, problem, _expected(case.name, exact), result,
                 time.perf_counter() - start)


@pytest.mark.parametrize("name", [n for n, c in CASES.items() if c.exact is not None])
def test_exact_answers_are_reached_by_some_solver(name):
    """The exact answers are right: the best of several independent methods reproduces each
    to 1e-8 (a wrong formula would leave every method far off)."""
    problem = CASES[name].problem
    expected = _expected(name).velocities
    candidates = [m for m in ("clarabel", "clarabel-dual", "clarabel-direct", "bb", "apgd-as")
                  if m in methods()]
    errors = {}
    for method in candidates:
        if _outside_domain(problem, method):
            continue
        result = solve(problem, method, tol=1e-10)
        if result.status == CONVERGED:
            errors[method] = scaled_velocity_error(problem, result.velocities, expected)
    assert min(errors.values()) < 1e-8, errors


@pytest.mark.parametrize("solver", methods())
def test_non_finite_warm_start_is_rejected(solver):
    problem = CASES["hex_box_jammed"].problem
    with pytest.raises(ValueError, match="warm_start"):
        solve(problem, solver, warm_start=np.full(problem.n_rows, np.nan))


@pytest.mark.parametrize("solver", methods())
@pytest.mark.parametrize("guess", [1e3, -1e12])
def test_far_warm_start_is_never_silently_wrong(solver, guess):
    """Warm starts 1e3 times too large, or hugely negative (projected away): ``ok`` or flagged."""
    case = CASES["hex_box_jammed"]
    problem = case.problem
    warm = np.full(problem.n_rows, guess) * _expected(case.name).reference.force_scale
    result = solve(problem, solver, tol=1e-9, warm_start=warm)
    cell = judge(case, problem, _expected(case.name), result, 0.0)
    assert cell.verdict in (OK, FLAGGED), (cell.error, cell.failed)


def test_gamma_within_state_tolerance_snaps_at_the_update():
    """gamma 1e-9 from 0 or from gamma_min is snapped exactly at the next update (model/laws.py)."""
    law = GlueyLubrication(GAMMA_MIN)
    sim = Simulation(_gamma_scene(), law, 0.01)
    contacts = find_contacts(sim.scene, sim.d_max)
    gamma = np.array([g for g, _ in GAMMA_STATES])
    new = law.update_gamma(contacts, gamma, np.zeros(contacts.count), 0.01, force_scale=1.0)
    assert np.all(new[np.abs(gamma) <= GAMMA_NEAR] == 0.0)
    assert np.all(new[np.abs(gamma - GAMMA_MIN) <= GAMMA_NEAR] == GAMMA_MIN)
    assert np.all((new >= GAMMA_MIN) & (new <= 0.0))


def _gamma_scene():
    count = len(GAMMA_STATES)
    positions = np.stack([2.0 * np.arange(count), np.full(count, 0.5)], axis=1)
    return floor_scene(positions, 0.5, masses=1.0, velocities=[v for _, v in GAMMA_STATES],
                       gravity=0.0)


# -- through the time stepper ----------------------------------------------------------------------
STEPPER_SOLVER = next(m for m in ("apgd-as", "apgd-jacobi", "apgd") if m in methods())


def _stepper_scene(name: str):
    """A hard scene, its law and initial gamma (or None), as the time stepper meets it."""
    if name == "hex_box_lid_friction":
        centres, width, top = hexagonal_box(6, 6)
        return floor_scene(centres, 0.5, masses=1.0, walls=(0.0, width), lid=top), Coulomb(0.3), None
    if name == "heavy_on_light_stack":
        positions = [[0.5, 0.5 + k] for k in range(6)] + [[0.5, 6.5]]
        return floor_scene(positions, 0.5, masses=[1.0] * 6 + [1e4]), Inelastic(), None
    if name == "wedge_planes":
        return _wedge_scene(), Inelastic(), None
    gamma = np.array([g for g, _ in GAMMA_STATES])
    return _gamma_scene(), GlueyCoulomb(0.5, GAMMA_MIN), gamma


@pytest.mark.parametrize("solver", [STEPPER_SOLVER, "clarabel"])
@pytest.mark.parametrize("name", ["hex_box_lid_friction", "heavy_on_light_stack", "wedge_planes",
                                  "gamma_states_gluey_coulomb"])
def test_stepper_keeps_a_finite_non_penetrating_state(name, solver):
    """Ten steps with the fast solver and the reference (fixed point on s for friction, warm
    starts by pair, gamma updates): every step converges, the state stays finite, no gap below
    -1e-6 dt V."""
    scene, law, gamma = _stepper_scene(name)
    sim = Simulation(scene, law, 0.01, solver=solver, on_failure="raise")
    if gamma is not None:
        keys = find_contacts(sim.scene, sim.d_max).keys
        sim.state.pairs = PairState.from_contacts(keys, gamma)
    penetration = 0.0
    for _ in range(10):
        report = sim.step()
        assert report.result.status == CONVERGED
        length = report.problem.normalized().scaling.length
        penetration = max(penetration, -float(report.gaps_after.min()) / length)
    assert np.all(np.isfinite(sim.scene.grains.positions))
    assert np.all(np.isfinite(sim.scene.grains.velocities))
    assert penetration <= 1e-6


# -- failure policies ---------------------------------------------------------------------------------
@pytest.fixture
def nan_method():
    """A registered method that returns NaN forces (removed afterwards)."""

    @register("test-nan")
    def _nan(problem, *, tol, warm_start=None, max_iter=1):
        return MethodOutput(np.full(problem.n_rows, np.nan), CONVERGED, 1, 0.0, 0.0)

    yield "test-nan"
    unregister("test-nan")


def test_non_finite_forces_become_zero_and_diverged(nan_method):
    problem = CASES["wedge_planes"].problem
    result = solve(problem, nan_method)
    assert result.status == "diverged"
    assert np.all(result.forces == 0.0)
    np.testing.assert_array_equal(result.velocities, problem.free_velocity)


def _wedge_simulation(solver: str, on_failure: str) -> Simulation:
    return Simulation(_wedge_scene(), Inelastic(), 0.01, solver=solver, on_failure=on_failure,
                      solver_options={"max_iter": 3} if solver == "pgd" else None)


def _wedge_scene():
    half_angle = 1e-3
    normals = [[np.cos(half_angle), np.sin(half_angle)], [-np.cos(half_angle), np.sin(half_angle)]]
    grains = Grains.create([[0.0, 1.0 / np.sin(half_angle)]], 1.0, masses=1.0)
    return Scene.create(grains, plane_points=np.zeros((2, 2)), plane_normals=normals,
                        gravity=[0.0, -1.0])


def test_raise_policy_leaves_the_state_untouched():
    sim = _wedge_simulation("pgd", "raise")
    before = sim.scene.grains.positions.copy(), sim.scene.grains.velocities.copy(), sim.scene.time
    with pytest.raises(SolverError):
        sim.step()
    np.testing.assert_array_equal(sim.scene.grains.positions, before[0])
    np.testing.assert_array_equal(sim.scene.grains.velocities, before[1])
    assert sim.scene.time == before[2] and sim.steps_done == 0


def test_warn_policy_applies_the_best_iterate_and_warns(nan_method):
    sim = _wedge_simulation(nan_method, "warn")
    with pytest.warns(SolverWarning):
        sim.step()
    assert np.all(np.isfinite(sim.scene.grains.positions))
    assert sim.trajectory.status[-1] == "diverged"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Simulation(_wedge_scene(), Inelastic(), 0.01, solver=nan_method, on_failure="ignore").step()


def test_check_hard_command_prints_the_matrix(capsys):
    code = main(["--cases", "zero_contacts,single_contact", "--solvers", "clarabel,pgd"])
    out = capsys.readouterr().out
    assert code == 0
    assert "single_contact" in out and "pgd" in out and "ok" in out
    table = matrix(run_case(CASES["wedge_planes"], ["clarabel"], 1e-9, None), markdown=True)
    assert table.splitlines()[0].startswith("| case | clarabel |")


def test_osqp_prints_nothing(capfd):
    """OSQP's C code reports polishing on standard output ("Polishing not needed ..." on
    `single_contact`); `osqp` silences it so command tables stay readable. The C library's
    buffer is flushed before reading, or buffered text would escape the capture."""
    result = solve(CASES["single_contact"].problem, "osqp", tol=1e-9)
    assert result.status == CONVERGED
    ctypes.CDLL(None).fflush(None)
    assert "Polishing" not in capfd.readouterr().out
