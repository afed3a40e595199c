"""The example gallery (docs/guide/gallery.md): every script runs in quick mode, writes its figure
and reproduces the numbers its docstring states (exact solutions of docs/guide/model.md section 7
where there is one)."""
import os
import runpy
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
GALLERY = ["single_contact", "push_pull_and_incline", "coulomb_incline", "gluey_friction",
           "solver_work_precision", "hard_case", "flow_animation", "shear_cell", "squeeze"]


def quick(name, out):
    """Run ``examples/NAME.py``'s ``main(quick=True, out=out)``; return its checked numbers."""
    namespace = runpy.run_path(str(EXAMPLES / f"{name}.py"), run_name=f"gallery_{name}")
    checks = namespace["main"](True, out)
    assert (out / f"{name}.png").stat().st_size > 10_000
    return checks


def test_single_contact_force_is_on_the_cone_edge(tmp_path):
    checks = quick("single_contact", tmp_path)
    assert checks["exact_lam_n"] == pytest.approx(0.09 / 0.0127, rel=1e-12)
    assert checks["clarabel_error"] < 1e-8 and checks["pgd_error"] < 1e-10
    assert (checks["coulomb_lam_n"], checks["coulomb_lam_t"]) == pytest.approx((6.0, 1.8), abs=1e-6)


def test_push_pull_and_incline_unglue_on_time_at_first_order(tmp_path):
    checks = quick("push_pull_and_incline", tmp_path)
    for case in ("push-pull", "incline"):
        assert checks[f"{case}_gamma_error"] < 1e-9
        assert checks[f"{case}_unglue_error"] <= 1e-2 + 1e-12           # within one step (dt 1e-2)
        assert checks[f"{case}_slope"] == pytest.approx(1.0, abs=0.05)
        assert checks[f"{case}_flight_error"] == pytest.approx(checks[f"{case}_discrete"], rel=1e-6)


def test_coulomb_incline_threshold_and_dilatancy(tmp_path):
    checks = quick("coulomb_incline", tmp_path)
    assert checks["x_error"] < 1e-2                       # O(dt) of the scheme, dt / t = 5e-3
    assert checks["fraction_error"] < 1e-6                # rolls below tan a = 3 mu, slides above
    assert checks["first_lift_error"] < 1e-9              # the relaxation lifts by mu dt |u_T|
    assert checks["relaxed_apex"] == pytest.approx(checks["exact_apex"], rel=0.05)
    assert checks["fixed_point_gap"] < 1e-9 and checks["fixed_point_speed_error"] < 1e-8


def test_gluey_friction_regimes_switch_on_time(tmp_path):
    checks = quick("gluey_friction", tmp_path)
    assert abs(checks["first_union"] - checks["t_f"]) <= 0.02 + 1e-9       # one quick step
    assert abs(checks["unglued"] - checks["t_u"]) <= 0.02 + 1e-9
    assert max(checks["velocity_error"], checks["spin_error"], checks["normal_error"]) < 1e-3


def test_work_precision_reports_every_method(tmp_path):
    checks = quick("solver_work_precision", tmp_path)
    assert checks["frictionless_tightest_error"] < 1e-6 and checks["friction_tightest_error"] < 1e-5
    assert checks["friction_not_converged"] > 0           # tol 1e-2 is flagged, not hidden


def test_hard_case_statuses_are_honest(tmp_path):
    checks = quick("hard_case", tmp_path)
    assert checks["cond"] == pytest.approx(4e6, rel=1e-3)
    assert checks["pgd_status"] == "max_iter" and checks["pgd_error"] > 1e-3
    assert checks["worst_converged_error"] < 1e-9
    assert "max_iter" in checks["tight_statuses"]
    # Clarabel cut at 4 iterations says so (raw), and its polished answer meets tol
    assert checks["tight_interior_points"] == [("converged", "MaxIterations"),
                                               ("converged", "optimal_inaccurate"),
                                               ("converged", "user_limit")]


def test_flow_animation_writes_a_gif(tmp_path):
    checks = quick("flow_animation", tmp_path)
    assert 10_000 < (tmp_path / "flow_animation.gif").stat().st_size < 1_500_000
    assert checks["flow_rate"] > 0 and checks["min_gap_converged"] > -1e-4


def test_shear_cell_lid_follows_its_schedule(tmp_path):
    checks = quick("shear_cell", tmp_path)
    assert checks["converged"] == 1.0 and checks["min_gap"] > -1e-5
    assert checks["lid_y"] == pytest.approx(8.0, abs=1e-9) and checks["lid_shift_error"] < 1e-9
    # the last window's profile: v_x rises across the gap from the resting bottom wall to the lid.
    # The trajectory is chaotic and rounding differs between CPUs: measured on two, the bottom
    # slab at 0.03-0.08 U, the top one at 0.68-0.80 U, a straight-line fit rising by 0.6-0.7 U.
    assert 0 < checks["bottom_slab"] < 0.2 and checks["top_slab"] > 0.5 and checks["rise"] > 0.4


def test_squeeze_flags_the_infeasible_steps(tmp_path):
    checks = quick("squeeze", tmp_path)
    assert checks["apgd-as_top_force"] == 0.0 and checks["apgd-as_last_t"] == 2.0
    assert checks["clarabel_top_force"] == pytest.approx(1 / np.sqrt(2), rel=1e-6)
    assert checks["clarabel_last_t"] == 1.0                # stopped with SolverError, state kept
    assert checks["apgd-as_floor_gamma"] == pytest.approx(-1.0, abs=1e-12)
    assert checks["apgd-as_height_error"] < 1e-12
    assert checks["converged_on_infeasible"] == 0


def test_scripts_run_from_the_command_line(tmp_path, monkeypatch, capsys):
    env = dict(os.environ, MPLBACKEND="Agg", OPENBLAS_NUM_THREADS="1")
    done = subprocess.run([sys.executable, str(EXAMPLES / "single_contact.py"), "--quick", "--out",
                           str(tmp_path)], env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "DUAL" in done.stdout and (tmp_path / "single_contact.png").exists()
    for name in GALLERY:                                   # every script's options, in process
        monkeypatch.setattr(sys, "argv", [f"{name}.py", "--help"])
        with pytest.raises(SystemExit) as exit_info:
            runpy.run_path(str(EXAMPLES / f"{name}.py"), run_name="__main__")
        assert exit_info.value.code == 0 and "--quick" in capsys.readouterr().out, name
