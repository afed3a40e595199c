"""The solver registry: capabilities, kinds, up-front rejection, and SolveSettings dispatch."""
import numpy as np
import pytest

from lubcontact import Coulomb, Grains, Inelastic, Scene, Simulation, scenes, solve
from lubcontact.bench.cases.hard import CASES
from lubcontact.model.assemble import assemble
from lubcontact.model.contacts import find_contacts
from lubcontact.problem import ConeKind, ConicProblem
from lubcontact.problem.metrics import velocity_error
from lubcontact.scenes.packing import deposit_pile
from lubcontact.solvers import (
    CONVERGED,
    DIVERGED,
    FIRST_ORDER,
    INTERIOR_POINT,
    KINDS,
    MAX_ITER,
    NEWTON,
    QP,
    CoulombResult,
    MethodOutput,
    SolveSettings,
    capable_methods,
    dual_data,
    methods,
    register,
    solve_coulomb,
    solver_info,
    unregister,
)
from lubcontact.solvers.registry import ALL_CONES


def test_every_method_has_a_kind_and_the_kinds_partition_the_registry():
    by_kind = {kind: set(methods(kind=kind)) for kind in KINDS}
    assert set().union(*by_kind.values()) == set(methods())
    assert sum(len(names) for names in by_kind.values()) == len(methods())
    assert {"pgd", "apgd", "apgd-jacobi", "apgd-as", "bb"} <= by_kind[FIRST_ORDER]
    assert {"clarabel", "clarabel-dual", "clarabel-direct"} <= by_kind[INTERIOR_POINT]
    assert by_kind[QP] == {"osqp"}
    assert by_kind[NEWTON] == {"newton-ac"}


def test_unknown_kind_and_duplicate_name_are_rejected():
    with pytest.raises(ValueError, match="kind"):
        methods(kind="quasi-newton")
    with pytest.raises(ValueError, match="name: solver 'apgd' is already registered"):
        register("apgd")(lambda problem, **_: None)
    with pytest.raises(ValueError, match="kind"):
        register("new-one", kind="magic")


def test_an_unsupported_problem_is_rejected_before_any_work():
    """osqp takes no UNION cones and no 3D cones: one message, naming the methods that can."""
    calls = []

    @register("test-convex-only", kind=QP, cones={ConeKind.NONNEG, ConeKind.FREE},
              second_order=False)
    def _never(problem, *, tol, warm_start=None):
        calls.append(1)
        return MethodOutput(np.zeros(problem.n_rows), CONVERGED, 1)

    try:
        union = CASES["gamma_states_gluey_coulomb"].problem
        assert not union.cones.is_convex
        with pytest.raises(ValueError, match=r"method: 'osqp' cannot solve this problem: UNION"):
            solve(union, "osqp")
        with pytest.raises(ValueError, match="UNION contacts are not supported"):
            solve(union, "test-convex-only")
        assert calls == []
        cone_3d = CASES["cone_apex_3d"].problem
        with pytest.raises(ValueError, match="second-order"):
            solve(cone_3d, "osqp")
        assert solver_info("osqp").rejection(CASES["wedge_planes"].problem) is None
        assert "test-convex-only" not in capable_methods(union)
        assert "clarabel" in capable_methods(union)
    finally:
        unregister("test-convex-only")
    assert "test-convex-only" not in methods()


def test_an_unsupported_problem_is_rejected_before_a_native_coulomb_solve():
    """An exact-Coulomb solve by a method that solves Coulomb natively is refused before the
    method runs, with the message of solve(): a 2D-only native method given 3D cones (before, the
    method ran first and its forces were refused afterwards, by the check at s*)."""
    calls = []

    @register("test-planar-coulomb", cones={ConeKind.NONNEG, ConeKind.FREE, ConeKind.COULOMB},
              second_order=False, native_coulomb=True)
    def _never(problem, *, tol, warm_start=None):
        calls.append(1)
        return MethodOutput(np.zeros(problem.n_rows), CONVERGED, 1)

    try:
        cone_3d = CASES["cone_apex_3d"].problem
        with pytest.raises(ValueError, match=r"method: 'test-planar-coulomb' cannot solve this "
                                             r"problem: second-order"):
            solve_coulomb(cone_3d, "test-planar-coulomb")
        with pytest.raises(ValueError, match=r"method: 'nsgs' cannot solve this problem: second"):
            solve_coulomb(cone_3d, "nsgs")
        assert calls == []
    finally:
        unregister("test-planar-coulomb")


@pytest.mark.parametrize("value", [0, -3, 2.5])
def test_bad_max_iter_is_rejected_naming_the_field(value):
    with pytest.raises(ValueError, match="max_iter"):
        solve(CASES["wedge_planes"].problem, "apgd", max_iter=value)


def test_both_problem_kinds_satisfy_the_protocol():
    from lubcontact.bench.problem_sets import data_dir
    from lubcontact.io import read_problem

    step = CASES["wedge_planes"].problem
    local = read_problem(data_dir() / "fclib-local" / "local_problem_test.hdf5")
    for problem in (step, local, step.normalized(), local.normalized()):
        assert isinstance(problem, ConicProblem)
    assert local.delassus_factor is None and step.delassus_factor is not None


def _frictional_step():
    """A disk sliding on a floor (tangential speed 1, mu = 0.3): the contact slides."""
    grains = Grains.create(positions=[[0.0, 0.5]], radii=0.5, masses=1.0, velocities=[[1.0, 0.0]])
    scene = Scene.create(grains, plane_points=[[0.0, 0.0]], plane_normals=[[0.0, 1.0]],
                         gravity=[0.0, -1.0])
    contacts = find_contacts(scene, 0.05)
    law = Coulomb(0.3)
    return assemble(scene, contacts, law.cones(contacts, np.zeros(contacts.count)), 0.1,
                    rotations=law.needs_rotation)


def test_settings_solve_exact_coulomb_or_the_relaxation():
    problem = _frictional_step()
    assert problem.cones.has_friction
    exact = SolveSettings(method="clarabel", tol=1e-9, tol_fp=1e-8).solve(problem)
    relaxed = SolveSettings(method="clarabel", tol=1e-9, exact_coulomb=False).solve(problem)
    assert isinstance(exact, CoulombResult) and isinstance(relaxed, CoulombResult)
    assert exact.success and exact.fixed_point_converged and exact.outer_iterations > 1
    assert np.any(exact.shift > 0)                       # sliding contacts got their shift
    assert relaxed.success and relaxed.outer_iterations == 1 and np.all(relaxed.shift == 0)
    # the relaxation lifts the sliding disk off (dilatancy mu |u_T|); the shift removes it
    assert problem.gaps_after(relaxed.velocities)[0] > 1e-3
    assert abs(problem.gaps_after(exact.velocities)[0]) < 1e-9
    assert velocity_error(problem, exact.velocities, relaxed.velocities) > 1e-3


@pytest.mark.parametrize("matrix", ["dense_delassus", "delassus"])
def test_outer_iterations_share_the_delassus_matrix(matrix):
    """The fixed point normalises once: on a small problem every inner solve sees the same W
    object, the dense one of the solvers' dense lane (it was rebuilt by every outer iteration)
    and the sparse one that the other methods use."""
    problem = _frictional_step()
    assert dual_data.is_small(problem)
    seen = []

    apgd = solver_info("apgd").function

    @register("test-spy", kind=FIRST_ORDER)
    def _spy(scaled, **kwargs):
        seen.append(id(getattr(scaled, matrix)))
        return apgd(scaled, **kwargs)

    try:
        SolveSettings(method="test-spy", tol=1e-6, max_outer=4).solve(problem)
    finally:
        unregister("test-spy")
    assert len(seen) >= 2 and len(set(seen)) == 1


def test_a_method_that_reports_no_times_is_timed_whole_as_solve_time():
    """``MethodOutput.times``: a method's own split where it gives one (a missing half is 0),
    the whole call as solve time where it gives neither."""
    out = MethodOutput(np.zeros(2), CONVERGED, 3)
    assert out.times(0.3) == (0.0, 0.3)
    out.setup_time = 0.1
    assert out.times(0.3) == (0.1, 0.0)
    out.solve_time = 0.2
    assert out.times(0.3) == (0.1, 0.2)


def test_the_fixed_point_times_are_summed_over_its_inner_solves():
    """A fixed point's ``setup_time`` and ``solve_time`` are its inner solves' together (they
    were the last one's): a method that reports 0.25 s of set-up and 1.5 s of iterations per
    call gives 1.5 s per outer iteration, and 0.25 s per outer iteration plus normalising; the
    joint phase adds its time to ``solve_time``."""
    problem = _frictional_step()
    apgd = solver_info("apgd").function

    @register("test-timed", kind=FIRST_ORDER)
    def _timed(scaled, **kwargs):
        out = apgd(scaled, **kwargs)
        out.setup_time, out.solve_time = 0.25, 1.5
        return out

    try:
        result = SolveSettings(method="test-timed", tol=1e-8, tol_fp=1e-8).solve(problem)
        joined = SolveSettings(method="test-timed", tol=1e-8, tol_fp=1e-8,
                               options={"joint": 5}).solve(problem)
    finally:
        unregister("test-timed")
    assert result.success and result.outer_iterations >= 2
    assert result.solve_time == pytest.approx(1.5 * result.outer_iterations, rel=1e-12)
    assert 0.25 * result.outer_iterations <= result.setup_time < 0.25 * result.outer_iterations + 0.5
    assert joined.success and joined.joint_iterations > 0
    assert 1.5 * joined.outer_iterations < joined.solve_time < 1.5 * joined.outer_iterations + 0.5


def test_the_fixed_point_builds_only_the_operator_its_method_uses():
    """On a problem above the dense lane, a first-order method applies ``F^T (F x)``: the fixed
    point does not assemble ``W`` for it (0.17 s and more memory per 10^5-grain step), and
    every inner solve after the first shares the factor and the scaled ``H`` the first one
    built."""
    scene = deposit_pile(60, seed=5)                       # a 60-grain pile on a floor
    contacts = find_contacts(scene, 0.05)
    law = Coulomb(0.3)
    problem = assemble(scene, contacts, law.cones(contacts, np.zeros(contacts.count)), 0.01,
                       rotations=law.needs_rotation)
    assert not dual_data.is_small(problem.normalized())
    seen = []
    apgd = solver_info("apgd-jacobi").function

    @register("test-spy", kind=FIRST_ORDER)
    def _spy(scaled, **kwargs):
        seen.append(("delassus" in scaled.__dict__, scaled.__dict__.get("delassus_factor"),
                     scaled.__dict__.get("jacobian")))
        return apgd(scaled, **kwargs)

    try:
        result = SolveSettings(method="test-spy", tol=1e-6, tol_fp=1e-6).solve(problem)
    finally:
        unregister("test-spy")
    assert result.outer_iterations >= 2 and len(seen) == result.outer_iterations
    assert not any(assembled for assembled, _, _ in seen)
    for position in (1, 2):         # the factor L, and the normalised H its offset needs
        built = [entry[position] for entry in seen]
        assert built[0] is None and built[1] is not None
        assert all(matrix is built[1] for matrix in built[1:])


def test_settings_validate_their_fields():
    with pytest.raises(ValueError, match="solver: must be a registered method"):
        SolveSettings(method="foo")
    with pytest.raises(ValueError, match="tol"):
        SolveSettings(tol=0.0)
    with pytest.raises(ValueError, match="max_outer"):
        SolveSettings(max_outer=0)
    with pytest.raises(ValueError, match="max_iter"):
        SolveSettings(max_iter=5, options={"max_iter": 6})
    assert SolveSettings(options={"max_iter": 6}).max_iter == 6
    with pytest.raises(ValueError, match="solver"):
        Simulation(scenes.push_pull(), Inelastic(), dt=0.1, solver="foo")


@pytest.mark.parametrize("method", ["apgd-jacobi", "newton-ac"])
def test_the_fixed_point_takes_a_whole_number_of_outer_iterations(settling_step, method):
    """``max_outer`` of solve_coulomb (the fixed point on s, or the branch loop of a method that
    solves exact Coulomb itself) is an integer >= 1 (3.0 is one): 2.5 was taken as 2."""
    problem, _ = settling_step
    for bad in (2.5, 0, -1):
        with pytest.raises(ValueError, match="max_outer"):
            solve_coulomb(problem, method, tol=1e-6, max_outer=bad)
    assert 1 <= solve_coulomb(problem, method, tol=1e-6, max_outer=3.0).outer_iterations <= 3


def test_the_iteration_cap_of_exact_coulomb_is_refused_before_anything_is_solved(settling_step):
    """``max_iter`` of solve_coulomb is an integer >= 1, checked before any solve: by the fixed
    point on s with its joint phase (which took 2.5 and -1 as given and failed inside its
    compiled loop), and for a method that solves exact Coulomb itself, which is never called
    (its check came after the solve, through solve()); an integral float is taken as an int."""
    problem, _ = settling_step
    calls = []

    @register("test-native-cap", cones=ALL_CONES, native_coulomb=True)
    def _native(problem, *, tol, max_iter=None, warm_start=None):
        calls.append(max_iter)
        return MethodOutput(np.zeros(problem.n_rows), CONVERGED, 1)

    try:
        for bad in (2.5, 0, -1):
            for method, options in (("test-native-cap", {}), ("apgd-jacobi", {"joint": 5}),
                                    ("apgd-jacobi", {})):
                with pytest.raises(ValueError, match=f"max_iter: must be an integer >= 1, got {bad}"):
                    solve_coulomb(problem, method, tol=1e-6, max_iter=bad, **options)
        assert calls == []
        solve_coulomb(problem, "test-native-cap", tol=1e-6, max_iter=5.0)
        assert calls == [5] and type(calls[0]) is int
    finally:
        unregister("test-native-cap")
    result = solve_coulomb(problem, "nsgs", tol=1e-6, max_iter=5.0)
    assert type(result.iterations) is int and result.iterations <= 5 * result.outer_iterations


def test_a_native_method_out_of_outer_iterations_is_checked_on_the_pieces_it_solved():
    """A native method that takes only the two pieces of UNION contacts (COULOMB and NONPOS), cut
    at one outer iteration after which a contact flips piece: the answer is ``max_iter``, and its
    residual is that of the pieces its forces were solved on (all pushed, from no warm start), not
    the flipped ones' (1.6 before)."""
    from lubcontact.bench.hard import load_cases
    from lubcontact.solvers.newton import newton_alart_curnier

    problem = load_cases()["gamma_states_gluey_coulomb"].problem

    @register("test-native-pieces", cones={ConeKind.NONNEG, ConeKind.FREE, ConeKind.COULOMB,
                                           ConeKind.NONPOS}, native_coulomb=True)
    def _pieces(problem, *, tol, max_iter=None, warm_start=None):
        return newton_alart_curnier(problem, tol=tol, warm_start=warm_start)

    try:
        cut = solve_coulomb(problem, "test-native-pieces", tol=1e-8, max_outer=1)
    finally:
        unregister("test-native-pieces")
    assert cut.status == MAX_ITER and cut.branch_flips == [1]
    pushed = problem.with_cones(problem.cones.with_branches(np.zeros(problem.n_contacts, dtype=bool)))
    scaled = pushed.with_shift(cut.shift).normalized()
    forces = cut.forces / scaled.scaling.force
    residual = scaled.cones.natural_residual(forces, scaled.constraint_values(scaled.velocity(forces)))
    assert cut.residual == pytest.approx(residual, rel=1e-9, abs=1e-12) and cut.residual < 1e-6


def test_a_native_method_whose_forces_overflow_their_velocities_is_diverged(settling_step):
    """Finite forces whose shift s* = mu |u_T| overflows (1e300 on every row) end ``diverged``
    with zero forces, as non-finite forces do; before, solve_coulomb raised from inside, on the
    shift's own check."""
    problem, _ = settling_step

    @register("test-native-huge", cones=ALL_CONES, native_coulomb=True)
    def _huge(problem, *, tol, max_iter=None, warm_start=None):
        return MethodOutput(np.full(problem.n_rows, 1e300), CONVERGED, 3)

    try:
        with np.errstate(over="raise", invalid="raise"):
            result = solve_coulomb(problem, "test-native-huge", tol=1e-6)
    finally:
        unregister("test-native-huge")
    assert result.status == DIVERGED and not result.success
    assert np.array_equal(result.forces, np.zeros(problem.n_rows))
    assert np.array_equal(result.shift, np.zeros(problem.n_contacts))



OPEN_TRIOS = {   # gaps (floor, pair, top), velocities, masses: every contact stays open
    "a": ([0.01469577229359832, 0.0334092122436204, 0.02034169783681011],
          [[1.1845819264950987, -0.01413158109420849], [1.2084563349160844, -0.43371072315125064],
           [-0.2839232402680096, 1.2998307451335014]],
          [0.2789631201536663, 6.561309939438363, 3.6486039157564614]),
    "b": ([0.01610528477221524, 0.06760981381745425, 0.03103741861436504],
          [[-0.08536547813463852, 0.4632147488587887], [-0.38360045147230754, 0.2340887321493547],
           [-0.16373362210959072, -0.01746817702280519]],
          [0.14644466963720845, 5.6644492685809515, 2.2184755527672033]),
}


def _open_trio(name):
    """Three disks near a floor and each other whose gaps all stay open after the free step."""
    gaps, velocities, masses = OPEN_TRIOS[name]
    positions = [[0.0, 0.5 + gaps[0]], [1.0 + gaps[1], 0.5 + gaps[0]],
                 [0.5, 0.5 + gaps[0] + 0.866 + gaps[2]]]
    grains = Grains.create(positions=positions, radii=0.5, masses=masses, velocities=velocities)
    scene = Scene.create(grains, plane_points=[[0.0, 0.0]], plane_normals=[[0.0, 1.0]],
                         gravity=[0.0, -1.0])
    contacts = find_contacts(scene, 0.1)
    law = Inelastic()
    return assemble(scene, contacts, law.cones(contacts, np.zeros(contacts.count)), 0.01,
                    rotations=False)


@pytest.mark.parametrize("method", ["clarabel", "clarabel-dual", "clarabel-direct", "apgd-as"])
@pytest.mark.parametrize("tol", [1e-9, 1e-6])
@pytest.mark.parametrize("trio", sorted(OPEN_TRIOS))
def test_open_contacts_get_exactly_zero_force(method, tol, trio):
    """Polishing classes contacts against an absolute force level, not the largest force (noise
    when every contact is open): the interior point's ~1e-10 forces become exact zeros."""
    problem = _open_trio(trio)
    assert problem.n_contacts >= 2 and problem.gaps_after(problem.free_velocity).min() > 1e-3
    result = solve(problem, method, tol=tol)
    assert result.success
    assert np.all(result.forces == 0.0)
    assert np.array_equal(result.velocities, problem.free_velocity)


def test_the_check_s_compiled_projection_is_the_numpy_one_to_the_bit(monkeypatch):
    """solve()'s check projects 2D cones with the compiled kernel: the same floating-point
    operations as Cones.project on every kind (mu = 0 included), inside, on the boundary, in the
    polar cone and beyond, and the same natural residual; 3D cones never reach the 2D kernel."""
    from lubcontact.problem.cones import Cones
    from lubcontact.solvers.compiled_modules import kernels
    from lubcontact.solvers.registry import compiled_projection

    kernels()                               # loaded, as after any compiled solve
    rng = np.random.default_rng(7)
    convex = [ConeKind.NONNEG, ConeKind.FREE, ConeKind.NONPOS, ConeKind.COULOMB]

    def random_case(tangent_dim):
        count = int(rng.integers(1, 12))
        kinds = rng.choice(np.array(convex, dtype=np.int8), size=count)
        mu = rng.choice([0.0, 0.3, 1.0, 2.5], size=count)
        tangential = np.flatnonzero((kinds == ConeKind.COULOMB) | (rng.random(count) < 0.3))
        cones = Cones(kinds=kinds, mu=mu, tangential=tangential, tangent_dim=tangent_dim)
        x = rng.normal(scale=3.0, size=cones.n_rows)
        x[rng.random(cones.n_rows) < 0.2] = 0.0                      # ties and zeros
        if tangent_dim == 1 and tangential.size:                    # one on the cone's edge
            c = rng.integers(tangential.size)
            x[count + c] = mu[tangential[c]] * x[tangential[c]]
        return cones, x

    for _ in range(100):
        cones, x = random_case(1)
        np.testing.assert_array_equal(compiled_projection(cones, x), cones.project(x))
        forces, gradient = cones.project(x), rng.normal(size=cones.n_rows)
        assert cones.natural_residual(forces, gradient, project=compiled_projection) \
            == cones.natural_residual(forces, gradient)

    def planar_only(*args):
        raise AssertionError("a 3D problem reached the 2D kernel")

    monkeypatch.setattr(kernels(), "project_cones", planar_only)
    for _ in range(20):
        cones, x = random_case(2)
        np.testing.assert_array_equal(compiled_projection(cones, x), cones.project(x))
