"""newton-ac, the semismooth Newton method on the Alart-Curnier function, against exact answers,
the Clarabel reference and Siconos' test problems."""
import inspect
import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from lubcontact.bench.cases.reference import CASES as REFERENCE_CASES
from lubcontact.bench.cases.reference import load as load_reference
from lubcontact.bench.hard import expected_for, load_cases
from lubcontact.bench.problem_sets import benchmark_file
from lubcontact.io.readers import read_problem
from lubcontact.problem.cones import ConeKind
from lubcontact.problem.metrics import (
    coulomb_error,
    coulomb_shift,
    scaled_coulomb_error,
    scaled_velocity_error,
    velocity_error,
)
from lubcontact.problem.step import StepProblem
from lubcontact.solvers import (
    CONVERGED,
    DIVERGED,
    FIRST_ORDER,
    INACCURATE,
    MAX_ITER,
    SolveSettings,
    factorisations,
    newton,
    solve,
    solve_coulomb,
    solver_info,
)
from lubcontact.solvers.coulomb import has_joint_phase
from lubcontact.solvers.gauss_seidel import nonsmooth_gauss_seidel
from lubcontact.solvers.newton import (
    FALLBACK_GAP,
    SIGMA_MAX,
    STALL_FACTOR,
    STALL_HORIZON,
    STALL_WINDOW,
    STRATEGY_GAP,
    AlartCurnier,
    _line_search,
    _proximal_newton,
    _StallRule,
    fallback_chain,
    newton_alart_curnier,
)
from lubcontact.solvers.registry import ALL_CONES, register, unregister
from lubcontact.solvers.result import MethodOutput


def siconos_test_problem(name):
    problem = read_problem(benchmark_file("siconos-testdata", name))
    return problem.local() if hasattr(problem, "local") else problem


@pytest.mark.parametrize("name", sorted(REFERENCE_CASES))
def test_agrees_with_the_stored_reference_on_every_reference_case(name):
    problem, solution = load_reference(name)
    result = solve_coulomb(problem, "newton-ac", tol=1e-12)
    assert result.status == CONVERGED
    assert velocity_error(problem, result.velocities, solution["velocities"]) <= 1e-8


FRICTIONAL_HARD = ["radius_ratio_100_friction", "mu_zero_friction", "hex_box_lid_friction",
                   "wedge_planes_friction", "cone_apex_2d", "cone_apex_3d", "dt_large_friction",
                   "tetrahedron_3d_friction"]


@pytest.mark.parametrize("name", FRICTIONAL_HARD)
def test_exact_coulomb_on_the_frictional_hard_cases(name):
    """Exact answers where the case has one, else Clarabel's fixed point on s (unique there)."""
    case = load_cases()[name]
    expected = expected_for(case, case.problem, fixed_point=True)
    result = solve_coulomb(case.problem, "newton-ac", tol=1e-10)
    assert result.status == CONVERGED
    assert scaled_velocity_error(case.problem, result.velocities, expected.velocities) <= 1e-8


def test_mu_ten_converges_where_the_fixed_point_on_s_does_not():
    """mu = 10: the fixed point on s hits its cap with apgd-jacobi and Clarabel (check-hard
    --fixed-point); Newton converges in 8 iterations to a Coulomb error of round-off."""
    case = load_cases()["mu_ten"]
    result = solve_coulomb(case.problem, "newton-ac", tol=1e-10)
    assert result.status == CONVERGED and result.iterations <= 20
    assert scaled_coulomb_error(case.problem, result.forces) <= 1e-10
    assert "fallback_iterations" not in result.info


@pytest.mark.parametrize("name, cap", [
    ("FrictionContactProblem00237.dat", 100),   # 2D, 376 contacts: the file apgd-jacobi misses
    ("Capsules-i122-1617.dat", 100),            # 3D, non-symmetric and rank-deficient W
    ("spheres-in-a-box-98-i10000-256-10.hdf5", 250),  # plain Newton after the proximal loop stalls
])
def test_siconos_problems_reach_1e_8_by_newton_alone(name, cap):
    problem = siconos_test_problem(name)
    result = solve_coulomb(problem, "newton-ac", tol=1e-8)
    assert result.status == CONVERGED
    assert scaled_coulomb_error(problem, result.forces) <= 1e-8
    assert result.info["newton_status"] == CONVERGED and result.iterations <= cap


def test_newton_that_runs_out_hands_over_to_the_fallback_and_says_so():
    """Two Newton iterations cannot solve Capsules-i122-1617; apgd-jacobi's fixed point takes over
    from the best iterate and reaches the tolerance."""
    problem = siconos_test_problem("Capsules-i122-1617.dat")
    alone = solve_coulomb(problem, "newton-ac", tol=1e-6, max_iter=2, fallback=None)
    assert alone.status == MAX_ITER and scaled_coulomb_error(problem, alone.forces) > 1e-6
    rescued = solve_coulomb(problem, "newton-ac", tol=1e-6, max_iter=2)
    assert rescued.info["newton_status"] == MAX_ITER and rescued.info["fallback_iterations"] > 0
    assert rescued.status == CONVERGED and scaled_coulomb_error(problem, rescued.forces) <= 1e-6


def test_the_strategies_stall_by_their_own_rule_on_a_frictional_pile_at_rest_before_the_cap():
    """The 800-grain frictional pile at rest of ``lubcontact compare`` (3 296 rows, from zero
    forces, tol 1e-8; singular W): every Newton strategy stalls by its own rule within the
    default cap (774 iterations), and the solve reaches tol (today through Gauss-Seidel's rounds
    and their polishes).
    At a cap of 500 the last strategy was cut at its 351st iteration while still progressing
    (1.2e-5), and the run ended max_iter at 9.4e-7 with this package's elimination order."""
    from lubcontact.bench.problem_sets import build_frictional_piles

    pile, = [case for case in build_frictional_piles() if case.name == "rest800-coulomb"]
    result = SolveSettings(method="newton-ac", tol=1e-8, exact_coulomb=True).solve(pile.problem)
    assert result.status == CONVERGED
    assert scaled_coulomb_error(pile.problem, result.forces) <= 1e-8
    assert result.info["newton_status"] != MAX_ITER          # stalled by its rule, not capped


def test_a_gluey_problem_falls_back_on_gauss_seidel_alone():
    """The fixed point on s flips union contacts by its branch rule; on a gluey bed coming to rest
    it flipped some at every outer iteration for 50 of them (three quarters of the step, an answer
    9-37 times worse than Gauss-Seidel's): 2D problems with UNION contacts fall back on nsgs
    alone, convex 2D ones on nsgs then apgd-jacobi's fixed point (Siconos' 2020-contact file
    needs it), 3D ones on apgd-jacobi."""
    with np.load(Path(__file__).parents[1] / "flow" / "data" / "gluey-flow-step.npz") as data:
        gluey = StepProblem.from_arrays(data)
        guess, shift = data["warm_start"], data["warm_shift"]
    assert np.any(gluey.cones.kinds == ConeKind.UNION)
    assert fallback_chain(gluey.cones, "auto") == ("nsgs",)
    dry = siconos_test_problem("FrictionContactProblem00237.dat")
    assert dry.cones.tangent_dim == 1 and fallback_chain(dry.cones, "auto") == ("nsgs", "apgd-jacobi")
    spatial = siconos_test_problem("Capsules-i122-1617.dat")
    assert fallback_chain(spatial.cones, "auto") == ("apgd-jacobi",)
    assert fallback_chain(gluey.cones, "apgd-jacobi") == ("apgd-jacobi",)
    assert fallback_chain(gluey.cones, None) == ()
    rescued = solve_coulomb(gluey, "newton-ac", tol=1e-6, max_iter=2, warm_start=guess, shift=shift)
    assert rescued.info["newton_status"] == MAX_ITER and rescued.info["fallbacks"] == ["nsgs"]
    assert rescued.status == CONVERGED and scaled_coulomb_error(gluey, rescued.forces) <= 1e-6


def test_the_proximal_loop_solves_the_rank_deficient_problems_plain_newton_does_not():
    """FCLIB's LMGC_100_PR_PerioBox: plain Newton (sigma = 0) stalls at 7.6e-2; the proximal loop
    converges in a dozen Newton iterations."""
    problem = read_problem(benchmark_file("fclib-local", "LMGC_100_PR_PerioBox-i00361-60-03000.hdf5"))
    scaled = problem.normalized()
    function = AlartCurnier(scaled)
    unshifted = scaled.with_shift(np.zeros(scaled.n_contacts))
    start = np.zeros(scaled.n_rows)
    plain = _proximal_newton(function, unshifted, start, 1e-8, 200, sigma=0.0)
    assert plain.status != CONVERGED and plain.error > 1e-3
    proximal = _proximal_newton(function, unshifted, start, 1e-8, 200, sigma=1e-3)
    assert proximal.status == CONVERGED and proximal.iterations <= 30 and proximal.proximal_steps >= 2


def test_a_creeping_bed_converges_by_the_proximal_loop_without_fallback():
    """A creeping 300-grain bed (tests/solvers/data/README.md): the proximal loop centres each
    subproblem at the last one's solution; centred at the best iterate it posed the same
    subproblem again and every strategy stalled at an FCLIB error of 2.3e-5."""
    with np.load(Path(__file__).parent / "data" / "creeping-bed-step.npz") as data:
        problem = StepProblem.from_arrays(data)
        warm_start, warm_shift = data["warm_start"], data["warm_shift"]
    settings = SolveSettings(method="newton-ac", tol=1e-6, exact_coulomb=True,
                             options={"fallback": None})
    result = settings.solve(problem, warm_start, warm_shift)
    assert result.status == CONVERGED and result.info["strategies"] == [(newton.WARM_FLOW_WEIGHT, "warm")]
    assert scaled_coulomb_error(problem, result.forces) <= 1e-6


def test_a_creeping_bed_from_a_capped_joint_phase_converges_in_fewer_newton_iterations():
    """The joint phase ends at its iteration cap on the creeping bed's step, nearer Coulomb's law
    than the warm start: Newton starts from it (75 iterations against 188 from the warm start;
    70 against 221 where each subproblem is solved, RECENTRE_WINDOW 0) and converges to tol
    without fallback."""
    with np.load(Path(__file__).parent / "data" / "creeping-bed-step.npz") as data:
        problem = StepProblem.from_arrays(data)
        warm_start, warm_shift = data["warm_start"], data["warm_shift"]
    results = {joint: SolveSettings(method="newton-ac", tol=1e-6, exact_coulomb=True,
                                    options={"fallback": None, "joint": joint}
                                    ).solve(problem, warm_start, warm_shift) for joint in (0, 5)}
    joined = results[5]
    assert joined.status == CONVERGED and scaled_coulomb_error(problem, joined.forces) <= 1e-6
    assert joined.joint_iterations == newton.JOINT_START_ITERATIONS
    assert joined.info["newton_iterations"] < results[0].info["newton_iterations"] / 2


@pytest.mark.parametrize("path", [Path(__file__).parents[1] / "flow" / "data" / "gluey-flow-step.npz",
                                  Path(__file__).parent / "data" / "creeping-bed-step.npz"])
def test_a_flow_step_takes_fewer_newton_iterations_re_centred_after_each(path, monkeypatch):
    """On a flow's step (the sparse lane, 2D) the proximal loop first re-centres after every
    Newton iteration at the same weight: the gluey flow's step converges in 10 Newton iterations
    against 14 with each subproblem solved (RECENTRE_WINDOW 0), the creeping bed's in 188 against
    221, to the same tol without fallback."""
    with np.load(path) as data:
        problem = StepProblem.from_arrays(data)
        warm_start, warm_shift = data["warm_start"], data["warm_shift"]
    settings = SolveSettings(method="newton-ac", tol=1e-6, exact_coulomb=True,
                             options={"fallback": None})
    iterations = []
    for window in (newton.RECENTRE_WINDOW, 0):
        monkeypatch.setattr(newton, "RECENTRE_WINDOW", window)
        result = settings.solve(problem, warm_start, warm_shift)
        assert result.status == CONVERGED and scaled_coulomb_error(problem, result.forces) <= 1e-6
        iterations.append(result.info["newton_iterations"])
    re_centred, solved = iterations
    assert re_centred < 0.9 * solved


def test_on_a_gluey_flow_step_the_re_centred_weight_follows_the_error(monkeypatch):
    """A 2 000-grain gluey flow's step (8 279 rows): each re-centred Newton iteration's weight is
    at most its centre's FCLIB error (in units of the median diagonal of ``W``), so it falls with
    the error from the first weight on, and the step reaches tol in 10 Newton iterations against
    14 at the first weight throughout (``UNION_RECENTRE_FOLLOWS`` off), to the same tol; without
    the line search's corrected full steps (``CORRECTED_SWEEPS`` 0), which take fewer
    iterations still (the test of corrected full steps below)."""
    problem, warm_start, warm_shift = _stored_step("gluey-2000-recentred-step.npz")
    assert not problem.cones.is_convex
    settings = SolveSettings(method="newton-ac", tol=1e-6, exact_coulomb=True,
                             options={"fallback": None})
    monkeypatch.setattr(newton, "CORRECTED_SWEEPS", 0)
    phase, re_centred = newton._newton_phase, []

    def spied(function, unshifted, forces, tol, max_iter, inner_tol=0.0, **known):
        if max_iter == 1 and known.get("error") is not None:        # a re-centred iteration
            re_centred.append((function.sigma / function.typical, known["error"]))
        return phase(function, unshifted, forces, tol, max_iter, inner_tol, **known)

    monkeypatch.setattr(newton, "_newton_phase", spied)
    outcomes = {}
    for follows in (True, False):
        monkeypatch.setattr(newton, "UNION_RECENTRE_FOLLOWS", follows)
        result = settings.solve(problem, warm_start, warm_shift)
        assert result.status == CONVERGED and scaled_coulomb_error(problem, result.forces) <= 1e-6
        outcomes[follows] = result.info["newton_iterations"], list(re_centred)
        re_centred.clear()
    (following, weights), (fixed, fixed_weights) = outcomes[True], outcomes[False]
    assert len(weights) >= 3 and len(fixed_weights) >= 3
    assert all(weight == pytest.approx(newton.WARM_FLOW_WEIGHT, rel=1e-12) for weight, _ in fixed_weights)
    assert all(weight == pytest.approx(min(newton.WARM_FLOW_WEIGHT, error), rel=1e-12)
               for weight, error in weights)
    assert weights[-1][0] < newton.WARM_FLOW_WEIGHT / 3          # it fell with the error
    assert following == 10 and fixed == 14


def test_local_sweeps_take_a_flow_step_to_tol_in_fewer_newton_iterations(monkeypatch):
    """A 2 000-grain gluey flow's step (8 337 rows): where the FCLIB error's residual concentrates
    on a few rows, Gauss-Seidel sweeps over them start the next proximal subproblem, and the step
    reaches tol in 6 Newton iterations against 13 without them (``LOCAL_SWEEPS`` 0), or on a
    problem under ``LOCAL_MIN_ROWS`` rows (none are swept there). The line search's corrected
    full steps (``CORRECTED_SWEEPS``, which sweep too) are left out here: the next tests."""
    with np.load(Path(__file__).parent / "data" / "gluey-2000-step.npz") as data:
        problem = StepProblem.from_arrays(data)
        warm_start, warm_shift = data["warm_start"], data["warm_shift"]
    settings = SolveSettings(method="newton-ac", tol=1e-6, exact_coulomb=True,
                             options={"fallback": None})
    monkeypatch.setattr(newton, "CORRECTED_SWEEPS", 0)
    outcomes = []
    for sweeps, least in ((newton.LOCAL_SWEEPS, newton.LOCAL_MIN_ROWS), (0, newton.LOCAL_MIN_ROWS),
                          (newton.LOCAL_SWEEPS, problem.n_rows)):
        monkeypatch.setattr(newton, "LOCAL_SWEEPS", sweeps)
        monkeypatch.setattr(newton, "LOCAL_MIN_ROWS", least)
        result = settings.solve(problem, warm_start, warm_shift)
        assert result.status == CONVERGED and scaled_coulomb_error(problem, result.forces) <= 1e-6
        outcomes.append((result.info["newton_iterations"], result.info["local_sweeps"]))
    swept, plain, small = outcomes
    assert swept[0] <= 7 and swept[1] >= 3
    assert plain == small and plain[0] >= 2 * swept[0] and plain[1] == 0


def _stored_step(name: str) -> tuple[StepProblem, np.ndarray, np.ndarray]:
    """The step problem stored in ``data/<name>`` and its warm start and shift (the README there
    says what each step is)."""
    with np.load(Path(__file__).parent / "data" / name) as data:
        return StepProblem.from_arrays(data), data["warm_start"], data["warm_shift"]


def test_a_full_step_corrected_on_the_rows_where_it_fails_is_taken(monkeypatch):
    """Where a full Newton step of a flow's step fails the line search's bound on a few rows, the
    line search sweeps them (``AlartCurnier.corrected``) and takes the corrected point: its merit
    is below the full step's bound, it is the full step but on the swept rows (and their
    contacts' other rows), whose residual held at least ``CORRECTED_SHARE`` of the full step's;
    without the correction the same search cuts the step."""
    from lubcontact.solvers import kernels

    problem, warm_start, warm_shift = _stored_step("gluey-2000-recentred-step.npz")
    calls = []
    search = newton._line_search

    def spied(function, forces, velocity, direction, slope, reference, merit=None):
        kept = function.corrections_kept
        accepted = search(function, forces, velocity, direction, slope, reference, merit)
        phi_full = function.residual(forces + direction)[0]
        failed = 0.5 * phi_full @ phi_full > reference - newton.ARMIJO * slope
        if function.corrections_kept > kept and failed and not calls:
            calls.append((function, forces.copy(), velocity.copy(), direction.copy(), slope,
                          reference, accepted, function.sigma, function.center.copy()))
        return accepted

    monkeypatch.setattr(newton, "_line_search", spied)
    SolveSettings(method="newton-ac", tol=1e-6, exact_coulomb=True).solve(problem, warm_start,
                                                                          warm_shift)
    assert calls, "no full step was corrected"
    function, forces, velocity, direction, slope, reference, accepted, sigma, center = calls[0]
    function.set_proximal(sigma, center)
    bound = reference - newton.ARMIJO * slope
    full = forces + direction
    phi_full = function.residual(full)[0]
    assert 0.5 * phi_full @ phi_full > bound                        # the full step fails
    corrected, phi = accepted[0], accepted[1]
    assert 0.5 * phi @ phi <= bound
    # its velocity carried through the swept rows (moved_velocity): the residual afresh to rounding
    np.testing.assert_allclose(function.residual(corrected)[0], phi, rtol=0,
                               atol=1e-13 * np.abs(phi).max())
    moved = np.flatnonzero(corrected != full)
    worst = np.argsort(phi_full ** 2)[::-1][:newton.CORRECTED_ROWS]
    near = kernels.neighbourhood(*function.w_arrays[:2], worst, newton.LOCAL_HOPS)
    touched = np.isin(function.cone_n, near) | np.isin(function.tangent_rows, near)
    swept = np.concatenate([near, function.cone_n[touched], function.tangent_rows[touched]])
    assert moved.size > 0 and np.isin(moved, swept).all()       # a contact swept whole
    assert (phi_full[worst] ** 2).sum() >= newton.CORRECTED_SHARE * (phi_full ** 2).sum()
    monkeypatch.setattr(newton, "CORRECTED_SWEEPS", 0)
    cut = search(function, forces, velocity, direction, slope, reference)[0]
    step = np.abs(cut - forces).max() / np.abs(direction).max()
    assert step <= 0.5


def test_a_full_step_that_passes_the_bound_without_lowering_the_merit_is_corrected(monkeypatch):
    """Where the non-monotone line search accepts a full Newton step whose merit is above
    ``CYCLING_MERIT`` times the current one (the 10 000-grain gluey step whose sliding contacts'
    friction jumps from one side of their cone to the other at every full step), the search
    sweeps the rows where the step's ``phi`` is largest (``AlartCurnier.corrected``) and takes the
    corrected point where its merit is below the full step's; an accepted full step below that
    fraction, and any full step of a search given no current merit (steepest descent), is taken
    as it is."""
    problem, warm_start, warm_shift = _stored_step("gluey-10000-cycling-step.npz")
    cycling, lower, without_merit = [], [], []
    search = newton._line_search

    def spied(function, forces, velocity, direction, slope, reference, merit=None):
        kept = function.corrections_kept
        accepted = search(function, forces, velocity, direction, slope, reference, merit)
        phi_full = function.residual(forces + direction)[0]
        psi_full = 0.5 * phi_full @ phi_full
        if merit is not None and psi_full <= reference - newton.ARMIJO * slope:   # passed
            record = (function.corrections_kept > kept, accepted, forces + direction, psi_full)
            if psi_full <= newton.CYCLING_MERIT * merit:
                lower.append(record)
            else:
                if not cycling:           # the same search, given no current merit
                    without_merit.append(search(function, forces, velocity, direction, slope,
                                                reference)[0])
                cycling.append(record)
        return accepted

    monkeypatch.setattr(newton, "_line_search", spied)
    SolveSettings(method="newton-ac", tol=1e-6, exact_coulomb=True).solve(problem, warm_start,
                                                                          warm_shift)
    assert cycling and lower
    assert any(corrected for corrected, *_ in cycling)
    for corrected, accepted, full, psi_full in cycling:
        if corrected:
            assert 0.5 * accepted[1] @ accepted[1] < psi_full
        else:
            np.testing.assert_array_equal(accepted[0], full)
    for corrected, accepted, full, _ in lower:
        assert not corrected
        np.testing.assert_array_equal(accepted[0], full)
    np.testing.assert_array_equal(without_merit[0], cycling[0][2])


def test_corrected_cycling_steps_take_a_flow_step_to_tol_in_under_a_quarter_of_the_iterations(
        monkeypatch):
    """On the 10 000-grain gluey step whose full steps cycle (``gluey-10000-cycling-step.npz``)
    the first strategy converges in 31 Newton iterations with the cycling full steps corrected,
    against 150 and three strategies without (``CYCLING_MERIT`` infinite: the first stalls at
    1.5e-4, its weight raised to 2e9 with the merit unchanged), to the same tol."""
    problem, warm_start, warm_shift = _stored_step("gluey-10000-cycling-step.npz")
    settings = SolveSettings(method="newton-ac", tol=1e-6, exact_coulomb=True,
                             options={"fallback": None})
    outcomes = []
    for cycling in (newton.CYCLING_MERIT, np.inf):
        monkeypatch.setattr(newton, "CYCLING_MERIT", cycling)
        result = settings.solve(problem, warm_start, warm_shift)
        assert result.status == CONVERGED and scaled_coulomb_error(problem, result.forces) <= 1e-6
        outcomes.append((result.info["newton_iterations"], len(result.info["strategies"])))
    (corrected, strategies), (plain, plain_strategies) = outcomes
    assert strategies == 1 and plain_strategies == 3
    assert corrected <= 40 and 4 * corrected <= plain


@pytest.mark.parametrize("tol", [1e-6, 1e-7])
def test_corrected_full_steps_take_a_flow_step_to_tol_in_fewer_newton_iterations(monkeypatch, tol):
    """On the 2 000-grain gluey step the corrected full steps take 8 Newton iterations to tol,
    against 10 (tol 1e-6) and 11 (1e-7) without them (``CORRECTED_SWEEPS`` 0), to an FCLIB
    error below tol either way."""
    problem, warm_start, warm_shift = _stored_step("gluey-2000-recentred-step.npz")
    settings = SolveSettings(method="newton-ac", tol=tol, exact_coulomb=True,
                             options={"fallback": None})
    outcomes = []
    for sweeps in (newton.CORRECTED_SWEEPS, 0):
        monkeypatch.setattr(newton, "CORRECTED_SWEEPS", sweeps)
        result = settings.solve(problem, warm_start, warm_shift)
        assert result.status == CONVERGED and scaled_coulomb_error(problem, result.forces) <= tol
        outcomes.append((result.info["newton_iterations"], result.info["corrected_steps"]))
    (corrected, taken), (plain, none) = outcomes
    assert taken >= 1 and none == 0
    assert corrected <= plain - 2


def test_the_products_go_through_the_factor_where_it_has_under_half_the_entries_of_w(monkeypatch):
    """On the sparse lane the products ``W x`` go through ``W = L^T L``'s factor where ``L`` and
    ``L^T`` together hold at most FACTOR_PRODUCT_SHARE of ``W``'s entries (a dense dry flow's
    step: 0.41 of them), else through ``W``: the creeping bed's step (0.65) takes ``W``; with the
    share raised it takes the factor, whose products agree with ``W``'s to rounding, and the step
    converges in the same 188 Newton iterations, each product through the factor."""
    from lubcontact.solvers import kernels

    with np.load(Path(__file__).parent / "data" / "creeping-bed-step.npz") as data:
        problem = StepProblem.from_arrays(data)
        warm_start, warm_shift = data["warm_start"], data["warm_shift"]
    scaled = problem.normalized()
    share = (scaled.delassus_factor.nnz + scaled.delassus_factor_transpose.nnz) / scaled.delassus.nnz
    assert newton.FACTOR_PRODUCT_SHARE < share < 1.0
    assert AlartCurnier(scaled).factor_arrays is None
    settings = SolveSettings(method="newton-ac", tol=1e-6, exact_coulomb=True,
                             options={"fallback": None})
    calls = []
    apply_operator = kernels.apply_operator
    monkeypatch.setattr(kernels, "apply_operator",
                        lambda *arrays: calls.append(1) or apply_operator(*arrays))
    plain = settings.solve(problem, warm_start, warm_shift)
    assert calls == []
    monkeypatch.setattr(newton, "FACTOR_PRODUCT_SHARE", 1.0)
    function = AlartCurnier(scaled)
    assert function.compiled_rows and function.factor_arrays is not None
    vector = np.random.default_rng(3).normal(size=scaled.n_rows)
    expected = function.W @ vector
    assert np.abs(function.product(vector) - expected).max() <= 1e-13 * np.abs(expected).max()
    calls.clear()
    factored = settings.solve(problem, warm_start, warm_shift)
    assert len(calls) >= factored.info["newton_iterations"]   # the line search's, one a direction
    assert plain.status == factored.status == CONVERGED
    assert plain.info["newton_iterations"] == factored.info["newton_iterations"] == 188
    assert scaled_coulomb_error(problem, factored.forces) <= 1e-6


def test_a_phase_started_where_the_last_ended_takes_its_velocity_and_error(monkeypatch):
    """Where ``_proximal_newton`` hands a Newton phase the velocity and the FCLIB error of its
    start (the last phase's last iterate, re-centred), they are those of its forces: the
    velocity, carried from the last line search on this lane, is ``W r + q`` to rounding, and
    the error that of that velocity, to the bit, and of a fresh product's to rounding. On the
    gluey flow's step every phase but the first is handed them (eight re-centred ones of one
    iteration, then a subproblem of at most UNION_INNER_CAP iterations, a gluey step's), and the
    step takes the same 10 Newton iterations."""
    with np.load(Path(__file__).parents[1] / "flow" / "data" / "gluey-flow-step.npz") as data:
        problem = StepProblem.from_arrays(data)
        warm_start, warm_shift = data["warm_start"], data["warm_shift"]
    phase = newton._newton_phase
    handed, drift, errors = [], [], []

    def spy(function, unshifted, forces, tol, max_iter, inner_tol=0.0, **known):
        if known.get("velocity") is not None:
            velocity = function.product(forces) + function.q
            drift.append(np.abs(known["velocity"] - velocity).max() / np.abs(velocity).max())
            assert known["error"] == function.coulomb_error(unshifted, forces, known["velocity"])
            errors.append(abs(known["error"] / function.coulomb_error(unshifted, forces, velocity) - 1))
            handed.append(max_iter)
        return phase(function, unshifted, forces, tol, max_iter, inner_tol, **known)

    monkeypatch.setattr(newton, "_newton_phase", spy)
    settings = SolveSettings(method="newton-ac", tol=1e-6, exact_coulomb=True,
                             options={"fallback": None})
    result = settings.solve(problem, warm_start, warm_shift)
    assert result.status == CONVERGED and result.info["newton_iterations"] == 10
    assert handed == [1] * 8 + [newton.UNION_INNER_CAP] and newton.UNION_INNER_CAP < newton.INNER_CAP
    assert max(drift) <= 1e-14 and max(errors) <= 1e-12       # measured: 3.5e-16, 1.3e-14


def scripted_recentring(monkeypatch, errors):
    """``_proximal_newton`` on a flow-lane problem from zero forces (tol 1e-10, sigma 1e-3), each
    Newton phase scripted to take one iteration to the next of ``errors``; the centre's FCLIB
    error, and per phase (weight, iteration cap, whether solved to INNER_REDUCTION, the sum of
    the centre's entries), and the result."""
    problem = siconos_test_problem("FrictionContactProblem00237.dat").normalized()
    function = AlartCurnier(problem)
    assert function.flow_step and function.cone_n.size
    start = np.zeros(problem.n_rows)
    centre = function.coulomb_error(problem, start)
    errors = iter(errors(centre))
    calls, previous = [], [centre]

    def phase(function, unshifted, forces, tol, max_iter, inner_tol=0.0, **known):
        error = next(errors)
        calls.append((function.sigma / function.typical, max_iter, inner_tol > 0,
                      float(np.abs(function.center).sum())))
        moved = forces + error                       # each iterate a point of its own
        history = np.array([previous[-1], error])    # the start's error, then the iterate's
        previous.append(error)
        return newton._Phase(forces=moved, status=MAX_ITER, iterations=1, error=error,
                             history=history, gradient_steps=0, solved=inner_tol > 0,
                             last=moved, last_error=error)

    monkeypatch.setattr(newton, "_newton_phase", phase)
    return centre, calls, _proximal_newton(function, problem, start, 1e-10, 50, sigma=1e-3)


def test_re_centring_keeps_the_weight_until_the_error_stops_halving(monkeypatch):
    """Re-centred at each Newton iteration's result at the same weight while the best FCLIB error
    halves within RECENTRE_WINDOW iterations; from the first window that does not, each
    subproblem is solved (INNER_CAP iterations, INNER_REDUCTION) from there, at a weight no
    larger than the iterate's FCLIB error."""
    window = newton.RECENTRE_WINDOW
    centre, calls, result = scripted_recentring(
        monkeypatch, lambda centre: [centre / 2, centre / 4] + [centre / 5] * window + [1e-12])
    assert result.status == CONVERGED and result.proximal_steps == window + 3
    re_centred, solving = calls[:window + 2], calls[window + 2:]
    assert all(sigma == 1e-3 and cap == 1 and not solved for sigma, cap, solved, _ in re_centred)
    centres = [c for *_, c in calls]
    assert all(later > earlier for earlier, later in zip(centres, centres[1:]))   # moved each time
    assert solving == [(min(1e-3, centre / 5), newton.INNER_CAP, True, centres[-1])]


def test_re_centring_stops_near_tol(monkeypatch):
    """Re-centred while the best FCLIB error is above RECENTRE_UNTIL tol (1e-8 at tol 1e-10): from
    there each subproblem is solved, the weight lowered to the iterate's error (5e-9)."""
    _, calls, result = scripted_recentring(monkeypatch, lambda centre: [centre / 2, 5e-9, 1e-12])
    assert result.status == CONVERGED
    assert [(sigma, cap, solved) for sigma, cap, solved, _ in calls] == [
        (1e-3, 1, False), (1e-3, 1, False), (5e-9, newton.INNER_CAP, True)]


def test_a_stuck_proximal_step_raises_the_weight_a_hundredfold(monkeypatch):
    """The weight after a subproblem not solved: 10 times where the step lowered the FCLIB error
    below STUCK times the centre's, STUCK_RISE times where it did not (a stuck iterate; before,
    10 times always, and a hard flow step failed at every weight from 1e-7 to 1e-3 in turn)."""
    problem = siconos_test_problem("FrictionContactProblem00237.dat").normalized()
    function = AlartCurnier(problem)
    start = np.zeros(problem.n_rows)
    centre = function.coulomb_error(problem, start)
    outcomes = iter([(False, centre), (False, 0.5 * centre), (True, 1e-12), (False, 1e-12)])
    weights = []

    def scripted_phase(function, unshifted, forces, tol, max_iter, inner_tol=0.0, **known):
        weights.append(function.sigma / function.typical)
        solved, error = next(outcomes)
        return newton._Phase(forces=forces, status=MAX_ITER, iterations=1, error=error,
                             history=np.array([error]), gradient_steps=0, solved=solved,
                             last=forces, last_error=error)

    monkeypatch.setattr(newton, "_newton_phase", scripted_phase)
    monkeypatch.setattr(newton, "RECENTRE_WINDOW", 0)       # each subproblem solved
    phase = _proximal_newton(function, problem, start, 1e-10, 50, sigma=1e-3)
    # stuck: x100; progress, not solved: x10; solved (friction cones: no plain finish)
    assert np.allclose(weights, [1e-3, 1e-1, 1.0]) and phase.status == CONVERGED


@pytest.mark.parametrize(("name", "factor"), [("gamma_states_gluey_coulomb", "UNION_SIGMA_DECREASE"),
                                             ("mu_ten", "SIGMA_DECREASE")])
def test_the_proximal_weight_falls_slower_on_a_gluey_sparse_problem(name, factor, monkeypatch):
    """After each solved subproblem the weight is divided by UNION_SIGMA_DECREASE (1.5) on a 2D
    problem of the sparse lane with UNION contacts (a gluey flow's step: 2 712 -> 2 027 Newton
    iterations on 70 steps at 12 000 grains with 3), by SIGMA_DECREASE (10) on a dry one (each
    subproblem solved: no re-centring after one iteration, RECENTRE_WINDOW)."""
    use_the_sparse_lane(monkeypatch)
    monkeypatch.setattr(newton, "RECENTRE_WINDOW", 0)
    problem = load_cases()[name].problem.normalized()
    function = AlartCurnier(problem)
    assert not function.dense and function.planar
    start = np.zeros(problem.n_rows)
    centre = function.coulomb_error(problem, start)
    errors = iter([centre / 2, centre / 4, centre / 8, 1e-12])
    weights = []

    def solved_phase(function, unshifted, forces, tol, max_iter, inner_tol=0.0, **known):
        weights.append(function.sigma / function.typical)
        error = next(errors)
        return newton._Phase(forces=forces, status=MAX_ITER, iterations=1, error=error,
                             history=np.array([error]), gradient_steps=0, solved=True,
                             last=forces, last_error=error)

    monkeypatch.setattr(newton, "_newton_phase", solved_phase)
    _proximal_newton(function, problem, start, 1e-10, 50, sigma=1e-3)
    decrease = getattr(newton, factor)
    assert np.allclose(weights, 1e-3 / decrease ** np.arange(4))


def test_the_proximal_weight_stops_rising_at_its_ceiling(monkeypatch):
    """A subproblem stuck at every weight raises the weight a hundredfold each time, up to
    SIGMA_MAX: there the phase has stalled (before, the weight rose until the products
    overflowed on a stuck gluey flow step, with hundreds of numpy warnings)."""
    problem = siconos_test_problem("FrictionContactProblem00237.dat").normalized()
    function = AlartCurnier(problem)
    start = np.zeros(problem.n_rows)
    centre = function.coulomb_error(problem, start)
    weights = []

    def stuck_phase(function, unshifted, forces, tol, max_iter, inner_tol=0.0, **known):
        weights.append(function.sigma / function.typical)
        return newton._Phase(forces=forces, status=MAX_ITER, iterations=1, error=centre,
                             history=np.array([centre]), gradient_steps=0, solved=False,
                             last=forces, last_error=centre)

    monkeypatch.setattr(newton, "_newton_phase", stuck_phase)
    monkeypatch.setattr(newton, "RECENTRE_WINDOW", 0)       # each subproblem solved
    phase = _proximal_newton(function, problem, start, 1e-10, 500, sigma=1e-3)
    assert np.allclose(weights, 1e-3 * 100.0 ** np.arange(7))          # 1e-3 ... 1e9
    assert max(weights) <= SIGMA_MAX and phase.status == newton.STALLED


def test_a_line_search_rejects_a_direction_that_overflows_without_warnings():
    """A direction so long that every trial's residual overflows is given up (None) quietly:
    the trials are rejected, not reported as numpy warnings."""
    problem = siconos_test_problem("FrictionContactProblem00237.dat").normalized()
    function = AlartCurnier(problem)
    forces = np.zeros(problem.n_rows)
    phi, _, velocity = function.residual(forces)
    merit = 0.5 * float(phi @ phi)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _line_search(function, forces, velocity, np.full(problem.n_rows, 1e300),
                            2.0 * merit, merit) is None


def _errors(start: float, rate_per_window: float, windows: int) -> list[float]:
    """FCLIB errors of a phase falling steadily by ``rate_per_window`` every STALL_WINDOW
    iterations, ``windows`` windows long (the start first)."""
    per_iteration = rate_per_window ** (1.0 / STALL_WINDOW)
    return [start * per_iteration**k for k in range(windows * STALL_WINDOW + 1)]


def _first_stall(history: list[float], tol: float) -> int | None:
    """The length of ``history`` at which a phase's stall rule, asked after every iteration as
    the phase grows, first says stalled (None: never)."""
    rule = _StallRule(tol)
    for length in range(1, len(history) + 1):
        if rule.stalled(history[:length], min(history[:length])):
            return length
    return None


def test_a_phase_closing_slowly_on_tol_has_not_stalled():
    """A creeping bed's proximal loop near tol 1e-5: 0.85 per window, 1.2 tol to go. The rule
    of halving per window alone called it stalled and handed it to a fallback that took longer
    for the same distance (docs/records/benchmarks.md, "the last tenths to tol")."""
    history = _errors(1.6e-5, 0.85, 2)
    best = min(history)
    assert 1.1e-5 < best < 1.2e-5 and best > STALL_FACTOR * min(history[:-STALL_WINDOW])
    assert not _StallRule(1e-5).stalled(history, best)    # 3 windows at 0.85: 0.61 x best


def test_a_phase_falling_too_slowly_for_tol_or_flat_has_stalled():
    slow = _errors(1.6e-5, 0.85, 2)                        # the same pace, tol too far for it
    assert _StallRule(5e-6).stalled(slow, min(slow))
    flat = [2e-5] * (STALL_WINDOW + 5)
    assert _StallRule(1.9e-5).stalled(flat, 2e-5)
    assert not _StallRule(1.9e-5).stalled(flat[:STALL_WINDOW], 2e-5)   # not one window yet
    halving = _errors(1e-3, 0.4, 2)                        # the fast phase: never stalled
    assert _first_stall(halving, 1e-12) is None


def test_the_reprieve_near_tol_ends_when_the_pace_no_longer_reaches_tol():
    """A phase whose distance to tol shrinks by 0.7 per window approaches tol without reaching
    it: spared at its first slow window (that window's rate would reach tol within the horizon),
    it stalls once its pace no longer would, before the reprieve's end, not never (the rate of
    each new window spared it again until max_iter). A phase keeping a pace of 0.85 per window
    is never called stalled on its way to tol."""
    tol = 1e-5
    per_iteration = 0.7 ** (1.0 / STALL_WINDOW)
    approaching = [tol * (1.0 + 0.5 * per_iteration**k) for k in range(10 * STALL_WINDOW)]
    first = _first_stall(approaching, tol)
    assert first is not None and STALL_WINDOW + 1 < first <= 2 + (1 + STALL_HORIZON) * STALL_WINDOW
    assert _first_stall(approaching, 0.5 * tol) == STALL_WINDOW + 1     # no reprieve: far from tol
    steady = _errors(1.6e-5, 0.85, 4)
    assert min(steady) < tol and _first_stall(steady, tol) is None


def test_max_iter_is_reported_with_the_best_iterate():
    problem = siconos_test_problem("FrictionContactProblem00237.dat").normalized()
    out = newton_alart_curnier(problem, tol=1e-14, max_iter=3, fallback=None)
    assert out.status == MAX_ITER and out.iterations == 3
    assert out.info["error"] == pytest.approx(coulomb_error(problem, out.forces))
    assert out.info["error"] == pytest.approx(out.residual_history.min())


def test_jacobian_matches_finite_differences_away_from_kinks():
    """J = I - G + G diag(rho) W: a directional derivative of phi at a generic point."""
    problem = siconos_test_problem("Capsules-i122-1617.dat").normalized()
    function = AlartCurnier(problem)
    rng = np.random.default_rng(0)
    forces = np.abs(rng.normal(size=problem.n_rows))
    phi, y, _ = function.residual(forces)
    rows, active, _ = function.jacobian(y)                # the rows of J where G is not zero
    assert rows.shape == (np.count_nonzero(active), problem.n_rows)
    direction = rng.normal(size=problem.n_rows)
    product = direction.copy()                         # J's other rows are the identity's
    product[active] = rows @ direction
    step = 1e-7
    difference = (function.residual(forces + step * direction)[0] - phi) / step
    assert np.linalg.norm(difference - product) <= 1e-5 * np.linalg.norm(product)
    inactive = ~active
    assert np.allclose(difference[inactive], direction[inactive], atol=1e-6)


def test_solves_coulomb_natively_in_one_solve():
    info = solver_info("newton-ac")
    assert info.native_coulomb and info.kind == "newton" and ConeKind.UNION in info.cones
    problem = siconos_test_problem("FrictionContactProblem00237.dat")
    result = solve_coulomb(problem, "newton-ac", tol=1e-8)
    assert result.outer_iterations == 1 and result.fixed_point_converged


@pytest.mark.parametrize("name", ["dt_large_friction", "cone_apex_2d", "mu_ten", "tetrahedron_3d_friction",
                                  "gamma_states_gluey_coulomb"])
def test_the_native_solve_s_shift_is_mu_times_the_tangential_velocity_of_its_forces(name):
    """s* = mu |g_T(r*)|, the fixed point by construction, whichever way it is computed: from the
    normalised problem's dense W on small 2D problems (W r + b), from its g(v(r)) elsewhere
    (3D), against the physical problem's g(v(r)), to rounding; the first four slide, the gluey
    one's contacts stick or are pulled (no shift)."""
    problem = load_cases()[name].problem
    result = solve_coulomb(problem, "newton-ac", tol=1e-10)
    unshifted = problem.with_shift(np.zeros(problem.n_contacts))
    expected = coulomb_shift(unshifted, result.forces)
    rounding = 1e-12 * np.abs(unshifted.gradient(result.forces)).max()
    assert result.status == CONVERGED
    assert (expected.max() > 1e6 * rounding) == (name != "gamma_states_gluey_coulomb")
    np.testing.assert_allclose(result.shift, expected, rtol=1e-12, atol=rounding)


def test_union_contacts_are_solved_natively_in_one_solve():
    """Gluey + friction at gamma_min (UNION): one Newton solve of the union law (bilateral normal
    row, friction while pushed) gives Clarabel's fixed point on s with its branch rule."""
    case = load_cases()["gamma_states_gluey_coulomb"]
    kinds = case.problem.cones.kinds
    assert np.any(kinds == ConeKind.UNION)
    expected = expected_for(case, case.problem, fixed_point=True)
    result = solve_coulomb(case.problem, "newton-ac", tol=1e-10)
    assert result.status == CONVERGED and result.outer_iterations == 1
    assert scaled_velocity_error(case.problem, result.velocities, expected.velocities) <= 1e-8
    pulled = case.problem.cones.pulled(result.forces)
    assert np.any(pulled) and np.any(~pulled[kinds == ConeKind.UNION])   # both pieces occur


def test_union_contacts_skip_the_joint_start(monkeypatch):
    """The joint phase would shift both pieces of a UNION contact (spurious minimisers): with
    UNION contacts newton-ac runs without it (on the sparse lane too)."""
    case = load_cases()["gamma_states_gluey_coulomb"]
    use_the_sparse_lane(monkeypatch)
    plain = solve_coulomb(case.problem, "newton-ac", tol=1e-10)
    joint = solve_coulomb(case.problem, "newton-ac", tol=1e-10, joint=5)
    assert joint.joint_iterations == 0
    np.testing.assert_array_equal(joint.forces, plain.forces)


@pytest.fixture(scope="module")
def stalling():
    """Siconos' 2020-contact granular file at tol 1e-8: every Newton strategy stalls (indefinite
    stored W, degenerate contacts; docs/records/siconos-testdata.md)."""
    problem = read_problem(benchmark_file("siconos-fc2d", "fc2d_granularflowonwall_02020_00213.dat"))
    alone = solve_coulomb(problem, "newton-ac", tol=1e-8, fallback=None)
    return problem, alone


def test_a_stalled_newton_without_fallback_is_inaccurate_with_its_best_iterate(stalling):
    problem, alone = stalling
    assert alone.info["newton_status"] == "stalled" and alone.status == INACCURATE
    assert scaled_coulomb_error(problem, alone.forces) == pytest.approx(alone.info["error"], rel=1e-6)
    assert 1e-8 < alone.info["error"] < 1e-4


def test_a_strategy_stalled_near_tol_goes_to_the_fallbacks_without_the_other_strategies(stalling):
    """The first strategy stalls within STRATEGY_GAP of tol: the other starting weights (which
    stall further away on such problems) are not tried; the fallbacks finish the solve."""
    problem, alone = stalling
    assert alone.info["strategies"] == [(1e-3, "cold")]
    assert alone.info["error"] <= STRATEGY_GAP * 1e-8
    rescued = solve_coulomb(problem, "newton-ac", tol=1e-8)
    # Gauss-Seidel's rounds first, each polished by the proximal loop with its local sweeps
    # (4 040 rows); whether a polish reaches tol or apgd-jacobi, the chain's next, finishes
    # follows the rounding of the stalled strategy's iterates (the first polish reached tol
    # while the sparse lane took W r afresh after each line search; since, apgd-jacobi finishes)
    assert rescued.status == CONVERGED and rescued.info["fallbacks"][0] == "nsgs"
    assert rescued.info["local_sweeps"] > 0
    assert scaled_coulomb_error(problem, rescued.forces) <= 1e-8


def test_a_fallback_answer_kept_within_the_gap_ends_the_chain(stalling, monkeypatch):
    """A first fallback whose answer (unpolished here) is kept above tol but within FALLBACK_GAP
    tol ends the chain, and not with a smaller gap; a first fallback whose answer is not kept
    (zero forces) never ends it, whatever Newton's own error."""
    problem, alone = stalling
    solution = newton_alart_curnier(problem.normalized(), tol=1e-8).forces

    def nearer(problem, *, tol, max_iter=1, warm_start=None):
        return MethodOutput(solution * (1.0 + 1e-7), MAX_ITER, 1)   # FCLIB error 5e-8

    def zero(problem, *, tol, max_iter=1, warm_start=None):
        return MethodOutput(np.zeros(problem.n_rows), MAX_ITER, 1)

    def echo(problem, *, tol, max_iter=1, warm_start=None):
        return MethodOutput(np.array(warm_start, dtype=float), MAX_ITER, 1)

    def chain(first, gap):
        monkeypatch.setattr(newton, "FALLBACKS_2D", (first, "echo-test"))
        monkeypatch.setattr(newton, "FALLBACK_GAP", gap)
        return solve_coulomb(problem, "newton-ac", tol=1e-8)

    monkeypatch.setattr(newton, "FALLBACK_POLISH_ITERATIONS", 0)   # each fallback's answer as it is
    fakes = {"nearer-test": nearer, "zero-test": zero, "echo-test": echo}
    registered = []
    try:
        for name, fake in fakes.items():
            register(name, kind=FIRST_ORDER, cones=ALL_CONES, warm_start=True)(fake)
            registered.append(name)
        within = chain("nearer-test", FALLBACK_GAP)
        kept = within.info["error"]
        above = chain("nearer-test", 0.5 * kept / 1e-8)
        not_kept = chain("zero-test", np.inf)
    finally:
        for name in registered:
            unregister(name)
    assert 1e-8 < kept <= FALLBACK_GAP * 1e-8 and kept < alone.info["error"]
    assert within.info["fallbacks"] == ["nearer-test"]
    assert above.info["fallbacks"] == ["nearer-test", "echo-test"]
    assert not_kept.info["fallbacks"] == ["zero-test", "echo-test"]
    assert not_kept.info["error"] == pytest.approx(alone.info["error"], rel=1e-12)


def test_a_fallback_that_solves_coulomb_itself_runs_in_rounds_each_polished(stalling, monkeypatch):
    """A fallback that solves exact Coulomb itself (as nsgs) spends its iteration cap in rounds
    (fallback_rounds: FALLBACK_ROUND, FALLBACK_ROUND, twice, four times, then the rest), each
    from the last one's forces and polished: here the second round's answer is the solution, and
    the chain stops there, where one call with the whole cap ended short of tol. The rounds stop
    too where the fallback says it converged (its answer polished above tol: inaccurate) or
    diverged (non-finite forces, zero after solve's check). A fixed point on s (apgd-jacobi) runs
    in one call."""
    problem, alone = stalling
    solution = newton_alart_curnier(problem.normalized(), tol=1e-8).forces
    monkeypatch.setattr(newton, "FALLBACK_POLISH_ITERATIONS", 0)     # each round's answer as it is

    def rounds(answer):
        """The solve with a fake native fallback whose k-th call (1, 2, ...) returns
        ``answer(k, warm_start)``; the calls' caps and warm starts."""
        calls = []

        def fake(problem, *, tol, max_iter=20_000, warm_start=None):
            calls.append((max_iter, np.array(warm_start, dtype=float)))
            forces, status = answer(len(calls), calls[-1][1])
            return MethodOutput(forces, status, max_iter)

        register("rounds-test", kind=FIRST_ORDER, cones=ALL_CONES, warm_start=True,
                 native_coulomb=True)(fake)
        try:
            assert newton.fallback_rounds("rounds-test") == (1000, 1000, 2000, 4000, 12000)
            return solve_coulomb(problem, "newton-ac", tol=1e-8, fallback="rounds-test"), calls
        finally:
            unregister("rounds-test")

    halfway = lambda warm_start: 0.5 * (warm_start + solution)       # noqa: E731
    result, calls = rounds(lambda k, warm: (solution if k == 2 else halfway(warm), MAX_ITER))
    assert [cap for cap, _ in calls] == [newton.FALLBACK_ROUND] * 2
    assert np.array_equal(calls[1][1], halfway(calls[0][1]))          # from the first's answer
    assert result.status == CONVERGED and result.info["fallback_iterations"] == 2 * newton.FALLBACK_ROUND
    assert scaled_coulomb_error(problem, result.forces) <= 1e-8 < alone.info["error"]
    said, calls = rounds(lambda k, warm: (halfway(warm), CONVERGED))
    assert len(calls) == 1 and said.status == INACCURATE and said.info["fallback_status"] == CONVERGED
    diverged, calls = rounds(lambda k, warm: (np.full_like(warm, np.nan), MAX_ITER))
    assert len(calls) == 1 and diverged.info["fallback_status"] == DIVERGED
    assert diverged.info["error"] == pytest.approx(alone.info["error"], rel=1e-12)
    cap = inspect.signature(nonsmooth_gauss_seidel).parameters["max_iter"].default
    assert sum(newton.fallback_rounds("nsgs")) == cap
    assert newton.fallback_rounds("apgd-jacobi") == (None,)


def test_a_fallback_worse_than_newton_never_replaces_its_best_iterate(stalling, monkeypatch):
    """A fallback whose answer is worse than the best Newton iterate (here: zero forces said to be
    converged, unpolished: 30 Newton iterations from zero forces may do better than the stalled
    strategy's best) leaves that iterate as the answer; the status stays honest."""
    problem, alone = stalling
    monkeypatch.setattr(newton, "FALLBACK_POLISH_ITERATIONS", 0)

    @register("zero-forces-test", kind=FIRST_ORDER, cones=ALL_CONES)
    def zero_forces(problem, *, tol, max_iter=1, warm_start=None):
        return MethodOutput(np.zeros(problem.n_rows), CONVERGED, 1)

    try:
        result = solve_coulomb(problem, "newton-ac", tol=1e-8, fallback="zero-forces-test")
    finally:
        unregister("zero-forces-test")
    assert result.info["fallback_iterations"] == 1    # it ran (its claim is rejected: inaccurate)
    assert result.status == INACCURATE
    error = scaled_coulomb_error(problem, result.forces)
    assert error == pytest.approx(alone.info["error"], rel=1e-6)
    assert error < scaled_coulomb_error(problem, np.zeros(problem.n_rows))


def test_a_fallback_with_non_finite_forces_leaves_newtons_answer_and_status(monkeypatch):
    """One Newton iteration, then a fallback that diverges (NaN forces, zeroed by the registry):
    the answer is the better of Newton's best iterate and the fallback's (unpolished: 30 Newton
    iterations from zero solve this case), with status max_iter (the iterations ran out), never
    the fallback's 'diverged'."""
    case = load_cases()["hex_box_lid_friction"]
    monkeypatch.setattr(newton, "FALLBACK_POLISH_ITERATIONS", 0)

    @register("nan-forces-test", kind=FIRST_ORDER, cones=ALL_CONES)
    def nan_forces(problem, *, tol, max_iter=1, warm_start=None):
        return MethodOutput(np.full(problem.n_rows, np.nan), "diverged", 1)

    try:
        result = solve_coulomb(case.problem, "newton-ac", tol=1e-9, max_iter=1,
                               fallback="nan-forces-test")
    finally:
        unregister("nan-forces-test")
    assert result.info["newton_status"] == MAX_ITER and result.info["fallback_status"] == "diverged"
    assert result.status == MAX_ITER and np.all(np.isfinite(result.forces))


def use_the_sparse_lane(monkeypatch):
    """Zero dense limits: every problem takes newton-ac's sparse lane (SuperLU, kept LUs)."""
    from lubcontact.solvers import dual_data

    monkeypatch.setattr(dual_data, "DENSE_OPERATOR_LIMIT", 0)
    monkeypatch.setattr(newton, "DENSE_LIMIT", 0)
    monkeypatch.setattr(newton, "COMPILED_LIMIT", 0)


@pytest.mark.parametrize("name", ["gamma_states_gluey_coulomb", "mu_ten", "dt_large_friction",
                                  "tetrahedron_3d_friction"])
def test_small_problems_take_the_dense_lane_with_the_same_newton_steps(name, monkeypatch):
    """At most DENSE_OPERATOR_LIMIT rows (2D: COMPILED_LIMIT, compiled) the Jacobian's rows are
    dense: the same values as the sparse rows, and the same Newton iterations to the same forces
    (zero limits force the sparse lane)."""
    from lubcontact.solvers import dual_data

    problem = load_cases()[name].problem.normalized()
    assert dual_data.is_small(problem)
    monkeypatch.setattr(newton, "UNION_SIGMA_DECREASE", newton.SIGMA_DECREASE)  # one schedule
    monkeypatch.setattr(newton, "RECENTRE_WINDOW", 0)
    function = AlartCurnier(problem)
    y = function.residual(np.abs(np.random.default_rng(1).normal(size=problem.n_rows)))[1]
    rows, active, _ = function.jacobian(y)
    dense = solve_coulomb(problem, "newton-ac", tol=1e-10)
    use_the_sparse_lane(monkeypatch)
    sparse_function = AlartCurnier(problem)
    sparse_rows, sparse_active, _ = sparse_function.jacobian(y)
    assert isinstance(rows, np.ndarray) and not isinstance(sparse_rows, np.ndarray)
    assert np.array_equal(active, sparse_active)
    assert np.allclose(rows, sparse_rows.toarray(), rtol=0, atol=1e-13 * np.abs(rows).max())
    sparse = solve_coulomb(problem, "newton-ac", tol=1e-10)
    assert dense.status == sparse.status == CONVERGED
    assert dense.info["newton_iterations"] == sparse.info["newton_iterations"]
    assert np.abs(dense.forces - sparse.forces).max() <= 1e-9 * np.abs(sparse.forces).max()


COMPILED_CASES = ["gamma_states_gluey_coulomb", "mu_ten", "dt_large_friction", "mu_zero_friction",
                  "cone_apex_2d", "hex_box_lid_friction"]


def compiled_and_numpy(problem, run):
    """``run(function, unshifted)`` on ``problem``'s Alart-Curnier function with its Newton
    phases compiled, then with the numpy phases: the two outcomes."""
    unshifted = problem.with_shift(np.zeros(problem.cones.count))
    outcomes = []
    for compiled in (True, False):
        function = AlartCurnier(problem)
        function.compiled = compiled
        outcomes.append(run(function, unshifted))
    return outcomes


def fclib_residual(problem, forces):
    """The vector whose norm is metrics.coulomb_error's numerator, row by row (numpy)."""
    nc = problem.cones.count
    corrected = problem.gradient(forces)
    corrected[:nc] += coulomb_shift(problem, forces, corrected) - problem.shift
    cones = problem.cones if problem.cones.is_convex else \
        problem.cones.with_branches(problem.cones.pulled(forces))
    return forces - cones.project(forces - corrected)


@pytest.mark.parametrize("name", COMPILED_CASES)
@pytest.mark.parametrize("sigma", [0.0, 1e-2])
def test_the_compiled_residual_jacobian_and_error_are_their_numpy_twins(name, sigma):
    """On a small 2D problem the Newton phase runs compiled (kernels.newton_phase_2d): at points with
    every contact state (random signs and sizes), its residual, velocity, Jacobian rows and
    FCLIB error are those of AlartCurnier and metrics.coulomb_error."""
    from lubcontact.solvers import kernels as kernel

    problem = load_cases()[name].problem.normalized()
    function = AlartCurnier(problem)
    assert function.compiled
    unshifted = problem.with_shift(np.zeros(problem.cones.count))
    rng = np.random.default_rng(3)
    function.set_proximal(sigma, rng.normal(size=problem.n_rows))
    n = problem.n_rows
    for _ in range(20):
        forces = rng.normal(size=n) * rng.choice([1e-3, 1.0, 1e3], size=n)
        phi, y, velocity = function.residual(forces)
        compiled = np.empty(n), np.empty(n), np.empty(n)
        kernel.product_2d(function.W, *function.w_arrays, forces, function.q, compiled[2])
        by_rows = np.empty(n)                   # W by its rows: the same sums, zeros left out
        kernel.product_2d(function.W, *kernel.compressed_rows(function.W), forces, function.q,
                          by_rows)
        assert np.array_equal(by_rows, compiled[2])
        merit = kernel.alart_curnier_2d(
            function.rho, function.lower, function.upper, function.cone_n, function.tangent_rows,
            function.cone_mu, function.unilateral, function.sigma, function.center, forces,
            compiled[2], compiled[0], compiled[1])
        scale = np.abs(forces).max() + np.abs(velocity).max()
        for mine, theirs in zip(compiled, (phi, y, velocity), strict=True):
            assert np.abs(mine - theirs).max() <= 1e-13 * scale
        assert merit == pytest.approx(0.5 * phi @ phi, rel=1e-12)
        error = kernel.coulomb_error_2d(forces, velocity, function.lower, function.upper,
                                        function.cone_n, function.tangent_rows, function.cone_mu,
                                        function.unilateral, function.q_scale)
        assert error == pytest.approx(coulomb_error(unshifted, forces), rel=1e-12)
        residual = kernel.coulomb_residual_2d(forces, velocity, function.lower, function.upper,
                                              function.cone_n, function.tangent_rows,
                                              function.cone_mu, function.unilateral)
        expected = fclib_residual(unshifted, forces)
        assert np.abs(residual - expected).max() <= 1e-13 * scale
        rows, J = kernel.jacobian_rows_2d(function.W, function.rho, function.lower, function.upper,
                                          function.box, function.cone_n, function.tangent_rows,
                                          function.cone_mu, function.unilateral, function.sigma, y)
        expected, active, _ = function.jacobian(y)
        assert np.array_equal(rows, np.flatnonzero(active))
        assert np.abs(J - expected).max() <= 1e-13 * max(np.abs(expected).max(initial=0.0), 1.0)


@pytest.mark.parametrize("name", COMPILED_CASES)
@pytest.mark.parametrize("sigma", [0.0, 1e-2])
def test_the_compiled_sparse_jacobian_rows_are_the_numpy_rows(name, sigma, monkeypatch):
    """On the sparse lane (limits set to zero) a 2D problem's residual and Jacobian rows are
    computed by compiled kernels: the same residual and ``y`` as the numpy ones, to the bit, the
    same active rows and values as the numpy sparse product, and the same count of rows of
    diag(rho) W (singular_by_count's; also counted alone by plain_rows_2d), at points with every
    contact state."""
    from lubcontact.solvers.kernels import plain_rows_2d

    use_the_sparse_lane(monkeypatch)
    problem = load_cases()[name].problem.normalized()
    function = AlartCurnier(problem)
    assert function.compiled_rows and not function.dense
    rng = np.random.default_rng(4)
    function.set_proximal(sigma, rng.normal(size=problem.n_rows))
    for _ in range(20):
        forces = rng.normal(size=problem.n_rows) * rng.choice([1e-3, 1.0, 1e3], size=problem.n_rows)
        compiled = function.residual(forces)
        y = compiled[1]
        rows, active, plain = function.jacobian(y)
        function.compiled_rows = False
        expected, expected_active, expected_plain = function.jacobian(y)
        numpy_residual = function.residual(forces)
        function.compiled_rows = True
        assert np.array_equal(compiled[0], numpy_residual[0])
        assert np.array_equal(compiled[1], numpy_residual[1])
        assert np.array_equal(active, expected_active) and plain == expected_plain
        assert plain_rows_2d(function.lower, function.upper, function.box, function.cone_n,
                             function.tangent_rows, function.cone_mu, function.unilateral,
                             y) == plain
        difference = np.abs(rows.toarray() - expected.toarray()).max(initial=0.0)
        assert difference <= 1e-13 * max(np.abs(expected.toarray()).max(initial=0.0), 1.0)


def solves_the_whole_newton_system(J, active, phi, direction):
    """Check that ``direction``, found from a reduced system, solves the whole Newton system
    ``J d = -phi`` (J: the active rows) as the unreduced block's (_newton_direction) does."""
    expected = newton._newton_direction(J, active, phi)
    assert np.array_equal(direction[~active], -phi[~active])
    scale = abs(J).max() * np.abs(direction).max()          # a backward error: 7e-15
    assert np.abs(J @ direction + phi[active]).max() <= 1e-13 * scale
    assert np.abs(direction - expected).max() <= 1e-10 * np.abs(expected).max()


def eliminated_sliding_rows(function, points):
    """Check the sparse lane's reduced Newton system (AlartCurnier.reduced_system) of
    ``function`` at each of ``points`` (forces): a block of as many rows as J has rows of
    diag(rho) (W + sigma I), by rows, each row's columns once and its diagonal first, and a
    direction that solves the whole system (:func:`solves_the_whole_newton_system`). Returns the
    sliding rows eliminated at each point, and whether any of them has an entry of W in a kept
    row (its column folded into its normal's)."""
    assert function.compiled_rows
    eliminated, folded = [], False
    for forces in points:
        phi, y, _ = function.residual(forces)
        J, active, plain = function.jacobian(y)
        kept, block, *_, sliding, _, _ = function.reduced_system(y, phi)
        assert kept.size == plain and sliding.size == np.count_nonzero(active) - plain
        indptr, indices = block.indptr, block.indices
        canonical = block.copy()
        canonical.sum_duplicates()
        assert canonical.nnz == block.nnz
        assert np.array_equal(indices[indptr[:-1]], np.arange(kept.size))
        assert np.count_nonzero(block.diagonal()) == kept.size or function.sigma == 0
        eliminated.append(sliding)
        folded = folded or function.W[kept][:, sliding].nnz > 0
        solves_the_whole_newton_system(J, active, phi, function.newton_direction(y, phi))
    return eliminated, folded


@pytest.mark.parametrize("name", [name for name in COMPILED_CASES if name != "mu_zero_friction"])
@pytest.mark.parametrize("sigma", [1e-4, 1e-2])
@pytest.mark.parametrize("static_rows", [0, 10**6])
def test_the_compiled_dense_lane_solves_the_newton_system_without_its_sliding_rows(
        name, sigma, static_rows, monkeypatch):
    """The compiled dense lane's Newton direction (kernels.newton_direction_2d) comes from the
    system reduced to its rows of diag(rho) (W + sigma I), as on the sparse lane: checked at
    points with every contact state, on the hard cases with friction, where contacts slide
    (before, it factorised the whole active block); with the block factorised sparse in a
    minimum-degree order (STATIC_DENSE_ROWS 0) and by LAPACK's dense LU."""
    from lubcontact.solvers.kernels import fold_sliding_rows_2d, generalised_jacobian_2d, newton_direction_2d

    monkeypatch.setattr(newton, "STATIC_DENSE_ROWS", static_rows)
    problem = load_cases()[name].problem.normalized()
    function = AlartCurnier(problem)
    assert function.compiled and function.dense
    assert (function.elimination_places.size > 0) == (static_rows == 0)
    rng = np.random.default_rng(5)
    function.set_proximal(sigma, rng.normal(size=problem.n_rows))
    n = problem.n_rows
    sliding_rows = 0
    for _ in range(20):
        forces = rng.normal(size=n) * rng.choice([1e-3, 1.0, 1e3], size=n)
        phi, y, _ = function.residual(forces)
        J, active, plain = function.jacobian(y)
        states = (function.lower, function.upper, function.box, function.cone_n,
                  function.tangent_rows, function.cone_mu, function.unilateral)
        kept, *_, base, sliding, normal, slope = fold_sliding_rows_2d(
            *generalised_jacobian_2d(*states, y), phi)
        assert kept.size == plain and sliding.size == np.count_nonzero(active) - plain
        sliding_rows += sliding.size
        direction, ok = newton_direction_2d(function.W, function.w_arrays, function.rho, *states,
                                            function.sigma, y, phi,
                                            np.array(newton.REGULARISATIONS),
                                            function.elimination_places,
                                            newton.STATIC_LU_BACKWARD_ERROR)
        assert ok
        solves_the_whole_newton_system(J, active, phi, direction)
        # the sliding rows' unknowns follow their normal rows' exactly: they were eliminated
        assert np.array_equal(direction[sliding], base[sliding] + slope * direction[normal])
    assert sliding_rows > 0


def grid_pattern(side: int, seed: int):
    """The rows (32-bit CSR arrays, as kernels.compressed_rows gives them) of a symmetric matrix
    whose pattern is a ``side`` x ``side`` grid's, a random fifth of its edges left out."""
    from lubcontact.solvers.kernels import compressed_rows

    n = side * side
    matrix = 4.0 * np.eye(n)
    rng = np.random.default_rng(seed)
    for node in range(n):
        for other in (node + 1 if (node + 1) % side else -1, node + side if node + side < n else -1):
            if other >= 0 and rng.random() > 0.2:
                matrix[node, other] = matrix[other, node] = -1.0
    return compressed_rows(matrix)[:2]


def test_the_compiled_lanes_elimination_order_is_kept_by_the_pattern_of_w(monkeypatch):
    """The compiled lane's elimination order (newton.elimination_places) of the pattern met last
    is the one found for it, the same read-only array, whatever arrays hold the pattern's
    values; it is the order found afresh; another pattern, also one with the same row counts,
    has its own, and the first is then found again."""
    monkeypatch.setattr(newton, "_last_order", [((b"", b""), np.empty(0, dtype=np.int32))])
    first, second = grid_pattern(12, seed=1), grid_pattern(12, seed=2)
    places = newton.elimination_places(*first)
    assert np.array_equal(places, newton.minimum_degree_places(*first))
    assert not np.array_equal(places, newton.minimum_degree_places(*second))
    assert not places.flags.writeable
    assert newton.elimination_places(*(array.astype(np.int64) for array in first)) is places
    others = newton.elimination_places(*second)
    assert others is not places and np.array_equal(others, newton.minimum_degree_places(*second))
    again = newton.elimination_places(*first)
    assert again is not places and np.array_equal(again, places)
    # a path 0-1-2-3 and the path 0-2-1-3: the same row counts, other columns
    path = (np.array([0, 2, 5, 8, 10], dtype=np.uint32),
            np.array([0, 1, 0, 1, 2, 1, 2, 3, 2, 3], dtype=np.uint32))
    relabelled = (path[0], np.array([0, 2, 1, 2, 3, 0, 1, 2, 1, 3], dtype=np.uint32))
    straight = newton.elimination_places(*path)
    crossed = newton.elimination_places(*relabelled)
    assert crossed is not straight
    assert np.array_equal(crossed, newton.minimum_degree_places(*relabelled))


def test_steps_of_a_small_pile_reuse_their_order_and_give_the_same_answers(monkeypatch):
    """On consecutive steps of a settling 40-grain frictional pile (compiled lane, over
    STATIC_DENSE_ROWS rows) most solves keep the order of the step before, and each answer is
    the one found with every order found afresh, to the bit."""
    from lubcontact import scenes
    from lubcontact.model.laws import Coulomb
    from lubcontact.sim.simulation import Simulation

    sim = Simulation(scenes.settling_pile(40, seed=1), Coulomb(0.3), 0.02, solver="newton-ac",
                     tol=1e-8, fixed_point=True, tol_fp=1e-6, on_failure="ignore")
    sim.run(150)
    steps = []
    for _ in range(8):
        steps.append(sim.next_problem()[2:])
        sim.step()
    assert min(problem.n_rows for problem, _, _ in steps) >= newton.STATIC_DENSE_ROWS
    found = []
    fresh = newton.minimum_degree_places
    monkeypatch.setattr(newton, "minimum_degree_places",
                        lambda *pattern: found.append(pattern[0].size) or fresh(*pattern))
    monkeypatch.setattr(newton, "_last_order", [((b"", b""), np.empty(0, dtype=np.int32))])
    kept = [solve_coulomb(problem, "newton-ac", tol=1e-8, warm_start=forces, shift=shift)
            for problem, forces, shift in steps]
    assert len(found) <= len(steps) // 2

    def afresh_places(*pattern):                # read-only, as the kept ones: the same kernels
        places = fresh(*pattern)
        places.flags.writeable = False
        return places

    monkeypatch.setattr(newton, "elimination_places", afresh_places)
    for (problem, forces, shift), answer in zip(steps, kept):
        afresh = solve_coulomb(problem, "newton-ac", tol=1e-8, warm_start=forces, shift=shift)
        assert answer.status == afresh.status == CONVERGED
        assert np.array_equal(answer.forces, afresh.forces) and answer.iterations == afresh.iterations


@pytest.mark.parametrize("name", [name for name in COMPILED_CASES if name != "mu_zero_friction"])
@pytest.mark.parametrize("sigma", [1e-4, 1e-2])
def test_the_sparse_lane_solves_the_newton_system_without_its_sliding_rows(name, sigma, monkeypatch):
    """On the sparse lane a 2D Newton system is reduced to its rows of diag(rho) (W + sigma I)
    (a sliding tangential row's unknown follows its normal row's): checked at points with every
    contact state, on the hard cases with friction, where contacts slide."""
    use_the_sparse_lane(monkeypatch)
    problem = load_cases()[name].problem.normalized()
    function = AlartCurnier(problem)
    rng = np.random.default_rng(5)
    function.set_proximal(sigma, rng.normal(size=problem.n_rows))
    n = problem.n_rows
    eliminated, _ = eliminated_sliding_rows(
        function, [rng.normal(size=n) * rng.choice([1e-3, 1.0, 1e3], size=n) for _ in range(20)])
    assert sum(rows.size for rows in eliminated) > 0


@pytest.mark.parametrize("sigma", [1e-3, 1e-5])
@pytest.mark.parametrize("dense_limit", [None, 1000])
def test_the_sliding_rows_of_union_contacts_fold_into_their_bilateral_normal_rows(
        sigma, dense_limit, monkeypatch):
    """A gluey + friction flow step (1 635 rows: the sparse lane) at its warm start and near it:
    the sliding rows eliminated are UNION contacts' (pushed, bilateral normal rows) coupled to
    kept rows, and the reduced system gives the whole system's direction; also where the
    reduced block (some 700 rows) is at most DENSE_LIMIT rows, factorised dense."""
    if dense_limit is not None:
        monkeypatch.setattr(newton, "DENSE_LIMIT", dense_limit)
    with np.load(Path(__file__).parents[1] / "flow" / "data" / "gluey-flow-step.npz") as data:
        problem = StepProblem.from_arrays(data).normalized()
        start = data["warm_start"] / problem.scaling.force
    function = AlartCurnier(problem)
    function.set_proximal(sigma * function.typical, start)
    rng = np.random.default_rng(6)
    points = [start] + [start * (1 + 0.3 * rng.normal(size=start.size)) for _ in range(4)]
    eliminated, folded = eliminated_sliding_rows(function, points)
    union_normal = function.cone_n[~function.unilateral]
    assert all(rows.size for rows in eliminated) and folded
    assert np.isin(function.cone_n[np.searchsorted(function.tangent_rows, eliminated[0])],
                   union_normal).all()


def same_csr(first, second):
    """Whether two CSR matrices have the same arrays, entry for entry."""
    return (np.array_equal(first.indptr, second.indptr)
            and np.array_equal(first.indices, second.indices)
            and np.array_equal(first.data, second.data))


def reduced_block_fold(function, forces):
    """``(kept, target, factor, outer)`` of the sparse lane's reduced Newton system at
    ``forces`` (kernels.fold_sliding_rows_2d)."""
    from lubcontact.solvers import kernels

    phi, y, _ = function.residual(forces)
    return kernels.fold_sliding_rows_2d(*kernels.generalised_jacobian_2d(
        function.lower, function.upper, function.box, function.cone_n, function.tangent_rows,
        function.cone_mu, function.unilateral, y), phi)[:4]


def gluey_flow_function():
    """AlartCurnier of the gluey + friction flow step (1 635 rows, the sparse lane) and its
    warm start, normalised."""
    with np.load(Path(__file__).parents[1] / "flow" / "data" / "gluey-flow-step.npz") as data:
        problem = StepProblem.from_arrays(data).normalized()
        start = data["warm_start"] / problem.scaling.force
    return AlartCurnier(problem), start


def test_a_newton_phase_carries_the_accepted_trials_velocity_within_rounding():
    """The sparse lane's Newton iterations go on from the line search's accepted trial, whose
    velocity is ``v + alpha W d``, not ``W r + q`` afresh: after 30 iterations on the gluey flow
    step (1 635 rows; a proximal weight, so that they do not stop at tol), or fewer where the
    proximal subproblem's carried residual comes out exactly 0 (27 with the static LU by pairs
    of columns), the last iterate's carried velocity is ``W r + q`` to 1e-13 of its size, its
    FCLIB error that of the fresh velocity to 1e-9 of itself, and the phase took Newton steps,
    not gradient steps."""
    function, start = gluey_flow_function()
    assert not function.compiled                # a 2D problem: its FCLIB error reads no problem
    function.set_proximal(1e-3 * function.typical, start)
    phase = newton._newton_phase(function, None, start, 1e-14, 30)
    assert phase.gradient_steps == 0 and phase.iterations >= 20
    assert phase.iterations == 30 or phase.solved
    fresh = function.W @ phase.last + function.q
    assert np.abs(phase.last_velocity - fresh).max() <= 1e-13 * np.abs(fresh).max()
    assert function.coulomb_error(None, phase.last, fresh) == \
        pytest.approx(phase.last_error, rel=1e-9)


def test_local_sweeps_carry_the_velocity_through_the_rows_they_moved(monkeypatch):
    """``AlartCurnier.swept`` and ``corrected`` give the swept forces' velocity as the one at the
    forces given plus the change through the rows of ``W`` that the sweeps moved
    (``moved_velocity``), not as a product afresh: on the gluey flow step (1 635 rows), the
    sweeps moving a few of its rows, it is ``W r + q`` to 1e-13 of its size, with the FCLIB
    error and the residual of the fresh velocity."""
    function, start = gluey_flow_function()
    for name in ("LOCAL_SHARE", "CORRECTED_SHARE"):         # swept whatever the residual's share
        monkeypatch.setattr(newton, name, 0.0)
    for name in ("LOCAL_ROWS", "CORRECTED_ROWS"):           # around a few rows
        monkeypatch.setattr(newton, name, 10)
    velocity = function.W @ start + function.q
    swept, carried, error = function.swept(start, velocity)
    moved = np.flatnonzero(swept != start)
    assert 0 < moved.size < function.n_rows // 4
    fresh = function.W @ swept + function.q
    assert np.abs(carried - fresh).max() <= 1e-13 * np.abs(fresh).max()
    assert error == pytest.approx(function.coulomb_error(None, swept, fresh), rel=1e-9)
    phi = function.residual(start, velocity)[0]
    corrected, phi_corrected, _, carried = function.corrected(start, phi, velocity)
    assert 0 < np.flatnonzero(corrected != start).size < function.n_rows // 4
    fresh = function.W @ corrected + function.q
    assert np.abs(carried - fresh).max() <= 1e-13 * np.abs(fresh).max()
    np.testing.assert_allclose(phi_corrected, function.residual(corrected, fresh)[0], rtol=0,
                               atol=1e-13 * np.abs(phi_corrected).max())


def test_the_lane_carries_out_a_flow_steps_rules_without_choosing_them(monkeypatch):
    """The gluey + friction flow step (1 635 rows) solved on the sparse lane and, its limit raised,
    on the compiled lane: the rules are a flow step's on both (its first weight, its re-centring,
    its inner cap), so both take the same Newton iterations and strategies and reach tol. When
    the compiled lane ended at DENSE_LIMIT rows, a rule of a flow's step was a rule of the sparse
    lane, and the compiled lane above 300 rows ended a flow step at max_iter (one in 180)."""
    with np.load(Path(__file__).parents[1] / "flow" / "data" / "gluey-flow-step.npz") as data:
        problem = StepProblem.from_arrays(data)
        guess = data["warm_start"]
    lanes = {}
    for limit in (newton.COMPILED_LIMIT, problem.n_rows):
        monkeypatch.setattr(newton, "COMPILED_LIMIT", limit)
        function = AlartCurnier(problem.normalized())
        assert function.flow_step and function.compiled == (limit == problem.n_rows)
        lanes[function.compiled] = solve_coulomb(problem, "newton-ac", tol=1e-6, warm_start=guess,
                                                 fallback=None)
    for result in lanes.values():
        assert result.status == CONVERGED and scaled_coulomb_error(problem, result.forces) <= 1e-6
    assert lanes[True].info["strategies"] == lanes[False].info["strategies"] \
        == [(newton.WARM_FLOW_WEIGHT, "warm")]
    assert lanes[True].info["newton_iterations"] == lanes[False].info["newton_iterations"]


def test_on_the_compiled_lane_every_strategy_comes_before_the_fallbacks(monkeypatch):
    """A gluey flow's step (328 rows, tests/solvers/data/README.md) whose first strategy stalls
    within STRATEGY_GAP of tol: on the compiled lane the next strategy converges, without
    Gauss-Seidel (whose rounds took 20 000 sweeps and 1.1 s on it, 30 times the time)."""
    with np.load(Path(__file__).parent / "data" / "gluey-90-step.npz") as data:
        problem = StepProblem.from_arrays(data)
        guess, shift = data["warm_start"], data["warm_shift"]
    assert AlartCurnier(problem.normalized()).compiled
    result = solve_coulomb(problem, "newton-ac", tol=1e-6, warm_start=guess, shift=shift)
    assert result.status == CONVERGED and "fallbacks" not in result.info
    assert result.info["strategies"] == [(newton.WARM_FLOW_WEIGHT, "warm"), (1e-3, "cold")]
    assert scaled_coulomb_error(problem, result.forces) <= 1e-6


def test_on_a_gluey_flow_step_zero_forces_come_before_the_fallbacks(monkeypatch):
    """On the sparse lane a strategy stalled within STRATEGY_GAP of tol sends a step to the
    fallbacks, but on a gluey flow's step from a warm start the first weight from zero forces
    comes first: on the stored 90-grain gluey step (the compiled lane switched off) the first
    strategy stalls within the gap and the one from zero forces converges. Where every strategy
    stalls within the gap (phases faked), a gluey step from a warm start tries those two; a cold
    one (no warm start) and a dry flow's step (the creeping bed) the first alone."""
    monkeypatch.setattr(newton, "COMPILED_LIMIT", 0)
    with np.load(Path(__file__).parent / "data" / "gluey-90-step.npz") as data:
        gluey = StepProblem.from_arrays(data)
        guess, shift = data["warm_start"], data["warm_shift"]
    phases, proximal = [], newton._proximal_newton

    def spied(*args, **kwargs):
        phases.append(proximal(*args, **kwargs))
        return phases[-1]

    monkeypatch.setattr(newton, "_proximal_newton", spied)
    result = solve_coulomb(gluey, "newton-ac", tol=1e-6, warm_start=guess, shift=shift, fallback=None)
    assert AlartCurnier(gluey.normalized()).gluey_flow and not AlartCurnier(gluey.normalized()).compiled
    assert phases[0].status == newton.STALLED and 1e-6 < phases[0].error <= STRATEGY_GAP * 1e-6
    assert result.info["strategies"] == [(newton.WARM_FLOW_WEIGHT, "warm"), (1e-3, "cold")]
    assert result.status == CONVERGED and scaled_coulomb_error(gluey, result.forces) <= 1e-6

    def stalled(function, unshifted, forces, tol, *args, **kwargs):
        return newton._Phase(forces=forces, status=newton.STALLED, iterations=1, error=2.0 * tol,
                             history=np.array([2.0 * tol]), gradient_steps=0)

    monkeypatch.setattr(newton, "_proximal_newton", stalled)
    with np.load(Path(__file__).parent / "data" / "creeping-bed-step.npz") as data:
        dry = StepProblem.from_arrays(data)
        dry_guess, dry_shift = data["warm_start"], data["warm_shift"]
    assert AlartCurnier(dry.normalized()).flow_step and not AlartCurnier(dry.normalized()).gluey_flow
    tried = {name: solve_coulomb(problem, "newton-ac", tol=1e-6, warm_start=start, shift=offset,
                                 fallback=None).info["strategies"]
             for name, problem, start, offset in (("warm", gluey, guess, shift), ("cold", gluey, None, None),
                                                  ("dry", dry, dry_guess, dry_shift))}
    assert tried == {"warm": [(newton.WARM_FLOW_WEIGHT, "warm"), (1e-3, "cold")], "cold": [(1e-3, "cold")],
                     "dry": [(newton.WARM_FLOW_WEIGHT, "warm")]}


def test_on_the_compiled_lane_the_joint_phase_rescues_stalled_strategies():
    """A dry flow's step (654 rows, tests/solvers/data/README.md) on which every Newton strategy
    stalled and Gauss-Seidel's rounds took 8 000 sweeps (1.5 s, 30 times a usual step): with
    ``joint`` (a flow run's) the joint phase runs once the first weight has stalled from the
    warm start and from zero forces, and the first weight from its forces converges, without
    fallback."""
    with np.load(Path(__file__).parent / "data" / "dry-150-step.npz") as data:
        problem = StepProblem.from_arrays(data)
        guess, shift = data["warm_start"], data["warm_shift"]
    assert AlartCurnier(problem.normalized()).compiled and problem.cones.is_convex
    result = solve_coulomb(problem, "newton-ac", tol=1e-6, warm_start=guess, shift=shift, joint=5)
    assert result.status == CONVERGED and "fallbacks" not in result.info
    assert result.info["strategies"] == [(newton.WARM_FLOW_WEIGHT, "warm"), (1e-3, "cold"),
                                         (newton.WARM_FLOW_WEIGHT, "joint")]
    assert 0 < result.info["joint_iterations"] <= newton.JOINT_START_ITERATIONS
    assert scaled_coulomb_error(problem, result.forces) <= 1e-6


def test_newton_finishes_an_early_gauss_seidel_round_on_a_gluey_step(monkeypatch):
    """A gluey flow's step (931 rows, tests/solvers/data/README.md) whose first strategy stalls
    within STRATEGY_GAP of tol, and the one from zero forces after it (the sparse lane: on to the
    fallbacks): FALLBACK_POLISH_ITERATIONS
    Newton iterations finish Gauss-Seidel's fourth round (8 000 sweeps in all), where ten
    finished none and the rounds spent the whole cap (20 000 sweeps). The re-centred weight
    kept at the first weight (``UNION_RECENTRE_FOLLOWS`` off), as when the step was stored: with
    it following the error the strategies stall at another iterate, from which the rounds run to
    the cap (the step converges either way)."""
    monkeypatch.setattr(newton, "UNION_RECENTRE_FOLLOWS", False)
    with np.load(Path(__file__).parent / "data" / "gluey-250-step.npz") as data:
        problem = StepProblem.from_arrays(data)
        guess, shift = data["warm_start"], data["warm_shift"]
    assert not AlartCurnier(problem.normalized()).compiled
    result = solve_coulomb(problem, "newton-ac", tol=1e-6, warm_start=guess, shift=shift)
    assert result.status == CONVERGED and result.info["fallbacks"] == ["nsgs"]
    assert result.info["strategies"] == [(newton.WARM_FLOW_WEIGHT, "warm"), (1e-3, "cold")]
    assert result.info["fallback_iterations"] == sum(newton.fallback_rounds("nsgs")[:4]) == 8000
    assert scaled_coulomb_error(problem, result.forces) <= 1e-6


def test_a_reduced_block_rereads_from_w_only_the_rows_whose_columns_changed_their_fold(
        monkeypatch):
    """The sparse lane's reduced Newton blocks built from the last block's rows (_ReducedBlocks
    with W's factor) equal those built with no last block (every row read from W), entry for
    entry, with the same ``(W outer)[kept]``, along points of a gluey + friction flow step
    where a few contacts change state from one to the next, and as sigma changes (at one point
    alone: the last block's arrays, shared). With the last block's folded rows doubled, every
    row that reads a column of W whose fold changed (or that was not kept) is still right, and
    the rest come out doubled: they were taken from the last block, not read from W. (The rows
    are reused where the products go through W's factor: raised share.)"""
    monkeypatch.setattr(newton, "FACTOR_PRODUCT_SHARE", 1.0)
    function, start = gluey_flow_function()
    blocks = function.reduced_blocks
    assert blocks.hops[0].size
    pattern = function.W.tocsr(copy=True)
    pattern.data[:] = 1.0
    rng = np.random.default_rng(11)
    forces, sigma = start.copy(), 1e-3 * function.typical
    taken = reread = 0
    for _ in range(6):
        moved = rng.random(forces.size) < 0.02
        forces = np.where(moved, forces * (1 + rng.normal(size=forces.size)), forces)
        kept, target, factor, outer = reduced_block_fold(function, forces)
        fold = (kept, target, factor, sigma, outer)
        whole = newton._ReducedBlocks(function.w_arrays, function.rho,       # no last rows
                                      function.factor_arrays)
        expected, expected_outside = whole.block(*fold)
        last = blocks.last
        block, outside = blocks.block(*fold)
        assert same_csr(block, expected) and np.array_equal(outside, expected_outside)
        after = blocks.last
        blocks.last = (*last[:6], 2 * last[6])
        doubled, _ = blocks.block(*fold)
        blocks.last = after
        if last[0].size:
            changed = (after[0] != last[0]) | (factor != last[1])
            needed = (pattern[kept] @ changed > 0) | ~np.isin(kept, last[3])
            starts, ends = expected.indptr[:-1], expected.indptr[1:]
            right = np.array([np.array_equal(doubled.data[i:j], expected.data[i:j])
                              for i, j in zip(starts, ends)])
            assert right[needed].all() and np.array_equal(doubled.indices, expected.indices)
            for i, j in zip(starts[~right], ends[~right]):      # off the diagonal: exactly 2x
                assert np.array_equal(doubled.data[i + 1:j], 2 * expected.data[i + 1:j])
            taken += np.count_nonzero(~right)
            reread += np.count_nonzero(right)
        sigma *= 0.5
    assert taken > 0 and reread > 0
    # the same point at another weight: no row read from W, F's arrays the last ones
    last = blocks.last
    block, _ = blocks.block(*fold[:3], 3 * sigma, outer)
    whole = newton._ReducedBlocks(function.w_arrays, function.rho, function.factor_arrays)
    assert same_csr(block, whole.block(*fold[:3], 3 * sigma, outer)[0])
    assert blocks.last[6] is last[6] and blocks.last[5] is last[5]


@pytest.mark.parametrize("share", [0.0, 1.0])
def test_a_reduced_block_is_w_folded_on_its_kept_rows_scaled_by_rho(share, monkeypatch):
    """The sparse lane's reduced Newton block is ``rho_i (W_ij factor_j + sigma delta)`` summed
    into column ``target_j``, read whole (share 0) or from the last block's rows (share 1), at
    points where contacts change state: on the gluey flow's step in physical units, where rho
    is far from 1 (on a normalised problem it is about 1)."""
    monkeypatch.setattr(newton, "FACTOR_PRODUCT_SHARE", share)
    with np.load(Path(__file__).parents[1] / "flow" / "data" / "gluey-flow-step.npz") as data:
        problem = StepProblem.from_arrays(data)
        start = data["warm_start"]
    function = AlartCurnier(problem)
    assert function.compiled_rows and (function.factor_arrays is not None) == (share == 1.0)
    assert np.abs(np.log10(function.rho)).min() > 1
    W = function.W.toarray()
    rng = np.random.default_rng(2)
    sigma = 1e-3 * function.typical
    for scale in (0.0, 0.01, 0.02):
        forces = start * (1 + scale * rng.normal(size=start.size))
        kept, target, factor, outer = reduced_block_fold(function, forces)
        block, _ = function.reduced_blocks.block(kept, target, factor, sigma, outer)
        expected = np.zeros((kept.size, kept.size + 1))
        for a, i in enumerate(kept):
            np.add.at(expected[a], target, W[i] * factor)
            expected[a, a] += sigma
        expected = function.rho[kept, None] * expected[:, :-1]
        assert np.abs(block.toarray() - expected).max() <= 1e-13 * np.abs(expected).max()


@pytest.mark.parametrize("share", [None, 1.0])
def test_a_reduced_right_hand_side_reads_the_kept_rows_of_w_or_of_its_factor(share, monkeypatch):
    """The sparse lane's reduced Newton system's right-hand side, ``-phi - rho W outer`` on the
    kept rows, from W's rows, or through its factor where the products go through it
    (FACTOR_PRODUCT_SHARE raised), to rounding."""
    if share is not None:
        monkeypatch.setattr(newton, "FACTOR_PRODUCT_SHARE", share)
    function, start = gluey_flow_function()
    assert (function.factor_arrays is not None) == (share is not None)
    kept, _, _, outer = reduced_block_fold(function, start)
    phi, y, _ = function.residual(start)
    expected = -phi[kept] - function.rho[kept] * (function.W @ outer)[kept]
    assert np.abs(outer).max() > 0 and kept.size
    rhs = function.reduced_system(y, phi)[2]
    assert np.abs(rhs - expected).max() <= 1e-13 * np.abs(expected).max()


@pytest.mark.parametrize("name", COMPILED_CASES)
@pytest.mark.parametrize("start", ["cold", "perturbed"])
def test_the_compiled_newton_phase_takes_the_numpy_phase_steps(name, start):
    """The compiled phase and the numpy one (``compiled`` off) from the same start: the same
    iterations, steepest-descent steps, status and errors, and the same velocities to round-off
    (the compiled phase factorises the Newton system without its sliding rows, the numpy one the
    whole active block with LAPACK).

    On the hyperstatic hexagonal packing, whose regularised Newton systems are ill-conditioned,
    the two solves' rounding decides the last steps: the iterates agree while the error is above
    1e-6, then the numpy phase's path depends on the BLAS kernels. From zero forces it took 17
    iterations in 5 proximal steps like the compiled phase with OpenBLAS's AVX2 kernels
    (velocities 8e-12 apart) and 18 in 6 with its AVX-512 ones (1.1e-9 apart: two answers below
    ``tol``, whose forces are not unique there). There the counts may differ by one, and the
    velocities by 1e-8."""
    problem = load_cases()[name].problem.normalized()
    unshifted = problem.with_shift(np.zeros(problem.cones.count))
    forces = np.zeros(problem.n_rows)
    if start == "perturbed":
        exact = solve_coulomb(problem, "newton-ac", tol=1e-12).forces / problem.scaling.force
        forces = exact * (1 + 0.3 * np.random.default_rng(0).normal(size=exact.size))
    mine, theirs = compiled_and_numpy(
        problem, lambda function, unshifted: _proximal_newton(function, unshifted, forces, 1e-10,
                                                              200, 1e-3))
    assert mine.status == theirs.status == CONVERGED
    steps, expected_steps = ((phase.iterations, phase.gradient_steps, phase.proximal_steps)
                             for phase in (mine, theirs))
    if name == "hex_box_lid_friction":
        assert max(abs(a - b) for a, b in zip(steps, expected_steps)) <= 1
        above = np.flatnonzero(theirs.history < 1e-6)[0]
        assert above >= 10 and np.allclose(mine.history[:above], theirs.history[:above], rtol=1e-6)
        rounding = 1e-8                                 # measured: 8e-12 and 1.1e-9 (docstring)
    else:
        assert steps == expected_steps
        rounding = 1e-12                                # measured: 1e-14
        assert np.allclose(mine.history, theirs.history, rtol=1e-6, atol=rounding * theirs.history[0])
    velocity, expected = unshifted.gradient(mine.forces), unshifted.gradient(theirs.forces)
    assert np.abs(velocity - expected).max() <= rounding * max(np.abs(expected).max(), 1.0)


@pytest.mark.parametrize("name", ["mu_ten", "gamma_states_gluey_coulomb"])
def test_the_compiled_phase_takes_the_same_steepest_descent_steps(name, monkeypatch):
    """Without regularisations to try, a singular or failed Newton system leaves the steepest
    descent direction ``-J^T phi``: with none at all, every step of both phases is one, the same."""
    problem = load_cases()[name].problem.normalized()
    monkeypatch.setattr(newton, "REGULARISATIONS", np.zeros(0))
    cold = np.zeros(problem.n_rows)
    mine, theirs = compiled_and_numpy(
        problem, lambda function, unshifted: newton._newton_phase(function, unshifted, cold, 1e-10, 30))
    assert mine.gradient_steps == theirs.gradient_steps == mine.iterations == theirs.iterations > 0
    assert mine.status == theirs.status
    assert np.allclose(mine.history, theirs.history, rtol=1e-8, atol=1e-15)
    assert np.abs(mine.last - theirs.last).max() <= 1e-9 * max(np.abs(theirs.last).max(), 1.0)


def test_a_failed_compiled_phase_reports_the_errors_of_its_iterates_only(monkeypatch):
    """Without halvings the first line search fails: both phases stop ``failed`` after one
    iteration with the start's error alone in their history (the compiled one returned an
    unwritten entry as well, which the stall rule then read as an error)."""
    problem = load_cases()["mu_ten"].problem.normalized()
    monkeypatch.setattr(newton, "MAX_HALVINGS", 0)
    cold = np.zeros(problem.n_rows)
    mine, theirs = compiled_and_numpy(
        problem, lambda function, unshifted: newton._newton_phase(function, unshifted, cold, 1e-10, 10))
    assert mine.status == theirs.status == newton.FAILED
    assert mine.iterations == theirs.iterations == 1
    assert mine.history.size == theirs.history.size == 1
    assert mine.history[0] == pytest.approx(theirs.history[0], rel=1e-12)


def test_the_compiled_strategies_take_the_numpy_steps_where_newton_fails():
    """An infeasible glued contact (a singular ``W``): the first weight's proximal phase stalls
    near 0.995 after 60 iterations, then plain Newton's line searches fail and steepest-descent
    steps follow. The compiled phases try the same strategies to the same best error, and never
    report an error they did not compute. Their iterates agree for the first 73; after, the
    singular block's elimination picks the null-space component (``_block_solve``): the numpy
    phase's LAPACK LU rounds as the CPU's kernels do (with AVX-512 its plain Newton stalls after
    60 iterations without a gradient step, with AVX2 it takes 174), so only the compiled phase's
    count is pinned."""
    problem = load_cases()["glued_infeasible"].problem.normalized()
    cold = np.zeros(problem.n_rows)
    mine, theirs = compiled_and_numpy(
        problem, lambda function, unshifted: newton._strategies(function, unshifted, cold, 1e-8, 200))
    assert mine.gradient_steps > 100 and mine.iterations == 200
    assert mine.status == theirs.status != CONVERGED
    assert mine.strategies[:2] == theirs.strategies[:2] == [(1e-3, "cold"), (0.0, "cold")]
    assert mine.error == mine.history.min() == pytest.approx(theirs.error, rel=1e-9)
    assert theirs.error == theirs.history.min()
    assert np.allclose(mine.history[:73], theirs.history[:73], rtol=1e-9, atol=0)


def test_an_active_block_met_again_is_solved_with_its_kept_factors():
    """The sparse lane keeps the factors of the last two active blocks: a block equal entry for
    entry to one of them is not factorised again and gives the same direction, bit for bit; a
    block that differs in one entry, or a third block, is factorised."""
    rng = np.random.default_rng(3)
    n = newton.DENSE_LIMIT + 50                    # above the dense limit: SuperLU
    def rows_of_J(seed):
        extra = sp.random(n, n, density=0.01, random_state=seed, format="csr")
        return (sp.identity(n, format="csr") * 4.0 + extra).tocsr()
    active, phi = np.ones(n, dtype=bool), rng.normal(size=n)
    first, second = rows_of_J(1), rows_of_J(2)
    kept = factorisations.Factorisations()
    fresh = newton._newton_direction(first, active, phi)
    assert np.array_equal(newton._newton_direction(first, active, phi, kept), fresh)
    newton._newton_direction(second, active, phi, kept)
    assert kept.reused == 0
    again = newton._newton_direction(first.copy(), active, phi, kept)   # A, B, A: the cycle
    assert kept.reused == 1 and np.array_equal(again, fresh)
    changed = first.copy()
    changed.data[0] += 1e-12
    newton._newton_direction(changed, active, phi, kept)
    assert kept.reused == 1
    newton._newton_direction(second, active, phi, kept)    # pushed out by A, then the changed A
    assert kept.reused == 1


def test_an_active_block_with_few_new_rows_is_factorised_in_the_carried_order():
    """A block whose rows are all but NEW_ROWS_LIMIT of them rows of the last block SuperLU
    ordered is factorised in that block's elimination order (no ordering of its own): the same
    direction as a block ordered afresh, the same fill where no row is new, its factors reused
    when the block comes again; a block with more new rows, or after a carried order whose fill
    grew past FILL_GROWTH, is ordered afresh."""
    side = 40                                     # a grid's pattern, symmetric like W's
    n = side * side
    grid = sp.diags([np.ones(n - 1), np.ones(n - side)], [1, side], shape=(n, n))
    rng = np.random.default_rng(5)
    values = (grid + grid.T).tocsr()
    values.data = rng.uniform(-1.0, 1.0, size=values.nnz)
    system = (values + 8.0 * sp.identity(n)).tocsr()
    phi = rng.normal(size=n)

    def direction(active, kept, matrix=system):
        return newton._newton_direction(matrix[np.flatnonzero(active)], active, phi, kept)

    def fill(kept):
        return kept.kept[0][1].nnz

    everything = np.ones(n, dtype=bool)
    kept = factorisations.Factorisations(carry=True)
    direction(everything, kept)
    ordered = fill(kept)
    direction(everything, kept, system + 1e-3 * sp.identity(n, format="csr"))   # no new row
    assert kept.carried == 1 and fill(kept) == ordered
    edge = everything.copy()
    edge[:n // 200] = False                      # 8 new rows, at the grid's edge
    kept = factorisations.Factorisations(carry=True)
    direction(edge, kept)
    carried = direction(everything, kept)
    assert kept.carried == 1 and kept.ordered_rows is not None
    fresh = direction(everything, factorisations.Factorisations(carry=True))
    assert np.allclose(carried, fresh, rtol=0, atol=1e-12 * np.abs(fresh).max())
    assert np.abs(system @ carried + phi).max() <= 1e-12 * np.abs(phi).max()
    assert np.array_equal(direction(everything, kept), carried) and kept.reused == 1
    scattered = everything.copy()                # as many new rows as the limit lets in, inside
    scattered[rng.choice(n, size=int(factorisations.NEW_ROWS_LIMIT * n), replace=False)] = False
    kept = factorisations.Factorisations(carry=True)
    direction(scattered, kept)
    direction(everything, kept)
    assert kept.carried == 1 and kept.ordered_rows is None           # the next is ordered afresh
    kept = factorisations.Factorisations(carry=True)
    direction(np.arange(n) >= n // 4, kept)
    direction(everything, kept)                                      # a quarter of the rows new
    assert kept.carried == 0 and kept.ordered_rows.size == n
    assert factorisations.Factorisations().carry is False


@pytest.mark.parametrize("hops", [0, 1, 3])
def test_the_neighbourhood_of_some_rows_is_found_step_by_step_in_the_pattern(hops):
    """kernels.neighbourhood: the rows within ``hops`` steps of the seeds (repeated, unsorted),
    a step going from a row to the columns of its entries (a pattern not symmetric), sorted; as
    the products of the pattern's transpose with the reached rows find them."""
    from lubcontact.solvers import kernels as kernel
    from lubcontact.solvers.compiled_apgd import csr_arrays

    pattern = sp.random(300, 300, density=0.006, random_state=4, format="csr")
    pattern.data[:] = 1.0
    seeds = np.array([250, 3, 77, 3])
    reached = np.zeros(300, dtype=bool)
    reached[seeds] = True
    for _ in range(hops):
        reached |= pattern.T @ reached.astype(float) > 0
    rows = kernel.neighbourhood(*csr_arrays(pattern)[:2], seeds, hops)
    assert np.array_equal(rows, np.flatnonzero(reached))
    assert hops == 0 or rows.size > 3 * hops


@pytest.mark.parametrize("size", [1, 7, 300, 301, 5000])
def test_the_rows_of_largest_squares_are_those_a_full_sort_finds(size):
    """kernels.largest_squares: the LOCAL_ROWS rows (all of them below) whose squares are largest
    in a vector of both signs and magnitudes over nine decades, as a full sort of the squares
    finds them, and the share of the sum of squares they hold (to rounding); a zero vector's
    share is 1."""
    from lubcontact.solvers import kernels as kernel

    rng = np.random.default_rng(size)
    values = rng.standard_normal(size) * 10.0 ** rng.uniform(-6, 3, size)
    count = min(newton.LOCAL_ROWS, size)
    rows, share = kernel.largest_squares(values, count)
    squares = values**2
    expected = np.argsort(squares)[::-1][:count]
    assert np.array_equal(np.sort(rows), np.sort(expected))
    assert share == pytest.approx(squares[expected].sum() / squares.sum(), rel=1e-12)
    assert kernel.largest_squares(np.zeros(size), count)[1] == 1.0


@pytest.mark.parametrize("pattern", ["symmetric", "asymmetric", "forest"])
def test_the_static_lu_has_the_fill_of_symbolic_elimination_and_solves(pattern):
    """On a grid's pattern (random values, randomly ordered) the patterns of
    kernels.static_pattern are those of elimination without pivoting (row ``i`` reaches column
    ``j`` through every earlier pivot they share, done on booleans); the same on two grids and
    three isolated rows (an elimination forest: the tree is found as the columns are written);
    with a quarter of the entries above the diagonal dropped (a pattern not symmetric, as ``W``'s
    where a product came out exactly 0) they hold them (those of ``A + A^T``). Either way L U is
    the matrix to rounding and the solve's residual is at rounding; its norm (for the backward
    error) is ``|A|_inf``, as factorisations._permuted gives it. Through
    factorisations.StaticLU, which hands the kernels unsigned index arrays, as the Newton phases
    do."""
    def lattice(side):
        size = side * side
        return sp.diags([np.ones(size - 1), np.ones(size - side)], [1, side], shape=(size, size))
    grid = sp.block_diag([lattice(9)] + ([lattice(5), sp.csr_matrix((3, 3))] if pattern == "forest" else []))
    n = grid.shape[0]
    symmetric = pattern != "asymmetric"
    rng = np.random.default_rng(8)
    order = rng.permutation(n)
    dense = (grid + grid.T + sp.identity(n)).toarray()[order][:, order]
    dense = np.where(dense != 0, rng.uniform(-1.0, 1.0, size=(n, n)), 0.0) + 10.0 * np.eye(n)
    if not symmetric:
        upper = np.argwhere(np.triu(dense, 1) != 0)
        dropped = upper[rng.choice(len(upper), size=len(upper) // 4, replace=False)]
        dense[dropped[:, 0], dropped[:, 1]] = 0.0
    matrix = sp.csc_matrix(dense)
    factors = factorisations.StaticLU.factorise(                    # the same order
        *factorisations._permuted(matrix, np.arange(n)))
    lower_ptr, lower_idx, upper_ptr, upper_idx = factors.pattern
    assert lower_idx.dtype == upper_idx.dtype == np.uint32
    filled = dense != 0
    for k in range(n):                           # symbolic elimination, on booleans
        below = np.flatnonzero(filled[k + 1:, k]) + k + 1
        right = np.flatnonzero(filled[k, k + 1:]) + k + 1
        filled[np.ix_(below, right)] = True
    assert np.array_equal(lower_idx[lower_ptr[:-1]], np.arange(n))              # L's diagonal first
    assert all(np.all(np.diff(upper_idx[upper_ptr[j]:upper_ptr[j + 1]].astype(int)) > 0)
               and upper_idx[upper_ptr[j + 1] - 1] == j for j in range(n))     # U's sorted, diagonal last
    lower = sp.csc_matrix((np.ones(lower_idx.size), lower_idx, lower_ptr), shape=(n, n)).toarray() != 0
    upper = sp.csc_matrix((np.ones(upper_idx.size), upper_idx, upper_ptr), shape=(n, n)).toarray() != 0
    assert np.array_equal(lower, upper.T)
    if symmetric:
        assert np.array_equal(lower, np.tril(filled)) and np.array_equal(upper, np.triu(filled))
    else:
        assert np.all(lower >= np.tril(filled)) and np.all(upper >= np.triu(filled))
        assert np.any(np.tril(filled) != np.triu(filled).T)
    L = sp.csc_matrix((factors.lower, lower_idx, lower_ptr), shape=(n, n))
    U = sp.csc_matrix((factors.upper, upper_idx, upper_ptr), shape=(n, n))
    assert np.allclose((L @ U).toarray(), dense, rtol=0, atol=1e-13)
    rhs = rng.normal(size=n)
    solved = factors.solve(rhs)
    assert np.abs(matrix @ solved - rhs).max() <= 1e-13 * np.abs(rhs).max()
    assert factors.norm == pytest.approx(np.abs(dense).sum(axis=1).max(), rel=1e-14)


def test_the_static_lu_takes_a_pair_of_columns_in_one_pass():
    """A 6 x 6 grid's rows doubled, each row's twin next to it (as a contact's two rows ordered
    together), random values: kernels.static_pattern pairs the twins' columns (a supernode of two:
    below the second column, the first's rows are the second's, in the same order), and
    kernels.static_lu's factors with the pairs are those without them to rounding, L U = A."""
    from lubcontact.solvers import kernels

    line = sp.diags([1.0, 1.0, 1.0], [-1, 0, 1], shape=(6, 6))
    grid = sp.kron(line, sp.identity(6)) + sp.kron(sp.identity(6), line)
    pattern = sp.kron(grid, np.ones((2, 2))).toarray() != 0
    rng = np.random.default_rng(4)
    dense = np.where(pattern, rng.uniform(-1.0, 1.0, pattern.shape), 0.0) + 8.0 * np.eye(72)
    matrix = sp.csc_matrix(dense)
    indptr, indices, data = matrix.indptr, matrix.indices.astype(np.uint32), matrix.data
    lower_ptr, lower_idx, upper_ptr, upper_idx, paired = kernels.static_pattern(indptr, indices)
    assert paired[::2].all() and not paired[1::2].any()
    for k in range(0, 72, 2):
        first, second, end = lower_ptr[k], lower_ptr[k + 1], lower_ptr[k + 2]
        assert lower_idx[first + 1] == k + 1
        assert np.array_equal(lower_idx[first + 2:second], lower_idx[second + 1:end])
    pattern_arrays = (lower_ptr, lower_idx, upper_ptr, upper_idx)
    by_pairs = kernels.static_lu(indptr, indices, data, *pattern_arrays, paired)
    by_columns = kernels.static_lu(indptr, indices, data, *pattern_arrays, np.zeros(72, dtype=bool))
    assert by_pairs[2] == by_columns[2] == -1
    for got, wanted in zip(by_pairs[:2], by_columns[:2]):
        assert np.abs(got - wanted).max() <= 1e-14 * np.abs(wanted).max()
    lower = sp.csc_matrix((by_pairs[0], lower_idx, lower_ptr), shape=(72, 72)).toarray()
    upper = sp.csc_matrix((by_pairs[1], upper_idx, upper_ptr), shape=(72, 72)).toarray()
    assert np.abs(lower @ upper - dense).max() <= 1e-13 * np.abs(dense).max()


def test_a_small_block_is_solved_sparse_in_its_order_where_that_is_stable():
    """kernels.static_block_solve: a block given by its rows (CSR, kernels.compressed_rows of a
    dense one, as on the compiled lane) in a random order is solved to rounding; a zero pivot,
    or a tiny one whose solve misses the backward error bound (1e-12 in the corner: a backward
    error of about 1e-4), is no answer (ok False: LAPACK's LU then solves it); the tiny pivot's
    block in the other order is (rows and columns are permuted alike: a zero diagonal stays)."""
    from lubcontact.solvers.kernels import compressed_rows, static_block_solve

    rng = np.random.default_rng(12)
    n = 60
    dense = sp.random(n, n, density=0.08, random_state=3).toarray() + 4.0 * np.eye(n)
    indptr, indices, values = compressed_rows(dense)
    assert indptr.dtype == indices.dtype == np.uint32
    assert np.array_equal(sp.csr_matrix((values, indices, indptr), shape=(n, n)).toarray(), dense)
    rhs = rng.normal(size=n)
    bound = newton.STATIC_LU_BACKWARD_ERROR
    solved, ok = static_block_solve(indptr, indices, values, rhs, rng.permutation(n), bound)
    assert ok and np.abs(dense @ solved - rhs).max() <= 1e-14 * np.abs(dense).max() * np.abs(solved).max()
    swap = np.array([1, 0])
    for block, natural, swapped in (([[0.0, 1.0], [1.0, 0.0]], False, False),
                                    ([[1e-12, 1.0], [1.0, 1.0]], False, True),
                                    ([[4.0, 1.0], [1.0, 5.0]], True, True)):
        arrays = compressed_rows(np.array(block))
        for order, expected in ((np.arange(2), natural), (swap, swapped)):
            solved, ok = static_block_solve(*arrays, np.array([1.0, 2.0]), order, bound)
            assert ok == expected
            if ok:
                assert np.abs(np.array(block) @ solved - [1.0, 2.0]).max() <= 1e-15


def test_a_carried_block_without_a_stable_static_lu_is_factorised_by_superlu():
    """A carried block is factorised without pivoting (factorisations.StaticLU) where that is
    stable, also where its pattern is not symmetric; a zero pivot, or a tiny one whose solve
    misses STATIC_LU_BACKWARD_ERROR (1e-12 on a symmetric 2 x 2's diagonal: a backward error of
    1e-5), hands it to SuperLU, which pivots: the direction is then at rounding."""
    assert factorisations.StaticLU.factorise(sp.csc_matrix(np.array([[0.0, 1.0], [1.0, 0.0]])), 1.0) is None
    rows, rhs = np.arange(2), np.array([1.0, 1.0])
    kept = factorisations.Factorisations(carry=True)
    kept.solve(sp.csc_matrix(np.array([[2.0, 1.0], [1.0, 3.0]])), rhs, rows)      # ordered
    stable = sp.csc_matrix(np.array([[4.0, 1.0], [1.0, 5.0]]))
    kept.solve(stable, rhs, rows)
    assert kept.carried == 1 and kept.pivoted == 0 and isinstance(kept.kept[0][1], factorisations.StaticLU)
    tiny = sp.csc_matrix(np.array([[1e-12, 1.0], [1.0, 1e-12]]))
    static = factorisations.StaticLU.factorise(*factorisations._permuted(tiny, rows))
    assert static is not None and not static.accurate(static.solve(rhs), rhs)
    solved = kept.solve(tiny, rhs, rows)
    assert kept.carried == 2 and kept.pivoted == 1 and isinstance(kept.kept[0][1], spla.SuperLU)
    assert np.abs(tiny @ solved - rhs).max() <= 1e-15
    kept = factorisations.Factorisations(carry=True)
    kept.solve(sp.csc_matrix(np.array([[2.0, 0.0], [1.0, 3.0]])), rhs, rows)      # ordered
    lopsided = sp.csc_matrix(np.array([[4.0, 0.0], [1.0, 5.0]]))        # no mirror entry
    solved = kept.solve(lopsided, rhs, rows)
    assert kept.carried == 1 and isinstance(kept.kept[0][1], factorisations.StaticLU)
    assert np.abs(lopsided @ solved - rhs).max() <= 1e-15


def test_a_new_row_of_a_carried_order_goes_just_after_its_last_old_neighbour(monkeypatch):
    """On a path (each row coupled to the next) ordered backwards, a new row goes just after the
    last of its neighbours in the carried order, and a new row with no old neighbour at the end
    (the limit on new rows raised for this 13-row block)."""
    monkeypatch.setattr(factorisations, "NEW_ROWS_LIMIT", 0.5)
    n = 12
    path = sp.diags([np.ones(n - 1), 4.0 * np.ones(n), np.ones(n - 1)], [-1, 0, 1],
                    shape=(n, n), format="csc")
    isolated = sp.block_diag([path, sp.identity(1)], format="csc")      # row 12: no neighbour
    kept = factorisations.Factorisations(carry=True)
    kept.ordered_rows = np.array([0, 1, 2, 3, 5, 6, 7, 8, 9, 10, 11])   # rows 4 and 12 new
    kept.positions = np.array([10, 9, 8, 7, 6, 5, 4, 3, 2, 1, 0])      # eliminated backwards
    order = kept._carried_order(isolated, np.arange(n + 1))
    assert order is not None and order.size == n + 1
    place = np.empty(n + 1, dtype=int)
    place[order] = np.arange(n + 1)
    # row 4's old neighbours 3 and 5 sit at places 7 and 6: it goes just after row 3's
    assert place[3] + 1 == place[4] and place[12] == n


@pytest.mark.parametrize("seed", range(5))
def test_the_carried_order_is_a_stable_sort_of_the_places(seed):
    """kernels.carried_order's counting sort gives the stable sort of the places: an old row at
    its place in the ordered block, a new row half a place after its contact's other row where
    that one is old, else half a place after its last old neighbour, one with neither last, ties
    by row (on random symmetric patterns with rows kept, dropped and new, half the rows paired
    in contacts)."""
    from lubcontact.solvers.kernels import carried_order

    rng = np.random.default_rng(seed)
    pattern = sp.random(300, 300, density=0.01, random_state=seed, format="csc")
    pattern = (pattern + pattern.T + sp.identity(300)).tocsc()
    rows = np.sort(rng.choice(1000, size=300, replace=False))
    old = rng.random(300) < 0.9
    dropped = np.setdiff1d(rng.choice(1000, size=40, replace=False), rows)
    ordered_rows = np.sort(np.concatenate([rows[old], dropped]))
    positions = rng.permutation(ordered_rows.size)
    partner = np.where(np.arange(1000) < 500, np.arange(1000) ^ 1, -1)   # rows 2k and 2k + 1
    order, carried = carried_order(pattern.indptr, pattern.indices, rows, ordered_rows, positions,
                                   0.5 * rows.size, partner)
    place = np.full(rows.size, np.inf)
    place[old] = positions[np.searchsorted(ordered_rows, rows[old])]
    old_place = place.copy()
    after_partner = 0
    for a in np.flatnonzero(~old):
        other = partner[rows[a]]
        if other >= 0 and other in ordered_rows:
            place[a] = positions[np.searchsorted(ordered_rows, other)] + 0.5
            after_partner += 1
            continue
        neighbours = old_place[pattern.indices[pattern.indptr[a]:pattern.indptr[a + 1]]]
        if np.isfinite(neighbours).any():
            place[a] = neighbours[np.isfinite(neighbours)].max() + 0.5
    assert carried and np.array_equal(order, np.argsort(place, kind="stable"))
    assert after_partner > 0
    assert not carried_order(pattern.indptr, pattern.indices, rows, ordered_rows, positions,
                             0.05 * rows.size, partner)[1]     # about 30 new rows: not carried
    # a new row (1) whose one old neighbour (0) is first in the order, two (3, 4) with none;
    # with 4 paired with 2 (old, last): 4 goes after it
    small = sp.csc_matrix(np.array([[1, 1, 0, 0, 0], [1, 1, 0, 0, 0], [0, 0, 1, 0, 0],
                                    [0, 0, 0, 1, 0], [0, 0, 0, 0, 1]], dtype=float))
    for paired, expected in ((np.empty(0, dtype=np.int64), [0, 1, 2, 3, 4]),
                             (np.array([-1, -1, 4, -1, 2]), [0, 1, 2, 4, 3])):
        order, carried = carried_order(small.indptr, small.indices, np.arange(5),
                                       np.array([0, 2]), np.array([0, 1]), 5.0, paired)
        assert carried and np.array_equal(order, expected)


def test_on_the_sparse_lane_the_carried_orders_pair_each_friction_contacts_two_rows():
    """On the 2D sparse lane the factorisations know each friction contact's two rows (a new
    row goes after its contact's other row in a carried order); a dense problem's carry has no
    pairs."""
    function, _ = gluey_flow_function()
    assert function.compiled_rows and function.cone_n.size > 0
    partner = function.factorisations.partner
    assert np.array_equal(partner[function.cone_n], function.tangent_rows)
    assert np.array_equal(partner[function.tangent_rows], function.cone_n)
    paired = np.zeros(function.n_rows, dtype=bool)
    paired[function.cone_n] = paired[function.tangent_rows] = True
    assert np.all(partner[~paired] == -1) and paired.sum() < function.n_rows
    small = AlartCurnier(load_cases()["glued_infeasible"].problem.normalized())
    assert small.dense and small.factorisations.carry and small.factorisations.partner.size == 0


@pytest.mark.parametrize("form", ["csr", "csc"])
def test_a_block_permuted_for_its_carried_order_is_scipys_permutation_with_sorted_indices(form):
    """``_permuted`` gives ``matrix[order][:, order]`` in CSC form entry for entry, its indices
    sorted (so that SuperLU's call does not sort them again) and 32-bit (SuperLU's), and
    ``|matrix|_inf``, from a matrix by rows (a 2D block) or by columns, also one whose indices
    are not sorted."""
    matrix = sp.random(500, 500, density=0.02, random_state=6, format=form)
    rng = np.random.default_rng(6)
    order = rng.permutation(500)
    expected = matrix[order][:, order].tocsc()
    expected.sort_indices()
    for line in range(0, 500, 7):            # unsorted input indices give the same block
        start, end = matrix.indptr[line], matrix.indptr[line + 1]
        shuffle = start + rng.permutation(end - start)
        matrix.indices[start:end], matrix.data[start:end] = \
            matrix.indices[shuffle].copy(), matrix.data[shuffle].copy()
    permuted, norm = factorisations._permuted(matrix, order)
    assert sp.isspmatrix_csc(permuted)
    assert permuted.indices.dtype == permuted.indptr.dtype == np.int32
    for name in ("indptr", "indices", "data"):
        assert np.array_equal(getattr(permuted, name), getattr(expected, name))
    assert norm == pytest.approx(np.abs(matrix.toarray()).sum(axis=1).max(), rel=1e-14)


@pytest.fixture(scope="module")
def pile_at_rest():
    """The step after 184 steps of a 30-grain frictional settling pile (mu = 0.3), at rest:
    more sticking rows than degrees of freedom (hyperstatic), and the previous step's forces.
    At 184 steps SuperLU meets plain Newton's block singular, as the test below needs; which
    steps it does moves with the trajectory's rounding (at 160 before the compiled lane's
    sparse blocks, at 180 before the static LU by pairs of columns, not since: after 140-199
    steps it does at all but 12)."""
    from lubcontact import scenes
    from lubcontact.model.laws import Coulomb
    from lubcontact.sim.simulation import Simulation

    sim = Simulation(scenes.settling_pile(30, seed=3), Coulomb(0.3), 0.05, solver="newton-ac",
                     tol=1e-8, fixed_point=True, tol_fp=1e-6, on_failure="ignore")
    sim.run(184)
    _, _, problem, guess, _ = sim.next_problem()
    return problem, guess


def test_a_block_singular_by_its_count_of_sticking_rows_skips_the_failed_factorisation(
        pile_at_rest, monkeypatch):
    """At rest, plain Newton's active block has more rows of W than degrees of freedom: singular.
    The count says so (not with a proximal weight: rows of W + sigma I), and the direction
    is the regularised one without SuperLU first failing on the block (at 12 800 grains that
    failure took 1.8 s against 0.17 s for the factorisation); on the 2D sparse lane's reduced
    system too (AlartCurnier.newton_direction)."""
    problem, guess = pile_at_rest
    use_the_sparse_lane(monkeypatch)
    monkeypatch.setattr(newton, "RECENTRE_WINDOW", 0)   # an answer where SuperLU meets it singular
    answer = solve_coulomb(problem, "newton-ac", tol=1e-8, warm_start=guess)
    assert answer.status == CONVERGED
    scaled = problem.normalized()
    function = AlartCurnier(scaled)
    phi, y, _ = function.residual(answer.forces / scaled.scaling.force)
    J, active, plain = function.jacobian(y)
    assert function.singular_by_count(plain)
    assert function.rank_bound == problem.n_dof < plain <= active.sum()
    function.set_proximal(1e-3 * function.typical, answer.forces / scaled.scaling.force)
    assert not function.singular_by_count(plain)
    outcomes = []
    factorise = spla.splu

    def counted(matrix, **options):
        try:
            factors = factorise(matrix, **options)
        except RuntimeError:
            outcomes.append("singular")
            raise
        outcomes.append("factorised")
        return factors

    monkeypatch.setattr(factorisations.spla, "splu", counted)
    tried = newton._newton_direction(J, active, phi)
    assert outcomes == ["singular", "factorised"]
    outcomes.clear()
    assert np.array_equal(newton._newton_direction(J, active, phi, singular=True), tried)
    assert outcomes == ["factorised"]
    outcomes.clear()                    # the sparse lane's reduced system counts alike
    static = factorisations.StaticLU.factorise             # (in 2D its fresh blocks: the static LU)
    monkeypatch.setattr(factorisations.StaticLU, "factorise", classmethod(
        lambda cls, matrix, norm: outcomes.append("factorised") or static(matrix, norm)))
    function.set_proximal(0.0, answer.forces / scaled.scaling.force)
    direction = function.newton_direction(y, phi)
    assert outcomes == ["factorised"] and np.isfinite(direction).all()
    # the same regularised direction but for the sliding rows' shift (delta 1e-10 here): 9e-8
    assert np.abs(direction - tried).max() <= 1e-6 * np.abs(tried).max()


def test_no_polish_past_tol_where_the_block_is_singular_by_its_count(pile_at_rest, settling_step,
                                                                      monkeypatch):
    """Past tol, Newton iterations run for their quadratic convergence, which a singular block
    does not have: from the joint phase newton-ac polishes its answer to JOINT_FINISH tol on a
    moving pile (more iterations, a lower error), and not at rest (hyperstatic), where its answer
    is the one without the polish."""
    use_the_sparse_lane(monkeypatch)
    for (problem, guess), at_rest in ((pile_at_rest, True), ((settling_step[0], None), False)):
        joint = solve_coulomb(problem, "newton-ac", tol=1e-6, warm_start=guess, joint=5)
        with monkeypatch.context() as patch:
            patch.setattr(newton, "JOINT_FINISH", 1.0)
            unpolished = solve_coulomb(problem, "newton-ac", tol=1e-6, warm_start=guess, joint=5)
        assert joint.joint_iterations > 0
        assert joint.status == unpolished.status == CONVERGED
        scaled = problem.normalized()
        assert AlartCurnier(scaled).hyperstatic(unpolished.forces / scaled.scaling.force) == at_rest
        if at_rest:
            assert joint.info["newton_iterations"] == unpolished.info["newton_iterations"]
            np.testing.assert_array_equal(joint.forces, unpolished.forces)
        else:
            assert joint.info["newton_iterations"] > unpolished.info["newton_iterations"]
            assert joint.info["error"] <= newton.JOINT_FINISH * 1e-6 < unpolished.info["error"]


def test_the_compiled_lu_solves_like_numpy_and_reports_an_exactly_singular_block():
    """``kernels.lu_solve`` (LAPACK's gesv through numba's bindings, given the transpose) solves
    what ``np.linalg.solve`` solves, returns ok False on an exactly singular matrix instead of
    raising, and accepts an empty block."""
    from lubcontact.solvers.kernels import lu_solve

    rng = np.random.default_rng(5)
    for size in (1, 7, 60):
        matrix = rng.normal(size=(size, size)) + size * np.eye(size)
        rhs = rng.normal(size=size)
        solved, ok = lu_solve(np.ascontiguousarray(matrix.T), rhs)
        assert ok
        assert np.allclose(solved, np.linalg.solve(matrix, rhs), rtol=1e-12, atol=1e-12)
    singular = np.array([[1.0, 2.0], [2.0, 4.0]])
    assert not lu_solve(np.ascontiguousarray(singular.T), np.ones(2))[1]
    solved, ok = lu_solve(np.zeros((0, 0)), np.zeros(0))
    assert ok and solved.shape == (0,)


@pytest.mark.parametrize("sparse", [False, True])
def test_a_singular_active_block_is_regularised_alike_when_compiled(sparse):
    """Two equal rows and columns of ``W`` (box rows inside their bounds, no proximal weight)
    make the active block singular: the compiled direction takes the first regularisation that
    factorises, as _newton_direction does, and finds the same direction; with the block
    factorised by LAPACK's LU, and sparse without pivoting (``sparse``: W by rows, in its own
    order), whose solve of this ill-conditioned block (``W + 1e-10 I``) is held to the static
    LU's backward error instead (``STATIC_LU_BACKWARD_ERROR``; its direction is within 2e-16 of
    LAPACK's, relative, on this block, which a condition number near 3e11 does not promise)."""
    from lubcontact.solvers.kernels import compressed_rows, lu_solve, newton_direction_2d

    rng = np.random.default_rng(2)
    root = rng.normal(size=(4, 4))
    spread = np.array([[1, 0, 0, 0], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    # rows and columns 0 and 1 alike, and the largest in column 0: the LU pivots on row 0 first,
    # so row 1 cancels to exact zeros on every CPU (with another pivot first, the two rows are
    # updated alike only where the BLAS kernels round them alike: not with SSE/AVX kernels)
    W = spread @ (root @ root.T + np.diag([10.0, 1, 1, 1])) @ spread.T
    n = W.shape[0]
    phi, y = rng.normal(size=n), rng.normal(size=n)
    assert not lu_solve(np.ascontiguousarray(W.T), phi)[1]        # a zero pivot: singular
    no_cones = np.zeros(0, dtype=np.int64)
    w_arrays, places = (compressed_rows(W), np.arange(n)) if sparse else \
        ((np.zeros(0, dtype=np.uint32), np.zeros(0, dtype=np.uint32), np.zeros(0)), no_cones)
    direction, ok = newton_direction_2d(
        W, w_arrays, np.ones(n), np.full(n, -np.inf), np.full(n, np.inf), np.ones(n, dtype=bool),
        no_cones, no_cones, np.zeros(0), np.zeros(0, dtype=bool), 0.0, y, phi,
        np.array(newton.REGULARISATIONS), places, newton.STATIC_LU_BACKWARD_ERROR)
    expected = newton._newton_direction(W, np.ones(n, dtype=bool), phi)   # J = W here
    assert ok and expected is not None
    regularised = W + newton.REGULARISATIONS[1] * np.eye(n)
    scale = np.abs(regularised).sum(axis=1).max() * np.abs(direction).max() + np.abs(phi).max()
    assert np.abs(regularised @ direction + phi).max() <= newton.STATIC_LU_BACKWARD_ERROR * scale
    if not sparse:
        assert np.allclose(direction, expected, rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("name", COMPILED_CASES)
def test_the_reused_factorisations_count_the_polish_after_a_fallback(name, monkeypatch):
    """``info["reused_factorisations"]`` and ``info["carried_orderings"]`` count every reuse
    and carried order of the solve, the polishing Newton iterations after a fallback included
    (``newton_iterations`` counts those iterations)."""
    use_the_sparse_lane(monkeypatch)                       # with its kept LUs
    made = []
    init = factorisations.Factorisations.__init__
    monkeypatch.setattr(factorisations.Factorisations, "__init__",
                        lambda self, *args, **kwargs: (init(self, *args, **kwargs),
                                                       made.append(self))[0])
    problem = load_cases()[name].problem.normalized()
    out = newton_alart_curnier(problem, tol=1e-12, max_iter=2)     # runs out: a fallback, a polish
    assert out.info.get("fallbacks")
    assert out.info["reused_factorisations"] == made[-1].reused
    assert out.info["carried_orderings"] == made[-1].carried


@pytest.mark.parametrize("name", ["mu_ten", "dt_large_friction"])
def test_an_exact_solve_by_newton_ac_leaves_the_callers_problem_as_it_was(name):
    """newton-ac's exact-Coulomb solve of a problem without a shift caches nothing on the
    caller's problem (its later products would take the dense path, with other rounding)."""
    problem = StepProblem.from_arrays(load_cases()[name].problem.to_arrays())   # a fresh copy
    assert not problem.shift.any()
    forces = np.random.default_rng(0).normal(size=problem.n_rows)
    before, cached = problem.velocity(forces), set(problem.__dict__)
    solve_coulomb(problem, "newton-ac", tol=1e-10)
    assert set(problem.__dict__) - cached == set()
    assert np.array_equal(problem.velocity(forces), before)


# -- the joint phase before the Newton phases ----------------------------------------------------
def test_newton_after_the_joint_phase_matches_clarabel_in_fewer_newton_iterations(settling_step,
                                                                                   monkeypatch):
    """newton-ac's joint start on the sparse lane: the joint phase's forces start the Newton
    phases, which then only finish (newton-ac's test, the FCLIB error at tol, is unchanged)."""
    problem, reference = settling_step
    use_the_sparse_lane(monkeypatch)
    plain = solve_coulomb(problem, "newton-ac", tol=1e-9)
    joint = solve_coulomb(problem, "newton-ac", tol=1e-9, joint=5)
    assert plain.success and joint.success and plain.joint_iterations == 0
    assert joint.joint_iterations == joint.info["joint_iterations"] > 0
    assert joint.iterations == joint.joint_iterations + joint.info["newton_iterations"]
    assert joint.info["newton_iterations"] < plain.info["newton_iterations"]
    assert velocity_error(problem, joint.velocities, reference.velocities) <= 1e-8
    assert coulomb_error(problem.normalized(), joint.forces / joint.force_scale) <= 1e-9


def test_newtons_answer_from_the_joint_phase_is_taken_below_joint_finish_tol(settling_step,
                                                                            monkeypatch):
    """The joint phase stops just below tol, where the finish's plain Newton iterations may not
    lower the error (on developed dry flows): Newton then goes on to JOINT_FINISH tol (here the
    finish is switched off; without the rule the answer stays at 3.5e-8, above 1e-9)."""
    problem, reference = settling_step
    use_the_sparse_lane(monkeypatch)
    monkeypatch.setattr(newton, "FINISH_ITERATIONS", 0)
    result = solve_coulomb(problem, "newton-ac", tol=1e-6, joint=5)
    assert result.success and result.joint_iterations > 0
    assert coulomb_error(problem.normalized(), result.forces / result.force_scale) \
        <= newton.JOINT_FINISH * 1e-6
    assert velocity_error(problem, result.velocities, reference.velocities) <= 1e-8


def test_the_polish_to_joint_finish_tol_stops_at_its_target(settling_step, monkeypatch):
    """The polish after the joint phase goes to JOINT_FINISH tol and stops there: no plain
    finishing Newton phase after it (when the finish always ran two iterations, they took the
    answer on to round-off for 13 % of a 12 000-grain dry step; docs/records/benchmarks.md). The main
    phase's finish is switched off, as above, so that the polish runs."""
    problem, reference = settling_step
    use_the_sparse_lane(monkeypatch)
    monkeypatch.setattr(newton, "FINISH_ITERATIONS", 0)
    targets = []
    phase = newton._newton_phase

    def spy(function, unshifted, forces, tol, max_iter, inner_tol=0.0, **known):
        targets.append(tol)
        return phase(function, unshifted, forces, tol, max_iter, inner_tol, **known)

    monkeypatch.setattr(newton, "_newton_phase", spy)
    result = solve_coulomb(problem, "newton-ac", tol=1e-6, joint=5)
    polish = newton.JOINT_FINISH * 1e-6
    assert result.success and polish in targets
    assert newton.ROUND_OFF not in targets[targets.index(polish):]   # no plain finish after it
    assert coulomb_error(problem.normalized(), result.forces / result.force_scale) <= polish
    assert velocity_error(problem, result.velocities, reference.velocities) <= 1e-8


def plain_finishes(problem, lane, monkeypatch, **options):
    """``solve_coulomb(problem, "newton-ac", **options)`` on the ``lane`` ("compiled" or
    "sparse"), and the Newton phases of its plain finish (sigma 0, target ROUND_OFF)."""
    if lane == "sparse":
        use_the_sparse_lane(monkeypatch)
    finishes = []
    phase = newton._newton_phase

    def spy(function, unshifted, forces, tol, max_iter, inner_tol=0.0, **known):
        out = phase(function, unshifted, forces, tol, max_iter, inner_tol, **known)
        if function.sigma == 0.0 and tol == newton.ROUND_OFF:
            finishes.append(out)
        return out

    monkeypatch.setattr(newton, "_newton_phase", spy)
    return solve_coulomb(problem, "newton-ac", **options), finishes


@pytest.mark.parametrize("lane", ["compiled", "sparse"])
def test_a_plain_finish_follows_the_proximal_loop_only_without_friction_cones(settling_step, lane,
                                                                               monkeypatch):
    """With friction cones newton-ac's answer is its proximal loop's, at tol: no plain Newton phase
    to round-off after it (FINISH_ITERATIONS; on this step one took the answer there, but on the
    settling frictional piles of bench small such a phase lowered the error tenfold on 1-14 % of
    the solves, for a Newton iteration on every one). Without friction cones the Alart-Curnier
    function is piecewise linear, and from the loop's answer one plain step lands on the
    solution (the glued chain, from zero forces)."""
    problem, reference = settling_step
    result, finishes = plain_finishes(problem, lane, monkeypatch, tol=1e-6,
                                      warm_start=reference.forces * (1.0 + 1e-3))
    assert result.success and finishes == []
    error = coulomb_error(problem.normalized(), result.forces / result.force_scale)
    assert newton.ROUND_OFF < error <= 1e-6
    assert velocity_error(problem, result.velocities, reference.velocities) <= 1e-6
    chain = load_cases()["glued_chain_anchored"].problem
    result, finishes = plain_finishes(chain, lane, monkeypatch, tol=1e-8)
    assert result.success and [finish.iterations for finish in finishes] == [1]
    assert finishes[0].history[0] > newton.ROUND_OFF >= finishes[0].history[-1]
    assert coulomb_error(chain.normalized(), result.forces / result.force_scale) <= newton.ROUND_OFF


def test_the_plain_trys_finish_stops_after_an_iteration_that_gains_nothing(monkeypatch):
    """After the plain try, a second finishing iteration follows only a first that lowered the
    FCLIB error below FINISH_GAIN times its start's: from near the solution of the heavy-on-light
    stack the plain try takes it to 1.2e-12 in one iteration, the first of the finish leaves it
    at 1.8e-12 (its floor), and a second would factorise again for nothing."""
    stack = load_cases()["heavy_on_light_stack"].problem.normalized()
    near = plain_try_strategies(stack, np.zeros(stack.n_rows)).forces * (1.0 + 1e-3)
    finished = plain_try_strategies(stack, near)
    assert finished.status == CONVERGED and finished.strategies == [(0.0, "warm")]
    assert finished.iterations == 2 and newton.ROUND_OFF < finished.error <= 1e-11
    monkeypatch.setattr(newton, "FINISH_GAIN", 1.0)            # any iteration that does not lose
    assert plain_try_strategies(stack, near).iterations == 3


def plain_try_strategies(problem, warm_start, compiled=True):
    """:func:`newton._strategies` on the normalised ``problem`` from ``warm_start`` (scaled) at
    tol 1e-8, its Newton phases compiled or numpy."""
    unshifted = problem.with_shift(np.zeros(problem.n_contacts))
    function = AlartCurnier(problem)
    function.compiled = compiled
    return newton._strategies(function, unshifted, warm_start, 1e-8, 200)


def test_a_small_frictionless_problem_near_its_warm_start_is_solved_by_the_plain_try(
        settling_step, monkeypatch):
    """From a warm start near the solution of a small frictionless problem, plain Newton (the
    plain try, PLAIN_TRY) takes the answer to round-off in one iteration, where the proximal
    loop spends one iteration per weight (WARM_DENSE_WEIGHT, then a tenth of it, ..., then the
    finish); from a warm start already at tol, the finish takes it there. No plain try on the
    sparse lane, with friction cones, or where the block at the warm start is singular by its
    count (the jammed hexagonal box)."""
    original = load_cases()["glued_chain_anchored"].problem
    chain = original.normalized()
    solution = plain_try_strategies(chain, np.zeros(chain.n_rows)).forces
    near = solution * (1.0 + 1e-3)
    plain = plain_try_strategies(chain, near)
    assert plain.status == CONVERGED and plain.strategies == [(0.0, "warm")]
    assert plain.iterations == 1 and plain.error <= newton.ROUND_OFF
    function = AlartCurnier(chain)                     # a warm start already at tol: the finish
    loose = newton._strategies(function, chain.with_shift(np.zeros(chain.n_contacts)), near, 1e-2, 200)
    assert loose.history[0] <= 1e-2 and loose.strategies == [(0.0, "warm")]
    assert loose.iterations == 1 and loose.error <= newton.ROUND_OFF
    monkeypatch.setattr(newton, "PLAIN_TRY", 0)
    proximal = plain_try_strategies(chain, near)
    assert proximal.status == CONVERGED and proximal.strategies == [(newton.WARM_DENSE_WEIGHT, "warm")]
    assert proximal.iterations >= 3
    monkeypatch.undo()
    jammed = load_cases()["hex_box_jammed"].problem.normalized()
    assert AlartCurnier(jammed).singular_at(np.ones(jammed.n_rows))
    first = (newton.WARM_DENSE_WEIGHT, "warm")
    assert plain_try_strategies(jammed, np.ones(jammed.n_rows)).strategies[0] == first
    problem, reference = settling_step                     # friction cones
    frictional = solve_coulomb(problem, "newton-ac", tol=1e-6, warm_start=reference.forces * (1.0 + 1e-3))
    assert frictional.success and frictional.info["strategies"] == [(newton.WARM_DENSE_WEIGHT, "warm")]
    cold = plain_try_strategies(chain, np.zeros(chain.n_rows))
    assert cold.status == CONVERGED and cold.strategies[0] == (1e-3, "cold")
    stack = load_cases()["heavy_on_light_stack"].problem.normalized()    # max_iter too small
    unshifted = stack.with_shift(np.zeros(stack.n_contacts))
    tight = newton._strategies(AlartCurnier(stack), unshifted, np.random.default_rng(0).normal(
        size=stack.n_rows), 1e-8, 2 * newton.PLAIN_TRY)
    assert tight.status == CONVERGED and tight.strategies[0] == (newton.WARM_DENSE_WEIGHT, "warm")
    use_the_sparse_lane(monkeypatch)
    sparse = solve(original, "newton-ac", tol=1e-8, warm_start=near * chain.scaling.force)
    assert sparse.success and sparse.info["strategies"] == [(newton.WARM_FLOW_WEIGHT, "warm")]


def test_plain_newton_as_a_strategy_has_no_finish():
    """The mass-ratio sandwich stalls at weight 1e-3 and converges by plain Newton, the second
    strategy, in one iteration; its FCLIB error's floor is 7.6e-13, so a finish to round-off
    would spend an iteration for nothing (two before FINISH_GAIN)."""
    result = solve(load_cases()["mass_ratio_1e6_sandwich"].problem, "newton-ac", tol=1e-8)
    assert result.status == CONVERGED and result.info["strategies"] == [(1e-3, "cold"), (0.0, "cold")]
    assert result.iterations == 2 and result.info["error"] > newton.ROUND_OFF


def test_the_first_weight_from_a_warm_start_depends_on_the_size(settling_step, monkeypatch):
    """From a warm start the strategies begin at WARM_DENSE_WEIGHT on a small 2D problem (a small
    system's step) and at WARM_FLOW_WEIGHT on a larger one (a flow's step), then try
    STRATEGIES[0] from zero forces and the rest of STRATEGIES from the warm start, the first
    weight's place among them taken by STRATEGIES[0]: each start once. From zero forces they
    begin at STRATEGIES[0]."""
    problem, reference = settling_step
    scaled = problem.normalized()
    unshifted = scaled.with_shift(np.zeros(scaled.n_contacts))
    warm = reference.forces / scaled.scaling.force
    tried = []

    def stalled(function, unshifted, forces, tol, max_iter, sigma, finish=True):
        tried.append((sigma, "warm" if forces.any() else "cold"))
        return newton._Phase(forces=forces, status=newton.STALLED, iterations=1, error=1.0,
                             history=np.ones(2), gradient_steps=0)

    monkeypatch.setattr(newton, "_proximal_newton", stalled)
    dense = AlartCurnier(scaled)
    assert dense.planar and dense.small and not dense.flow_step
    newton._strategies(dense, unshifted, warm, 1e-8, 200)
    assert tried == [(newton.WARM_DENSE_WEIGHT, "warm"), (1e-3, "cold"), (0.0, "warm"), (1e-3, "warm")]
    tried.clear()
    newton._strategies(dense, unshifted, np.zeros_like(warm), 1e-8, 200)
    assert tried == [(sigma, "cold") for sigma in newton.STRATEGIES]
    tried.clear()
    use_the_sparse_lane(monkeypatch)
    sparse = AlartCurnier(scaled)
    assert sparse.flow_step
    newton._strategies(sparse, unshifted, warm, 1e-8, 200)
    assert tried == [(newton.WARM_FLOW_WEIGHT, "warm"), (1e-3, "cold"), (0.0, "warm"), (1e-4, "warm")]


def test_a_best_plain_try_short_of_tol_is_reported_stalled():
    """An infeasible glued contact from near Newton's best point: no phase reaches tol, and
    the plain try's iterate is the best. It stopped at its own cap, not the solve's
    ``max_iter``: the phase is stalled and the solve inaccurate, as before the plain try."""
    problem = load_cases()["glued_infeasible"].problem
    scaled = problem.normalized()
    best = plain_try_strategies(scaled, np.zeros(scaled.n_rows)).forces
    result = solve(problem, "newton-ac", tol=1e-8, max_iter=1000, fallback=None,
                   warm_start=best * (1.0 + 1e-3) * scaled.scaling.force)
    assert result.info["strategies"][0] == (0.0, "warm")
    assert result.status == INACCURATE and result.info["newton_status"] == newton.STALLED
    assert result.iterations < 1000


@pytest.mark.parametrize("compiled", [True, False])
def test_a_failed_plain_try_hands_over_to_the_strategies_from_the_warm_start(compiled, monkeypatch):
    """From a random warm start of the jammed hexagonal box, not singular by its count there,
    plain Newton does not converge in PLAIN_TRY iterations: the first strategy then starts from
    the warm start, not from the plain try's iterate, and takes the same iterations to the same
    answer as without the plain try (PLAIN_TRY iterations more in all), with the Newton phases
    compiled and in numpy."""
    jammed = load_cases()["hex_box_jammed"].problem.normalized()
    warm_start = np.random.default_rng(0).normal(size=jammed.n_rows)
    assert not AlartCurnier(jammed).singular_at(warm_start)
    tried, cap = plain_try_strategies(jammed, warm_start, compiled), newton.PLAIN_TRY
    monkeypatch.setattr(newton, "PLAIN_TRY", 0)
    untried = plain_try_strategies(jammed, warm_start, compiled)
    first = (newton.WARM_DENSE_WEIGHT, "warm")
    assert tried.strategies == [(0.0, "warm"), first] and untried.strategies == [first]
    assert tried.status == untried.status == CONVERGED
    assert tried.iterations == untried.iterations + cap > cap
    assert tried.error == untried.error <= 1e-8
    assert np.array_equal(tried.forces, untried.forces)


def test_a_joint_phase_worse_than_the_warm_start_does_not_start_newton(settling_step, monkeypatch):
    """From a solution the joint phase (which stops at tol on its own measure) ends farther
    from Coulomb's law than its start: the Newton phases start from the warm start itself."""
    problem, _ = settling_step
    use_the_sparse_lane(monkeypatch)
    solution = solve_coulomb(problem, "newton-ac", tol=1e-9).forces
    plain = solve_coulomb(problem, "newton-ac", tol=1e-9, warm_start=solution)
    joint = solve_coulomb(problem, "newton-ac", tol=1e-9, warm_start=solution, joint=5)
    assert joint.joint_iterations > 0
    assert joint.info["newton_iterations"] == plain.info["newton_iterations"]
    np.testing.assert_array_equal(joint.forces, plain.forces)


def test_the_compiled_lane_skips_the_joint_start(settling_step):
    """On the compiled lane (at most COMPILED_LIMIT rows) the Newton phases cost less than the
    APGD run."""
    problem, _ = settling_step
    plain = solve_coulomb(problem, "newton-ac", tol=1e-9)
    joint = solve_coulomb(problem, "newton-ac", tol=1e-9, joint=5)
    assert problem.n_rows <= newton.COMPILED_LIMIT and joint.joint_iterations == 0
    np.testing.assert_array_equal(joint.forces, plain.forces)


def test_the_joint_start_runs_only_above_the_compiled_lane(monkeypatch):
    """Siconos' 460-row granular step (2D, no UNION contact) is on the compiled lane, where the
    joint phase cost more than it saved on dry flows of 650-660 rows: it does not run first, and
    here the first strategy converges, so it does not run after stalled strategies either; on the
    sparse lane (its limit lowered) it runs first, as it did at this size before the compiled lane
    reached 700 rows. Both converge."""
    problem = siconos_test_problem("gfc2d_granularflowonwall_00230_00206.dat")
    assert newton.DENSE_LIMIT < problem.n_rows <= newton.COMPILED_LIMIT and problem.cones.is_convex
    compiled = solve_coulomb(problem, "newton-ac", tol=1e-8, joint=5)
    assert compiled.status == CONVERGED and compiled.joint_iterations == 0
    monkeypatch.setattr(newton, "COMPILED_LIMIT", 0)
    sparse = solve_coulomb(problem, "newton-ac", tol=1e-8, joint=5)
    assert sparse.status == CONVERGED and sparse.joint_iterations > 0


def test_a_native_coulomb_method_without_a_joint_option_is_not_given_one():
    """A run's default ``joint`` reaches every exact solve: a native Coulomb method without the
    option (Siconos' solvers) solves as without it."""
    problem = siconos_test_problem("FrictionContactProblem00237.dat")

    @register("native-without-joint-test", kind=FIRST_ORDER, cones=ALL_CONES, native_coulomb=True)
    def native(problem, *, tol, max_iter=None, warm_start=None):
        return newton_alart_curnier(problem, tol=tol, warm_start=warm_start)

    try:
        assert not has_joint_phase("native-without-joint-test")
        result = solve_coulomb(problem, "native-without-joint-test", tol=1e-8, joint=5)
    finally:
        unregister("native-without-joint-test")
    assert has_joint_phase("newton-ac") and has_joint_phase("apgd-jacobi")
    assert result.status == CONVERGED and result.joint_iterations == 0



def chained_and_not(problem, monkeypatch, **options):
    """newton-ac's exact Coulomb on ``problem`` with the proximal loop's solved subproblems
    chained in one compiled call, then one call per subproblem (CHAINED_SUBPROBLEMS): the two
    answers, and each chained call's subproblems and whether its last one was solved."""
    chains = []
    compiled_phase = newton._compiled_phase

    def recorded(*args, **kwargs):
        phase = compiled_phase(*args, **kwargs)
        if phase.chained is not None:
            chains.append((phase.chained.subproblems, phase.solved))
        return phase

    monkeypatch.setattr(newton, "_compiled_phase", recorded)
    answers = []
    for chained in (True, False):
        monkeypatch.setattr(newton, "CHAINED_SUBPROBLEMS", chained)
        answers.append(solve_coulomb(problem, "newton-ac", tol=1e-8, **options))
    mine, theirs = answers
    assert mine.status == theirs.status == CONVERGED
    assert np.array_equal(mine.forces, theirs.forces)
    assert mine.iterations == theirs.iterations
    assert mine.info["proximal_steps"] == theirs.info["proximal_steps"]
    assert np.array_equal(mine.residual_history, theirs.residual_history)
    return chains


def test_the_chained_subproblems_take_the_proximal_loops_own_steps(monkeypatch):
    """On the compiled lane the subproblems that follow a solved one run in the same compiled
    call (CHAINED_SUBPROBLEMS), centred and weighed as the proximal loop would: on warm-started
    steps of a settling frictional pile, the same forces to the bit, iterations and proximal
    steps as one call per subproblem, with calls that ran several."""
    from lubcontact import scenes
    from lubcontact.model.laws import Coulomb
    from lubcontact.sim.simulation import Simulation

    sim = Simulation(scenes.settling_pile(20, seed=1), Coulomb(0.3), 0.02, solver="newton-ac",
                     tol=1e-8, fixed_point=True, tol_fp=1e-6, on_failure="ignore")
    sim.run(40)
    chains = []
    for _ in range(8):
        _, _, problem, forces, shift = sim.next_problem()
        chains += chained_and_not(problem, monkeypatch, warm_start=forces, shift=shift)
        sim.step()
    assert max(count for count, _ in chains) >= 3


@pytest.mark.parametrize("name", ["hex_box_lid_friction", "mu_zero_friction"])
def test_a_chain_that_ends_on_a_subproblem_not_solved_is_weighed_from_its_centre(name, monkeypatch):
    """With one Newton iteration per subproblem (``INNER_CAP`` 1) some chains end on a subproblem
    not solved: the loop raises its weight from that subproblem's centre error, not the chain's
    first, and goes on from that subproblem's best iterate: the same steps as one call each."""
    monkeypatch.setattr(newton, "INNER_CAP", 1)
    chains = chained_and_not(load_cases()[name].problem, monkeypatch, tol_fp=1e-8)
    assert any(count > 1 and not solved for count, solved in chains)


@pytest.mark.parametrize("contacts", [0, 1, 2, 5, 6, 1001, 25000])
@pytest.mark.parametrize("tangent_dim", [1, 2])
def test_the_contact_steps_are_one_over_the_floored_diagonal_and_the_median_its_middle(
        contacts, tangent_dim):
    """kernels.contact_steps (compiled; the median by a partition): rho = 1 / max(W_nn, 1e-12 of
    the largest) on each contact's rows, its tangential rows after the normal ones, and the median
    of W_nn as the middle of the sorted values (the mean of the two middle ones for an even
    count; 1 without contacts), exactly."""
    from lubcontact.solvers.compiled_modules import kernels

    rng = np.random.default_rng(contacts)
    diagonal = rng.random(contacts)
    diagonal[: min(3, contacts // 2)] = 0.0                 # floored rows
    tangential = np.arange(contacts, dtype=np.int64)[::2]
    rho, typical = kernels().contact_steps(diagonal, tangential, tangent_dim)
    floored = 1.0 / np.maximum(diagonal, 1e-12 * (diagonal.max() if contacts and diagonal.max() > 0
                                                  else 1.0))
    assert np.array_equal(rho, np.concatenate([floored, np.repeat(floored[tangential], tangent_dim)]))
    ordered, middle = np.sort(diagonal), contacts // 2
    assert typical == (1.0 if contacts == 0 else ordered[middle] if contacts % 2
                       else 0.5 * (ordered[middle - 1] + ordered[middle]))
