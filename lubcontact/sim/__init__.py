"""Time stepping: :class:`Simulation` advances a scene one step problem at a time."""
from .simulation import Simulation, StepReport, Trajectory

__all__ = ["Simulation", "StepReport", "Trajectory"]
