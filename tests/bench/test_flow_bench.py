"""``lubcontact bench flow``: a developed flow built once and cached, a row per method."""
import pytest

from lubcontact.bench import flow_steps


def test_bench_flow_prints_a_row_per_method_and_reuses_its_cache(tmp_path, capsys):
    argv = ["--sizes", "40", "--models", "dry", "--methods", "apgd-jacobi,newton-ac", "--steps", "2",
            "--settle-steps", "150", "--cache", str(tmp_path)]
    assert flow_steps.main(argv) == 0
    table = capsys.readouterr().out.splitlines()[-4:]
    assert table[0].split() == list(flow_steps.COLUMNS)
    rows = [dict(zip(flow_steps.COLUMNS, line.split(), strict=True)) for line in table[2:]]
    assert [row["method"] for row in rows] == ["apgd-jacobi", "newton-ac"]
    for row in rows:
        assert int(row["contacts"]) > 20              # a bed: contacts, not falling grains
        assert float(row["max_fclib_error"]) <= 1e-5 and row["statuses"] == "converged"
        shares = [float(row[f"{phase}_pc"]) for phase in flow_steps.PHASES]
        assert all(share >= 0 for share in shares) and 95.0 <= sum(shares) <= 100.0 + 1e-6
        assert 0 < float(row["warm_cold"]) and float(row["peak_mb"]) > 50
    cached = list(tmp_path.glob("flow-40-dry-*.npz"))
    assert len(cached) == 1
    stamp = cached[0].stat().st_mtime_ns
    assert flow_steps.main(argv) == 0
    assert cached[0].stat().st_mtime_ns == stamp      # read back, not rebuilt


@pytest.mark.parametrize("bad, flag", [(["--sizes", "0"], "--sizes"), (["--methods", "nope"], "--methods"),
                                       (["--models", "wet"], "--models"), (["--tol", "0"], "--tol")])
def test_bad_flags_are_one_line_errors(bad, flag, capsys):
    with pytest.raises(SystemExit) as exit_:
        flow_steps.main(bad)
    assert exit_.value.code == 2
    assert flag in capsys.readouterr().err.strip().splitlines()[-1]
