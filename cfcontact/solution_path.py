"""The result model of path following: :class:`SolutionPath` and its parts.

The solution path is a chain (a tree, with :func:`cfcontact.exact.follow_alternative`) of
oriented linear branches (inactive sets Z fixed, orientation s = +-1) joined at transition
points.  Along a branch y is affine in alpha, exactly; every branch stores it in *reference
form*: a reference alpha_r, the point there and the rate, y(alpha) = Y_r + (alpha - alpha_r) Y'
(the exact method takes the branch's entry as reference, so a branch keeps full accuracy near
its own alpha range however large its values at alpha = 0 and 1 would be; the seed method gives
Y1 = DirNeu(Z, f1) and Y2 = DirNeu(Z, f2), i.e. alpha_r = 0).
:meth:`SolutionPath.solutions_at` evaluates branches exactly (no interpolation between stored
points), also after :meth:`SolutionPath.load`.

Lazy branches: with the condensed backend (:class:`cfcontact.condensed.CondensedSolver`) a
branch is determined by its multipliers, lam(alpha) = lam_r + (alpha - alpha_r) lam', and the
exact method stores only those, the indicators in the same form and the backend.
The displacements u = K^-1 (f - B^T lam) of such branches (and of their stored points) are
formed when first needed (``ys``, ``points``, ``branch_y``, ``solutions_at``, ``save``), for
many branches at once in one multi-right-hand-side solve.  ``multiplicity``,
``max_multiplicity``, :meth:`SolutionPath.multiplicity_intervals` and the multiplier
components of ``component`` need no u at all.

The multiplicity scan (number of distinct solutions between consecutive branch ends) runs once
per state of the path and is cached: :meth:`~SolutionPath.max_multiplicity`,
:meth:`~SolutionPath.multiplicity_intervals`, :meth:`~SolutionPath.summary`, the CLI's reports
and :func:`cfcontact.plotting.plot_multiplicity` share it.

This module needs NumPy, SciPy and the semi-smooth Newton layer's set objects only.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from dataclasses import asdict, dataclass, field
from typing import Optional

import numpy as np
import scipy.sparse as sp

from cfcontact.errors import InputError
from cfcontact.jsonio import blocking_file, holds_format, jsonable
from cfcontact.options import METHODS
from cfcontact.ssnm import STATE_NAMES, InactiveSets, Solution
from cfcontact.system import ContactGeometry, ContactSystem, check_alpha

#: Version 2 stores the branches in reference form (alpha_ref, Y_ref, dY) and the gap; version 1
#: (Y1, Y2 at alpha = 0 and 1, no gap) still loads.
FORMAT_VERSION = 2
SET_NAMES = ("nu", "tp", "tm")  # which indicator of (17): normal, slip+, slip-
#: Every status a path can have (a saved path with another one is refused on load)
STATUSES = ("running", "completed", "stopped by callback", "stuck", "cycling", "closed_loop", "max_transitions",
            "max_steps")


def parameter_name(parameter: str) -> str:
    """A path parameter's name in messages and pictures: "alpha", or "F" for "friction" (a path
    over the friction coefficient)."""
    return "F" if parameter == "friction" else "alpha"


class PathPoint:
    """An accepted point of the path (what the callback sees): its index, alpha, branch and the
    live path.  ``solution`` (a :class:`~cfcontact.ssnm.Solution`) is formed when first asked
    for: a callback that reads only alpha and the path forms no displacement (on a lazy path that
    would cost a solve with K per point)."""

    __slots__ = ("index", "alpha", "branch", "path", "_solution", "_make")

    def __init__(self, index: int, alpha: float, branch: int, solution=None, path=None, make=None):
        self.index, self.alpha, self.branch, self.path = int(index), float(alpha), int(branch), path
        self._solution, self._make = solution, make

    @property
    def solution(self) -> Solution:
        if self._solution is None and self._make is not None:
            self._solution, self._make = self._make(), None
        return self._solution

    def __repr__(self):
        return f"PathPoint(index={self.index}, alpha={self.alpha!r}, branch={self.branch})"


def _size(x) -> float:
    """max |x| (0 for an empty array)."""
    return float(np.abs(np.asarray(x, dtype=float)).max(initial=0.0))


@dataclass
class Branch:
    """An oriented linear branch: inactive sets, orientation and the points the path took on it.

    alpha_enter / alpha_exit: where the path entered and left the branch (estimates at
    transitions for the seed method, exact for the exact method).
    origin: index of the transition that started it (None for the first branch).
    """

    index: int
    sets: InactiveSets
    orientation: int
    points: list = field(default_factory=list)
    alpha_enter: float = float("nan")
    alpha_exit: float = float("nan")
    origin: Optional[int] = None
    parent: Optional[int] = None

    def to_dict(self) -> dict:
        return {"index": self.index, "sets": self.sets.to_dict(), "states": self.sets.states(),
                "orientation": self.orientation, "points": list(map(int, self.points)),
                "alpha_enter": self.alpha_enter, "alpha_exit": self.alpha_exit,
                "origin": self.origin, "parent": self.parent}

    @classmethod
    def from_dict(cls, d) -> "Branch":
        return cls(index=d["index"], sets=InactiveSets.from_dict(d["sets"]), orientation=d["orientation"],
                   points=list(d["points"]), alpha_enter=d["alpha_enter"], alpha_exit=d["alpha_exit"],
                   origin=d["origin"], parent=d.get("parent"))


@dataclass
class Transition:
    """A transition point between two branches.

    kind: "transversal" (alpha keeps its direction) or "fold" (alpha turns back).
    node, set: the contact node and the set ("nu": A_nu <-> I_nu, "tp": A_t <-> I_t^+,
        "tm": A_t <-> I_t^-) that changed (where a change moves the node in or out of two
        sets, both methods name the first of nu, tp, tm: a node that opens is "nu");
        ``changes`` lists all of them when several nodes changed.
    alpha: the transition parameter (seed: last point before it, within the bracket;
        exact: the root of the indicator).  bracket: (lo, hi) known to contain it.
    pivots: at a degenerate point of the exact method, the single facet crossings (node, set,
        from, to, orientation) by which its lexicographic rule went from branch to branch.
    """

    index: int
    alpha: float
    kind: str
    node: int
    set: str
    from_branch: int
    to_branch: int
    bracket: tuple = (float("nan"), float("nan"))
    changes: list = field(default_factory=list)
    pivots: list = field(default_factory=list)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["bracket"] = list(self.bracket)
        if not d["pivots"]:
            del d["pivots"]  # (the form of paths saved before pivots existed)
        return d

    @classmethod
    def from_dict(cls, d) -> "Transition":
        d = dict(d)
        d["bracket"] = tuple(d["bracket"])
        return cls(**d)


@dataclass
class PathEvent:
    """Something the run could not handle normally (reported, never silent)."""

    kind: str
    alpha: float
    message: str
    branch: Optional[int] = None
    data: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)


#: Lazy branches are formed together (one batch) when their displacements take at most this
#: many doubles; beyond it only the branches asked for are formed.
BATCH_LIMIT = 200_000_000


class _Points(list):
    """y of every stored point.  An entry None lies on a lazy branch (multipliers only) and is
    formed on first access (indexing, iteration); the list then holds the array."""

    __slots__ = ("_path",)

    def __init__(self, path, items=()):
        super().__init__(items)
        self._path = path

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[j] for j in range(len(self))[i]]
        v = list.__getitem__(self, i)
        if v is None:
            j = i + len(self) if i < 0 else i
            self._path._form_points([j])
            v = list.__getitem__(self, j)
        return v

    def __iter__(self):
        self._path._form_points(range(len(self)))
        return list.__iter__(self)

    def __reduce__(self):
        return (list, (list(self),))


class SolutionPath:
    """The traced solution path: points, branches, transitions, and exact branch evaluation."""

    #: The ``format`` of a saved path of this class (:meth:`load` reads only its own; a path over
    #: another parameter, :class:`cfcontact.friction.FrictionPath`, has its own).
    FORMAT = "cfcontact-path"
    #: the path's parameter: "alpha" (the load path), "friction" for a path over F (FrictionPath)
    parameter = "alpha"

    @property
    def parameter_name(self) -> str:
        """The parameter's name in messages and pictures (:func:`parameter_name`)."""
        return parameter_name(self.parameter)

    def __init__(self, n, m, N, T, friction, rho, method, alpha_start, alpha_end, options=None,
                 geometry: Optional[ContactGeometry] = None, gap=None):
        self.n, self.m = int(n), int(m)
        self.N, self.T = sp.csr_matrix(N), sp.csr_matrix(T)
        self.gap = np.zeros(self.m) if gap is None else np.asarray(gap, dtype=float).reshape(self.m)
        self.friction = friction
        self.rho = float(rho)
        self.method = method
        self.alpha_start, self.alpha_end = float(alpha_start), float(alpha_end)
        self.options = options or {}
        self.geometry = geometry
        self._alphas: list = []
        self._ys: list = _Points(self)
        self._point_branch: list = []
        self.branches: list = []
        self.transitions: list = []
        self.events: list = []
        self.status = "running"
        self.stats: dict = {}
        self.resume_state: Optional[dict] = None  # state to continue a stopped run (trace_path(resume=...))
        self._Y: dict = {}  # branch index -> (alpha_ref, Y_ref, dY)
        # lazy branches: index -> (alpha_ref, lam_ref, dlam); indicators (alpha_ref, g_ref, dg: 3m);
        # unformed -> backend
        self._lam: dict = {}
        self._ind: dict = {}
        self._pending: dict = {}
        self._scan = None  # cached multiplicity scan: (key, [(a, b, k)])
        #: SHA-256 of the system the path belongs to (:meth:`ContactSystem.checksum`), None if unknown
        self.system_checksum: Optional[str] = None

    # ------------------------------------------------------------- building
    @classmethod
    def for_system(cls, system: ContactSystem, method, alpha_start, alpha_end, options=None):
        N, T = system.contact_maps()
        path = cls(system.n, system.m, N, T, system.friction, system.rho, method, alpha_start, alpha_end,
                   options, system.geometry, getattr(system, "gap", None))
        path.system_checksum = system.checksum()
        return path

    def add_branch(self, sets, orientation, Y1, Y2, origin=None, parent=None, alpha_enter=float("nan"),
                   multipliers=None, indicators=None, source=None, reference=None):
        """Append a branch.

        ``reference=None``: Y1, Y2 are its points at alpha = 0 and 1, y(alpha) = (1 - alpha) Y1 +
        alpha Y2.  ``reference=alpha_r``: Y1 is its point at alpha_r and Y2 its rate, y(alpha) =
        Y1 + (alpha - alpha_r) Y2 (likewise for ``multipliers`` and ``indicators``).

        Lazy form: Y1 = Y2 = None, ``multipliers`` (2m each), ``source`` = a backend with
        ``displacements(lams, alphas)`` (:class:`~cfcontact.condensed.CondensedSolver`) that forms
        u when needed, optionally ``indicators``: the three indicator vectors of (17) stacked (3m)."""
        b = Branch(len(self.branches), sets, int(orientation), origin=origin, parent=parent, alpha_enter=alpha_enter)
        self.branches.append(b)

        def ref_form(pair):
            x, z = np.asarray(pair[0], dtype=float), np.asarray(pair[1], dtype=float)
            return (0.0, x, z - x) if reference is None else (float(reference), x, z)

        if Y1 is None:
            if multipliers is None or source is None:
                raise InputError("a lazy branch needs multipliers and a source backend")
            self._lam[b.index] = ref_form(multipliers)
            if indicators is not None:
                self._ind[b.index] = ref_form(indicators)
            self._pending[b.index] = source
        else:
            self._Y[b.index] = ref_form((Y1, Y2))
        return b

    def end_branch_at(self, branch, alpha, lam, indicators=None, y=None):
        """Make a branch pass through its exit point at alpha: a lazy branch through (alpha, lam)
        (and the indicators, 3m, when given), a branch with displacements through ``y`` (the
        whole point, or a function that forms it; lam and indicators are then ignored).  Its
        values become the chord from its reference point to there.  The exact method passes the
        next branch's entry point, a fresh solve at the transition, and at the end of the range
        a solve there, so that the branch's exit point is not extrapolated from its entry along
        rates that carry its rounding (on a slender body a steep slip rate, 1e13 per unit alpha,
        put a stored exit 47 N off its own vanishing condition); every linear condition that
        holds at both ends (the branch's equations) holds along the chord.

        The branch is then referenced at whichever end has the smaller multipliers (the smaller
        relative displacements B u, or displacements, where both ends have the same): values
        read off the chord carry the rounding of its reference point, so a branch that unloads
        towards zero (its exit at a load f = 0, say) keeps its exit exact instead of a remainder
        of its entry's size, which against the exit's own size is no solution (1e-16 of the
        entry's values: equilibrium residuals of 2e-5 to 1 of the point's own size)."""
        b = branch.index if isinstance(branch, Branch) else int(branch)
        alpha = float(alpha)
        if b in self._lam:
            a_r, lr, _ = self._lam[b]
            da = alpha - a_r
            if da == 0.0:
                return
            lam = np.array(lam, dtype=float)
            ind = self._ind.get(b) if indicators is not None else None
            if ind is not None and ind[0] != a_r:
                ind = None
            # (an open branch, lam = 0 at both ends: by its relative displacements B u, formed only then)
            s_exit, s_ref = _size(lam), _size(lr)
            at_exit = s_exit < s_ref or (s_exit == s_ref and ind is not None and
                                         self._contact_size(lam, indicators) < self._contact_size(lr, ind[1]))
            dl = (lam - lr) / da
            self._lam[b] = (alpha, lam, dl) if at_exit else (a_r, lr, dl)
            if ind is not None:
                gx = np.array(indicators, dtype=float)
                dg = (gx - ind[1]) / da
                self._ind[b] = (alpha, gx, dg) if at_exit else (a_r, ind[1], dg)
        elif y is not None and b in self._Y:
            a_r, Yr, _ = self._Y[b]
            da = alpha - a_r
            if da == 0.0:
                return
            y = np.array(y() if callable(y) else y, dtype=float)
            n = self.n
            dY = (y - Yr) / da
            at_exit = (_size(y[n:]), _size(y[:n])) < (_size(Yr[n:]), _size(Yr[:n]))
            self._Y[b] = (alpha, y, dY) if at_exit else (a_r, Yr, dY)

    def _contact_size(self, lam, ind) -> float:
        """max |B u| of a point given by its multipliers and indicators (a, bp, bm) of (17):
        N u - g = (a - lam_n) / rho, T u = ((bp + bm) / 2 - lam_t) / rho."""
        m = self.m
        lam, ind = np.asarray(lam, dtype=float), np.asarray(ind, dtype=float)
        nu = (ind[:m] - lam[:m]) / self.rho + self.gap
        tu = (0.5 * (ind[m:2 * m] + ind[2 * m:]) - lam[m:]) / self.rho
        return max(_size(nu), _size(tu))

    def start_branch_at(self, branch, alpha, lam, indicators=None):
        """Make a lazy branch referenced at ``alpha`` start from (alpha, lam) (and the indicators,
        3m): its reference values are replaced, its rates kept.  The exact method passes the
        previous branch's exit where that locates the transition point more precisely than the
        new branch's own solve (see ``exact._precise_side``)."""
        b = branch.index if isinstance(branch, Branch) else int(branch)
        if b not in self._lam or self._lam[b][0] != float(alpha):
            return
        a_r, _, dl = self._lam[b]
        self._lam[b] = (a_r, np.array(lam, dtype=float), dl)
        if indicators is not None and b in self._ind and self._ind[b][0] == a_r:
            self._ind[b] = (a_r, np.array(indicators, dtype=float), self._ind[b][2])

    def drop_branch_values(self, branch) -> None:
        """Forget a lazy branch's values (multipliers, indicators, the backend that forms its u):
        for a walk that reads only its last branches and keeps no points of the others (the exact
        method's homotopy starts)."""
        b = branch.index if isinstance(branch, Branch) else int(branch)
        for store in (self._lam, self._ind, self._pending):
            store.pop(b, None)

    def add_point(self, branch: Branch, alpha, y=None) -> int:
        """Append a point; y=None: the point of ``branch`` at alpha (formed lazily on a lazy branch)."""
        if y is None and branch.index not in self._Y:
            if branch.index not in self._pending:
                raise InputError(f"add_point without y needs a lazy branch (branch {branch.index} is not)")
        elif y is None:
            y = self.branch_y(branch, alpha)
        self._alphas.append(float(alpha))
        self._ys.append(None if y is None else np.asarray(y, dtype=float))
        self._point_branch.append(branch.index)
        idx = len(self._alphas) - 1
        branch.points.append(idx)
        return idx

    # ------------------------------------------------------------- accessors
    @property
    def alphas(self) -> np.ndarray:
        """alpha of every stored point, in path order."""
        return np.asarray(self._alphas, dtype=float)

    @property
    def ys(self) -> np.ndarray:
        """y = (u, lam_n, lam_t) of every stored point, (P, n + 2m)."""
        self._form_points(range(len(self._ys)))
        return np.asarray(list(self._ys), dtype=float).reshape(len(self._ys), self.n + 2 * self.m)

    def point_y(self, i: int) -> np.ndarray:
        """y of stored point ``i`` (a lazy path forms the displacements of that point's branch only)."""
        return self._ys[int(i)]

    @property
    def lams(self) -> np.ndarray:
        """(lam_n, lam_t) of every stored point, (P, 2m): no displacement is formed."""
        if not self._pending:
            return self.ys[:, self.n:]
        return np.asarray([self._point_lam(i) for i in range(len(self._alphas))], dtype=float).reshape(
            len(self._alphas), 2 * self.m)

    @property
    def point_branch(self) -> np.ndarray:
        return np.asarray(self._point_branch, dtype=int)

    @property
    def points(self):
        """[(alpha, y)] in path order."""
        return list(zip(self._alphas, self._ys))

    @property
    def folds(self) -> list:
        return [t for t in self.transitions if t.kind == "fold"]

    def branch_y(self, branch, alpha) -> np.ndarray:
        """y on a branch at alpha, exactly: Y_ref + (alpha - alpha_ref) dY."""
        b = branch.index if isinstance(branch, Branch) else int(branch)
        if b not in self._Y:
            self.form([b])
        a_r, Yr, dY = self._Y[b]
        return Yr + (alpha - a_r) * dY

    # ------------------------------------------------------- lazy branches
    @property
    def lazy(self) -> bool:
        """Does the path have branches whose displacements are not formed yet?"""
        return bool(self._pending)

    def form(self, branches=None):
        """Form the displacements of lazy branches (default: all): u at the reference alpha and at
        one more (the rate is their difference; f is affine in alpha), in one multi-RHS solve
        per backend.

        Collective under MPI (every rank must call it for the same branches).  When the
        requested branches are few, every pending branch is formed along with them as long as
        that batch stays within BATCH_LIMIT doubles."""
        want = sorted(self._pending) if branches is None else sorted({int(b) for b in branches} & set(self._pending))
        if not want:
            return
        if branches is not None and len(self._pending) * 2 * (self.n + 2 * self.m) <= BATCH_LIMIT:
            want = sorted(self._pending)
        by_source: dict = {}
        for b in want:
            by_source.setdefault(id(self._pending[b]), (self._pending[b], []))[1].append(b)
        for source, bs in by_source.values():
            lams = np.empty((2 * self.m, 2 * len(bs)))
            alphas = np.empty(2 * len(bs))
            for k, b in enumerate(bs):
                a_r, lr, dl = self._lam[b]
                lams[:, 2 * k], lams[:, 2 * k + 1] = lr, lr + dl
                alphas[2 * k], alphas[2 * k + 1] = a_r, a_r + 1.0
            imposed = np.repeat(np.column_stack([source.imposed_of_sets(self.branches[b].sets) for b in bs]), 2, axis=1)
            U = source.displacements(lams, alphas, imposed, np.tile([True, False], len(bs)))
            for k, b in enumerate(bs):
                a_r, lr, dl = self._lam[b]
                self._Y[b] = (a_r, np.concatenate([U[:, 2 * k], lr]),
                              np.concatenate([U[:, 2 * k + 1] - U[:, 2 * k], dl]))
                del self._pending[b]

    def _form_points(self, indices):
        """Replace the lazy entries (None) among the points ``indices`` by their y."""
        ys = self._ys
        idx = [i for i in indices if list.__getitem__(ys, i) is None]
        if not idx:
            return
        self.form({self._point_branch[i] for i in idx})
        for i in idx:
            list.__setitem__(ys, i, self.branch_y(self._point_branch[i], self._alphas[i]))

    def iter_points(self, batch: int = 256, indices=None):
        """(alpha, y) of every stored point (or of the points ``indices``) in path order, without
        keeping the displacements of lazy points: they are formed ``batch`` at a time (one
        multi-RHS solve) and dropped.  Collective under MPI.  For verifying large paths."""
        order = list(range(len(self._alphas))) if indices is None else [int(i) for i in indices]
        P, batch = len(order), max(1, int(batch))
        for c0 in range(0, P, batch):
            idx = order[c0:c0 + batch]
            lazy = [i for i in idx if list.__getitem__(self._ys, i) is None
                    and self._point_branch[i] in self._pending]
            formed = {}
            by_source: dict = {}
            for i in lazy:
                src = self._pending[self._point_branch[i]]
                by_source.setdefault(id(src), (src, []))[1].append(i)
            for src, ii in by_source.values():
                lams = np.stack([self._point_lam(i) for i in ii], axis=1)
                imposed = np.column_stack([src.imposed_of_sets(self.branches[self._point_branch[i]].sets) for i in ii])
                U = src.displacements(lams, [self._alphas[i] for i in ii], imposed)
                for k, i in enumerate(ii):
                    formed[i] = np.concatenate([U[:, k], lams[:, k]])
            for i in idx:
                yield self._alphas[i], formed[i] if i in formed else self._ys[i]

    def branch_lam(self, branch, alpha):
        """(lam_n, lam_t) on a branch (or its index) at alpha; a lazy branch forms no displacement."""
        b = branch.index if isinstance(branch, Branch) else int(branch)
        if b in self._lam:
            a_r, lr, dl = self._lam[b]
            return lr + (alpha - a_r) * dl
        return self.branch_y(b, alpha)[self.n:]

    def _point_lam(self, i):
        y = list.__getitem__(self._ys, i)
        if y is not None:
            return y[self.n:]
        return self.branch_lam(self._point_branch[i], self._alphas[i])

    def _branch_indicators(self, b, alpha):
        """(a, bp, bm) of (17) on branch b at alpha (from the stored indicators of a lazy branch)."""
        if b in self._ind:
            a_r, gr, dg = self._ind[b]
            g = gr + (alpha - a_r) * dg
            m = self.m
            return g[:m], g[m:2 * m], g[2 * m:]
        return self._indicators(self.branch_y(b, alpha))

    def _indicators(self, y):
        n, m = self.n, self.m
        u, ln, lt = y[:n], y[n:n + m], y[n + m:]
        F = np.broadcast_to(np.asarray(self.friction, dtype=float), (m,))
        a = ln + self.rho * (self.N @ u - self.gap)
        b = lt + self.rho * (self.T @ u)
        return a, b - F * ln, b + F * ln

    def _rounding(self, b, alpha) -> float:
        """What rounding can make of the indicators of formed branch b at alpha: y(alpha) = Y_ref +
        (alpha - alpha_ref) dY carries the rounding of its terms and of the data it was solved from,
        f(alpha) = (1 - alpha) f1 + alpha f2 (terms of the size of the rate dY), which near a point
        where the data vanish (a load reversed through zero) are far larger than y itself."""
        a_r, Yr, dY = self._Y[b]
        n, d = self.n, abs(alpha - a_r) + abs(a_r) + 1.0
        size_u = np.abs(Yr[:n]).max(initial=0) + d * np.abs(dY[:n]).max(initial=0)
        size_l = np.abs(Yr[n:]).max(initial=0) + d * np.abs(dY[n:]).max(initial=0)
        data = getattr(self, "_rounding_data", None)
        if data is None:  # (the path's N, T, friction and gap: computed once)
            data = self._rounding_data = (
                max(np.asarray(abs(A).sum(axis=1)).max(initial=0) for A in (self.N, self.T)),
                np.asarray(self.friction, dtype=float).max(initial=0),
                np.abs(np.asarray(self.gap, dtype=float)).max(initial=0))
        rows, F, gap = data
        return 16 * np.finfo(float).eps * ((1.0 + F) * size_l + self.rho * (rows * size_u + gap))

    def _consistent(self, y, sets, slack=1e-9, ind=None, floor=0.0):
        """Z(y) agrees with ``sets`` up to ties within ``slack`` (relative) or ``floor`` (absolute:
        the indicators' rounding); ``ind`` = (a, bp, bm) of y if known."""
        a, bp, bm = self._indicators(y) if ind is None else ind
        scale = max(np.abs(a).max(initial=0), np.abs(bp).max(initial=0), np.abs(bm).max(initial=0), 1e-300)
        tol = max(slack * scale, floor)
        F = np.broadcast_to(np.asarray(self.friction, dtype=float), (self.m,))
        free = sets.nu | (F == 0.0)
        ok_nu = np.where(sets.nu, a < tol, a > -tol)
        ok_tp = np.where(sets.tp, bp > -tol, bp < tol)
        ok_tm = np.where(sets.tm, bm < tol, bm > -tol)
        # open nodes / F = 0: only "tangentially free or stuck" matters
        it = sets.tp | sets.tm
        ok_free = np.where(it, (bp > -tol) | (bm < tol), (bp < tol) & (bm > -tol))
        ok_t = np.where(free, ok_free, ok_tp & ok_tm)
        return bool(np.all(ok_nu & ok_t))

    def branch_extent(self, branch, brackets: bool = False) -> tuple:
        """(lo, hi) of alpha covered by the path on this branch (transition to transition).
        ``brackets``: include the brackets of the branch's transitions (the seed method knows a
        transition only to within its bracket: the branch may hold in part of it)."""
        b = self.branches[branch] if not isinstance(branch, Branch) else branch
        vals = [self._alphas[i] for i in b.points]
        for a in (b.alpha_enter, b.alpha_exit):
            if np.isfinite(a):
                vals.append(a)
        if brackets:
            vals += self._bracket_ends().get(b.index, [])
        return (min(vals), max(vals)) if vals else (np.nan, np.nan)

    def _bracket_ends(self) -> dict:
        """{branch index: the finite bracket ends of its transitions} (cached per transition count)."""
        cache = getattr(self, "_brackets", None)
        if cache is None or cache[0] != len(self.transitions):
            ends: dict = {}
            for t in self.transitions:
                lo, hi = t.bracket
                if np.isfinite(lo) and np.isfinite(hi) and hi > lo:
                    for b in (t.from_branch, t.to_branch):
                        ends.setdefault(b, []).extend((float(lo), float(hi)))
            cache = (len(self.transitions), ends)
            self._brackets = cache
        return cache[1]

    def solutions_at(self, alpha: float, rtol: float = 1e-9) -> list:
        """Every distinct solution the path has at ``alpha``, evaluated exactly on each branch crossing it.

        Returns a list of :class:`Solution` sorted by branch order.
        """
        alpha = check_alpha(alpha)
        if not (isinstance(rtol, (int, float, np.floating, np.integer)) and not isinstance(rtol, bool)
                and 0.0 <= rtol < 1.0):
            raise InputError(f"rtol must be a number in [0, 1) (the relative distance below which two solutions are "
                             f"one), got {rtol!r}")
        picked = self._solution_branches(alpha, rtol)
        self.form([b.index for b in picked])
        out = []
        n, m = self.n, self.m
        for b in picked:
            y = self.branch_y(b, alpha)
            out.append(Solution(y[:n].copy(), y[n:n + m].copy(), y[n + m:].copy(), alpha, b.sets, 0))
        return out

    def _solution_branches(self, alpha, rtol=1e-9, extents=None) -> list:
        """The branches giving the distinct solutions at alpha (lazy branches are decided from
        their multipliers and indicators, without forming u; the multipliers determine u).
        ``extents``: the (B, 2) array of every branch's extent, if already at hand."""
        out, keys = [], []
        if extents is None:
            extents = np.array([self.branch_extent(b) for b in self.branches], dtype=float).reshape(-1, 2)
        candidates = ((extents[:, 0] <= alpha) & (alpha <= extents[:, 1])).nonzero()[0].tolist()
        strict = set()
        if self._bracket_ends():
            # inside a transition's bracket (seed method): the branches on both sides, each only
            # where it holds to rounding (near the transition both hold within a looser slack)
            for j, ends in self._bracket_ends().items():
                if j not in candidates and min(ends) <= alpha <= max(ends):
                    candidates.append(j)
                    strict.add(j)
        for j in sorted(candidates):
            b = self.branches[j]
            slack = 1e-12 if j in strict else 1e-9
            if b.index in self._Y:
                y = self.branch_y(b, alpha)
                if not self._consistent(y, b.sets, slack=slack, floor=self._rounding(b.index, alpha)):
                    continue
                key = (y, False)
            else:
                if not self._consistent(None, b.sets, slack=slack, ind=self._branch_indicators(b.index, alpha)):
                    continue
                key = (self.branch_lam(b.index, alpha), True)
            if any(_same_point(key, z, self.n, rtol) for z in keys):
                continue
            keys.append(key)
            out.append(b)
        return out

    def reach(self) -> float:
        """The alpha farthest towards alpha_end that a branch of the path covers (nan without any)."""
        ends = [e for b in self.branches for e in self.branch_extent(b) if np.isfinite(e)]
        if not ends:
            return float("nan")
        return float(max(ends) if self.alpha_end >= self.alpha_start else min(ends))

    def turned_back(self) -> bool:
        """True when the path completed without reaching alpha_end: it folded back and left its
        range on the side of alpha_start, so no solution on it lies beyond :meth:`reach` (the
        solutions there, if any, are not connected to the start by this path)."""
        if self.status != "completed":
            return False
        far, end = self.reach(), self.alpha_end
        return bool(np.isfinite(far) and abs(far - end) > 1e-12 * max(1.0, abs(end))
                    and (far < end if end >= self.alpha_start else far > end))

    def multiplicity(self, alpha: float) -> int:
        """Number of distinct solutions of the path at alpha."""
        return len(self._solution_branches(check_alpha(alpha)))

    def _multiplicity_scan(self) -> tuple:
        """([(a, b, k)] for every pair of consecutive distinct branch ends a < b, k = the number of
        distinct solutions at (a + b) / 2 (constant between branch ends); the extents array).

        Cached until the branches, their extents or the formed state of lazy branches change."""
        extents = np.array([self.branch_extent(b) for b in self.branches], dtype=float).reshape(-1, 2)
        key = (len(self.branches), len(self._pending), extents.tobytes())
        if self._scan is None or self._scan[0] != key:
            ends = sorted({float(e) for e in extents.ravel() if np.isfinite(e)})
            scan = [(a, b, len(self._solution_branches(0.5 * (a + b), extents=extents)))
                    for a, b in zip(ends[:-1], ends[1:]) if b > a]
            self._scan = (key, scan)
        return self._scan[1], extents

    def multiplicity_intervals(self, alpha_range=None) -> list:
        """[(alpha_lo, alpha_hi, k)]: the number k of distinct solutions on each alpha interval
        between branch ends (neighbours with equal k merged), in increasing alpha; with
        ``alpha_range`` = (lo, hi) the intervals of that window."""
        if alpha_range is None:
            scan = self._multiplicity_scan()[0]
        else:
            try:
                lo, hi = (float(a) for a in alpha_range)
            except (TypeError, ValueError):
                raise InputError(f"alpha_range must be (lo, hi), two numbers, got {alpha_range!r}") from None
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
                raise InputError(f"alpha_range must be (lo, hi) with finite lo < hi, got {alpha_range!r}")
            ends = sorted({float(e) for b in self.branches for e in self.branch_extent(b) if np.isfinite(e)})
            ends = sorted({lo, hi, *[e for e in ends if lo < e < hi]})
            scan = [(a, b, self.multiplicity(0.5 * (a + b))) for a, b in zip(ends[:-1], ends[1:]) if b > a]
        out = []
        for a, b, k in scan:
            if out and out[-1][2] == k:
                out[-1] = (out[-1][0], b, k)
            else:
                out.append((a, b, k))
        return out

    def max_multiplicity(self, samples: int = 0):
        """(max multiplicity, an alpha where it occurs), checked at the midpoints between all branch
        ends (and at ``samples`` evenly spaced alphas)."""
        if not (isinstance(samples, (int, np.integer)) and not isinstance(samples, bool) and samples >= 0):
            raise InputError(f"samples must be an integer >= 0, got {samples!r}")
        scan, extents = self._multiplicity_scan()
        best = (0, float("nan"))
        for a, b, k in scan:
            if k > best[0]:
                best = (k, 0.5 * (a + b))
        ends = sorted({float(e) for e in extents.ravel() if np.isfinite(e)}) if samples else []
        if ends:  # (a path without branches has nothing to sample: (0, nan))
            for a in np.linspace(min(ends), max(ends), samples):
                k = len(self._solution_branches(float(a), extents=extents))
                if k > best[0]:
                    best = (k, a)
        return best

    def component(self, spec) -> np.ndarray:
        """Values of one component at every point: ("lam_n", i), ("lam_t", i), ("u", dof), "lam_n:i" or an
        index of y."""
        idx = self.component_index(spec)
        if idx >= self.n:  # a multiplier: no displacement needed
            return self.lams[:, idx - self.n]
        return self.ys[:, idx]

    def component_index(self, spec) -> int:
        """The index in y of a component (see :func:`component_index`)."""
        return component_index(self.n, self.m, spec)

    def summary(self) -> dict:
        mult, at = self.max_multiplicity()
        return {"method": self.method, "status": self.status, "points": len(self._alphas),
                "branches": len(self.branches), "transitions": len(self.transitions),
                "transversal": sum(t.kind == "transversal" for t in self.transitions),
                "folds": len(self.folds), "max_multiplicity": mult, "alpha_of_max": at,
                "reach": self.reach(), "turned_back": self.turned_back(),
                "events": len(self.events), **self.stats}

    def __repr__(self):
        return (f"SolutionPath(method={self.method!r}, status={self.status!r}, points={len(self._alphas)}, "
                f"branches={len(self.branches)}, transitions={len(self.transitions)}, folds={len(self.folds)})")

    # ------------------------------------------------------------ save / load
    def save(self, path) -> str:
        """Write the path to a directory ``path`` (created; replaced atomically if it exists).

        Format (version 2): ``path.json`` holds the structure (method, options, status, stats,
        branches with sets and orientation, transitions, events); ``fields.npz`` holds the
        arrays (alphas, ys, point_branch, the branches in reference form -- alpha_ref, Y_ref,
        dY --, N and T in CSR form, friction, gap, geometry of a FEM model).  Lazy branches are formed first (one batched solve), so
        the saved file is the same as for an eagerly formed path.  An existing ``path`` is
        replaced only when it is a saved path or an empty folder (InputError otherwise: nothing
        else is overwritten).
        """
        path = os.fspath(path)
        if not path.strip():
            raise InputError("save needs a folder name, got an empty path")
        blocking = blocking_file(os.path.dirname(os.path.abspath(path)))
        if blocking is not None:
            raise InputError(f"cannot save to {path!r}: {blocking!r} is a file, not a folder")
        if os.path.lexists(path) and not _replaceable(path, self.FORMAT):
            raise InputError(f"refusing to replace {path!r}: it is not a saved cfcontact path (a folder with path.json) "
                             "nor an empty folder; choose another folder")
        parent = os.path.dirname(os.path.abspath(path))
        os.makedirs(parent, exist_ok=True)
        tmp = tempfile.mkdtemp(prefix=".cfpath-", dir=parent)
        try:
            os.chmod(tmp, 0o777 & ~_umask())  # (mkdtemp makes it 0700; a saved path is an ordinary folder)
            meta = {"format": self.FORMAT, "version": FORMAT_VERSION, "n": self.n, "m": self.m,
                    "rho": self.rho, "method": self.method, "alpha_start": self.alpha_start,
                    "alpha_end": self.alpha_end, "options": self.options, "status": self.status,
                    "stats": self.stats, "branches": [b.to_dict() for b in self.branches],
                    "transitions": [t.to_dict() for t in self.transitions],
                    "events": [e.to_dict() for e in self.events], "has_geometry": self.geometry is not None,
                    "system_checksum": self.system_checksum}
            with open(os.path.join(tmp, "path.json"), "w") as fh:
                json.dump(jsonable(meta, strict=False), fh, indent=1)
            self.form()
            arrays = {"alphas": self.alphas, "ys": self.ys, "point_branch": self.point_branch,
                      "friction": np.asarray(self.friction, dtype=float), "gap": self.gap,
                      "N_data": self.N.data, "N_indices": self.N.indices, "N_indptr": self.N.indptr,
                      "T_data": self.T.data, "T_indices": self.T.indices, "T_indptr": self.T.indptr}
            arrays.update(self._branch_arrays())
            if self.geometry is not None:
                arrays.update({"geometry_" + k: v for k, v in self.geometry.to_dict().items()})
            np.savez_compressed(os.path.join(tmp, "fields.npz"), **arrays)
            if os.path.isdir(path):
                old = path + ".old-" + os.path.basename(tmp)
                os.rename(path, old)
                os.rename(tmp, path)
                shutil.rmtree(old)
            else:
                os.rename(tmp, path)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        return path

    def _branch_arrays(self) -> dict:
        """The branches' arrays of a save (:meth:`save` has formed every branch): the reference form."""
        if not self.branches:
            return {}
        return {"alpha_ref": np.array([self._Y[b.index][0] for b in self.branches]),
                "Y_ref": np.stack([self._Y[b.index][1] for b in self.branches]),
                "dY": np.stack([self._Y[b.index][2] for b in self.branches])}

    def _set_branch_arrays(self, arrays):
        """The branches of a loaded path from the arrays :meth:`_branch_arrays` saved."""
        for b in self.branches:
            if "Y_ref" in arrays:
                self._Y[b.index] = (float(arrays["alpha_ref"][b.index]), arrays["Y_ref"][b.index],
                                    arrays["dY"][b.index])
            else:  # version 1: the points at alpha = 0 and 1
                self._Y[b.index] = (0.0, arrays["Y1"][b.index], arrays["Y2"][b.index] - arrays["Y1"][b.index])

    @classmethod
    def load(cls, path) -> "SolutionPath":
        """Read a path written by :meth:`save`.  Every file is checked first
        (:func:`read_saved_meta`, :func:`read_saved_arrays`, :func:`validate_saved`): a missing,
        truncated or corrupted file, a missing key, a wrongly shaped or non-finite array is an
        InputError naming the file and what is wrong."""
        path = os.fspath(path)
        meta = read_saved_meta(path, cls.FORMAT)
        arrays = read_saved_arrays(path)
        validate_saved(meta, arrays, path)
        n, m = meta["n"], meta["m"]
        N = sp.csr_matrix((arrays["N_data"], arrays["N_indices"], arrays["N_indptr"]), shape=(m, n))
        T = sp.csr_matrix((arrays["T_data"], arrays["T_indices"], arrays["T_indptr"]), shape=(m, n))
        fr = arrays["friction"]
        friction = float(fr) if fr.ndim == 0 else fr
        geometry = None
        if meta.get("has_geometry"):
            geometry = ContactGeometry.from_dict({k[len("geometry_"):]: v for k, v in arrays.items()
                                                  if k.startswith("geometry_")})
        p = cls(n, m, N, T, friction, meta["rho"], meta["method"], meta["alpha_start"], meta["alpha_end"],
                meta["options"], geometry, arrays.get("gap"))
        p._alphas = [float(a) for a in arrays["alphas"]]
        ys = arrays["ys"]
        p._ys = _Points(p, [ys[i] for i in range(ys.shape[0])])
        p._point_branch = [int(b) for b in arrays["point_branch"]]
        p.branches = [Branch.from_dict(d) for d in meta["branches"]]
        p._set_branch_arrays(arrays)
        p.transitions = [Transition.from_dict(d) for d in meta["transitions"]]
        p.events = [PathEvent(**d) for d in meta["events"]]
        p.status = meta["status"]
        p.stats = meta["stats"]
        p.system_checksum = meta.get("system_checksum")
        return p


# ------------------------------------------------------------ checks of saved files
def _umask() -> int:
    """The process's file-creation mask: Linux's /proc/self/status, else read by setting it and
    back (which another thread could see for an instant)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _replaceable(path, fmt) -> bool:
    """May :meth:`SolutionPath.save` replace ``path``: an empty folder, or a folder whose path.json
    says it is a saved path of format ``fmt`` (not the working directory itself)?"""
    if os.path.islink(path) or not os.path.isdir(path) or os.path.abspath(path) == os.getcwd():
        return False
    return holds_format(path, "path.json", fmt, empty=True)


class _Bad(Exception):
    """What is wrong with one saved item (turned into an InputError naming the file)."""


def read_saved_meta(path, fmt: str = "cfcontact-path") -> dict:
    """path.json of a saved path, parsed and checked against the format ``fmt`` (InputError naming
    the file)."""
    jpath = os.path.join(path, "path.json")
    if not os.path.isfile(jpath):
        raise InputError(f"{path!r} is not a saved cfcontact path (no path.json inside)")
    try:
        with open(jpath) as fh:
            meta = json.load(fh)
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"{jpath}: unreadable or truncated JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise InputError(f"{jpath}: not a saved cfcontact path (a JSON {type(meta).__name__}, expected an object)")
    if meta.get("format") != fmt or meta.get("version") not in (1, FORMAT_VERSION):
        raise InputError(f"{path!r}: unsupported format {meta.get('format')!r} version {meta.get('version')!r}")
    try:
        _check_meta(meta)
    except _Bad as exc:
        raise InputError(f"{jpath}: {exc}") from None
    return meta


def read_saved_arrays(path) -> dict:
    """The arrays of fields.npz of a saved path (InputError naming the file: missing, empty,
    truncated, not an .npz archive, pickled data)."""
    fpath = os.path.join(path, "fields.npz")
    if not os.path.isfile(fpath):
        raise InputError(f"{fpath}: missing (the saved path has no arrays)")
    try:
        with np.load(fpath, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except Exception as exc:  # zipfile.BadZipFile, EOFError, ValueError (pickled / empty), OSError, zlib.error
        raise InputError(f"{fpath}: truncated or not an .npz archive of arrays ({type(exc).__name__}: {exc})") \
            from None


def _need(d, key, kinds, where):
    if key not in d:
        raise _Bad(f"missing key {key!r}{where}")
    value = d[key]
    if not isinstance(value, kinds) or isinstance(value, bool) and bool not in (kinds if isinstance(kinds, tuple)
                                                                               else (kinds,)):
        raise _Bad(f"key {key!r}{where} has the wrong type ({type(value).__name__})")
    return value


def _finite_number(d, key, where, optional=False):
    if optional and d.get(key) is None:
        return
    v = _need(d, key, (int, float), where)
    if not np.isfinite(v):
        raise _Bad(f"key {key!r}{where} is not finite ({v!r})")


def _check_meta(meta):
    """Keys and types of path.json (the structure; the arrays are checked by validate_saved)."""
    n, m = _need(meta, "n", int, ""), _need(meta, "m", int, "")
    if n < 1 or m < 0:
        raise _Bad(f"n = {n}, m = {m}: need n >= 1 and m >= 0")
    _finite_number(meta, "rho", "")
    if not meta["rho"] > 0:
        raise _Bad(f"rho = {meta['rho']!r} must be > 0")
    if _need(meta, "method", str, "") not in METHODS:
        raise _Bad(f"method {meta['method']!r} is not one of {', '.join(map(repr, METHODS))}")
    _finite_number(meta, "alpha_start", "")
    _finite_number(meta, "alpha_end", "")
    _need(meta, "options", dict, "")
    if _need(meta, "status", str, "") not in STATUSES:
        raise _Bad(f"status {meta['status']!r} is not a path status ({', '.join(map(repr, STATUSES))})")
    _need(meta, "stats", dict, "")
    for key in ("branches", "transitions", "events"):
        _need(meta, key, list, "")
    checksum = meta.get("system_checksum")
    if checksum is not None and not (isinstance(checksum, str) and len(checksum) == 64):
        raise _Bad(f"system_checksum {checksum!r} is not a SHA-256 hex digest")
    nb = len(meta["branches"])
    for k, b in enumerate(meta["branches"]):
        where = f" in branches[{k}]"
        if not isinstance(b, dict):
            raise _Bad(f"branches[{k}] is not an object")
        if _need(b, "index", int, where) != k:
            raise _Bad(f"branches[{k}] has index {b['index']}")
        sets = _need(b, "sets", dict, where)
        if sets.get("m") != m or not all(isinstance(sets.get(name), list) and all(
                isinstance(i, int) and 0 <= i < m for i in sets[name]) for name in SET_NAMES):
            raise _Bad(f"branches[{k}].sets are not inactive sets of m = {m} nodes")
        states = b.get("states")
        if states is not None and not (isinstance(states, list) and len(states) == m
                                       and all(isinstance(x, str) and x in STATE_NAMES for x in states)):
            raise _Bad(f"branches[{k}].states are not {m} node states ({', '.join(map(repr, STATE_NAMES))})")
        if _need(b, "orientation", int, where) not in (-1, 1):
            raise _Bad(f"branches[{k}].orientation must be +1 or -1")
        _need(b, "points", list, where)
        for key in ("alpha_enter", "alpha_exit"):
            if b.get(key) is not None:
                _need(b, key, (int, float), where)
        for key in ("origin", "parent"):
            if b.get(key) is not None and not isinstance(b[key], int):
                raise _Bad(f"key {key!r}{where} has the wrong type")
    for k, t in enumerate(meta["transitions"]):
        where = f" in transitions[{k}]"
        if not isinstance(t, dict):
            raise _Bad(f"transitions[{k}] is not an object")
        for key in ("from_branch", "to_branch"):
            if not 0 <= _need(t, key, int, where) < max(nb, 1):
                raise _Bad(f"transitions[{k}].{key} = {t[key]} is not a branch (0..{nb - 1})")
        for key in ("index", "alpha", "kind", "node", "set", "bracket"):
            if key not in t:
                raise _Bad(f"missing key {key!r}{where}")
        _finite_number(t, "alpha", where)
        # (node -1: an alternative followed at a branch point changes no node)
        if not (isinstance(t["node"], int) and not isinstance(t["node"], bool) and -1 <= t["node"] < m):
            raise _Bad(f"transitions[{k}].node = {t['node']!r} is not a contact node (0..{m - 1})")
        if t["kind"] not in ("transversal", "fold"):
            raise _Bad(f"transitions[{k}].kind = {t['kind']!r} is not 'transversal' or 'fold'")
        bracket = t["bracket"]
        if not (isinstance(bracket, list) and len(bracket) == 2 and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) for x in bracket)):
            raise _Bad(f"transitions[{k}].bracket = {bracket!r} is not two numbers")
    for k, e in enumerate(meta["events"]):
        if not isinstance(e, dict) or not {"kind", "alpha", "message"} <= set(e):
            raise _Bad(f"events[{k}] is not an event (kind, alpha, message)")


def expected_arrays(meta, arrays) -> dict:
    """{array name: (expected shape (None = any length), kind)} of fields.npz for the path.json
    ``meta``; kind "f" (finite floats), "i" (integers) or "s" (text).  P = number of points,
    B = number of branches, from the arrays and the branches.  Arrays of the geometry only when
    it is saved."""
    n, m = meta["n"], meta["m"]
    P = len(arrays["alphas"]) if "alphas" in arrays and np.ndim(arrays["alphas"]) == 1 else None
    B = len(meta["branches"])
    width = n + 2 * m
    exp = {"alphas": ((P,), "f"), "ys": ((P, width), "f"), "point_branch": ((P,), "i"),
           "friction": (None, "f"),
           "N_data": ((None,), "f"), "N_indices": ((None,), "i"), "N_indptr": ((m + 1,), "i"),
           "T_data": ((None,), "f"), "T_indices": ((None,), "i"), "T_indptr": ((m + 1,), "i")}
    if meta.get("format") == "cfcontact-friction-path":  # branches in exact rational form (cfcontact.friction)
        if B:
            exp.update({"fb_p": ((B,), "i"), "fb_lam0": ((B, 2 * m), "f"), "fb_gam0": ((B, None), "f"),
                        "fb_h": ((None,), "f"), "fb_H": ((None,), "f"), "fb_L": ((2 * m, None), "f"),
                        "fb_GamL": ((2 * m, None), "f"), "fb_u0": ((B, n), "f"), "fb_U": ((n, None), "f")})
    elif B and meta.get("version") == 1:  # the branches at alpha = 0 and 1
        exp["Y1"] = ((B, width), "f")
        exp["Y2"] = ((B, width), "f")
    elif B:  # the branches in reference form
        exp["alpha_ref"] = ((B,), "f")
        exp["Y_ref"] = ((B, width), "f")
        exp["dY"] = ((B, width), "f")
    if meta.get("version", FORMAT_VERSION) >= 2:
        exp["gap"] = ((m,), "f")
    if meta.get("has_geometry"):
        exp.update({"geometry_points": ((None, 2), "f"), "geometry_cells": ((None, None), "i"),
                    "geometry_cell_body": ((None,), "i"), "geometry_dof_node": ((n,), "i"),
                    "geometry_dof_comp": ((n,), "i"), "geometry_contact_nodes": ((m, 2), "i"),
                    "geometry_contact_points": ((m, 2), "f"), "geometry_normals": ((m, 2), "f"),
                    "geometry_tangents": ((m, 2), "f")})
        optional = {"geometry_tributary": ((m,), "f"), "geometry_prescribed": ((None, 4), "f"),
                    "geometry_material": ((), "s"), "geometry_obstacle": ((), "s")}
        exp.update({k: v for k, v in optional.items() if k in arrays})
    return exp


def validate_arrays(arrays, expected, where):
    """Check every expected array by name (present), shape (None: any length) and kind (finite
    floats, integers, text); InputError naming ``where`` and the array."""
    for name, (shape, kind) in expected.items():
        if name not in arrays:
            raise InputError(f"{where}: array {name!r} is missing")
        a = arrays[name]
        if shape is not None and (a.ndim != len(shape) or any(e is not None and e != s
                                                               for e, s in zip(shape, a.shape))):
            want = "(" + ", ".join("*" if e is None else str(e) for e in shape) + ("," if len(shape) == 1 else "") + ")"
            raise InputError(f"{where}: array {name!r} has shape {a.shape}, expected {want}")
        if kind == "f":
            if a.dtype.kind not in "fiu":
                raise InputError(f"{where}: array {name!r} is not numeric ({a.dtype})")
            if not np.all(np.isfinite(a)):
                raise InputError(f"{where}: array {name!r} has non-finite values (nan or inf)")
        elif kind == "i" and a.dtype.kind not in "iu":
            raise InputError(f"{where}: array {name!r} is not an integer array ({a.dtype})")
        elif kind == "s" and a.dtype.kind not in "US":
            raise InputError(f"{where}: array {name!r} is not text ({a.dtype})")


def validate_saved(meta, arrays, path):
    """The arrays of a saved path against its path.json (:func:`expected_arrays`), and the
    references between them (CSR structure of N and T, branch and node indices)."""
    where = os.path.join(path, "fields.npz")
    validate_arrays(arrays, expected_arrays(meta, arrays), where)
    n, m = meta["n"], meta["m"]
    for name in ("N", "T"):
        ptr, idx, data = arrays[f"{name}_indptr"], arrays[f"{name}_indices"], arrays[f"{name}_data"]
        if ptr[0] != 0 or np.any(np.diff(ptr) < 0) or ptr[-1] != len(idx) or len(idx) != len(data) \
                or (len(idx) and (idx.min() < 0 or idx.max() >= n)):
            raise InputError(f"{where}: {name} is not a valid {m} x {n} CSR matrix")
    fr = arrays["friction"]
    if not (fr.ndim == 0 or fr.shape == (m,)) or np.any(fr < 0):
        raise InputError(f"{where}: array 'friction' must be a number >= 0 or one per contact node ({m},)")
    P, B = len(arrays["alphas"]), len(meta["branches"])
    pb = arrays["point_branch"]
    if P and (pb.min() < 0 or pb.max() >= B):
        raise InputError(f"{where}: array 'point_branch' refers to branches outside 0..{B - 1}")
    for k, b in enumerate(meta["branches"]):
        if not all(isinstance(i, int) and 0 <= i < P for i in b["points"]):
            raise InputError(f"{os.path.join(path, 'path.json')}: branches[{k}].points refer to points outside "
                             f"0..{P - 1} (fields.npz has {P})")
    if meta.get("has_geometry"):
        npts = len(arrays["geometry_points"])
        for name in ("geometry_cells", "geometry_dof_node"):
            a = arrays[name]
            if a.size and (a.min() < 0 or a.max() >= npts):
                raise InputError(f"{where}: array {name!r} refers to nodes outside 0..{npts - 1}")
        cn = arrays["geometry_contact_nodes"]
        if cn.size and (cn.min() < -1 or cn.max() >= npts):
            raise InputError(f"{where}: array 'geometry_contact_nodes' refers to nodes outside 0..{npts - 1} "
                             f"(or -1: a rigid master)")
        if len(arrays["geometry_cell_body"]) != len(arrays["geometry_cells"]):
            raise InputError(f"{where}: arrays 'geometry_cell_body' and 'geometry_cells' differ in length")
        bad = arrays["geometry_cell_body"][arrays["geometry_cell_body"] < 1]
        if bad.size:
            raise InputError(f"{where}: array 'geometry_cell_body' holds {int(bad[0])}; a cell's body is the number "
                             "of its 2-D physical group (1, 2, or another part's, >= 1)")
        for name in ("geometry_material", "geometry_obstacle"):  # (JSON text)
            if name in arrays:
                try:
                    json.loads(str(arrays[name]))
                except ValueError:
                    raise InputError(f"{where}: array {name!r} is not JSON text") from None


def _same_point(a, b, n, rtol) -> bool:
    """Same solution?  a, b = (vector, is_multipliers_only); a full y against multipliers compares
    the multiplier parts (the multipliers determine u for a given load)."""
    (x, xl), (z, zl) = a, b
    if xl != zl:
        x, z = (x if xl else x[n:]), (z if zl else z[n:])
    return bool(np.abs(x - z).max(initial=0.0) <= rtol * max(np.abs(x).max(initial=0.0),
                                                             np.abs(z).max(initial=0.0), 1e-300))


def component_index(n: int, m: int, spec) -> int:
    """Index in y = (u, lam_n, lam_t) (n DOFs, m contact nodes) of ("lam_n", i), ("lam_t", i),
    ("u", dof), "lam_n:i" (the form of case files and the command line) or an index of y;
    InputError when out of range or of another form."""
    if isinstance(spec, str) and ":" in spec:
        name, _, i = spec.partition(":")
        try:
            spec = (name.strip(), int(i))
        except ValueError:
            raise InputError(f"component {spec!r}: expected 'NAME:INDEX' with an integer index") from None
    if isinstance(spec, (int, np.integer)) and not isinstance(spec, bool):
        idx = int(spec)
        limit = n + 2 * m
    else:
        if not (isinstance(spec, (tuple, list)) and len(spec) == 2 and isinstance(spec[1], (int, np.integer))):
            raise InputError(f"component must be ('lam_n', i), ('lam_t', i), ('u', dof), 'lam_n:i' or an index of y, "
                             f"got {spec!r}")
        name, i = spec
        offsets = {"u": (0, n), "lam_n": (n, m), "lam_t": (n + m, m)}
        if name not in offsets:
            raise InputError(f"unknown component {name!r}; valid: 'u', 'lam_n', 'lam_t' or an index of y")
        off, limit = offsets[name]
        if not (0 <= int(i) < limit):
            raise InputError(f"component index {i} out of range for {name!r} (0..{limit - 1})")
        return off + int(i)
    if not (0 <= idx < limit):
        raise InputError(f"component index {idx} out of range (0..{limit - 1})")
    return idx
