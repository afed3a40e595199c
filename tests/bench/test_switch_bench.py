"""``lubcontact bench switch``: one module constant changed, each captured step solved both ways."""
import json

import pytest

from lubcontact.bench import switch
from lubcontact.solvers import newton


def _rows(tmp_path, *args):
    out = tmp_path / "rows.json"
    assert switch.main([*args, "--small", "4", "--steps", "6", "--rounds", "1",
                        "--json", str(out)]) == 0
    return json.loads(out.read_text())


def test_a_switch_that_keeps_the_steps_gives_the_same_forces_and_is_put_back(tmp_path):
    """The chained subproblems off: the same iterations and forces to the bit (force_difference
    0), and the constant is its own value again after the run."""
    (row,) = _rows(tmp_path, "--switch", "lubcontact.solvers.newton.CHAINED_SUBPROBLEMS=False")
    assert row["set"] == "pile 4 exact" and row["steps"] == 6
    assert row["iterations_a"] == row["iterations_b"] > 0
    assert row["force_difference"] == 0.0
    assert row["us_a"] > 0 and row["us_b"] > 0 and row["sum_ratio"] > 0
    assert newton.CHAINED_SUBPROBLEMS is True


def test_a_switch_that_changes_the_method_shows_in_its_iterations(tmp_path):
    """Plain Newton as the first weight and one Newton iteration per subproblem: other steps."""
    (row,) = _rows(tmp_path, "--switch", "lubcontact.solvers.newton.WARM_DENSE_WEIGHT=1.0",
                   "--switch", "lubcontact.solvers.newton.INNER_CAP=1")
    assert row["iterations_b"] != row["iterations_a"]
    assert newton.WARM_DENSE_WEIGHT == 1e-4 and newton.INNER_CAP == 10


@pytest.mark.parametrize("args, flag", [
    (["--switch", "INNER_CAP=3", "--small", "4"], "--switch"),
    (["--switch", "lubcontact.solvers.nowhere.X=1", "--small", "4"], "--switch"),
    (["--switch", "lubcontact.solvers.newton.NO_SUCH=1", "--small", "4"], "--switch"),
    (["--switch", "lubcontact.solvers.newton.INNER_CAP=three", "--small", "4"], "--switch"),
    (["--switch", "lubcontact.solvers.newton.INNER_CAP=3"], "--small"),
    (["--switch", "lubcontact.solvers.newton.INNER_CAP=3", "--sizes", "10"], "--sizes"),
    (["--switch", "lubcontact.solvers.newton.INNER_CAP=3", "--small", "0"], "--small"),
    (["--switch", "lubcontact.solvers.newton.INNER_CAP=3", "--small", "4", "--method", "newton"],
     "--method"),
])
def test_bad_flags_are_one_line_errors(args, flag, capsys):
    with pytest.raises(SystemExit):
        switch.main(args)
    assert flag in capsys.readouterr().err.strip().splitlines()[-1]


def test_steps_of_a_widened_layer_are_taken_with_the_flows_own_settings(tmp_path, dry_layer):
    """``--layer`` and ``--sizes``: a 24-grain dry layer widened to 48 grains, stepped as ``bench
    flow --layer`` steps it; a size that is not a multiple of the layer's is a one-line error."""
    checkpoint = str(dry_layer() / "checkpoint.npz")
    out = tmp_path / "rows.json"
    assert switch.main(["--switch", "lubcontact.solvers.newton.CHAINED_SUBPROBLEMS=False",
                        "--layer", checkpoint, "--sizes", "48", "--steps", "3", "--rounds", "1",
                        "--cache", str(tmp_path / "cache"), "--json", str(out)]) == 0
    (row,) = json.loads(out.read_text())
    assert row["set"] == "layer 48" and row["steps"] == 3 and row["force_difference"] == 0.0
    with pytest.raises(SystemExit):
        switch.main(["--switch", "lubcontact.solvers.newton.INNER_CAP=3", "--layer", checkpoint,
                     "--sizes", "30", "--cache", str(tmp_path / "cache")])
