"""Exact paths, their stored solutions and contact pairing against independent references.

The references here use NumPy/SciPy only (no cfcontact solver):

* ``brute_force``: every solution of a small system at one alpha, by trying every state of every
  node (open, stick, slip+, slip-: 4^m dense linear solves of K u + N^T lam_n + T^T lam_t = f with
  the state's equations) and keeping those whose inequalities hold;
* ``dense_branch``: the affine solution y(alpha) of one branch (fixed states) by two dense solves,
  and the constraints of its states along it, whose first root in the branch's direction is where
  the branch must end (the exact method's ratio test, redone independently);
* the closed form of the one-node problem (tests/reference.py) and analytic gaps and normals.

These tests were written by mutation testing: each kills at least one plausible bug that the rest
of the suite let pass (see the docstrings).
"""

import numpy as np
import pytest

import cfcontact
from cfcontact import pairing
from cfcontact.lumped import one_node, random_system
from reference import alpha_of_tan, one_node_solutions, state_solve

STATES = ("open", "stick", "slip+", "slip-")


# ------------------------------------------------------------------ references
def _dense(system):
    K, N, T, f1, f2 = system.to_scipy()
    K, N, T = (np.asarray(A.toarray() if hasattr(A, "toarray") else A, dtype=float) for A in (K, N, T))
    F = np.broadcast_to(np.asarray(system.friction_vector, dtype=float), (system.m,))
    gap = np.broadcast_to(np.asarray(system.gap, dtype=float), (system.m,))
    return K, N, T, np.asarray(f1, dtype=float), np.asarray(f2, dtype=float), F, gap


def _constraints(N, T, F, gap, states, y, n):
    """The inequalities of the states at y, each >= 0 where they hold (one list entry per
    inequality: (node, value))."""
    m = N.shape[0]
    u, ln, lt = y[:n], y[n:n + m], y[n + m:]
    gn, tu = N @ u - gap, T @ u
    out = []
    for i, st in enumerate(states):
        if st == "open":
            out.append((i, -gn[i]))  # N u <= g
        else:
            out.append((i, ln[i]))  # lam_n >= 0
            if st == "stick":
                out += [(i, F[i] * ln[i] - lt[i]), (i, F[i] * ln[i] + lt[i])]  # |lam_t| <= F lam_n
            elif F[i] == 0.0:
                pass  # F = 0: closed and tangentially free (coded slip+), no sign on T u
            elif st == "slip+":
                out.append((i, tu[i]))  # T u >= 0
            else:
                out.append((i, -tu[i]))
    return out


def brute_force(system, alpha, rtol=1e-9):
    """Every distinct solution of the system at alpha: [(states, y)] by trying all 4^m states."""
    K, N, T, f1, f2, F, gap = _dense(system)
    n, m = K.shape[0], N.shape[0]
    f = (1.0 - alpha) * f1 + alpha * f2
    sols = []
    for combo in np.ndindex(*(4,) * m):
        states = [STATES[c] for c in combo]
        if any(F[i] == 0 and st in ("stick", "slip-") for i, st in enumerate(states)):
            continue  # F = 0: open or closed and free (slip+) only
        y = state_solve(K, N, T, F, gap, states, f)
        if y is None:
            continue
        scale = max(np.abs(y).max(), np.abs(f).max(), 1.0)
        if all(v >= -rtol * scale for _, v in _constraints(N, T, F, gap, states, y, n)):
            if not any(np.abs(y - z).max() <= 1e-7 * scale for _, z in sols):
                sols.append((states, y))
    return sols


def dense_branch(system, states):
    """(y0, dy): the branch of ``states`` as y(alpha) = y0 + alpha dy, by two dense solves."""
    K, N, T, f1, f2, F, gap = _dense(system)
    y1 = state_solve(K, N, T, F, gap, states, f1)
    y2 = state_solve(K, N, T, F, gap, states, f2)
    return y1, y2 - y1


def first_root(system, states, alpha0, s, lo, hi):
    """The first alpha beyond alpha0 (direction s) where a constraint of ``states`` that decreases
    in direction s vanishes on the dense branch (the end of the range if none), and the
    constraints' smallest value on the branch between alpha0 and there (relative)."""
    K, N, T, f1, f2, F, gap = _dense(system)
    n = K.shape[0]
    y0, dy = dense_branch(system, states)
    c0 = np.array([v for _, v in _constraints(N, T, F, gap, states, y0 + alpha0 * dy, n)])
    c1 = np.array([v for _, v in _constraints(N, T, F, gap, states, y0 + (alpha0 + s) * dy, n)])
    rate = c1 - c0  # per unit step in direction s (the constraints are affine in y)
    scale = max(np.abs(y0).max(), np.abs(dy).max(), 1.0)
    dec = rate < -1e-12 * scale
    t = np.where(dec, c0 / np.where(dec, -rate, 1.0), np.inf)
    t = np.maximum(t, 0.0)
    end = hi if s > 0 else lo
    a = alpha0 + s * min(t.min(initial=np.inf), abs(end - alpha0))
    mid = 0.5 * (alpha0 + a)
    cm = np.array([v for _, v in _constraints(N, T, F, gap, states, y0 + mid * dy, n)])
    return a, cm.min(initial=np.inf) / scale


def _sample_alphas(path, k=7):
    """Alphas in [0, 1] away from every transition (midpoints between transitions, and a grid)."""
    marks = sorted({0.0, 1.0, *[t.alpha for t in path.transitions if 0.0 <= t.alpha <= 1.0]})
    mids = [0.5 * (a + b) for a, b in zip(marks[:-1], marks[1:]) if b - a > 1e-7]
    grid = [a for a in np.linspace(0.0, 1.0, k) if all(abs(a - t) > 1e-6 for t in marks[1:-1])]
    return sorted(set(mids + grid))


def _matches(y, refs, rtol=1e-8):
    return [k for k, (_, z) in enumerate(refs) if np.abs(y - z).max() <= rtol * max(np.abs(z).max(), 1.0)]


def _check_against_brute_force(system, path):
    """Every solution the path has at the sampled alphas is a brute-force solution (distinct ones
    distinct), and where the brute force finds exactly one, the path (which covers [0, 1]) has it."""
    assert path.status == "completed" and path.reach() == 1.0
    for a in _sample_alphas(path):
        refs = brute_force(system, a)
        sols = path.solutions_at(a)
        assert path.multiplicity(a) == len(sols) >= 1, a
        hit = [_matches(sol.y, refs) for sol in sols]
        assert all(len(h) == 1 for h in hit), (a, [s.states() for s in sols], [r[0] for r in refs])
        assert len({h[0] for h in hit}) == len(sols), a  # distinct solutions are distinct
        for sol, h in zip(sols, hit):
            assert sol.states() == refs[h[0]][0], (a, sol.states(), refs[h[0]][0])
        if len(refs) == 1:
            assert len(sols) == 1, a


def _check_branches_end_at_first_roots(system, path, tol=1e-9):
    """Every branch of the path, solved afresh by dense solves, holds its constraints on its
    extent, and ends where the first of them vanishes in its direction (or at the range's end)."""
    for b in path.branches:
        s = b.orientation
        a_exit, worst = first_root(system, b.sets.states(), b.alpha_enter, s, 0.0, 1.0)
        assert worst >= -tol, (b.index, b.sets.states(), worst)
        assert abs(a_exit - b.alpha_exit) <= tol, (b.index, b.sets.states(), a_exit, b.alpha_exit)


# ------------------------------------------------------------------ exact paths
def _system(m, seed, friction, extra_dofs=3, reverse=False, gap=None):
    system = random_system(m, seed, friction=friction, extra_dofs=extra_dofs, gap=gap)
    if reverse:  # a load path that reverses the second load: unloading, folds at large F
        f1, f2 = system.loads_numpy()
        system = system.with_loads(f1, -f2)
    return system


CASES = {  # (m, seed, friction, extra_dofs, reverse, gap): transitions, folds, max multiplicity
    "m2-F1": (2, 1, 1.0, 2, False, None),  # 1, 0, 1
    "m3-F0.3": (3, 0, 0.3, 2, False, None),  # 2, 0, 1
    "m3-F2.5": (3, 5, 2.5, 2, False, None),  # 3, 0, 1
    "m4-F30-folds": (4, 1, 30.0, 3, False, None),  # 10, 4, 3
    "m3-F30-rev": (3, 2, 30.0, 3, True, None),  # 6, 4, 3
    "m4-F30-rev": (4, 0, 30.0, 3, True, None),  # 10, 2, 3
    "m3-mixedF-gap": (3, 3, [0.0, 0.6, 2.5], 3, True, [0.05, 0.0, 0.02]),
}


@pytest.mark.parametrize("case", list(CASES))
def test_exact_path_against_brute_force_enumeration(case):
    """Random lumped systems (m = 2 to 4, F from 0.3 to 30, folds and up to 3 solutions at one
    alpha, a node without friction and initial gaps): at alphas between the transitions every
    solution of the exact path is one that the brute-force enumeration of all 4^m states finds
    (with the same states; distinct ones distinct), and where that solution is unique the path has
    it; every branch, solved afresh by two dense solves, holds its constraints over its extent and
    ends at the first root of its constraints in its direction (the ratio test, redone)."""
    system = _system(*CASES[case])
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    _check_against_brute_force(system, path)
    _check_branches_end_at_first_roots(system, path)


@pytest.mark.parametrize("case", ["m3-F2.5", "m4-F30-folds", "m3-F30-rev", "m3-mixedF-gap"])
def test_exact_path_without_compiled_kernels_against_brute_force(case, monkeypatch):
    """The same checks without cfcontact.native's compiled kernels (no C compiler, or
    CFCONTACT_NATIVE=0): then every transition goes through the NumPy forms (the ratio test of
    exact._exit, the pivots of exact._resolve), which the compiled ordinary step otherwise
    bypasses."""
    from cfcontact import native

    monkeypatch.setattr(native, "_tried", True)
    monkeypatch.setattr(native, "_lib", None)
    assert native.library() is None
    system = _system(*CASES[case])
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    _check_against_brute_force(system, path)
    _check_branches_end_at_first_roots(system, path)


def _two_identical_nodes():
    """Two uncoupled copies of the one-node problem of method.md (K = [[1, .5], [.5, 1]], F = 2.5):
    at every alpha between the folds each node has 3 solutions, the pair 9; the transitions of
    both nodes fall on the same alphas (degenerate points, resolved by the lexicographic rule)."""
    import scipy.linalg as sla

    from cfcontact.system import ContactSystem

    K1 = np.array([[1.0, 0.5], [0.5, 1.0]])
    K = sla.block_diag(K1, K1)
    N = np.array([[0, 1, 0, 0], [0, 0, 0, 1.0]])
    T = np.array([[1.0, 0, 0, 0], [0, 0, 1, 0]])
    d = lambda deg: np.array([np.cos(np.radians(deg)), np.sin(np.radians(deg))])  # noqa: E731
    return ContactSystem.from_arrays(K, N, T, np.tile(d(15), 2), np.tile(d(35), 2), 2.5)


@pytest.mark.parametrize("native_kernels", [True, False])
def test_tree_at_degenerate_points_against_brute_force(native_kernels, monkeypatch):
    """Two identical one-node problems: every transition is a degenerate point of both nodes at
    once, crossed by the lexicographic rule.  The tree of every alternative (trace_tree) has only
    brute-force solutions at alphas between its transitions, and between the folds it has all
    9 = 3 x 3 of them, each node's part equal to the one-node closed form (with and without the
    compiled kernels)."""
    from cfcontact import native
    from cfcontact.exact import trace_tree

    if not native_kernels:
        monkeypatch.setattr(native, "_tried", True)
        monkeypatch.setattr(native, "_lib", None)
    system = _two_identical_nodes()
    tree = trace_tree(system, 0.0, 1.0)
    assert tree.status in ("completed", "closed_loop")
    folds = sorted({round(t.alpha, 12) for t in tree.transitions if t.kind == "fold"})
    lo, hi = folds[0], folds[-1]
    K1 = np.array([[1.0, 0.5], [0.5, 1.0]])
    for a in (0.1, 0.5 * (lo + hi), lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo), 0.9):
        refs = brute_force(system, a)
        sols = tree.solutions_at(a)
        hit = [_matches(sol.y, refs) for sol in sols]
        assert all(len(h) == 1 for h in hit) and len({h[0] for h in hit}) == len(sols), a
        one = one_node_solutions(K1, 2.5, system.load(a)[:2])
        assert len(refs) == len(one) ** 2
        if lo < a < hi:
            assert len(sols) == 9, (a, len(sols))
            for sol in sols:
                for i in (0, 1):
                    got = np.array([sol.u[2 * i], sol.u[2 * i + 1], sol.lam_n[i], sol.lam_t[i]])
                    assert any(np.allclose(got, ref, atol=1e-12) for _, ref in one), (a, i, got)


def _one_node_within(K, F, f, tol=1e-12):
    """The closed-form solutions of the one-node problem (tests/reference.py's formulas) with
    their validity conditions relaxed by ``tol`` (at a fold a condition holds with equality, which
    rounding can tip either way)."""
    (ktt, ktn), (_, knn) = K
    ft, fn = f
    out = []
    if ktt * fn - ktn * ft < tol:
        u = np.linalg.solve(K, f)
        out.append(np.array([u[0], u[1], 0.0, 0.0]))
    if fn >= -tol and abs(ft) <= F * fn + tol:
        out.append(np.array([0.0, 0.0, fn, ft]))
    for s in (1, -1):
        den = ktt - s * F * ktn
        ut, p = (ft - s * F * fn) / den, (ktt * fn - ktn * ft) / den
        if s * ut > -tol and p >= -tol:
            out.append(np.array([ut, 0.0, p, s * F * p]))
    return out


def test_one_node_solutions_at_and_around_the_folds_against_the_closed_form():
    """The one-node problem of method.md (F = 2.5): the folds lie on the wedge's rays, and at the
    fold alphas themselves and around them the path's solutions are the
    closed form's: 3 or 1 of them 1e-9 either side, and 2 at the fold alpha itself, where the
    two branches of the fold meet."""
    K = np.array([[1.0, 0.5], [0.5, 1.0]])
    system = one_node(2.5, K)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    rays = sorted([alpha_of_tan(system, 0.4), alpha_of_tan(system, 0.5)])
    folds = sorted(t.alpha for t in path.folds)
    assert np.allclose(folds, rays, rtol=0, atol=1e-12)
    for a0 in folds:
        for a in (a0 - 1e-9, a0, a0 + 1e-9, np.nextafter(a0, 0.0), np.nextafter(a0, 1.0)):
            distinct = []
            for v in _one_node_within(K, 2.5, system.load(a)):
                if not any(np.allclose(v, w, atol=1e-9) for w in distinct):
                    distinct.append(v)
            sols = path.solutions_at(a)
            got = [np.array([s.u[0], s.u[1], s.lam_n[0], s.lam_t[0]]) for s in sols]
            assert path.multiplicity(a) == len(sols)
            for g in got:
                assert any(np.allclose(g, v, atol=1e-9) for v in distinct), (a, g)
            if abs(a - a0) >= 1e-9:
                assert len(sols) == len(distinct), (a, len(sols), len(distinct))
            elif a == a0:  # the two branches of the fold meet in one solution, and the third
                assert len(sols) == 2, (a, len(sols))
            else:  # an ulp off the fold the meeting pair exists or not by rounding
                assert len(sols) >= 1


def test_one_node_multiplicity_intervals_are_the_wedge_of_the_closed_form():
    """The one-node problem of method.md (F = 2.5): 3 solutions for load directions strictly
    between atan(0.4) and atan(0.5), 1 outside.  The path's multiplicity intervals are exactly
    [(0, a_lo, 1), (a_lo, a_hi, 3), (a_hi, 1, 1)] with a_lo, a_hi the alphas of those directions
    (closed form), also over a window, and max_multiplicity is 3 at an alpha inside the wedge."""
    K = np.array([[1.0, 0.5], [0.5, 1.0]])
    system = one_node(2.5, K)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    a_lo, a_hi = sorted([alpha_of_tan(system, 0.4), alpha_of_tan(system, 0.5)])
    got = path.multiplicity_intervals()
    assert [k for _, _, k in got] == [1, 3, 1]
    assert np.allclose([x for a, b, _ in got for x in (a, b)], [0.0, a_lo, a_lo, a_hi, a_hi, 1.0], rtol=0, atol=1e-12)
    window = path.multiplicity_intervals((0.5 * a_lo, 0.5 * (a_lo + a_hi)))
    assert [k for _, _, k in window] == [1, 3] and abs(window[0][1] - a_lo) <= 1e-12
    mult, at = path.max_multiplicity()
    assert mult == 3 and a_lo < at < a_hi
    assert len(one_node_solutions(K, 2.5, system.load(at))) == 3


@pytest.mark.parametrize("case", ["m4-F30-folds", "m3-mixedF-gap"])
def test_saved_and_loaded_path_against_brute_force(case, tmp_path):
    """A path saved and loaded again (every branch formed, in reference form) has at the sampled
    alphas the same solutions as before, each a brute-force solution, and the same multiplicity
    intervals."""
    system = _system(*CASES[case])
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    before = {a: path.solutions_at(a) for a in _sample_alphas(path)}
    intervals = path.multiplicity_intervals()
    path.save(str(tmp_path / "p"))
    loaded = cfcontact.SolutionPath.load(str(tmp_path / "p"))
    _check_against_brute_force(system, loaded)
    for a, sols in before.items():
        again = loaded.solutions_at(a)
        assert len(again) == len(sols)
        for x, z in zip(sols, again):
            assert np.allclose(x.y, z.y, rtol=1e-12, atol=1e-14) and x.states() == z.states()
    got = loaded.multiplicity_intervals()
    assert [k for _, _, k in got] == [k for _, _, k in intervals]
    assert np.allclose([(a, b) for a, b, _ in got], [(a, b) for a, b, _ in intervals], rtol=0, atol=1e-14)


# ------------------------------------------------------------------ pairing
def _flat_slave(xs, y, body_above=True):
    """Slave facets along y = const through the x coordinates xs, its body above (outer normal
    (0, -1)) or below: (points, facets, centroids)."""
    pts = np.column_stack([xs, np.full(len(xs), y)])
    facets = np.column_stack([np.arange(len(xs) - 1), np.arange(1, len(xs))])
    mid = 0.5 * (pts[:-1] + pts[1:])
    cent = mid + (0.0, 0.1 if body_above else -0.1)
    return pts, facets, cent


def _flat_master(xs, y, offset, body_below=True):
    """Master facets along y = const (node numbers from ``offset``), its body below (outer normal
    (0, 1)) or above."""
    pts = np.column_stack([xs, np.full(len(xs), y)])
    facets = offset + np.column_stack([np.arange(len(xs) - 1), np.arange(1, len(xs))])
    mid = 0.5 * (pts[:-1] + pts[1:])
    cent = mid + (0.0, -0.05 if body_below else 0.05)
    return pts, facets, cent


def test_node_to_segment_interference_is_kept_beyond_the_snap():
    """A flat slave boundary 1e-3 below a flat master surface y = 0 (an interference), another
    2e-3 above it (a clearance), one at 1e-14 (on it, to rounding): node to segment with snap
    1e-9 gives the signed distances -1e-3, 2e-3 and exactly 0 (only gaps within the snap are
    zeroed, an interference is not)."""
    xm = np.linspace(-1.0, 1.0, 9)
    for y, want in ((-1e-3, -1e-3), (2e-3, 2e-3), (1e-14, 0.0)):
        ps, sf, sc = _flat_slave(np.linspace(-0.7, 0.7, 6), y)
        pm, mf, mc = _flat_master(xm, 0.0, len(ps))
        pr = pairing.node_to_segment(np.vstack([ps, pm]), sf, sc, mf, mc, snap=1e-9)
        assert pr.m == 6 and np.allclose(pr.normals, [0.0, -1.0], rtol=0, atol=0)
        assert np.allclose(pr.gap, want, rtol=1e-12, atol=0) and (want != 0.0 or not pr.gap.any()), (y, pr.gap)


def test_node_to_segment_takes_the_nearest_front_crossing_not_one_behind():
    """Slave nodes at y = -0.15, outer normal (0, -1), between two master layers: the master
    boundary has two surfaces facing that normal, y = 0 (layer A's top, behind the nodes: the ray
    meets it at t = -0.15) and y = -0.2 (layer B's top, ahead at t = 0.05).  The nearest crossing
    (smallest |t|) is the pairing: gap 0.05 on layer B -- not an interference of -0.15 through
    layer A."""
    ps, sf, sc = _flat_slave(np.linspace(-0.5, 0.5, 5), -0.15)
    xm = np.linspace(-1.0, 1.0, 6)
    top_a, fa, ca = _flat_master(xm, 0.0, len(ps))  # layer A's top, its body below (y in [-0.1, 0])
    bot_a, fb, cb = _flat_master(xm, -0.1, len(ps) + 6, body_below=False)  # layer A's bottom (a back face)
    top_b, fc, cc = _flat_master(xm, -0.2, len(ps) + 12)  # layer B's top
    pts = np.vstack([ps, top_a, bot_a, top_b])
    pr = pairing.node_to_segment(pts, sf, sc, np.vstack([fa, fb, fc]), np.vstack([ca, cb, cc]), snap=1e-9)
    assert pr.m == 5
    assert np.allclose(pr.gap, 0.05, rtol=1e-12, atol=0), pr.gap
    assert np.allclose(pr.projections[:, 1], -0.2, rtol=0, atol=1e-15)
    assert np.all(pr.master >= len(ps) + 12)


def test_node_to_segment_weights_near_a_master_vertex_are_the_shape_functions():
    """Slave nodes 1e-6 to 1e-3 along a master facet from its first node (a slightly offset mesh):
    the master weights are the linear shape functions (1 - xi, xi) exactly as far as rounding
    goes (snapped to (1, 0) only within WEIGHT_SNAP = 1e-12), so N u is the relative displacement
    of any affine field."""
    offs = np.array([1e-6, 1e-5, 1e-4, 1e-3])
    xm = np.arange(0.0, 6.0)  # master facets of length 1
    xs = np.concatenate([[-0.5], 1.0 + np.arange(4) + offs, [5.5]])
    ps, sf, sc = _flat_slave(xs, 0.01)
    pm, mf, mc = _flat_master(xm, 0.0, len(ps))
    pr = pairing.node_to_segment(np.vstack([ps, pm]), sf, sc, mf, mc, snap=1e-9)
    inner = np.isin(pr.slave, np.arange(1, 5))
    assert inner.sum() == 4
    xi = pr.weights[inner, 1]
    assert np.allclose(xi, offs, rtol=1e-9, atol=0), xi
    assert np.allclose(pr.weights.sum(axis=1), 1.0, rtol=0, atol=1e-15)
    # the rows of an affine field u(x) = (a x + b, c x + d) on the master, 0 on the slave
    a, b, c, d = 0.3, -0.2, 0.7, 0.1
    pts = np.vstack([ps, pm])
    pair, node, fac = pr.entries()
    U = np.column_stack([a * pts[:, 0] + b, c * pts[:, 0] + d])
    U[: len(ps)] = 0.0
    Nu = np.zeros(pr.m)
    np.add.at(Nu, pair, fac * np.sum(U[node] * pr.normals[pair], axis=1))
    xp = pr.projections[:, 0]
    assert np.allclose(Nu, -np.sum(np.column_stack([a * xp + b, c * xp + d]) * pr.normals, axis=1),
                       rtol=0, atol=1e-14)


def test_obstacle_pairing_of_a_flat_boundary_pressed_into_a_disc():
    """A flat boundary y = -1e-3 (its body above, outer normal (0, -1)) over a rigid disc of radius
    1 centred at (0, -1): the central nodes lie inside the disc (an interference), the outer ones
    outside.  Every node is paired, with the signed distance to the circle, hypot(x, y + 1) - 1
    (negative inside), and the disc's normal at the nearest point, -(x, y + 1) / hypot (analytic);
    only a gap within the snap is zeroed."""
    xs = np.linspace(-0.1, 0.1, 21)
    ps, sf, sc = _flat_slave(xs, -1e-3)
    disc = pairing.Circle((0.0, -1.0), 1.0)
    pr = pairing.obstacle_pairing(ps, sf, sc, disc, snap=1e-9)
    assert pr.m == 21 and pr.excluded.size == 0
    x = ps[pr.slave, 0]
    r = np.hypot(x, -1e-3 + 1.0)
    assert np.allclose(pr.gap, r - 1.0, rtol=1e-9, atol=1e-15) and (pr.gap < 0).sum() >= 3
    assert np.allclose(pr.normals, -np.column_stack([x, np.full_like(x, 1.0 - 1e-3)]) / r[:, None], rtol=0, atol=1e-15)


@pytest.mark.parametrize("angle, state", [(60.0, "slip+"), (120.0, "slip-"), (80.0, "stick")])
def test_a_node_closing_with_no_slip_continues_as_the_closed_form(angle, state):
    """Two uncoupled nodes; node B (gap 0.1) closes at alpha = 1/2 exactly where its tangential
    displacement vanishes too (its load passes through K (0, g): the apex of its shifted problem,
    while node A is loaded), so the direction it slips in is decided by the lexicographic rule.
    Beyond, node B's solutions are those of the one-node closed form for the load (alpha - 1/2) d
    (d at ``angle`` degrees: one solution each, slip+, slip- or stick)."""
    K1, K2 = np.array([[1.0, 0.3], [0.3, 1.0]]), np.array([[1.0, 0.5], [0.5, 1.0]])
    K = np.zeros((4, 4))
    K[:2, :2], K[2:, 2:] = K1, K2
    N = np.array([[0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    T = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    g, a_star, F = 0.1, 0.5, 0.3
    d = np.array([np.cos(np.radians(angle)), np.sin(np.radians(angle))])
    fB = K2 @ np.array([0.0, g])
    f1 = np.concatenate([[0.2, 1.0], fB - a_star * d])
    f2 = np.concatenate([[0.5, 1.2], fB + (1.0 - a_star) * d])
    system = cfcontact.ContactSystem.from_arrays(K, N, T, f1, f2, F, gap=np.array([0.0, g]))
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    assert path.status == "completed"
    closing = [t for t in path.transitions if t.node == 1]
    assert len(closing) == 1 and abs(closing[0].alpha - a_star) <= 1e-12
    for a in (0.5 + 1e-9, 0.7, 1.0):
        (ref_state, ref), = one_node_solutions(K2, F, (a - a_star) * d)
        sols = path.solutions_at(a)
        assert ref_state == state and [s.states()[1] for s in sols] == [state]
        sol = sols[0]
        got = np.array([sol.u[2], sol.u[3] - g, sol.lam_n[1], sol.lam_t[1]])
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12)
