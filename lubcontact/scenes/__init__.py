"""Built-in scenes: exact-solution cases, piles, sedimentation and inclined flow."""
from .small import disk_on_incline, push_pull, settling_pile, two_grains

__all__ = ["disk_on_incline", "push_pull", "settling_pile", "two_grains"]
