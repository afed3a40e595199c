"""Sweeps over seeds, viscosity and roughness; angle ramps and the hysteresis of the flow angle."""
import csv
import os
import signal
import time
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from lubcontact.flow import cli as flow_cli
from lubcontact.flow import hysteresis, interrupt, measure, sweep
from lubcontact.flow.bed import initial_scene
from lubcontact.flow.config import RunConfig
from lubcontact.flow.run import FlowRun
from lubcontact.model import laws
from lubcontact.scenes import inclined

TINY = ["--n", "16", "--width", "10", "--dt", "0.05", "--settle-steps", "10", "--solver",
        "clarabel", "--checkpoint-every", "3", "--sample-every", "2", "--no-progress"]


def read_csv(path):
    with open(path, newline="") as stream:
        return list(csv.DictReader(stream))


def final_state(run_dir):
    with np.load(run_dir / "checkpoint.npz") as data:
        return {key: data[key] for key in data.files if key.startswith("scene")}


# -- the axes ---------------------------------------------------------------------------------------
def test_axis_groups_are_the_product_of_the_given_axes_seed_outermost():
    groups = sweep.axis_groups(roughness=[1e-7, 1e-6], seed=[0, 3])
    assert groups == [{"seed": 0, "roughness": 1e-7}, {"seed": 0, "roughness": 1e-6},
                      {"seed": 3, "roughness": 1e-7}, {"seed": 3, "roughness": 1e-6}]
    assert sweep.axis_groups() == [{}] and sweep.axis_groups(viscosity=None) == [{}]
    assert str(sweep.group_folder("out", {"seed": 3, "viscosity": 0.01})) == "out/seed_3/eta_0.01"
    with pytest.raises(ValueError, match="friction"):
        sweep.axis_groups(friction=[0.3])
    with pytest.raises(ValueError, match="seed"):
        sweep.axis_groups(seed=[1, 1])
    # folder names keep every digit of a seed and 12 of a parameter (they once kept 6 and two
    # seeds got one folder, the second reading back the first one's runs)
    folders = {sweep.group_folder("out", g) for g in sweep.axis_groups(seed=[1000000, 1000001])}
    assert len(folders) == 2
    assert len({sweep.group_folder("out", g) for g in
                sweep.axis_groups(viscosity=[1e-3, 1.0000001e-3])}) == 2
    with pytest.raises(ValueError, match="viscosity: needs distinct values"):
        sweep.axis_groups(viscosity=[1e-3, 1e-3 * (1 + 1e-14)])


def test_viscosity_and_roughness_set_gamma_min_of_the_poster_preset():
    """gamma_min = 6 pi eta r_eff^2 ln(eps / r_eff): linear in eta, through ln(eps) in eps."""
    base = RunConfig(preset="poster").params
    thicker = RunConfig(preset="poster", viscosity=0.1, roughness=1e-5).params
    assert (base.viscosity, base.roughness) == (1e-3, 1e-6)
    assert (thicker.viscosity, thicker.roughness) == (0.1, 1e-5)
    contacts = SimpleNamespace(effective_radius=np.array([0.5e-3, 0.4e-3]), count=2)
    r_eff = contacts.effective_radius
    np.testing.assert_allclose(thicker.law("gluey").gamma_min(contacts),
                               6 * np.pi * 0.1 * r_eff**2 * np.log(1e-5 / r_eff), rtol=1e-12)
    np.testing.assert_allclose(base.law("gluey").gamma_min(contacts),
                               6 * np.pi * 1e-3 * r_eff**2 * np.log(1e-6 / r_eff), rtol=1e-12)
    with pytest.raises(ValueError, match="viscosity: only the poster preset"):
        RunConfig(viscosity=0.1)
    with pytest.raises(ValueError, match="roughness: must be > 0"):
        RunConfig(preset="poster", roughness=0.0)
    with pytest.raises(ValueError, match="roughness: must be below the smallest effective radius"):
        RunConfig(preset="poster", roughness=5e-4)             # r (1 - 0.2) / 2 = 4e-4


def test_seed_means_give_the_mean_and_the_spread_over_seeds():
    rows = [{"model": "dry", "angle": 20.0, "seed": s, "viscosity": None, "roughness": None,
             "flow_rate": q, "fraction_glued": None} for s, q in ((0, 1.0), (1, 2.0), (2, 6.0))]
    rows.append({"model": "dry", "angle": 22.0, "seed": 0, "viscosity": None, "roughness": None,
                 "flow_rate": 5.0})
    means = sweep.seed_means(rows)
    assert [(m["angle"], m["seeds"]) for m in means] == [(20.0, 3), (22.0, 1)]
    assert means[0]["flow_rate"] == pytest.approx(3.0)
    assert means[0]["flow_rate_sd"] == pytest.approx(np.sqrt(7.0))      # (4 + 1 + 9) / 2
    assert means[0]["flow_rate_se"] == pytest.approx(np.sqrt(7.0 / 3.0))
    assert np.isnan(means[0]["fraction_glued"]) and np.isnan(means[1]["flow_rate_sd"])
    rows[1]["flow_rate"] = float("nan")          # NaN (a fresh summary) is left out like None
    assert sweep.seed_means(rows)[0]["flow_rate"] == pytest.approx(3.5)


def test_a_seed_of_a_seed_sweep_is_the_plain_sweep_of_that_seed(tmp_path, capsys):
    """--seeds 0,2 puts each seed in seed_<k>/ with its own bed; the seed-2 runs are bit for bit
    the runs of --seed 2; sweep_means.csv averages the two seeds."""
    common = [*TINY, "--models", "dry", "--angles", "22", "--steps", "4"]
    assert flow_cli.sweep_main([*common, "--seeds", "0,2", "--out", str(tmp_path / "two")]) == 0
    assert flow_cli.sweep_main([*common, "--seed", "2", "--out", str(tmp_path / "one")]) == 0
    run = ("dry", "angle_22.00")
    two, one = final_state(tmp_path / "two" / "seed_2" / "dry" / run[1]), \
        final_state(tmp_path / "one" / "dry" / run[1])
    assert two.keys() == one.keys()
    for key in one:
        np.testing.assert_array_equal(two[key], one[key], err_msg=key)
    assert (tmp_path / "two" / "seed_0" / "bed.npz").exists()
    rows = read_csv(tmp_path / "two" / "sweep.csv")
    assert [row["seed"] for row in rows] == ["0", "2"]
    means = read_csv(tmp_path / "two" / "sweep_means.csv")
    rates = [float(row["flow_rate [d sqrt(g' d)]"]) for row in rows]
    assert len(means) == 1 and means[0]["seeds"] == "2"
    assert float(means[0]["flow_rate [d sqrt(g' d)]"]) == pytest.approx(np.mean(rates))
    assert float(means[0]["flow_rate_sd"]) == pytest.approx(np.std(rates, ddof=1))
    assert not (tmp_path / "one" / "sweep_means.csv").exists()
    for figure in ("flow_rate.png", "contact_states.png", "coordination.png"):
        assert (tmp_path / "two" / figure).exists()
    report = (tmp_path / "two" / "report.md").read_text()
    assert "lubcontact sweep" in report and "--seeds 0,2" in report
    assert f"| dry | 22 | - | - | 2 | 0 | {np.mean(rates):.4g} +/- " in report
    assert (tmp_path / "two" / "seed_2" / "dry" / "angle_22.00" / "snapshot.png").exists()


def test_a_viscosity_sweep_runs_each_viscosity_in_its_folder_with_its_glue(tmp_path, capsys):
    argv = [*TINY, "--preset", "poster", "--models", "gluey", "--angles", "20", "--steps", "2",
            "--viscosities", "1e-3,10", "--out", str(tmp_path)]
    assert flow_cli.sweep_main(argv) == 0
    rows = read_csv(tmp_path / "sweep.csv")
    assert [float(row["viscosity [Pa s]"]) for row in rows] == [1e-3, 10.0]
    for eta in ("eta_0.001", "eta_10"):
        stored = RunConfig.from_json(str(np.load(tmp_path / eta / "gluey" / "angle_20.00" /
                                                 "checkpoint.npz")["config"]))
        assert stored.viscosity == float(eta[4:])
    assert (tmp_path / "regime_map.png").exists()


# -- coordination ------------------------------------------------------------------------------------
def test_coordination_counts_both_ends_of_a_grain_grain_contact_and_one_of_a_bed_contact():
    """Three free grains (0, 1, 2), fixed bodies from 3 on: contacts (0,1) glued, (3,1) frictional,
    (1,2) frictional, (4,2) inactive."""
    gamma = np.array([-0.5, -1.0, -1.0, -2.0])
    active = np.array([True, True, True, False])
    masks = laws.GlueyCoulomb(0.3, gamma_min=-1.0).contact_states(SimpleNamespace(count=4), gamma,
                                                                 active)
    np.testing.assert_array_equal(masks.sum(axis=1), [0, 1, 2])
    a_is_free = np.array([0, 3, 1, 4]) < 3
    np.testing.assert_allclose(measure.coordination(masks, a_is_free, 3), [0.0, 2 / 3, 3 / 3])


# -- ramps -----------------------------------------------------------------------------------------
def test_a_ramp_goes_up_by_its_step_every_hold_then_back_down():
    config = hysteresis.ramp_config(RunConfig(sample_every=1), 14.0, 17.5, 1.5, 10)
    assert (config.ramp_stages, config.ramp_step, config.steps) == (2, 1.5, 50)
    angles = [config.ramp_stage(step) for step in (0, 9, 10, 19, 20, 29, 30, 39, 40, 49, 60)]
    assert angles == [(0, 14.0), (0, 14.0), (1, 15.5), (1, 15.5), (2, 17.0), (2, 17.0),
                      (3, 15.5), (3, 15.5), (4, 14.0), (4, 14.0), (4, 14.0)]
    with pytest.raises(ValueError, match="stop: must be at least one step"):
        hysteresis.ramp_config(RunConfig(sample_every=1), 20.0, 18.0, 1.0, 10)
    with pytest.raises(ValueError, match="sample_every: must be at most"):
        hysteresis.ramp_config(RunConfig(sample_every=5), 14.0, 16.0, 1.0, 20)
    with pytest.raises(ValueError, match="ramp_step: ramp_step and hold_steps need"):
        RunConfig(hold_steps=5)
    with pytest.raises(ValueError, match="steps: a ramp of 2 stages"):
        RunConfig(angle=14.0, ramp_step=1.0, ramp_stages=2, hold_steps=10, steps=40)
    with pytest.raises(ValueError, match="far end"):
        RunConfig(angle=80.0, ramp_step=5.0, ramp_stages=2, hold_steps=1, steps=5)
    with pytest.raises(ValueError, match="stop"):
        hysteresis.ramp_config(RunConfig(sample_every=1), 14.0, 14.5, 1.0, 10)


def test_a_ramp_run_tilts_gravity_by_stage_and_resumes_to_the_same_state(tmp_path):
    """Gravity follows the schedule (also after a resume); a ramp interrupted mid-way and resumed
    reaches the state of the uninterrupted ramp bit for bit; the sampled angles are the stages'."""
    config = RunConfig(n_grains=16, width=10.0, model="gluey", dt_fraction=0.05, settle_steps=10,
                       solver="clarabel", checkpoint_every=3, sample_every=1, angle=20.0,
                       ramp_step=2.0, ramp_stages=2, hold_steps=3, steps=15)
    scene = initial_scene(config, tmp_path)
    whole = FlowRun(config, scene, tmp_path / "whole")
    whole.advance(4)
    g = np.linalg.norm(whole.sim.scene.gravity)
    np.testing.assert_allclose(whole.sim.scene.gravity, inclined.tilted_gravity(g, 22.0))
    whole.finish()
    assert whole.series["angle"] == [20.0] * 3 + [22.0] * 3 + [24.0] * 3 + [22.0] * 3 + [20.0] * 3
    parted = FlowRun(config, scene, tmp_path / "parted")
    parted.advance(7)                  # checkpoint at step 6, in the top stage's hold
    resumed = FlowRun.resume(tmp_path / "parted" / "checkpoint.npz")
    resumed.finish()
    for key, value in final_state(tmp_path / "whole").items():
        np.testing.assert_array_equal(final_state(tmp_path / "parted")[key], value, err_msg=key)


def test_a_ramp_runs_progress_bar_names_the_angle_of_its_current_hold(tmp_path, capsys):
    """The bar named the ramp's first angle at every hold (a 2000-grain ascent's 18-degree hold
    showed '17 deg'), and so did the message of a run interrupted there."""
    config = RunConfig(n_grains=16, width=10.0, model="dry", dt_fraction=0.05, settle_steps=10,
                       solver="clarabel", sample_every=1, angle=20.0, ramp_step=2.0,
                       ramp_stages=1, hold_steps=3, steps=9)
    run = FlowRun(config, initial_scene(config, tmp_path), None)
    run.advance(3)
    capsys.readouterr()
    run.advance(4, progress=True)                  # the 22-degree hold, then back at 20
    bar = capsys.readouterr().err
    assert "inclined_flow dry 22 deg" in bar and "inclined_flow dry 20 deg" in bar
    assert bar.index("dry 22 deg") < bar.index("dry 20 deg")
    stopped = FlowRun(config, initial_scene(config, tmp_path), None)
    stopped.advance(6)                             # the last step done: the 22-degree hold's
    with interrupt.stop_on_signals():
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.1)                            # the handler runs in the main thread
        with pytest.raises(interrupt.Interrupted) as stop:
            stopped.advance(1)
    assert stop.value.what == "inclined_flow dry 22 deg" and stop.value.step == 6


def test_onset_angles_read_the_last_start_up_and_the_last_stop_down():
    """theta_start: the angle from which the layer flows at every later hold up (a transient
    just after the tilt does not count); theta_stop: the angle from which it stays still."""
    config = hysteresis.ramp_config(RunConfig(sample_every=1), 10.0, 14.0, 1.0, 8)
    velocity = {0: 0.02, 1: 2e-3, 2: 0.05, 3: 0.2, 4: 0.5, 5: 0.3, 6: 0.02, 7: 0.004, 8: 1e-5}
    steps = np.arange(1, config.steps + 1)

    def series(speeds):
        return {"step": steps, "mean_velocity": np.array([speeds[(k - 1) // 8] for k in steps])}

    holds = hysteresis.stages(series(velocity), config)
    assert [(h.leg, h.angle) for h in holds][:6] == [("up", 10.0), ("up", 11.0), ("up", 12.0),
                                                     ("up", 13.0), ("up", 14.0), ("down", 13.0)]
    assert hysteresis.onset_angles(holds, 0.01) == (12.0, 11.0)
    assert hysteresis.onset_angles(holds, 0.001) == (10.0, 10.0)
    start, stop = hysteresis.onset_angles(holds, 1.0)         # never flows
    assert np.isnan(start) and np.isnan(stop)
    moving = {**velocity, 6: 0.2, 7: 0.1, 8: 0.05}            # never stops on the way down
    start, stop = hysteresis.onset_angles(hysteresis.stages(series(moving), config), 0.01)
    assert start == 12.0 and np.isnan(stop)
    restart = {**velocity, 7: 0.004, 8: 0.02}                 # stops, then creeps again
    assert np.isnan(hysteresis.onset_angles(hysteresis.stages(series(restart), config), 0.01)[1])
    assert len(hysteresis.stages({"step": steps[:20], "mean_velocity": steps[:20]}, config)) == 2
    ramp = {"step": steps, "mean_velocity": 0.1 * config.dt_fraction * steps}    # v = 0.1 g' t
    np.testing.assert_allclose([h.acceleration for h in hysteresis.stages(ramp, config)], 0.1)
    sparse = {"step": steps[::7], "mean_velocity": steps[::7]}           # a hold's end unsampled
    with pytest.raises(ValueError, match="series: no sample in the first or the last"):
        hysteresis.stages(sparse, config)


def test_a_ramp_with_a_negative_step_goes_down_first():
    config = RunConfig(sample_every=1, angle=14.0, ramp_step=-1.0, ramp_stages=2, hold_steps=8,
                       steps=40)
    steps = np.arange(1, 41)
    holds = hysteresis.stages({"step": steps, "mean_velocity": np.ones(40)}, config)
    assert [(h.leg, h.angle) for h in holds] == [("down", 14.0), ("down", 13.0), ("down", 12.0),
                                                 ("up", 13.0), ("up", 14.0)]


def flowing_layer(tmp_path):
    """A 16-grain gluey layer flowing at 26 degrees after 8 steps, and its checkpoint (the
    start of the descents below)."""
    config = RunConfig(n_grains=16, width=10.0, model="gluey", dt_fraction=0.05, settle_steps=40,
                       solver="newton-ac", fixed_point=True, checkpoint_every=4, sample_every=1,
                       angle=26.0, steps=8)
    layer = FlowRun(config, initial_scene(config, tmp_path), tmp_path / "layer")
    layer.advance(8)
    layer.save_checkpoint()
    return layer, tmp_path / "layer" / "checkpoint.npz"


def test_a_descent_continues_a_flowing_layer_hold_by_hold_and_ends_at_a_still_hold(tmp_path):
    """The descent's first hold is the layer's own next steps (velocities, glue states and warm
    start carried over), the incline turns by the step every hold, a layer still at the end of
    a hold ends the descent there, and the same call again reads the descent back."""
    layer, checkpoint = flowing_layer(tmp_path)
    assert np.count_nonzero(layer.sim.state.pairs.gamma) >= 4      # glued contacts to carry over
    onward = FlowRun.resume(checkpoint, out_dir=tmp_path / "onward", steps=16)
    onward.advance(8)

    down = hysteresis.descent(checkpoint, tmp_path / "down", 26.0, 22.0, 2.0, 8, flow_speed=1e-9)
    assert [(h.leg, h.angle) for h in down.holds] == [("down", 26.0), ("down", 24.0),
                                                      ("down", 22.0)]
    assert np.isnan(down.theta_stop) and down.failure is None       # still flowing at 22
    assert sum(down.step_statuses.values()) == 24 and down.rescued_steps == 0
    series = FlowRun.resume(tmp_path / "down" / "checkpoint.npz").series
    assert series["angle"] == [26.0] * 8 + [24.0] * 8 + [22.0] * 8
    np.testing.assert_allclose(series["mean_velocity"][:8], onward.series["mean_velocity"][-8:],
                               rtol=1e-9)
    assert [row["leg"] for row in read_csv(tmp_path / "down" / "stages.csv")] == ["down"] * 3
    again = hysteresis.descent(checkpoint, tmp_path / "down", 26.0, 22.0, 2.0, 8, flow_speed=1e-9)
    assert [h.mean_velocity for h in again.holds] == [h.mean_velocity for h in down.holds]
    assert FlowRun.resume(tmp_path / "down" / "checkpoint.npz").steps_done == 24

    still = hysteresis.descent(checkpoint, tmp_path / "still", 26.0, 22.0, 2.0, 8, flow_speed=1e9)
    assert len(still.holds) == 1 and np.isnan(still.theta_stop)     # never flowed: no theta_stop
    assert still.holds[0].steps == 4                  # "at rest" from the first check, half way
    held = FlowRun.resume(tmp_path / "still" / "checkpoint.npz")
    assert held.steps_done == 4
    halfway = FlowRun.resume(checkpoint, out_dir=tmp_path / "halfway", steps=16)
    halfway.advance(4)
    np.testing.assert_allclose(held.sim.scene.grains.positions, halfway.sim.scene.grains.positions,
                               rtol=0, atol=1e-12)
    np.testing.assert_array_equal(held.sim.state.pairs.gamma, halfway.sim.state.pairs.gamma)
    with pytest.raises(ValueError, match="out_dir: .* holds a descent with other settings: "
                                         "hold_steps 8 [(]asked 16[)]"):
        hysteresis.descent(checkpoint, tmp_path / "down", 26.0, 22.0, 2.0, 16)
    with pytest.raises(ValueError, match="stop: must be at least one step"):
        hysteresis.descent(checkpoint, tmp_path / "up", 22.0, 26.0, 2.0, 8)
    with pytest.raises(ValueError, match="hold: must be an integer >= 1"):
        hysteresis.descent(checkpoint, tmp_path / "none", 26.0, 22.0, 2.0, 0)


def test_a_descent_ends_within_a_hold_once_the_layer_is_at_rest(tmp_path):
    """In a hold's second half (checked every third of the end window), once the mean velocity
    over the hold's end window (its last quarter of steps) falls below REST_FACTOR x flow_speed,
    the descent ends there: that hold is its last, shortened and still, and theta_stop is its
    angle; the same call reads it back."""
    _, checkpoint = flowing_layer(tmp_path)
    hold, window, part = 24, 6, 2                  # the end window, a third of it
    assert window == hysteresis.END_FRACTION * hold
    whole = hysteresis.descent(checkpoint, tmp_path / "whole", 26.0, 2.0, 8.0, hold,
                               flow_speed=1e-9)    # never still: every hold run to its end
    velocity = FlowRun.resume(tmp_path / "whole" / "checkpoint.npz").series["mean_velocity"]
    assert [h.angle for h in whole.holds] == [26.0, 18.0, 10.0, 2.0]   # slows down at 2 degrees

    def window_mean(step):                         # over the window ending after ``step`` steps
        return abs(np.mean(velocity[step - window:step]))

    # the first check of the rule (rest checks from half a hold on, then the hold's end) that
    # a threshold can make the first "at rest" while every earlier hold ended flowing
    checks = [k * hold + done for k in range(4) for done in [*range(hold // 2, hold, part), hold]]
    for index, step in enumerate(checks):
        threshold = 2.0 * window_mean(step) * (1.0 + 1e-9)
        earlier = checks[:index]
        if step > hold and step % hold and all(window_mean(c) > threshold / 2 for c in earlier) \
                and all(window_mean(c) > threshold for c in earlier if c % hold == 0):
            break
    else:
        pytest.fail("no threshold stops this descent within a hold")
    rest = hysteresis.descent(checkpoint, tmp_path / "rest", 26.0, 2.0, 8.0, hold,
                              flow_speed=threshold)
    stage, done = divmod(step, hold)
    assert [h.steps for h in rest.holds] == [hold] * stage + [done]
    assert rest.theta_stop == 26.0 - 8.0 * stage and rest.failure is None
    assert rest.holds[-1].mean_velocity == pytest.approx(np.mean(velocity[step - window:step]),
                                                         rel=1e-9)
    assert FlowRun.resume(tmp_path / "rest" / "checkpoint.npz").steps_done == step
    assert [int(row["steps"]) for row in read_csv(tmp_path / "rest" / "stages.csv")][-1] == done
    again = hysteresis.descent(checkpoint, tmp_path / "rest", 26.0, 2.0, 8.0, hold,
                               flow_speed=threshold)
    assert [h.steps for h in again.holds] == [h.steps for h in rest.holds]
    assert FlowRun.resume(tmp_path / "rest" / "checkpoint.npz").steps_done == step


def test_an_ascent_is_the_way_up_of_the_ramp_ended_once_the_layer_flows(tmp_path):
    """The ascent's holds are the ramp's way up (the same run step for step); it ends after
    ``confirm`` holds that end flowing, theta_start the first of them; the same call again
    reads it back."""
    config = RunConfig(n_grains=16, width=10.0, model="dry", dt_fraction=0.05, settle_steps=40,
                       solver="newton-ac", fixed_point=True, checkpoint_every=4, sample_every=1)
    ramp = hysteresis.ramp_config(config, 10.0, 40.0, 10.0, 8)
    whole = FlowRun(ramp, initial_scene(ramp, tmp_path), tmp_path / "ramp")
    whole.advance(32)
    way_up = hysteresis.stages(whole.series, ramp)
    speeds = [h.mean_velocity for h in way_up]
    assert max(speeds[:2]) < min(speeds[2:]) and speeds[2] < 0.8 * speeds[3]   # the bed starts
    threshold = 0.5 * (max(speeds[:2]) + speeds[2])

    up = hysteresis.ascent(config, tmp_path / "up", 10.0, 50.0, 10.0, 8, flow_speed=threshold)
    assert [(h.leg, h.angle) for h in up.holds] == [("up", 10.0), ("up", 20.0), ("up", 30.0),
                                                    ("up", 40.0)]         # not on to 50
    assert up.theta_start == 30.0 and up.failure is None
    np.testing.assert_allclose([h.mean_velocity for h in up.holds], speeds, rtol=1e-9)
    assert [row["flowing"] for row in read_csv(tmp_path / "up" / "stages.csv")] == \
        ["0", "0", "1", "1"]
    again = hysteresis.ascent(config, tmp_path / "up", 10.0, 50.0, 10.0, 8, flow_speed=threshold)
    assert again.theta_start == 30.0 and FlowRun.resume(
        tmp_path / "up" / "checkpoint.npz").steps_done == 32

    once = hysteresis.ascent(config, tmp_path / "up", 10.0, 50.0, 10.0, 8, confirm=1,
                             flow_speed=threshold)            # already past: read back
    assert once.theta_start == 30.0 and len(once.holds) == 4
    never = hysteresis.ascent(config, tmp_path / "never", 10.0, 20.0, 10.0, 8, flow_speed=1e9)
    assert len(never.holds) == 2 and np.isnan(never.theta_start)
    at_once = hysteresis.ascent(config, tmp_path / "at_once", 10.0, 30.0, 10.0, 8,
                                flow_speed=1e-9)
    assert len(at_once.holds) == 2 and np.isnan(at_once.theta_start)   # flowed from the start
    with pytest.raises(ValueError, match="out_dir: .* holds an ascent with other settings: "
                                         "model dry [(]asked gluey[)]"):
        hysteresis.ascent(replace(config, model="gluey"), tmp_path / "up", 10.0, 50.0, 10.0, 8)
    with pytest.raises(ValueError, match="confirm: must be an integer >= 1"):
        hysteresis.ascent(config, tmp_path / "none", 10.0, 50.0, 10.0, 8, confirm=0)
    with pytest.raises(ValueError, match="stop: must be at least one step"):
        hysteresis.ascent(config, tmp_path / "none", 30.0, 20.0, 10.0, 8)


def test_the_hysteresis_command_writes_one_row_per_model_and_seed(tmp_path, capsys):
    argv = [*TINY, "--models", "dry", "--seeds", "0,1", "--from", "18", "--to", "20", "--step",
            "2", "--hold", "8", "--sample-every", "1", "--out", str(tmp_path)]
    assert flow_cli.hysteresis_main(argv) == 0
    rows = read_csv(tmp_path / "hysteresis.csv")
    assert [(row["model"], row["seed"]) for row in rows] == [("dry", "0"), ("dry", "1")]
    stages = read_csv(tmp_path / "stages.csv")
    assert [row["leg"] for row in stages] == ["up", "up", "down"] * 2
    assert [float(row["angle [deg]"]) for row in stages] == [18.0, 20.0, 18.0] * 2
    assert (tmp_path / "ramp.png").exists() and (tmp_path / "seed_1" / "bed.npz").exists()
    out = capsys.readouterr().out
    assert "theta_start" in out and "hysteresis.csv" in out
    assert flow_cli.hysteresis_main(argv) == 0          # read back, not run again
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_:             # another hold: refused, naming --hold
        flow_cli.hysteresis_main([*argv[:-2], "--hold", "12", "--out", str(tmp_path)])
    assert exit_.value.code == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1 and "--hold 8" in lines[0] and "--hold 12" in lines[0], lines


# -- a step no method solves stops the run instead of being applied ------------------------------------
def test_a_step_that_fails_beyond_the_accepted_residual_stops_the_run_before_it_is_applied(tmp_path):
    """A failed step (here a solve reported inaccurate at residual 0.5) used to be applied with
    the run going on (a gluey run at 28 degrees went from Q = 5 to 114); now the run stops at
    the last good state, says why, and its summary says ``failed``; a sweep's means leave it
    out. A step below the accepted residual is applied and counted."""
    from dataclasses import replace as replace_result

    class Failing:
        """The run's settings, whose solves report ``inaccurate`` at a given residual."""

        def __init__(self, settings, residual):
            self.settings, self.residual = settings, residual

        def __getattr__(self, name):
            return getattr(self.settings, name)

        def solve(self, problem, *args, **kwargs):
            self.problem, self.warm_start = problem, args[0]
            result = self.settings.solve(problem, *args, **kwargs)
            return replace_result(result, status="inaccurate", residual=self.residual)

    config = RunConfig(n_grains=16, width=10.0, model="dry", dt_fraction=0.05, settle_steps=40,
                       solver="clarabel", checkpoint_every=2, sample_every=1, steps=6)
    run = FlowRun(config, initial_scene(config, tmp_path), tmp_path / "run")
    run.advance(2)
    settings = run.sim.settings
    run.sim.settings = Failing(settings, 1e-4)
    run.advance(1)                               # below 1e-3 per row: applied, counted
    assert run.steps_done == 3 and run.statuses["inaccurate"] == 1 and run.failure is None
    before = run.sim.scene.grains.positions.copy()
    run.sim.settings = failing = Failing(settings, 0.5)
    wall_before = run.wall_time
    run.advance(3)
    assert run.steps_done == 3 and run.failure.startswith("step 4: clarabel: status inaccurate")
    np.testing.assert_array_equal(run.sim.scene.grains.positions, before)
    with np.load(tmp_path / "run" / "checkpoint.npz") as data:   # the last good state, kept
        assert int(data["steps_done"]) == 3                       # (the last periodic one: 2)
        assert float(data["wall_time"]) == run.wall_time > wall_before   # the failed step's time
    assert failing.problem.n_contacts >= 5 and failing.warm_start is not None
    with np.load(tmp_path / "run" / "failed_step.npz") as data:   # the failed step, to reproduce
        for name, value in failing.problem.to_arrays().items():
            np.testing.assert_array_equal(data[name], value)
        np.testing.assert_array_equal(data["warm_start"], failing.warm_start)
        assert int(data["step"]) == 4 and str(data["failure"]) == run.failure
    summary = run.finish()
    assert summary["state"] == "failed" and summary["failure"] == run.failure
    rows = [{"model": "dry", "angle": 20.0, "flow_rate": 1.0, "state": "steady"},
            {"model": "dry", "angle": 20.0, "flow_rate": 90.0, "state": "failed"}]
    mean = sweep.seed_means(rows)[0]
    assert (mean["flow_rate"], mean["seeds"], mean["failed"]) == (1.0, 1, 1)


def test_a_step_rescued_by_clarabel_is_counted(tmp_path):
    """A step whose fast solve ends above the failure threshold is solved again by Clarabel and
    applied: the run goes on and counts it (summary, checkpoint), instead of stopping."""
    config = RunConfig(n_grains=16, width=10.0, model="dry", dt_fraction=0.05, settle_steps=40,
                       solver="apgd-jacobi", checkpoint_every=2, sample_every=1, steps=6)
    run = FlowRun(config, initial_scene(config, tmp_path), tmp_path / "run")
    run.advance(2)
    assert run.rescued == 0 and run.last_report.contacts.count >= 5
    run.sim.settings = replace(run.sim.settings, max_iter=1)     # one iteration: far off
    run.sim.max_residual = 1e-12
    summary = run.finish()
    assert run.failure is None and run.steps_done == 6
    assert run.rescued == 4 and summary["rescued_steps"] == 4          # every step after
    assert run.statuses.get("converged", 0) == 6          # Clarabel's status, counted
    assert FlowRun.resume(tmp_path / "run" / "checkpoint.npz").rescued == run.rescued


# -- runs from a developed flow -----------------------------------------------------------------------
def test_a_sweep_starts_each_run_from_its_model_and_seeds_developed_state(tmp_path, capsys,
                                                                          monkeypatch):
    """``--start-from`` with {model} and {seed}: each run is that state tilted to its angle, the
    grains still moving (the 2000-grain protocol of the records, by hand before), no bed settled."""
    layer, _ = flowing_layer(tmp_path / "gluey-seed0")
    start = tmp_path / "{model}-seed{seed}" / "layer" / "checkpoint.npz"
    argv = ["--n", "16", "--width", "10", "--dt", "0.05", "--solver", "newton-ac",
            "--fixed-point", "--checkpoint-every", "4", "--sample-every", "1", "--steps", "4",
            "--average-from", "0.25", "--models", "gluey", "--angles", "22", "--seeds", "0",
            "--start-from", str(start), "--no-progress", "--out", str(tmp_path / "sweep")]
    assert flow_cli.sweep_main(argv) == 0
    run_dir = tmp_path / "sweep" / "seed_0" / "gluey" / "angle_22.00"
    stored = FlowRun.resume(run_dir / "checkpoint.npz")
    assert stored.config.start_from == str(tmp_path / "gluey-seed0" / "layer" / "checkpoint.npz")
    assert stored.config.average_from == 0.25 and stored.config.bed == ""
    assert not list((tmp_path / "sweep").rglob("bed.npz"))

    scene = layer.sim.scene.copy()                       # the protocol written out by hand
    inclined.tilt(scene, 22.0)
    by_hand = FlowRun(replace(stored.config, start_from=""), scene)
    by_hand.advance(4)
    np.testing.assert_array_equal(stored.sim.scene.grains.positions,
                                  by_hand.sim.scene.grains.positions)
    first = stored.series["mean_velocity"][0]
    assert first > 0.5 * measure.mean_velocity(layer.sim.scene) > 0    # still moving at step 1

    # the same sweep again, the state's path spelled relative: read back, not refused
    relative = [a if a != str(start) else str(start.relative_to(tmp_path)) for a in argv]
    monkeypatch.chdir(tmp_path)
    assert flow_cli.sweep_main(relative) == 0
    assert len(read_csv(tmp_path / "sweep" / "sweep.csv")) == 1
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_:          # another window: refused, not mixed
        flow_cli.sweep_main([*relative, "--average-from", "0.5"])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "--average-from 0.25 (here: --average-from 0.5)" in err


def test_a_widened_start_lays_the_state_side_by_side_and_each_seed_parts_the_copies(tmp_path):
    """``--widen 3`` with ``--start-from``: three copies of the layer side by side (positions
    shifted by the period, the bed tiled), their velocities jittered by 1e-3 of the rms with the
    run's seed (the records' 2000-grain protocol, by hand before), the same for the same seed,
    not for another; the run then flows on the wide layer."""
    layer, checkpoint = flowing_layer(tmp_path)
    small = dict(n_grains=48, width=30.0, model="gluey", dt_fraction=0.05, solver="newton-ac",
                 fixed_point=True, checkpoint_every=2, sample_every=1, angle=20.0, steps=2,
                 start_from=str(checkpoint), widen=3)
    scenes = {seed: initial_scene(RunConfig(**small, seed=seed)) for seed in (1, 2)}
    again = initial_scene(RunConfig(**small, seed=1))
    source = layer.sim.scene
    period = source.period
    wide = scenes[1]
    assert wide.grains.count == 48 and np.isclose(wide.period, 3 * period)
    for copy in range(3):
        part = slice(16 * copy, 16 * (copy + 1))
        np.testing.assert_allclose(wide.grains.positions[part, 0],
                                   source.grains.positions[:, 0] + copy * period, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(wide.grains.radii[part], source.grains.radii)
    bed = source.fixed_positions
    np.testing.assert_allclose(wide.fixed_positions, np.concatenate(
        [bed + [copy * period, 0.0] for copy in range(3)]), rtol=0, atol=1e-12)
    rms = np.sqrt(np.mean(np.sum(source.grains.velocities**2, axis=1)))
    kick = wide.grains.velocities - np.tile(source.grains.velocities, (3, 1))
    assert 0 < np.abs(kick).max() < 5e-3 * rms and 0.5e-3 < np.std(kick) / rms < 2e-3
    np.testing.assert_array_equal(again.grains.velocities, wide.grains.velocities)
    assert not np.array_equal(scenes[2].grains.velocities, wide.grains.velocities)
    assert np.allclose(wide.gravity, inclined.tilted_gravity(np.linalg.norm(wide.gravity), 20.0))
    run = FlowRun(RunConfig(**small, seed=1), wide, tmp_path / "wide")
    run.advance(2)
    assert run.steps_done == 2 and run.series["mean_velocity"][-1] > 0


def test_widen_errors_name_the_field_or_the_flag(tmp_path, capsys):
    """``widen`` without a state to widen, below 1, or copies that do not make the run's grains
    and width: a ValueError naming the field, one line naming the flag on the command line."""
    _, checkpoint = flowing_layer(tmp_path)
    with pytest.raises(ValueError, match="widen: only a run's state"):
        RunConfig(widen=2)
    with pytest.raises(ValueError, match="widen: must be >= 1, got 0"):
        RunConfig(widen=0, start_from=str(checkpoint))
    common = ["inclined_flow", "--start-from", str(checkpoint), "--steps", "2", "--dt", "0.05",
              "--no-progress", "--out", str(tmp_path / "run")]
    cases = {"argument --start-from: ": [*common, "--n", "32", "--width", "30", "--widen", "2"],
             "argument --widen: must be >= 1": [*common, "--widen", "0"],
             "argument --widen: only a run's state": ["inclined_flow", "--widen", "2", "--out",
                                                     str(tmp_path / "run2"), "--no-progress"]}
    for said, argv in cases.items():
        with pytest.raises(SystemExit) as exit_:
            flow_cli.run_main(argv)
        err = capsys.readouterr().err.strip()
        assert exit_.value.code == 2 and len(err.splitlines()) == 1 and said in err, err
    message = str(pytest.raises(ValueError, initial_scene, RunConfig(
        n_grains=32, width=30.0, start_from=str(checkpoint), widen=2)).value)
    assert "times 2 copies" in message and "(n_grains, width, widen)" in message
    with pytest.raises(SystemExit):                  # the help's jitter is the one applied
        flow_cli.run_main(["--help"])
    said = " ".join(capsys.readouterr().out.split()).partition("velocity jitter of ")[2]
    assert float(said.split()[0]) == inclined.PARTING_JITTER and said.split()[1:3] == ["of", "the"]


def test_the_window_command_prints_each_runs_window_statistics(tmp_path, capsys):
    """``lubcontact window RUN --length L``: each run's mean, block error, trend and block means
    over its last L steps, as ``measure.window_statistics`` gives them from the checkpoint's
    series, and the flow's verdict over the window (``measure.classify_flow``); a run that has
    not reached ``--end``, a window not a whole number of blocks and a folder without a
    checkpoint are one line naming the argument, before anything is printed."""
    layer, checkpoint = flowing_layer(tmp_path)
    with np.load(checkpoint) as data:
        expected = measure.window_statistics(data["series.step"], data["series.flow_rate"], 8, 8,
                                             blocks=4)
        inside = (data["series.step"] > 0) & (data["series.step"] <= 8)
        state = measure.classify_flow(data["series.time"][inside],
                                      data["series.kinetic_energy"][inside],
                                      data["series.flow_rate"][inside], window=1.0)
    assert flow_cli.window_main([str(tmp_path / "layer"), "--length", "8", "--blocks", "4"]) == 0
    row = capsys.readouterr().out.splitlines()[1].split()
    assert row[:4] == [str(tmp_path / "layer"), "8", "(0,", "8]"]
    assert float(row[4]) == pytest.approx(expected.mean, rel=1e-3)
    assert float(row[5]) == pytest.approx(expected.standard_error, rel=1e-1)
    assert float(row[6]) == pytest.approx(expected.trend, rel=1e-2, abs=1e-12)
    assert row[7] == state.label and row[8].endswith("%")
    assert float(row[8][:-1]) == pytest.approx(100 * state.relative_change, abs=0.051)
    np.testing.assert_allclose([float(v) for v in row[9:]], expected.blocks, rtol=1e-3)
    assert flow_cli.window_main([str(checkpoint), "--length", "2", "--blocks", "2"]) == 0
    assert capsys.readouterr().out.splitlines()[1].split()[7:9] == ["-", "-"]   # too few samples
    cases = {"argument --end: ": ["--length", "4", "--end", "12"],
             "argument --length: ": ["--length", "6", "--blocks", "4"]}
    for said, options in cases.items():
        with pytest.raises(SystemExit) as exit_:
            flow_cli.window_main([str(checkpoint), *options])
        out, err = capsys.readouterr()
        assert exit_.value.code == 2 and out == "" and said in err and len(err.splitlines()) == 1
    (tmp_path / "notes.npz").write_text("not an archive")
    data = dict(np.load(checkpoint))
    data["series.mean_velocity"][-2:] = np.nan            # a series newer than the checkpoint
    np.savez(tmp_path / "older.npz", **data)
    window = ["--length", "4", "--blocks", "2"]
    bad = {"argument RUN: no such file or folder": [str(tmp_path / "none"), *window],
           "argument RUN: ": [str(tmp_path / "notes.npz"), *window],
           "argument --series: ": [str(tmp_path / "older.npz"), *window, "--series", "mean_velocity"],
           "starts before": ["--length", "10", "--blocks", "2"]}
    for said, arguments in bad.items():
        with pytest.raises(SystemExit) as exit_:          # the first run is fine: nothing printed
            flow_cli.window_main([str(checkpoint), *arguments])
        out, err = capsys.readouterr()
        assert exit_.value.code == 2 and out == "" and said in err and len(err.splitlines()) == 1
    data["series.mean_velocity"][:] = 1.0
    data["series.mean_velocity"][:2] = np.nan             # NaN before the window only: read
    np.savez(tmp_path / "older.npz", **data)
    assert flow_cli.window_main([str(tmp_path / "older.npz"), "--length", "4", "--blocks", "2",
                                 "--series", "mean_velocity"]) == 0
    assert capsys.readouterr().out.splitlines()[1].split()[4:7] == ["1.000", "0", "+0"]


def synthetic_run(tmp_path, name, checkpoint, **series):
    """A copy of ``checkpoint`` with its series replaced: steps 5..4000 every 5, the given
    series (functions of the step), the others constant."""
    data = dict(np.load(checkpoint))
    steps = np.arange(5, 4001, 5)
    data.update({"series.step": steps, "series.time": 0.01 * steps, "steps_done": np.array(4000),
                 "series.kinetic_energy": np.ones(steps.size),
                 "series.mean_velocity": np.full(steps.size, 2.0)})
    data.update({f"series.{key}": function(steps) for key, function in series.items()})
    np.savez(tmp_path / name, **data)
    return str(tmp_path / name)


def test_the_window_commands_verdict_is_the_windows_with_the_runs_peak_energy(tmp_path, capsys):
    """The verdict column: ``measure.classify_flow`` on the window's halves, except that a run
    whose energy fell below 1e-6 of its largest so far is ``no_flow`` (its flow-rate noise
    is not an acceleration); fewer than four samples, or a checkpoint without the energy
    series, give no verdict."""
    _, checkpoint = flowing_layer(tmp_path)
    stopped = synthetic_run(
        tmp_path, "stopped.npz", checkpoint,
        kinetic_energy=lambda step: np.where(step <= 2000, 1.0, 1e-20),
        flow_rate=lambda step: np.where(step <= 2000, 10.0 + 0.01 * step,
                                        1e-14 * np.sin(step)))

    def verdict(*arguments):
        assert flow_cli.window_main([stopped, *arguments]) == 0
        return capsys.readouterr().out.splitlines()[1].split()[7:9]

    assert verdict("--length", "1000")[0] == "no_flow"
    steps = np.arange(1005, 2001, 5)
    state = measure.classify_flow(0.01 * steps, np.ones(steps.size), 10.0 + 0.01 * steps,
                                  window=1.0)
    label, change = verdict("--length", "1000", "--end", "2000")
    assert label == state.label == "accelerating"
    assert float(change[:-1]) == pytest.approx(100 * state.relative_change, abs=0.051)
    assert verdict("--length", "15", "--blocks", "3", "--end", "2000") == ["-", "-"]
    assert verdict("--length", "20", "--blocks", "2", "--end", "2000")[0] == "steady"   # 4 samples
    data = dict(np.load(stopped))
    del data["series.kinetic_energy"]
    np.savez(tmp_path / "older.npz", **data)
    assert flow_cli.window_main([str(tmp_path / "older.npz"), "--length", "1000"]) == 0
    assert capsys.readouterr().out.splitlines()[1].split()[7:9] == ["-", "-"]


def test_the_window_command_fits_the_approach_of_the_block_means(tmp_path, capsys):
    """``--approach``: the limit and time constant of ``measure.fit_approach`` on the window's
    block means ('-' where there is no approach), after the verdict; fewer than 4 blocks name
    ``--blocks``."""
    _, checkpoint = flowing_layer(tmp_path)
    data = dict(np.load(checkpoint))
    steps = np.arange(5, 6001, 5)
    data.update({"series.step": steps, "series.time": 0.01 * steps,
                 "series.kinetic_energy": np.ones(steps.size), "steps_done": np.array(6000),
                 "series.flow_rate": 100.0 - 40.0 * np.exp(-steps / 1500.0),
                 "series.mean_velocity": np.full(steps.size, 2.0)})
    np.savez(tmp_path / "approach.npz", **data)
    arguments = [str(tmp_path / "approach.npz"), "--length", "5000", "--blocks", "10",
                 "--approach"]
    assert flow_cli.window_main(arguments) == 0
    header, row = capsys.readouterr().out.splitlines()
    assert header.split()[9:12] == ["limit", "s.e.", "tau"]
    assert row.split()[7] == "accelerating" and float(row.split()[9]) == pytest.approx(100.0)
    assert float(row.split()[11]) == pytest.approx(1500.0) and float(row.split()[10]) < 1e-6
    assert flow_cli.window_main([*arguments, "--series", "mean_velocity"]) == 0
    assert capsys.readouterr().out.splitlines()[1].split()[9:12] == ["-", "-", "-"]
    with pytest.raises(SystemExit) as exit_:
        flow_cli.window_main([*arguments[:3], "--blocks", "2", "--approach"])
    out, err = capsys.readouterr()
    assert exit_.value.code == 2 and out == "" and "argument --blocks: " in err


def test_the_window_command_offers_every_series_a_run_samples():
    from lubcontact.flow.run import SERIES

    assert sorted(flow_cli.WINDOW_SERIES) == sorted(set(SERIES) - {"step"})


def test_start_from_errors_are_one_line_naming_the_flag(tmp_path, capsys):
    """A missing state, a bed instead of a run's checkpoint, another number of grains, an
    unknown placeholder and a sedimentation from a state: each one line naming --start-from."""
    _, checkpoint = flowing_layer(tmp_path)
    bed = tmp_path / "bed.npz"
    common = ["--n", "16", "--width", "10", "--dt", "0.05", "--steps", "2", "--no-progress",
              "--models", "gluey", "--angles", "20"]
    (tmp_path / "text.npz").write_text("not an archive")
    np.save(tmp_path / "array.npy", np.zeros(3))
    cases = {"no such file": [*common, "--start-from", str(tmp_path / "none.npz")],
             "not a run's checkpoint": [*common, "--start-from", str(bed)],
             "text.npz is not a run's checkpoint": [*common, "--start-from",
                                                    str(tmp_path / "text.npz")],
             "array.npy is not a run's checkpoint": [*common, "--start-from",
                                                     str(tmp_path / "array.npy")],
             "holds 16 grains": [*common[:1], "17", *common[2:], "--start-from", str(checkpoint)],
             "placeholders are {model} and {seed}": [*common, "--start-from",
                                                     str(tmp_path / "{angle}.npz")],
             "a literal brace is written twice": [*common, "--start-from",
                                                  str(tmp_path / "{model.x}.npz")]}
    for number, (said, argv) in enumerate(cases.items()):
        with pytest.raises(SystemExit) as exit_:
            flow_cli.sweep_main([*argv, "--out", str(tmp_path / f"sweep{number}")])
        err = capsys.readouterr().err.strip()
        assert exit_.value.code == 2 and len(err.splitlines()) == 1, err
        assert "argument --start-from: " in err and said in err, err
    for argv in (["sedimentation", "--start-from", str(checkpoint)],
                 ["inclined_flow", "--start-from", str(checkpoint), "--bed", str(bed)]):
        with pytest.raises(SystemExit) as exit_:
            flow_cli.run_main([*argv, "--out", str(tmp_path / "run")])
        err = capsys.readouterr().err.strip()
        assert exit_.value.code == 2 and "argument --start-from: " in err, err
        assert len(err.splitlines()) == 1
    with pytest.raises(ValueError, match="start_from: an angle ramp starts from a bed at rest"):
        hysteresis.ramp_config(replace(RunConfig(sample_every=1), start_from=str(checkpoint)),
                               20, 22, 1, 8)


def test_a_resumed_run_keeps_its_averaging_window(tmp_path, capsys):
    """--average-from cannot change on --resume: the profiles were accumulated over the old
    window (one line naming the flag)."""
    out = tmp_path / "run"
    small = ["--n", "16", "--width", "10", "--dt", "0.05", "--settle-steps", "10", "--solver",
             "clarabel", "--checkpoint-every", "2", "--sample-every", "1", "--no-progress"]
    assert flow_cli.run_main(["inclined_flow", "--steps", "4", "--average-from", "0.25",
                              "--out", str(out), *small]) == 0
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_:
        flow_cli.run_main(["--resume", "--steps", "6", "--average-from", "0.5", "--out",
                           str(out)])
    err = capsys.readouterr().err.strip()
    assert exit_.value.code == 2 and err.count("\n") == 0
    assert "argument --average-from: the checkpoint's run averages from 0.25" in err
    assert flow_cli.run_main(["--resume", "--steps", "6", "--average-from", "0.25", "--out",
                              str(out)]) == 0
