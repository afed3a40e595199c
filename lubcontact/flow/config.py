"""What defines a run of the flow experiment: :class:`RunConfig`, its checks and its JSON form."""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, fields, replace

from ..scenes import inclined
from ..solvers import FIRST_ORDER, methods

SCENES = ("sedimentation", "inclined_flow")
DEFAULT_FAST_SOLVER = "apgd"
"""The solver runs use by default when it is registered as a first-order method."""
REFERENCE_SOLVER = "clarabel"
"""The default otherwise (always registered)."""


def default_solver() -> str:
    """The default step solver of a run.

    Returns
    -------
    str
        :data:`DEFAULT_FAST_SOLVER` when it is registered among the
        first-order methods (``methods(kind="first-order")``), else
        :data:`REFERENCE_SOLVER`.
    """
    if DEFAULT_FAST_SOLVER in methods(kind=FIRST_ORDER):
        return DEFAULT_FAST_SOLVER
    return REFERENCE_SOLVER


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
    angle : float
        Incline angle (degrees) for ``inclined_flow``.
    steps : int
        Total steps of the run.
    dt_fraction : float
        Time step as a fraction of ``sqrt(d / g')`` (dimensionless).
    solver, tol : str, float
        Step solver and its tolerance (default solver: :func:`default_solver`).
    fixed_point : bool
        Exact Coulomb friction by the fixed point on s; default False: the
        convex relaxation, one solve per step (the fixed point cost 3x more
        and often hit its outer-iteration cap on flowing piles, see
        docs/records/validation.md).
    tol_fp, max_outer : float, int
        Tolerance and outer-iteration cap of that fixed point.
    joint : int
        Solve Coulomb's problem jointly inside the first APGD run, updating
        the shift every ``joint`` iterations, before the outer loop checks it
        (``solve_coulomb(joint=...)`` of :mod:`lubcontact.solvers.coulomb`;
        0: plain outer loop).
    friction : float or None
        Coulomb coefficient overriding the preset's ``mu`` (None: the preset's).
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
    average_from : float
        Profiles and means are time-averaged over steps after this fraction
        of the run.
    width : float
        Period along x in mean radii.
    seed : int
        Seed of the random grain sizes and initial lattice jitter.
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
    angle: float = 22.0
    steps: int = 1000
    dt_fraction: float = 0.01
    solver: str = field(default_factory=default_solver)
    tol: float = 1e-6
    fixed_point: bool = False
    tol_fp: float = 1e-8
    max_outer: int = 50
    joint: int = 0
    friction: float | None = None
    checkpoint_every: int = 200
    sample_every: int = 10
    frame_every: int = 0
    cross_check_every: int = 0
    settle_steps: int = 600
    settle_model: str = "frictionless"
    bed: str = ""
    average_from: float = 0.5
    width: float = 40.0
    seed: int = 0
    bins_per_radius: int = 2

    def __post_init__(self) -> None:
        if self.scene not in SCENES:
            raise ValueError(f"scene: must be one of {SCENES}, got {self.scene!r}")
        if self.preset not in inclined.PRESETS:
            raise ValueError(f"preset: must be one of {tuple(inclined.PRESETS)}, "
                             f"got {self.preset!r}")
        for name in ("model", "settle_model"):
            if getattr(self, name) not in inclined.MODELS:
                raise ValueError(f"{name}: must be one of {inclined.MODELS}, "
                                 f"got {getattr(self, name)!r}")
        for name in ("n_grains", "checkpoint_every", "sample_every", "bins_per_radius",
                     "max_outer"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name}: must be >= 1, got {getattr(self, name)}")
        for name in ("steps", "frame_every", "cross_check_every", "settle_steps", "joint"):
            if int(getattr(self, name)) < 0:
                raise ValueError(f"{name}: must be >= 0, got {getattr(self, name)}")
        if not self.tol_fp > 0:
            raise ValueError(f"tol_fp: must be > 0, got {self.tol_fp}")
        if self.friction is not None and not self.friction >= 0:
            raise ValueError(f"friction: must be >= 0, got {self.friction}")
        if not 0 <= self.average_from < 1:
            raise ValueError(f"average_from: must be in [0, 1), got {self.average_from}")

    @property
    def params(self) -> inclined.FlowParameters:
        """The preset's physical parameters, with ``friction`` applied when set."""
        params = inclined.PRESETS[self.preset]()
        return params if self.friction is None else replace(params, friction=self.friction)

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
