"""cfcontact.critical: the friction at which a contact configuration can first make the path fold."""

import itertools
import json
import os
import subprocess
import sys

import numpy as np
import pytest
import scipy.linalg

from cfcontact.condensed import get_condensed_solver
from cfcontact.critical import critical_friction, first_sign_change, piece_matrices
from cfcontact.errors import InputError
from cfcontact.lumped import one_node, random_system
from cfcontact.system import ContactSystem

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.parametrize("K", [((1.0, 0.5), (0.5, 1.0)), ((1.0, -0.25), (-0.25, 2.0)), ((3.0, 0.1), (0.1, 0.5))])
def test_one_node_bound(K):
    """method.md: one node is unique for every load iff F |k_tn| < k_tt."""
    K = np.array(K)
    crit = critical_friction(one_node(K=K))
    assert crit.friction == pytest.approx(K[0, 0] / abs(K[0, 1]), rel=1e-10)
    assert crit.nodes == [0] and crit.states == ["slip+" if K[0, 1] > 0 else "slip-"]


def test_decoupled_nodes_take_the_smaller_bound():
    Ka, Kb = np.array([[1.0, 0.5], [0.5, 1.0]]), np.array([[2.0, -0.8], [-0.8, 1.0]])  # bounds 2 and 2.5
    K = scipy.linalg.block_diag(Ka, Kb)
    T = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    N = np.array([[0, 1.0, 0, 0], [0, 0, 0, 1.0]])
    system = ContactSystem.from_arrays(K, N, T, np.ones(4), np.ones(4), 1.0)
    crit = critical_friction(system)
    assert crit.friction == pytest.approx(2.0, rel=1e-10) and crit.nodes == [0]
    # the piece of node 1 alone changes sign at its own bound
    S = np.linalg.inv(K)
    B = np.vstack([N, T])
    assert first_sign_change(*piece_matrices(B @ S @ B.T, [1], [], [-1])) == pytest.approx(2.5, rel=1e-10)


def test_random_lumped_scan_agrees_with_determinant_grid():
    """Independent check: the determinant of each scanned piece, sampled on a fine F grid, keeps its
    sign below the reported F for every piece, and one piece has changed sign just above it."""
    system = random_system(3, seed=4, coupling=3.0)
    crit = critical_friction(system, window=3, stick_window=3)
    assert np.isfinite(crit.friction)
    S = get_condensed_solver(system).S
    grid = np.linspace(0.0, crit.friction * (1 - 1e-6), 400)
    for L in (1, 2, 3):
        for i0 in range(3 - L + 1):
            nodes = list(range(i0, i0 + L))
            for r in range(L):
                for stick in itertools.combinations(nodes, r):
                    for signs in itertools.product((1, -1), repeat=L):
                        M0, M1 = piece_matrices(S, nodes, stick, signs)
                        assert all(np.linalg.det(M0 + F * M1) > 0 for F in grid)
    M0, M1 = piece_matrices(S, crit.nodes, [i for i, s in zip(crit.nodes, crit.states) if s == "stick"],
                            [1 if s != "slip-" else -1 for s in crit.states])
    assert np.linalg.det(M0 + crit.friction * (1 + 1e-6) * M1) < 0


def test_bad_input():
    with pytest.raises(InputError, match="window must be an integer >= 1, got 0"):
        critical_friction(one_node(), window=0)
    with pytest.raises(InputError, match="stick_window"):
        critical_friction(one_node(), stick_window=-1)


@pytest.mark.slow
def test_demo_script_quick(tmp_path):
    """The shipped scan: mirror-identical blocks never fold (zero coupling, method.md); two steel
    blocks can fold below F = 30, where the benchmark's blocks fold, but not at 0.6; the main
    demo's steel block on a soft layer at a smaller F (0.56 on the demo's mesh; the coarse one
    here gives about 1.07)."""
    out = tmp_path / "crit.json"
    subprocess.run([sys.executable, os.path.join(ROOT, "demos", "critical_friction.py"), "--quick", "--json", str(out)],
                   check=True, capture_output=True)
    rows = {r["model"]: r for r in json.loads(out.read_text())}
    assert rows["equal blocks (height2 = height)"]["critical_friction"] == float("inf")
    blocks = rows["two steel blocks (height2 = 0.5), quadrilaterals"]["critical_friction"]
    assert 1.0 < blocks < 30.0
    soft = [r for k, r in rows.items() if k.startswith("main demo model")][0]["critical_friction"]
    assert soft < 0.6 * blocks
