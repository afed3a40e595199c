"""The hard-case suite: step problems that stress a solver's numerics (see docs/hard_cases.md)."""
from .cases import CASES, HardCase

__all__ = ["CASES", "HardCase"]
