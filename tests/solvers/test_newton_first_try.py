"""newton-ac's first try on small 2D exact-Coulomb steps (lubcontact.solvers.newton_first_try)."""
from dataclasses import replace

import numpy as np
import pytest

from lubcontact import scenes
from lubcontact.bench.hard import load_cases
from lubcontact.model.laws import Coulomb, GlueyCoulomb
from lubcontact.problem.cones import ConeKind
from lubcontact.sim.simulation import Simulation
from lubcontact.solvers import (
    CONVERGED,
    MAX_ITER,
    newton,
    register_first_try,
    registry,
    solve_coulomb,
    solver_info,
)
from lubcontact.solvers.coulomb import solve_native_coulomb
from lubcontact.solvers.newton_first_try import first_try


@pytest.fixture
def counted_first_try(monkeypatch):
    """newton-ac with its first try counted: a list of what each call returned, None or the
    normalised problem and output (cleared by the tests once their steps are built)."""
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


def same_answers(mine, theirs, status=CONVERGED):
    """The first try's result is the general path's, every field but the timings to the bit (its
    status ``status`` unless None)."""
    assert status is None or mine.status == status
    for name, expected in vars(theirs).items():
        if name not in ("setup_time", "solve_time"):
            got = getattr(mine, name)
            assert np.array_equal(got, expected) if isinstance(expected, np.ndarray) \
                else got == expected, name


def answered(answers):
    return sum(answer is not None for answer in answers)


@pytest.mark.parametrize("grains, settled, law", [(4, 30, None), (10, 30, None), (20, 30, None),
                                                  (40, 150, None),
                                                  (10, 30, GlueyCoulomb(0.3, gamma_min=-0.01))])
def test_the_first_try_gives_the_general_paths_answer_on_a_settling_pile(grains, settled, law,
                                                                         counted_first_try,
                                                                         monkeypatch):
    """On warm-started steps of settling frictional piles (6-66 contacts, the 40-grain pile's
    steps over 96 rows: the blocks factorised in a minimum-degree order; the gluey one with 2-5
    UNION contacts at the floor of their glue) the first try answers every step, with the general
    path's answer."""
    steps = settling_steps(grains, settled, 12, law)
    counted_first_try.clear()
    if law is not None:
        assert all(np.any(problem.cones.kinds == ConeKind.UNION) for problem, _, _ in steps)
    if grains == 40:
        assert min(problem.n_rows for problem, _, _ in steps) >= newton.STATIC_DENSE_ROWS
    for problem, forces, shift in steps:
        mine = solve_coulomb(problem, "newton-ac", tol=1e-8, warm_start=forces, shift=shift)
        theirs = without_first_try(problem, monkeypatch, tol=1e-8, warm_start=forces, shift=shift)
        same_answers(mine, theirs)
    assert answered(counted_first_try) == len(counted_first_try) == len(steps)


@pytest.mark.parametrize("options", [dict(tol=1e-12, max_iter=1, fallback=None),
                                     dict(tol=1e-12, max_iter=3), dict(tol=1e-12, joint=5),
                                     dict(tol=1e-12, fallback=None)])
def test_solves_cut_short_or_with_options_are_the_general_paths_too(options, counted_first_try,
                                                                    monkeypatch):
    """From a warm start 10 % off, with one or three Newton iterations allowed (``max_iter``
    then, or the fallbacks' answer), the joint phase asked for or no fallback: the first try
    answers, with the general path's answer."""
    problem, forces, shift = settling_steps(10, 30, 1)[0]
    counted_first_try.clear()
    mine = solve_coulomb(problem, "newton-ac", warm_start=0.9 * forces, shift=shift, **options)
    theirs = without_first_try(problem, monkeypatch, warm_start=0.9 * forces, shift=shift,
                               **options)
    assert answered(counted_first_try) == 1
    same_answers(mine, theirs, status=MAX_ITER if options.get("max_iter") == 1 else None)


def test_no_first_try_on_a_problem_already_normalised(counted_first_try):
    problem, forces, _ = settling_steps(4, 30, 1)[0]
    scaled = problem.normalized()
    counted_first_try.clear()
    result = solve_coulomb(scaled, "newton-ac", tol=1e-8, warm_start=forces / scaled.scaling.force)
    assert result.status == CONVERGED and counted_first_try == [None]


def test_union_contacts_pulled_and_pushed_are_checked_on_the_piece_of_their_force(
        counted_first_try, monkeypatch):
    """A gluey + friction problem whose UNION contacts end on both pieces, warm-started 10 % off
    its answer: the first try answers, with the general path's answer, pulled contacts included."""
    problem = load_cases()["gamma_states_gluey_coulomb"].problem
    warm = 0.9 * without_first_try(problem, monkeypatch, tol=1e-10).forces
    mine = solve_coulomb(problem, "newton-ac", tol=1e-10, warm_start=warm)
    theirs = without_first_try(problem, monkeypatch, tol=1e-10, warm_start=warm)
    assert answered(counted_first_try) == 1
    same_answers(mine, theirs)
    union = problem.cones.kinds == ConeKind.UNION
    assert mine.pulled.size and np.any(union & ~problem.cones.pulled(mine.forces))


def test_a_shift_moving_obstacles_and_a_warm_start_already_within_tol(counted_first_try,
                                                                      monkeypatch):
    """A problem with its own shift (which exact Coulomb ignores) and moving obstacles' offset,
    from a warm start 10 % off and from its own answer (no Newton iteration): the first try
    answers, with the general path's answer."""
    problem, forces, _ = settling_steps(10, 30, 1)[0]
    rng = np.random.default_rng(3)
    moved = replace(problem, shift=rng.uniform(0.0, 1e-3, problem.n_contacts),
                    obstacle_offset=rng.uniform(-1e-4, 1e-4, problem.n_rows))
    answer = without_first_try(moved, monkeypatch, tol=1e-8, warm_start=forces).forces
    counted_first_try.clear()
    for warm in (0.9 * answer, answer):
        mine = solve_coulomb(moved, "newton-ac", tol=1e-8, warm_start=warm)
        same_answers(mine, without_first_try(moved, monkeypatch, tol=1e-8, warm_start=warm))
    assert answered(counted_first_try) == 2 and mine.iterations == 0


def test_no_first_try_on_3d_cones(counted_first_try):
    problem = load_cases()["tetrahedron_3d_friction"].problem
    warm = solve_coulomb(problem, "newton-ac", tol=1e-8).forces
    result = solve_coulomb(problem, "newton-ac", tol=1e-8, warm_start=warm)
    assert result.status == CONVERGED
    assert counted_first_try == [None, None]


def test_no_first_try_without_a_warm_start(counted_first_try):
    problem, _, _ = settling_steps(4, 30, 1)[0]
    counted_first_try.clear()
    assert solve_coulomb(problem, "newton-ac", tol=1e-8).status == CONVERGED
    assert counted_first_try == [None]


def test_an_option_the_method_does_not_take_is_refused_by_its_call(counted_first_try):
    problem, forces, _ = settling_steps(4, 30, 1)[0]
    counted_first_try.clear()
    with pytest.raises(TypeError, match="colour"):
        solve_coulomb(problem, "newton-ac", tol=1e-8, warm_start=forces, colour="red")
    assert counted_first_try == []


@pytest.mark.parametrize("option, value", [("fallback", "nope"), ("fallback", 3), ("joint", -1),
                                           ("joint", "x"), ("joint", 1.5)])
@pytest.mark.parametrize("first", [True, False])
def test_newton_ac_s_options_are_checked_with_or_without_the_first_try(option, value, first,
                                                                      monkeypatch):
    """A ``fallback`` that is not None, "auto" or a registered method, and a ``joint`` that is not
    an integer >= 0, are a ValueError naming the option, on a step the first try would answer and
    on the general path alike."""
    problem, forces, shift = settling_steps(4, 30, 1)[0]
    solve = solve_coulomb if first else lambda *args, **kwargs: without_first_try(
        *args[:1], monkeypatch, **kwargs)
    with pytest.raises(ValueError, match=option):
        solve(problem, "newton-ac", tol=1e-8, warm_start=forces, shift=shift, **{option: value})


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


@pytest.mark.parametrize("name, reason", [("apgd", "native_coulomb"), ("newton-ac", "already")])
def test_a_first_try_only_for_a_native_coulomb_method_without_one(name, reason):
    with pytest.raises(ValueError, match=reason):
        register_first_try(name)
