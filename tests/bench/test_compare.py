"""The comparison report: produced, sane numbers, reproducible (tiny sets, seconds)."""
import json

import numpy as np
import pytest

from lubcontact.bench import compare, problem_sets, runs, statistics
from lubcontact.solvers import STATUSES, methods
from lubcontact.solvers.siconos_peer import unregister_siconos


@pytest.fixture(autouse=True)
def _no_peer_left_registered():
    """compare registers the Siconos peer when installed: leave the registry as it was."""
    yield
    unregister_siconos()

PNG = b"\x89PNG\r\n\x1a\n"


def _solvers() -> list[str]:
    """The reference plus one other registered method (generic over the registry)."""
    others = [m for m in ("apgd", "pgd", "clarabel-primal") if m in methods()]
    return ["clarabel"] + others[:1]


def _run(tmp_path, name: str, tolerances=("1e-2", "1e-10"), repeats: int = 2) -> dict:
    argv = ["--set", name, "--solvers", *_solvers(), "--tolerances", *tolerances,
            "--repeats", str(repeats), "--out", str(tmp_path), "--quiet"]
    assert compare.main(argv) == 0
    return json.loads((tmp_path / name / "results.json").read_text())


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    out = tmp_path_factory.mktemp("compare")
    return out, _run(out, "tiny")


def test_report_files_and_header(tiny):
    out, data = tiny
    folder = out / "tiny"
    for figure in ("work_precision.png", "performance_profile.png", "iterations.png"):
        assert (folder / figure).read_bytes()[:8] == PNG
    report = (folder / "report.md").read_text()
    assert "lubcontact compare --set tiny" in report
    assert "## Headline" in report and "## Success rate per tolerance" in report
    assert data["meta"]["environment"]["packages"]["numpy"] != "absent"
    header = (folder / "results.csv").read_text().splitlines()[0].split(",")
    for column in ("setup_s", "solve_s", "iterations", "velocity_error", "fclib_error", "min_gap",
                   "status"):
        assert column in header


def test_reference_scores_zero_error_against_itself(tiny):
    _, data = tiny
    rows = [r for r in data["results"] if r["solver"] == "clarabel" and r["tol"] == 1e-10]
    assert len(rows) == len(data["instances"]) == 5
    for row in rows:
        assert row["velocity_error"] == 0.0
        assert row["success"] and row["status"] == "converged"


def test_numbers_are_sane(tiny):
    _, data = tiny
    rows = data["results"]
    assert {r["status"] for r in rows} <= set(STATUSES) | {"error", "skipped"}
    labels = data["meta"]["solvers"]
    for tol in data["meta"]["tolerances"]:
        summary = statistics.summary_rows([runs.Measurement(**r) for r in rows], labels, tol)
        assert all(0.0 <= s.success <= 1.0 for s in summary)
        assert min(s.time_sgm_rel for s in summary) == pytest.approx(1.0)
    for row in rows:
        if row["status"] not in ("error", "skipped"):       # measured rows, whatever the status
            assert row["time_min_s"] <= row["time_s"] <= row["time_max_s"]
            assert row["reproducible"]
            # a failure is penalised, not timed again: only converged solves are repeated
            assert row["repeats"] == (2 if row["status"] == "converged" else 1)
    # the stored reference velocities of the pile agree with the fresh reference solve
    pile = next(r for r in data["instances"] if r["instance"] == "pile200_inelastic")
    assert pile["reference_status"] == "converged" and pile["reference_fclib_error"] < 1e-9


def test_two_runs_give_the_same_errors_and_iterations(tmp_path):
    first = _run(tmp_path / "a", "tiny-sequence", repeats=1)
    second = _run(tmp_path / "b", "tiny-sequence", repeats=1)
    key = lambda r: (r["instance"], r["solver"], r["tol"])  # noqa: E731
    a = {key(r): (r["iterations"], r["status"], r["velocity_error"]) for r in first["results"]}
    b = {key(r): (r["iterations"], r["status"], r["velocity_error"]) for r in second["results"]}
    assert a == b
    labels = first["meta"]["solvers"]
    assert "clarabel+warm" in labels and len(labels) == 2 * len(_solvers())
    # Clarabel ignores warm starts on convex problems: warm and cold solves coincide
    for (instance, solver, tol), value in a.items():
        if solver == "clarabel":
            assert a[(instance, "clarabel+warm", tol)] == value


def test_sequence_warm_start_is_the_previous_solution_matched_by_key():
    from lubcontact.model.laws import GlueyLubrication
    from lubcontact.scenes.small import settling_pile

    steps = problem_sets.simulated_steps(settling_pile(12, seed=5), GlueyLubrication(),
                                         problem_sets.PILE_DT, 30, 2)
    (previous, forces, _), (problem, _, _) = steps
    instance, = problem_sets.sequence("s", steps, problem_sets.CONVEX, 30)
    assert instance.problem is problem and instance.step == 31
    common, old, new = np.intersect1d(previous.keys, problem.keys, return_indices=True)
    assert common.size > 0
    np.testing.assert_array_equal(instance.warm_start[new], forces[old])
    fresh = np.setdiff1d(np.arange(problem.n_contacts), new)
    assert np.all(instance.warm_start[fresh] == 0.0)


def test_statistics_on_known_numbers():
    assert statistics.shifted_geometric_mean(np.array([1.0, 1.0])) == pytest.approx(1.0)
    assert statistics.shifted_geometric_mean(np.array([0.0, 0.0])) == pytest.approx(0.0, abs=1e-15)
    # sqrt((1 + s)(4 + s)) - s with s = 1 ms
    assert statistics.shifted_geometric_mean(np.array([1.0, 4.0])) == pytest.approx(
        np.sqrt(1.001 * 4.001) - 0.001)
    rows = [runs.Measurement(instance=i, group="", mode=problem_sets.CONVEX, n_contacts=1, n_rows=1,
                             solver=s, method=s, warm=False, tol=1e-6, success=ok, time_s=t)
            for i, s, ok, t in [("p", "a", True, 1.0), ("p", "b", True, 3.0),
                                ("q", "a", False, 1.0), ("q", "b", True, 2.0)]]
    ratios = statistics.performance_ratios(rows, ["a", "b"], 1e-6)
    np.testing.assert_array_equal(ratios["a"], [1.0, np.inf])
    np.testing.assert_array_equal(ratios["b"], [3.0, 1.0])
    times = statistics.penalised_times(rows, ["a", "b"], 1e-6)
    np.testing.assert_array_equal(times["a"], [1.0, statistics.FAILURE_PENALTY * 2.0])


def test_missing_sources_and_bad_arguments(tmp_path, monkeypatch, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    monkeypatch.setenv(problem_sets.DATA_DIR_ENV, str(empty))
    with pytest.raises(problem_sets.SetUnavailable, match="no problem files"):
        problem_sets.SETS["siconos-fc2d"].instances()
    assert compare.main(["--set", "siconos-fc2d", "--out", str(tmp_path), "--quiet"]) == 1
    assert "skipping set 'siconos-fc2d'" in capsys.readouterr().err
    assert compare.main(["--set", "tiny", "--max-contacts", "0", "--out", str(tmp_path)]) == 1
    assert "more than 0 contacts" in capsys.readouterr().err
    assert compare.main(["--set", "nonsense"]) == 2
    assert "--set: unknown set 'nonsense'" in capsys.readouterr().err
    assert compare.main(["--set", "tiny", "--solvers", "nonsense"]) == 2
    assert compare.main(["--set", "tiny", "--tolerances", "-1"]) == 2
    assert compare.main(["--set", "tiny", "--solvers", ","]) == 2          # no method left
    capsys.readouterr()
    assert compare.main(["--set", "tiny", "--data-dir", str(tmp_path / "nowhere")]) == 2
    assert "--data-dir: not a directory" in capsys.readouterr().err


def test_hard_cases_use_exact_answers_and_flag_infeasible_problems():
    try:
        instances = {i.name: i for i in problem_sets.SETS["hard"].instances()}
    except problem_sets.SetUnavailable as exc:
        pytest.skip(str(exc))
    single, infeasible = instances["single_contact"], instances["glued_infeasible"]
    assert single.exact is not None and infeasible.must_flag
    variant = runs.Variant("clarabel")
    reference, summary = runs.reference_solve(single, None)
    assert summary.errors_against == "exact velocities"
    row = runs.measure(single, variant, 1e-8, reference, 1, None, runs.SUCCESS_SLACK)
    assert row.success and row.velocity_error < 1e-8
    reference, _ = runs.reference_solve(infeasible, None)
    row = runs.measure(infeasible, variant, 1e-8, reference, 1, None, runs.SUCCESS_SLACK)
    assert row.status != "converged" and row.success
    assert np.isnan(row.velocity_error)


def test_the_flows_set_builds_warm_started_steps_of_each_model():
    """``--set flows`` builds its inclined-flow snapshots (it imported a module that no longer
    held the flow scenes, and every call failed): of 3 consecutive steps, the last 2 with the
    previous step's forces."""
    instances = problem_sets.SETS["flows"].instances()
    assert [i.name for i in instances] == [f"flow60-{model}-step{step}" for model in ("dry", "gluey")
                                           for step in (21, 22)]
    assert all(i.mode == problem_sets.COULOMB and i.problem.n_contacts > 20 for i in instances)
    assert all(i.warm_start is not None for i in instances)
