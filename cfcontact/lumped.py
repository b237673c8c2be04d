"""Lumped (non-FEM) contact models driven through the same solver code.

``one_node`` is docs/theory.md's exact one-node check: one contact node against a rigid
foundation, u = (u_t, u_n), N = [0, 1], T = [1, 0].  ``random_system`` draws small
random SPD models (tests, property-based checks).
"""

from __future__ import annotations

import numpy as np

from cfcontact.system import ContactSystem


def one_node(friction=2.5, K=((1.0, 0.5), (0.5, 1.0)), f1=None, f2=None, rho=None, comm=None,
             gap=None) -> ContactSystem:
    """One node against a rigid foundation (docs/theory.md).  DOF order (u_t, u_n).

    Default loads: unit forces at 15 and 35 degrees from the tangential axis, so the
    load direction sweeps through the wedge atan(0.4)..atan(0.5) of three solutions.
    ``gap``: initial gap g (u_n <= g), default 0.
    """
    K = np.asarray(K, dtype=float)
    f1 = np.array([np.cos(np.radians(15.0)), np.sin(np.radians(15.0))]) if f1 is None else np.asarray(f1, float)
    f2 = np.array([np.cos(np.radians(35.0)), np.sin(np.radians(35.0))]) if f2 is None else np.asarray(f2, float)
    N = np.array([[0.0, 1.0]])
    T = np.array([[1.0, 0.0]])
    return ContactSystem.from_arrays(K, N, T, f1, f2, friction, rho=rho, comm=comm, gap=gap)


def random_system(m: int, seed: int, friction=1.0, extra_dofs: int = 2, coupling: float = 1.0,
                  comm=None, gap=None) -> ContactSystem:
    """A random small model: m contact nodes, each with a 2-D relative displacement, plus extra DOFs.

    K = A A^T + c I (SPD) with dense coupling; N, T pick the normal and tangential DOF of each
    node; f1, f2 random with a net push into contact (so contact is not trivially open).
    ``gap``: initial gaps (a number or one per node; default 0).
    """
    rng = np.random.default_rng(seed)
    n = 2 * m + extra_dofs
    A = rng.standard_normal((n, n))
    K = coupling * (A @ A.T) / n + np.eye(n)
    N = np.zeros((m, n))
    T = np.zeros((m, n))
    for i in range(m):
        T[i, 2 * i] = 1.0
        N[i, 2 * i + 1] = 1.0
    f1 = rng.standard_normal(n)
    f2 = rng.standard_normal(n)
    f1[1:2 * m:2] += 1.0
    f2[1:2 * m:2] += 1.0
    return ContactSystem.from_arrays(K, N, T, f1, f2, friction, comm=comm, gap=gap)
