"""Time stepping: :class:`Simulation` advances a :class:`SimulationState` one step problem at a time."""
from .simulation import Simulation
from .state import PreviousStep, SimulationState
from .trajectory import StepReport, Trajectory

__all__ = ["PreviousStep", "Simulation", "SimulationState", "StepReport", "Trajectory"]
