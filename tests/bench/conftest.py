"""Fixtures of the benchmark commands' tests."""
import pytest

from lubcontact.flow.bed import initial_scene
from lubcontact.flow.config import RunConfig
from lubcontact.flow.run import FlowRun


@pytest.fixture
def dry_layer(tmp_path):
    """``dry_layer(steps=6, **options)``: the folder of a 24-grain dry layer run ``steps`` steps at
    24 degrees (``RunConfig`` ``options`` added); its last checkpoint, ``checkpoint.npz``, is the
    ``--layer`` of the tests."""
    def run(steps: int = 6, **options):
        layer = tmp_path / "layer"
        config = RunConfig(scene="inclined_flow", n_grains=24, width=12.0, model="dry", angle=24.0,
                           steps=steps, dt_fraction=0.05, settle_steps=0, checkpoint_every=steps,
                           **options)
        FlowRun(config, initial_scene(config, layer), layer).advance(steps)
        return layer

    return run
