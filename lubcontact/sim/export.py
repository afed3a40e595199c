"""Export a run's step problems for other solvers: every k-th step, with its scene and reference.

Each exported step ``k`` writes, in the export folder,

- ``step_<k>.npz``: the :class:`~lubcontact.problem.StepProblem` as arrays
  (``StepProblem.to_arrays``, every force set, gluey ones included), the
  solution the run applied (``forces``, ``velocities``, ``solution_shift``, ``method``,
  ``status``), the reference solution (``reference_forces``,
  ``reference_velocities``, ``reference_status``, ``reference_method``:
  exact Coulomb when frictional), the step index and time, and the scene
  (``scene.*``, :func:`lubcontact.io.scene_arrays.scene_arrays`);
- ``step_<k>.hdf5``: the same problem in FCLIB's global format with the
  reference solution, when FCLIB can express it (no glued contact: FCLIB has
  no bilateral or union force sets).

``lubcontact verify step_<k>.npz SOLUTION`` checks an outside solver's
answer against it.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..io.fclib import write_fclib
from ..io.files import save_npz
from ..io.scene_arrays import scene_arrays
from ..model.scene import Scene
from ..problem.cones import ConeKind
from ..problem.step import StepProblem
from ..solvers import CoulombResult, SolveSettings, reference_method

FCLIB_KINDS = (ConeKind.NONNEG, ConeKind.COULOMB)
"""Force sets FCLIB can express."""


@dataclass
class StepExporter:
    """Writes the step problems of a run (module docstring).

    Attributes
    ----------
    folder : Path
        Where the files go (created on first use).
    reference : str or None
        Method computing the stored reference (None: the symbolic reference,
        :func:`~lubcontact.solvers.reference_method`).
    tol : float
        Tolerance of the reference solve.
    """

    folder: Path
    reference: str | None = None
    tol: float = 1e-10

    def export(self, step: int, problem: StepProblem, result: CoulombResult, scene: Scene
               ) -> list[Path]:
        """Write step ``step``'s problem, the run's solution and the reference; returns the files."""
        method = self.reference or reference_method(problem)
        settings = SolveSettings(method=method, tol=self.tol, tol_fp=self.tol)
        unshifted = problem.with_shift(np.zeros(problem.n_contacts))
        reference = settings.solve(unshifted)
        stem = Path(self.folder) / f"step_{step:08d}"
        save_npz(stem.with_suffix(".npz"), **problem.to_arrays(), step=np.int64(step),
                 time=np.float64(scene.time), forces=result.forces, velocities=result.velocities,
                 solution_shift=result.shift, method=np.array(result.method),
                 status=np.array(result.status),
                 reference_forces=reference.forces, reference_velocities=reference.velocities,
                 reference_status=np.array(reference.status), reference_method=np.array(method),
                 **{f"scene.{k}": v for k, v in scene_arrays(scene).items()})
        written = [stem.with_suffix(".npz")]
        if np.all(np.isin(problem.cones.kinds, FCLIB_KINDS)):
            metadata = {"title": f"lubcontact step {step}",
                        "description": f"time {scene.time:.17g}, reference {method} "
                                       f"({reference.status})"}
            written.append(write_fclib(unshifted, stem.with_suffix(".hdf5"), solution=reference,
                                       metadata=metadata))
        return written
