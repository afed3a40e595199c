"""The inclined-flow experiment: runs with checkpoints, measurements, plots and sweeps (tooling)."""
