"""Exact solutions of docs/guide/model.md section 7, frictionless laws, stepped with Clarabel."""
from functools import cache

import numpy as np
import pytest

from lubcontact import GlueyLubrication, Inelastic, Simulation, scenes


def run_recording_gamma(scene, law, dt, t_end, d_max=0.02):
    """Run to ``t_end``; return times, positions, velocities and the glue state per step."""
    sim = Simulation(scene, law, dt, d_max=d_max)
    gamma = []
    sim.run(int(round(t_end / dt)),
            callback=lambda s, report: gamma.append(report.gamma.min() if report.gamma.size else 0.0))
    record = sim.trajectory.arrays()
    return record["times"], record["positions"], record["velocities"], np.array(gamma)


def unglue_time(times, gamma, after):
    """End time of the first step after ``after`` whose glue state is back to exactly 0."""
    step_end = times[1:]
    free = (gamma == 0.0) & (step_end > after)
    return step_end[np.argmax(free)]


@cache
def push_pull(dt):
    return run_recording_gamma(scenes.push_pull(), GlueyLubrication(), dt, t_end=5.0)


@pytest.fixture(params=[1e-2, 1e-3], ids=["dt=1e-2", "dt=1e-3"])
def push_pull_run(request):
    return request.param, push_pull(request.param)


def test_push_pull_gamma_at_inversion(push_pull_run):
    dt, (times, _, _, gamma) = push_pull_run
    k = int(round(2.0 / dt)) - 1            # the step ending at t_inv = 2
    assert times[k + 1] == pytest.approx(2.0)
    assert gamma[k] == pytest.approx(-2.0, abs=1e-6)


def test_push_pull_unglues_at_four(push_pull_run):
    dt, (times, positions, _, gamma) = push_pull_run
    t_unglue = unglue_time(times, gamma, after=2.0)
    assert abs(t_unglue - 4.0) <= dt + 1e-12
    gap = positions[:, 0, 1] - 0.5
    glued = (times > 1.5) & (times < t_unglue)
    assert np.max(np.abs(gap[glued])) < 1e-9


def test_push_pull_roughness_cap_unglues_at_three():
    dt = 1e-2
    times, _, _, gamma = run_recording_gamma(scenes.push_pull(), GlueyLubrication(gamma_min=-1.0),
                                             dt, t_end=3.5)
    assert np.min(gamma) == pytest.approx(-1.0, abs=1e-12)
    assert abs(unglue_time(times, gamma, after=2.0) - 3.0) <= dt + 1e-12


def test_push_pull_free_flight_after_ungluing_converges_at_order_one():
    """``q(t) = (t - 4)^2 / 2`` after ungluing; the error is O(dt) (compare both dt)."""
    errors = {}
    for dt in (1e-2, 1e-3):
        times, positions, _, _ = push_pull(dt)
        after = times >= 4.0
        exact = 0.5 * (times[after] - 4.0) ** 2
        errors[dt] = np.max(np.abs(positions[after, 0, 1] - 0.5 - exact))
    assert errors[1e-2] < 0.05
    ratio = errors[1e-2] / errors[1e-3]
    assert 5.0 < ratio < 20.0, f"errors {errors}: expected first order"


@pytest.mark.parametrize("angle", [np.pi / 6, np.pi / 4, np.pi / 3])
def test_disk_slides_down_frictionless_incline(angle):
    dt, g = 1e-2, 1.0
    scene = scenes.disk_on_incline(angle, height=0.05)
    times, positions, velocities, _ = run_recording_gamma(scene, Inelastic(), dt, t_end=12.0)
    downhill = np.array([np.cos(angle), -np.sin(angle)])
    normal = np.array([np.sin(angle), np.cos(angle)])
    along = (positions[:, 0] - positions[0, 0]) @ downhill
    # semi-implicit Euler is exact on the discrete parabola t (t + dt) / 2 (the contact is
    # frictionless, so it must not disturb the tangential motion at all) ...
    discrete = g * np.sin(angle) * times * (times + dt) / 2
    np.testing.assert_allclose(along, discrete, rtol=1e-9, atol=1e-12)
    # ... whose relative distance to g sin(alpha) t^2 / 2 is dt / t <= 1e-3 once t >= 10
    exact = g * np.sin(angle) * times**2 / 2
    late = times >= 10.0 + dt
    assert np.max(np.abs(along[late] - exact[late]) / exact[late]) <= 1e-3
    t_impact = np.sqrt(2 * 0.05 / (g * np.cos(angle)))
    after = times > t_impact + 2 * dt
    normal_speed = np.abs(velocities[after, 0] @ normal)
    assert np.max(normal_speed / np.linalg.norm(velocities[after, 0], axis=1)) <= 1e-3


@pytest.mark.parametrize("gamma_min", [None, -1.0], ids=["uncapped", "gamma_min=-1"])
def test_gluey_disk_unsticks_from_incline(gamma_min):
    """Force reversed at t_inv: unstick at ``t_inv + |gamma_inv| / (g cos alpha)``."""
    dt, g, angle, t_inv = 1e-2, 1.0, np.pi / 6, 2.0
    scene = scenes.disk_on_incline(angle, height=0.05, t_inversion=t_inv)
    law = GlueyLubrication(gamma_min=gamma_min)
    times, _, _, gamma = run_recording_gamma(scene, law, dt, t_end=4.5)
    gamma_inv = -g * t_inv * np.cos(angle)
    if gamma_min is not None:
        gamma_inv = max(gamma_min, gamma_inv)
    expected = t_inv + abs(gamma_inv) / (g * np.cos(angle))
    assert abs(unglue_time(times, gamma, after=t_inv) - expected) <= dt + 1e-12


def test_two_grains_glue_time_is_push_impulse_over_pull_force():
    dt, push_time, pull_force = 1e-2, 1.0, 0.5
    scene = scenes.two_grains(push_time=push_time, push_force=2.0, pull_force=pull_force)
    times, positions, _, gamma = run_recording_gamma(scene, GlueyLubrication(), dt, t_end=6.0)
    stored = -gamma[int(round(push_time / dt)) - 1]
    assert stored == pytest.approx(2.0 * push_time, rel=1e-6)
    glue_time = unglue_time(times, gamma, after=push_time) - push_time
    assert abs(glue_time - stored / pull_force) <= dt + 1e-12
    separation = positions[:, 1, 0] - positions[:, 0, 0] - 1.0
    assert separation[-1] > 0.1                 # and then they fly apart
