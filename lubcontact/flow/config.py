"""What defines a run of the flow experiment: :class:`RunConfig`, its checks and its JSON form.

This module imports neither the scenes nor the solvers at import time (the
command line parses its options without them; see :mod:`lubcontact.flow.cli`).
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, fields, replace
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..scenes.inclined import FlowParameters

SCENES = ("sedimentation", "inclined_flow")
PRESET_NAMES = ("poster", "dimensionless")
"""Keys of :data:`lubcontact.scenes.inclined.PRESETS` (known here without importing the scenes)."""
MODEL_NAMES = ("dry", "gluey", "frictionless")
""":data:`lubcontact.scenes.inclined.MODELS` (known here without importing the scenes)."""
DEFAULT_FAST_SOLVER = "apgd-jacobi"
"""The solver of runs with the convex relaxation of friction (the default), when registered.
``apgd`` was until 2026-11-27: on a 400-grain gluey flow at 22 degrees it stopped at
``max_iter`` (residual 1.7e-2) on step 657 and failed the run, where ``apgd-jacobi`` converged
in 315 iterations and ran the 2000 steps; on developed dry flows of 400 to 12 800 grains its
steps cost 0.84x to 1.08x apgd's (docs/records/benchmarks.md)."""
DEFAULT_EXACT_SOLVER = "newton-ac"
"""The solver of runs with exact Coulomb friction (``fixed_point``), when registered: one native
solve per step; on developed 300-grain flows 9.0x (dry) and 3.9x (gluey) faster than ``apgd``
with its fixed point, every step at FCLIB error <= 1e-6 where apgd's end at ``max_iter``
(docs/records/benchmarks.md)."""
DEFAULT_JOINT = 5
"""``joint`` of runs with exact Coulomb friction: each step starts with the fixed point's joint
phase (APGD updating the shift every 5 iterations) where it applies: before ``newton-ac``'s
Newton phases on steps of more than ``COMPILED_LIMIT`` (700) rows without UNION contacts, on developed
dry flows of 400 to 12 800 grains 1.7-3.1x faster per step (FCLIB errors at most 1.5e-10),
on the first steps of a tilted bed as fast (on smaller steps without UNION contacts it runs
only where ``newton-ac``'s first Newton strategies have stalled, on the steps that went to
Gauss-Seidel's fallback: ``newton_alart_curnier``'s ``joint``); before the outer loop of any
other solver's fixed point on 2D steps, as its starting forces and shift (a gluey 2 000-grain
flow, ``apgd-jacobi``: 0.33 against 0.48 s per step) (docs/records/benchmarks.md, "newton-ac
from the joint phase")."""
REFERENCE_SOLVER = "clarabel"
"""The default otherwise (always registered)."""

DEFINING_FIELDS = ("scene", "n_grains", "preset", "model", "angle", "dt_fraction", "width", "seed",
                   "bed", "start_from", "widen", "settle_steps", "settle_model", "bins_per_radius",
                   "viscosity", "roughness", "ramp_step", "ramp_stages", "hold_steps")
"""Fields that define a run's scene or physics: a resumed run keeps its checkpoint's.

The state in a checkpoint was made by them (the grains, the bed, the tilt, the
contact law and its gluey state, the time ``steps_done x dt``); continuing it
with other values would mix two runs. The other fields (``steps``, the solver
settings, ``friction``, the output periods, ``average_from``) may change when a
run is resumed.
"""

Q_UNIT = "d sqrt(g' d)"
"""Unit of the flow rate in every output: ``d`` the mean grain diameter, ``g'`` the reduced gravity."""
FLOW_SPEED = 0.01
"""Default threshold of a flowing layer in a ramp (:mod:`lubcontact.flow.hysteresis`): mean
downhill velocity in units of ``sqrt(g' d)``."""
DT_UNIT = "sqrt(d/g')"
"""Unit of ``dt_fraction``: the time step is ``dt_fraction x sqrt(d / g')``."""
STOP_RATIO = 1e-6
"""Kinetic energy, relative to the run's largest, below which a flow is called stopped
(``no_flow``, :func:`lubcontact.flow.measure.classify_flow`)."""
STEADY_TOL = 0.05
"""Relative change of the mean flow rate between a window's halves below which a flow is called
steady (:func:`lubcontact.flow.measure.classify_flow`)."""


def default_solver(fixed_point: bool = False) -> str:
    """The default step solver of a run.

    Parameters
    ----------
    fixed_point : bool
        Whether the run solves exact Coulomb friction (:attr:`RunConfig.fixed_point`).

    Returns
    -------
    str
        :data:`DEFAULT_EXACT_SOLVER` (exact Coulomb) or :data:`DEFAULT_FAST_SOLVER`
        (the relaxation) when registered, else :data:`REFERENCE_SOLVER`.
    """
    from ..solvers import methods

    solver = DEFAULT_EXACT_SOLVER if fixed_point else DEFAULT_FAST_SOLVER
    return solver if solver in methods() else REFERENCE_SOLVER


def flow_rate_unit(params: FlowParameters) -> float:
    """The unit :data:`Q_UNIT` of the flow rate, ``d sqrt(g' d)`` with ``d = 2 r`` (length^2 / time)."""
    return 2.0 * params.radius * params.velocity_scale


@dataclass
class RunConfig:
    """Everything that defines a run (stored in its checkpoint as JSON).

    Lengths are in the preset's unit of length, times in its unit of time
    (see :mod:`lubcontact.scenes.inclined`).

    Attributes
    ----------
    scene : str
        ``sedimentation`` or ``inclined_flow``.
    n_grains : int
        Free grains.
    preset : str
        ``poster`` (SI) or ``dimensionless`` (see :mod:`lubcontact.scenes.inclined`).
    model : str
        ``dry`` (Coulomb) or ``gluey`` (gluey lubrication + Coulomb).
    angle : float or None
        Incline angle (degrees) for ``inclined_flow``, in (-90, 90); None for
        ``sedimentation`` (set so on construction: it has no incline).
    steps : int
        Total steps of the run.
    dt_fraction : float
        Time step as a fraction of ``sqrt(d / g')`` (:data:`DT_UNIT`; ``d`` the
        mean grain diameter, ``g'`` the reduced gravity).
    solver, tol : str, float
        Step solver and its tolerance (default solver, when empty:
        :func:`default_solver` of ``fixed_point``).
    fixed_point : bool
        Exact Coulomb friction by the fixed point on s; default False: the
        convex relaxation, one solve per step, for solvers that have one (a
        native Coulomb solver such as ``newton-ac`` solves exact Coulomb
        either way); with ``apgd`` the fixed point cost 3x more and often hit
        its outer-iteration cap on flowing piles (docs/records/validation.md).
    tol_fp, max_outer : float, int
        Tolerance and outer-iteration cap of that fixed point.
    joint : int
        Exact Coulomb friction: start each step by solving Coulomb's problem jointly in one
        APGD run that updates the shift every ``joint`` iterations, before the outer loop of
        the fixed point or ``newton-ac``'s Newton phases
        (``solve_coulomb(joint=...)`` of :mod:`lubcontact.solvers.coulomb`; default
        :data:`DEFAULT_JOINT`; 0: none).
    friction : float or None
        Coulomb coefficient overriding the preset's ``mu`` (None: the preset's).
    viscosity, roughness : float or None
        Fluid viscosity ``eta`` (Pa s) and asperity height ``eps`` (m)
        overriding the ``poster`` preset's (None: the preset's); they set
        each contact's ``gamma_min``. The ``dimensionless`` preset gives
        ``gamma_min`` directly and takes neither.
    ramp_step, ramp_stages, hold_steps : float, int, int
        An angle ramp (``inclined_flow`` only; ``ramp_stages = 0``: a fixed
        angle): the incline starts at ``angle``, turns by ``ramp_step``
        degrees every ``hold_steps`` steps for ``ramp_stages`` stages, then
        back down the same stages to ``angle`` (:meth:`ramp_stage`); the
        grains keep their velocities and contacts their gluey state across
        a change. ``steps`` is then ``(2 ramp_stages + 1) hold_steps``.
    checkpoint_every, sample_every, frame_every : int
        Periods (in steps) of checkpoints, measurement samples and frames
        (0: no frames).
    cross_check_every : int
        Every that many steps, re-solve the step with Clarabel (0: never).
    settle_steps : int
        Sedimentation steps before tilting (``inclined_flow`` without a bed).
    settle_model : str
        Model of that sedimentation (``frictionless`` settles fastest).
    bed : str
        Path of a settled bed (a sedimentation checkpoint); empty: settle here.
    start_from : str
        Path of a run's ``checkpoint.npz`` whose grains, with their velocities
        and spins, the run starts from instead of a bed at rest, tilted to
        ``angle`` (``inclined_flow`` only, not with ``bed`` nor a ramp): a
        developed flow turned to another angle, the way the 2000-grain runs of
        docs/records/poster-experiment.md reach each angle without each one's
        onset. The contacts' glue states and the solver's warm start start
        afresh (a descent of :mod:`~lubcontact.flow.hysteresis` keeps them). A
        sweep replaces ``{model}`` and ``{seed}`` in it by each run's
        (:func:`~lubcontact.flow.sweep.start_path`). Empty: the bed.
    widen : int
        Copies of the ``start_from`` state laid side by side
        (:func:`~lubcontact.scenes.inclined.widen`), their velocities jittered by
        :data:`~lubcontact.scenes.inclined.PARTING_JITTER` of their rms with ``seed`` so
        that they part: a developed layer made ``widen`` times wider, with ``n_grains`` and
        ``width`` the wide layer's; each seed parts the copies its own way. 1: the state
        as it is.
    average_from : float
        Profiles and means are time-averaged over steps after this fraction
        of the run.
    width : float
        Period along x in mean radii.
    seed : int
        Seed of the random grain sizes and initial lattice jitter, and with ``widen`` > 1 of
        the velocity jitter that parts the copies.
    bins_per_radius : int
        Profile slabs per mean radius.

    Raises
    ------
    ValueError
        On construction, naming the first field out of range.
    """

    scene: str = "inclined_flow"
    n_grains: int = 300
    preset: str = "dimensionless"
    model: str = "gluey"
    angle: float | None = 22.0
    steps: int = 1000
    dt_fraction: float = 0.01
    solver: str = ""
    tol: float = 1e-6
    fixed_point: bool = False
    tol_fp: float = 1e-8
    max_outer: int = 50
    joint: int = DEFAULT_JOINT
    friction: float | None = None
    viscosity: float | None = None
    roughness: float | None = None
    ramp_step: float = 0.0
    ramp_stages: int = 0
    hold_steps: int = 0
    checkpoint_every: int = 200
    sample_every: int = 10
    frame_every: int = 0
    cross_check_every: int = 0
    settle_steps: int = 600
    settle_model: str = "frictionless"
    bed: str = ""
    start_from: str = ""
    widen: int = 1
    average_from: float = 0.5
    width: float = 40.0
    seed: int = 0
    bins_per_radius: int = 2

    def __post_init__(self) -> None:
        if not self.solver:
            self.solver = default_solver(self.fixed_point)
        if self.scene not in SCENES:
            raise ValueError(f"scene: must be one of {SCENES}, got {self.scene!r}")
        if self.preset not in PRESET_NAMES:
            raise ValueError(f"preset: must be one of {PRESET_NAMES}, got {self.preset!r}")
        for name in ("model", "settle_model"):
            if getattr(self, name) not in MODEL_NAMES:
                raise ValueError(f"{name}: must be one of {MODEL_NAMES}, "
                                 f"got {getattr(self, name)!r}")
        if self.scene == "sedimentation":
            self.angle = None                 # no incline: nothing to record
        elif self.angle is None or not -90 < float(self.angle) < 90:
            raise ValueError(f"angle: must be in (-90, 90) degrees, got {self.angle}")
        for name in ("n_grains", "checkpoint_every", "sample_every", "bins_per_radius",
                     "max_outer"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name}: must be >= 1, got {getattr(self, name)}")
        for name in ("steps", "frame_every", "cross_check_every", "settle_steps", "joint"):
            if int(getattr(self, name)) < 0:
                raise ValueError(f"{name}: must be >= 0, got {getattr(self, name)}")
        for name in ("tol", "tol_fp", "dt_fraction", "width"):
            if not float(getattr(self, name)) > 0:
                raise ValueError(f"{name}: must be > 0, got {getattr(self, name)}")
        if self.friction is not None and not self.friction >= 0:
            raise ValueError(f"friction: must be >= 0, got {self.friction}")
        if self.start_from and self.scene != "inclined_flow":
            raise ValueError(f"start_from: only an inclined_flow starts from a run's state, "
                             f"got {self.start_from!r} for a {self.scene}")
        if self.start_from and self.bed:
            raise ValueError(f"start_from: a run starts from a bed or from a run's state, not "
                             f"both, got {self.start_from!r} and the bed {self.bed!r}")
        if int(self.widen) < 1:
            raise ValueError(f"widen: must be >= 1, got {self.widen}")
        if int(self.widen) > 1 and not self.start_from:
            raise ValueError(f"widen: only a run's state (start_from) is widened, got "
                             f"{self.widen} copies and no start_from")
        if self.start_from and self.ramp_stages:
            raise ValueError(f"start_from: an angle ramp starts from a bed at rest, got "
                             f"{self.start_from!r}")
        if not 0 <= self.average_from < 1:
            raise ValueError(f"average_from: must be in [0, 1), got {self.average_from}")
        for name in ("viscosity", "roughness"):
            value = getattr(self, name)
            if value is not None and not float(value) > 0:
                raise ValueError(f"{name}: must be > 0, got {value}")
            if value is not None and self.preset != "poster":
                raise ValueError(f"{name}: only the poster preset takes it (the {self.preset} "
                                 f"preset sets gamma_min directly), got {value}")
        if self.roughness is not None:
            params = self.params           # eps must stay below every contact's r_eff
            smallest = 0.5 * params.radius * (1.0 - params.polydispersity)
            if not self.roughness < smallest:
                raise ValueError(f"roughness: must be below the smallest effective radius "
                                 f"r (1 - polydispersity) / 2 = {smallest:g}, got {self.roughness}")
        self._check_ramp()

    def _check_ramp(self) -> None:
        """The ramp fields: consistent with each other, the scene, ``steps`` and the angle range."""
        if int(self.ramp_stages) < 0 or int(self.hold_steps) < 0:
            raise ValueError(f"ramp_stages: must be >= 0 with hold_steps >= 0, got "
                             f"{self.ramp_stages} and {self.hold_steps}")
        if not self.ramp_stages:
            if self.ramp_step or self.hold_steps:
                raise ValueError(f"ramp_step: ramp_step and hold_steps need ramp_stages > 0, got "
                                 f"{self.ramp_step} and {self.hold_steps}")
            return
        if self.scene != "inclined_flow":
            raise ValueError(f"ramp_stages: a ramp needs scene inclined_flow, got {self.scene!r}")
        if int(self.hold_steps) < 1 or not self.ramp_step:
            raise ValueError(f"hold_steps: a ramp needs hold_steps >= 1 and a nonzero ramp_step, "
                             f"got {self.hold_steps} and {self.ramp_step}")
        if self.steps != self.ramp_total_steps:
            raise ValueError(f"steps: a ramp of {self.ramp_stages} stages up and down, "
                             f"{self.hold_steps} steps each, takes {self.ramp_total_steps}, "
                             f"got {self.steps}")
        top = float(self.angle) + self.ramp_stages * float(self.ramp_step)
        if not -90 < top < 90:
            raise ValueError(f"ramp_step: the ramp's far end {top:g} is not in (-90, 90) degrees")

    @property
    def ramp_total_steps(self) -> int:
        """Steps of the whole ramp, up and down: ``(2 ramp_stages + 1) hold_steps``."""
        return (2 * int(self.ramp_stages) + 1) * int(self.hold_steps)

    def ramp_stage(self, step: int) -> tuple[int, float]:
        """The stage of a ramp (0-based) that step ``step`` (0-based) belongs to, and its angle.

        Stages ``0..ramp_stages`` go up by ``ramp_step`` each, the next
        ``ramp_stages`` come back down; without a ramp there is one stage.

        Returns
        -------
        (int, float)
            The stage and its incline angle (degrees; NaN for ``sedimentation``).
        """
        if not self.ramp_stages:
            return 0, float("nan") if self.angle is None else float(self.angle)
        stage = min(int(step) // int(self.hold_steps), 2 * int(self.ramp_stages))
        level = min(stage, 2 * int(self.ramp_stages) - stage)
        return stage, float(self.angle) + level * float(self.ramp_step)

    @property
    def params(self) -> FlowParameters:
        """The preset's physical parameters, with ``friction``, ``viscosity`` and ``roughness``
        applied when set."""
        from ..scenes import inclined

        params = inclined.PRESETS[self.preset]()
        changes = {name: getattr(self, name) for name in ("friction", "viscosity", "roughness")
                   if getattr(self, name) is not None}
        return replace(params, **changes) if changes else params

    @classmethod
    def field_names(cls) -> set[str]:
        """Names of the fields (the keys :meth:`from_json` and the command line accept)."""
        return {f.name for f in fields(cls)}

    def to_json(self) -> str:
        """The fields as a JSON object (keys sorted)."""
        return json.dumps(asdict(self), sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> RunConfig:
        """Inverse of :meth:`to_json`; keys that are not fields (older files) are ignored.

        Raises
        ------
        ValueError
            If a value is out of range (see the class).
        """
        known = cls.field_names()
        return cls(**{k: v for k, v in json.loads(text).items() if k in known})

    def differences(self, other: RunConfig, names: tuple[str, ...] = DEFINING_FIELDS
                    ) -> dict[str, tuple]:
        """The fields among ``names`` whose values differ: ``{name: (self's, other's)}``."""
        return {name: (getattr(self, name), getattr(other, name)) for name in names
                if getattr(self, name) != getattr(other, name)}
