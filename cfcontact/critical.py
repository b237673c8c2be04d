"""Where folds become possible: the smallest friction coefficient at which a small contact
configuration's DirNeu matrix loses its sign (a scan, not a proof).

Along a piecewise-affine solution path (docs/theory.md, "Path following") the path turns back in
alpha (a fold) exactly where it passes from one linear piece into a neighbour whose DirNeu
matrix has the opposite determinant sign.  In the condensed form (:mod:`cfcontact.condensed`,
S = B K^-1 B^T) a piece is fixed by its contact set C (nodes in contact), the stick nodes
St in C and the slip signs s of the others; its matrix in the unknowns lam_n(C), lam_t(St) is

    M(F) = [ S_nn[C,C] + F S_nt[C,Sl] D_s   S_nt[C,St] ]      (lam_t(Sl) = F s lam_n(Sl))
           [ S_tn[St,C] + F S_tt[St,Sl] D_s  S_tt[St,St] ]

For F = 0 it is a principal submatrix of the SPD S, so det M > 0; it is affine in F, and its
determinant first changes sign at the smallest positive real generalized eigenvalue of
(M(0), -dM/dF).  Below that F no path can fold through this piece.  One node against a rigid
foundation gives F = k_tt / |k_tn| (docs/theory.md's uniqueness bound).

:func:`critical_friction` scans windows of up to ``window`` neighbouring contact nodes (the
interface order of the system), every slip-sign pattern, and every stick subset of windows
of up to ``stick_window`` nodes; it returns the smallest such F with its configuration.  It
is a scan: configurations outside it (wider or non-contiguous contact sets) can only lower
the true threshold, so the result is an upper bound for the onset of folds, and a useful
measure of how strongly a model couples normal and tangential contact displacements.

An initial gap (:attr:`ContactSystem.gap`) does not enter: it shifts the right-hand side
w = B K^-1 f - (g; 0) of every piece, not its matrix, so it moves where a path meets a piece but
not whether the piece folds.  Loads do not enter either.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
import numpy as np
import scipy.linalg as sla

from cfcontact.errors import InputError
from cfcontact.system import ContactSystem

#: Entries of S below this fraction of its largest entry are rounding noise (e.g. the zero
#: normal-tangential coupling of mirror-symmetric bodies) and are set to zero.
ROUNDING = 1e-10


@dataclass
class CriticalConfiguration:
    """The smallest F found and the piece whose determinant vanishes there.

    ``states[i]`` is "stick", "slip+" or "slip-" for contact node ``nodes[i]``; every other node
    is open.  ``friction`` is ``inf`` when no scanned piece changes sign.
    """

    friction: float
    nodes: list = field(default_factory=list)
    states: list = field(default_factory=list)
    scanned: int = 0

    def __str__(self):
        if not np.isfinite(self.friction):
            return f"no sign change in {self.scanned} configurations"
        pieces = ", ".join(f"{i}:{s}" for i, s in zip(self.nodes, self.states))
        return f"F = {self.friction:.6g} ({pieces}; {self.scanned} configurations scanned)"


def piece_matrices(S: np.ndarray, nodes, stick, signs):
    """(M0, M1) with M(F) = M0 + F M1 for contact nodes ``nodes``, stick subset ``stick`` and slip
    signs ``signs`` (one per node of ``nodes``, ignored for stick nodes)."""
    m = S.shape[0] // 2
    C = np.asarray(nodes, dtype=int)
    St = np.asarray([i for i in C if i in set(stick)], dtype=int)
    sl_mask = ~np.isin(C, St)
    Sl = C[sl_mask]
    s = np.asarray(signs, dtype=float)[sl_mask]
    rows_n, rows_t = C, m + St
    cols_n, cols_t = C, m + St
    M0 = np.block([[S[np.ix_(rows_n, cols_n)], S[np.ix_(rows_n, cols_t)]],
                   [S[np.ix_(rows_t, cols_n)], S[np.ix_(rows_t, cols_t)]]])
    M1 = np.zeros_like(M0)
    pos = np.flatnonzero(sl_mask)  # columns of lam_n(Sl) in M
    M1[:, pos] = np.vstack([S[np.ix_(rows_n, m + Sl)], S[np.ix_(rows_t, m + Sl)]]) * s[None, :]
    return M0, M1


def first_sign_change(M0: np.ndarray, M1: np.ndarray, rel: float = 1e-7) -> float:
    """Smallest F > 0 where det(M0 + F M1) changes sign (inf if none)."""
    if not np.any(M1):
        return np.inf
    ev = sla.eigvals(M0, -M1)
    ev = ev[np.isfinite(ev)]
    cand = np.sort(ev.real[(ev.real > 0) & (np.abs(ev.imag) <= 1e-9 * np.abs(ev))])
    sign0 = np.linalg.slogdet(M0)[0]
    for F in cand:
        below = np.linalg.slogdet(M0 + F * (1 - rel) * M1)[0]
        above = np.linalg.slogdet(M0 + F * (1 + rel) * M1)[0]
        if below == sign0 and above != sign0:
            return float(F)
    return np.inf


def critical_friction(system: ContactSystem, window: int = 6, stick_window: int = 4,
                      solver=None) -> CriticalConfiguration:
    """Scan the small contact configurations of ``system`` (see the module docstring).

    ``solver``: a :class:`~cfcontact.condensed.CondensedSolver` of the system (default: the
    system's cached one), used only for S.  Cost: about m 2^window (4^stick_window) small
    eigenvalue problems; a few seconds for m = 30 with the defaults.
    """
    from cfcontact.condensed import CondensedSolver, get_condensed_solver

    for name, val, lo in (("window", window, 1), ("stick_window", stick_window, 0)):
        if isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < lo:
            raise InputError(f"{name} must be an integer >= {lo}, got {val!r}")
    solver = solver if isinstance(solver, CondensedSolver) else get_condensed_solver(system)
    S = np.array(solver.S, copy=True)
    S[np.abs(S) <= ROUNDING * np.abs(S).max(initial=0.0)] = 0.0  # couplings that vanish up to rounding
    m = system.m
    best = CriticalConfiguration(np.inf)
    count = 0
    for L in range(1, min(int(window), m) + 1):
        for i0 in range(m - L + 1):
            nodes = list(range(i0, i0 + L))
            stick_sets = ([()] if L > stick_window else
                          [c for r in range(L) for c in itertools.combinations(nodes, r)])
            for stick in stick_sets:
                for signs in itertools.product((1, -1), repeat=L):
                    if any(signs[k] == -1 for k, i in enumerate(nodes) if i in stick):
                        continue  # a stick node's sign is irrelevant: count it once
                    count += 1
                    F = first_sign_change(*piece_matrices(S, nodes, stick, signs))
                    if F < best.friction:
                        states = ["stick" if i in stick else ("slip+" if sg > 0 else "slip-")
                                  for i, sg in zip(nodes, signs)]
                        best = CriticalConfiguration(F, nodes, states)
    best.scanned = count
    return best

