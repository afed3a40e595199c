"""``lubcontact bench flow``: a developed flow built once and cached, a row per method."""
import json
from dataclasses import replace

import pytest

from lubcontact.bench import flow_steps
from lubcontact.bench.statistics import power_law_exponent
from lubcontact.problem.metrics import velocity_error


def test_bench_flow_prints_a_row_per_method_and_reuses_its_cache(tmp_path, capsys):
    argv = ["--sizes", "40", "--models", "dry", "--methods", "apgd-jacobi,newton-ac", "--steps", "2",
            "--settle-steps", "150", "--cache", str(tmp_path)]
    assert flow_steps.main(argv) == 0
    table = capsys.readouterr().out.splitlines()[-4:]
    columns = [name for name in flow_steps.COLUMNS
               if name not in ("joint_iterations", "v_err", "ref_s", "ref_statuses")]
    assert table[0].split() == columns                # those only with --joint, --reference
    rows = [dict(zip(columns, line.split(), strict=True)) for line in table[2:]]
    assert [row["method"] for row in rows] == ["apgd-jacobi", "newton-ac"]
    for row in rows:
        assert int(row["contacts"]) > 20              # a bed: contacts, not falling grains
        assert float(row["max_fclib_error"]) <= 1e-5 and row["statuses"] == "converged"
        shares = [float(row[f"{phase}_pc"]) for phase in flow_steps.PHASES]
        assert all(share >= 0 for share in shares) and 95.0 <= sum(shares) <= 100.0 + 1e-6
        assert float(row["setup_pc"]) > 0 and float(row["iterations_pc"]) > 0
        assert 0 < float(row["warm_cold"]) and float(row["peak_mb"]) > 50
    cached = list(tmp_path.glob("flow-40-dry-*.npz"))
    assert len(cached) == 1
    stamp = cached[0].stat().st_mtime_ns
    assert flow_steps.main(argv) == 0
    assert cached[0].stat().st_mtime_ns == stamp      # read back, not rebuilt


@pytest.mark.parametrize("bad, flag", [(["--sizes", "0"], "--sizes"), (["--methods", "nope"], "--methods"),
                                       (["--models", "wet"], "--models"), (["--tol", "0"], "--tol"),
                                       (["--joint", "-1"], "--joint"),
                                       (["--reference", "-2"], "--reference")])
def test_bad_flags_are_one_line_errors(bad, flag, capsys):
    with pytest.raises(SystemExit) as exit_:
        flow_steps.main(bad)
    assert exit_.value.code == 2
    assert flag in capsys.readouterr().err.strip().splitlines()[-1]


def test_a_layer_widened_to_each_size_gives_rows_an_exponent_and_a_figure(tmp_path, dry_layer, capsys):
    """A 24-grain run's checkpoint widened to 24 and 48 grains: twice the contacts at twice the
    grains, both frictions timed, the rows kept as JSON, the figure drawn (no cold solves)."""
    layer = dry_layer(sample_every=3)
    argv = ["--sizes", "24", "48", "--layer", str(layer / "checkpoint.npz"), "--methods", "apgd",
            "--friction", "exact,relaxation", "--steps", "2", "--cache", str(tmp_path / "cache"),
            "--json", str(tmp_path / "rows.json"), "--figure", str(tmp_path / "scaling.png"),
            "--no-cold"]
    assert flow_steps.main(argv) == 0
    rows = json.loads((tmp_path / "rows.json").read_text())
    assert not any("warm_cold" in row for row in rows)
    assert [(row["n_grains"], row["friction"]) for row in rows] == [
        (24, "exact"), (24, "relaxation"), (48, "exact"), (48, "relaxation")]
    assert rows[2]["contacts"] == pytest.approx(2 * rows[0]["contacts"], rel=0.1)
    assert all(row["model"] == "dry" and row["statuses"] == "converged" for row in rows)
    assert all(0 < row["per_product"] < 1e4 for row in rows)
    out = capsys.readouterr().out
    assert "# dry exact apgd: s/step ~ N^" in out
    assert (tmp_path / "scaling.png").stat().st_size > 10_000
    assert len(list((tmp_path / "cache").glob("widened-*-2x.npz"))) == 1


def test_exact_rows_with_the_joint_phase_are_labelled_and_converge(tmp_path, dry_layer, monkeypatch):
    """``--joint 5``: the exact rows of the methods it applies to (a first-order method's fixed
    point, newton-ac's start) are labelled ``+joint5`` and converge to the FCLIB tolerance; the
    first-order method's take fewer inner iterations than the plain fixed point on the same
    steps, newton-ac's more (its APGD iterations counted: the joint phase ran, on the sparse
    lane forced here)."""
    from lubcontact.solvers import dual_data, newton

    monkeypatch.setattr(dual_data, "DENSE_OPERATOR_LIMIT", 0)
    monkeypatch.setattr(newton, "DENSE_LIMIT", 0)
    monkeypatch.setattr(newton, "COMPILED_LIMIT", 0)
    layer = dry_layer()
    argv = ["--sizes", "24", "--layer", str(layer / "checkpoint.npz"), "--methods",
            "apgd-jacobi,newton-ac", "--joint", "5", "--steps", "2", "--cache", str(tmp_path),
            "--json", str(tmp_path / "rows.json")]
    assert flow_steps.main(argv) == 0
    rows = json.loads((tmp_path / "rows.json").read_text())
    assert [row["method"] for row in rows] == ["apgd-jacobi+joint5", "newton-ac+joint5"]
    for row in rows:
        assert row["statuses"] == "converged" and row["max_fclib_error"] <= 1e-5
        assert 0 < row["joint_iterations"] <= row["iterations"]
    plain = argv[:argv.index("--joint")] + argv[argv.index("--joint") + 2:]
    plain[plain.index("--json") + 1] = str(tmp_path / "plain.json")
    assert flow_steps.main(plain) == 0
    fixed_point, newton_alone = json.loads((tmp_path / "plain.json").read_text())
    assert (fixed_point["method"], newton_alone["method"]) == ("apgd-jacobi", "newton-ac")
    assert "joint_iterations" not in fixed_point and "joint_iterations" not in newton_alone
    assert rows[0]["iterations"] < fixed_point["iterations"]
    assert rows[1]["iterations"] > newton_alone["iterations"]


@pytest.mark.filterwarnings("ignore::lubcontact.solvers.result.SolverWarning")  # tol 1e-2 steps
def test_sampled_steps_are_checked_against_the_reference_and_newton_has_no_relaxation(tmp_path, dry_layer,
                                                                                    capsys):
    """``--reference 1``: every timed step re-solved by Clarabel at tol 1e-9 (exact Coulomb by
    its fixed point, the relaxation by one solve), each row's velocity error against it below
    what the law's difference would give; ``newton-ac`` solves exact Coulomb only, so its
    relaxation row is skipped with a note instead of timing exact Coulomb under that name."""
    layer = dry_layer()
    argv = ["--sizes", "24", "--layer", str(layer / "checkpoint.npz"), "--methods",
            "apgd-jacobi,newton-ac", "--friction", "exact,relaxation", "--steps", "2",
            "--reference", "1", "--no-cold", "--tol", "1e-8", "--cache", str(tmp_path),
            "--json", str(tmp_path / "rows.json")]
    assert flow_steps.main(argv) == 0
    assert "# relaxation skipped: newton-ac solves exact Coulomb itself, it has no relaxation" \
        in capsys.readouterr().out
    rows = json.loads((tmp_path / "rows.json").read_text())
    assert [(row["friction"], row["method"]) for row in rows] == [
        ("exact", "apgd-jacobi"), ("exact", "newton-ac"), ("relaxation", "apgd-jacobi")]
    for row in rows:
        assert row["ref_statuses"] == "converged" and row["ref_s"] > 0
        assert 0 < row["v_err"] <= 1e-6
    relaxation = flow_steps.reference_settings("clarabel", "relaxation")
    exact = flow_steps.reference_settings("clarabel", "exact")
    _, sim = flow_steps.widened_flow(layer / "checkpoint.npz", 24, tmp_path)
    report = sim.step(exact)
    apart = velocity_error(report.problem, report.result.velocities,
                           relaxation.solve(report.problem).velocities)
    assert apart > 1e3 * max(row["v_err"] for row in rows)     # the two laws, told apart
    loose = argv[:argv.index("--tol")] + ["--tol", "1e-2"] + argv[argv.index("--tol") + 2:]
    loose[loose.index("--methods") + 1] = "apgd-jacobi"
    assert flow_steps.main(loose) == 0
    assert all(row["v_err"] > 1e-6 for row in json.loads((tmp_path / "rows.json").read_text()))


def test_a_reference_not_trusted_gives_no_velocity_error(tmp_path, dry_layer, capsys, monkeypatch):
    """A reference stopped at its first iteration is not trusted: said on its own line, its
    status in the row, and no ``v_err`` measured against it."""
    layer = dry_layer()
    settings = flow_steps.reference_settings
    monkeypatch.setattr(flow_steps, "reference_settings",
                        lambda method, friction: replace(settings(method, friction), max_iter=1))
    argv = ["--sizes", "24", "--layer", str(layer / "checkpoint.npz"), "--methods", "apgd-jacobi",
            "--friction", "relaxation", "--steps", "2", "--reference", "1", "--no-cold",
            "--cache", str(tmp_path), "--json", str(tmp_path / "rows.json")]
    assert flow_steps.main(argv) == 0
    assert "# reference NOT trusted on timed step 1: reference status" in capsys.readouterr().out
    (row,) = json.loads((tmp_path / "rows.json").read_text())
    assert row["ref_statuses"] == "not trusted" and "v_err" not in row


def test_a_size_that_is_not_a_multiple_of_the_layer_is_a_one_line_error(tmp_path, dry_layer, capsys):
    layer = dry_layer(steps=3)
    with pytest.raises(SystemExit):
        flow_steps.main(["--sizes", "30", "--layer", str(layer / "checkpoint.npz"),
                         "--cache", str(tmp_path)])
    assert "--sizes: 30 is not a multiple" in capsys.readouterr().err.strip().splitlines()[-1]


def test_power_law_exponent_recovers_the_exponent_and_rejects_one_size():
    assert power_law_exponent([100, 1000, 10000], [2e-3, 2e-3 * 10**1.3, 2e-3 * 100**1.3]) == \
        pytest.approx(1.3, abs=1e-12)
    with pytest.raises(ValueError, match="sizes"):
        power_law_exponent([100, 100], [1.0, 2.0])
