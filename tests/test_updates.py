"""Factorization updates of the exact method's branches (condensed backend, issue #13).

The updated solves (one kept factorization, Sherman-Morrison-Woodbury on the rows of the nodes
whose state differs) are compared with fresh factorizations: branch by branch on long random
walks through the state codes (single and multiple node changes, refactorizations forced by a
small rank limit), and path by path (the same sequence of set changes, the same transition
points) on systems with degenerate points and folds.  A callback that reads only alpha and the
path forms no displacement."""

import numpy as np
import pytest
import scipy.linalg as sla

import cfcontact
from cfcontact import condensed
from cfcontact.condensed import CondensedSolver, _Updater
from cfcontact.exact import OPEN, SLIP_M, SLIP_P, STICK, canonical_codes
from cfcontact.lumped import random_system
from cfcontact.ssnm import SolverOptions
from cfcontact.system import ContactSystem


def fresh(solver, codes, W):
    """(lam, g) of the reduced system factored afresh (no updates): the reference."""
    key = b"ref:" + codes.tobytes()
    lam = solver.multipliers_many(None, W, key=key, codes=codes)
    return lam, solver.indicators(lam, W, support=solver._lu[key][5])


def random_walk(rng, m, F0, steps):
    """State codes visited by a walk that changes one node (sometimes two or three) per step."""
    codes = rng.choice([OPEN, STICK, SLIP_P, SLIP_M], size=m).astype(np.int8)
    out = []
    for _ in range(steps):
        k = rng.choice([1, 1, 1, 2, 3])
        for i in rng.choice(m, size=k, replace=False):
            codes[i] = rng.choice([OPEN, STICK, SLIP_P, SLIP_M])
        codes = np.where((codes != OPEN) & F0, SLIP_P, codes).astype(np.int8)
        out.append(codes.copy())
    return out


@pytest.mark.parametrize("max_rank, m", [(3, 40), (12, 40), (None, 40), (None, 210)])
def test_updated_branches_equal_fresh_factorizations(max_rank, m):
    """m = 210: 2m >= COLUMNWISE_MIN_ROWS, the products and solves go column by column."""
    rng = np.random.default_rng(7)
    friction = np.where(rng.random(m) < 0.1, 0.0, rng.uniform(0.2, 3.0, m))
    system = random_system(m, 3, friction=friction, extra_dofs=10)
    ref = CondensedSolver(system, SolverOptions(updates=False))
    upd = CondensedSolver(system, SolverOptions(updates=True))
    upd._updater = _Updater(upd, max_rank=max_rank)
    W = ref.load_data_many(list(system.loads_numpy()))
    F0 = system.friction_vector == 0.0
    for codes in random_walk(rng, m, F0, 150):
        lam_ref, g_ref = fresh(ref, codes, W)
        lam, g, eg = upd.branch_data(W, b"", codes, refine=True)
        scale = np.abs(lam_ref).max()
        assert np.abs(lam - lam_ref).max() <= 1e-9 * scale
        assert np.abs(g - g_ref).max() <= 1e-9 * np.abs(g_ref).max()
        assert eg.shape == g.shape and np.all(np.isfinite(eg))
    st = upd.stats.as_dict()
    assert st["dense_updates"] == 150
    if max_rank == 3:  # walks of 150 steps leave a rank-3 neighbourhood often: refactorizations
        assert upd._updater.refactorizations > 5
    else:  # (random states often make M(Z) near singular, where the refinement refactors: 77 of
        # 150 branches at m = 210; 91 before the column-wise solves)
        assert upd._updater.refactorizations < (40 if m == 40 else 100)


def test_the_updates_refactor_when_they_have_cost_a_refactorization(monkeypatch):
    """The rebase rule: a branch refactors the kept base once the updates since the last
    refactorization have cost (by UPDATE_NODE_COST per changed node and contact node) what one
    costs; made expensive here, the rule refactors often (reason "cost"), made free it never does,
    and the branches equal fresh factorizations either way."""
    m = 60
    rng = np.random.default_rng(11)
    system = random_system(m, 3, friction=rng.uniform(0.2, 3.0, m), extra_dofs=10)
    ref = CondensedSolver(system, SolverOptions(updates=False))
    W = ref.load_data_many(list(system.loads_numpy()))
    walk = random_walk(rng, m, np.zeros(m, dtype=bool), 60)
    counts = {}
    for cost in (1e-3, 0.0):
        monkeypatch.setattr(condensed, "UPDATE_NODE_COST", cost)
        monkeypatch.setattr(condensed, "UPDATE_FLOP_COST", 0.0 if cost == 0.0 else 2.8e-11)
        upd = CondensedSolver(system, SolverOptions(updates=True))
        upd._updater = _Updater(upd, max_rank=400)
        for codes in walk:
            lam_ref, g_ref = fresh(ref, codes, W)
            lam, g, _ = upd.branch_data(W, b"", codes, refine=True)
            assert np.abs(lam - lam_ref).max() <= 1e-9 * np.abs(lam_ref).max()
            assert np.abs(g - g_ref).max() <= 1e-9 * np.abs(g_ref).max()
        counts[cost] = upd._updater.reasons.get("cost", 0)
    assert counts[1e-3] >= 20 and counts[0.0] == 0


@pytest.mark.parametrize("n", [50, 450])
def test_columnwise_products_and_solves_equal_blas_ones(n):
    """_times and _lu_solve (column by column from COLUMNWISE_MIN_ROWS rows on) give A X and
    A^-1 X, A^-T X to rounding for 1 to 4 columns and vectors."""
    rng = np.random.default_rng(3)
    A = rng.standard_normal((n, n)) + n * np.eye(n)
    lu, piv, _ = sla.lapack.dgetrf(A)
    for c in (None, 1, 2, 3, 4):
        X = rng.standard_normal(n if c is None else (n, c))
        assert np.allclose(condensed._times(A, X), A @ X, rtol=0, atol=1e-12 * np.abs(A).max() * n)
        assert np.allclose(condensed._times(A.T, X), A.T @ X, rtol=0, atol=1e-12 * np.abs(A).max() * n)
        for trans, Ar in ((0, A), (1, A.T)):
            Y = condensed._lu_solve(lu, piv, X, trans=trans)
            assert Y.shape == X.shape
            assert np.abs(Ar @ Y - X).max() <= 1e-12 * np.abs(X).max() * n


def test_dense_factorization_cache_stays_within_its_byte_budget(monkeypatch):
    """The reduced systems' LUs are cached within DENSE_CACHE_BYTES (newest kept): 20 set
    combinations under a budget of three LUs keep at most three, and a dropped one is factored
    again with the same result."""
    rng = np.random.default_rng(5)
    m = 20
    system = random_system(m, 3, friction=0.7, extra_dofs=10)
    solver = CondensedSolver(system, SolverOptions(updates=False))
    W = solver.load_data_many(list(system.loads_numpy()))
    monkeypatch.setattr(condensed, "DENSE_CACHE_BYTES", 3 * 8 * (2 * m) ** 2)
    walk = random_walk(rng, m, np.zeros(m, dtype=bool), 20)
    first = fresh(solver, walk[0], W)[0]
    for codes in walk[1:]:
        fresh(solver, codes, W)
        assert sum(e[0].nbytes for e in solver._lu.values()) <= condensed.DENSE_CACHE_BYTES
        assert list(solver._lu)[-1] == b"ref:" + codes.tobytes()
    assert b"ref:" + walk[0].tobytes() not in solver._lu
    n0 = solver.stats.dense_factorizations
    np.testing.assert_array_equal(fresh(solver, walk[0], W)[0], first)
    assert solver.stats.dense_factorizations == n0 + 1


@pytest.mark.parametrize("updates, kernel_rows", [(True, None), (False, 0), (False, 10 ** 9)])
def test_singular_sets_are_reported_by_the_updates_too(updates, kernel_rows, monkeypatch, request):
    """A node pair with identical rows in S makes some sets singular: every way says so (updates,
    fresh LAPACK factorizations, the compiled branch kernel)."""
    if kernel_rows:
        request.getfixturevalue("kernels")  # (skipped without them)
    if kernel_rows is not None:
        monkeypatch.setattr(condensed, "BRANCH_KERNEL_MAX_ROWS", kernel_rows)
    rng = np.random.default_rng(1)
    m = 30
    A = rng.standard_normal((2 * m, 2 * m))
    K = A @ A.T + 2 * m * np.eye(2 * m)
    B = np.eye(2 * m)
    N, T = B[:m].copy(), B[m:].copy()
    N[1] = N[0]  # node 1 measures node 0's gap: closing both is singular
    system = ContactSystem.from_arrays(K, N, T, rng.standard_normal(2 * m), rng.standard_normal(2 * m), 0.5)
    upd = CondensedSolver(system, SolverOptions(updates=updates))
    W = upd.load_data_many(list(system.loads_numpy()))
    codes = np.full(m, OPEN, dtype=np.int8)
    codes[0] = STICK
    upd.branch_data(W, b"", codes, refine=True)  # regular
    codes[1] = STICK
    with pytest.raises(cfcontact.SingularSystemError, match="singular"):
        upd.branch_data(W, codes.tobytes(), codes, refine=True)
    if kernel_rows:
        assert upd._kernel is not None


def _chain(m, F, seed, copies=1):
    """A lumped model of m contact nodes with nearest-neighbour elastic coupling, several
    identical copies (block diagonal: exact ties between the copies' transitions)."""
    rng = np.random.default_rng(seed)
    n1 = 2 * m
    K1 = np.zeros((n1, n1))
    for i in range(m):
        K1[2 * i:2 * i + 2, 2 * i:2 * i + 2] += [[1.0, 0.6], [0.6, 1.0]]
        if i + 1 < m:
            for c in (0, 1):
                a, b = 2 * i + c, 2 * (i + 1) + c
                K1[a, a] += 0.5
                K1[b, b] += 0.5
                K1[a, b] -= 0.5
                K1[b, a] -= 0.5
    f1 = np.tile([0.3, 1.0], m) + 0.05 * rng.standard_normal(n1)
    f2 = np.tile([1.0, 0.2], m) + 0.05 * rng.standard_normal(n1)
    K = sla.block_diag(*([K1] * copies))
    M = m * copies
    N = np.zeros((M, 2 * M))
    T = np.zeros((M, 2 * M))
    for i in range(M):
        T[i, 2 * i], N[i, 2 * i + 1] = 1.0, 1.0
    return ContactSystem.from_arrays(K, N, T, np.tile(f1, copies), np.tile(f2, copies), F)


def _same_paths(a, b):
    assert a.status == b.status
    assert [(t.node, t.set, t.kind) for t in a.transitions] == [(t.node, t.set, t.kind) for t in b.transitions]
    assert np.allclose([t.alpha for t in a.transitions], [t.alpha for t in b.transitions], rtol=1e-10, atol=1e-12)
    assert [canonical_codes(x.sets, a.friction).tolist() for x in a.branches] == \
        [canonical_codes(x.sets, b.friction).tolist() for x in b.branches]


@pytest.mark.parametrize("friction, copies, m, columnwise, first", [
    (0.5, 1, 90, False, True), (2.7, 1, 16, False, True), (2.7, 2, 16, False, True), (2.7, 2, 16, True, True),
    (0.5, 1, 90, False, False), (2.7, 2, 16, False, False)])
def test_paths_with_updates_equal_paths_without(friction, copies, m, columnwise, first, monkeypatch):
    """Long paths (folds at F = 2.7, above the chain's critical friction; exact ties between the
    copies' transitions: degenerate points) are the same with and without updates.
    ``columnwise``: every product and solve with 2-3 columns goes column by column (products with
    two by the compiled kernel), as on large interfaces.  ``first``: an updated first solve within
    UPDATE_FIRST_RTOL is taken after one correction (else, UPDATE_FIRST_RTOL = 0, every branch's
    refinement measures a second correction, left unapplied at rounding level)."""
    if columnwise:
        monkeypatch.setattr(condensed, "COLUMNWISE_MIN_ROWS", 1)
    if not first:
        monkeypatch.setattr(condensed, "UPDATE_FIRST_RTOL", 0.0)
    system = _chain(m // copies, friction, 5, copies)
    paths = {}
    for updates in (True, False):
        solver = CondensedSolver(system, SolverOptions(updates=updates))
        paths[updates] = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver)
        if updates:
            assert solver.stats.dense_updates > 0
            assert solver._updater.refactorizations < solver.stats.dense_updates
            # the refinement ended early: first solves within UPDATE_FIRST_RTOL corrected once (all
            # but 0-3 branches here), else last corrections at rounding level measured, not applied
            # (62 of 139 branches at F = 2.7, m = 16; most at F = 0.5)
            u = solver._updater
            if first:
                assert u.first_accepted > 0.9 * solver.stats.dense_updates
            else:
                assert u.first_accepted < 0.05 * solver.stats.dense_updates  # (exactly zero corrections)
                assert u.unapplied > solver.stats.dense_updates // 4
    _same_paths(paths[True], paths[False])
    p = paths[True]
    assert p.status == "completed" and len(p.transitions) > 50
    if friction > 1:
        assert p.folds
    if copies > 1:
        assert p.stats["degenerate_points"] > 0
    for i in range(0, len(p.transitions), max(1, len(p.transitions) // 10)):
        t = p.transitions[i]
        for b in (t.from_branch, t.to_branch):
            assert cfcontact.verify(system, p.branch_y(b, t.alpha), t.alpha).ok(1e-9)


def test_a_callback_reading_alpha_forms_no_displacement():
    system = random_system(6, 2, friction=1.0)
    base = CondensedSolver(system)
    cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=base)
    seen = []
    solver = CondensedSolver(system)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver,
                                callback=lambda pt: seen.append((pt.alpha, len(pt.path.transitions))))
    assert len(seen) == len(path.transitions) + 2  # the start, each branch's entry, the end
    assert solver.stats.linear_solves == base.stats.linear_solves  # no solve with K for the callback
    # asking for the solution forms it
    got = []
    cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=CondensedSolver(system),
                         callback=lambda pt: got.append(cfcontact.verify(system, pt.solution, pt.alpha).worst()))
    assert max(got) <= 1e-10


@pytest.mark.slow
def test_updates_near_singular_branches_keep_the_path():
    """Strip with m = 150 at F = 30 (Part C's model): its path runs through branches 3e-7 long
    between folds, where an updated solve was 1e6 times less accurate than a fresh LU; its wide
    rounding bounds merged four separate roots into one degenerate point, and the path went into
    a branch that violated four nodes' conditions (ending 'cycling' at 17 016 transitions).  The
    updater now refactors such branches: the same transitions as without updates."""
    from cfcontact.bench_stress import strip

    system = strip(150, 30.0, seed=0)
    paths = {}
    for updates in (True, False):
        solver = CondensedSolver(system, options=SolverOptions(updates=updates))
        paths[updates] = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver,
                                              max_transitions=17100)
    a, b = paths[True], paths[False]
    assert a.status == b.status == "max_transitions", (a.status, a.events[-1:])
    assert [(t.node, t.set, t.kind) for t in a.transitions] == [(t.node, t.set, t.kind) for t in b.transitions]
    ta, tb = np.array([t.alpha for t in a.transitions]), np.array([t.alpha for t in b.transitions])
    assert np.abs(ta - tb).max() <= 1e-10 * np.abs(tb).max()
    assert (a.transitions[17000].node, a.transitions[17000].set) == (82, "nu")


def _point_setup(system, rng):
    """(solver without updates, W = the loads' data and two random columns, the F = 0 mask, 15
    random nodes of a degenerate point, every node closed: slipping at F = 0, else sticking)."""
    m = system.m
    solver = CondensedSolver(system, SolverOptions(updates=False))
    W = np.column_stack([solver.load_data_many(list(system.loads_numpy())), rng.standard_normal((2 * m, 2))])
    F0 = system.friction_vector == 0.0
    nodes = np.sort(rng.choice(m, size=15, replace=False))
    return solver, W, F0, nodes, np.where(F0, SLIP_P, STICK).astype(np.int8)


def test_point_model_equals_fresh_solves():
    """The point model of a degenerate point (rank-2 updates, one node's state at a time, from a
    first branch) gives the multipliers of a fresh factorization on a long random walk through
    the states of its nodes; a change of a node outside it is refused (None)."""
    from cfcontact.condensed import PointModel

    rng = np.random.default_rng(11)
    m = 40
    friction = np.where(rng.random(m) < 0.1, 0.0, rng.uniform(0.2, 3.0, m))
    system = random_system(m, 5, friction=friction, extra_dofs=10)
    solver, W, F0, nodes, codes = _point_setup(system, rng)
    model = PointModel(solver, codes, W, nodes)
    for step in range(200):
        i = int(rng.choice(nodes))
        codes = codes.copy()
        codes[i] = SLIP_P if F0[i] and codes[i] == OPEN else (OPEN if F0[i] else rng.choice(
            [c for c in (OPEN, STICK, SLIP_P, SLIP_M) if c != codes[i]]))
        X, SX = model.move_to(codes)
        lam_ref, _ = fresh(solver, codes, W)
        assert np.abs(X - lam_ref).max() <= 1e-10 * np.abs(lam_ref).max(), step
        np.testing.assert_allclose(SX, solver.S @ X, rtol=0, atol=1e-12 * np.abs(solver.S @ X).max())
    assert model.updates > 150
    outside = codes.copy()
    j = int(np.setdiff1d(np.arange(m), nodes)[0])
    outside[j] = OPEN if outside[j] != OPEN else (SLIP_P if F0[j] else STICK)
    assert model.move_to(outside) is None


def test_point_tableau_equals_fresh_solves():
    """The tableau of a degenerate point (its nodes' indicators for the columns of W, rank-one
    and rank-two updates per state change) gives the indicators of a fresh factorization at
    those nodes on a long random walk through their states, nodes with F = 0 and without a
    tangential unknown included; the compiled update and indicators (cfcontact.native) give
    those of the NumPy/BLAS form to rounding at every step (without the kernels -- CFCONTACT_NATIVE=0
    or no C compiler -- both are that form)."""
    from cfcontact import native
    from cfcontact.condensed import PointTableau

    rng = np.random.default_rng(12)
    m = 40
    friction = np.where(rng.random(m) < 0.1, 0.0, rng.uniform(0.2, 3.0, m))
    nt = rng.random(m) < 0.1  # nodes without a tangential unknown (their rows of T vanish)
    n = 2 * m + 10
    A = rng.standard_normal((n, n))
    N, T = np.zeros((m, n)), np.zeros((m, n))
    N[np.arange(m), 2 * np.arange(m) + 1] = 1.0
    T[np.arange(m), 2 * np.arange(m)] = np.where(nt, 0.0, 1.0)
    f1, f2 = rng.standard_normal(n), rng.standard_normal(n)
    system = ContactSystem.from_arrays(A @ A.T / n + np.eye(n), N, T, f1, f2, friction)
    assert np.array_equal(system.no_tangent, nt)
    solver, W, F0, nodes, codes = _point_setup(system, rng)
    tab = PointTableau(solver, codes, W, nodes)
    assert (tab._lib is not None) == (native.library() is not None)  # (the compiled kernels; the twin: without)
    twin = PointTableau(solver, codes, W, nodes)
    twin._lib = None
    ranks = set()
    for step in range(300):
        j = int(rng.integers(nodes.size))
        i = int(nodes[j])
        old = int(codes[i])
        choices = (OPEN, STICK) if nt[i] else (OPEN, SLIP_P) if F0[i] else (OPEN, STICK, SLIP_P, SLIP_M)
        new = int(rng.choice([c for c in choices if c != old]))
        before = tab.A.copy()
        assert tab.change(j, old, new)
        assert twin.change(j, old, new)
        assert np.abs(tab.A - twin.A).max() <= 1e-12 * np.abs(twin.A).max(), step
        ranks.add(int(np.linalg.matrix_rank(tab.A - before, tol=1e-12 * np.abs(before).max())))
        codes = codes.copy()
        codes[i] = new
        _, g_ref = fresh(solver, codes, W)
        got = tab.indicators()  # 3k x p, node by node
        ref = g_ref.reshape(3, m, -1)[:, nodes].transpose(1, 0, 2).reshape(3 * nodes.size, -1)
        assert np.abs(got - ref).max() <= 1e-9 * np.abs(ref).max(), step
        assert np.abs(got - twin.indicators()).max() <= 1e-12 * np.abs(ref).max(), step
    assert tab.updates == twin.updates == 300 and ranks == {1, 2}


@pytest.mark.parametrize("friction, updates", [(0.5, True), (2.0, False),
                                               pytest.param(2.0, True, marks=pytest.mark.slow)])
def test_paths_with_point_model_equal_paths_without(friction, updates, monkeypatch):
    """Four identical chains (m = 100): the transitions of one are degenerate points of four
    nodes (at F = 2.0 with folds, the copies partly separated), crossed by pivots whose
    intermediate branches come from the point model from the third on.  The path is the same as
    with a fresh solve per pivot, pivot by pivot (each run with a new solver: the updates' kept
    factorization has a history)."""
    import cfcontact.exact as exact

    system = _chain(25, friction, 5, 4)
    paths = {}
    for use in (True, False):
        monkeypatch.setattr(exact, "POINT_MODEL_MIN_SIZE", 160 if use else 10 ** 9)
        solver = CondensedSolver(system, SolverOptions(updates=updates))
        paths[use] = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver)
    assert paths[True].stats["point_updates"] > 20 and paths[False].stats["point_updates"] == 0
    _same_paths(paths[True], paths[False])
    assert [t.pivots for t in paths[True].transitions] == [t.pivots for t in paths[False].transitions]
    assert paths[True].stats["degenerate_points"] > 10


@pytest.mark.parametrize("model", ["chain", "closing", "fallback"])
def test_paths_with_point_tableau_equal_paths_without(model, monkeypatch):
    """Degenerate points of many nodes are crossed on the point's tableau (one rank-one or
    rank-two update of the nodes' rows per pivot): sixteen identical chains (every transition a
    point of 16 nodes), and two FEM blocks whose whole interface (24 nodes) closes at one alpha.
    The path is the same as with a solve per pivot, pivot by pivot.  "fallback": the check of
    every walk's leaving branch is made to fail, so each point is crossed again by a solve per
    pivot from where the walk began: still the same path, and the pivot counts are not doubled."""
    import cfcontact.exact as exact

    if model == "fallback":
        monkeypatch.setattr(exact, "TABLEAU_RTOL", -1.0)
    if model in ("chain", "fallback"):
        system = _chain(4, 1.0, 5, 16)
    else:
        from cfcontact.bench_stress import _closing

        system = _closing(24, 0.3)  # (an apex: crossed by the lexicographic rule, not by its ray)
        monkeypatch.setattr(exact, "APEX_RULE", False)
    paths = {}
    for use in (True, False):
        monkeypatch.setattr(exact, "TABLEAU_MIN_NODES", 8 if use else 10 ** 9)
        paths[use] = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=CondensedSolver(system))
    a, b = paths[True], paths[False]
    assert a.stats["tableau_updates"] > 50 and b.stats["tableau_updates"] == 0
    assert a.stats["max_vanishing"] >= 16
    _same_paths(a, b)
    assert [t.pivots for t in a.transitions] == [t.pivots for t in b.transitions]
    assert a.stats["pivots"] == b.stats["pivots"]


@pytest.mark.parametrize("model", ["chain", "closing", "restart"])
def test_compiled_tableau_walk_gives_the_same_path(kernels, model, monkeypatch):
    """The tableau walk's loop in one compiled call (PointTableau.walk, cfc_tableau_walk) against
    the loop in Python (exact.TABLEAU_COMPILED = False): the same path to the last bit, pivot by
    pivot, counters included -- on sixteen identical chains (every transition a point of 16
    nodes) and on two FEM blocks whose whole interface (24 nodes) closes at one alpha.
    "restart": the compiled walk is given room for fewer visited states than the walk needs, so
    it hands each point back (the tableau has moved on) and the loop in Python starts afresh."""
    import cfcontact.exact as exact
    from cfcontact.condensed import PointTableau

    if model == "closing":
        from cfcontact.bench_stress import _closing

        system = _closing(24, 0.3)
        monkeypatch.setattr(exact, "APEX_RULE", False)
    else:
        system = _chain(4, 1.0, 5, 16)
    if model == "restart":
        monkeypatch.setattr(PointTableau, "WALK_STATES_PER_NODE", 0)
        monkeypatch.setattr(PointTableau, "WALK_STATES_EXTRA", 2)
    monkeypatch.setattr(exact, "TABLEAU_MIN_NODES", 8)
    walks = _spy(monkeypatch, PointTableau, "walk")
    (a, sa), (b, sb) = _traced_both_ways(monkeypatch, system, "TABLEAU_COMPILED")
    # (a restarted point builds its tableau twice: the solver counts that)
    _bitwise_same_paths(a, b, sa, sb, solver_counts=model != "restart")
    assert [t.pivots for t in a.transitions] == [t.pivots for t in b.transitions]
    assert a.stats["tableau_updates"] > 50 and a.stats["max_vanishing"] >= 16
    statuses = [w[0] for w in walks]
    assert statuses and all(st == (3 if model == "restart" else 0) for st in statuses), statuses


def test_perturbation_data_come_with_the_condensation(monkeypatch):
    """Where S is formed by one multi-right-hand-side solve with K (MUMPS), the exact method's
    perturbation loads ride along: its first degenerate point solves nothing with K (a separate
    solve of two columns cost 0.7-0.9 ms there, a third of that point), and the path is the one
    whose perturbation data are solved for at the point."""
    import cfcontact.exact as exact
    from cfcontact.bench_stress import _closing

    monkeypatch.setattr(exact, "APEX_RULE", False)  # (its whole interface closes at one point: 48 nodes)
    system = _closing(48, 0.3)
    E = system.perturbation_loads()
    runs = []
    for kept in (True, False):
        solver = CondensedSolver(system)
        assert solver.condensation == "solves" and solver.k_factorization == "lu/mumps"
        if not kept:  # (the set-up's data of the perturbation loads forgotten)
            solver._loads = [(f, w) for f, w in solver._loads if not any(np.array_equal(f, e) for e in E.T)]
        solves = []
        dense = solver._ksolve_dense
        monkeypatch.setattr(solver, "_ksolve_dense", lambda rhs: solves.append(rhs.shape[1]) or dense(rhs))
        path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver)
        assert path.stats["degenerate_points"] == 1 and path.stats["max_vanishing"] == 48
        assert solves == ([] if kept else [E.shape[1]])
        runs.append(path)
    _same_paths(*runs)
    assert [t.pivots for t in runs[0].transitions] == [t.pivots for t in runs[1].transitions]
    # the loads themselves: fixed (the same in every call), at least the default columns
    again = system.perturbation_loads(1)
    assert again.shape == E.shape and np.array_equal(again, E)
    assert system.perturbation_loads(5).shape == (system.n, 5)
    for bad in (0, -2, 2.5, "2", True):
        with pytest.raises(cfcontact.InputError, match="columns must be a positive integer"):
            system.perturbation_loads(bad)


@pytest.mark.parametrize("updates", [True, False])
def test_paths_without_the_compiled_kernels_are_the_same(kernels, monkeypatch, updates):
    """Without cfcontact.native's kernels (no compiler, CFCONTACT_NATIVE=0) products with two
    columns go by BLAS' gemv and branches without updates by NumPy and LAPACK instead of the
    branch kernel: the same path, rounding apart (every product column by column, as on large
    interfaces, so that the kernels are used where they can be)."""
    from cfcontact import native

    monkeypatch.setattr(condensed, "COLUMNWISE_MIN_ROWS", 1)
    system = _chain(8, 2.7, 5, 2)
    paths = {}
    for compiled in (True, False):
        if not compiled:
            monkeypatch.setattr(native, "_tried", True)
            monkeypatch.setattr(native, "_lib", None)
        assert (native.library() is not None) == compiled
        solver = CondensedSolver(system, SolverOptions(updates=updates))
        paths[compiled] = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver)
        assert (solver._kernel is not None) == (compiled and not updates)
    _same_paths(paths[True], paths[False])
    assert paths[True].status == "completed" and paths[True].folds and len(paths[True].transitions) > 50


def _spy(monkeypatch, owner, name) -> list:
    """Wrap owner.name so that every result it returns is also appended to the list returned."""
    seen = []
    f = getattr(owner, name)
    monkeypatch.setattr(owner, name, lambda *a: seen.append(f(*a)) or seen[-1])
    return seen


def _traced_both_ways(monkeypatch, system, flag):
    """The exact path of ``system`` with ``exact.<flag>`` True and False, each with a fresh
    solver: ((path, solver) with, (path, solver) without)."""
    import cfcontact.exact as exact

    runs = {}
    for on in (True, False):
        monkeypatch.setattr(exact, flag, on)
        solver = CondensedSolver(system)
        runs[on] = (cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver), solver)
    return runs[True], runs[False]


def _bitwise_same_paths(a, b, sa, sb, solver_counts=True):
    """The same path to the last bit: transitions, stored points, branches' multipliers and
    indicators, the path's statistics and (``solver_counts``) the solver's counters."""
    assert a.status == b.status and len(a.transitions) == len(b.transitions)
    assert [t.to_dict() for t in a.transitions] == [t.to_dict() for t in b.transitions]
    assert a._alphas == b._alphas and a._point_branch == b._point_branch
    for store in ("_lam", "_ind"):
        x, y = getattr(a, store), getattr(b, store)
        assert x.keys() == y.keys()
        for key in x:
            assert x[key][0] == y[key][0]
            for u, v in zip(x[key][1:], y[key][1:]):
                np.testing.assert_array_equal(u, v)
    timeless = lambda d: {k: v for k, v in d.items() if "time" not in k}  # noqa: E731
    counts = set() if solver_counts else set(sa.stats.as_dict())  # (path.stats carries them too)
    assert ({k: v for k, v in timeless(dict(a.stats)).items() if k not in counts}
            == {k: v for k, v in timeless(dict(b.stats)).items() if k not in counts})
    if solver_counts:
        assert timeless(sa.stats.as_dict()) == timeless(sb.stats.as_dict())


@pytest.mark.parametrize("case", ["chain folds", "copies: degenerate points", "random gaps", "no tangent"])
def test_compiled_ordinary_transitions_give_the_same_path(kernels, monkeypatch, case):
    """Ordinary transitions through one compiled call (exact._ordinary_transition,
    native.OrdinaryStep: the first root, the facet, the next branch and the checks) against the
    general form (exact.ORDINARY_COMPILED = False): the same path to the last bit, on long paths
    with folds, with exact ties (degenerate points: the compiled step hands those to the general
    form), with initial gaps, and with nodes without tangential unknown and frictionless ones."""
    from cfcontact import exact

    if case == "chain folds":
        system = _chain(12, 2.7, 3)
    elif case == "copies: degenerate points":
        system = _chain(6, 2.7, 4, copies=3)
    elif case == "random gaps":
        system = random_system(9, 21, friction=0.8, gap=np.linspace(-0.05, 0.1, 9))
    else:
        m, n = 10, 26
        rng = np.random.default_rng(5)
        A = rng.standard_normal((n, n))
        N, T = np.zeros((m, n)), np.zeros((m, n))
        for i in range(m):
            T[i, 2 * i], N[i, 2 * i + 1] = (0.0 if i in (2, 7) else 1.0), 1.0
        system = ContactSystem.from_arrays(A @ A.T / n + np.eye(n), N, T, rng.standard_normal(n),
                                           rng.standard_normal(n) + np.tile([0.0, 1.0], n // 2),
                                           np.where(np.arange(m) % 4 == 1, 0.0, 1.5))
    taken = _spy(monkeypatch, exact, "_ordinary_transition")
    (a, sa), (b, sb) = _traced_both_ways(monkeypatch, system, "ORDINARY_COMPILED")
    _bitwise_same_paths(a, b, sa, sb)
    n_fast = sum(r is not None and r[0] is not None for r in taken)
    assert len(a.transitions) > 5 and n_fast >= 0.5 * len(a.transitions)
    if case.startswith("copies"):
        assert a.stats["degenerate_points"] > 0 and n_fast < len(a.transitions)
    if case == "no tangent":
        assert system.no_tangent.any()


@pytest.mark.parametrize("friction", ["0.3", "30", "mixed"])
def test_ssnm_iterates_by_updates_equal_fresh_factorizations(monkeypatch, friction):
    """SSNM in the multipliers solves its iterates by updates of one kept factorization on large
    systems (2m >= SSNM_UPDATE_MIN_SIZE, where the backend uses updates; both lowered here to
    every system): the same iterations,
    convergence and sets as with a fresh LU per iterate, the multipliers within rounding, with
    friction, at F = 0 nodes, and for the frictionless problem."""
    monkeypatch.setattr(condensed, "SSNM_UPDATE_MIN_SIZE", 2)
    monkeypatch.setattr(condensed, "UPDATE_MIN_SIZE", 2)
    for seed in range(12):
        m = 10
        F = {"0.3": 0.3, "30": 30.0, "mixed": np.where(np.arange(m) % 3 == 0, 0.0, 1.0)}[friction]
        system = random_system(m, 300 + seed, friction=F)
        upd, ref = CondensedSolver(system), CondensedSolver(system, SolverOptions(updates=False))
        Z0 = cfcontact.InactiveSets(np.zeros(m, bool), np.zeros(m, bool), np.zeros(m, bool))
        for alpha in (0.0, 0.5, 1.0):
            w = upd.load_data(system.load(alpha))
            a = upd._ssnm_lam(w, Z0, np.zeros(2 * m), 1e-12, 25)
            b = ref._ssnm_lam(w, Z0, np.zeros(2 * m), 1e-12, 25)
            assert a[2:] == b[2:] and np.array_equal(a[1].state_codes(), b[1].state_codes())
            assert np.allclose(a[0], b[0], rtol=0, atol=1e-10 * np.abs(b[0]).max())
            fa, fb = upd.frictionless_solution(w, 1e-12, 25), ref.frictionless_solution(w, 1e-12, 25)
            assert np.allclose(fa[0], fb[0], rtol=0, atol=1e-10 * np.abs(fb[0]).max())
        assert upd.stats.dense_updates > 0 and ref.stats.dense_updates == 0


def test_a_failed_ssnm_start_on_a_long_strip_factors_few_dense_systems(monkeypatch):
    """On a strip with m = 500 at F = 0.3 (2m = 1000: SSNM's iterates by updates) SSNM does not
    converge at alpha = 0 in its 25 iterations and the frictionless solution (SSNM too) starts
    the homotopy (390 transitions): those 36 iterations refactor the dense system a few times
    (the updates' rank limit and rebase rule: 17 in all, against 46 with a fresh LU per iterate),
    not once per iterate, and the start is the one of a fresh LU per iterate."""
    from cfcontact.bench_stress import strip

    system = strip(500, 0.3, seed=0)
    runs = []
    for size in (condensed.SSNM_UPDATE_MIN_SIZE, 10 ** 9):  # with, then without SSNM's updates
        monkeypatch.setattr(condensed, "SSNM_UPDATE_MIN_SIZE", size)
        solver = CondensedSolver(system)
        path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver, callback=lambda p: True)
        assert path.stats["start"] == "frictionless" and solver.stats.ssnm_iterations >= 30
        runs.append((path, solver.stats.dense_factorizations))
    (new, k_new), (old, k_old) = runs
    assert k_new <= 20 and k_old - k_new >= 25
    assert new.stats["homotopy_transitions"] == old.stats["homotopy_transitions"]
    assert np.array_equal(canonical_codes(new.branches[0].sets, system.friction),
                          canonical_codes(old.branches[0].sets, system.friction))


def test_each_column_of_an_updated_solve_is_judged_by_its_own_size():
    """The columns of a branch solve (values, rates) can differ by orders of magnitude.  Judged by
    the largest, a small column whose first correction was 160 times itself and its second 6 %
    passed as converged (the contraction looked like 4e-4): on the m = 500 strip at F = 30 with the
    base refactored every 50 nodes, 4 stored points were 1.3e-9 to 3.7e-9 from (1)-(3) and their
    alphas 3e-9 off.  Each column is now judged by its own size: such a branch is refined on to
    its rounding floor and corrected against K (a fresh base where its refinement stops
    contracting).  Since the kept base solves each branch's data with its own right-hand side
    (test_the_base_solves_the_branch_data_with_its_own_right_hand_side) that strip's first solves
    are accurate and no branch needs it there; the strip stays within 1e-9."""
    from cfcontact.bench_stress import strip

    big, small = 1.0, 1.7e-5
    Lc = np.array([small, big])
    # corrections per step and column: the small column's contraction is that of the large one's scale
    assert not condensed._columns_converged([np.array([160 * small, 2e-4]), np.array([0.063 * small, 1e-12])],
                                            False, Lc)
    assert condensed._columns_converged([np.array([1e-3 * small, 2e-4]), np.array([1e-9 * small, 1e-12])],
                                        False, Lc)
    assert condensed._columns_converged([np.array([1e-3 * small, 2e-4]), np.array([1e-12 * small, 1e-16])],
                                        True, Lc)
    assert condensed._columns_converged([np.array([0.0, 2e-4]), np.array([0.0, 1e-12])], False,
                                        np.array([0.0, big]))  # a column of zeros
    # a first solve is taken after one correction only when every column's is within the bound
    assert not condensed._columns_converged([np.array([1e-7 * small, 1e-12])], True, Lc, 1e-9)
    assert condensed._columns_converged([np.array([1e-10 * small, 1e-12])], True, Lc, 1e-9)
    system = strip(500, 30.0, seed=1, kind="uniform")
    solver = CondensedSolver(system)
    solver._updater = _Updater(solver, max_rank=50)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver)
    assert path.status == "completed" and len(path.transitions) == 208
    worst = max(cfcontact.verify(system, y, a, solver=solver).worst() for a, y in path.iter_points(128))
    assert worst <= 1e-9


def test_the_base_solves_the_branch_data_with_its_own_right_hand_side():
    """M(Z)^-1 B = y - Zc C^-1 (V^T y + s) for y = M(Z0)^-1 (B + U s) and any s on D's rows.  With
    s = 0 (y from the branch's own right-hand side) a node the branch opens reads w_j = 0 in the
    base's gap row, so y holds the size of the data w, which are far above the multipliers (the
    bodies' displacement without contact), and x = y - ... loses those digits; with the base's own
    right-hand side (s: what the base has on D's rows) y is the base state's solution of the same
    data.  Reference: the branch's reduced system factored afresh and refined.  Part B's steel
    blocks (90 x 30 cells each), branches 5-120 of the path at F = 30 from its start branch's base:
    at most 3.3e-12 of the multipliers off (median 1.5e-13), against 9.4e-9 (median 9.2e-10)
    with s = 0."""
    from cfcontact.condensed import _node_rows, _scaled_rhs
    from cfcontact.demo_models import DEMO_ALPHA, build_blocks

    system = build_blocks(30.0, nx=90, ny=30)
    solver = CondensedSolver(system)
    path = cfcontact.trace_path(system, *DEMO_ALPHA, method="exact", solver=solver)
    codes = [canonical_codes(b.sets, system.friction_vector) for b in path.branches]
    W = np.column_stack([solver.load_data(f) for f in system.loads_numpy()])
    up = _Updater(solver, max_rank=10 ** 6)
    up.rebase(codes[0])
    err = {True: [], False: []}
    rho = system.rho
    for c in codes[5:121]:
        types = up._types(c)
        D = np.flatnonzero((types[0] != up.types0[0]) | (types[1] != up.types0[1]) | (types[2] != up.types0[2]))
        up._ensure(D)
        solve = up._solver(types, D)
        B = _scaled_rhs(types, W, rho)
        entry = solver._factor_codes(b"ref:" + c.tobytes(), c)
        ref = condensed._full_solve(solver, entry, B, rho)
        for _ in range(2):
            ref = ref + condensed._full_solve(solver, entry, condensed._scaled_residual(types, W, ref, solver.S @ ref,
                                                                                          rho), rho)
        B0 = _scaled_rhs(up.types0, W, rho)
        for own in (True, False):
            x = solve(B, up._base_solve(B0), (B0 - B)[_node_rows(solver.m, D)]) if own else solve(B)
            err[own].append(float((np.abs(x - ref).max(axis=0) / np.abs(ref).max(axis=0)).max()))
    assert max(err[True]) < 1e-11
    assert np.median(err[False]) > 30 * np.median(err[True])
