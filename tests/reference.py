"""Independent references for the tests (no cfcontact import here).

one_node_solutions: the closed-form solutions of method.md's one-node problem.
frictionless_dual: F = 0 solved as the dual QP min_{lam >= 0} 1/2 lam^T S lam - lam^T (w - g)
by SciPy's NNLS on a Cholesky factor (S = N K^-1 N^T, w = N K^-1 f, g the initial gap).
"""

import numpy as np
import scipy.linalg as la
import scipy.optimize as opt
import scipy.sparse as sp
import scipy.sparse.linalg as spla


def one_node_solutions(K, F, f):
    """All solutions (u_t, u_n, p, lam_t) of the one-node problem of method.md, by the closed form."""
    (ktt, ktn), (_, knn) = np.asarray(K, dtype=float)
    ft, fn = f
    sols = []
    # separation: u = K^-1 f, valid iff ktt fn - ktn ft < 0
    if ktt * fn - ktn * ft < 0:
        u = np.linalg.solve(K, f)
        sols.append(("open", np.array([u[0], u[1], 0.0, 0.0])))
    # stick: u = 0, valid iff fn >= 0 and |ft| <= F fn
    if fn >= 0 and abs(ft) <= F * fn:
        sols.append(("stick", np.array([0.0, 0.0, fn, ft])))
    for s in (+1, -1):
        den = ktt - s * F * ktn
        if den == 0:
            continue
        ut = (ft - s * F * fn) / den
        p = (ktt * fn - ktn * ft) / den
        if s * ut > 0 and p >= 0:
            # K u = f + r, r = (-lam_t, -p) with lam_t = s F p
            sols.append(("slip+" if s > 0 else "slip-", np.array([ut, 0.0, p, s * F * p])))
    return sols


def alpha_of_tan(system, tan):
    """alpha at which the one-node load f(alpha) has direction atan(tan) (closed form)."""
    th = np.arctan(tan)
    f1, f2 = system.loads_numpy()
    c1 = f1[0] * np.sin(th) - f1[1] * np.cos(th)
    c2 = f2[0] * np.sin(th) - f2[1] * np.cos(th)
    return c1 / (c1 - c2)


def state_solve(K, N, T, F, gap, states, f):
    """y = (u, lam_n, lam_t) of fixed per-node states for the load f, from J(Z) written out densely
    (docs/theory.md (5)): K u + N^T lam_n + T^T lam_t = f, and per node: open lam_n = lam_t = 0;
    stick N u = g, T u = 0; slip+- N u = g, lam_t = +-F lam_n.  None if J(Z) is singular."""
    n, m = K.shape[0], N.shape[0]
    A = np.zeros((n + 2 * m, n + 2 * m))
    b = np.zeros(n + 2 * m)
    A[:n, :n], A[:n, n:n + m], A[:n, n + m:] = K, N.T, T.T
    b[:n] = f
    for i, st in enumerate(states):
        rn, rt = n + i, n + m + i
        if st == "open":
            A[rn, n + i] = 1.0
            A[rt, n + m + i] = 1.0
        else:
            A[rn, :n] = N[i]
            b[rn] = gap[i]
            if st == "stick":
                A[rt, :n] = T[i]
            else:
                A[rt, n + m + i] = 1.0
                A[rt, n + i] = -F[i] if st == "slip+" else F[i]
    try:
        return np.linalg.solve(A, b)
    except np.linalg.LinAlgError:
        return None


def frictionless_dual(K, N, f, gap=None):
    """(u, lam) of the frictionless problem K u + N^T lam = f, N u <= g, lam >= 0, lam^T (N u - g) = 0."""
    K = sp.csc_matrix(K)
    N = sp.csr_matrix(N)
    lu = spla.splu(K)
    KinvNT = lu.solve(N.T.toarray())
    S = N @ KinvNT
    S = 0.5 * (S + S.T)
    w = N @ lu.solve(f)
    if gap is not None:
        w = w - np.asarray(gap, dtype=float)
    L = la.cholesky(S, lower=True)  # S = L L^T
    # 1/2 lam^T S lam - lam^T w = 1/2 ||L^T lam - L^-1 w||^2 + const  (w includes -g)
    b = la.solve_triangular(L, w, lower=True)
    lam, _ = opt.nnls(L.T, b, maxiter=50 * S.shape[0])
    u = lu.solve(f - N.T @ lam)
    return u, lam
