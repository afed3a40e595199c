"""``lubcontact run`` / ``sweep``: resume semantics, interruption, help text and argument errors."""
import json
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from lubcontact.flow import cli as flow_cli
from lubcontact.flow.bed import initial_scene
from lubcontact.flow.config import RunConfig
from lubcontact.flow.run import FlowRun

SMALL = ["--n", "24", "--width", "12", "--model", "dry", "--dt", "0.05", "--settle-steps", "0",
         "--solver", "clarabel", "--checkpoint-every", "3", "--sample-every", "3", "--no-progress"]
ENV = dict(os.environ, OPENBLAS_NUM_THREADS="1", MPLBACKEND="Agg")


def small_run(out, steps, done):
    """A run of ``steps`` steps stopped after ``done`` (its checkpoint: the multiple of 3 below)."""
    config = RunConfig(scene="inclined_flow", n_grains=24, width=12.0, model="dry", angle=22.0,
                       steps=steps, dt_fraction=0.05, settle_steps=0, solver="clarabel",
                       checkpoint_every=3, sample_every=3)
    run = FlowRun(config, initial_scene(config, out), out)
    run.advance(done)
    return run


def stored(out):
    with np.load(out / "checkpoint.npz") as data:
        return int(data["steps_done"]), RunConfig.from_json(str(data["config"]))


def error_lines(capsys):
    return [line for line in capsys.readouterr().err.splitlines() if line.strip()]


# -- defect 1: resume ------------------------------------------------------------------------------
def test_resume_without_steps_continues_the_stored_run(tmp_path, capsys):
    """A 12-step run killed at step 7 resumes to 12 steps (not to the default 1000)."""
    out = tmp_path / "run"
    small_run(out, steps=12, done=7)                        # checkpoint at step 6
    assert stored(out)[0] == 6
    assert flow_cli.run_main(["inclined_flow", "--out", str(out), "--resume", "--no-progress"]) == 0
    steps_done, config = stored(out)
    assert (steps_done, config.steps) == (12, 12)
    assert json.loads((out / "summary.json").read_text())["steps"] == 12
    assert "resuming" in capsys.readouterr().out


def test_resume_with_explicit_steps_changes_the_total_and_says_so(tmp_path, capsys):
    out = tmp_path / "run"
    small_run(out, steps=12, done=12)
    capsys.readouterr()
    assert flow_cli.run_main(["inclined_flow", "--out", str(out), "--resume", "--steps", "18",
                              "--no-progress"]) == 0
    assert stored(out)[0] == 18 and stored(out)[1].steps == 18
    assert "from 12 to 18 steps" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exit_:                # below the checkpoint's step: refused
        flow_cli.run_main(["--out", str(out), "--resume", "--steps", "9", "--no-progress"])
    assert exit_.value.code == 2
    lines = error_lines(capsys)
    assert len(lines) == 1 and "--steps" in lines[0]


CONFLICTS = [(["--n", "30"], "--n"), (["--angle", "25"], "--angle"), (["--model", "gluey"], "--model"),
             (["--preset", "poster"], "--preset"), (["--seed", "3"], "--seed"),
             (["--dt", "0.02"], "--dt"), (["--width", "14"], "--width"),
             (["--settle-steps", "5"], "--settle-steps")]


def test_resume_rejects_flags_that_define_the_scene_or_the_physics(tmp_path, capsys):
    out = tmp_path / "run"
    small_run(out, steps=12, done=12)
    before = (out / "checkpoint.npz").read_bytes()
    base = ["inclined_flow", "--out", str(out), "--resume", "--steps", "12", "--no-progress"]
    for flags, name in CONFLICTS:
        capsys.readouterr()
        with pytest.raises(SystemExit) as exit_:
            flow_cli.run_main(base + flags)
        assert exit_.value.code == 2, flags
        lines = error_lines(capsys)
        assert len(lines) == 1 and name in lines[0], (flags, lines)
    with pytest.raises(SystemExit):                         # several at once: all named, one line
        flow_cli.run_main(base + ["--n", "30", "--seed", "4"])
    lines = error_lines(capsys)
    assert len(lines) == 1 and "--n" in lines[0] and "--seed" in lines[0]
    with pytest.raises(SystemExit):                         # the scene too
        flow_cli.run_main(["sedimentation"] + base[1:])
    assert "sedimentation" in error_lines(capsys)[0]
    assert (out / "checkpoint.npz").read_bytes() == before  # nothing was touched
    # the stored values themselves may be repeated (the same command line plus --resume)
    assert flow_cli.run_main(base + ["--n", "24", "--model", "dry", "--dt", "0.05"]) == 0


def test_resume_without_a_checkpoint_is_an_error(tmp_path, capsys):
    out = tmp_path / "nothing"
    with pytest.raises(SystemExit) as exit_:
        flow_cli.run_main(["inclined_flow", "--out", str(out), "--resume", "--steps", "3", *SMALL])
    assert exit_.value.code == 2
    lines = error_lines(capsys)
    assert len(lines) == 1 and "checkpoint" in lines[0] and "--resume" in lines[0]
    assert not out.exists()


# -- defect 2: Ctrl-C -----------------------------------------------------------------------------
def wait_for(path, process, seconds=60.0):
    deadline = time.monotonic() + seconds
    while not path.exists():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, f"no {path} after {seconds} s"
        time.sleep(0.05)


def interrupt(command, checkpoint):
    process = subprocess.Popen(command, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    try:
        wait_for(checkpoint, process)
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
    return process.returncode, stderr


def test_ctrl_c_stops_the_run_with_a_checkpoint_and_one_line(tmp_path):
    out = tmp_path / "run"
    command = [sys.executable, "-m", "lubcontact.cli", "run", "inclined_flow", "--n", "24",
               "--width", "12", "--model", "dry", "--steps", "800", "--dt", "0.02",
               "--settle-steps", "0", "--checkpoint-every", "50", "--sample-every", "10",
               "--out", str(out)]
    code, stderr = interrupt(command, out / "checkpoint.npz")
    assert code == 130, stderr
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "interrupted at step" in lines[0], stderr
    assert f"lubcontact run --out {out} --resume" in lines[0]
    step = int(re.search(r"interrupted at step (\d+)", lines[0]).group(1))
    steps_done, config = stored(out)
    assert steps_done == step and 0 < step < 800 and config.steps == 800
    resumed = subprocess.run([sys.executable, "-m", "lubcontact.cli", "run", "--out", str(out),
                              "--resume"], env=ENV, capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    assert json.loads((out / "summary.json").read_text())["steps"] == 800
    assert stored(out)[0] == 800


def test_ctrl_c_stops_a_sweep_with_a_checkpoint_and_one_line(tmp_path):
    out = tmp_path / "sweep"
    args = ["--angles", "22", "--models", "dry", "--n", "24", "--width", "12", "--steps", "800",
            "--dt", "0.02", "--settle-steps", "0", "--checkpoint-every", "50", "--sample-every", "10",
            "--out", str(out)]
    command = [sys.executable, "-m", "lubcontact.cli", "sweep", *args]
    run_dir = out / "dry" / "angle_22.00"
    code, stderr = interrupt(command, run_dir / "checkpoint.npz")
    assert code == 130, stderr
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "interrupted at step" in lines[0], stderr
    assert "lubcontact sweep" in lines[0] and "--angles 22" in lines[0]
    step = int(re.search(r"interrupted at step (\d+)", lines[0]).group(1))
    assert stored(run_dir)[0] == step
    resumed = subprocess.run(command, env=ENV, capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    assert json.loads((run_dir / "summary.json").read_text())["steps"] == 800


SCRIPT = """
import pathlib, sys
from lubcontact.flow.bed import initial_scene
from lubcontact.flow.config import RunConfig
from lubcontact.flow.interrupt import Interrupted
from lubcontact.flow.run import FlowRun
out = pathlib.Path(sys.argv[1])
config = RunConfig(scene="inclined_flow", n_grains=24, width=12.0, model="dry", angle=22.0,
                   steps=800, dt_fraction=0.02, settle_steps=0, checkpoint_every=50,
                   sample_every=10)
run = FlowRun(config, initial_scene(config, out), out)
try:
    run.advance(800)
except Interrupted as stop:
    print("stopped", stop.step, run.steps_done)
"""


@pytest.mark.parametrize("signal_", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_stops_a_scripted_run_after_its_step_with_a_checkpoint(tmp_path, signal_):
    """``FlowRun.advance`` called from a script (no command line around it) handles Ctrl-C
    and SIGTERM itself: the step under way ends, a checkpoint of it is written, and
    ``Interrupted`` says which step (before, Ctrl-C raised ``KeyboardInterrupt`` inside a
    step and SIGTERM killed the process: the steps since the last checkpoint were lost)."""
    out = tmp_path / "run"
    process = subprocess.Popen([sys.executable, "-c", SCRIPT, str(out)], env=ENV,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_for(out / "checkpoint.npz", process)
        process.send_signal(signal_)
        stdout, stderr = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0, stderr
    step, steps_done = map(int, re.search(r"stopped (\d+) (\d+)", stdout).groups())
    assert step == steps_done == stored(out)[0]
    assert 50 <= step < 800


def test_a_signal_between_two_runs_stops_the_next_one_inside_an_outer_block(tmp_path):
    """Blocks of ``stop_on_signals`` nest: a request noted by an outer block (a sweep between
    two runs) is kept by the run's own block, which stops before its first step."""
    from lubcontact.flow import interrupt
    run = small_run(tmp_path / "run", steps=12, done=2)
    with interrupt.stop_on_signals():
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.1)                         # the handler runs in the main thread
        with pytest.raises(interrupt.Interrupted) as stop:
            run.advance(10)
    assert stop.value.step == run.steps_done == stored(tmp_path / "run")[0] == 2


def test_a_signal_during_the_last_step_of_a_call_still_stops_the_run(tmp_path):
    """A signal that arrives while ``advance`` takes its last step is not forgotten when the
    call's block ends: the step is finished, checkpointed, and ``Interrupted`` raised."""
    from lubcontact.flow import interrupt
    run = small_run(tmp_path / "run", steps=12, done=2)
    step = run.sim.step

    def step_with_ctrl_c(*args, **kwargs):
        report = step(*args, **kwargs)
        if run.sim.steps_done == 5:             # the third and last step of the call below
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.1)                     # the handler runs in the main thread
        return report

    run.sim.step = step_with_ctrl_c
    with pytest.raises(interrupt.Interrupted) as stop:
        run.advance(3)
    assert stop.value.step == run.steps_done == stored(tmp_path / "run")[0] == 5


# -- defect 5: help, argument errors, progress bar, import cost ------------------------------------
def help_blocks(text):
    """``{invocation: help text}`` of each option (and positional) of an argparse help page."""
    blocks, current = {}, None
    for line in text.splitlines():
        if re.match(r"^  [-{]", line):
            parts = re.split(r"\s{2,}", line.strip(), maxsplit=1)
            current = parts[0]
            blocks[current] = parts[1] if len(parts) > 1 else ""
        elif current is not None and line.startswith("   ") and line.strip():
            blocks[current] += " " + line.strip()
        else:
            current = None
    return blocks


@pytest.mark.parametrize("command", ["run", "sweep", "hysteresis"])
def test_help_gives_a_text_and_the_default_of_every_option(command, capsys):
    main = {"run": flow_cli.run_main, "sweep": flow_cli.sweep_main,
            "hysteresis": flow_cli.hysteresis_main}[command]
    with pytest.raises(SystemExit) as exit_:
        main(["--help"])
    assert exit_.value.code == 0
    text = capsys.readouterr().out
    for markup in ("``", ":func:", ":class:", ":mod:"):
        assert markup not in text
    blocks = help_blocks(text)
    assert len(blocks) > 20
    for invocation, help_ in blocks.items():
        if invocation.startswith("-h"):
            continue
        assert help_, f"{invocation}: no help text"
        assert "default" in help_, f"{invocation}: no default shown ({help_!r})"
    dt = next(h for i, h in blocks.items() if i.startswith("--dt"))
    assert "sqrt(d/g')" in dt and "mean" in dt and "diameter" in dt


RUN_ERRORS = [(["--n", "0"], "--n", "n_grains"), (["--angle", "abc"], "--angle", None),
              (["--angle", "95"], "--angle", "angle_deg"), (["--steps", "-5"], "--steps", None),
              (["--tol", "0"], "--tol", None), (["--dt", "0"], "--dt", "dt_fraction"),
              (["--checkpoint-every", "0"], "--checkpoint-every", "checkpoint_every"),
              (["--mu", "-1"], "--mu", "friction"), (["--solver", "nope"], "--solver", None),
              (["--width", "-2"], "--width", None), (["--max-outer", "0"], "--max-outer", "max_outer")]
SWEEP_ERRORS = [(["--angles", "15:28"], "--angles", None), (["--models", "dry,wet"], "--models", None),
                (["--n", "0"], "--n", "n_grains"), (["--tol-fp", "0"], "--tol-fp", "tol_fp"),
                (["--workers", "0"], "--workers", None), (["--seeds", "1,x"], "--seeds", None),
                (["--seeds", "1,1"], "--seeds", None), (["--seeds", "1", "--seed", "2"], "--seeds",
                                                        None),
                (["--viscosities", "1e-3"], "--viscosities", "viscosity"),
                (["--viscosity", "1e-3"], "--viscosity", None),
                (["--preset", "poster", "--roughnesses", "0,1e-6"], "--roughnesses", None)]
HYSTERESIS_ERRORS = [(["--to", "14.5"], "--to", None), (["--seed", "1"], "--seed", None),
                     (["--step", "0"], "--step", None), (["--hold", "0"], "--hold", None),
                     (["--models", "wet"], "--models", None),
                     (["--flow-speed", "-1"], "--flow-speed", None)]


def test_bad_values_are_one_line_errors_naming_the_flag(tmp_path, capsys):
    run_base = ["inclined_flow", "--out", str(tmp_path / "run"), *SMALL, "--steps", "1"]
    sweep_base = ["--out", str(tmp_path / "sweep"), *SMALL, "--steps", "1", "--angles", "22",
                  "--models", "dry"]
    ramp_base = ["--out", str(tmp_path / "ramp"), *SMALL, "--from", "14", "--to", "16",
                 "--hold", "1", "--models", "dry"]
    ramp_base.remove("--model")
    ramp_base.remove("dry")
    cases = ([(flow_cli.run_main, run_base, *case) for case in RUN_ERRORS]
             + [(flow_cli.sweep_main, sweep_base, *case) for case in SWEEP_ERRORS]
             + [(flow_cli.hysteresis_main, ramp_base, *case) for case in HYSTERESIS_ERRORS])
    for main, base, bad, flag, field in cases:
        capsys.readouterr()
        with pytest.raises(SystemExit) as exit_:
            main(base + bad)
        assert exit_.value.code == 2, bad
        lines = error_lines(capsys)
        assert len(lines) == 1 and flag in lines[0], (bad, lines)
        assert "Traceback" not in lines[0] and (field is None or field not in lines[0]), lines


def test_no_progress_bar_when_stderr_is_not_a_terminal(tmp_path, capsys):
    argv = ["inclined_flow", "--out", str(tmp_path / "run"), *SMALL, "--steps", "4"]
    argv.remove("--no-progress")
    assert flow_cli.run_main(argv) == 0
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("command", ["run", "sweep", "hysteresis"])
def test_help_imports_no_solver_plotting_or_scipy(command):
    """``lubcontact run --help`` must stay instant: nothing heavy is imported to parse."""
    done = subprocess.run([sys.executable, "-X", "importtime", "-m", "lubcontact.cli", command,
                           "--help"], env=ENV, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and "usage" in done.stdout
    imported = {line.rsplit("|", 1)[-1].strip() for line in done.stderr.splitlines()
                if line.startswith("import time:")}
    heavy = {"numba", "cvxpy", "matplotlib", "scipy", "lubcontact.solvers", "tqdm"}
    assert not heavy & imported, sorted(heavy & imported)


def test_names_known_to_the_parser_match_the_scenes():
    from lubcontact.flow.config import MODEL_NAMES, PRESET_NAMES
    from lubcontact.scenes import inclined
    assert PRESET_NAMES == tuple(inclined.PRESETS) and MODEL_NAMES == inclined.MODELS


def test_the_default_solver_follows_the_friction_model(tmp_path, capsys):
    """The relaxation's method by default (apgd-jacobi), exact Coulomb's (newton-ac) with
    --fixed-point; a solver given explicitly is kept; the checkpoint and summary record it."""
    assert RunConfig().solver == "apgd-jacobi" and RunConfig(fixed_point=True).solver == "newton-ac"
    assert RunConfig(fixed_point=True, solver="apgd-jacobi").solver == "apgd-jacobi"
    out = tmp_path / "exact"
    assert flow_cli.run_main(["inclined_flow", "--n", "12", "--width", "8", "--steps", "2",
                              "--settle-steps", "0", "--fixed-point", "--no-progress",
                              "--out", str(out)]) == 0
    assert stored(out)[1].solver == "newton-ac"
    assert json.loads((out / "summary.json").read_text())["solver"] == "newton-ac"


# -- sweeps in worker processes (issue 16) ---------------------------------------------------------
SWEEP_SMALL = ["--models", "dry", "--angles", "20,24", "--n", "24", "--width", "12", "--dt", "0.05",
               "--settle-steps", "0", "--solver", "clarabel", "--checkpoint-every", "3",
               "--sample-every", "3", "--no-progress"]


def sweep_rows(out):
    lines = (out / "sweep.csv").read_text().splitlines()
    header = lines[0].split(",")
    timing = {i for i, name in enumerate(header) if "time" in name or "per_" in name
              or "second" in name}
    return [[cell for i, cell in enumerate(line.split(",")) if i not in timing] for line in lines]


def final_positions(run_dir):
    with np.load(run_dir / "checkpoint.npz") as data:
        return {key: data[key] for key in data.files if key.startswith("scene")}


def test_a_sweep_in_two_workers_equals_the_sequential_sweep(tmp_path, capsys):
    sequential, parallel = tmp_path / "one", tmp_path / "two"
    assert flow_cli.sweep_main([*SWEEP_SMALL, "--steps", "9", "--out", str(sequential)]) == 0
    assert flow_cli.sweep_main([*SWEEP_SMALL, "--steps", "9", "--out", str(parallel),
                                "--workers", "2"]) == 0
    assert sweep_rows(sequential) == sweep_rows(parallel)
    assert len(sweep_rows(parallel)) == 3
    for angle in ("angle_20.00", "angle_24.00"):
        one = final_positions(sequential / "dry" / angle)
        two = final_positions(parallel / "dry" / angle)
        assert one.keys() == two.keys() and one
        for key in one:
            np.testing.assert_array_equal(one[key], two[key])


def test_a_killed_worker_loses_at_most_its_last_checkpoint_interval(tmp_path):
    out = tmp_path / "sweep"
    command = [sys.executable, "-m", "lubcontact.cli", "sweep", *SWEEP_SMALL, "--steps", "400",
               "--out", str(out), "--workers", "2"]
    process = subprocess.Popen(command, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    checkpoint = out / "dry" / "angle_20.00" / "checkpoint.npz"
    deadline = time.time() + 240
    while not checkpoint.exists() and time.time() < deadline and process.poll() is None:
        time.sleep(0.2)
    assert checkpoint.exists(), process.communicate()[1]
    children = subprocess.run(["pgrep", "-P", str(process.pid)], capture_output=True, text=True)
    workers = [int(pid) for pid in children.stdout.split()
               if b"spawn_main" in open(f"/proc/{pid}/cmdline", "rb").read()]   # not the resource tracker
    assert len(workers) == 2
    os.kill(workers[0], signal.SIGKILL)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 1, stderr
    lines = [line for line in stderr.splitlines() if line.strip()]
    died = [line for line in lines if "worker process died" in line]   # workers may warn before
    assert len(died) == 1 and died[0] == lines[-1] and "--workers 2" in died[0], stderr
    assert "Traceback" not in stderr
    kept = stored(checkpoint.parent)[0]
    assert kept >= 3
    resumed = subprocess.run(command, env=ENV, capture_output=True, text=True, timeout=600)
    assert resumed.returncode == 0, resumed.stderr
    for angle in ("angle_20.00", "angle_24.00"):
        assert json.loads((out / "dry" / angle / "summary.json").read_text())["steps"] == 400


def test_a_sweep_on_a_dask_cluster_equals_the_sequential_sweep_and_survives_a_lost_worker(tmp_path):
    """A local Dask cluster of two worker processes. One worker is killed once its run has written
    a checkpoint; Dask hands the task to a worker again, which continues from that checkpoint."""
    distributed = pytest.importorskip("distributed")
    sequential, on_dask = tmp_path / "one", tmp_path / "dask"
    assert flow_cli.sweep_main([*SWEEP_SMALL, "--steps", "30", "--out", str(sequential)]) == 0
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        argv = [*SWEEP_SMALL, "--steps", "30", "--out", str(on_dask),
                "--scheduler", cluster.scheduler_address]
        checkpoint = on_dask / "dry" / "angle_20.00" / "checkpoint.npz"
        killed = []

        def kill_one_worker_at_its_first_checkpoint():
            deadline = time.time() + 120
            while not checkpoint.exists() and time.time() < deadline:
                time.sleep(0.05)
            with distributed.Client(cluster.scheduler_address) as client:
                address = next(iter(client.scheduler_info()["workers"]))
                killed.append(stored(checkpoint.parent)[0])
                try:
                    client.run(os._exit, 1, workers=[address])
                except (OSError, distributed.comm.core.CommClosedError):
                    pass                    # the worker died before it could answer: expected

        import threading
        killer = threading.Thread(target=kill_one_worker_at_its_first_checkpoint)
        killer.start()
        assert flow_cli.sweep_main(argv) == 0
        killer.join()
    assert killed and killed[0] >= 3
    assert sweep_rows(sequential) == sweep_rows(on_dask)
    for angle in ("angle_20.00", "angle_24.00"):
        one = final_positions(sequential / "dry" / angle)
        two = final_positions(on_dask / "dry" / angle)
        for key in one:
            np.testing.assert_array_equal(one[key], two[key])


def test_an_unreachable_scheduler_is_a_one_line_error(tmp_path, capsys):
    pytest.importorskip("distributed")
    import dask

    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        code = flow_cli.sweep_main([*SWEEP_SMALL, "--steps", "3", "--out", str(tmp_path / "s"),
                                    "--scheduler", "tcp://127.0.0.1:9"])
    assert code == 2
    lines = error_lines(capsys)
    assert len(lines) == 1 and "--scheduler" in lines[0] and "127.0.0.1:9" in lines[0]
