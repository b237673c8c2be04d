"""Condensed backend: lazy branches (multipliers only, u formed on demand), the MUMPS Schur
complement for S, reduced dense systems, batched displacements and the condensed SSNM."""

import numpy as np
import pytest
import scipy.sparse as sp
from petsc4py import PETSc

import cfcontact
from cfcontact import condensed, linalg, native
from cfcontact.condensed import CondensedSolver
from cfcontact.exact import canonical_codes
from cfcontact.lumped import one_node, random_system
from cfcontact.ssnm import DirNeuSolver, InactiveSets, SolverOptions


def keys(path, friction):
    return [canonical_codes(b.sets, friction).tolist() for b in path.branches]


@pytest.fixture(scope="module")
def systems():
    return [random_system(5, seed, friction=1.3, extra_dofs=4) for seed in range(3)]


def test_lazy_exact_path_equals_eager_path(systems, tmp_path):
    for k, system in enumerate(systems):
        solver = CondensedSolver(system)
        lazy = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver)
        eager = cfcontact.trace_path(system, 0.0, 1.0, method="exact", backend="full")  # DirNeuSolver: Y1, Y2 per branch
        assert lazy.status == eager.status == "completed"
        assert lazy.lazy and not eager.lazy
        assert keys(lazy, 1.3) == keys(eager, 1.3)
        # no displacement is needed for multiplicities and multiplier components
        solves = solver.stats.linear_solves
        (ml, al), (me, ae) = lazy.max_multiplicity(), eager.max_multiplicity()
        assert ml == me and abs(al - ae) <= 1e-10
        for a in np.linspace(0, 1, 7):
            assert lazy.multiplicity(a) == eager.multiplicity(a)
        comp = lazy.component(("lam_n", 1))
        assert lazy.lazy and solver.stats.linear_solves == solves
        assert np.allclose(comp, eager.component(("lam_n", 1)), rtol=0, atol=1e-10 * np.abs(comp).max())
        # residuals of every stored point without keeping u
        for alpha, y in lazy.iter_points(batch=3):
            assert cfcontact.verify(system, y, alpha, solver=solver).ok(1e-10)
        assert lazy.lazy
        # solutions_at forms only what it needs, equal to the eager path's
        for a in (0.1, 0.5, 0.9):
            s1, s2 = lazy.solutions_at(a), eager.solutions_at(a)
            assert len(s1) == len(s2)
            for x, y in zip(s1, s2):
                assert np.abs(x.y - y.y).max() <= 1e-10 * np.abs(y.y).max()
        # every point, and the saved file, equal the eager path's
        ys = lazy.ys
        assert not lazy.lazy
        assert np.abs(ys - eager.ys).max() <= 1e-10 * np.abs(eager.ys).max()
        back = cfcontact.SolutionPath.load(lazy.save(tmp_path / f"p{k}"))
        assert np.array_equal(back.ys, ys) and not back.lazy
        for b in lazy.branches:
            assert np.array_equal(back.branch_y(b.index, 0.3), lazy.branch_y(b.index, 0.3))


def test_lazy_points_by_index_and_save_before_forming(systems, tmp_path):
    system = systems[0]
    solver = CondensedSolver(system)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver)
    y_last = path._ys[-1]  # one point: formed on access
    assert y_last.shape == (system.n + 2 * system.m,)
    assert cfcontact.verify(system, y_last, path.alphas[-1], solver=solver).ok(1e-10)
    back = cfcontact.SolutionPath.load(path.save(tmp_path / "p"))  # save forms everything
    assert not path.lazy and np.array_equal(back.ys, path.ys)
    pts = list(path.iter_points(indices=[0, len(path.alphas) - 1]))
    assert len(pts) == 2 and np.array_equal(pts[1][1], path.ys[-1])


def test_exact_callback_sees_displacements_with_lazy_branches(systems):
    system = systems[1]
    seen = []
    cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=CondensedSolver(system),
                         callback=lambda p: seen.append(p) and False)
    assert seen
    for p in seen:
        assert cfcontact.verify(system, p.solution, p.alpha).ok(1e-10)


MUMPS = SolverOptions(solver_type="mumps")


def _envelope_or_petsc() -> str:
    """The default factorization of a small K on one rank: the envelope kernels, or PETSc's
    Cholesky without a C compiler (CFCONTACT_NATIVE=0)."""
    return "cholesky/envelope" if native.library() is not None else "cholesky/petsc"


@pytest.mark.parametrize("fem", [False, True])
def test_schur_complement_and_forward_substitutions_match_solves(fem):
    system = (cfcontact.two_blocks(nx=9, ny=3, friction=0.5, tractions1={"top1": (1e7, -1e8)},
                                   tractions2={"top1": (1e8, -1e7)}) if fem
              else random_system(4, 7, friction=0.8, extra_dofs=6))
    a, b = CondensedSolver(system, schur=True), CondensedSolver(system, options=MUMPS, schur=False)
    c = CondensedSolver(system)  # small and serial: K's envelope Cholesky, S from forward substitutions
    d = CondensedSolver(system, options=SolverOptions(solver_type="petsc"))  # the same with PETSc's Cholesky
    assert a.condensation == "schur" and b.condensation == "solves" and c.condensation == d.condensation == "forward"
    assert a.k_factorization == b.k_factorization == "lu/mumps"
    assert c.k_factorization == _envelope_or_petsc() and d.k_factorization == "cholesky/petsc"
    # the loads ride along (w1, w2 = B K^-1 f1,2 cached): by solves 2m + 4 columns in one solve call
    # (the exact method's two perturbation loads too), by forward substitutions 2m + 2 of them and
    # one backward substitution (the check); each solver first probes its solves' accuracy with one
    # refined solve (2 solves; no refinement needed here)
    assert all(s.refine_steps == 0 for s in (a, b, c, d))
    assert a.stats.linear_solves == 2 and b.stats.linear_solves == 2 * system.m + 6
    assert c.stats.linear_solves == d.stats.linear_solves == 2 * system.m + 5
    # independent reference: B K^-1 B^T and B K^-1 f by a dense SciPy solve
    K, N, T, f1, f2 = system.to_scipy()
    B = np.vstack([N.toarray(), T.toarray()])
    X = np.linalg.solve(K.toarray(), np.column_stack([B.T, f1, f2]))
    S_ref, W_ref = B @ X[:, :-2], B @ X[:, -2:]
    for s in (a, b, c, d):
        assert np.abs(s.S - S_ref).max() <= 1e-10 * np.abs(S_ref).max(), s.condensation
        assert np.abs(s.load_data_many([f1, f2]) - W_ref).max() <= 1e-10 * np.abs(W_ref).max(), s.condensation
    assert b.stats.linear_solves == 2 * system.m + 6 and c.stats.linear_solves == 2 * system.m + 5  # cached
    rng = np.random.default_rng(1)
    full = DirNeuSolver(system)
    for _ in range(5):
        Z = InactiveSets.from_states(rng.integers(0, 4, system.m))
        f = system.load(rng.uniform(0, 1))
        yf = full.solve(Z, f)
        for s in (a, c):
            assert np.abs(s.solve(Z, f) - yf).max() <= 1e-9 * np.abs(yf).max()


def test_s_by_solves_is_the_solves_own_so_formed_points_meet_their_gaps():
    """S by solves keeps its columns B K^-1 b_j as the solves give them (S^T kept beside it): the
    solve forming u = K^-1 (f - B^T lam) then agrees with B u = w - S lam.  On a slender strip
    (L/H = 10, m = 500) the SSNM start's closed nodes meet their gaps to 3e-12 of the multipliers;
    with S symmetrized it was 4e-11.  (Without refinement; refined solves give S corrected and
    symmetric, checked at the end.)"""
    from cfcontact.bench_stress import strip

    system = strip(500, 0.3, seed=0)
    # (MUMPS: by default this thin strip is factored by PETSc's Cholesky, S from forward substitutions)
    solver = CondensedSolver(system, SolverOptions(refine=False, solver_type="mumps"))
    assert solver.condensation == "solves" and not np.array_equal(solver.S, solver.S.T)
    assert np.array_equal(solver.St, solver.S.T) and solver.St.flags.c_contiguous
    sol = cfcontact.ssnm(system, 0.0, solver=solver)
    assert cfcontact.verify(system, sol, 0.0, solver=solver).worst() <= 1e-11
    # the sparse S products read S^T's rows: the same as S itself
    lam = np.zeros(2 * system.m)
    lam[[3, 70, 600]] = (1.0, -2.0, 0.5)
    w = solver.load_data(system.load(0.3))
    Slam = solver.S @ lam
    g = solver.indicators(lam, w)
    ref = lam + system.rho * (w - Slam)
    assert np.abs(g[:system.m] - ref[:system.m]).max() <= 1e-12 * np.abs(ref).max()
    refined = CondensedSolver(system, SolverOptions(refine=True))
    assert refined.refine_steps >= 1 and refined.St is refined.S
    sol = cfcontact.ssnm(system, 0.0, solver=refined)
    assert cfcontact.verify(system, sol, 0.0, solver=refined).worst() <= 1e-11


@pytest.mark.slow
def test_strip_at_high_friction_starts_frictionless_and_its_updates_are_refined_to_the_end():
    """The strip of Part D (L/H = 10, m = 500, uniform tractions) at F = 30: SSNM from 0 does not
    converge and the homotopy from the all-open state did not end in 120 s; from the frictionless
    solution the start takes a few transitions and the whole path completes.  Its branches come
    from updates of a kept factorization whose first solve can be 5 % off: every refinement
    correction is applied (the last one was once only measured, and left the closed nodes'
    gaps off by 2e-13 -- residuals up to 1.5e-7 of the multipliers, 35 points above 1e-9).  Every
    stored point meets (1)-(3) as with fresh factorizations: 1.5e-9 to 4.3e-9 (with the BLAS'
    summation order) while the transition points were extrapolated from either side, 7.2e-10
    since they are stored from the side that imposes the changing node's gap or slip (the floor
    rho |w| eps / |lam| is ~5e-10 per unit of rounding in the gaps for this strip)."""
    from cfcontact.bench_stress import strip

    system = strip(500, 30.0, seed=1, kind="uniform")
    solver = CondensedSolver(system)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver)
    assert path.status == "completed" and len(path.transitions) > 100
    assert path.stats["start"] == "frictionless" and path.stats["homotopy_transitions"] < 20
    assert solver.stats.dense_updates > 100  # the branches came from updates
    worst = max(cfcontact.verify(system, y, a, solver=solver).worst() for a, y in path.iter_points(128))
    assert worst <= 2e-9


def test_forward_substitutions_refuse_a_singular_K():
    # the third DOF is a rigid mode (zero row and column): a zero pivot in the Cholesky factor
    K = np.array([[2.0, 0.5, 0.0], [0.5, 1.0, 0.0], [0.0, 0.0, 0.0]])
    system = cfcontact.ContactSystem.from_arrays(K, [[0, 1, 1]], [[1, 0, 1]], [1, 1, 1], [1, 1, 1], 0.3)
    with pytest.raises(cfcontact.SingularSystemError, match="singular"):
        CondensedSolver(system)
    # nearly singular: a soft spring of 1e-15 relative stiffness on the free DOF
    K[2, 2] = 1e-15
    system = cfcontact.ContactSystem.from_arrays(K, [[0, 1, 1]], [[1, 0, 1]], [1, 1, 1], [1, 1, 1], 0.3)
    with pytest.raises(cfcontact.SingularSystemError, match="condition number"):
        CondensedSolver(system)


def test_solver_type_selects_the_factorization_of_K(monkeypatch):
    """Small or thin K on one rank: the envelope Cholesky (compiled), or PETSc's when solver_type
    says so, when the user set options for K's solver, or without the compiled kernels; wider
    bands: MUMPS."""
    system = random_system(4, 3, friction=0.8, extra_dofs=6)
    assert CondensedSolver(system).k_factorization == _envelope_or_petsc()
    petsc = CondensedSolver(system, options=SolverOptions(solver_type="petsc"))
    assert petsc.k_factorization == "cholesky/petsc" and petsc.condensation == "forward"
    assert CondensedSolver(system, options=MUMPS).k_factorization == "lu/mumps"
    opts = PETSc.Options()
    opts["cfcontact_K_pc_factor_ordering_type"] = "nd"
    try:
        assert CondensedSolver(system).k_factorization == "cholesky/petsc"
    finally:
        opts.delValue("cfcontact_K_pc_factor_ordering_type")
    with monkeypatch.context() as mp:
        mp.setattr(native, "_tried", True)
        mp.setattr(native, "_lib", None)
        assert CondensedSolver(system).k_factorization == "cholesky/petsc"
    monkeypatch.setattr(condensed, "NATIVE_MAX_DOFS", system.n - 1)  # above the limit: K's envelope decides
    per_dof = linalg.rcm_envelope(linalg.local_csr(system.K)) / system.n
    monkeypatch.setattr(condensed, "NATIVE_ENVELOPE_PER_DOF", per_dof)
    calls = []
    rcm_order = linalg.rcm_order
    monkeypatch.setattr(linalg, "rcm_order", lambda A: calls.append(1) or rcm_order(A))
    thin = CondensedSolver(system)
    assert thin.k_factorization == _envelope_or_petsc()
    assert len(calls) == 1  # the order that chose the factorization is the envelope factor's
    if thin._envelope is not None:
        assert np.array_equal(thin._envelope.perm, rcm_order(linalg.local_csr(system.K)))
    monkeypatch.setattr(condensed, "NATIVE_ENVELOPE_PER_DOF", 0.99 * per_dof)  # a wider band: MUMPS
    assert CondensedSolver(system).k_factorization == "lu/mumps"


@pytest.mark.parametrize("friction", [0.3, 30.0])
def test_exact_paths_with_the_envelope_and_with_petscs_cholesky_agree(friction):
    """The exact path of two blocks (FEM, n = 240, 14 and 22 transitions) with K factored by the
    envelope kernels and by PETSc's Cholesky: the same set changes, transition alpha to rounding,
    both verified."""
    from cfcontact.report import worst_residual

    system = cfcontact.two_blocks(nx=12, ny=4, friction=friction, tractions1={"top1": (3e7, -1e8)},
                                  tractions2={"top1": (-1e8, -2e7)})
    paths = []
    for opts in (None, SolverOptions(solver_type="petsc")):
        solver = CondensedSolver(system, opts)
        paths.append(cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver))
        assert paths[-1].status == "completed" and worst_residual(system, paths[-1], solver) < 1e-10
    a, b = paths
    assert len(a.transitions) >= 5
    assert [(t.node, t.set, t.kind) for t in a.transitions] == [(t.node, t.set, t.kind) for t in b.transitions]
    np.testing.assert_allclose([t.alpha for t in a.transitions], [t.alpha for t in b.transitions], rtol=1e-9,
                               atol=1e-12)


def test_the_envelope_factorization_records_that_K_is_positive_definite(kernels, monkeypatch):
    """Every pivot of the envelope Cholesky factor positive: the system keeps the inertia (0, 0, n)
    and checks K before tracing without a factorization of its own (skipped without the compiled
    kernels: PETSc factors K then)."""
    system = random_system(4, 3, friction=0.8, extra_dofs=6)
    monkeypatch.setattr(linalg, "inertia", lambda A: pytest.fail("K factored again for its inertia"))
    assert CondensedSolver(system).k_factorization == "cholesky/envelope"
    assert system.inertia() == (0, 0, system.n)
    system.check_positive_definite()
    with pytest.raises(cfcontact.InputError, match="counts n = "):
        system.record_inertia((0, 0, system.n + 1))


def test_rcm_envelope_is_the_size_of_petscs_cholesky_factor():
    """The envelope that chooses K's factorization: 2n - 1 for a tridiagonal matrix (any
    numbering of a chain), and within a few per cent of the entries of PETSc's own Cholesky factor
    in RCM order on a mesh (the orderings' start nodes may differ); a long strip's envelope per
    DOF does not grow with its length, a square's does."""
    from petsc4py import PETSc

    from cfcontact.bench_stress import strip
    from cfcontact.demo_models import build_blocks

    n = 50
    perm = np.random.default_rng(3).permutation(n)
    T = sp.diags([np.full(n - 1, -1.0), np.full(n, 2.0), np.full(n - 1, -1.0)], [-1, 0, 1]).tocsr()
    assert linalg.rcm_envelope(T[perm][:, perm]) == 2 * n - 1
    system = build_blocks(0.3, nx=45, ny=15)
    ksp = PETSc.KSP().create()
    ksp.setOperators(system.K)
    ksp.setType("preonly")
    ksp.getPC().setType("cholesky")
    ksp.getPC().setFactorOrdering("rcm")
    ksp.setUp()
    nz = ksp.getPC().getFactorMatrix().getInfo()["nz_used"]
    env = linalg.rcm_envelope(linalg.local_csr(system.K))
    assert abs(env - nz) <= 0.05 * nz, (env, nz)
    ksp.destroy()
    per_dof = [linalg.rcm_envelope(linalg.local_csr(s.K)) / s.n for s in (strip(100, 0.3), strip(400, 0.3))]
    assert abs(per_dof[1] - per_dof[0]) <= 0.05 * per_dof[0] and per_dof[0] < condensed.NATIVE_ENVELOPE_PER_DOF
    assert env / system.n > condensed.NATIVE_ENVELOPE_PER_DOF


def test_schur_needs_interior_dofs_and_falls_back():
    system = one_node(2.5)  # every DOF is a contact DOF: no Schur complement, S by solves
    assert CondensedSolver(system, options=MUMPS).condensation == "solves"
    assert CondensedSolver(system).condensation == "forward"
    with pytest.raises(cfcontact.InputError):
        CondensedSolver(system, schur=True)


def test_reduced_multipliers_and_batched_displacements():
    system = random_system(5, 3, friction=[0.0, 0.4, 1.1, 2.0, 0.7], extra_dofs=3)
    solver = CondensedSolver(system)
    f1, f2 = system.loads_numpy()
    w = solver.load_data(f1)
    rng = np.random.default_rng(5)
    lams, alphas = [], []
    for _ in range(10):
        Z = InactiveSets(rng.random(5) < 0.3, rng.random(5) < 0.4, rng.random(5) < 0.4)
        lam = solver.multipliers(Z, w)
        ref = np.linalg.solve(solver.matrix(Z), solver.rhs(Z, w))  # the full 2m x 2m form
        assert np.abs(lam - ref).max() <= 1e-10 * max(np.abs(ref).max(), 1e-300)
        lams.append(lam)
        alphas.append(rng.uniform(-0.5, 1.5))
    U = solver.displacements(np.column_stack(lams), alphas)
    for j, (lam, a) in enumerate(zip(lams, alphas)):
        u = solver.displacement(system.load(a), lam)
        assert np.abs(U[:, j] - u).max() <= 1e-12 * np.abs(u).max()


def test_condensed_ssnm_matches_full_ssnm(systems):
    for system in systems:
        for a in (0.0, 0.4, 1.0):
            sc = cfcontact.ssnm(system, a, solver=CondensedSolver(system))
            sf = cfcontact.ssnm(system, a, solver=DirNeuSolver(system))
            assert np.abs(sc.y - sf.y).max() <= 1e-10 * np.abs(sf.y).max()
            assert sc.sets.equivalent(sf.sets, system.friction)


def test_plotting_a_multiplier_forms_no_displacement(systems, tmp_path):
    """Plots of multiplier components (the default) read the branches' multipliers only; the
    values equal those of the eagerly formed path."""
    from cfcontact import plotting

    system = systems[0]
    solver = CondensedSolver(system)
    lazy = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver)
    eager = cfcontact.trace_path(system, 0.0, 1.0, method="exact", backend="full")
    solves = solver.stats.linear_solves
    assert plotting.default_component(lazy) == plotting.default_component(eager)
    a, v, _ = plotting.path_curve(lazy)
    ae, ve, _ = plotting.path_curve(eager)
    np.testing.assert_allclose(a, ae, rtol=0, atol=1e-12)
    np.testing.assert_allclose(v, ve, rtol=0, atol=1e-10 * np.abs(ve).max())
    plotting.save_figure(plotting.plot_path(lazy), str(tmp_path / "p.png"))
    assert (tmp_path / "p.png").stat().st_size > 0
    assert lazy.lazy and solver.stats.linear_solves == solves  # nothing formed
    np.testing.assert_allclose(lazy.lams, eager.ys[:, system.n:], rtol=0, atol=1e-10 * np.abs(ve).max())


def test_ssnm_sets_equal_ssnm_from_zero(systems):
    """The exact method's start (sets of SSNM from 0 in the multipliers, no u) is the start of
    the seed's SSNM with the J(Z) solver; an SSNM that does not converge gives None."""
    for system in systems:
        solver = CondensedSolver(system)
        for alpha in (0.0, 0.4, 1.0):
            ref = cfcontact.ssnm(system, alpha, solver=DirNeuSolver(system))
            Z = solver.ssnm_sets(system.load(alpha), 1e-9, 100)
            assert Z is not None and Z.states() == ref.sets.states()
        assert solver.ssnm_sets(system.load(0.5), 1e-300, 1) is None


def test_schur_complement_calls_are_found_by_feature_detection():
    """petsc4py does not wrap MatFactorSetSchurIS / MatFactorGetSchurComplement: cfcontact.compat_petsc
    finds them through petsc4py's extension module (no scan of the process's mappings), here on
    every supported PETSc; a factor matrix without a Schur request gives no Schur complement."""
    from petsc4py import PETSc

    from cfcontact import compat_petsc

    assert compat_petsc.schur_complement_available()
    K = PETSc.Mat().createAIJ((3, 3), comm=PETSc.COMM_SELF)
    K.setUp()
    for i in range(3):
        K.setValue(i, i, 2.0)
    K.assemble()
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOperators(K)
    ksp.setType("preonly")
    ksp.getPC().setType("lu")
    ksp.getPC().setFactorSolverType("mumps")
    ksp.getPC().setFactorSetUpSolverType()
    compat_petsc.factor_set_schur_is(ksp.getPC().getFactorMatrix(), [1, 2])
    ksp.setUp()
    Sc = compat_petsc.factor_schur_complement(ksp.getPC().getFactorMatrix(), 2)
    np.testing.assert_allclose(Sc, 2.0 * np.eye(2))


def test_a_branch_that_unloads_to_zero_is_saved_exact_at_its_exit(tmp_path):
    """A cylinder pressed in and released (the top's displacement from 0.01 back to 0, alpha from
    1 to 0): the last branch ends at zero load, where every quantity vanishes.  Its stored chord was
    referenced at its entry, so the saved path's last points were the entry's rounding (1e-16 of
    the entry's multipliers), no solution at their own size: residual 0.16 (equal materials) and
    2e-5 (a stiff block).  Referenced at the smaller end, the saved points verify like the path's
    own."""
    from cfcontact.models import cylinder_on_block
    from cfcontact.solution_path import SolutionPath
    from cfcontact.ssnm import verify

    models = [cylinder_on_block(size=0.08, size_far=0.5, friction=0.6, E=E,
                                dirichlet={"top1": {"x": (0.0, 0.0), "y": (0.0, -0.01)}})
              for E in (2.1e11, {"body1": 2.1e9, "body2": 2.1e13})]
    # with an initial gap the contact opens first (alpha = 0.2): the last branch is open, lam = 0 at
    # both of its ends, and is referenced by its relative displacements (residual 0.25 before)
    models.append(cylinder_on_block(size=0.08, size_far=0.5, friction=0.3, gap0=0.001, half=True))
    for E, system in zip(("steel", "stiff block", "gap"), models):
        path = cfcontact.trace_path(system, 1.0, 0.0, method="exact")
        assert path.status == "completed" and path.transitions and path.alphas[-1] == 0.0
        path.save(tmp_path / "path")
        saved = SolutionPath.load(tmp_path / "path")
        for live, (a, y) in zip(path.iter_points(), saved.iter_points()):
            assert a == live[0]
            assert verify(system, live[1], a).worst() < 1e-12
            assert verify(system, y, a).worst() < 1e-12, (E, a)


@pytest.mark.parametrize("backend", ["condensed", "full"])
def test_a_path_to_zero_load_ends_there_without_transitions_of_rounding(backend, tmp_path):
    """f1 = 0: on a branch that reaches alpha = 0 every quantity is proportional to alpha, so every
    constraint vanishes there, rounded to either side.  The roots just inside the range were taken
    as transitions, which cascaded (alpha = 2e-82, 2e-150, 0), each stored point the rounding of
    its branch's entry (residuals up to 0.85).  A root within its uncertainty of the range's end is
    the end; the end point is solved for, not extrapolated, on both backends (an open branch too)."""
    from cfcontact.models import two_blocks
    from cfcontact.solution_path import SolutionPath
    from cfcontact.ssnm import verify

    for ty in (-5e7, 5e7):  # pressed (closed and slipping nodes), lifted (every node open)
        system = two_blocks(nx=8, ny=3, friction=0.5, tractions1={}, tractions2={"top1": (3e7, ty)})
        path = cfcontact.trace_path(system, 0.7, 0.0, method="exact", backend=backend)
        assert path.status == "completed" and not path.transitions
        assert list(path.alphas) == [0.7, 0.0]
        saved = SolutionPath.load(path.save(tmp_path / f"p{ty}"))
        for a, y in saved.iter_points():
            assert verify(system, y, a).worst() < 1e-12, (ty, a)
        assert np.abs(saved.ys[-1]).max() < 1e-20  # the solution at zero load is zero
