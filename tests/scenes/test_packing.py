"""Settled piles: an interrupted settling run resumes to the same pile."""
import numpy as np
import pytest

from lubcontact.scenes.packing import settle_pile
from lubcontact.sim import simulation as integrator


def test_interrupted_settling_resumes_to_the_same_pile(tmp_path, monkeypatch):
    whole, whole_info = settle_pile(30, seed=4, cache=str(tmp_path / "whole"), progress=None)
    assert whole_info["at_rest"]
    original_step = integrator.Simulation.step
    calls = {"count": 0}

    def interrupted_step(self, settings=None):
        calls["count"] += 1
        if calls["count"] == 110:            # after the checkpoint of step 100
            raise KeyboardInterrupt
        return original_step(self, settings)

    folder = tmp_path / "resumed"
    monkeypatch.setattr(integrator.Simulation, "step", interrupted_step)
    with pytest.raises(KeyboardInterrupt):
        settle_pile(30, seed=4, cache=str(folder), progress=None)
    assert len(list(folder.glob("*.partial.npz"))) == 1
    monkeypatch.setattr(integrator.Simulation, "step", original_step)
    resumed, resumed_info = settle_pile(30, seed=4, cache=str(folder), progress=None)
    assert resumed_info["steps"] == whole_info["steps"]
    np.testing.assert_allclose(resumed.grains.positions, whole.grains.positions, rtol=0, atol=1e-12)
    assert not list(folder.glob("*.partial.npz"))
