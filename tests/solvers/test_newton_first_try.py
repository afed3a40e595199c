"""newton-ac's first try on small 2D exact-Coulomb steps (lubcontact.solvers.newton_first_try)."""
from dataclasses import replace

import numpy as np
import pytest

from lubcontact import scenes
from lubcontact.bench.hard import load_cases
from lubcontact.model.laws import Coulomb, GlueyCoulomb
from lubcontact.problem.cones import ConeKind
from lubcontact.sim.simulation import Simulation
from lubcontact.solvers import CONVERGED, newton, registry, solve_coulomb, solver_info
from lubcontact.solvers.coulomb import solve_native_coulomb
from lubcontact.solvers.newton_first_try import first_try
from lubcontact.solvers.registry import register_first_try


@pytest.fixture
def counted_first_try(monkeypatch):
    """newton-ac with its first try counted: a list of what each call returned (cleared by the
    tests once their steps are built)."""
    answers = []

    def counted(*args, **kwargs):
        answers.append(first_try(*args, **kwargs))
        return answers[-1]

    monkeypatch.setitem(registry._REGISTRY, "newton-ac",
                        replace(solver_info("newton-ac"), first_try=counted))
    return answers


def without_first_try(problem, monkeypatch, **options):
    """The general path's exact-Coulomb solve of ``problem`` by newton-ac."""
    with monkeypatch.context() as patched:
        patched.setitem(registry._REGISTRY, "newton-ac",
                        replace(solver_info("newton-ac"), first_try=None))
        return solve_coulomb(problem, "newton-ac", **options)


def settling_steps(grains: int, settled: int, count: int, law=None):
    """``count`` warm-started steps of a settling frictional pile (``Coulomb(0.3)`` by default)
    after ``settled`` steps: (problem, warm start, shift) of each."""
    sim = Simulation(scenes.settling_pile(grains, seed=1), law or Coulomb(0.3), 0.02,
                     solver="newton-ac", tol=1e-8, fixed_point=True, tol_fp=1e-6, on_failure="ignore")
    sim.run(settled)
    steps = []
    for _ in range(count):
        _, _, problem, forces, shift = sim.next_problem()
        steps.append((problem, forces, shift))
        sim.step()
    return steps


def same_answers(mine, theirs):
    """Whether the first try's result is the general path's: forces, velocities, shift, record,
    pulled contacts to the bit, the residual to rounding."""
    assert mine.status == theirs.status == CONVERGED
    assert np.array_equal(mine.forces, theirs.forces)
    assert np.array_equal(mine.velocities, theirs.velocities)
    assert np.array_equal(mine.shift, theirs.shift)
    assert np.array_equal(mine.residual_history, theirs.residual_history)
    assert np.array_equal(mine.pulled, theirs.pulled)
    assert mine.iterations == theirs.iterations and mine.info == theirs.info
    assert (mine.outer_iterations, mine.fixed_point_converged, mine.joint_iterations,
            mine.branch_flips) == (theirs.outer_iterations, theirs.fixed_point_converged,
                                   theirs.joint_iterations, theirs.branch_flips)
    assert abs(mine.residual - theirs.residual) <= 1e-13 * (1.0 + theirs.residual)
    assert (mine.force_scale, mine.length_scale) == (theirs.force_scale, theirs.length_scale)


@pytest.mark.parametrize("grains, law", [(4, None), (10, None), (20, None),
                                         (10, GlueyCoulomb(0.3, gamma_min=-0.01))])
def test_the_first_try_gives_the_general_paths_answer_on_a_settling_pile(grains, law,
                                                                         counted_first_try,
                                                                         monkeypatch):
    """On warm-started steps of settling frictional piles (6-40 contacts; the gluey one with 2-5
    UNION contacts at the floor of their glue) the first try answers nearly every step, with the
    general path's answer (:func:`same_answers`)."""
    steps = settling_steps(grains, 30, 12, law)
    if law is not None:
        assert all(np.any(problem.cones.kinds == ConeKind.UNION) for problem, _, _ in steps)
    counted_first_try.clear()
    for problem, forces, shift in steps:
        mine = solve_coulomb(problem, "newton-ac", tol=1e-8, warm_start=forces, shift=shift)
        theirs = without_first_try(problem, monkeypatch, tol=1e-8, warm_start=forces, shift=shift)
        same_answers(mine, theirs)
    answered = sum(answer is not None for answer in counted_first_try)
    assert len(counted_first_try) == len(steps) and answered >= len(steps) - 1


def test_union_contacts_pulled_and_pushed_are_checked_on_the_piece_of_their_force(
        counted_first_try, monkeypatch):
    """A gluey + friction problem whose UNION contacts end on both pieces, warm-started 10 % off
    its answer: the first try answers, with the general path's answer, pulled contacts included."""
    case = load_cases()["gamma_states_gluey_coulomb"]
    problem = case.problem
    warm = 0.9 * without_first_try(problem, monkeypatch, tol=1e-10).forces
    mine = solve_coulomb(problem, "newton-ac", tol=1e-10, warm_start=warm)
    theirs = without_first_try(problem, monkeypatch, tol=1e-10, warm_start=warm)
    assert counted_first_try[-1] is mine
    same_answers(mine, theirs)
    union = problem.cones.kinds == ConeKind.UNION
    assert mine.pulled.size and np.any(union & ~problem.cones.pulled(mine.forces))


def test_no_first_try_on_3d_cones(counted_first_try):
    problem = load_cases()["tetrahedron_3d_friction"].problem
    warm = solve_coulomb(problem, "newton-ac", tol=1e-8).forces
    result = solve_coulomb(problem, "newton-ac", tol=1e-8, warm_start=warm)
    assert result.status == CONVERGED
    assert counted_first_try == [None, None]


def test_no_first_try_without_a_warm_start_or_with_zero_forces(counted_first_try):
    problem, _, _ = settling_steps(4, 30, 1)[0]
    counted_first_try.clear()
    for warm in (None, np.zeros(problem.n_rows)):
        assert solve_coulomb(problem, "newton-ac", tol=1e-8, warm_start=warm).status == CONVERGED
    assert counted_first_try == [None, None]


def test_a_first_call_that_does_not_converge_leaves_the_step_to_the_general_path(
        counted_first_try, monkeypatch):
    """With one Newton iteration allowed from a warm start 10 % off, the first call stops short
    of tol: the first try declines and the general path answers, as it does alone."""
    problem, forces, shift = settling_steps(10, 30, 1)[0]
    counted_first_try.clear()
    options = dict(tol=1e-12, warm_start=0.9 * forces, shift=shift, max_iter=1, fallback=None)
    result = solve_coulomb(problem, "newton-ac", **options)
    alone = without_first_try(problem, monkeypatch, **options)
    assert counted_first_try == [None]
    assert result.status == alone.status != CONVERGED
    assert np.array_equal(result.forces, alone.forces)


def test_no_first_try_where_the_general_path_does_not_chain_the_subproblems(counted_first_try,
                                                                           monkeypatch):
    problem, forces, shift = settling_steps(4, 30, 1)[0]
    counted_first_try.clear()
    monkeypatch.setattr(newton, "CHAINED_SUBPROBLEMS", False)
    assert solve_coulomb(problem, "newton-ac", tol=1e-8, warm_start=forces, shift=shift).status \
        == CONVERGED
    assert counted_first_try == [None]


@pytest.mark.parametrize("field, value", [("warm_start", "short"), ("tol", 0.0), ("max_outer", 0),
                                          ("max_iter", 0)])
def test_the_arguments_are_checked_before_the_first_try(field, value, counted_first_try):
    problem, forces, _ = settling_steps(4, 30, 1)[0]
    counted_first_try.clear()
    arguments = dict(tol=1e-8, warm_start=forces)
    arguments[field] = forces[:-1] if value == "short" else value
    with pytest.raises(ValueError, match=field):
        solve_native_coulomb(problem, "newton-ac", **arguments)
    assert counted_first_try == []


def test_a_first_try_is_only_for_a_method_that_solves_exact_coulomb_itself():
    with pytest.raises(ValueError, match="native_coulomb"):
        register_first_try("apgd")
