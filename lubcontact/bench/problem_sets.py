"""Problem sets for solver comparisons (``lubcontact compare --set NAME``).

A :class:`ProblemSet` builds a list of :class:`Instance` (a step or local
problem, how to solve it, an optional warm start) on demand. Sources that
belong to other parts of the project or live outside the repository (the
reference cases, the hard-case suite, the flow scenes, the Siconos and FCLIB
files read by :mod:`lubcontact.io`) are imported lazily: a set whose sources
are missing raises :class:`SetUnavailable` with the reason, and the
comparison skips it.

The external Siconos and FCLIB problems ship with the package
(``lubcontact/bench/data/``, provenance in its ``README.md``); :func:`data_dir`
says which folder is read: an explicit override, else the environment
variable ``LUBCONTACT_DATA_DIR``, else the package data.

Two solve modes:

- ``convex``: one call of :func:`lubcontact.solvers.solve` (frictionless and
  gluey problems, whose force sets are convex);
- ``coulomb``: exact Coulomb friction by the fixed point on ``s`` around the
  solver (:func:`lubcontact.solvers.solve_coulomb`), as a time step does.

Time-stepping sequences are consecutive steps of one simulation; each carries
the previous step's reference forces (and shift) matched by pair key, the
warm start a simulation would give a solver.
"""
from __future__ import annotations

import importlib
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

import numpy as np

from ..model.assemble import assemble
from ..model.laws import Coulomb, GlueyLubrication, Inelastic, Law
from ..model.scene import Scene
from ..problem.step import StepProblem

PACKAGE_DATA = Path(__file__).resolve().parent / "data"
DATA_DIR_ENV = "LUBCONTACT_DATA_DIR"
CONVEX, COULOMB = "convex", "coulomb"
PILE_DT = 0.05          # time step of the settling piles (units r = 0.5, g = 1)
PILE_STEPS = 80         # steps before the snapshot (the pile has landed and is settling)
FRICTION = 0.3          # Coulomb coefficient of the frictional piles
FLOW_SETTLE_STEPS = 250  # frictionless sedimentation steps before tilting


class SetUnavailable(RuntimeError):
    """A problem set's sources are missing (not written yet, or files absent)."""


def data_dir(override: str | Path | None = None) -> Path:
    """The folder of the external benchmark problems.

    It holds ``siconos-fc2d/``, ``fclib-local/`` and ``siconos-testdata/``.

    Parameters
    ----------
    override : str or Path, optional
        Folder to use (a ``--data-dir`` option). When None, the environment
        variable ``LUBCONTACT_DATA_DIR`` if set and not empty, else the
        package data ``lubcontact/bench/data``.

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        ``override`` (or the environment variable) is not a directory.
    """
    if override is not None:
        path, origin = Path(override).expanduser(), ""
    elif os.environ.get(DATA_DIR_ENV):
        path, origin = Path(os.environ[DATA_DIR_ENV]).expanduser(), f" (from {DATA_DIR_ENV})"
    else:
        return PACKAGE_DATA
    if not path.is_dir():
        raise ValueError(f"data_dir: not a directory: {path}{origin}")
    return path


def benchmark_file(folder: str, name: str, root: str | Path | None = None) -> Path:
    """The file ``name`` of the benchmark ``folder`` under :func:`data_dir` (``root``).

    Raises
    ------
    SetUnavailable
        The file is absent (the message names the folder and the file).
    ValueError
        ``root`` (or ``LUBCONTACT_DATA_DIR``) is not a directory.
    """
    path = data_dir(root) / folder / name
    if not path.is_file():
        raise SetUnavailable(f"benchmark folder {folder!r} has no file {name!r} "
                             f"(looked for {path})")
    return path


@dataclass
class Instance:
    """One problem of a set.

    Attributes
    ----------
    name : str
        Unique within the set.
    problem : StepProblem or LocalProblem
        In physical (or file) units.
    mode : {"convex", "coulomb"}
        How every solver is run on it (module docstring).
    group : str
        Family of instances (a scene and law, a benchmark collection); curves
        and tables never mix sizes silently: the CSV keeps every instance.
    warm_start : ndarray, shape (n_rows,), optional
        Forces of the previous step matched by pair key (sequences only).
    warm_shift : ndarray, shape (nc,), optional
        Shift ``s`` of the previous step matched by pair key (coulomb sequences).
    step : int or None
        Step index within its sequence.
    exact : ndarray, shape (n_dof,), optional
        Exact velocities after the step, when known (errors are then measured
        against them instead of the Clarabel reference).
    must_flag : bool
        The problem has no solution: success means a non-converged status.
    """

    name: str
    problem: object
    mode: str = CONVEX
    group: str = ""
    warm_start: np.ndarray | None = None
    warm_shift: np.ndarray | None = None
    step: int | None = None
    exact: np.ndarray | None = None
    must_flag: bool = False

    @property
    def n_contacts(self) -> int:
        return int(self.problem.n_contacts)

    @property
    def n_rows(self) -> int:
        return int(self.problem.n_rows)


@dataclass
class ProblemSet:
    """A named, deterministic collection of instances.

    Attributes
    ----------
    name, description : str
    build : callable
        ``build() -> list[Instance]``; raises :class:`SetUnavailable` when a
        source is missing.
    seeds : dict
        Every random seed the set uses (reported in the header).
    reads_data : bool
        ``build`` reads files under :func:`data_dir` and is called as
        ``build(data)`` with the folder override (None: the default).
    """

    name: str
    description: str
    build: Callable[..., list[Instance]]
    seeds: dict = field(default_factory=dict)
    reads_data: bool = False

    def instances(self, data: str | Path | None = None) -> list[Instance]:
        """Build the instances; ``data`` overrides the benchmark folder (:func:`data_dir`).

        ``data`` is ignored by sets that read no file.
        """
        instances = self.build(data) if self.reads_data else self.build()
        if not instances:
            raise SetUnavailable(f"set {self.name!r}: no instance could be built")
        return instances


# -- lazy sources ------------------------------------------------------------------------------
def _import(module: str, what: str) -> ModuleType:
    """Import ``module`` or raise SetUnavailable."""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        raise SetUnavailable(f"{what} needs {module!r}, which is not available ({exc})") from exc


def _benchmark_files(folder: str, patterns: tuple[str, ...],
                     root: str | Path | None = None) -> list[Path]:
    directory = data_dir(root) / folder
    files = sorted({path for pattern in patterns for path in directory.glob(pattern)})
    if not files:
        raise SetUnavailable(f"no problem files ({', '.join(patterns)}) in benchmark folder "
                             f"{folder!r} under {directory.parent}")
    return files


# -- step problems from scenes -------------------------------------------------------------------
def snapshot(scene: Scene, law: Law, dt: float, gamma: float = 0.0) -> StepProblem:
    """The first step problem of ``scene`` with every candidate contact at gluey state ``gamma``."""
    from ..model.contacts import find_contacts
    from ..sim.simulation import Simulation

    sim = Simulation(scene, law, dt)
    contacts = find_contacts(sim.scene, sim.d_max)
    return assemble(sim.scene, contacts, law.cones(contacts, np.full(contacts.count, gamma)), sim.dt,
                    rotations=law.needs_rotation)


def simulated_steps(scene: Scene, law: Law, dt: float, first: int, count: int,
                    tol: float = 1e-10) -> list[tuple[StepProblem, np.ndarray, np.ndarray]]:
    """Problems of steps ``first .. first + count - 1`` of a Clarabel-driven simulation.

    Returns
    -------
    list of (problem, forces, shift)
        Each step's problem with the forces and shift the simulation applied.
    """
    from ..sim.simulation import Simulation

    sim = Simulation(scene, law, dt, solver="clarabel", tol=tol, on_failure="warn")
    sim.run(first)
    steps = []
    for _ in range(count):
        report = sim.step()
        shift = report.result.shift
        steps.append((report.problem, report.result.forces.copy(), np.asarray(shift, dtype=float)))
    return steps


def matched_warm_start(previous: StepProblem, forces: np.ndarray, shift: np.ndarray,
                       problem: StepProblem) -> tuple[np.ndarray, np.ndarray]:
    """The previous step's forces and shift carried over to ``problem`` by pair key,
    as :class:`~lubcontact.sim.Simulation` does (pairs new to ``problem`` start at 0).

    Returns
    -------
    forces : ndarray, shape (problem.n_rows,)
    shift : ndarray, shape (problem.n_contacts,)
    """
    from ..sim.state import PreviousStep

    return PreviousStep.of(previous, forces, shift).warm_start(problem)


def sequence(name: str, steps: list[tuple[StepProblem, np.ndarray, np.ndarray]], mode: str,
             first: int) -> list[Instance]:
    """Instances of consecutive steps; all but the first carry the previous step's solution."""
    instances = []
    for k in range(1, len(steps)):
        problem = steps[k][0]
        warm, shift = matched_warm_start(*steps[k - 1], problem)
        instances.append(Instance(f"{name}-step{first + k}", problem, mode, group=name,
                                  warm_start=warm, warm_shift=shift, step=first + k))
    return instances


# -- builders ----------------------------------------------------------------------------------
def _reference_cases(names: tuple[str, ...]) -> list[Instance]:
    cases = _import("lubcontact.bench.cases.reference", "the reference cases")
    return [Instance(name, cases.load(name)[0], CONVEX, group="reference") for name in names]


def _settling(n_grains: int, law: Law, label: str, seed: int = 3) -> Instance:
    from ..scenes.small import settling_pile

    (problem, _, _), = simulated_steps(settling_pile(n_grains, seed=seed), law, PILE_DT,
                                       PILE_STEPS, 1)
    return Instance(f"settling{n_grains}-{label}", problem, CONVEX, group=f"settling-{label}")


def _deposited(n_grains: int, law: Law, label: str, mode: str, seed: int = 1) -> Instance:
    packing = _import("lubcontact.scenes.packing", "piles at rest")
    problem = snapshot(packing.deposit_pile(n_grains, seed=seed), law, PILE_DT)
    return Instance(f"rest{n_grains}-{label}", problem, mode, group=f"rest-{label}")


def build_tiny() -> list[Instance]:
    """Four one-contact reference cases and the 200-disk dry settling pile (CI, seconds)."""
    return _reference_cases(("push_pull_impact", "push_pull_pulled", "incline_resting",
                             "two_grains_glued", "pile200_inelastic"))


def build_tiny_sequence() -> list[Instance]:
    """Three consecutive steps of a 12-disk glued settling pile (CI, seconds)."""
    from ..scenes.small import settling_pile

    steps = simulated_steps(settling_pile(12, seed=5), GlueyLubrication(), PILE_DT, 30, 3)
    return sequence("settling12-gluey", steps, CONVEX, 30)


def build_piles() -> list[Instance]:
    """Frictionless piles: dry piles at rest (3 sizes), settling dry and glued piles (2 sizes)."""
    instances = _reference_cases(("pile200_inelastic", "pile200_gluey"))
    instances += [_settling(n, GlueyLubrication(), "gluey") for n in (50, 400)]
    instances += [_deposited(n, Inelastic(), "dry", CONVEX) for n in (100, 400, 1600)]
    return instances


def build_frictional_piles() -> list[Instance]:
    """Dry Coulomb piles at rest (mu = 0.3), exact friction by the fixed point on s."""
    return [_deposited(n, Coulomb(FRICTION), "coulomb", COULOMB) for n in (50, 200, 800)]


def build_sequences() -> list[Instance]:
    """Consecutive steps of settling piles (dry and glued, 100 grains): warm starts."""
    from ..scenes.small import settling_pile

    first, count = 60, 6
    instances = []
    for label, law in (("dry", Inelastic()), ("gluey", GlueyLubrication())):
        steps = simulated_steps(settling_pile(100, seed=3), law, PILE_DT, first, count)
        instances += sequence(f"settling100-{label}", steps, CONVEX, first)
    return instances


def build_flows() -> list[Instance]:
    """Snapshots of inclined flows (dry Coulomb, gluey + Coulomb), 60 grains, 25 degrees."""
    flow = _import("lubcontact.scenes.inclined", "the flow scenes")
    params = flow.dimensionless_parameters()
    dt = flow.time_step(params)
    bed = flow.sedimentation(60, params, width=20.0 * params.radius, seed=2)
    from ..sim.simulation import Simulation

    sim = Simulation(bed, Inelastic(), dt, solver="clarabel", tol=1e-8)
    sim.run(FLOW_SETTLE_STEPS)
    tilted = flow.inclined_flow(sim.scene, 25.0)
    instances = []
    for model in ("dry", "gluey"):
        steps = simulated_steps(tilted, params.law(model), dt, 20, 3)
        instances += sequence(f"flow60-{model}", steps, COULOMB, 20)
    return instances


def build_hard() -> list[Instance]:
    """The hard-case suite of ``lubcontact.bench.cases.hard``: single solves, exact answers where known."""
    hard = _import("lubcontact.bench.cases.hard", "the hard-case suite")
    instances = []
    for name, case in hard.CASES.items():
        problem = case.problem
        exact = case.exact(problem) if case.exact is not None else None
        instances.append(Instance(name, problem, CONVEX, group="hard", exact=exact,
                                  must_flag=case.must_flag))
    return instances


def _files(folder: str, patterns: tuple[str, ...], group: str,
           root: str | Path | None = None) -> list[Instance]:
    """Every problem file of ``folder`` (global ones in their local form); empty ones left out."""
    io = _import("lubcontact.io.readers", "external benchmark problems")
    instances = []
    for path in _benchmark_files(folder, patterns, root):
        problem = io.read_problem(path)
        if problem.n_contacts:
            instances.append(Instance(path.name.removesuffix(".dat").removesuffix(".hdf5"),
                                      problem, COULOMB, group=group))
    return sorted(instances, key=lambda instance: instance.n_contacts)


def build_siconos(data: str | Path | None = None) -> list[Instance]:
    """Siconos 2D frictional problems (``siconos-fc2d/*.dat`` under :func:`data_dir`)."""
    return _files("siconos-fc2d", ("*.dat",), "siconos-fc2d", data)


def build_siconos_testdata(data: str | Path | None = None) -> list[Instance]:
    """Siconos' friction-contact test problems (``siconos-testdata/``: 2D and 3D, local and
    global ``.dat``, FCLIB ``.hdf5``; global ones in their local form, empty ones left out)."""
    return _files("siconos-testdata", ("*.dat", "*.hdf5"), "siconos-testdata", data)


def build_fclib(data: str | Path | None = None) -> list[Instance]:
    """FCLIB 3D local problems (``fclib-local/*.hdf5`` under :func:`data_dir`)."""
    return _files("fclib-local", ("*.hdf5", "*.h5"), "fclib", data)


SETS: dict[str, ProblemSet] = {s.name: s for s in [
    ProblemSet("tiny", "four one-contact reference cases and the 200-disk dry settling pile (CI)",
               build_tiny, seeds={"settling_pile": 3}),
    ProblemSet("tiny-sequence", "3 consecutive steps of a 12-disk glued settling pile (CI): "
               "cold against warm-started solves", build_tiny_sequence, seeds={"settling_pile": 5}),
    ProblemSet("piles", "frictionless piles: 2D piles at rest (100, 400, 1600 disks, dry) and "
               f"settling piles after {PILE_STEPS} steps (200 dry; 50, 200, 400 glued)",
               build_piles, seeds={"settling_pile": 3, "deposit_pile": 1}),
    ProblemSet("frictional-piles", f"2D piles at rest with Coulomb friction mu = {FRICTION} "
               "(50, 200, 800 disks), fixed point on s", build_frictional_piles,
               seeds={"deposit_pile": 1}),
    ProblemSet("sequences", "6 consecutive steps of 100-disk settling piles (dry, glued): "
               "cold against warm-started solves", build_sequences, seeds={"settling_pile": 3}),
    ProblemSet("flows", "inclined flows at 25 degrees, 60 disks: dry Coulomb and gluey + Coulomb, "
               "steps 21 and 22, warm-started from the step before", build_flows, seeds={"sedimentation": 2}),
    ProblemSet("hard", "the hard-case suite (lubcontact/bench/cases/hard.py, docs/records/hard_cases.md): "
               "one solve each, errors against the exact velocities where known", build_hard),
    ProblemSet("siconos-fc2d", "Siconos 2D granular flow on a wall (667, 2020, 7002 contacts)",
               build_siconos, reads_data=True),
    ProblemSet("fclib", "FCLIB 3D local problems (48 to 286 contacts)", build_fclib,
               reads_data=True),
    ProblemSet("siconos-testdata", "Siconos' friction-contact test problems: 2D and 3D, local and "
               "global (in local form), 1 to 376 contacts", build_siconos_testdata,
               reads_data=True),
]}
