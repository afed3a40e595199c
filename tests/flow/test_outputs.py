"""What the flow experiment writes: strict JSON, rounded text, folders, units, sedimentation labels."""
import csv
import functools
import json
import math
import pathlib

import numpy as np
import pytest
from matplotlib.colors import to_hex

from lubcontact.flow import cli as flow_cli
from lubcontact.flow import demo as flow_demo
from lubcontact.flow import measure, plots
from lubcontact.flow.bed import initial_scene
from lubcontact.flow.config import RunConfig
from lubcontact.flow.run import FlowRun, frame_arrays

SMALL = ["--n", "24", "--width", "12", "--dt", "0.05", "--settle-steps", "0", "--solver",
         "clarabel", "--checkpoint-every", "3", "--sample-every", "3", "--no-progress"]
Q_UNIT = "d sqrt(g' d)"


def strict(text):
    """``json.loads`` that refuses NaN and infinities (not JSON)."""
    def refuse(constant):
        raise ValueError(f"not JSON: {constant}")
    return json.loads(text, parse_constant=refuse)


@pytest.fixture
def figures(monkeypatch):
    """The figures the flow code saves, by file name (not written)."""
    saved = {}

    def keep(fig, path):
        saved[path.name] = fig
    monkeypatch.setattr(plots, "_save", keep)
    return saved


# -- defect 3: output hygiene ---------------------------------------------------------------------
def test_summary_json_is_strict_json(tmp_path, capsys):
    """No cross-checks: max_cross_check has no value; it is written null, not NaN."""
    out = tmp_path / "run"
    assert flow_cli.run_main(["inclined_flow", "--model", "dry", "--steps", "6", "--out", str(out),
                              *SMALL]) == 0
    summary = strict((out / "summary.json").read_text())
    assert summary["max_cross_check"] is None
    printed = capsys.readouterr().out
    assert strict(printed[printed.index("{"):])["max_cross_check"] is None


def test_demo_flow_files_land_in_out_flow(tmp_path, monkeypatch):
    """``lubcontact demo`` hands ``out/flow`` to the flow demo: no ``out/flow/flow``."""
    from lubcontact import demo as main_demo
    monkeypatch.setattr(flow_demo, "demo", functools.partial(
        flow_demo.demo, n_grains=24, steps=10, settle_steps=20, width=12.0))
    main_demo.flow_section(tmp_path)
    folder = tmp_path / "flow"
    for name in ("checkpoint.npz", "summary.json", "bed.npz", "flow_report.md", "flow_snapshot.png"):
        assert (folder / name).is_file(), name
    assert not (folder / "flow").exists()


def test_summary_lines_round_floats():
    """The text lines of a summary (``out/summary.txt``) show 4 significant digits."""
    summary = {"flow_rate": 0.123456789123, "max_cross_check": 1.23456789e-9, "state": "steady",
               "unconverged_steps": 0, "energy_ratio": float("nan"), "wall_time": 12.3456789,
               "step_statuses": {"converged": 25}, "units": {"flow_rate": Q_UNIT}}
    text = "\n".join(flow_demo.summary_lines(summary))
    assert "flow_rate: 0.1235" in text and "1.235e-09" in text and "wall_time: 12.35" in text
    assert "state: steady" in text and "converged" in text and "energy_ratio: n/a" in text
    assert "123456" not in text and "nan" not in text


# -- defect 4: units ------------------------------------------------------------------------------
def test_flow_rate_is_in_units_of_d_sqrt_gd(tmp_path):
    config = RunConfig(scene="inclined_flow", n_grains=24, width=12.0, model="dry", angle=25.0,
                       steps=12, dt_fraction=0.05, settle_steps=0, solver="clarabel", sample_every=3)
    run = FlowRun(config, initial_scene(config))
    run.advance(12)
    params = config.params
    unit = 2.0 * params.radius * np.sqrt(2.0 * params.radius * params.reduced_gravity)
    assert unit != pytest.approx(1.0)
    assert run.series["flow_rate"][-1] == pytest.approx(measure.flow_rate(run.sim.scene) / unit,
                                                        rel=1e-12)
    summary = run.summary()
    assert summary["units"]["flow_rate"] == Q_UNIT
    assert "sqrt(d/g')" in summary["units"]["dt_fraction"]
    report = flow_demo.demo_report(summary, config)
    assert Q_UNIT in report and "r^2" not in report and "sqrt(d/g')" in report


def test_sweep_table_csv_and_figure_share_the_unit(tmp_path, capsys, figures):
    out = tmp_path / "sweep"
    assert flow_cli.sweep_main(["--angles", "24", "--models", "dry", "--steps", "9", "--out",
                                str(out), *SMALL]) == 0
    console = capsys.readouterr().out
    assert Q_UNIT in console
    with open(out / "sweep.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    column = f"flow_rate [{Q_UNIT}]"
    assert column in rows[0] and f"flow_rate_std [{Q_UNIT}]" in rows[0]
    summary = json.loads((out / "dry" / "angle_24.00" / "summary.json").read_text())
    assert float(rows[0][column]) == pytest.approx(summary["flow_rate"], rel=1e-9)
    axis = figures["flow_rate.png"].axes[0]
    assert axis.get_ylabel() == f"flow rate Q / ({Q_UNIT})"
    plotted = np.asarray(axis.containers[0].lines[0].get_ydata(), dtype=float)   # the curve
    np.testing.assert_allclose(plotted, [summary["flow_rate"]], rtol=1e-12)


def test_a_sedimentation_run_records_and_shows_no_angle(tmp_path, capsys, figures):
    out = tmp_path / "sed"
    assert flow_cli.run_main(["sedimentation", "--model", "frictionless", "--steps", "6",
                              "--out", str(out), *SMALL]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert "angle" not in summary or summary["angle"] is None
    with np.load(out / "checkpoint.npz") as data:
        assert RunConfig.from_json(str(data["config"])).angle is None
    snapshot = figures["snapshot.png"].axes[0]
    assert "theta" not in snapshot.get_title() and "deg" not in snapshot.get_title()
    labels = [ax.get_xlabel() + " | " + ax.get_ylabel()
              for fig in figures.values() for ax in fig.axes]
    assert not any("downhill" in label or "incline" in label for label in labels), labels
    assert snapshot.get_xlabel().startswith("x / d") and snapshot.get_ylabel().startswith("z / d")
    profile = figures["profile.png"].axes[0]
    assert profile.get_ylabel().startswith("z / d")
    legend = [t.get_text() for t in profile.get_legend().get_texts()]
    assert not any("deg" in t for t in legend), legend
    # --angle means nothing to a sedimentation: refused, naming the flag
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_:
        flow_cli.run_main(["sedimentation", "--angle", "20", "--steps", "3", "--out",
                           str(tmp_path / "other"), *SMALL])
    assert exit_.value.code == 2 and "--angle" in capsys.readouterr().err
    assert math.isfinite(summary["flow_rate"])


def test_the_snapshot_shows_the_bed_and_gravity_and_fractions_stay_off_the_frame(tmp_path,
                                                                                 monkeypatch):
    """The flow snapshot has a legend naming the fixed bed and an arrow along gravity; the
    contact-state fractions (often exactly 0 or 1) are not drawn on the frame of the axes."""
    saved = []
    monkeypatch.setattr(plots, "_save", lambda fig, path: saved.append(fig))
    flow_demo.demo(tmp_path / "flow", n_grains=30, steps=4, settle_steps=30)
    snapshot = next(fig for fig in saved if "grains" in fig.axes[0].get_title())
    ax = snapshot.axes[0]
    labels = [text.get_text() for text in ax.get_legend().get_texts()]
    assert labels[0] == "grains" and "fixed bed" in labels[1]
    arrows = [child for child in ax.texts if child.get_text() == "g"]
    assert len(arrows) == 1 and any(patch.arrow_patch is not None for patch in ax.texts
                                    if hasattr(patch, "arrow_patch"))
    plots.state_fractions([{"model": "gluey", "angle": 20.0, "fraction_unglued": 0.0,
                            "fraction_glued": 1.0, "fraction_frictional": 0.0}], tmp_path / "s.png")
    low, high = saved[-1].axes[0].get_ylim()
    assert low < 0.0 and high > 1.0


def test_a_resumed_run_draws_the_contacts_of_its_last_step(tmp_path, figures):
    """A run resumed from its checkpoint, no step taken since, draws and exports the contacts of
    its last step: the same pairs, glue states and impulses, found again from the state (its
    snapshot had no contacts before, a sweep run read back at its last step drew bare grains)."""
    config = RunConfig(n_grains=16, width=10.0, model="gluey", dt_fraction=0.05, settle_steps=40,
                       solver="newton-ac", fixed_point=True, checkpoint_every=4, sample_every=1,
                       angle=26.0, steps=8)
    run = FlowRun(config, initial_scene(config, tmp_path), tmp_path / "run")
    assert run.sim.last_contacts() is None                   # no step yet: nothing to draw
    run.advance(8)
    run.save_checkpoint()
    resumed = FlowRun.resume(tmp_path / "run" / "checkpoint.npz")
    assert resumed.last_report is None and resumed.steps_done == 8
    stepped = plots.contact_segments(run.sim, *run.sim.last_contacts(run.last_report))
    found = plots.contact_segments(resumed.sim, *resumed.sim.last_contacts())
    assert len(stepped[0]) >= 6 and np.count_nonzero(stepped[1]) >= 2   # glued pairs among them
    np.testing.assert_array_equal(found[0], stepped[0])
    np.testing.assert_array_equal(found[1], stepped[1])
    plots.snapshot(resumed.sim, None, tmp_path / "snapshot.png")
    drawn = figures["snapshot.png"].axes[0].collections[-1]
    np.testing.assert_array_equal(drawn.get_array(), stepped[1])

    def active(frame):
        on = (frame["contact_gamma"] < 0) | (frame["contact_force"] > 0)
        return set(zip(*(frame[name][on].tolist() for name in (
            "contact_a", "contact_b", "contact_gamma", "contact_force"))))
    assert active(frame_arrays(resumed.sim, None)) == active(frame_arrays(run.sim, run.last_report))


def test_a_snapshot_colours_contacts_by_their_glue_level(tmp_path, figures):
    """Dry Coulomb contacts are frictional (level 1; they were drawn 'lubricated' on a scale
    from -1e-30 to 0); gluey ones run from 0 (lubricated) to 1 (at their own gamma_min)."""
    for model in ("dry", "gluey"):
        config = RunConfig(n_grains=16, width=10.0, model=model, dt_fraction=0.05,
                           settle_steps=40, solver="newton-ac", fixed_point=True, angle=26.0,
                           steps=8)
        run = FlowRun(config, initial_scene(config, tmp_path / model))
        run.advance(8)
        plots.snapshot(run.sim, run.last_report, tmp_path / f"{model}.png")
        drawn = figures[f"{model}.png"].axes[0].collections[-1]
        level = np.asarray(drawn.get_array())
        assert drawn.get_clim() == (0.0, 1.0) and level.size >= 6
        contacts, gamma, normal = run.sim.last_contacts(run.last_report)
        _, glued, frictional = run.sim.law.contact_states(contacts, gamma,
                                                          (gamma < 0) | (normal > 0))
        if model == "dry":
            np.testing.assert_array_equal(level, 1.0)
        else:
            partial = (level > 0) & (level < 1)
            assert np.count_nonzero(level == 1.0) >= 1 and np.count_nonzero(partial) >= 1
            floor = run.sim.law.gamma_min(contacts)
            np.testing.assert_allclose(np.sort(level[partial]), np.sort(
                (gamma / floor)[glued & (contacts.body_a < 16 + len(run.sim.scene.fixed_radii))
                                & (gamma > floor)]))


def test_fourteen_angles_get_fourteen_colours(tmp_path, figures):
    """A sweep's profiles and gamma histograms over 15-28 degrees: one colour per angle (the
    ten-colour cycle gave 15 and 25 degrees the same blue)."""
    edges = np.linspace(0.0, 10.0, 11)
    prof = measure.Profile(edges, np.full(10, 0.8), np.linspace(0.0, 5.0, 10))
    params = RunConfig(preset="poster").params
    plots.profiles([(f"{a} deg", prof) for a in range(15, 29)], pathlib.Path("p.png"),
                   params)
    runs = []
    for angle in range(15, 29):
        np.savez(tmp_path / f"{angle}.npz", gamma_histogram=np.arange(1, 5))
        runs.append((f"{angle} deg", tmp_path / f"{angle}.npz"))
    plots.gamma_histograms(runs, pathlib.Path("g.png"))
    for ax in figures["p.png"].axes:
        assert len({to_hex(line.get_color()) for line in ax.get_lines()}) == 14
    stairs = figures["g.png"].axes[0].patches
    assert len(stairs) == 14 and len({to_hex(step.get_edgecolor()) for step in stairs}) == 14
