"""Solver and assembly results against independent references (gaps found by mutation testing).

Every reference here is formed without the code under test:

- ``dense_dirneu``: J(Z) y = (f, r_g, 0) of docs/theory.md (5) written out row by row in NumPy
  (closed node: (N u)_i = g_i, open: lam_n,i = 0; stick: (T u)_i = 0, slip+-: lam_t,i = +-F
  lam_n,i, open: lam_t,i = 0) and solved by ``numpy.linalg.solve``;
- ``all_solutions``: every state combination of a small model solved by ``dense_dirneu`` and kept
  when it satisfies (1)-(3) as checked here (``satisfies``), i.e. the enumeration of Remark 3.2;
- the indicators (17) formed from such a reference solution;
- hand-made nodal loads (value x edge length / 2 at both ends of each edge) and rigid translations
  (the gap and slip of a translated body are the translation's normal and tangential parts).
"""

import itertools

import numpy as np
import pytest

import cfcontact
from cfcontact.condensed import CondensedSolver
from cfcontact.lumped import one_node, random_system
from cfcontact.ssnm import DirNeuSolver, InactiveSets, SolverOptions
from reference import frictionless_dual, state_solve

STATES = ("open", "stick", "slip+", "slip-")


# ----------------------------------------------------------------- references
def _dense(system):
    K, N, T, f1, f2 = system.to_scipy()
    return K.toarray(), N.toarray(), T.toarray(), f1, f2


def dense_dirneu(system, states, f):
    """y = (u, lam_n, lam_t) of DirNeu for per-node states, from J(Z) written out densely."""
    K, N, T, _, _ = _dense(system)
    F = np.broadcast_to(np.asarray(system.friction, dtype=float), (system.m,))
    y = state_solve(K, N, T, F, np.asarray(system.gap, dtype=float), states, f)
    if y is None:
        raise np.linalg.LinAlgError(f"J(Z) of {states} is singular")
    return y


def satisfies(system, y, f, tol=1e-9):
    """(1)-(3) at y, checked directly (equilibrium, sign, complementarity, Coulomb's cone and the
    slip direction), with a tolerance relative to the size of y's forces and the load."""
    K, N, T, _, _ = _dense(system)
    n, m = system.n, system.m
    F = np.broadcast_to(np.asarray(system.friction, dtype=float), (m,))
    u, ln, lt = y[:n], y[n:n + m], y[n + m:]
    gap = N @ u - system.gap
    slip = T @ u
    fs = max(np.abs(f).max(), np.abs(ln).max(initial=0), np.abs(lt).max(initial=0))
    us = max(np.abs(u).max(), 1e-300)
    ok = np.abs(K @ u + N.T @ ln + T.T @ lt - f).max() <= tol * fs
    ok &= bool((ln >= -tol * fs).all() and (gap <= tol * us).all())
    ok &= bool((np.minimum(ln / fs, -gap / us) <= tol).all() and (np.abs(lt) <= F * ln + tol * fs).all())
    inside = np.abs(lt) < F * ln - tol * fs
    ok &= bool((np.abs(slip[inside]) <= tol * us).all())
    edge = (~inside) & (ln > tol * fs)
    ok &= bool((np.sign(lt[edge]) * slip[edge] >= -tol * us).all())
    return bool(ok)


def all_solutions(system, f):
    """Every solution of (1)-(3) for the load f, by trying every state combination."""
    out = []
    for states in itertools.product(STATES, repeat=system.m):
        y = dense_dirneu(system, states, f)
        if satisfies(system, y, f):
            out.append(y)
    return out


def reference_indicators(system, y):
    """(a, bp, bm) of (17) from a reference y: lam_n + rho (N u - g), lam_t + rho T u -+ F lam_n."""
    _, N, T, _, _ = _dense(system)
    n, m, rho = system.n, system.m, system.rho
    F = np.broadcast_to(np.asarray(system.friction, dtype=float), (m,))
    u, ln, lt = y[:n], y[n:n + m], y[n + m:]
    b = lt + rho * (T @ u)
    return np.concatenate([ln + rho * (N @ u - system.gap), b - F * ln, b + F * ln])


def _random_states(m, count, seed):
    rng = np.random.default_rng(seed)
    return [tuple(STATES[c] for c in rng.integers(0, 4, m)) for _ in range(count)]


def _codes(states):
    return np.array([STATES.index(s) for s in states], dtype=np.int8)


def _model(seed=3, m=4, friction=0.7):
    """A random lumped model with per-node friction and a non-zero gap (open and interfering nodes)."""
    F = friction * (0.5 + np.arange(m) / m)
    gap = 0.05 * np.random.default_rng(seed + 100).standard_normal(m)
    return random_system(m, seed, friction=F, gap=gap)


# -------------------------------------------------------------- DirNeu solves
def test_both_backends_solve_dirneu_as_the_dense_jacobian():
    """DirNeu(Z, f) of the full backend (DirNeuSolver, PETSc LU of J(Z)) and of the condensed one
    (S, w and the reduced dense systems) for random state combinations -- slip+ and slip- nodes,
    per-node F, a non-zero gap -- against J(Z) written out densely and solved by NumPy."""
    system = _model()
    full, cond = DirNeuSolver(system), CondensedSolver(system)
    f1, f2 = system.loads_numpy()
    scale = None
    for k, states in enumerate(_random_states(system.m, 24, 7)):
        f = f1 if k % 2 else f2  # alternate loads: a cached w of the other load must not be reused
        ref = dense_dirneu(system, states, f)
        scale = np.abs(ref).max()
        Z = InactiveSets.from_states(states)
        for name, solver in (("full", full), ("condensed", cond)):
            y = solver.solve(Z, f)
            np.testing.assert_allclose(y, ref, rtol=0, atol=1e-10 * scale, err_msg=f"{name} {states}")
    assert scale is not None


def test_condensed_branch_data_equals_the_dense_jacobian_and_its_indicators():
    """CondensedSolver.branch_data (the exact method's branch solve, from state codes: by the
    NumPy/LAPACK form, by the compiled branch kernel (two columns, refined) and by factorization
    updates of a kept base) against the dense J(Z)'s multipliers and the indicators (17) formed
    from the dense solution's u."""
    system = _model(seed=5, m=5, friction=0.9)
    f1, f2 = system.loads_numpy()
    statess = _random_states(system.m, 16, 11)
    refs = [(np.column_stack([dense_dirneu(system, s, f) for f in (f1, f2)])) for s in statess]
    n, m = system.n, system.m
    for updates in (False, True):
        solver = CondensedSolver(system, SolverOptions(updates=updates))
        W = np.column_stack([solver.load_data(f1), solver.load_data(f2)])
        for k, (states, Y) in enumerate(zip(statess, refs)):
            codes = _codes(states)
            key = b"ref" + codes.tobytes()
            G_ref = np.column_stack([reference_indicators(system, Y[:, j]) for j in range(2)])
            scale = max(np.abs(Y[n:]).max(), np.abs(G_ref).max())
            for refine in (False, True):
                res = solver.branch_data(W, key, codes, refine=refine)
                L, G = res[0], res[1]
                np.testing.assert_allclose(L, Y[n:], rtol=0, atol=1e-10 * scale,
                                           err_msg=f"updates={updates} refine={refine} {states}")
                np.testing.assert_allclose(G, G_ref, rtol=0, atol=1e-9 * scale,
                                           err_msg=f"updates={updates} refine={refine} {states}")
            # and one column alone (the NumPy form; the kernel takes two)
            L1, G1 = solver.branch_data(W[:, :1], key, codes)
            np.testing.assert_allclose(L1[:, 0], Y[n:, 0], rtol=0, atol=1e-10 * scale)
            assert m == L1.shape[0] // 2


def test_updated_branch_solves_follow_one_node_changes_from_a_kept_base():
    """Factorization updates (SolverOptions(updates=True)): a walk of branches, each differing
    from the last in one node's state (as the exact method's transitions do), so that the kept
    base is updated rather than refactored; every branch's multipliers against the dense J(Z)."""
    system = _model(seed=9, m=6, friction=1.2)
    f1, f2 = system.loads_numpy()
    n = system.n
    solver = CondensedSolver(system, SolverOptions(updates=True))
    W = np.column_stack([solver.load_data(f1), solver.load_data(f2)])
    rng = np.random.default_rng(2)
    states = ["stick"] * system.m
    for step in range(30):
        i = int(rng.integers(system.m))
        states[i] = STATES[(STATES.index(states[i]) + 1 + int(rng.integers(3))) % 4]
        codes = _codes(states)
        Y = np.column_stack([dense_dirneu(system, states, f) for f in (f1, f2)])
        L, G, _ = solver.branch_data(W, b"walk" + codes.tobytes(), codes, refine=True)
        scale = np.abs(Y[n:]).max()
        np.testing.assert_allclose(L, Y[n:], rtol=0, atol=1e-10 * scale, err_msg=f"step {step} {states}")
        G_ref = np.column_stack([reference_indicators(system, Y[:, j]) for j in range(2)])
        np.testing.assert_allclose(G, G_ref, rtol=0, atol=1e-9 * max(scale, np.abs(G_ref).max()))
    assert solver._updater is not None and solver._updater.updates >= 30


def test_condensed_dirneu_with_compliances_1e13_apart_is_solved_not_refused():
    """A regular model whose contact nodes' compliances differ by up to 1e13 (a very stiff node
    next to soft ones: the reduced system's pivots as far apart) is solved by the condensed backend
    as by the dense J(Z), for every state of the stiff node, not refused as singular."""
    m = 3
    n = 2 * m
    k = np.array([1.0, 1.0, 4.0, 4.0, 1e13, 1e13])
    K = np.diag(k)
    K[0, 2] = K[2, 0] = 0.3
    N, T = np.zeros((m, n)), np.zeros((m, n))
    for i in range(m):
        T[i, 2 * i], N[i, 2 * i + 1] = 1.0, 1.0
    f = np.array([0.2, 1.0, -0.1, 0.5, 3e12, 2e13])
    system = cfcontact.ContactSystem.from_arrays(K, N, T, f, f, 0.4)
    solver = CondensedSolver(system)
    u_scale = np.abs(np.linalg.solve(K, f)).max()
    for states in itertools.product(("stick", "slip+", "slip-"), repeat=m):
        ref = dense_dirneu(system, states, f)
        y = solver.solve(InactiveSets.from_states(states), f)
        np.testing.assert_allclose(y[:n], ref[:n], rtol=0, atol=1e-12 * u_scale, err_msg=str(states))
        np.testing.assert_allclose(y[n:], ref[n:], rtol=1e-9, atol=1e-12 * np.abs(ref[n:]).max(), err_msg=str(states))


def test_frictionless_start_leaves_the_frictional_factorizations_intact():
    """The condensed backend's frictionless solution (the exact method's homotopy start, solved
    with F = 0 in the same solver) against the dual QP by NNLS (tests/reference.py), between
    frictional DirNeu solves with slipping nodes: before and after it, they equal the dense J(Z)
    (a factorization of one problem must not be reused for the other)."""
    system = _model(seed=6, m=4, friction=0.9)
    f = system.load(0.5)
    solver = CondensedSolver(system)
    # every open/slip+ combination (a frictionless node that moves is tangentially free, coded
    # slip+ as well), and some with slip- and stick
    statess = [tuple(c) for c in itertools.product(("open", "slip+"), repeat=system.m) if "slip+" in c]
    statess += [("slip+", "slip-", "stick", "slip+"), ("slip+", "slip+", "slip-", "slip-")]

    def check_frictional():
        for states in statess:
            ref = dense_dirneu(system, states, f)
            y = solver.solve(InactiveSets.from_states(states), f)
            np.testing.assert_allclose(y, ref, rtol=0, atol=1e-10 * np.abs(ref).max(), err_msg=str(states))

    check_frictional()
    K, N, T, _, _ = system.to_scipy()
    _, lam_ref = frictionless_dual(K, N, f, gap=system.gap)
    lam, _ = solver.frictionless_solution(solver.load_data(f), 1e-12, 50)
    m = system.m
    np.testing.assert_allclose(lam[:m], lam_ref, rtol=0, atol=1e-9 * max(np.abs(lam_ref).max(), 1e-300))
    assert not lam[m:].any()
    check_frictional()


def test_true_rows_of_path_loads_and_rates_against_dense_solves():
    """CondensedSolver.true_rows for PathLoads (values at two alphas and one rate column f2 - f1,
    the form the exact method's corrections against K use) equals B K^-1 (f - B^T lam) - (g; 0)
    for the values and B K^-1 (f2 - f1 - B^T lam) for the rate, by dense NumPy solves."""
    from cfcontact.condensed import PathLoads

    system = _model(seed=8, m=4, friction=0.5)
    K, N, T, f1, f2 = _dense(system)
    B = np.vstack([N, T])
    m = system.m
    solver = CondensedSolver(system, SolverOptions(refine=True))
    rng = np.random.default_rng(1)
    L = rng.standard_normal((2 * m, 3))
    loads = PathLoads([0.25, 0.8], rates=1)
    gap = np.array([True, True, False])
    R = solver.true_rows(loads, L, gap)
    fs = [(1 - 0.25) * f1 + 0.25 * f2, (1 - 0.8) * f1 + 0.8 * f2, f2 - f1]
    for j, f in enumerate(fs):
        ref = B @ np.linalg.solve(K, f - B.T @ L[:, j])
        if gap[j]:
            ref[:m] -= system.gap
        np.testing.assert_allclose(R[:, j], ref, rtol=0, atol=1e-12 * np.abs(ref).max(), err_msg=f"column {j}")


# -------------------------------------------------------------------- SSNM
@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_ssnm_of_both_backends_finds_a_solution_of_the_enumeration(seed):
    """SSNM from 0 (full backend, and the condensed backend's SSNM in the multipliers) returns one
    of the solutions found by solving every state combination densely and checking (1)-(3)
    directly; the sets it reports are consistent with that solution."""
    system = _model(seed=seed, m=3, friction=0.6)
    alpha = 0.4
    f = system.load(alpha)
    sols = all_solutions(system, f)
    assert sols, "the enumeration found no solution"
    for solver in (DirNeuSolver(system), CondensedSolver(system)):
        sol = cfcontact.ssnm(system, alpha, solver=solver)
        dist = min(np.abs(sol.y - y).max() / max(np.abs(y).max(), 1e-300) for y in sols)
        assert dist < 1e-9, (type(solver).__name__, dist)
        assert cfcontact.is_fixed_point(system, sol, sol.sets)


def test_inactive_sets_read_the_indicators_with_the_right_sides():
    """inactive_sets(y) against the definitions of method.md, on points whose indicators are far
    from zero: a node is open iff lam_n + rho (N u - g) < 0, in I_t+ iff lam_t + rho T u - F lam_n
    > 0, in I_t- iff lam_t + rho T u + F lam_n < 0."""
    system = _model(seed=4, m=5, friction=0.8)
    rng = np.random.default_rng(0)
    for _ in range(20):
        y = rng.standard_normal(system.n + 2 * system.m)
        a, bp, bm = np.split(reference_indicators(system, y), 3)
        Z = cfcontact.inactive_sets(system, y)
        np.testing.assert_array_equal(Z.nu, a < 0)
        np.testing.assert_array_equal(Z.tp, bp > 0)
        np.testing.assert_array_equal(Z.tm, bm < 0)


# ------------------------------------------------------------------ verify
def _one_node_verify(y, F=0.5):
    """verify on the one-node model (K = I, N = (0, 1), T = (1, 0), rho = 1, f = 0)."""
    system = one_node(F, K=np.eye(2), f1=np.zeros(2), f2=np.zeros(2), rho=1.0)
    return cfcontact.verify(system, np.asarray(y, dtype=float), 0.0, f=np.zeros(2))


def test_verify_flags_each_violated_condition_by_its_hand_computed_size():
    """verify's entries against hand computation on the one-node model with f = 0, rho = 1, K = I:
    y = (u_t, u_n, lam_n, lam_t).  Each case breaks one condition of (2)-(3) by a known amount
    relative to verify's scale (the largest of |lam|, rho |N u|, rho |T u|)."""
    # a negative tangential force outside the cone: |lam_t| - F lam_n = 3 - 0.5 = 2.5, scale 3
    v = _one_node_verify([0.0, 0.0, 1.0, -3.0])
    assert v.cone == pytest.approx(2.5 / 3.0)
    # penetration without force: N u - g = 0.2 > 0, scale 0.2
    v = _one_node_verify([0.0, 0.2, 0.0, 0.0])
    assert v.sign == pytest.approx(1.0)
    # a force at an open gap: lam_n = 1, N u = -0.5: min(lam_n, -(N u)) = 0.5, scale 1
    v = _one_node_verify([0.0, -0.5, 1.0, 0.0])
    assert v.complementarity == pytest.approx(0.5)
    # slip against the friction force: lam_t = +F lam_n (on the cone) needs T u >= 0; T u = -0.25
    v = _one_node_verify([-0.25, 0.0, 1.0, 0.5])
    assert v.slip_direction == pytest.approx(0.25)
    # ... and slip with it: no violation
    v = _one_node_verify([0.25, 0.0, 1.0, 0.5])
    assert v.slip_direction == 0.0 and v.cone == 0.0 and v.sign == 0.0 and v.complementarity == 0.0


# ---------------------------------------------------------------- assembly
def test_windowed_traction_bounded_in_y_on_a_vertical_edge():
    """A traction windowed in y on right1 (x = 3, y in [0, 1]) acts on the window's part only
    (0 <= y <= 2/3): against hand-made nodal loads (value x edge length / 2 at both ends of each
    edge inside the window), the edge above the window unloaded."""
    pytest.importorskip("dolfinx")
    t = np.array([3.0e5, -2.0e5])
    S = cfcontact.two_blocks(nx=6, ny=3, length=3.0, height=1.0,
                             tractions1={"right1": {"value": t, "y": (0.0, 0.6667)}}, tractions2={})
    f1 = S.loads_numpy()[0]
    g = S.geometry
    P = g.points
    body1 = np.unique(g.cells[g.cell_body == 1])
    on = body1[np.isclose(P[body1, 0], 3.0)]
    on = on[np.argsort(P[on, 1])]
    ref = np.zeros(S.n)
    for a, b in zip(on[:-1], on[1:]):
        ya, yb = P[a, 1], P[b, 1]
        if yb <= 0.6667 + 1e-9:
            for node in (a, b):
                for c in (0, 1):
                    ref[(g.dof_node == node) & (g.dof_comp == c)] += 0.5 * t[c] * (yb - ya)
    assert np.count_nonzero(ref) == 2 * 3  # three nodes of the window (y = 0, 1/3, 2/3)
    np.testing.assert_allclose(f1, ref, rtol=0, atol=1e-9 * np.abs(ref).max())


def test_assembled_stiffness_is_the_full_stiffness_on_the_free_dofs():
    """K of assemble_contact_system (Dirichlet DOFs eliminated, symmetrized) equals the rows and
    columns of the free DOFs of full_stiffness (all DOFs, itself checked against hand-computed
    element matrices in test_assembly.py), for two materials and a roller."""
    pytest.importorskip("dolfinx")
    import gmsh

    from cfcontact import compat
    from cfcontact.assembly import assemble_contact_system, full_stiffness
    from cfcontact.meshes import two_blocks as geo

    E, nu = {"body1": 2.0e11, "body2": 7.0e10}, {"body1": 0.3, "body2": 0.35}
    with compat.gmsh_model("free-dofs"):
        geo.build(nx=4, ny=2, length=2.0, height=1.0, cell="triangle")
        Kf = full_stiffness(gmsh.model, E=E, nu=nu)[0]
        system = assemble_contact_system(gmsh.model, E=E, nu=nu, clamp=("left1", "left2"),
                                         dirichlet={"right2": {"x": 0.0}}, tractions1={}, tractions2={})
    g = system.geometry
    free = 2 * g.dof_node + g.dof_comp
    K = system.to_scipy()[0].toarray()
    ref = Kf.toarray()[np.ix_(free, free)]
    np.testing.assert_allclose(K, ref, rtol=0, atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("pairing", ["node", "segment"])
def test_contact_rows_measure_a_rigid_translation_of_either_body(pairing):
    """N and T of a matching (node) and a non-matching (segment, body 2 meshed finer) interface:
    translating body 1 by d gives every row (N u)_i = d . n_i and (T u)_i = d . t_i, translating
    body 2 by d gives -d . n_i and -d . t_i (the relative displacement u1 - u2 of method.md), and
    translating both gives 0 (the interpolation weights on the master side sum to one)."""
    pytest.importorskip("dolfinx")
    kw = dict(nx=6, ny=2, clamp=("left1", "left2"), tractions1={}, tractions2={}, angle=20.0)
    if pairing == "segment":
        kw.update(nx2=9, ny2=2, pairing="segment")
    S = cfcontact.two_blocks(**kw)
    g = S.geometry
    N, T = (A.toarray() for A in S.contact_maps())
    body1 = np.isin(g.dof_node, np.unique(g.cells[g.cell_body == 1]))
    d = np.array([0.3, -0.7])
    u1 = np.where(body1, d[g.dof_comp], 0.0)
    u2 = np.where(~body1, d[g.dof_comp], 0.0)
    # rows touching a clamped node see only part of the translation: compare the others
    free_rows = np.ones(S.m, dtype=bool)
    for i, nodes in enumerate(g.contact_nodes):
        for node in nodes:
            if node >= 0 and np.count_nonzero(g.dof_node == node) < 2:
                free_rows[i] = False
    free_rows &= np.abs(N).sum(axis=1) > 0
    assert free_rows.sum() >= S.m - 2 and S.m >= 5
    full = d[g.dof_comp]
    nd, td = g.normals @ d, g.tangents @ d
    r = free_rows
    np.testing.assert_allclose((N @ u1)[r], nd[r], rtol=0, atol=1e-12)
    np.testing.assert_allclose((T @ u1)[r], td[r], rtol=0, atol=1e-12)
    np.testing.assert_allclose((N @ u2)[r], -nd[r], rtol=0, atol=1e-12)
    np.testing.assert_allclose((T @ u2)[r], -td[r], rtol=0, atol=1e-12)
    np.testing.assert_allclose((N @ full)[r], 0.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose((T @ full)[r], 0.0, rtol=0, atol=1e-12)
