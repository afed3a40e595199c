"""Contact laws: which force set each contact gets, and how the gluey state evolves.

Laws: :class:`Inelastic` (dry, frictionless), :class:`Coulomb` (dry with
Coulomb friction), :class:`GlueyLubrication` (the gluey limit of lubrication,
frictionless) and :class:`GlueyCoulomb` (lubrication + friction: friction acts
only through asperities, at ``gamma = gamma_min``; docs/guide/model.md section 4).

A law turns the candidate contacts (and the per-pair state gamma) into
:class:`~lubcontact.problem.cones.Cones`, and updates gamma from the normal forces
after a step (docs/guide/model.md sections 1 and 3):

    gamma^{k+1} = min(0, max(gamma_min, gamma^k - dt lambda_n))

snapped to the nearer of 0 and gamma_min within ``state_rtol * dt * force_scale``
where ``force_scale`` is the larger of ``max |lambda|`` and the step problem's force
unit (so solver noise on an open contact never glues it, and a floor closer to 0
than that tolerance never glues an unpushed contact). Gamma has
units of impulse (force x time). Pairs are identified by their contact keys;
a pair that leaves the candidate list forgets its gamma.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .. import checks
from ..problem.cones import ConeKind, Cones
from .contacts import Contacts, lookup_by_key


@dataclass
class PairState:
    """Gamma per contact pair, kept sorted by pair key."""

    keys: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    gamma: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def lookup(self, keys: np.ndarray) -> np.ndarray:
        """Gamma of each given pair (0 for pairs not stored)."""
        return lookup_by_key(self.keys, self.gamma, np.asarray(keys))

    @classmethod
    def from_contacts(cls, keys: np.ndarray, gamma: np.ndarray) -> PairState:
        """Store the non-zero gammas of the current contacts (keys sorted)."""
        glued = gamma != 0
        order = np.argsort(keys[glued], kind="stable")
        return cls(keys=keys[glued][order].astype(np.int64), gamma=gamma[glued][order])


FrictionLike = float | Callable[[Contacts], np.ndarray]


class Law:
    """Base class: a frictionless, stateless inelastic law.

    Attributes
    ----------
    needs_rotation : bool
        Whether spins are unknowns of the step problem (only with friction).
    has_friction : bool
        Whether some contact may get a friction cone (then the integrator runs
        the fixed point on s unless told otherwise).
    """

    needs_rotation = False
    has_friction = False

    def cones(self, contacts: Contacts, gamma: np.ndarray) -> Cones:
        """Force sets for the contacts given their current gamma.

        The arrays of the returned :class:`~lubcontact.problem.cones.Cones` are new ones, never
        written afterwards: a :class:`~lubcontact.sim.simulation.Simulation` keeps the last
        step's cones, and what it derived from them, where the next step's hold the same sets."""
        return Cones.frictionless(np.full(contacts.count, ConeKind.NONNEG), contacts.dim - 1)

    def gamma_min(self, contacts: Contacts) -> np.ndarray:
        """Lower bound of gamma per contact (``-inf`` when roughness does not cap it)."""
        return np.full(contacts.count, -np.inf)

    def contact_states(self, contacts: Contacts, gamma: np.ndarray, active: np.ndarray
                       ) -> np.ndarray:
        """Which active contacts are unglued, glued or frictional.

        Here (no glue, no friction) every active contact is unglued; :class:`Coulomb`
        makes its contacts with ``mu > 0`` frictional, :class:`GlueyLubrication` sorts
        them by their glue state.

        Parameters
        ----------
        contacts : Contacts
        gamma : ndarray, shape (nc,)
            Glue state after the step.
        active : ndarray of bool, shape (nc,)
            Contacts that carry a force or are glued.

        Returns
        -------
        ndarray of bool, shape (3, nc)
            The masks ``(unglued, glued, frictional)``.
        """
        none = np.zeros_like(active)
        return np.stack([active, none, none])

    def update_gamma(self, contacts: Contacts, gamma: np.ndarray, normal_forces: np.ndarray,
                     dt: float, force_scale: float, *, gaps_after: np.ndarray | None = None,
                     length_scale: float = 1.0) -> np.ndarray:
        """Gamma after the step (zeros for a law without glue).

        Parameters
        ----------
        normal_forces : ndarray, shape (nc,)
            The step's normal forces (force units).
        force_scale : float
            Typical force of the step (the solver's force unit), for snapping.
        gaps_after : ndarray, shape (nc,), optional
            Gaps at the end of the step, ``D + dt u_n`` (length). With them a
            contact that ends the step open does not push (:func:`pushing`).
        length_scale : float
            The solver's length unit, to compare a gap with a force (:func:`pushing`).
        """
        return np.zeros(contacts.count)


class Inelastic(Law):
    """Dry, frictionless, perfectly inelastic unilateral contact (``lambda_n >= 0``)."""


class FrictionCoefficient:
    """A friction coefficient: one number, or a function of the contacts.

    Parameters
    ----------
    mu : float or callable
        ``mu >= 0`` for every contact, or ``mu(contacts) -> ndarray (nc,)``
        (per contact, e.g. looked up per material pair from ``body_a``,
        ``body_b``); values must be finite and >= 0.
    """

    def __init__(self, mu: FrictionLike):
        if callable(mu):
            self._function, self._value = mu, None
        else:
            self._function, self._value = None, float(checks.nonnegative("mu", mu, shape=()))

    @property
    def may_be_positive(self) -> bool:
        return self._function is not None or self._value > 0

    def __call__(self, contacts: Contacts) -> np.ndarray:
        if self._function is None:
            return np.full(contacts.count, self._value)
        return checks.nonnegative("mu", self._function(contacts), shape=(contacts.count,))


def _friction_cones(kinds: np.ndarray, mu: np.ndarray, dim: int) -> Cones:
    """Cones with tangential rows for the COULOMB and UNION contacts, in contact order."""
    kinds = np.asarray(kinds, dtype=np.int8)
    with_rows = np.flatnonzero((kinds == ConeKind.COULOMB) | (kinds == ConeKind.UNION))
    return Cones(kinds=kinds, mu=np.asarray(mu, dtype=float), tangential=with_rows,
                 tangent_dim=dim - 1)


class Coulomb(Law):
    """Dry unilateral contact with Coulomb friction ``|lambda_T| <= mu lambda_n``.

    Contacts with ``mu = 0`` get no tangential rows (plain ``lambda_n >= 0``);
    with ``mu = 0`` everywhere the law is :class:`Inelastic` and no rotational
    unknowns are modelled.

    Parameters
    ----------
    mu : float or callable
        Friction coefficient (dimensionless, >= 0), or ``mu(contacts) ->
        ndarray (nc,)`` for per-contact or per-material-pair values.
    """

    def __init__(self, mu: FrictionLike):
        self.mu = FrictionCoefficient(mu)
        self.needs_rotation = self.has_friction = self.mu.may_be_positive

    def cones(self, contacts: Contacts, gamma: np.ndarray) -> Cones:
        mu = self.mu(contacts)
        kinds = np.where(mu > 0, ConeKind.COULOMB, ConeKind.NONNEG)
        return _friction_cones(kinds, mu, contacts.dim)

    def contact_states(self, contacts: Contacts, gamma: np.ndarray, active: np.ndarray
                       ) -> np.ndarray:
        """:meth:`Law.contact_states`: an active contact is frictional where ``mu > 0``,
        unglued where ``mu = 0``; none is glued."""
        frictional = active & (self.mu(contacts) > 0)
        return np.stack([active & ~frictional, np.zeros_like(active), frictional])


def pushing(normal_forces: np.ndarray, gaps_after: np.ndarray, force_scale: float,
            length_scale: float) -> np.ndarray:
    """The normal forces with the pushes of contacts that end the step open set to 0.

    Complementarity (a contact pushes only while closed) holds to the solver's
    accuracy: an open contact may keep a small force, a pushed one a small gap.
    The side that is noise is the smaller of the two in the solver's units: a
    contact whose gap after the step (in ``length_scale``) exceeds its force (in
    ``force_scale``) is open and its push is noise; it must not glue the
    contact, which would then have to close that gap in one step. Pulls are
    kept.

    Parameters
    ----------
    normal_forces, gaps_after : ndarray, shape (nc,)
        Normal forces (force) and gaps at the end of the step (length).
    force_scale, length_scale : float
        The solver's force and length units (``SolveResult.force_scale``,
        ``SolveResult.length_scale``).
    """
    opening = gaps_after / length_scale > normal_forces / force_scale
    return np.where(opening, np.minimum(normal_forces, 0.0), normal_forces)


class GlueyLubrication(Law):
    """The gluey limit of lubrication (frictionless).

    Unglued contacts (gamma = 0) are unilateral; glued ones (gamma < 0) are
    bilateral and store the impact and push impulses in gamma.

    Parameters
    ----------
    gamma_min : float, optional
        Lower bound of gamma (< 0), the same for every contact.
    viscosity, roughness : float, optional
        Alternatively, ``eta`` and ``eps``: per contact
        ``gamma_min = 6 pi eta r_eff^2 ln(eps / r_eff)`` (docs/guide/model.md section 1).
        With neither, gamma is not bounded below.
    state_rtol : float
        Relative tolerance snapping gamma to 0 or gamma_min.
    """

    def __init__(self, gamma_min: float | None = None, *, viscosity: float | None = None,
                 roughness: float | None = None, state_rtol: float = 1e-6):
        if gamma_min is not None:
            checks.require(gamma_min < 0 and np.isfinite(gamma_min), "gamma_min",
                           "must be finite and < 0", gamma_min)
            checks.require(viscosity is None and roughness is None, "gamma_min",
                           "give gamma_min or (viscosity, roughness), not both", gamma_min)
        if (viscosity is None) != (roughness is None):
            raise ValueError(f"viscosity, roughness: give both or neither, got "
                             f"viscosity={viscosity}, roughness={roughness}")
        if viscosity is not None:
            checks.positive_scalar("viscosity", viscosity)
            checks.positive_scalar("roughness", roughness)
        self._gamma_min = gamma_min
        self.viscosity, self.roughness = viscosity, roughness
        self.state_rtol = checks.positive_scalar("state_rtol", state_rtol)

    def gamma_min(self, contacts: Contacts) -> np.ndarray:
        if self._gamma_min is not None:
            return np.full(contacts.count, float(self._gamma_min))
        if self.viscosity is None:
            return np.full(contacts.count, -np.inf)
        r_eff = contacts.effective_radius
        return gamma_min_from_roughness(self.viscosity, self.roughness, r_eff)

    def cones(self, contacts: Contacts, gamma: np.ndarray) -> Cones:
        kinds = np.where(gamma < 0, ConeKind.FREE, ConeKind.NONNEG)
        return Cones.frictionless(kinds, contacts.dim - 1)

    def contact_states(self, contacts: Contacts, gamma: np.ndarray, active: np.ndarray
                       ) -> np.ndarray:
        """:meth:`Law.contact_states`: an active contact at its floor (``gamma <= gamma_min``,
        finite) is frictional, one above it with ``gamma < 0`` glued, one with ``gamma = 0``
        unglued (with or without friction: the floor is where asperities touch)."""
        floor = self.gamma_min(contacts)
        frictional = active & np.isfinite(floor) & (gamma <= floor)
        return np.stack([active & (gamma == 0), active & (gamma < 0) & ~frictional, frictional])

    def update_gamma(self, contacts: Contacts, gamma: np.ndarray, normal_forces: np.ndarray,
                     dt: float, force_scale: float, *, gaps_after: np.ndarray | None = None,
                     length_scale: float = 1.0) -> np.ndarray:
        if gaps_after is not None:
            normal_forces = pushing(normal_forces, gaps_after, force_scale, length_scale)
        lower = self.gamma_min(contacts)
        new = np.minimum(0.0, np.maximum(lower, gamma - dt * normal_forces))
        largest = np.max(np.abs(normal_forces)) if normal_forces.size else 0.0
        tol = self.state_rtol * dt * max(largest, force_scale)
        # the nearer state wins where both are within tol (a floor |gamma_min| <= 2 tol):
        # an unpushed contact stays unglued, a saturated one stays at the floor
        from_zero, from_floor = np.abs(new), np.abs(new - lower)
        to_floor = (from_floor <= tol) & (from_floor < from_zero)
        new[(from_zero <= tol) & ~to_floor] = 0.0
        new[to_floor] = lower[to_floor]
        return new


class GlueyCoulomb(GlueyLubrication):
    """Lubrication + friction (the poster's last model).

    Per contact, by gluey state:

    - unglued (``gamma = 0``): unilateral, frictionless (``NONNEG``);
    - glued, ``gamma_min < gamma < 0``: bilateral, frictionless (``FREE``);
    - at ``gamma = gamma_min`` (asperities touch): the non-convex ``UNION`` of
      the Coulomb cone (pushed) and the pulled half-line (frictionless).

    Parameters
    ----------
    mu : float or callable
        Friction coefficient at the asperities (see :class:`Coulomb`).
    gamma_min, viscosity, roughness, state_rtol
        As for :class:`GlueyLubrication`. Without a finite ``gamma_min`` no
        contact ever reaches the asperities and the law is frictionless.
    """

    def __init__(self, mu: FrictionLike, gamma_min: float | None = None, *,
                 viscosity: float | None = None, roughness: float | None = None,
                 state_rtol: float = 1e-6):
        super().__init__(gamma_min, viscosity=viscosity, roughness=roughness, state_rtol=state_rtol)
        self.mu = FrictionCoefficient(mu)
        capped = gamma_min is not None or viscosity is not None
        self.needs_rotation = self.has_friction = capped and self.mu.may_be_positive

    def cones(self, contacts: Contacts, gamma: np.ndarray) -> Cones:
        lower = self.gamma_min(contacts)
        at_floor = np.isfinite(lower) & (gamma <= lower) & (gamma < 0)
        mu = self.mu(contacts) if self.has_friction else np.zeros(contacts.count)
        kinds = np.where(gamma < 0, ConeKind.FREE, ConeKind.NONNEG)
        # at the floor with mu = 0 the union {pushed} U {pulled} is all of R: FREE
        kinds = np.where(at_floor & (mu > 0), ConeKind.UNION, kinds)
        return _friction_cones(kinds, mu, contacts.dim)


def gamma_min_from_roughness(viscosity: float, roughness: float, r_eff: np.ndarray) -> np.ndarray:
    """``gamma_min = k ln(eps / r_eff)`` with ``k = 6 pi eta r_eff^2`` (q_ref = r_eff).

    Parameters
    ----------
    viscosity : float
        Fluid viscosity ``eta`` (Pa s in SI).
    roughness : float
        Asperity height ``eps`` (length).
    r_eff : ndarray
        Effective radius of each contact (length).
    """
    rough = np.flatnonzero(roughness >= r_eff)
    checks.require(rough.size == 0, "roughness", f"must be smaller than the effective radius of "
                   f"every contact (gamma_min >= 0 would switch the glue off), got {roughness} "
                   f"against an effective radius {float(np.min(r_eff, initial=np.inf)):.6g}")
    k = 6.0 * np.pi * viscosity * r_eff**2
    return k * np.log(roughness / r_eff)
