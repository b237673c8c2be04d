"""The initial gap g of ContactSystem (issue #12, item 1): N u <= g, lam_n^T (N u - g) = 0.

Independent references: the closed-form one-node solutions of method.md and the dense dual QP
(tests/reference.py), and the shift identity: when some u_g has N u_g = g and T u_g = 0, the
problem with gap g and load f is the gap-free problem with load f - K u_g, shifted by u_g --
which the gap-free code (tested elsewhere) solves.
"""

import numpy as np
import pytest

import cfcontact
from cfcontact.condensed import CondensedSolver
from cfcontact.critical import critical_friction
from cfcontact.enumerate import enumerate_solutions
from cfcontact.lumped import one_node, random_system
from cfcontact.system import ContactSystem
from reference import frictionless_dual, one_node_solutions

K1 = np.array([[1.0, 0.5], [0.5, 1.0]])


def shifted(system):
    """(u_g, the gap-free system with loads f - K u_g) for a lumped system whose N, T select DOFs."""
    K, N, T, f1, f2 = system.to_scipy()
    B = np.vstack([N.toarray(), T.toarray()])
    u_g = np.linalg.lstsq(B, np.concatenate([system.gap, np.zeros(system.m)]), rcond=None)[0]
    assert np.allclose(B @ u_g, np.concatenate([system.gap, np.zeros(system.m)]), atol=1e-14)
    Ku = K @ u_g
    return u_g, ContactSystem.from_arrays(K, N, T, f1 - Ku, f2 - Ku, system.friction, rho=system.rho)


def _close(a, b, rtol=1e-9):
    return np.abs(a - b).max(initial=0.0) <= rtol * max(np.abs(a).max(initial=0.0), np.abs(b).max(initial=0.0), 1e-300)


# ----------------------------------------------------------------- the object
def test_gap_default_zero_validated_and_carried():
    system = random_system(3, 0)
    assert system.gap.shape == (3,) and not system.gap.any() and not system.has_gap
    g = np.array([0.1, 0.0, -0.05])
    sg = random_system(3, 0, gap=g)
    assert np.array_equal(sg.gap, g) and sg.has_gap
    with pytest.raises(ValueError):
        sg.gap[0] = 1.0  # read-only
    for variant in (sg.with_friction(0.3), sg.with_rho(2.0 * sg.rho), sg.with_loads(*sg.loads_numpy())):
        assert np.array_equal(variant.gap, g)
    assert np.array_equal(system.with_gap(g).gap, g) and not sg.with_gap(None).has_gap
    assert np.array_equal(random_system(3, 0, gap=0.25).gap, [0.25] * 3)  # one number for every node
    assert "gap in [-0.05, 0.1]" in repr(sg)
    K, N, T, f1, f2 = system.to_scipy()
    for bad, words in (([0.1, 0.2], "one value per contact node (shape (3,))"),
                       ([0.1, np.nan, 0.0], "finite; nodes [1]"), ("wide", "number"), (np.inf, "finite")):
        with pytest.raises(cfcontact.InputError, match=words.replace("(", "\\(").replace(")", "\\)")
                           .replace("[", "\\[").replace("]", "\\]")):
            ContactSystem.from_arrays(K, N, T, f1, f2, 0.3, gap=bad)


# ------------------------------------------------------------- one node
@pytest.mark.parametrize("g", [0.3, -0.2])
def test_one_node_with_gap_against_closed_form(g):
    """u_n <= g: the solutions are method.md's closed form for the load f - K (0, g), shifted by (0, g)."""
    for theta in np.linspace(-170, 170, 35):
        f = np.array([np.cos(np.radians(theta)), np.sin(np.radians(theta))])
        system = one_node(2.5, K1, f1=f, f2=f, gap=g)
        ref = one_node_solutions(K1, 2.5, f - K1 @ np.array([0.0, g]))
        got = enumerate_solutions(system, 0.0)
        assert sorted(s for s, _ in ref) == sorted(s.states()[0] for s in got), theta
        for state, y in ref:
            match = [s for s in got if s.states()[0] == state]
            assert len(match) == 1
            expect = y + np.array([0.0, g, 0.0, 0.0])
            assert _close(match[0].y, expect, 1e-10), (theta, state)
            assert cfcontact.verify(system, match[0], 0.0).ok(1e-10)


def test_verify_measures_penetration_against_the_gap():
    f = np.array([0.2, 1.0])  # pressing into the foundation
    system = one_node(0.5, K1, f1=f, f2=f, gap=0.1)
    sol = cfcontact.ssnm(system, 0.0)
    assert sol.states() == ["stick"] and sol.u[1] == pytest.approx(0.1, rel=1e-12)
    assert cfcontact.verify(system, sol, 0.0).ok(1e-12)
    zero = system.with_gap(None)  # the same y penetrates a foundation without gap
    v = cfcontact.verify(zero, sol, 0.0)
    assert v.sign > 1e-3 and v.complementarity > 1e-3


# ------------------------------------------------------- random systems
@pytest.mark.parametrize("seed", range(4))
def test_ssnm_with_gap_is_the_shifted_gap_free_solution(seed):
    rng = np.random.default_rng(100 + seed)
    system = random_system(4, seed, friction=0.4, extra_dofs=3, gap=rng.uniform(-0.3, 0.6, 4))
    u_g, ref_system = shifted(system)
    for alpha in (0.0, 0.35, 1.0):
        ref = cfcontact.ssnm(ref_system, alpha)
        for solver in (None, CondensedSolver(system)):
            sol = cfcontact.ssnm(system, alpha, solver=solver)
            assert _close(sol.u, ref.u + u_g) and _close(sol.y[system.n:], ref.y[system.n:])
            assert sol.states() == ref.states()
            assert cfcontact.verify(system, sol, alpha).ok(1e-10)


@pytest.mark.parametrize("seed", range(3))
def test_enumeration_with_gap_is_the_shifted_enumeration(seed):
    rng = np.random.default_rng(7 + seed)
    system = random_system(3, seed, friction=2.0, coupling=3.0, gap=rng.uniform(-0.2, 0.4, 3))
    u_g, ref_system = shifted(system)
    for alpha in (0.2, 0.8):
        got = enumerate_solutions(system, alpha)
        ref = enumerate_solutions(ref_system, alpha)
        assert len(got) == len(ref) >= 1
        for s in ref:
            assert any(_close(t.u, s.u + u_g) and _close(t.y[system.n:], s.y[system.n:]) for t in got)


@pytest.mark.parametrize("seed", range(4))
def test_frictionless_with_gap_against_dual_qp(seed):
    rng = np.random.default_rng(seed)
    g = rng.uniform(-0.5, 1.0, 5)
    system = random_system(5, seed, friction=0.0, extra_dofs=3, gap=g)
    K, N, T, f1, f2 = system.to_scipy()
    f = 0.6 * f1 + 0.4 * f2
    u_ref, lam_ref = frictionless_dual(K, N, f, gap=g)
    assert np.any(lam_ref == 0) or np.all(lam_ref > 0)
    for solver in (None, CondensedSolver(system)):
        sol = cfcontact.ssnm(system, 0.4, solver=solver)
        assert np.allclose(sol.u, u_ref, rtol=1e-8, atol=1e-10 * np.abs(u_ref).max())
        assert np.allclose(sol.lam_n, lam_ref, rtol=1e-8, atol=1e-10 * max(np.abs(lam_ref).max(), 1))
        assert np.allclose(N @ sol.u - g, np.minimum(N @ sol.u - g, 0.0), atol=1e-10)


def test_dirneu_affine_not_linear_and_backends_agree():
    """With a gap DirNeu(Z, f) is affine in f: DirNeu(Z, 0) != 0 closes the closed nodes at u = g, and
    y(alpha) = (1 - alpha) DirNeu(Z, f1) + alpha DirNeu(Z, f2) still holds exactly."""
    g = np.array([0.2, -0.1, 0.05, 0.3])
    system = random_system(4, 3, friction=0.7, gap=g)
    condensed = CondensedSolver(system)
    N = system.contact_maps()[0]
    for states in (["stick"] * 4, ["open", "slip+", "stick", "slip-"], ["slip-", "open", "open", "stick"]):
        Z = cfcontact.InactiveSets.from_states(states)
        y0, y1 = (cfcontact.dirneu(system, Z, a).y for a in (0.0, 1.0))
        for alpha in (0.25, 0.8):
            y = cfcontact.dirneu(system, Z, alpha).y
            assert _close(y, (1 - alpha) * y0 + alpha * y1, 1e-11)
            assert _close(condensed.solve(Z, system.load(alpha)), y, 1e-10)
        zero = cfcontact.dirneu(system, Z, f=np.zeros(system.n))
        closed = ~Z.nu
        assert np.allclose((N @ zero.u)[closed], g[closed], atol=1e-13) and np.abs(zero.y).max() > 1e-3


def test_condensed_load_data_is_shifted_by_the_gap():
    g = np.array([0.2, -0.1, 0.05])
    system = random_system(3, 1, gap=g)
    plain = CondensedSolver(system.with_gap(None))
    solver = CondensedSolver(system)
    f1, f2 = system.loads_numpy()
    shift = np.concatenate([g, np.zeros(3)])
    assert _close(solver.load_data(f1), plain.load_data(f1) - shift, 1e-13)
    assert _close(solver.load_data(f1), plain.load_data(f1) - shift, 1e-13)  # cached: shifted again, once
    W = solver.load_data_many([f1, f2])
    assert _close(W, plain.load_data_many([f1, f2]) - shift[:, None], 1e-13)
    assert _close(plain.load_data(f2), plain.load_data(f2), 0.0)


def test_critical_friction_does_not_depend_on_the_gap():
    system = random_system(3, 4, coupling=3.0)
    a = critical_friction(system, window=3, stick_window=3)
    b = critical_friction(system.with_gap([0.3, -0.1, 0.2]), window=3, stick_window=3)
    assert a.friction == b.friction and a.nodes == b.nodes and a.states == b.states


# --------------------------------------------------- node without tangent DOFs
def test_node_without_tangential_dofs_sticks_with_zero_lam_t():
    """A zero row of T (a node on a symmetry plane: its tangential DOFs prescribed) has no tangential
    unknown: J(Z) of a sticking node takes lam_t = 0 (instead of the singular row 0 = 0)."""
    base = random_system(3, 2, friction=0.5, gap=[0.0, 0.1, -0.05])
    K, N, T, f1, f2 = base.to_scipy()
    T = T.tolil()
    T[1, :] = 0.0
    K = K.tolil()
    # the tangential DOF of node 1 no longer couples to anything: keep K SPD
    system = ContactSystem.from_arrays(K.tocsr(), N, T.tocsr(), f1, f2, 0.5, gap=base.gap)
    assert system.no_tangent.tolist() == [False, True, False]
    sol = cfcontact.ssnm(system, 0.5)
    assert sol.lam_t[1] == 0.0 and sol.states()[1] in ("stick", "open")
    assert cfcontact.verify(system, sol, 0.5).ok(1e-10)
    found = enumerate_solutions(system, 0.5)
    assert any(_close(s.y, sol.y) for s in found)
    assert all(s.lam_t[1] == 0.0 for s in found)
    Z = cfcontact.InactiveSets.all_stick(3)
    assert np.isfinite(cfcontact.dirneu(system, Z, 0.5).y).all()


# ------------------------------------------------------------------ paths
@pytest.mark.parametrize("seed", range(4))
def test_seed_and_exact_paths_with_gap_agree_and_verify(seed):
    """Both path methods run unchanged with a gap (branches stay affine: g is constant): same
    transitions (alpha within the seed's h_min), every stored point satisfies (1)-(3) with the gap."""
    rng = np.random.default_rng(seed)
    system = random_system(4, seed, friction=0.6, coupling=2.0, gap=rng.uniform(-0.3, 0.6, 4))
    paths = {method: cfcontact.trace_path(system, 0, 1, method=method) for method in ("seed", "exact")}
    a, b = ([(t.alpha, t.kind, t.node, t.set) for t in paths[k].transitions] for k in ("seed", "exact"))
    assert len(a) == len(b) >= 1
    for x, y in zip(a, b):
        assert x[1:] == y[1:] and abs(x[0] - y[0]) <= 2e-5
    for path in paths.values():
        assert path.status == "completed"
        assert max(cfcontact.verify(system, y, al).worst() for al, y in zip(path.alphas, path.ys)) <= 1e-10
