"""Measurements of a periodic layer flowing along x (docs/guide/model.md section 8).

Profiles are exact area averages over horizontal slabs: a disk of centre
height ``y_i`` and radius ``r_i`` covers the area ``A_i(k)`` of slab ``k``
(``z_k <= y < z_{k+1}``), computed in closed form. With the period ``L``:

- packing fraction ``phi(z_k) = sum_i A_i(k) / (L dz)``;
- velocity ``u(z_k) = sum_i A_i(k) v_x,i / sum_i A_i(k)`` (area-weighted);
- flow rate (area flux per unit depth, length^2 / time)
  ``Q = int phi u dz = sum_i pi r_i^2 v_x,i / L``.

Contacts are *unglued*, *glued* (lubricated) or *frictional* (asperities
touch) by the law's rule (:meth:`~lubcontact.model.laws.Law.contact_states`);
only contacts that carry a force or are glued count (a candidate with an open
gap does not).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize

from .. import checks
from ..model.scene import Scene
from .config import STEADY_TOL, STOP_RATIO

STATES = ("unglued", "glued", "frictional")


def disk_area_below(height: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Area of a disk of radius ``r`` below a line at ``height`` above its centre.

    ``r^2 (asin(u) + u sqrt(1 - u^2) + pi/2)`` with ``u = clip(height / r, -1, 1)``.

    Parameters
    ----------
    height, radius : ndarray
        Lengths, broadcast against each other.

    Returns
    -------
    ndarray
        Areas (length^2), of the broadcast shape.
    """
    u = np.clip(height / radius, -1.0, 1.0)
    return radius**2 * (np.arcsin(u) + u * np.sqrt(1.0 - u * u) + 0.5 * np.pi)


def slab_areas(heights: np.ndarray, radii: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Area of each disk inside each slab ``[edges[k], edges[k+1])``.

    Parameters
    ----------
    heights, radii : ndarray, shape (N,)
        Centre heights and radii of the disks (length).
    edges : ndarray, shape (K + 1,)
        Slab boundaries (length).

    Returns
    -------
    ndarray, shape (N, K)
        Areas (length^2).
    """
    below = disk_area_below(edges[None, :] - heights[:, None], radii[:, None])
    return np.diff(below, axis=1)


@dataclass
class Profile:
    """Depth profiles of a layer (heights measured from the plane ``y = 0``).

    Attributes
    ----------
    edges : ndarray, shape (K + 1,)
        Slab boundaries (length).
    packing : ndarray, shape (K,)
        Area fraction of grains per slab.
    velocity : ndarray, shape (K,)
        Area-weighted mean downhill velocity per slab (length / time; NaN in
        empty slabs).
    """

    edges: np.ndarray
    packing: np.ndarray
    velocity: np.ndarray

    @property
    def centres(self) -> np.ndarray:
        """Slab mid-heights, shape (K,) (length)."""
        return 0.5 * (self.edges[1:] + self.edges[:-1])


@dataclass
class ProfileAccumulator:
    """Time average of profiles over samples (sums of areas and area x velocity).

    Parameters
    ----------
    edges : ndarray, shape (K + 1,)
        Slab boundaries (length), increasing.
    period : float
        Length of the periodic cell along x.
    area, momentum : ndarray, shape (K,), optional
        Sums so far of the grain area (length^2) and of area x downhill
        velocity (length^3 / time) per slab (default zeros).
    samples : int
        Number of samples in those sums.
    """

    edges: np.ndarray
    period: float
    area: np.ndarray = field(default=None)
    momentum: np.ndarray = field(default=None)
    samples: int = 0

    def __post_init__(self):
        self.edges = checks.as_array("edges", self.edges, shape=(None,))
        checks.require(self.edges.size >= 2 and bool(np.all(np.diff(self.edges) > 0)), "edges",
                       "must be increasing with at least two entries", self.edges)
        self.period = checks.positive_scalar("period", self.period)
        k = self.edges.size - 1
        self.area = np.zeros(k) if self.area is None else np.asarray(self.area, dtype=float)
        self.momentum = np.zeros(k) if self.momentum is None else np.asarray(self.momentum, float)

    def add(self, scene: Scene) -> None:
        """Accumulate the current state of ``scene``.

        The grid grows upwards (slabs as wide as its top one) to cover every
        grain: a flowing layer dilates above its settled height, and a grid cut
        below the free surface would hide the dilute surface layer.
        """
        grains = scene.grains
        self._cover(float(np.max(grains.positions[:, 1] + grains.radii, initial=self.edges[-1])))
        areas = slab_areas(grains.positions[:, 1], grains.radii, self.edges)
        self.area += areas.sum(axis=0)
        self.momentum += areas.T @ grains.velocities[:, 0]
        self.samples += 1

    def profile(self) -> Profile:
        """The time-averaged profile of the samples so far."""
        widths = np.diff(self.edges)
        count = max(self.samples, 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            velocity = np.where(self.area > 0, self.momentum / self.area, np.nan)
        return Profile(edges=self.edges.copy(), packing=self.area / (count * self.period * widths),
                       velocity=velocity)

    def _cover(self, top: float) -> None:
        """Append empty slabs, as wide as the top one, until the grid reaches ``top``."""
        if top <= self.edges[-1]:
            return
        width = self.edges[-1] - self.edges[-2]
        extra = int(np.ceil((top - self.edges[-1]) / width))
        self.edges = np.concatenate([self.edges, self.edges[-1] + width * np.arange(1, extra + 1)])
        self.area = np.concatenate([self.area, np.zeros(extra)])
        self.momentum = np.concatenate([self.momentum, np.zeros(extra)])

    def reset(self) -> None:
        """Forget the samples (the grid is kept)."""
        self.area[:] = 0.0
        self.momentum[:] = 0.0
        self.samples = 0


def profile(scene: Scene, edges: np.ndarray) -> Profile:
    """The instantaneous profile of a periodic scene.

    Parameters
    ----------
    scene : Scene
        Periodic along x.
    edges : ndarray, shape (K + 1,)
        Slab boundaries (length), increasing; extended upwards if grains lie above.

    Returns
    -------
    Profile
    """
    accumulator = ProfileAccumulator(edges, _period(scene))
    accumulator.add(scene)
    return accumulator.profile()


def _period(scene: Scene) -> float:
    checks.require(scene.period is not None, "scene.period", "measurements need a periodic scene",
                   None)
    return float(scene.period)


def flow_rate(scene: Scene) -> float:
    """``Q = sum_i pi r_i^2 v_x,i / L``: grain area crossing a section per unit time.

    Parameters
    ----------
    scene : Scene
        Periodic along x, of period ``L``.

    Returns
    -------
    float
        Flow rate (length^2 / time).
    """
    grains = scene.grains
    return float(np.pi * grains.radii**2 @ grains.velocities[:, 0] / _period(scene))


def mean_velocity(scene: Scene) -> float:
    """Mass-weighted mean downhill velocity of the free grains (length / time)."""
    masses = scene.grains.masses
    return float(masses @ scene.grains.velocities[:, 0] / np.sum(masses))


def kinetic_energy(scene: Scene) -> float:
    """Translational plus rotational kinetic energy of the free grains.

    Returns
    -------
    float
        ``sum_i (m_i |v_i|^2 + I_i |w_i|^2) / 2`` (mass length^2 / time^2).
    """
    grains = scene.grains
    return float(0.5 * grains.masses @ np.sum(grains.velocities**2, axis=1)
                 + 0.5 * grains.inertias @ np.sum(grains.spins**2, axis=1))


def coordination(masks: np.ndarray, a_is_free: np.ndarray, n_grains: int) -> np.ndarray:
    """Contacts per free grain in each state, shape (len(masks),).

    A contact between two free grains counts for both, one with a fixed body
    (a bed grain, a plane) for its free grain only (``body_b`` is always free).

    Parameters
    ----------
    masks : ndarray of bool, shape (k, nc)
        Contacts in each state (:meth:`~lubcontact.model.laws.Law.contact_states`).
    a_is_free : ndarray of bool, shape (nc,)
        Whether each contact's first body is a free grain (``Contacts.a_is_free``).
    n_grains : int
        Number of free grains.
    """
    ends = 1.0 + np.asarray(a_is_free, dtype=float)
    return (masks @ ends) / max(int(n_grains), 1)


def glue_level(gamma: np.ndarray, gamma_min: np.ndarray) -> np.ndarray:
    """How deep each contact is in its glue, relative to its floor.

    Parameters
    ----------
    gamma, gamma_min : ndarray, shape (nc,)
        Glue state and its floor (impulse; ``-inf``: no floor).

    Returns
    -------
    ndarray, shape (nc,)
        ``gamma / gamma_min`` clipped to ``[0, 1]`` (dimensionless): 0 unglued or just glued
        (lubricated), 1 at the floor (frictional); 0 where the floor is not finite.
    """
    floored = np.isfinite(gamma_min) & (gamma_min < 0)
    return np.where(floored, np.clip(gamma / np.where(floored, gamma_min, -1.0), 0.0, 1.0), 0.0)


def gamma_histogram(gamma: np.ndarray, gamma_min: np.ndarray, bins: int = 20) -> np.ndarray:
    """Histogram of :func:`glue_level` over glued contacts with a floor, shape (bins,).

    0 is lubricated (just glued), 1 is frictional (at the floor).
    """
    glued = (gamma < 0) & np.isfinite(gamma_min)
    return np.histogram(glue_level(gamma[glued], gamma_min[glued]), bins=bins,
                        range=(0.0, 1.0))[0]


def layer_height(prof: Profile, fraction: float = 0.5) -> float:
    """Free-surface height: where the packing falls to ``fraction`` of the bulk packing (length).

    The bulk packing is the median over the occupied slabs; the crossing above
    the highest slab at or over the threshold is interpolated linearly between
    slab centres.

    Raises
    ------
    ValueError
        If the top slab of the grid is still at or over the threshold: the
        surface lies above the grid and cannot be located.
    """
    occupied = prof.packing > 0
    checks.require(bool(np.any(occupied)), "prof", "the profile holds no grain", 0)
    threshold = fraction * float(np.median(prof.packing[occupied]))
    last = int(np.flatnonzero(prof.packing >= threshold)[-1])
    checks.require(last + 1 < prof.packing.size, "prof",
                   "the top slab is still dense: the free surface lies above the profile grid",
                   prof.packing[-1])
    z, phi = prof.centres, prof.packing
    weight = (phi[last] - threshold) / (phi[last] - phi[last + 1])
    return float(z[last] + weight * (z[last + 1] - z[last]))


@dataclass
class BagnoldFit:
    """Least-squares fit of ``u(z) = u_s - A (h - z)^n`` (:func:`fit_bagnold`).

    Attributes
    ----------
    exponent : float
        ``n`` (Bagnold: 3/2).
    exponent_error : float
        Standard error of ``n`` from the fit's Jacobian, with slabs taken as
        independent (they are not quite: a lower bound).
    surface_velocity : float
        ``u_s`` (length / time), fitted, not read from a slab.
    amplitude : float
        ``A`` (length^(1 - n) / time).
    surface : float
        ``h``, the free surface the depth is measured from (length).
    fit_range : (float, float)
        Heights of the lowest and highest slab centre used (length).
    slabs : int
        Number of slabs fitted.
    rms_residual : float
        Root mean square of ``u - fit`` over those slabs (length / time).
    """

    exponent: float
    exponent_error: float
    surface_velocity: float
    amplitude: float
    surface: float
    fit_range: tuple[float, float]
    slabs: int
    rms_residual: float


EXPONENT_BOUNDS = (0.2, 5.0)


def _bagnold_linear_part(depth: np.ndarray, u: np.ndarray, exponent: float
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Best ``(u_s, A)`` for a given exponent (linear least squares) and the residual vector."""
    design = np.stack([np.ones_like(depth), -depth**exponent], axis=1)
    coefficients = np.linalg.lstsq(design, u, rcond=None)[0]
    return coefficients, u - design @ coefficients


def fit_bagnold(prof: Profile, bottom: float, surface: float, diameter: float, *,
                bed_layers: float = 2.0, surface_layers: float = 1.0) -> BagnoldFit:
    """Fit ``u(z) = u_s - A (h - z)^n`` on the dense part of a time-averaged profile.

    ``u_s``, ``A`` and ``n`` are free (least squares on ``u`` itself, not on
    ``log(u_s - u)``, so slabs near the surface where ``u_s - u`` is small and
    noisy carry no excess weight); the depth is measured from the free surface
    ``h`` of the packing profile (:func:`layer_height`), not from the top grain.
    Slabs within ``bed_layers`` diameters of the bed top (the layers that feel
    the bed) and within ``surface_layers`` diameters of ``h`` (the dilute
    surface layer) are left out.

    Parameters
    ----------
    prof : Profile
        A time-averaged profile.
    bottom : float
        Height of the bed top (length).
    surface : float
        Free-surface height ``h`` (length).
    diameter : float
        Mean grain diameter (length), the unit of the margins.
    bed_layers, surface_layers : float
        Margins left out at the bed and below the surface (grain diameters).

    Returns
    -------
    BagnoldFit
    """
    checks.require(surface > bottom, "surface", "must be above bottom", surface)
    diameter = checks.positive_scalar("diameter", diameter)
    low, high = bottom + bed_layers * diameter, surface - surface_layers * diameter
    z, u = prof.centres, prof.velocity
    use = (z > low) & (z < high) & np.isfinite(u)
    checks.require(np.count_nonzero(use) >= 5, "prof", "fewer than 5 slabs in the dense part",
                   np.count_nonzero(use))
    depth, u = surface - z[use], u[use]
    search = optimize.minimize_scalar(
        lambda n: float(np.sum(_bagnold_linear_part(depth, u, n)[1]**2)),
        bounds=EXPONENT_BOUNDS, method="bounded", options={"xatol": 1e-10})
    exponent = float(search.x)
    checks.require(EXPONENT_BOUNDS[0] + 1e-3 < exponent < EXPONENT_BOUNDS[1] - 1e-3, "prof",
                   f"fitted exponent at the search bound {EXPONENT_BOUNDS}", exponent)
    (u_s, amplitude), residual = _bagnold_linear_part(depth, u, exponent)
    power = depth**exponent
    jacobian = np.stack([np.ones_like(depth), -power, -amplitude * power * np.log(depth)], axis=1)
    variance = np.sum(residual**2) / max(depth.size - 3, 1)
    covariance = variance * np.linalg.pinv(jacobian.T @ jacobian)
    return BagnoldFit(exponent=exponent, exponent_error=float(np.sqrt(covariance[2, 2])),
                      surface_velocity=float(u_s), amplitude=float(amplitude),
                      surface=float(surface), fit_range=(float(z[use][0]), float(z[use][-1])),
                      slabs=int(depth.size), rms_residual=float(np.sqrt(np.mean(residual**2))))


@dataclass
class FlowState:
    """Verdict of :func:`classify_flow`.

    Attributes
    ----------
    label : str
        ``"no_flow"``, ``"steady"``, ``"accelerating"`` or ``"transient"``.
    energy_ratio : float
        Last kinetic energy over the largest one.
    relative_change : float
        Change of the mean flow rate between the two halves of the window,
        over the mean flow rate.
    """

    label: str
    energy_ratio: float
    relative_change: float


def classify_flow(times: np.ndarray, energy: np.ndarray, rate: np.ndarray, *,
                  stop_ratio: float = STOP_RATIO, steady_tol: float = STEADY_TOL,
                  window: float = 0.5, peak_energy: float | None = None) -> FlowState:
    """Classify a run from its kinetic energy and flow-rate series.

    - ``no_flow``: the energy fell below ``stop_ratio`` of its maximum (``peak_energy``
      when given: the run's largest energy where the series is a window of it);
    - otherwise the last ``window`` fraction of the samples is split in two
      halves: ``steady`` if their mean flow rates differ by less than
      ``steady_tol`` (relative), ``accelerating`` if the rate grew by more,
      ``transient`` if it decreased by more (still decaying).
    """
    times = checks.as_array("times", times, shape=(None,))
    energy = checks.as_array("energy", energy, shape=times.shape)
    rate = checks.as_array("rate", rate, shape=times.shape)
    checks.require(times.size >= 4, "times", "need at least 4 samples", times.size)
    peak = float(energy.max()) if peak_energy is None else max(float(peak_energy),
                                                                float(energy.max()))
    ratio = float(energy[-1] / peak) if peak > 0 else 0.0
    tail = rate[int((1.0 - window) * rate.size):]
    half = tail.size // 2
    first, second = tail[:half].mean(), tail[half:].mean()
    scale = max(abs(first), abs(second), np.finfo(float).tiny)
    change = float((second - first) / scale)
    if ratio < stop_ratio:
        label = "no_flow"
    elif abs(change) < steady_tol:
        label = "steady"
    else:
        label = "accelerating" if change > 0 else "transient"
    return FlowState(label=label, energy_ratio=ratio, relative_change=change)


@dataclass
class WindowStatistics:
    """A sampled series over a window of steps (:func:`window_statistics`).

    Attributes
    ----------
    mean : float
        Mean of the samples in the window.
    standard_error : float
        Block standard error: the standard deviation of the block means over ``sqrt(blocks)``
        (samples within a block are correlated, block means much less).
    trend : float
        Last block's mean minus the first's (their middles ``length - length / blocks`` steps
        apart), in the series' unit.
    blocks : ndarray, shape (blocks,)
        The block means.
    centres : ndarray, shape (blocks,)
        The blocks' middle steps.
    """

    mean: float
    standard_error: float
    trend: float
    blocks: np.ndarray
    centres: np.ndarray


def window_statistics(steps: np.ndarray, values: np.ndarray, end: int, length: int,
                      blocks: int = 5) -> WindowStatistics:
    """The mean, block standard error and trend of ``values`` over the steps ``(end - length,
    end]``, cut into ``blocks`` equal blocks of steps.

    Parameters
    ----------
    steps : ndarray of int, shape (n,)
        The step of each sample (a run's ``series.step``).
    values : ndarray, shape (n,)
        The sampled quantity (e.g. ``series.flow_rate``).
    end, length : int
        Last step of the window and its length in steps; ``length`` a multiple of ``blocks``.
    blocks : int
        Number of blocks, >= 2.

    Raises
    ------
    ValueError
        For a window that is not a whole number of blocks or has a block without samples, or
        a non-finite value anywhere in ``values`` (a series restored as NaN from an older
        checkpoint: cut it to the window first).
    """
    steps = checks.as_array("steps", steps, shape=(None,))
    values = checks.as_array("values", values, shape=steps.shape)
    blocks = checks.integer("blocks", blocks, minimum=2)
    length = checks.integer("length", length, minimum=blocks)
    end = checks.integer("end", end, minimum=length)
    checks.require(length % blocks == 0, "length", f"must be a multiple of blocks = {blocks}", length)
    size = length // blocks
    starts = end - length + size * np.arange(blocks)
    means = []
    for start in starts:                      # a few blocks: not a loop over samples
        inside = (steps > start) & (steps <= start + size)
        checks.require(inside.any(), "end", f"no sample in the block of steps ({start}, "
                                            f"{start + size}]", end)
        means.append(values[inside].mean())
    means = np.array(means)
    window = (steps > end - length) & (steps <= end)
    return WindowStatistics(mean=float(values[window].mean()),
                            standard_error=float(means.std(ddof=1) / np.sqrt(blocks)),
                            trend=float(means[-1] - means[0]), blocks=means,
                            centres=starts + 0.5 * size)


@dataclass
class ApproachFit:
    """An exponential approach fitted to block means (:func:`fit_approach`).

    Attributes
    ----------
    limit, limit_error : float
        The value the series approaches and its standard error (the series' unit); NaN when
        the series shows no approach (``found`` False).
    tau, tau_error : float
        The time constant and its standard error, in steps; NaN as ``limit``.
    found : bool
        Whether an approach was found (:func:`fit_approach`).
    """

    limit: float
    limit_error: float
    tau: float
    tau_error: float
    found: bool


APPROACH_MAX_TAU_SPANS = 10.0
"""Longest time constant :func:`fit_approach` accepts, in spans of the fitted blocks' centres:
beyond, the blocks lie on a straight line and the limit is not determined by them."""
APPROACH_SIGNIFICANCE = 3.0
"""Smallest amplitude of an approach :func:`fit_approach` accepts, in its standard errors: below,
the block means' noise alone could give it (pure noise gave an approach for 25-40 % of seeds
without this test)."""


def fit_approach(centres: np.ndarray, means: np.ndarray) -> ApproachFit:
    """Fit ``m(t) = limit - amplitude exp(-(t - t_0) / tau)`` to block means (least squares).

    The limit is the steady value of a flow still accelerating or slowing, extrapolated from
    how its approach slows down. Its error is the fit's (the covariance of the least-squares
    fit scaled by the residuals): it does not include how far the exponential form is from
    the flow's own approach, which can be larger (the records measure it on runs long enough
    to compare). No approach is found (``found`` False, NaN values) when the means do not vary
    (a level series: its mean is its steady value), when the fit does not converge or its
    covariance cannot be estimated, when ``tau`` is not positive or longer than
    :data:`APPROACH_MAX_TAU_SPANS` times the span of the centres (a straight line), or when the
    amplitude is below :data:`APPROACH_SIGNIFICANCE` of its standard errors (noise). The fit
    runs on the means shifted and scaled to a unit range, so their offset and unit do not
    matter.

    Parameters
    ----------
    centres : ndarray, shape (k,)
        The blocks' middle steps (``WindowStatistics.centres``), increasing, k >= 4.
    means : ndarray, shape (k,)
        The block means (``WindowStatistics.blocks``), in the series' unit.

    Returns
    -------
    ApproachFit
        ``limit`` and ``limit_error`` in the means' unit, ``tau`` and ``tau_error`` in steps.

    Raises
    ------
    ValueError
        Naming ``means`` for fewer than four blocks (three parameters) or a non-finite mean,
        ``centres`` when they do not increase.
    """
    centres = checks.as_array("centres", centres, shape=(None,))
    means = checks.as_array("means", means, shape=centres.shape)
    checks.require(means.size >= 4, "means", "need at least 4 blocks to fit 3 parameters",
                   means.size)
    checks.require(bool(np.all(np.diff(centres) > 0)), "centres", "must increase", centres)
    none = ApproachFit(limit=np.nan, limit_error=np.nan, tau=np.nan, tau_error=np.nan,
                       found=False)
    spread = float(np.ptp(means))
    if spread == 0:
        return none
    span = float(centres[-1] - centres[0])
    elapsed = centres - centres[0]
    unit = (means - means[-1]) / spread                 # the fit in a unit range

    def model(t: np.ndarray, limit: float, amplitude: float, tau: float) -> np.ndarray:
        return limit - amplitude * np.exp(-t / tau)

    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("error", optimize.OptimizeWarning)    # no covariance: none
            parameters, covariance = optimize.curve_fit(
                model, elapsed, unit, p0=(0.0, unit[-1] - unit[0], span / 2), maxfev=20000)
    except (RuntimeError, optimize.OptimizeWarning):
        return none
    limit, amplitude, tau = (float(value) for value in parameters)
    errors = np.sqrt(np.diag(covariance))
    if not (0 < tau <= APPROACH_MAX_TAU_SPANS * span and np.isfinite(errors).all()
            and abs(amplitude) > APPROACH_SIGNIFICANCE * errors[1]):
        return none
    return ApproachFit(limit=float(means[-1] + spread * limit),
                       limit_error=float(spread * errors[0]), tau=tau,
                       tau_error=float(errors[2]), found=True)
