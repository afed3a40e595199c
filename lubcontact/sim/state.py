"""The state a time step takes and returns: :class:`SimulationState`.

Everything a run carries from one step to the next lives here, so that a
checkpoint is this dataclass written as arrays (:meth:`SimulationState.to_arrays`)
and a resumed run continues bit for bit: the scene, the glue state gamma per
contact pair, the previous step's forces and shift by pair (the warm start of
an iterative solver stops at a different iterate without them), and the step
count.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from ..io.scene_arrays import scene_arrays, scene_from_arrays
from ..model.contacts import lookup_by_key
from ..model.laws import PairState
from ..model.scene import Scene
from ..problem.step import StepProblem


@dataclass
class PreviousStep:
    """What the next step's warm start needs, by pair key.

    Attributes
    ----------
    keys : ndarray of int64, shape (nc,)
        Pair keys of the step's contacts (sorted).
    normal : ndarray, shape (nc,)
        Normal forces.
    tangential_contacts : ndarray of int, shape (nt,)
        Contacts with tangential rows.
    tangential : ndarray, shape (nt, tangent_dim)
        Their tangential forces.
    shift : ndarray, shape (nc,)
        The shift of the fixed point on s the step ended with.
    """

    keys: np.ndarray
    normal: np.ndarray
    tangential_contacts: np.ndarray
    tangential: np.ndarray
    shift: np.ndarray

    @classmethod
    def of(cls, problem: StepProblem, forces: np.ndarray, shift: np.ndarray) -> PreviousStep:
        """The record of a solved step problem (its pair keys, forces and shift)."""
        normal, tangential = problem.cones.split(forces)
        return cls(keys=problem.keys, normal=normal.copy(),
                   tangential_contacts=problem.cones.tangential.copy(),
                   tangential=tangential.copy(), shift=np.asarray(shift, dtype=float))

    def warm_start(self, problem: StepProblem) -> tuple[np.ndarray, np.ndarray]:
        """Forces (normal and tangential) and shift for ``problem``, matched by pair key.

        Returns
        -------
        (ndarray, ndarray)
            Forces, shape (n_rows,), and shift, shape (nc,); pairs new to
            ``problem`` start at 0.
        """
        cones = problem.cones
        normal = lookup_by_key(self.keys, self.normal, problem.keys)
        shift = lookup_by_key(self.keys, self.shift, problem.keys)
        tangential = lookup_by_key(self.keys[self.tangential_contacts], self.tangential,
                                   problem.keys[cones.tangential], width=cones.tangent_dim)
        return cones.join(normal, tangential), shift


@dataclass
class SimulationState:
    """What a step takes and returns.

    Attributes
    ----------
    scene : Scene
        Grains, obstacles and time.
    pairs : PairState
        Glue state gamma per contact pair.
    previous : PreviousStep or None
        The last step's forces and shift by pair (None before the first step).
    steps_done : int
        Steps taken since ``start_time``.
    start_time : float
        The scene's time when the run started (``time = start_time + steps_done dt``).
    """

    scene: Scene
    pairs: PairState = field(default_factory=PairState)
    previous: PreviousStep | None = None
    steps_done: int = 0
    start_time: float = 0.0

    def copy(self) -> SimulationState:
        """An independent copy: a step moves its scene in place, and replaces (never changes)
        the pair states and the previous step, so the scene is copied and those are shared."""
        return replace(self, scene=self.scene.copy())

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Plain arrays (for ``np.savez``) that :meth:`from_arrays` restores bit for bit.

        The scene's external force, if any, is not stored (the caller rebuilds it).
        """
        out = {f"scene.{k}": v for k, v in scene_arrays(self.scene).items()}
        out.update({"pairs.keys": self.pairs.keys, "pairs.gamma": self.pairs.gamma,
                    "steps_done": np.int64(self.steps_done),
                    "start_time": np.float64(self.start_time)})
        if self.previous is not None:
            out.update({f"previous.{k}": np.asarray(v) for k, v in vars(self.previous).items()})
        return out

    @classmethod
    def from_arrays(cls, data: Mapping[str, np.ndarray], scene: Scene | None = None) -> SimulationState:
        """Inverse of :meth:`to_arrays` (a dict or an ``NpzFile``).

        Parameters
        ----------
        scene : Scene, optional
            Use this scene instead of the stored one (e.g. one carrying its external force).
        """
        stored = {k[len("scene."):]: data[k] for k in data.keys() if k.startswith("scene.")}
        previous = {k[len("previous."):]: data[k] for k in data.keys() if k.startswith("previous.")}
        return cls(scene=scene if scene is not None else scene_from_arrays(stored),
                   pairs=PairState(keys=np.asarray(data["pairs.keys"], dtype=np.int64),
                                   gamma=np.asarray(data["pairs.gamma"], dtype=float)),
                   previous=PreviousStep(**previous) if previous else None,
                   steps_done=int(data["steps_done"]), start_time=float(data["start_time"]))
