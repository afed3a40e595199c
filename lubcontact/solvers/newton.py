"""Semismooth Newton on the Alart-Curnier function: exact Coulomb friction in a few sparse solves.

The first-order methods need 10^3-10^5 iterations where Coulomb's law is
stiff (dense piles, large ``mu``); a Newton method on a non-smooth equation
needs tens. With ``u = W r + q`` (the problem's offset ``b`` without any shift
``s``), ``rho_c > 0`` per contact and ``y = r - rho u``, Coulomb's law and the
frictionless force sets are the zeros of (Alart and Curnier, 1991)::

    phi(r) = r - P(y)

    P_n(y) = max(y_n, 0)                                     NONNEG and COULOMB normal rows
    P_T(y) = projection of y_T onto the disk of radius       COULOMB and UNION tangential rows
             mu max(y_n, 0)
    P_i(y) = clip(y_i, lo_i, hi_i)                           other rows: FREE (R), NONPOS,
                                                             UNION normal rows (R),
                                                             tangential rows forced to 0

``phi = 0`` says: the normal force and the normal velocity are complementary,
the tangential force lies in the friction disk, and a sliding contact's force
opposes its sliding velocity; it is Coulomb's law itself, not the convex
relaxation, so the method is registered with ``native_coulomb=True`` and the
fixed point on ``s`` is not needed (:func:`~lubcontact.solvers.solve_coulomb`
runs it once).

UNION contacts (gluey + friction at ``gamma_min``) are solved natively too. At
a solution of the union law the contact stays closed on either piece (pushed:
a positive force keeps the gap at 0; pulled: the glue holds it at 0; a vanishing
force on an opening contact is what the branch rule of the fixed point flips to
the pulled piece), so its law is a bilateral normal row (``P_n(y) = y_n``, any
normal force) with Coulomb's disk of radius ``mu max(y_n, 0)`` on its
tangential rows: friction while pushed, none while pulled. One Newton solve
replaces the branch rule's re-solves (``UNION`` is in the method's cones).

Newton step. ``P`` is piecewise smooth; with ``G`` an element of its
generalised Jacobian at ``y`` (block diagonal per contact: 0 or 1 on box rows,
1 on a pushed normal row, the identity on a sticking tangential block,
``(R/|y_T|) (I - t t^T)`` and the column ``mu t`` on a sliding one, ``t =
y_T/|y_T|``), the Jacobian of ``phi`` is ``J = I - G + G diag(rho) W``. Rows
where ``G`` vanishes (open contacts, zero-forced rows) are identity rows: their
update is ``-phi`` and they are eliminated, so the LU factorisation (sparse above
``DENSE_LIMIT`` rows: :class:`~lubcontact.solvers.factorisations.Factorisations`) is of the
active rows only. A 2D problem of up to :data:`COMPILED_LIMIT` rows runs each Newton phase in one
compiled call on the dense ``W`` (:func:`~lubcontact.solvers.kernels.newton_phase_2d`, with
the numpy phase's rules; from :data:`STATIC_DENSE_ROWS` rows with ``W`` also by its rows and
each block factorised sparse, in a minimum-degree order of ``W``, LAPACK's LU the fallback);
there and
on a larger 2D problem the Newton system is solved without its sliding tangential rows: in 2D
``I - t t^T`` vanishes, so such a row says ``d_T = mu t d_n`` plus a constant, and its unknown
folds into its normal row's (:meth:`AlartCurnier.newton_direction`,
:func:`~lubcontact.solvers.kernels.newton_direction_2d`). The numpy phase, the compiled one's
reference in the tests, factorises the whole active block; the two directions agree to
round-off where the block is regular.

Globalisation: a non-monotone Armijo line search on ``psi = |phi|^2 / 2``
(the reference value is the largest of the last few); when the Newton
direction gives no decrease, the steepest-descent direction of ``psi``,
``-J^T phi``, is tried instead. Where ``W`` is rank deficient (more contact
rows than degrees of freedom: a hyperstatic packing, most dense piles) the
Newton system is singular at sticking contacts; a proximal-point outer loop
(as in Siconos' PROX) makes each subproblem well posed: solve with ``W + sigma
I`` and ``q - sigma r_k``, centre ``r_k`` at the result, shrink ``sigma`` after
each subproblem solved (:func:`_proximal_newton`). The starting ``sigma`` values of
:data:`STRATEGIES` are tried in turn while one stalls far from ``tol``, after a few plain
Newton iterations on small frictionless problems with a warm start (:data:`PLAIN_TRY`).
Stopping: the FCLIB error (:func:`~lubcontact.problem.metrics.coulomb_error`, the measure
every report uses) below ``tol``. When every strategy stalls, the best iterate goes
to fallbacks in turn (``fallback``; in 2D Gauss-Seidel, then apgd-jacobi's fixed
point), each answer polished by Newton and kept when it beats the best so far, until one is
below ``tol``, or kept within :data:`FALLBACK_GAP` ``tol``; Gauss-Seidel in rounds, each
polished (:func:`fallback_rounds`).
"""
from __future__ import annotations

import inspect
import time
import warnings
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .. import checks
from ..problem.cones import Cones
from ..problem.conic import ConicProblem
from ..problem.metrics import coulomb_error
from ..problem.step import diagonal_scaled
from .compiled_apgd import csr_arrays, joint_applies, joint_coulomb_apgd, operator_arrays
from .compiled_modules import kernels, ordering
from .coulomb import solve_coulomb
from .dual_data import DENSE_LIMIT, dense_lu, dense_lu_solve, is_small
from .factorisations import STATIC_LU_BACKWARD_ERROR, Factorisations, places_of
from .gauss_seidel import Sweeps
from .registry import ALL_CONES, NEWTON, methods, register, solver_info
from .result import CONVERGED, DIVERGED, FAILED, INACCURATE, MAX_ITER, MethodOutput

LINE_SEARCH_MEMORY = 5
"""Non-monotone line search: ``psi`` is compared with the largest of this many last values."""

ARMIJO = 1e-4
"""Sufficient decrease factor of the line search."""

REGULARISATIONS = np.array([0.0, 1e-10, 1e-8, 1e-6, 1e-4])
"""Diagonal shifts tried in turn when the factorised block of a Newton system is singular
(:func:`_block_solve`; an array, as the compiled phases take it)."""

COMPILED_LIMIT = 700
"""The rows up to which a 2D problem takes the compiled lane (each Newton phase in one compiled
call, :func:`~lubcontact.solvers.kernels.newton_phase_2d`) rather than the sparse lane; its
proximal loop follows the same rules either way (:attr:`AlartCurnier.flow_step`), and both took
the same Newton iterations on every step measured. Over 100 captured steps of developed flows
(exact Coulomb, tol 1e-6), against ``DENSE_LIMIT`` (300): gluey 90 grains (298-344 rows) 0.50 of
the time, gluey 150 grains (518-558 rows) 0.72, dry 150 grains (650-660 rows, without the joint
phase, which costs more than it saves there: 42.5 ms per step against 51.5 with it) 0.78;
settling piles of 200 and 230 grains (600-680 rows) 0.96-1.0, a gluey 250-grain flow (866-937
rows) 1.0 (docs/records/benchmarks.md, "the compiled lane to 700 rows")."""

STATIC_DENSE_ROWS = 96
"""On the compiled lane (a 2D problem of at most :data:`COMPILED_LIMIT` rows), the rows from which
the products ``W x`` read ``W`` by its rows and the Newton blocks are factorised sparse, without
pivoting, in a minimum-degree order of ``W`` (``AlartCurnier.elimination_places``), rather
than by LAPACK's dense LU: a 40-grain pile's blocks (about 80 of its 130 rows, 6 % of ``W``'s
entries not zero) in 19 us against 33, the order 13 us at 100 rows, found again only where the
pattern of ``W`` changed (:func:`elimination_places`); below about 96 rows the order and the
sparse bookkeeping cost what they save (docs/records/benchmarks.md, "small
problems' blocks factorised sparse")."""

_NOT_BY_ROWS = (np.empty(0, dtype=np.uint32), np.empty(0, dtype=np.uint32), np.empty(0))
_NO_PLACES = np.empty(0, dtype=np.int32)
"""``W`` not by its rows, no elimination order: the compiled lane below :data:`STATIC_DENSE_ROWS`
rows (shared, never written)."""
_NO_PLACES.flags.writeable = False      # read-only, as the kept orders: one type for the kernels

_last_order = [((b"", b""), _NO_PLACES)]
"""The pattern (the bytes of its 32-bit CSR arrays) whose order :func:`elimination_places` found
last, and that order, as one tuple (replaced whole)."""

FACTOR_PRODUCT_SHARE = 0.5
"""On the sparse lane of a 2D problem whose ``W = L^T L`` comes with its factor, the products
``W x`` of the residual and the line search go through ``L`` (two compiled products) where ``L``
and ``L^T`` together hold at most this share of ``W``'s entries: on 25 captured dry 12 000-grain
steps (0.41 of them) a mean of 0.315-0.316 s per step against 0.348-0.354 through ``W``, the
same Newton iterations; on 30 gluey ones (0.58) 0.281-0.291 against 0.275-0.287, no gain
(docs/records/benchmarks.md, "fewer passes per Newton iteration")."""


STALL_WINDOW = 60
STALL_FACTOR = 0.5
"""Newton has stalled when its best FCLIB error did not fall by this factor over the last
``STALL_WINDOW`` iterations (the error of a semismooth Newton method is not monotone: its
global phase wanders for tens of iterations before the fast local phase), with one reprieve
(:data:`STALL_HORIZON`, :class:`_StallRule`)."""
STALL_HORIZON = 3
"""The reprieve: a phase that did not halve its error over the window but, falling at that
window's rate, would reach ``tol`` within this many more windows is given those windows while
its pace still allows it, once (until it halves its error over a window again). On 12 steps
of a 2000-grain bed creeping at 17 degrees the proximal loop closed the last tenths of a
decade to tol 1e-5 at about 0.8 per window and was called stalled on 8; `nsgs`, the fallback,
took 7-9 s for that distance where the longer Newton phase took 1-3 s
(docs/records/benchmarks.md, "newton-ac on creeping beds: the last tenths to tol")."""

STRATEGIES = (1e-3, 0.0, 1e-4)
"""Starting proximal weights ``sigma`` (units of the median diagonal of ``W``) tried in turn,
each from the warm start, while the previous one stalled: 1e-3 solves the rank-deficient
piles and the 3D Siconos files, plain Newton (0) spheres-in-a-box, 1e-4 the 2020-contact
granular file (measured on Siconos' and FCLIB's test problems). With a warm start, the first
weight is also tried from zero forces, second: in the first steps of a flow the previous step's
forces can be a start from which every weight stalls where a cold start converges (two of three
such gluey steps of the demo's flow)."""
WARM_FLOW_WEIGHT = 3e-3
"""The first starting weight, in place of ``STRATEGIES[0]``, from a warm start on a 2D problem of
more than ``DENSE_LIMIT`` rows (a flow's step, whose force network renews from step to step: the warm start's
FCLIB error about 2e-2 on developed gluey flows). Newton iterations summed over captured steps of
developed flows (exact Coulomb, tol 1e-6), 1e-3 against 3e-3 against 1e-2: gluey 2 000 to
12 000 grains (209 steps) 6 578, 5 767, 5 749; dry (113 steps) 2 646, 2 646, 2 511; the tests'
creeping 300-grain bed 234, 222, and with 1e-2 a stall. Not on smaller problems, where the warm
starts of small piles near rest took 3-14 % more iterations with either
(docs/records/benchmarks.md, "a firmer first weight on flows")."""
WARM_DENSE_WEIGHT = 1e-4
"""The first starting weight, in place of ``STRATEGIES[0]``, from a warm start on a 2D problem of
at most ``DENSE_LIMIT`` rows (a small system's step, near the previous one's
forces). Newton iterations summed over 150 captured steps of settling frictional piles of 10,
20 and 40 grains (exact Coulomb, tol 1e-8), 1e-3 against 3e-4, 1e-4, 3e-5, 1e-5: 275, 273, 269,
283, 339; 628, 583, 566, 509, 588; 1 005, 883, 918, 872, 899 (docs/records/benchmarks.md,
"a softer first weight on small systems")."""
SIGMA_DECREASE = 10.0
"""The factor dividing the proximal weight after an outer iteration whose subproblem was solved
(:func:`_proximal_newton`), but on gluey flows' steps (:data:`UNION_SIGMA_DECREASE`)."""
UNION_SIGMA_DECREASE = 1.5
"""The factor dividing the proximal weight after a solved subproblem on a flow's step
(``AlartCurnier.flow_step``) with UNION contacts (a gluey flow's step, whose contacts change
piece): more outer iterations, each in Newton's fast local phase. Newton iterations summed over
captured steps of developed gluey flows (exact Coulomb, tol 1e-6), factor 10 against 3: 12 000
grains (70 consecutive steps) 2 712 against 2 027 (one of the two steps that stalled into the
Gauss-Seidel fallback converges, the other needs one round of it instead of two), 8 000 (90 steps)
2 599 against 2 489, 4 000 (80) 1 929 against 1 844, 2 000 (8) 179 against 172. Factor 3 against
1.5 (``bench switch``, three beds, 16 steps each at 10 000 grains, 40 at 2 000): 10 000 grains 280,
257 and 254 against 269, 244 and 214 (0.97, 0.97 and 0.86 of the time), 2 000 grains 453, 1 379 and
307 against 434, 1 378 and 307; 10^5 grains (two beds, 4 steps) 117 and 89 against 98 and 88 (0.89
and 0.96); 2 against 1.5 at 10 000 grains: 284, 239 and 215. Not on dry problems: the tests'
creeping 300-grain bed stalls with 3 or 4 (converges with 5 and 10), and on dry flows the steps
cost more time with 3 (docs/records/benchmarks.md, "a slower decrease of the proximal weight on
gluey flows"); nor on small problems, where small piles near rest took 2-6 % more iterations with 5
or 3."""
PLAIN_TRY = 5
"""Plain Newton iterations (no proximal weight), at most, tried first from a warm start on a
small 2D problem (``AlartCurnier.small``) without friction cones, unless plain Newton's block is
singular by its count there (the plain try, :func:`_strategies`; then at most
:data:`FINISH_ITERATIONS` more to round-off); :data:`STRATEGIES` follow from the warm start
where they did not reach ``tol``. From the previous step's forces of a small frictionless pile
the proximal loop spends an iteration per weight (1e-3, 1e-4, ..., then the finish), where plain
Newton converges fast: on 300 steps of 20- and 40-grain settling piles, in 1-5
iterations (1 on most) against 1-7. Not with friction cones: with exact Coulomb it converged
within 5 iterations on 88 of the 20-grain pile's 300 steps and stalled on 92, and plain Newton
first took 1.5-3.2 times the iterations on developed 2 000-grain flows
(docs/records/benchmarks.md, "the plain try")."""
STRATEGY_GAP = 100.0
"""The next strategy is tried only while the best FCLIB error is above this many ``tol``: a
phase that stalled within two decades of ``tol`` goes to the fallbacks, whose Gauss-Seidel
sweeps and Newton polish finish it. On the costliest steps of a creeping 2000-grain bed the
first strategy stalled at 3-9 ``tol`` and the three others at 4 to 4000 ``tol``, spending
two thirds of the step (docs/records/benchmarks.md, "newton-ac on creeping beds"). Not on the
compiled lane (2D, at most :data:`COMPILED_LIMIT` rows), whose Newton iterations cost about ten
Gauss-Seidel sweeps: there every strategy is tried before the fallbacks. On 100 captured steps
each of developed flows of 90 to 150 grains (exact Coulomb, tol 1e-6) the steps that went to
Gauss-Seidel after the first strategy (1 to 5 per flow; its rounds wandered, up to 20 000 sweeps
and 1.1 s) took 80-1 100 ms, the second strategy converging on most of them in 25-135 ms: the
flows' 100 steps took 0.57 (gluey, 90 grains), 0.71 (dry, 90), 0.76 (gluey, 120), 0.94 and 1.0
(gluey and dry, 150) of the time; on one step every strategy stalled before Gauss-Seidel
(2.2 times the time) (docs/records/benchmarks.md, "the compiled lane to 700 rows, and every
strategy before the fallbacks there"). Nor, for the first weight from zero forces, on a gluey
flow's step from a warm start (``AlartCurnier.gluey_flow``): of 180 captured 10 000-grain gluey
steps solved at tol 1e-6, 1e-7 and 1e-8, the first strategy stalled within the gap on two steps
(three solves); the solves that went on to Gauss-Seidel's rounds took 1.72-3.77 s, those where
the first weight from zero forces followed (and converged) 0.74-1.35 s. Where that weight stalls
too, the fallbacks follow it: on the tests' 250-grain gluey step 293 Newton iterations instead of
202 before the same Gauss-Seidel rounds (docs/records/benchmarks.md, "zero forces before the
fallbacks on gluey flows")."""
SIGMA_MIN = 1e-10
"""Floor of the proximal weight, in units of the median diagonal of ``W``."""
SIGMA_MAX = 1e10
"""Ceiling of the proximal weight, in the same units: a subproblem that would need more moves the
forces by less than ``1 / SIGMA_MAX`` of its residual, so the phase has stalled. On a gluey
flow step at 15 degrees the numpy lane's products overflowed (``inf`` and ``nan`` in the line
search and the gradient step, hundreds of numpy warnings, then a fallback that converged): an
unbounded weight is the likely cause (not reproduced: the step was not kept), a direction far
too long the other, which :func:`_line_search` now rejects quietly."""

STUCK = 0.9
STUCK_RISE = 100.0
"""A proximal step whose subproblem was not solved raises the weight 10 times, or
``STUCK_RISE`` times where it did not lower the FCLIB error below ``STUCK`` times the
centre's: a stuck iterate. On the hard steps of developed flows the iterates cycle on a kink
at small weights: on one, every weight from 1e-7 to 1e-3 (in units of the median diagonal of
``W``) failed in turn, ten Newton iterations each, without moving, until 1e-2 solved its
subproblem in two. On 40 steps of a 3 200-grain gluey flow and 40 of a 2 000-grain dry one,
the rise of 100 took 4 % fewer Newton iterations (one fallback fewer), and 4-6 % fewer on 300
steps of 60- and 80-grain settling piles; 1 000 left three of the 60-grain pile's steps unconverged
(docs/records/benchmarks.md, "a stuck proximal step")."""

INNER_CAP = 10
INNER_REDUCTION = 0.3
"""Newton iterations per proximal step: at most ``INNER_CAP``, until ``|phi_sigma|`` is below
``INNER_REDUCTION`` times the current natural residual: an inexact proximal point. On developed
2000-grain flows (dry and gluey, exact Coulomb) 0.3 takes a third fewer Newton iterations per
step than solving each subproblem to 1e-3 did, and no more on any of Siconos' and FCLIB's test
problems (docs/records/benchmarks.md, "newton-ac on developed flows"); 0.1 gained less, 0.5
took up to 5 times more Newton iterations on some flow steps."""
UNION_INNER_CAP = 5
"""``INNER_CAP`` on a flow's step (``AlartCurnier.flow_step``) with UNION contacts (a gluey flow's step).
There the hard steps' subproblems at small weights end unsolved after all ten iterations, the
iterates cycling on a kink, before the weight rises. Newton iterations summed over captured steps
of developed gluey flows (exact Coulomb, tol 1e-6), caps 10, 6, 5, 4, 3: 4 000 grains (30
steps) 483, 479, 476, 474, 481; 8 000 (40) 708, 700, 689, 678, 657; 12 000 (70) 1 388, 1 347,
1 339, 1 319, 1 292; 10^5 (6) 268, 229, 226, 222, 239; with 3, steps went to the Gauss-Seidel
fallback at 4 000 and 10^5 grains (with 2 at 8 000, 12 000 and 10^5). Not on dry problems: the
tests' creeping 300-grain bed ends ``inaccurate`` with a cap of 6 (docs/records/benchmarks.md,
"a shorter proximal step on gluey flows")."""
CHAINED_SUBPROBLEMS = True
"""On the compiled lane (``AlartCurnier.compiled``), while no weight has failed, the proximal loop
hands the subproblems that follow a solved one to the same compiled call, which centres and weighs
each as the loop would (:func:`~lubcontact.solvers.kernels.newton_phase_2d`): the same iterates,
without a return to Python per subproblem. A small system's warm-started step solves one
subproblem per Newton iteration, two to five in all; chained, its solve took 0.92-0.97 of the
time at 6 to 63 contacts (docs/records/benchmarks.md, "Small solves: the solved subproblems in one
call"). False: one call per subproblem, as on the sparse lane."""

RECENTRE_WINDOW = 6
RECENTRE_UNTIL = 100.0
"""On a flow's step (``AlartCurnier.flow_step``) with friction cones the proximal loop first
takes one Newton iteration per subproblem, re-centred at its result at the same weight (a
regularised Newton method; on a gluey flow's step at most the centre's error,
:data:`UNION_RECENTRE_FOLLOWS`), while its best FCLIB error halves (by :data:`STALL_FACTOR`) within
``RECENTRE_WINDOW`` iterations and is above ``RECENTRE_UNTIL`` ``tol`` (not at all from a start
below it: the polish after a fallback or the joint phase); from there the weight
falls to the iterate's FCLIB error (in units of the median diagonal of ``W``) where that is
smaller, and each subproblem is solved as :data:`INNER_REDUCTION` says (``RECENTRE_WINDOW``
0: never re-centred). Solving each subproblem from the warm start spent Newton iterations
driving ``|phi_sigma|`` down at a centre whose own error no longer moved. Re-centred to ``tol``
at a fixed weight, the answers were as far from the nearest exact ones as the solved loop's at
a hundredth of the ``tol`` (velocities about 100 times the FCLIB error from Clarabel's, against
20): the error left in soft modes, which a fixed weight resolves slowly. Newton iterations
summed over captured steps of developed flows (exact Coulomb), each subproblem solved against
re-centred so: gluey 12 000 grains (70 consecutive steps) 1 957 against 1 388 at tol 1e-6, 2 061
against 1 704 at 1e-7; the velocities of eight 4 000-grain steps at tol 1e-7 at most 4.5e-6 from
Clarabel's (median 1.3e-6) against 1.9e-6 (median 4.9e-9). Not without friction cones, where
the proximal loop's plain finish is exact once the active set has settled (a frictionless
200-grain pile: 14 Newton iterations re-centred against 10) (docs/records/benchmarks.md,
"newton-ac: one Newton iteration per proximal centre on flows")."""
UNION_RECENTRE_FOLLOWS = True
"""On a flow's step with UNION contacts (a gluey flow's step), each re-centred iteration's weight
is at most the centre's FCLIB error (in units of the median diagonal of ``W``), as the weight
after re-centring is: it falls with the error from the first weight on (a regularised Newton
method whose regularisation follows the residual) instead of staying at the first weight until
the re-centring ends, where each iteration cut the error only by 0.6-0.9. Newton iterations
summed over captured consecutive steps of developed gluey flows (exact Coulomb, tol 1e-6),
before against after: 10 000 grains (10 and 30 steps) 148 and 402 against 132 and 351; 4 000
(30) 411 against 402; 2 000 (30) 355 against 367 (63 of the 100 steps take fewer iterations, 14
more; the sums move with the few hard steps, whose counts change either way); 0.76 and 0.88 of
the time on 200 steps of 150- and 250-grain gluey flows (the demo's recipe). Not on dry
problems: the tests' creeping 300-grain bed ends ``inaccurate`` with it (docs/records/
benchmarks.md, "newton-ac: the re-centred weight follows the error on gluey flows")."""

LOCAL_ROWS = 300
LOCAL_SHARE = 0.99
LOCAL_HOPS = 1
LOCAL_SWEEPS = 80
LOCAL_MIN_ROWS = 3000
"""Local Gauss-Seidel sweeps in the proximal loop (:func:`_proximal_newton`). On a 2D problem of
the sparse lane with friction cones and more than ``LOCAL_MIN_ROWS`` rows (a flow's step), before
each subproblem, re-centred ones included, where the ``LOCAL_ROWS`` rows with the largest FCLIB
residual hold at least ``LOCAL_SHARE`` of its square: ``LOCAL_SWEEPS`` sweeps of ``nsgs``'s
Gauss-Seidel (exact local Coulomb solves) over them and the rows ``LOCAL_HOPS`` step away in
``W``'s pattern, the other rows' forces frozen; their forces are the next centre where they lower
the FCLIB error (:meth:`AlartCurnier.swept`; ``LOCAL_SWEEPS`` 0: none). Late in a flow's step the
error sits on a few contacts (97-100 % of its square on 300 of 52 000 rows of 12 000-grain gluey
steps from the seventh re-centred iteration on; at 10^5 grains, where a subproblem failed, 90 %
on 5 to 31 of 426 000 rows), where Newton's iterates cycle on kinks of the Alart-Curnier function
while the weight rises and falls; the first sweeps there cut the FCLIB error 4 to 25 times.
Newton iterations summed over captured consecutive steps (exact Coulomb, tol 1e-6), without and
with the sweeps: gluey 4 000 grains (30 steps) 519 and 446, 10 000 (25) 415 and 310, 12 000 (25)
499 and 385, 10^5 (6) 294 and 203; dry 4 000 (30) 458 and 278; the 10 000-grain steps' time 7 %
less. Two steps away (three times the rows swept) took 5 % fewer iterations in all but more time
(1 % less than without). Not on smaller problems, where the swept rows would be much of it.
At tol 1e-6 the answers lie further from Clarabel's (velocities a median 2.6e-6 away against
2.7e-7 on nine 2 000-grain gluey steps); at 1e-7, which a velocity accuracy of 1e-6 needs either
way, 3.0e-7 at most against 1.9e-7, in 15 % fewer Newton iterations (dry: 2.3e-7 against 1.6e-8,
38 % fewer) (docs/records/benchmarks.md, "local Gauss-Seidel sweeps")."""

CORRECTED_ROWS = 30
CORRECTED_SHARE = 0.9
CORRECTED_SWEEPS = 20
"""A full Newton step corrected by local Gauss-Seidel sweeps in the line search
(:func:`_line_search`), where :attr:`AlartCurnier.sweeps_apply` (a flow's step): where the full
step fails the line search's bound and the ``CORRECTED_ROWS`` rows with the largest residual
``phi`` there hold at least ``CORRECTED_SHARE`` of its square, ``CORRECTED_SWEEPS`` sweeps over
them and the rows :data:`LOCAL_HOPS` step away, from the full step, the other rows' forces as the
step left them; the corrected point is taken where it passes the bound of the full step
(:meth:`AlartCurnier.corrected`; ``CORRECTED_SWEEPS`` 0: never). Traced on the hard steps of
developed gluey flows, the full steps that the line search cut to 1/128-1/8 failed on 2 to 17
rows (90 % of the full step's merit) crossing a kink of the Alart-Curnier function (a contact
opening, or sliding), the same few rows at one iteration after another, while the active set
changed by 0-7 rows.
Newton iterations summed over captured consecutive steps (exact Coulomb, tol 1e-6), without and
with the correction: gluey 10 000 grains, three beds (20, 15 and 15 steps, and 20 later steps
of the second) 270, 232, 243 and 268 against 243, 209, 210 and 211; gluey 4 000 grains (30)
433 against 371; dry 10 000 grains, two beds (15 and 20) 129 and 168 against 126 and 166;
gluey 10^5 grains, three beds (6, 2 and 3 steps) 121, 63 and 51 against 115, 46 and 51. On 65
of the 10 000-grain steps (the three gluey beds' first and the first dry bed's), 10 or 100
rows, a share of 0.8 or 0.95, 5 or 10 sweeps, no step or two steps away took 1-9 % fewer
iterations against 10 %; at 10^5 grains 100 rows left one step of six 1 067 iterations long,
300 another 72. Not on smaller problems (the sparse lane from 700 rows): the tests' creeping
300-grain bed (1 334 rows) ends ``max_iter`` with it
(docs/records/benchmarks.md, "a full Newton step corrected on the rows where it fails")."""

CYCLING_MERIT = 0.9
"""A full Newton step that the non-monotone line search accepts (:data:`LINE_SEARCH_MEMORY`)
with a merit ``psi`` above this fraction of the current one is corrected as a failed full step
is (:data:`CORRECTED_ROWS`: where :attr:`AlartCurnier.sweeps_apply`, and not with
``CORRECTED_SWEEPS`` 0), and the corrected point taken where its merit is below the full step's
(``info["corrected_steps"]`` counts both kinds of correction). Traced on a 10 000-grain gluey
step of 151 Newton iterations at tol 1e-8, a few sliding contacts' tangential forces jumped
between ``mu lam_n`` and ``-mu lam_n`` at every full step (their sliding velocity reversed by the
jump), the merit staying at 9.96e-4 while the proximal weight rose from 0.02 to 2e9 of the median
diagonal of ``W`` (eight rows held 99 % of ``phi``'s square); sweeps over those rows find them
sticking, and the step took 36 iterations (31 against 150 at tol 1e-6;
docs/records/benchmarks.md, "full steps that cycle, corrected")."""

POLISH_ITERATIONS = 10
"""Proximal Newton iterations of the finish from the joint phase's forces (:data:`JOINT_FINISH`)."""
FALLBACK_POLISH_ITERATIONS = 30
"""Proximal Newton iterations tried from each fallback call's forces (each round of a fallback run
in rounds, :func:`fallback_rounds`), kept where they lower the error: a round whose forces Newton
finishes ends the chain. On captured steps of developed flows on which every strategy stalled
(docs/records/benchmarks.md, "a longer polish after each fallback round"), 30 against 10 took
about half the Gauss-Seidel sweeps on gluey flows of 140 and 250 grains."""


FINISH_ITERATIONS = 2
"""Plain Newton iterations, at most, after the proximal loop or the plain try converged on a
problem without friction cones (kept where they lower the error; they stop at
:data:`ROUND_OFF`). There the Alart-Curnier function is piecewise linear, and once the active set
has settled a plain Newton step lands on the solution: round-off in one iteration where the
block is regular (none on the sparse lane where it is singular by its count:
:meth:`AlartCurnier.hyperstatic`), from where the next step of a pile at rest has no iteration
to do. Where the error's floor is above ``ROUND_OFF`` the first runs for nothing, and the second
only after a first that gained (:data:`FINISH_GAIN`): on ``heavy_on_light_stack`` from near its
solution the plain try takes 2 iterations where plain Newton alone takes 1, to the same FCLIB
error near 1e-12 (3 before the gain was asked for).

None with friction cones, where the loop's answer at ``tol`` is the answer: there they lowered
the error tenfold on few solves, for a Newton iteration on every one. On 150 steps each of the
settling frictional piles of ``bench small`` (10, 20 and 40 grains, exact Coulomb, tol 1e-8) they
gained on 1, 6 and 22 solves and cost 7-15 % of a solve; on 25 steps of a developed 12 000-grain
gluey flow (tol 1e-6) they gained on 7 and cost 6-9 % of the median step
(docs/records/benchmarks.md, "no plain finish with friction cones")."""
ROUND_OFF = 1e-14
"""FCLIB error at which those plain iterations stop: round-off (where the block is regular the
first takes the answer there, and a second would factorise again for nothing;
docs/records/benchmarks.md, "the finish stops at round-off")."""
FINISH_GAIN = 0.1
"""A plain iteration of the finish is followed by the next only where it lowered the FCLIB error
below this fraction of its start's (and not to :data:`ROUND_OFF`): from ``tol`` quadratic
convergence gains decades in one iteration, and where it gains less the block is singular
there though not by its count. On 40-grain frictional piles at rest (142 rows, 120 degrees of
freedom, 112 rows of ``W`` in the block), when proximal loops with friction cones were finished
too, the finish's block had singular values of 1e-16 and its two iterations left the error
where it was on half the steps (docs/records/benchmarks.md, "the finish stops where it gains
nothing"). Each iteration is a Newton phase of its own: the second's line search is monotone
from the first's iterate."""

FALLBACKS_2D = ("nsgs", "apgd-jacobi")
FALLBACKS_UNION = ("nsgs",)
FALLBACKS_3D = ("apgd-jacobi",)
"""Fallbacks (``fallback="auto"``) tried in turn from the best iterate so far when every Newton
strategy stalls, until one's polished answer is below tol (or kept within :data:`FALLBACK_GAP`
``tol``; Gauss-Seidel in rounds, each from the last one's forces and polished:
:func:`fallback_rounds`). In 2D first Gauss-Seidel with exact local solves (:mod:`.gauss_seidel`): on gluey
flow steps where Newton stalled at FCLIB errors 2e-5 to 1e-4 it reached 1e-6 in 0.3 s, or
5e-6 at its cap, where apgd-jacobi's fixed point ran out at 1e-4; then apgd-jacobi's fixed
point on ``s``, which solves Siconos' 2020-contact file to 1e-8 where Gauss-Seidel from
Newton's best iterate stops at 5.7e-7 (docs/records/benchmarks.md). On 2D problems with
UNION contacts (gluey + friction) Gauss-Seidel alone: the fixed point fixes each union contact
on one piece and flips pieces by its branch rule, which on a gluey bed coming to rest flipped
5 to 22 contacts at every outer iteration without settling: 50 outer iterations, three
quarters of the step (34-36 s at 2000 grains), and a polished answer 9 to 37 times worse
than Gauss-Seidel's (docs/records/benchmarks.md, "The gluey bed coming to rest")."""

FALLBACK_ROUND = 1000
"""Iterations of the first round of a fallback that solves exact Coulomb itself (``nsgs``): its
iteration cap is spent in rounds (:func:`fallback_rounds`: 1 000, 1 000, 2 000, 4 000, then the
rest), each continued from the last one's forces and polished (:data:`FALLBACK_POLISH_ITERATIONS`), until
a polished answer reaches ``tol``. On a developed 12 000-grain gluey step whose Newton phases
stalled at 2.9e-6 (tol 1e-6), Gauss-Seidel reached its own tol in about 4 500 sweeps (12.4 s),
while Newton from its forces after 1 000 sweeps converged in 16 iterations and after 2 000 in
one (docs/records/benchmarks.md, "the fallback in rounds")."""
FALLBACK_GAP = 10.0
"""A fallback whose polished answer is kept (it beats the best so far) and lies within this many
``tol`` ends the chain: the next, slower first-order fallback has not closed such a gap. On a
2000-grain dry bed creeping at 17 degrees (tol 1e-5) Gauss-Seidel's polished answers stopped
at 1.07e-5 and 1.22e-5, and apgd-jacobi's fixed point then took 10.5-10.8 s, half the step,
for polished answers 2-2.5 times worse. On Siconos' 2020-contact file (tol 1e-8) Gauss-Seidel's
polished answer (3.2e-7) is not kept, Newton's best being 3.1e-7, and apgd-jacobi's converges
(docs/records/benchmarks.md, "newton-ac on creeping beds: the fallbacks near tol")."""

JOINT_FINISH = 1e-3
"""From the joint phase's forces, Newton's answer is taken below ``JOINT_FINISH tol`` (at most
:data:`POLISH_ITERATIONS` more iterations, kept where they lower the error): the joint phase
stops just below ``tol``, and on 6 of 40 steps of a developed dry 2 000-grain flow the two
plain Newton iterations after it did not lower its FCLIB error (5e-7 to 8e-7), leaving
velocities 2e-5 to 8e-5 from the exact ones (from the warm start Newton's iterates end at
round-off). None where plain Newton's block at those forces is singular by its count (a pile
at rest: :meth:`AlartCurnier.hyperstatic`). That polish stops at its target (no plain
finishing iterations past it, :data:`FINISH_ITERATIONS`, none with friction cones: when two
always ran they took 13 % of a 12 000-grain dry step), so an answer from the joint phase is at
FCLIB error ``JOINT_FINISH tol`` or below, not always at round-off."""
JOINT_START_ITERATIONS = 2000
"""Cap on the iterations of the joint phase before the Newton phases (``joint``)."""

STALLED = "stalled"
"""Status of a Newton phase that stalled (reported in ``info``, never as a result's status)."""

MAX_HALVINGS = 30
"""Step halvings before a direction is given up."""


class AlartCurnier:
    """The Alart-Curnier function of one normalised problem and its generalised Jacobian.

    Parameters
    ----------
    problem : ConicProblem
        Normalised; its shift is ignored.

    Attributes
    ----------
    rho : ndarray, shape (n_rows,)
        Per-row step ``1 / W_nn`` of the row's contact.
    diagonal : ndarray, shape (n_rows,)
        ``W``'s diagonal (also the local sweeps', :attr:`local_sweeps`).
    cone_n, cone_t, cone_mu : ndarray
        Normal rows (nf,), tangential rows (nf, tangent_dim) and friction
        coefficients (nf,) of the frictional contacts (COULOMB, then UNION).
    unilateral : ndarray of bool, shape (nf,)
        True where the normal row is ``max(y_n, 0)`` (COULOMB), False where it
        is bilateral (UNION: a box row with no bounds).
    planar, compiled, compiled_rows, dense : bool
        A 2D problem (its FCLIB error compiled); one whose Newton phases run compiled on the
        dense ``W`` (at most :data:`COMPILED_LIMIT` rows); one on the sparse lane whose Newton
        systems, Jacobian rows and residuals are assembled compiled
        (:mod:`~lubcontact.solvers.kernels`; the residual in one pass, 6 % of a 12 000-grain gluey
        step); one whose ``W`` is dense (compiled, or :attr:`small`). These choose how a rule is
        carried out, not which rule, but for :data:`STRATEGY_GAP`, which weighs a Newton
        iteration's cost.
    small, flow_step, convex : bool
        A small system's problem (at most ``DENSE_OPERATOR_LIMIT`` rows, in 2D ``DENSE_LIMIT``:
        :data:`PLAIN_TRY`, :data:`WARM_DENSE_WEIGHT`, no :meth:`hyperstatic` test); a 2D one that
        is not small (a flow's step: :data:`WARM_FLOW_WEIGHT`, :data:`RECENTRE_WINDOW`); one
        without UNION contacts (``Cones.is_convex``).
    gluey_flow : bool
        A flow's step with UNION contacts (a gluey flow's): :data:`UNION_SIGMA_DECREASE`,
        :data:`UNION_INNER_CAP`, :data:`UNION_RECENTRE_FOLLOWS`, and the first weight from zero
        forces before the fallbacks (:data:`STRATEGY_GAP`).
    w_arrays : tuple of ndarray
        ``W``'s CSR arrays with unsigned indices (:func:`~.compiled_apgd.csr_arrays`), for the
        kernels of the sparse lane (``compiled_rows``): numba checks every signed index for
        wrap-around, and the reduced Newton system took 4.4 ms instead of 5.2 on a 12 000-grain
        gluey step (51 879 rows) with them; on the compiled lane, the dense ``W``'s entries
        that are not zero (:func:`~lubcontact.solvers.kernels.compressed_rows`) from
        :data:`STATIC_DENSE_ROWS` rows, for its products and blocks (a 40-grain pile's ``W`` is
        6 % full), else empty.
    elimination_places : ndarray of int32, shape (n_rows,) or (0,)
        On the compiled lane from :data:`STATIC_DENSE_ROWS` rows, each row's place in a
        minimum-degree elimination order of ``W``'s pattern (shared, read-only:
        :func:`elimination_places`), in which the Newton phases
        factorise their blocks without pivoting
        (:func:`~lubcontact.solvers.kernels.newton_direction_2d`); empty (LAPACK's LU) below.
    factor_arrays : tuple of ndarray or None
        On the sparse lane, the CSR arrays of ``W``'s factor ``L`` and of ``L^T`` and a work
        vector, where the products ``W x`` go through them (:meth:`product`); None otherwise.
    delassus_factors : tuple
        On the sparse lane of a 2D problem, ``W``'s factor ``L`` and ``L^T`` (CSR; None where
        the problem has none), for :attr:`local_sweeps`; ``(None, None)`` elsewhere.
    reduced_blocks : _ReducedBlocks or None
        On the sparse lane of a 2D problem, its reduced Newton blocks (:meth:`reduced_system`),
        each reusing the last one's rows where the products go through ``W``'s factor; None
        elsewhere.
    tangent_rows : ndarray of int, shape (nf,)
        ``cone_t``'s one column (planar problems only).
    q_scale : float
        ``1 + |q|``, the FCLIB error's denominator.
    rank_bound : int
        An upper bound on the rank of ``W`` (the problem's ``delassus_rank_bound``).
    """

    def __init__(self, problem: ConicProblem):
        cones = problem.cones
        nc, dim_t = cones.count, cones.tangent_dim
        # a small problem is dense throughout (W, the Jacobian's rows, the LU): at <= 128 rows
        # the sparse products' fixed cost was most of a Newton iteration (dual_data); a 2D one
        # of up to COMPILED_LIMIT rows runs each Newton phase in one compiled call (kernels),
        # 2-3x faster than the sparse lane at 190-300 rows, 1.3-2x at 300-660 on flows
        # (docs/records/benchmarks.md)
        self.planar, self.compiled, self.small = lanes(problem)
        self.flow_step = self.planar and not self.small
        self.dense = self.compiled or self.small
        self.W = problem.dense_delassus if self.dense else problem.delassus.tocsr()
        self.q = problem.offset.copy()
        self.q[:nc] -= problem.shift
        self.n_rows = problem.n_rows
        self.rank_bound = problem.delassus_rank_bound
        projector = cones.projector
        self.lower, self.upper = projector.lower.copy(), projector.upper.copy()
        self.cone_n, self.cone_t = projector.friction_normal, projector.friction_tangent
        self.cone_mu, self.unilateral = projector.friction_mu, ~projector.friction_union
        self.box = np.ones(self.n_rows, dtype=bool)
        self.box[self.cone_n[self.unilateral]] = False
        self.box[self.cone_t.ravel()] = False
        self.diagonal = self.W.diagonal()      # (a sparse W's: a pass over its entries)
        self.rho, self.typical = contact_steps(self.diagonal[:nc], cones)
        self.dim_t = dim_t
        self.sigma, self.center = 0.0, np.zeros(self.n_rows)
        # on the sparse lane, a 2D problem's Newton systems, Jacobian rows and residuals are
        # assembled compiled (a numpy sparse product G W and sum cost as much as the LU on
        # developed 2000-grain flows)
        self.compiled_rows = self.planar and not self.dense
        partner = None
        if self.compiled_rows:          # each friction contact's two rows, for carried orders
            partner = np.full(self.n_rows, -1, dtype=np.int64)
            partner[self.cone_n], partner[projector.planar_tangent] = \
                projector.planar_tangent, self.cone_n
        self.factorisations = Factorisations(carry=self.planar, partner=partner)
        self.sweeps_kept = 0            # local sweeps whose forces were taken (swept)
        self.corrections_kept = 0       # full Newton steps taken corrected (_line_search)
        self.convex = cones.is_convex
        self.gluey_flow = self.flow_step and not self.convex
        self.factor_arrays = self.reduced_blocks = None
        self.delassus_factors = None, None
        if self.compiled_rows:
            self.w_arrays = csr_arrays(self.W)
            factor, transpose = problem.delassus_factor, problem.delassus_factor_transpose
            self.delassus_factors = factor, transpose
            if factor is not None and \
                    factor.nnz + transpose.nnz <= FACTOR_PRODUCT_SHARE * self.W.nnz:
                self.factor_arrays = operator_arrays(factor, transpose)
            self.reduced_blocks = _ReducedBlocks(self.w_arrays, self.rho, self.factor_arrays)
        self.q_scale = 1.0 + float(np.sqrt(self.q @ self.q))
        if self.planar:             # one tangential row per contact, as the kernels take them
            self.tangent_rows = projector.planar_tangent
        if self.compiled:
            self.W = np.ascontiguousarray(self.W)
            self.w_arrays, self.elimination_places = _NOT_BY_ROWS, _NO_PLACES
            if self.n_rows >= STATIC_DENSE_ROWS:
                self.w_arrays = kernels().compressed_rows(self.W)
                self.elimination_places = elimination_places(*self.w_arrays[:2])

    @cached_property
    def scaled_W(self) -> sp.csr_matrix | np.ndarray:
        """``diag(rho) W``, built once, on first use (the numpy Jacobian rows; ``sigma`` enters as
        a diagonal)."""
        return self.rho[:, None] * self.W if self.dense else sp.diags(self.rho) @ self.W

    def product(self, vector: np.ndarray) -> np.ndarray:
        """``W x`` (n_rows,), through the factor where :attr:`factor_arrays` holds it
        (:data:`FACTOR_PRODUCT_SHARE`)."""
        if self.factor_arrays is None:
            return self.W @ vector
        out = np.empty(self.n_rows)
        kernels().apply_operator(*self.factor_arrays, vector, out)
        return out

    def set_proximal(self, sigma: float, center: np.ndarray) -> None:
        """Solve the proximal problem ``W + sigma I``, ``q - sigma center`` from now on (0: the problem)."""
        self.sigma, self.center = float(sigma), np.array(center, dtype=float)

    def residual(self, forces: np.ndarray, velocity: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``phi(r)``, ``y = r - rho (W r + q + sigma (r - center))`` and the velocity
        ``W r + q`` (the problem's, without the proximal term; computed here when not given),
        each shape (n_rows,)."""
        if velocity is None:
            velocity = self.product(forces) + self.q
        if self.compiled_rows:                # one pass (kernels.alart_curnier_2d), the same values
            phi, y = np.empty(self.n_rows), np.empty(self.n_rows)
            kernels().alart_curnier_2d(self.rho, self.lower, self.upper, self.cone_n,
                                       self.tangent_rows, self.cone_mu, self.unilateral,
                                       self.sigma, self.center, forces, velocity, phi, y)
            return phi, y, velocity
        y = forces - self.rho * velocity
        if self.sigma:
            y -= (self.rho * self.sigma) * (forces - self.center)
        projected = np.clip(y, self.lower, self.upper)
        if self.cone_n.size:
            y_n = y[self.cone_n]
            y_t = y[self.cone_t]
            radius = self.cone_mu * np.maximum(y_n, 0.0)
            norm_t = np.linalg.norm(y_t, axis=1)
            scale = np.minimum(1.0, np.divide(radius, norm_t, out=np.ones_like(norm_t), where=norm_t > 0))
            projected[self.cone_n] = np.where(self.unilateral, np.maximum(y_n, 0.0), y_n)
            projected[self.cone_t] = scale[:, None] * y_t
        return forces - projected, y, velocity

    def coulomb_error(self, unshifted: ConicProblem | None, forces: np.ndarray,
                      velocity: np.ndarray | None = None) -> float:
        """The FCLIB error of ``forces``: :func:`~lubcontact.problem.metrics.coulomb_error` of
        ``unshifted`` (this function's problem without its shift; not read on a 2D problem),
        from the velocity ``W r + q``
        (:meth:`residual`'s, computed here when not given); compiled on a 2D problem."""
        if velocity is None:
            velocity = self.product(forces) + self.q
        if self.planar:
            return float(kernels().coulomb_error_2d(forces, velocity, self.lower, self.upper,
                                                    self.cone_n, self.tangent_rows, self.cone_mu,
                                                    self.unilateral, self.q_scale))
        return coulomb_error(unshifted, forces, velocity)

    @cached_property
    def sweeps_apply(self) -> bool:
        """Whether the proximal loop tries :meth:`swept` on this problem: one of the sparse lane
        of a 2D problem (``compiled_rows``) with friction cones and more than :data:`LOCAL_MIN_ROWS`
        rows (a flow's step)."""
        return bool(self.compiled_rows and self.cone_n.size and self.n_rows > LOCAL_MIN_ROWS)

    @cached_property
    def local_sweeps(self) -> Sweeps:
        """The Gauss-Seidel sweeps over some rows of :meth:`swept`, prepared on first use (they
        read the velocities through ``W``'s factor where the problem gives it)."""
        factor, transpose = self.delassus_factors
        return Sweeps(self.W, self.q, self.lower, self.upper, self.cone_n, self.tangent_rows,
                      self.cone_mu, self.unilateral, factor=factor, factor_transpose=transpose,
                      diagonal=self.diagonal)

    def swept(self, forces: np.ndarray, velocity: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, float] | None:
        """``forces`` after :data:`LOCAL_SWEEPS` Gauss-Seidel sweeps over the rows within
        :data:`LOCAL_HOPS` of the :data:`LOCAL_ROWS` rows where the FCLIB error's residual
        (:func:`~lubcontact.solvers.kernels.coulomb_residual_2d`) is largest, with their
        velocity ``W r + q`` and FCLIB error; None, without sweeping, where those rows hold less
        than :data:`LOCAL_SHARE` of the residual's square (an error spread over the problem).
        ``velocity``: that of ``forces`` where known. Where :attr:`sweeps_apply`."""
        if velocity is None:
            velocity = self.product(forces) + self.q
        residual = kernels().coulomb_residual_2d(forces, velocity, self.lower, self.upper,
                                                 self.cone_n, self.tangent_rows, self.cone_mu,
                                                 self.unilateral)
        swept = self._swept_where_largest(forces, residual, LOCAL_ROWS, LOCAL_SHARE, LOCAL_SWEEPS)
        if swept is None:
            return None
        velocity = self.moved_velocity(forces, velocity, swept)
        return swept, velocity, self.coulomb_error(None, swept, velocity)

    def corrected(self, forces: np.ndarray, phi: np.ndarray, velocity: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """``forces`` (a full Newton step, ``phi`` its residual, ``velocity`` its ``W r + q``)
        after :data:`CORRECTED_SWEEPS` Gauss-Seidel sweeps over the rows within
        :data:`LOCAL_HOPS` of the :data:`CORRECTED_ROWS` rows where ``phi`` is largest, with
        their ``phi``, ``y`` and velocity (:meth:`residual`'s); None, without sweeping, where
        those rows hold less than :data:`CORRECTED_SHARE` of ``phi``'s square (the step fails
        all over the problem). Where :attr:`sweeps_apply`."""
        swept = self._swept_where_largest(forces, phi, CORRECTED_ROWS, CORRECTED_SHARE,
                                          CORRECTED_SWEEPS)
        return None if swept is None else \
            (swept, *self.residual(swept, self.moved_velocity(forces, velocity, swept)))

    def moved_velocity(self, forces: np.ndarray, velocity: np.ndarray, moved: np.ndarray
                       ) -> np.ndarray:
        """The velocity ``W r + q`` at ``moved`` (n_rows,), forces that differ from ``forces``
        on the few rows that local sweeps moved, from ``velocity``, the one at ``forces``: the
        change through those rows of ``W`` (:func:`~lubcontact.solvers.kernels.add_columns`,
        ``W`` symmetric), not a product with all of it. On the sparse lane of a 2D problem
        (``compiled_rows``: :attr:`w_arrays`), as the line search carries its velocities."""
        change = moved - forces
        out = velocity.copy()
        kernels().add_columns(*self.w_arrays, change, np.flatnonzero(change), out)
        return out

    def _swept_where_largest(self, forces: np.ndarray, values: np.ndarray, count: int,
                             share: float, sweeps: int) -> np.ndarray | None:
        """``forces`` after ``sweeps`` Gauss-Seidel sweeps (:attr:`local_sweeps`) over the rows
        within :data:`LOCAL_HOPS` of the ``count`` rows where ``values`` (a residual, shape
        (n_rows,)) is largest; None, without sweeping, where those rows hold less than
        ``share`` of its square (:meth:`swept`, :meth:`corrected`)."""
        compiled = kernels()
        worst, held = compiled.largest_squares(values, min(count, values.size))
        if held < share:
            return None
        rows = compiled.neighbourhood(*self.w_arrays[:2], worst, LOCAL_HOPS)
        return self.local_sweeps(forces, sweeps, rows)

    def jacobian(self, y: np.ndarray) -> tuple[sp.csr_matrix | np.ndarray, np.ndarray, int]:
        """The rows of ``J = I - G + G diag(rho) (W + sigma I)`` at ``y`` where ``G`` is not zero.

        Returns
        -------
        (scipy.sparse.csr_matrix or ndarray, ndarray of bool, int)
            Those rows, shape (m, n_rows) (a dense array on a small problem), the mask of
            the m rows (``active``; every other row of ``J`` is the identity's), and how many
            of them are rows of ``diag(rho) (W + sigma I)`` (``G``'s row is the identity's: box
            rows inside their bounds, pushed normal rows, sticking tangential rows; for
            :meth:`singular_by_count`). Only they are
            assembled: ``G``'s product with ``W`` for all rows cost 30 % of a Newton step on a
            developed 3200-grain flow. On the sparse lane a 2D problem's rows are assembled by
            :func:`~lubcontact.solvers.kernels.sparse_jacobian_rows_2d` (``compiled_rows``).
        """
        if self.compiled_rows:
            rows, indptr, indices, data, plain = kernels().sparse_jacobian_rows_2d(
                *self.w_arrays, self.rho, self.lower, self.upper,
                self.box, self.cone_n, self.tangent_rows, self.cone_mu, self.unilateral,
                self.sigma, y)
            active = np.zeros(self.n_rows, dtype=bool)
            active[rows] = True
            return (sp.csr_matrix((data, indices, indptr), shape=(rows.size, self.n_rows)), active,
                    plain)
        rows, cols, vals = [], [], []
        box = np.flatnonzero(self.box & (y > self.lower) & (y < self.upper))
        rows.append(box)
        cols.append(box)
        vals.append(np.ones(box.size))
        plain = box.size                                # rows of G that are the identity's
        if self.cone_n.size:
            y_n, y_t = y[self.cone_n], y[self.cone_t]
            pushed = y_n > 0
            normal = pushed & self.unilateral          # bilateral normal rows are box rows
            rows.append(self.cone_n[normal])
            cols.append(self.cone_n[normal])
            vals.append(np.ones(int(normal.sum())))
            radius = self.cone_mu * np.maximum(y_n, 0.0)
            norm_t = np.linalg.norm(y_t, axis=1)
            stick = pushed & (norm_t <= radius)
            slide = pushed & (norm_t > radius) & (radius > 0)
            k = self.dim_t
            eye = np.eye(k)
            t = y_t[slide] / norm_t[slide, None]
            block = (radius[slide] / norm_t[slide])[:, None, None] * (eye - t[:, :, None] * t[:, None, :])
            t_rows = self.cone_t[slide]
            rows.append(np.repeat(t_rows, k, axis=1).ravel())
            cols.append(np.tile(t_rows, (1, k)).ravel())
            vals.append(block.ravel())
            rows.append(t_rows.ravel())
            cols.append(np.repeat(self.cone_n[slide], k))
            vals.append((self.cone_mu[slide, None] * t).ravel())
            stick_rows = self.cone_t[stick].ravel()
            rows.append(stick_rows)
            cols.append(stick_rows)
            vals.append(np.ones(stick_rows.size))
            plain += int(normal.sum()) + stick_rows.size
        n = self.n_rows
        rows = np.concatenate(rows)
        active = np.zeros(n, dtype=bool)
        active[rows] = True
        position = np.cumsum(active) - 1               # row of J_A of each active row
        m = int(active.sum())
        if self.dense:                                  # each (row, column) appears once
            G = np.zeros((m, n))
            G[position[rows], np.concatenate(cols)] = np.concatenate(vals)
            J = G @ self.scaled_W - G
            if self.sigma:
                J += G * (self.sigma * self.rho)
            J[np.arange(m), np.flatnonzero(active)] += 1.0
            return J, active, plain
        G = sp.csr_matrix((np.concatenate(vals), (position[rows], np.concatenate(cols))), shape=(m, n))
        identity = sp.csr_matrix((np.ones(m), (np.arange(m), np.flatnonzero(active))), shape=(m, n))
        J = identity - G + G @ self.scaled_W
        if self.sigma:
            J = J + diagonal_scaled(G, columns=self.sigma * self.rho)
        return J.tocsr(), active, plain

    def newton_direction(self, y: np.ndarray, phi: np.ndarray) -> np.ndarray | None:
        """The Newton direction at ``y`` (``phi`` the residual there; :func:`_newton_direction`),
        or None where every regularisation of the active block fails.

        On the sparse lane of a 2D problem (``compiled_rows``) the system is reduced to its
        plain rows first (:meth:`reduced_system`): a sliding tangential row's unknown is its
        normal row's times ``mu s`` plus a constant, so the factorised block loses those rows
        (on developed 2D flows a ninth to a fifth of the active rows: docs/records/benchmarks.md,
        "the sliding rows eliminated"), and it is assembled by rows (CSR) directly, without the
        rows of ``J``.
        """
        if not self.compiled_rows:
            J, active, plain = self.jacobian(y)
            return _newton_direction(J, active, phi, self.factorisations, self.singular_by_count(plain))
        kept, block, rhs, direction, sliding, normal, slope = self.reduced_system(y, phi)
        if kept.size:
            solved = _block_solve(block, rhs, kept, self.factorisations,
                                  self.singular_by_count(kept.size))
            if solved is None:
                return None
            direction[kept] = solved
        direction[sliding] += slope * direction[normal]
        return direction

    def reduced_system(self, y: np.ndarray, phi: np.ndarray) -> tuple[
            np.ndarray, sp.csr_matrix, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The Newton system ``J d = -phi`` at ``y`` reduced to its plain rows, on the sparse lane
        of a 2D problem (``compiled_rows``): the identity rows and the sliding tangential rows
        eliminated (:func:`~lubcontact.solvers.kernels.fold_sliding_rows_2d`), the block's rows
        reused from the last call where their columns' folds are the same
        (:class:`_ReducedBlocks`).

        Returns
        -------
        tuple
            ``(kept, block, rhs, base, sliding, normal, slope)``: the plain rows (m,), sorted;
            the block ``B`` (m x m, CSR, each row's columns once, its diagonal first) of their
            equations and ``rhs`` (m,), ``-phi - rho W outer`` on them (``outer``: ``base`` on
            the other rows, 0 on the kept ones); the direction on the other rows (n_rows,):
            ``-phi`` on identity rows, ``c_t`` on the sliding rows ``sliding``, whose normal
            rows are ``normal`` and whose folded coefficients ``mu s`` are ``slope``. With
            ``B x = rhs`` solved, ``d = base``, ``d[kept] = x``, then
            ``d[sliding] += slope * d[normal]``.

        Raises
        ------
        ValueError
            Where a sliding tangential row's normal row is not plain, so that its column could
            not be folded (in 2D every active row that is not plain is a sliding tangential row
            whose normal row is plain).
        """
        compiled = kernels()
        kept, target, factor, outer, base, sliding, normal, slope = compiled.fold_sliding_rows_2d(
            *compiled.generalised_jacobian_2d(self.lower, self.upper, self.box, self.cone_n,
                                              self.tangent_rows, self.cone_mu, self.unilateral, y),
            phi)
        block, outside = self.reduced_blocks.block(kept, target, factor, self.sigma, outer)
        return kept, block, -phi[kept] - self.rho[kept] * outside, base, sliding, normal, slope

    def hyperstatic(self, forces: np.ndarray) -> bool:
        """Whether plain Newton's active block at ``forces`` is singular by its count of sticking
        rows (:meth:`singular_by_count`), as on a pile at rest, on a problem that is not
        :attr:`small` (False on small ones, where an iteration costs little). There the Newton
        iterations past ``tol`` do not converge quadratically:
        on a deposited 400-grain layer ten of them took the FCLIB error from 1.3e-7 to 1.0e-7,
        and at 12 800 grains each cost three times the whole joint phase
        (docs/records/benchmarks.md, "newton-ac on piles at rest")."""
        return not self.small and self.singular_at(forces)

    def singular_at(self, forces: np.ndarray) -> bool:
        """Whether plain Newton's active block at ``forces`` is singular by its count of sticking
        rows (:meth:`singular_by_count`), on any lane; not counted where ``W`` has no more rows
        than its rank bound (the counted rows are some of its rows). Where it counts, it leaves
        the proximal weight at 0 (plain Newton, centred at ``forces``); a 2D problem's count is
        taken without assembling the rows (:func:`~lubcontact.solvers.kernels.plain_rows_2d`:
        1.9 ms a call against 10 ms with the rows, a 12 800-grain pile at rest)."""
        if self.n_rows <= self.rank_bound:
            return False
        self.set_proximal(0.0, forces)
        y = self.residual(forces)[1]
        if self.planar:
            plain = kernels().plain_rows_2d(self.lower, self.upper, self.box, self.cone_n,
                                            self.tangent_rows, self.cone_mu, self.unilateral, y)
        else:
            plain = self.jacobian(y)[2]
        return self.singular_by_count(plain)

    def singular_by_count(self, plain: int) -> bool:
        """Whether an active block with ``plain`` rows of ``diag(rho) W`` (``G``'s row the
        identity's) is singular by a count: plain Newton (``sigma`` = 0) and more such rows than
        ``W``'s rank bound (:attr:`~lubcontact.problem.ConicProblem.delassus_rank_bound`: the
        degrees of freedom of a step problem), as at the sticking contacts of a hyperstatic pile
        at rest. SuperLU takes about ten times a factorisation's time to find such a block
        singular (43 200 active rows of a 12 800-grain deposited layer: 1.8 s against 0.17 s),
        so it is regularised at once (:func:`_block_solve`)."""
        return self.sigma == 0.0 and plain > self.rank_bound


def elimination_places(pointers: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """Each row's place in an approximate minimum degree order of a square symmetric pattern
    (:func:`minimum_degree_places`), kept for the next call with the same pattern.

    A small system's consecutive steps mostly keep their contacts, hence ``W``'s pattern: 133 of
    200 steps of a settling 40-grain pile had the pattern of the step before, 132 of 200 on a
    developed 40-grain dry inclined flow, 54 of 196 on a gluey one (keeping the last four
    patterns' orders: 133, 133 and 56). Finding the order (the symmetrised pattern, then the
    minimum degree) took 37 us of a 533-us exact-Coulomb solve at 66 contacts
    (docs/records/benchmarks.md, "small solves: the elimination order kept by W's pattern").

    Parameters
    ----------
    pointers, columns : ndarray of int
        The pattern by rows (``W``'s on the compiled lane:
        :func:`~lubcontact.solvers.kernels.compressed_rows`), taken as 32-bit unsigned.

    Returns
    -------
    ndarray of int32, shape (n,)
        Read-only: the same array for the same pattern, shared by the calls.
    """
    pointers, columns = np.asarray(pointers, dtype=np.uint32), np.asarray(columns, dtype=np.uint32)
    pattern = (pointers.tobytes(), columns.tobytes())
    kept, places = _last_order[0]
    if kept != pattern:
        places = minimum_degree_places(pointers, columns)
        places.flags.writeable = False
        _last_order[0] = (pattern, places)
    return places


def minimum_degree_places(pointers: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """Each row's place (int32, shape (n,)) in an approximate minimum degree order of a square
    symmetric pattern given by rows as 32-bit unsigned CSR arrays (the order of
    :func:`~lubcontact.solvers.ordering.approximate_minimum_degree` on
    :func:`~lubcontact.solvers.kernels.symmetrised_pattern`), found afresh."""
    return places_of(ordering().approximate_minimum_degree(
        *kernels().symmetrised_pattern(pointers, columns)))


def lanes(problem: ConicProblem) -> tuple[bool, bool, bool]:
    """Which lanes of :class:`AlartCurnier` ``problem`` takes: ``(planar, compiled, small)``
    (the attributes of the same names)."""
    planar = problem.cones.tangent_dim == 1
    return (planar, planar and problem.n_rows <= COMPILED_LIMIT,
            is_small(problem) or planar and problem.n_rows <= DENSE_LIMIT)


def contact_steps(diagonal: np.ndarray, cones: Cones) -> tuple[np.ndarray, float]:
    """Each row's step ``rho = 1 / W_nn`` of its contact (``W_nn`` floored at ``1e-12`` of the
    largest), shape (n_rows,), and the median ``W_nn`` (1 without contacts), from the normal
    rows' diagonal of ``W``, shape (nc,) (compiled: :func:`~.kernels.contact_steps`)."""
    rho, typical = kernels().contact_steps(np.ascontiguousarray(diagonal), cones.tangential,
                                           cones.tangent_dim)
    return rho, float(typical)


class _ReducedBlocks:
    """The reduced Newton blocks of a 2D problem on the sparse lane
    (:func:`~lubcontact.solvers.kernels.reduced_block_2d`), with the folded rows of the last one
    kept where ``W``'s factor is given, so that the next block reads from ``W`` only the rows
    whose columns changed their fold: late in a dense dry flow's step a Newton iteration changes
    a few (0-17 of 684 448 columns at 10^5 grains), and reading the kept rows of ``W`` was a
    third of that step. The rows that may read a changed column are found through the factor
    ``L`` (``W = L^T L``).

    :class:`AlartCurnier` gives the factor where its products go through it
    (:data:`FACTOR_PRODUCT_SHARE`: ``W`` dense against its factor, each row of ``W`` long): on
    gluey flows most rows change in the first Newton iterations of a step, and the bookkeeping
    cost more than the rows it saved (docs/records/benchmarks.md, "the reduced block's rows
    reused").

    Parameters
    ----------
    w_arrays : tuple of ndarray
        ``W``'s CSR arrays (:attr:`AlartCurnier.w_arrays`).
    rho : ndarray, shape (n_rows,)
        The rows' steps.
    factor_arrays : tuple of ndarray or None
        ``L``'s and ``L^T``'s CSR arrays and a work vector (:attr:`AlartCurnier.factor_arrays`);
        None: every block read from ``W`` whole.
    """

    def __init__(self, w_arrays: tuple[np.ndarray, np.ndarray, np.ndarray], rho: np.ndarray,
                 factor_arrays: tuple[np.ndarray, ...] | None):
        self.w_arrays, self.rho, self.factor_arrays = w_arrays, rho, factor_arrays
        none = np.empty(0, dtype=np.uint32)
        # L^T's rows (a contact row's degrees of freedom), then L's (a degree's contact rows)
        self.hops = (none, none, none, none) if factor_arrays is None else \
            (factor_arrays[3], factor_arrays[4], factor_arrays[0], factor_arrays[1])
        empty = np.empty(0, dtype=np.int32)
        self.last: tuple[np.ndarray, ...] = (empty, np.empty(0), empty, np.empty(0, dtype=np.int64),
                                             empty, empty, np.empty(0))

    def block(self, kept: np.ndarray, target: np.ndarray, factor: np.ndarray, sigma: float,
              outer: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
        """The reduced block ``B`` (m x m, CSR) at the fold ``kept``, ``target``, ``factor``,
        ``outer`` (:func:`~lubcontact.solvers.kernels.fold_sliding_rows_2d`) and the proximal
        weight ``sigma``, and ``(W outer)[kept]`` (m,): read with the block's rows where they
        are read whole, else through the factor; the folded rows kept for the next call."""
        compiled = kernels()
        row_ptr, columns, values, outside, into, slot, folded = compiled.reduced_block_2d(
            *self.w_arrays, self.rho, sigma, kept, target, factor, outer, *self.hops, *self.last)
        if self.factor_arrays is not None:
            self.last = (into, factor, slot, kept, row_ptr, columns, folded)
            outside = compiled.factor_rows_product(*self.factor_arrays, outer, kept)
        return sp.csr_matrix((values, columns, row_ptr), shape=(kept.size, kept.size)), outside


def _newton_direction(J: sp.csr_matrix | np.ndarray, active: np.ndarray,
                      phi: np.ndarray, factorisations: Factorisations | None = None,
                      singular: bool = False) -> np.ndarray | None:
    """Solve ``J d = -phi`` with the identity rows eliminated (``J``: the active rows, as
    :meth:`AlartCurnier.jacobian` returns them), the active block by :func:`_block_solve`
    (``factorisations``: a fresh one when not given); None where it fails."""
    direction = -phi.copy()
    rows = np.flatnonzero(active)
    if rows.size == 0:
        return direction
    rhs = -phi[rows] - J @ np.where(active, 0.0, direction)
    block = J[:, rows] if isinstance(J, np.ndarray) else J[:, rows].tocsc()
    solved = _block_solve(block, rhs, rows, Factorisations() if factorisations is None
                          else factorisations, singular)
    if solved is None:
        return None
    direction[rows] = solved
    return direction


def _block_solve(block: sp.spmatrix | np.ndarray, rhs: np.ndarray, rows: np.ndarray,
                 factorisations: Factorisations, singular: bool = False) -> np.ndarray | None:
    """``block^-1 rhs`` for the active block of a Newton system (``rows``: the system's rows it
    holds, sorted), or None when every regularisation fails.

    The block is factorised by a dense LU (LAPACK) up to :data:`DENSE_LIMIT` rows, sparse
    above, through ``factorisations`` (:class:`~lubcontact.solvers.factorisations.Factorisations`:
    in 2D an elimination order of its own or carried over and a static LU; in 3D SuperLU,
    :data:`~lubcontact.solvers.factorisations.SPARSE_LU`; the factors of a block met again
    reused).

    A singular active block (``W`` rank deficient: more sticking rows than
    degrees of freedom) is regularised, ``block + delta I`` with ``delta`` from
    :data:`REGULARISATIONS` in turn (a proximal step, as in Siconos' PROX), from the first
    positive one where the block is ``singular`` by a count (:meth:`AlartCurnier.singular_by_count`).
    On the 2D sparse lane the block is the reduced one (:meth:`AlartCurnier.newton_direction`;
    on the compiled dense lane too, :func:`~lubcontact.solvers.kernels.newton_direction_2d`),
    so only its rows are shifted, not the eliminated sliding rows: the regularised direction
    differs from that of the whole active block's by about ``delta`` (relative). Where the block
    is singular but factorises unregularised (plain Newton, ``sigma`` = 0, ``W`` rank deficient),
    the two eliminations pick different null-space components: directions that differ by up to
    O(1) relative, or one far too long, which the line search rejects.
    """
    dense = rows.size <= DENSE_LIMIT
    if dense and not isinstance(block, np.ndarray):
        block = block.toarray()
    for delta in (delta for delta in REGULARISATIONS if delta > 0 or not singular):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error", spla.MatrixRankWarning)
                if dense:
                    factors = dense_lu(block + delta * np.eye(rows.size))
                    if factors is None:                 # exactly singular
                        continue
                    solved = dense_lu_solve(factors, rhs)
                else:
                    matrix = block if delta == 0 else \
                        block + delta * sp.identity(rows.size, format=block.format)
                    solved = factorisations.solve(matrix, rhs, rows)
        except (RuntimeError, spla.MatrixRankWarning):
            continue
        if np.isfinite(solved).all():
            return solved
    return None

@register("newton-ac", kind=NEWTON, cones=ALL_CONES, warm_start=True, native_coulomb=True)
def newton_alart_curnier(problem: ConicProblem, *, tol: float, max_iter: int = 1000,
                         warm_start: np.ndarray | None = None, fallback: str | None = "auto",
                         joint: int = 0) -> MethodOutput:
    """Semismooth Newton on the Alart-Curnier function (exact Coulomb, one LU per iteration).

    Parameters
    ----------
    problem : ConicProblem
        Normalised; read as the Coulomb problem with ``q = b - [s, 0]``.
    tol : float
        Stop when the FCLIB error is below it.
    max_iter : int
        Cap on Newton iterations (one LU each, of the active rows, less the sliding ones on
        the 2D sparse lane: dense up to :data:`DENSE_LIMIT` rows, sparse above), shared by the
        strategies; the joint phase (``joint``) has its own cap, :data:`JOINT_START_ITERATIONS`.
        1 000 by default: at 500 the last strategy on the 800-grain frictional pile at rest of
        ``lubcontact compare`` (from zero forces, tol 1e-8) was cut at its 351st iteration,
        still progressing (1.2e-5), and whether the fallbacks then reached tol turned on the
        rounding (a change of elimination order flipped it); with 1 000 every strategy stalls
        by its own rule (774-789 iterations) and the fallbacks converge under either order
        (docs/records/benchmarks.md, "the minimum-degree order postordered along its assembly
        tree").
    warm_start : ndarray, shape (n_rows,), optional
        Initial forces (scaled); zero otherwise.
    fallback : str or None
        Registered method, or ``"auto"`` for a chain of them (:func:`fallback_chain`),
        whose exact-Coulomb solve (:func:`~lubcontact.solvers.solve_coulomb`) takes over
        from the best Newton iterate when every strategy stalls (:data:`STALL_WINDOW`,
        :data:`STALL_HORIZON`), fails or reaches ``max_iter``, each from the best iterate so
        far (one that solves exact Coulomb itself, ``nsgs``, in rounds, each polished:
        :func:`fallback_rounds`), until one's polished answer is below ``tol`` or is kept within
        :data:`FALLBACK_GAP` ``tol``; None: no fallback. The answer is the fallback's
        (polished) forces only where their FCLIB error is below the best iterate's so far.
        Newton stalls where the
        generalised Jacobian is singular at the solution for every proximal
        weight tried (degenerate contacts, e.g. the 7002-contact Siconos
        granular file with its indefinite ``W``).
    joint : int
        If > 0, on 2D convex cones (no UNION contact) of more than :data:`COMPILED_LIMIT` rows
        (the sparse lane): first the
        joint phase of the fixed point
        (:func:`~lubcontact.solvers.compiled_apgd.joint_coulomb_apgd`: APGD that updates the
        shift every ``joint`` iterations, to ``tol``, at most :data:`JOINT_START_ITERATIONS`
        iterations) from the warm start (also where the warm start is below ``tol``: on a
        deposited 12 800-grain layer, warm starts taken as they were drifted from 2e-7 to 9e-7
        in three steps, from where the joint phase took 3 192 iterations against 96); the Newton
        phases then start from its forces where their FCLIB error is below the warm start's,
        and go on to :data:`JOINT_FINISH` ``tol``.
        0: none. On developed dry flows its forces (FCLIB error near ``tol``) leave Newton 2 to
        13 iterations instead of 15-28; on the compiled lane the APGD run costs more than the
        Newton iterations it saves (dry 150-grain flows, 650-660 rows: 51.5 ms per step with it
        against 42.5 without), and with UNION contacts it ends on the wrong piece of the
        contacts that change piece, from where Newton took more iterations on 12 000-grain
        gluey steps (docs/records/benchmarks.md, "newton-ac from the joint phase"). On the
        compiled lane it runs only where the first weight has stalled from the warm start and
        from zero forces, from the warm start, and the strategies go on from its forces where
        they are better (:func:`_strategies`, ``strategies`` labelled ``"joint"``): on
        developed dry 140- and 150-grain flows the steps on which every strategy stalled went
        to Gauss-Seidel, 10-30 times a usual step (docs/records/benchmarks.md, "the joint
        phase after stalled strategies"). Not with UNION contacts there either: after the
        first strategy, with the contacts on the pieces of the warm start, it cost gluey
        90-grain flows more time.

    Returns
    -------
    MethodOutput
        ``iterations``: the joint phase's APGD iterations, Newton iterations (the
        finish from the joint phase's forces included) and the fallback's inner iterations.
        ``info``: ``joint_iterations`` (the joint phase's, with ``joint``),
        ``newton_iterations`` (each one LU, more where a
        singular block is regularised), ``reused_factorisations`` (the sparse lane's LUs
        saved by a block met again:
        :class:`~lubcontact.solvers.factorisations.Factorisations`), ``carried_orderings``
        (its LUs in the elimination order of an earlier block, not ordered again),
        ``pivoted_factorisations`` (the sparse lane's LUs in such an order or in a 2D block's
        own that SuperLU factorised, pivoting, after
        :class:`~lubcontact.solvers.factorisations.StaticLU`'s pivots or solve were not good
        enough), ``local_sweeps`` (the times the local Gauss-Seidel sweeps of the proximal
        loop lowered the error and were taken: :data:`LOCAL_ROWS`), ``gradient_steps``
        (steepest-descent steps taken where the Newton direction failed),
        ``proximal_steps`` and ``strategies`` (the starting weights tried, each with
        its start, ``"warm"``, ``"cold"`` or ``"joint"``: the joint phase's forces),
        ``newton_status`` and ``error`` (the Newton phase's FCLIB error), and
        ``fallbacks`` (the methods run), ``fallback_iterations`` (summed) and
        ``fallback_status`` (the last call's: for a fallback run in rounds,
        :func:`fallback_rounds`, its last round's) when a fallback ran.
    """
    joint = _checked_options(fallback, joint)
    start = time.perf_counter()
    function = AlartCurnier(problem)
    unshifted = problem.with_shift(np.zeros(problem.cones.count)) if problem.shift.any() else problem
    forces = np.zeros(problem.n_rows) if warm_start is None else np.array(warm_start, dtype=float)
    setup_time = time.perf_counter() - start
    joint_start = _JointStart(problem, function, unshifted, tol, joint) \
        if joint > 0 and problem.cones.is_convex and joint_applies(problem.cones) else None
    if joint_start is not None and not function.dense:
        joined = joint_start(forces)
        forces = forces if joined is None else joined
    phase = _strategies(function, unshifted, forces, tol, max_iter,
                        rescue=joint_start if function.dense else None)
    joint_iterations, joined_start = (0, False) if joint_start is None else \
        (joint_start.iterations, joint_start.taken)
    forces, iterations, history = phase.forces, phase.iterations + joint_iterations, phase.history
    status = INACCURATE if phase.status == STALLED else phase.status
    info = {"newton_iterations": phase.iterations, "gradient_steps": phase.gradient_steps,
            "proximal_steps": phase.proximal_steps, "strategies": phase.strategies,
            "newton_status": phase.status, "error": phase.error,
            "joint_iterations": joint_iterations}
    if joined_start and phase.status == CONVERGED and phase.error > JOINT_FINISH * tol \
            and not function.hyperstatic(forces):
        finish = _proximal_newton(function, unshifted, forces, JOINT_FINISH * tol, POLISH_ITERATIONS,
                                  STRATEGIES[0], finish=False)
        iterations += finish.iterations
        info["newton_iterations"] += finish.iterations
        history = np.concatenate([history, finish.history[1:]])
        if finish.error < phase.error:
            forces, info["error"] = finish.forces, finish.error
    chain = () if phase.status == CONVERGED else fallback_chain(problem.cones, fallback)
    best_error = phase.error
    for name in chain:
        info["fallbacks"] = [*info.get("fallbacks", []), name]
        origin, kept = forces, False
        for cap in fallback_rounds(name):
            rescue = solve_coulomb(problem, name, tol=tol, tol_fp=tol, warm_start=origin, max_iter=cap)
            iterations += rescue.iterations
            info["fallback_iterations"] = info.get("fallback_iterations", 0) + rescue.iterations
            info["fallback_status"] = rescue.status
            finish = _proximal_newton(function, unshifted, rescue.forces, tol,
                                      FALLBACK_POLISH_ITERATIONS,
                                      STRATEGIES[0])
            iterations += finish.iterations
            info["newton_iterations"] += finish.iterations
            if finish.error < best_error:      # else the best iterate so far and its status stay
                kept, forces, best_error = True, finish.forces, finish.error
                info["error"] = finish.error
                # newton-ac's test is the FCLIB error: a fallback "converged" by its own
                # measure but above tol is inaccurate here; otherwise the iterations ran out
                status = CONVERGED if finish.error <= tol else \
                    INACCURATE if rescue.status == CONVERGED else MAX_ITER
            if status == CONVERGED or rescue.status in (CONVERGED, DIVERGED, FAILED):
                break                            # (diverged: zero forces, from the registry's check)
            origin = rescue.forces               # the next round goes on from the fallback's own
        if status == CONVERGED or kept and best_error <= FALLBACK_GAP * tol:
            break
    info["reused_factorisations"] = function.factorisations.reused     # the polishes' too
    info["carried_orderings"] = function.factorisations.carried
    info["pivoted_factorisations"] = function.factorisations.pivoted
    info["local_sweeps"] = function.sweeps_kept
    info["corrected_steps"] = function.corrections_kept
    return MethodOutput(forces, status, iterations, setup_time=setup_time,
                        solve_time=time.perf_counter() - start - setup_time,
                        residual_history=history, info=info)


def _checked_options(fallback: str | None, joint: int) -> int:
    """:func:`newton_alart_curnier`'s ``fallback`` and ``joint`` checked, ``joint`` returned as an
    int: ``ValueError`` naming the option for a ``fallback`` other than None, ``"auto"`` or a
    registered method, and for a ``joint`` that is not an integer >= 0."""
    checks.require(fallback is None or fallback == "auto" or fallback in methods(), "fallback",
                   "must be None, 'auto' or a registered method", fallback)
    return checks.integer("joint", joint, minimum=0)


def fallback_rounds(name: str) -> tuple[int | None, ...]:
    """The iteration caps of the calls that spend fallback ``name``'s own cap (its ``max_iter``
    default): for a method that solves exact Coulomb itself from a warm start, :data:`FALLBACK_ROUND`
    twice, then twice and four times that, then the rest (fewer where its cap is smaller); for
    any other (a fixed point on s, whose outer loop a round would restart; a method without a
    positive integer default) one call, ``(None,)``."""
    info = solver_info(name)
    cap = inspect.signature(info.function).parameters.get("max_iter")
    if not (info.native_coulomb and info.warm_start) or cap is None \
            or not isinstance(cap.default, int) or cap.default <= 0:
        return (None,)
    rounds, left = [], cap.default
    for size in (FALLBACK_ROUND, FALLBACK_ROUND, 2 * FALLBACK_ROUND, 4 * FALLBACK_ROUND):
        if size >= left:
            break
        rounds.append(size)
        left -= size
    return (*rounds, left)


def fallback_chain(cones: Cones, fallback: str | None) -> tuple[str, ...]:
    """The methods newton-ac hands a stalled solve to, in turn: none for None, ``fallback``
    alone for a registered name, and for ``"auto"`` :data:`FALLBACKS_3D` on 3D cones,
    :data:`FALLBACKS_UNION` on 2D ones with UNION contacts, :data:`FALLBACKS_2D` otherwise."""
    if fallback is None:
        return ()
    if fallback != "auto":
        return (fallback,)
    if cones.tangent_dim > 1:
        return FALLBACKS_3D
    return FALLBACKS_2D if cones.is_convex else FALLBACKS_UNION


def _strategies(function: AlartCurnier, unshifted: ConicProblem, forces: np.ndarray,
                tol: float, max_iter: int, rescue: _JointStart | None = None) -> _Phase:
    """:func:`_proximal_newton` with each ``sigma`` of :data:`STRATEGIES` in turn, each from
    ``forces`` (a strategy's stalled iterate is a worse start than the warm start, measured),
    the first also from zero forces when ``forces`` is not zero (from a warm start on a flow's
    step, ``AlartCurnier.flow_step``, the first from ``forces`` is :data:`WARM_FLOW_WEIGHT`
    instead, on a small 2D problem :data:`WARM_DENSE_WEIGHT`, which ``STRATEGIES[0]`` then
    replaces among the later ones; from zero it stays ``STRATEGIES[0]``), until one converges,
    ``max_iter`` Newton iterations are spent or (off the compiled lane) the best error is within
    :data:`STRATEGY_GAP` of ``tol`` (on a gluey flow's step from a warm start, once the first
    weight from zero forces has been tried); the best phase is returned (the plain try's, if best, as
    stalled where it stopped short of ``tol``; its error counts in the test against
    :data:`STRATEGY_GAP`).

    First, on a small 2D problem without friction cones, from a warm start at which plain
    Newton's block is not singular by its count (:meth:`AlartCurnier.singular_at`), and where
    ``max_iter`` leaves the strategies room (more than twice :data:`PLAIN_TRY`), the plain try:
    at most :data:`PLAIN_TRY` plain Newton iterations from ``forces``, finished to round-off as a
    proximal loop is (:data:`FINISH_ITERATIONS`); plain Newton as a strategy has no finish.

    ``rescue`` (the joint phase, on the dense lanes: :class:`_JointStart`) is called once, with
    the warm start, where the first weight has stalled from it and from zero forces; where it
    returns forces, the first weight and the others start from them instead (labelled
    ``"joint"`` in ``strategies``), as on the sparse lane from the joint phase's forces."""
    best, history, tried = None, [], []
    iterations = gradient_steps = proximal_steps = 0
    warm = bool(forces.any())
    plain_try = PLAIN_TRY > 0 and max_iter > 2 * PLAIN_TRY and warm and function.small \
        and function.planar and not function.cone_n.size and not function.singular_at(forces)
    starts = ([(0.0, forces, True)] if plain_try else []) + _starts(function, forces)
    rescue_at = len(starts) - len(STRATEGIES) + 1       # before the other weights
    label = "warm" if warm else "cold"
    index = 0
    while index < len(starts):
        sigma, start, is_plain_try = starts[index]
        index += 1
        budget = PLAIN_TRY if is_plain_try else max_iter - iterations
        phase = _proximal_newton(function, unshifted, start, tol, budget, sigma,
                                 finish=sigma > 0 or is_plain_try)
        if is_plain_try and phase.status != CONVERGED:
            phase.status = STALLED                  # its cap, not the solve's max_iter
        tried.append((sigma, label if start is forces else "cold"))
        iterations += phase.iterations
        gradient_steps += phase.gradient_steps
        proximal_steps += phase.proximal_steps
        history.extend(phase.history if not history else phase.history[1:])
        if best is None or phase.error < best.error:
            best = phase
        near_tol = not function.compiled and not is_plain_try and best.error <= STRATEGY_GAP * tol \
            and not (function.gluey_flow and _zero_forces_next(starts, index, warm))
        if phase.status == CONVERGED or iterations >= max_iter or near_tol:
            break
        if rescue is not None and index == rescue_at:
            joined = rescue(forces)
            if joined is not None:
                forces, label = joined, "joint"
                starts[index:] = _starts(function, joined, cold=False)
    return _Phase(forces=best.forces, status=best.status, iterations=iterations, error=best.error,
                  history=np.asarray(history), gradient_steps=gradient_steps,
                  proximal_steps=proximal_steps, strategies=tried)


def _zero_forces_next(starts: list[tuple[float, np.ndarray, bool]], index: int, warm: bool) -> bool:
    """Whether the next of :func:`_strategies`' ``starts`` (after ``index``) is the first weight
    from zero forces, which follows a warm start (asked only where it decides: an array pass)."""
    return warm and index < len(starts) and not starts[index][1].any()


def _starts(function: AlartCurnier, forces: np.ndarray, cold: bool = True
            ) -> list[tuple[float, np.ndarray, bool]]:
    """The strategies of :func:`_strategies` from ``forces``, in turn: ``(sigma, start, False)``
    (the plain try aside); without the first weight from zero forces unless ``cold``."""
    warm = bool(forces.any())
    first = STRATEGIES[0]
    if warm and function.flow_step:
        first = WARM_FLOW_WEIGHT
    elif warm and function.planar and function.small:
        first = WARM_DENSE_WEIGHT
    return [(first, forces, False)] \
        + ([(STRATEGIES[0], np.zeros_like(forces), False)] if warm and cold else []) \
        + [(STRATEGIES[0] if sigma == first else sigma, forces, False) for sigma in STRATEGIES[1:]]


@dataclass
class _JointStart:
    """The joint phase of ``newton_alart_curnier`` (``joint``) as a start: called with forces,
    :func:`~lubcontact.solvers.compiled_apgd.joint_coulomb_apgd` from them (at most
    :data:`JOINT_START_ITERATIONS` iterations, the shift updated every ``every``), its forces
    where their FCLIB error is below that of the forces given (``taken``), else None."""

    problem: ConicProblem
    function: AlartCurnier
    unshifted: ConicProblem
    tol: float
    every: int
    iterations: int = 0
    taken: bool = False

    def __call__(self, forces: np.ndarray) -> np.ndarray | None:
        joined, self.iterations = joint_coulomb_apgd(self.problem, forces, self.tol,
                                                     JOINT_START_ITERATIONS, self.every)
        self.taken = self.function.coulomb_error(self.unshifted, joined) \
            < self.function.coulomb_error(self.unshifted, forces)
        return joined if self.taken else None


def _proximal_newton(function: AlartCurnier, unshifted: ConicProblem, forces: np.ndarray,
                     tol: float, max_iter: int, sigma: float, finish: bool = True) -> _Phase:
    """Proximal-point iterations, each solved by Newton, until the FCLIB error is below ``tol``.

    Each outer iteration solves (approximately: ``|phi_sigma|`` down by :data:`INNER_REDUCTION`, or
    the FCLIB error below ``tol``, in at most :data:`INNER_CAP` Newton iterations,
    :data:`UNION_INNER_CAP` on a 2D sparse problem with UNION contacts) the problem with
    ``W + sigma I`` and ``q - sigma r_k`` centred at the current forces ``r_k``: a well-posed problem
    even where ``W`` is rank deficient (more contact rows than degrees of freedom, a hyperstatic
    packing), whose Newton system is not singular. ``sigma`` starts at ``sigma`` times the median
    diagonal of ``W`` (0: plain Newton throughout), is divided by :data:`SIGMA_DECREASE`
    (:data:`UNION_SIGMA_DECREASE` on a 2D sparse problem with UNION contacts) after an outer
    iteration whose subproblem was solved (towards plain Newton, down to :data:`SIGMA_MIN`, but not
    down to a weight whose subproblem was not solved since the error last fell by
    :data:`STALL_FACTOR`) and multiplied by 10 after one whose was not (by :data:`STUCK_RISE` where
    that step did not lower the error either: a stuck iterate; the phase has stalled when it would
    pass :data:`SIGMA_MAX`). The next centre is a solved subproblem's solution (Newton's last
    iterate) even where its FCLIB error is above the centre's: re-centring at the best iterate
    posed the same subproblem again, and on creeping beds the weight then alternated between a
    subproblem that moved nothing and a smaller one not solved in :data:`INNER_CAP` iterations
    until the phase stalled (docs/records/benchmarks.md, "creeping beds"). The best iterate is what
    the phase returns. The phase stalls by :class:`_StallRule`. On the compiled lane the
    subproblems that follow a solved one run in the same compiled call while no weight has failed
    and the stall test could not stop the phase (:data:`CHAINED_SUBPROBLEMS`).
    On a flow's step (:data:`RECENTRE_WINDOW`) each subproblem first gets one Newton iteration,
    re-centred at its result at the same weight (on a gluey flow's step a weight at most the
    centre's FCLIB error, :data:`UNION_RECENTRE_FOLLOWS`), until the error stops halving or nears
    ``tol``; there, before each subproblem (re-centred ones too) where the error sits on a few rows, local
    Gauss-Seidel sweeps over them give the next centre if they lower the error (:data:`LOCAL_ROWS`;
    their error joins the record, the Newton iterations' errors, as an iteration's would).
    With ``finish``, a phase that converged on a problem without friction cones ends with at most
    :data:`FINISH_ITERATIONS` plain Newton iterations, exact there once the active set has
    settled (unless the block is singular by its count, :meth:`AlartCurnier.hyperstatic`): from
    ``tol`` to round-off (:data:`ROUND_OFF`) in one or two factorisations, the second only after
    a first that gained (:data:`FINISH_GAIN`). With friction cones, and without ``finish``, it
    stops at ``tol``. :func:`_strategies` asks for it after a proximal loop and after the plain
    try, not after plain Newton as a strategy (on two hard cases its iterations did not reach
    round-off); the polish to :data:`JOINT_FINISH` ``tol`` does not (that is its target).
    """
    scale = sigma * function.typical
    decrease = UNION_SIGMA_DECREASE if function.gluey_flow else SIGMA_DECREASE
    cap = UNION_INNER_CAP if function.gluey_flow else INNER_CAP
    error, velocity = function.coulomb_error(unshifted, forces), None
    history, best = [error], (error, forces)
    iterations = gradient_steps = proximal_steps = 0
    status = MAX_ITER
    floor, floor_error = 0.0, np.inf                # the largest weight that failed lately
    rule = _StallRule(tol)
    recentring = RECENTRE_WINDOW > 0 and function.flow_step and function.cone_n.size > 0 and scale > 0 \
        and error > RECENTRE_UNTIL * tol
    while best[0] > tol and iterations < max_iter:
        if rule.stalled(history, best[0]):
            status = STALLED
            break
        if recentring and (best[0] <= RECENTRE_UNTIL * tol
                           or not _halved_over(history, best[0], RECENTRE_WINDOW)):
            recentring = False              # near tol, or no longer halving: solve subproblems
            scale = _at_most_error(scale, error, function)
        if LOCAL_SWEEPS and scale > 0 and function.sweeps_apply:
            swept = function.swept(forces, velocity)
            if swept is not None and swept[2] < error:  # the few contacts Newton cycles on
                function.sweeps_kept += 1
                forces, velocity, error = swept
                history.append(error)
                best = min(best, (error, forces), key=lambda pair: pair[0])
                if error <= tol:
                    break
        centre_error = error
        if recentring and function.gluey_flow and UNION_RECENTRE_FOLLOWS:
            scale = _at_most_error(scale, error, function)
        function.set_proximal(scale, forces)
        known = dict(velocity=velocity, error=error)      # at forces: no product afresh
        if recentring:
            inner = _newton_phase(function, unshifted, forces, tol, 1, **known)
        elif scale > 0:
            # on the compiled lane, while no weight has failed, the solved subproblems in one call
            chain = (max_iter - iterations, STALL_WINDOW + 1 - len(history), decrease) \
                if CHAINED_SUBPROBLEMS and function.compiled and floor == 0.0 else None
            inner = _newton_phase(function, unshifted, forces, tol, min(cap, max_iter - iterations),
                                  inner_tol=INNER_REDUCTION * error * function.q_scale, chain=chain,
                                  **known)
        else:                           # plain Newton: one run, its line search's memory intact
            inner = _newton_phase(function, unshifted, forces, tol, min(STALL_WINDOW, max_iter - iterations),
                                  **known)
        if inner.chained is not None:      # the last subproblem's weight and centre error
            scale, centre_error = inner.chained.sigma, inner.chained.centre_error
        proximal_steps += 1 if inner.chained is None else inner.chained.subproblems
        iterations += inner.iterations
        gradient_steps += inner.gradient_steps
        history.extend(inner.history[1:])
        best = min(best, (inner.error, inner.forces) if inner.chained is None else inner.chained.best,
                   key=lambda pair: pair[0])
        solved = inner.solved or (recentring and inner.iterations > 0)
        if solved:                          # centred at the subproblem's solution, even where its
            forces, velocity, error = inner.last, inner.last_velocity, inner.last_error  # error is
        else:                                                                # above the centre's
            forces, velocity, error = inner.forces, None, inner.error
        if error < STALL_FACTOR * floor_error:          # progress since: try smaller weights
            floor, floor_error = 0.0, np.inf
        if scale > 0 and not solved:        # a better-posed subproblem
            floor, floor_error = max(floor, scale), error
            scale *= STUCK_RISE if inner.error > STUCK * centre_error else 10.0
            if scale > SIGMA_MAX * function.typical:
                status = STALLED
                break
        elif not recentring and scale / decrease > floor:   # towards plain Newton, not to a
            scale = max(scale / decrease, SIGMA_MIN * function.typical)     # weight that failed
        if inner.iterations == 0:
            status = FAILED
            break
    if best[0] <= tol:
        status = CONVERGED
        # the loop stops at tol; without friction cones a plain Newton step is exact from here
        if finish and not function.cone_n.size and best[0] > ROUND_OFF \
                and not function.hyperstatic(best[1]):
            function.set_proximal(0.0, best[1])
            start = best
            for _ in range(FINISH_ITERATIONS):       # one at a time: each must gain (FINISH_GAIN)
                plain = _newton_phase(function, unshifted, start[1], ROUND_OFF, 1, error=start[0])
                iterations += plain.iterations
                history.extend(plain.history[1:])
                best = min(best, (plain.error, plain.forces), key=lambda pair: pair[0])
                if plain.iterations == 0 or not ROUND_OFF < plain.error <= FINISH_GAIN * start[0]:
                    break
                start = (plain.error, plain.forces)
    return _Phase(forces=best[1], status=status, iterations=iterations, error=best[0],
                  history=np.asarray(history), gradient_steps=gradient_steps,
                  proximal_steps=proximal_steps)


def _at_most_error(scale: float, error: float, function: AlartCurnier) -> float:
    """The proximal weight ``scale``, at most the FCLIB ``error`` in units of the median diagonal
    of ``W`` (``function.typical``), and at least :data:`SIGMA_MIN` in those units."""
    return max(min(scale, error * function.typical), SIGMA_MIN * function.typical)


@dataclass
class _StallRule:
    """The stall test of one Newton phase at tolerance ``tol``, called once per proximal step.

    The phase has stalled when its best FCLIB error did not fall by :data:`STALL_FACTOR` over
    the last :data:`STALL_WINDOW` iterations, with one reprieve: at the first such window,
    if falling at that window's rate it would reach ``tol`` within :data:`STALL_HORIZON` more
    windows, it is given until then (``deadline``, an iteration count), and it stalls as soon
    as the rate of its last window would no longer bring it to ``tol`` by the deadline. A
    window that halves the error ends the reprieve. A phase that slows down near ``tol``
    therefore stalls at most ``STALL_HORIZON`` windows later than by the halving test alone.
    """

    tol: float
    deadline: int | None = None

    def stalled(self, history: list[float], best: float) -> bool:
        """Whether the phase whose FCLIB errors are ``history`` (one per iteration, the start
        first) and whose best error is ``best`` (at most every entry of ``history``) has
        stalled."""
        if _halved_over(history, best, STALL_WINDOW):    # progress (or too few iterations to tell)
            self.deadline = None
            return False
        count, before = len(history), min(history[:-STALL_WINDOW])
        if self.deadline is None:                     # before >= best > 0 from here on
            self.deadline = count + STALL_HORIZON * STALL_WINDOW
        windows_left = (self.deadline - count) / STALL_WINDOW
        return best * (best / before) ** windows_left > self.tol


def _halved_over(history: list[float], best: float, window: int) -> bool:
    """Whether ``best``, the least of ``history`` (FCLIB errors, one per iteration, the start
    first), is at most :data:`STALL_FACTOR` times the least before the last ``window``
    iterations (True while there are no more than ``window``)."""
    return len(history) <= window or not best > STALL_FACTOR * min(history[:-window])


@dataclass
class _Phase:
    """Outcome of the Newton iterations: the best iterate and its record."""

    forces: np.ndarray
    status: str
    iterations: int
    error: float
    history: np.ndarray
    gradient_steps: int
    proximal_steps: int = 0
    strategies: list = field(default_factory=list)
    solved: bool = False
    last: np.ndarray | None = None
    last_error: float = np.inf
    last_velocity: np.ndarray | None = None
    chained: _Chained | None = None


@dataclass
class _Chained:
    """What a compiled phase that ran the proximal loop's solved subproblems in one call
    (:data:`CHAINED_SUBPROBLEMS`) hands back beyond a phase's record, which is its last
    subproblem's: the subproblems, the last one's weight and the FCLIB error at its centre, and
    the best iterate of all, ``(error, forces)``."""

    subproblems: int
    sigma: float
    centre_error: float
    best: tuple[float, np.ndarray]


def _newton_phase(function: AlartCurnier, unshifted: ConicProblem, forces: np.ndarray,
                  tol: float, max_iter: int, inner_tol: float = 0.0, *,
                  velocity: np.ndarray | None = None, error: float | None = None,
                  chain: tuple[int, int, float] | None = None) -> _Phase:
    """Newton iterations on ``function`` from ``forces`` until the FCLIB error of ``unshifted``
    is below ``tol``, ``|phi| <= inner_tol``, a failed line search or the cap (in one compiled
    call on a small 2D problem, :func:`~lubcontact.solvers.kernels.newton_phase_2d`).
    ``velocity`` (``W r + q``) and ``error`` (the FCLIB error) at ``forces``, where the caller
    has them (the last phase's last iterate, re-centred: 0.6 and 0.2 ms of a 17 ms iteration at
    12 000 grains), are not computed again. ``chain`` (compiled lane only): ``(iterations,
    until, decrease)``, the proximal loop's iterations left, the iterations after which no next
    subproblem may start (its stall test could then stop it) and its weight's divisor: the solved
    subproblems that follow run in the same call (:func:`_compiled_phase`)."""
    if function.compiled:
        return _compiled_phase(function, forces, tol, max_iter, inner_tol, chain)
    phi, y, velocity = function.residual(forces, velocity)
    merit = 0.5 * float(phi @ phi)
    recent = [merit]
    if error is None:
        error = function.coulomb_error(unshifted, forces, velocity)
    history = [error]
    best = (error, forces)
    gradient_steps = iterations = 0
    status = MAX_ITER
    while error > tol and iterations < max_iter and np.sqrt(2.0 * merit) > inner_tol:
        iterations += 1
        newton = function.newton_direction(y, phi)
        step = None
        if newton is not None:
            step = _line_search(function, forces, velocity, newton, 2.0 * merit, max(recent),
                                merit=merit)
        if step is None:                   # J^T phi, J's inactive rows being the identity's
            J, active, _ = function.jacobian(y)
            gradient = np.where(active, 0.0, phi) + J.T @ phi[active]
            step = _line_search(function, forces, velocity, -gradient, float(gradient @ gradient),
                                max(recent))
            gradient_steps += 1
        if step is None:
            status = FAILED
            break
        forces, phi, y, velocity = step
        if not function.compiled_rows:          # W r afresh (line search's docstring)
            phi, y, velocity = function.residual(forces)
        merit = 0.5 * float(phi @ phi)
        recent = (recent + [merit])[-LINE_SEARCH_MEMORY:]
        error = function.coulomb_error(unshifted, forces, velocity)
        history.append(error)
        best = min(best, (error, forces), key=lambda pair: pair[0])
    if best[0] <= tol:
        status = CONVERGED
    return _Phase(forces=best[1], status=status, iterations=iterations, error=best[0],
                  history=np.asarray(history), gradient_steps=gradient_steps,
                  solved=bool(np.sqrt(2.0 * merit) <= inner_tol), last=forces, last_error=error,
                  last_velocity=velocity)


def _compiled_phase(function: AlartCurnier, forces: np.ndarray, tol: float, max_iter: int,
                    inner_tol: float, chain: tuple[int, int, float] | None = None) -> _Phase:
    """:func:`_newton_phase` by :func:`~lubcontact.solvers.kernels.newton_phase_2d`, with the
    solved subproblems that follow where ``chain`` is given (:func:`_newton_phase`)."""
    compiled = kernels()
    total, until, decrease = (max_iter, 0, 1.0) if chain is None else chain
    (best, best_error, last, last_error, iterations, gradient_steps, code, history,
     solved, sigma, subproblems, centre_error, overall, overall_error) = compiled.newton_phase_2d(
        function.W, function.w_arrays, function.q, function.rho, function.lower, function.upper,
        function.box, function.cone_n, function.tangent_rows, function.cone_mu, function.unilateral,
        function.sigma, function.center, function.q_scale, np.asarray(forces, dtype=float),
        float(tol), int(max_iter), float(inner_tol), REGULARISATIONS,
        function.elimination_places, STATIC_LU_BACKWARD_ERROR, LINE_SEARCH_MEMORY, ARMIJO,
        MAX_HALVINGS, int(total), int(until), float(decrease), SIGMA_MIN * function.typical,
        INNER_REDUCTION)
    status = FAILED if code == compiled.FAILED_CODE else \
        CONVERGED if code == compiled.CONVERGED_CODE else MAX_ITER
    chained = None if chain is None else \
        _Chained(int(subproblems), float(sigma), float(centre_error), (float(overall_error), overall))
    return _Phase(forces=best, status=status, iterations=int(iterations),
                  error=float(best_error), history=history, gradient_steps=int(gradient_steps),
                  solved=bool(solved), last=last, last_error=float(last_error), chained=chained)


def _line_search(function: AlartCurnier, forces: np.ndarray, velocity: np.ndarray,
                 direction: np.ndarray, slope: float, reference: float, merit: float | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """Backtrack from the full step until ``psi`` falls below the non-monotone Armijo bound.

    A trial's velocity is ``velocity + alpha W d``: one product with ``W`` per direction, not one
    per trial (on developed 2000-grain flows the search took five to six trials per Newton
    iteration). On the 2D sparse lane (``compiled_rows``) the next iteration goes on from the
    accepted trial's velocity, not from a product afresh: on 20 captured 10 000-grain gluey steps
    the velocities so carried through a solve stayed within 1.3e-15 of ``W r + q`` (relative to
    its largest entry), the same iterations in 0.95 of the time (docs/records/benchmarks.md).
    Elsewhere a product with ``W`` costs little beside a Newton iteration and
    :func:`_newton_phase` takes ``W r`` afresh: on a small infeasible problem whose forces grew
    to 1e14 (``glued_infeasible``) the carried velocity drifted by 5.6e-5 of its size. A trial
    whose residual is not finite (a direction far too long) is rejected like any other that
    fails the bound. On a flow's step (:attr:`AlartCurnier.sweeps_apply`) a full step that fails
    the bound is first corrected on the few rows where it fails and taken so where that passes
    the bound (:data:`CORRECTED_ROWS`, :meth:`AlartCurnier.corrected`); so is a full step that
    passes the bound with a ``psi`` above :data:`CYCLING_MERIT` times ``merit``, taken corrected
    where that lowers its ``psi``.

    Parameters
    ----------
    function : AlartCurnier
        The Alart-Curnier function, at its current proximal weight and centre.
    forces, velocity : ndarray, shape (n_rows,)
        The current forces and their velocity ``W r + q``.
    direction : ndarray, shape (n_rows,)
        The search direction ``d``.
    slope : float
        The decrease rate of ``psi`` along ``direction`` at ``forces`` (``2 psi`` for the Newton
        direction, ``|J^T phi|^2`` for steepest descent); none (``<= 0``): no step.
    reference : float
        The largest of the last :data:`LINE_SEARCH_MEMORY` merits, the bound's reference.
    merit : float, optional
        ``psi`` at ``forces``, given for a Newton direction: the cycling full steps' test.

    Returns
    -------
    tuple of ndarray or None
        The accepted forces with their ``phi``, ``y`` and velocity
        (:meth:`AlartCurnier.residual`'s), or None where no trial passed the bound.
    """
    if not slope > 0:
        return None
    alpha = 1.0
    correct = CORRECTED_SWEEPS > 0 and function.sweeps_apply
    with np.errstate(over="ignore", invalid="ignore"):   # a trial too far: rejected below
        change = function.product(direction)
        for _ in range(MAX_HALVINGS):
            trial = forces + alpha * direction
            phi, y, trial_velocity = function.residual(trial, velocity + alpha * change)
            psi = 0.5 * float(phi @ phi)
            bound = reference - ARMIJO * alpha * slope
            accepted = bool(np.isfinite(psi) and psi <= bound)
            cycling = accepted and merit is not None and psi > CYCLING_MERIT * merit
            if correct and (cycling or not accepted):   # the full step: failing, or barely lower
                correct = False
                corrected = function.corrected(trial, phi, trial_velocity) if np.isfinite(psi) else None
                if corrected is not None:
                    corrected_psi = 0.5 * float(corrected[1] @ corrected[1])
                    if (corrected_psi < psi) if accepted else (corrected_psi <= bound):
                        function.corrections_kept += 1
                        return corrected
            if accepted:
                return trial, phi, y, trial_velocity
            alpha *= 0.5
    return None
