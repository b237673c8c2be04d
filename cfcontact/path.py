"""Path following along f(alpha) = (1 - alpha) f1 + alpha f2 (the seed's Section 4).

The solution path is a chain of oriented linear branches (inactive sets Z fixed,
orientation s = +-1) joined at transition points.  :func:`trace_path` follows it with

* ``method="seed"``: the seed's predictor-corrector on each branch with adaptive step
  (h_min, h_max, c_p, c_s), the branching indicator (17)-(18) and the branching
  algorithm (transversal transition vs fold);
* ``method="exact"``: the exact piecewise-affine continuation of :mod:`cfcontact.exact`.

Both return a :class:`SolutionPath`.  Along a branch y(alpha) = (1 - alpha) Y1 + alpha Y2
with Y1 = DirNeu(Z, f1), Y2 = DirNeu(Z, f2) exactly, so every branch stores (Y1, Y2) and
:meth:`SolutionPath.solutions_at` evaluates branches exactly (no interpolation between
stored points), also after :meth:`SolutionPath.load`.

Lazy branches: with the condensed backend (:class:`cfcontact.condensed.CondensedSolver`) a
branch is determined by its multipliers, lam(alpha) = (1 - alpha) lam1 + alpha lam2, and the
exact method stores only (lam1, lam2), the indicator values at alpha = 0 and 1 and the backend.
The displacements u = K^-1 (f - B^T lam) of such branches (and of their stored points) are
formed when first needed (``ys``, ``points``, ``branch_y``, ``solutions_at``, ``save``), for
many branches at once in one multi-right-hand-side solve.  ``multiplicity``,
``max_multiplicity`` and the multiplier components of ``component`` need no u at all.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import tempfile
import time
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Callable, Optional

import numpy as np
import scipy.sparse as sp

from cfcontact.errors import InputError
from cfcontact.ssnm import (
    InactiveSets,
    Solution,
    get_solver,
    indicators,
    is_fixed_point,
    ssnm,
)
from cfcontact.system import ContactGeometry, ContactSystem

log = logging.getLogger(__name__)

FORMAT_VERSION = 1
SET_NAMES = ("nu", "tp", "tm")  # which indicator of (17): normal, slip+, slip-


@dataclass
class PathOptions:
    """Options of the path-following layer (seed defaults, its Figure 6).

    h_min, h_max, c_p, c_s: step-size range and prolongation / shortening rates.
    h0: initial step.  max_steps, max_transitions: caps (the run stops with that status).
    alpha_min, alpha_max: the path stops when alpha leaves [alpha_min, alpha_max]
        (default: the interval between alpha_start and alpha_end).
    tol, max_iter: SSNM options for the start point.
    callback: called with each accepted :class:`PathPoint`; a truthy return stops the run.
    """

    h_min: float = 1e-5
    h_max: float = 5.0
    c_p: float = 1.3
    c_s: float = 0.5
    h0: float = 1e-2
    max_steps: int = 200000
    max_transitions: int = 10000
    alpha_min: Optional[float] = None
    alpha_max: Optional[float] = None
    tol: float = 1e-9
    max_iter: int = 100
    callback: Optional[Callable] = None

    def validate(self):
        bad = []
        if not (0 < self.h_min <= self.h_max):
            bad.append(f"need 0 < h_min <= h_max, got h_min={self.h_min}, h_max={self.h_max}")
        if not (self.c_p > 1):
            bad.append(f"need c_p > 1, got {self.c_p}")
        if not (0 < self.c_s < 1):
            bad.append(f"need 0 < c_s < 1, got {self.c_s}")
        if not (self.h0 > 0):
            bad.append(f"need h0 > 0, got {self.h0}")
        if int(self.max_steps) < 1 or int(self.max_transitions) < 0:
            bad.append(f"need max_steps >= 1 and max_transitions >= 0, got {self.max_steps}, {self.max_transitions}")
        if bad:
            raise InputError("invalid path options: " + "; ".join(bad))

    def to_dict(self) -> dict:
        """The options without the callback (not copied: it may hold MPI/PETSc handles)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "callback"}


@dataclass
class PathPoint:
    """An accepted point of the path (what the callback sees)."""

    index: int
    alpha: float
    branch: int
    solution: Solution
    path: Optional["SolutionPath"] = field(default=None, repr=False, compare=False)  # the live path


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
        "tm": A_t <-> I_t^-) that changed; ``changes`` lists all of them when several did.
    alpha: the transition parameter (seed: last point before it, within the bracket;
        exact: the root of the indicator).  bracket: (lo, hi) known to contain it.
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

    def to_dict(self) -> dict:
        d = asdict(self)
        d["bracket"] = list(self.bracket)
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

    def __init__(self, n, m, N, T, friction, rho, method, alpha_start, alpha_end, options=None,
                 geometry: Optional[ContactGeometry] = None):
        self.n, self.m = int(n), int(m)
        self.N, self.T = sp.csr_matrix(N), sp.csr_matrix(T)
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
        self._Y: dict = {}  # branch index -> (Y1, Y2)
        # lazy branches: index -> (lam1, lam2); indicators (3m at alpha = 0 and 1); unformed -> backend
        self._lam: dict = {}
        self._ind: dict = {}
        self._pending: dict = {}

    # ------------------------------------------------------------- building
    @classmethod
    def for_system(cls, system: ContactSystem, method, alpha_start, alpha_end, options=None):
        N, T = system.contact_maps()
        return cls(system.n, system.m, N, T, system.friction, system.rho, method, alpha_start, alpha_end,
                   options, system.geometry)

    def add_branch(self, sets, orientation, Y1, Y2, origin=None, parent=None, alpha_enter=float("nan"),
                   multipliers=None, indicators=None, source=None):
        """Append a branch with y(alpha) = (1 - alpha) Y1 + alpha Y2.

        Lazy form: Y1 = Y2 = None, ``multipliers`` = (lam1, lam2) (2m each), ``source`` = a
        backend with ``displacements(lams, alphas)`` (:class:`~cfcontact.condensed.CondensedSolver`)
        that forms u when needed, optionally ``indicators`` = (g1, g2), the three indicator
        vectors of (17) stacked (3m) at alpha = 0 and 1."""
        b = Branch(len(self.branches), sets, int(orientation), origin=origin, parent=parent, alpha_enter=alpha_enter)
        self.branches.append(b)
        if Y1 is None:
            if multipliers is None or source is None:
                raise InputError("a lazy branch needs multipliers=(lam1, lam2) and a source backend")
            self._lam[b.index] = (np.asarray(multipliers[0], dtype=float), np.asarray(multipliers[1], dtype=float))
            if indicators is not None:
                self._ind[b.index] = (np.asarray(indicators[0], dtype=float), np.asarray(indicators[1], dtype=float))
            self._pending[b.index] = source
        else:
            self._Y[b.index] = (np.asarray(Y1, dtype=float), np.asarray(Y2, dtype=float))
        return b

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
        """y on a branch at alpha, exactly: (1 - alpha) Y1 + alpha Y2."""
        b = branch.index if isinstance(branch, Branch) else int(branch)
        if b not in self._Y:
            self.form([b])
        Y1, Y2 = self._Y[b]
        return (1.0 - alpha) * Y1 + alpha * Y2

    # ------------------------------------------------------- lazy branches
    @property
    def lazy(self) -> bool:
        """Does the path have branches whose displacements are not formed yet?"""
        return bool(self._pending)

    def form(self, branches=None):
        """Form (Y1, Y2) of lazy branches (default: all), in one multi-RHS solve per backend.

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
            for k, b in enumerate(bs):
                lams[:, 2 * k], lams[:, 2 * k + 1] = self._lam[b]
            U = source.displacements(lams, np.tile([0.0, 1.0], len(bs)))
            for k, b in enumerate(bs):
                lam1, lam2 = self._lam[b]
                self._Y[b] = (np.concatenate([U[:, 2 * k], lam1]), np.concatenate([U[:, 2 * k + 1], lam2]))
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
                U = src.displacements(lams, [self._alphas[i] for i in ii])
                for k, i in enumerate(ii):
                    formed[i] = np.concatenate([U[:, k], lams[:, k]])
            for i in idx:
                yield self._alphas[i], formed[i] if i in formed else self._ys[i]

    def branch_lam(self, branch, alpha):
        """(lam_n, lam_t) on a branch (or its index) at alpha; a lazy branch forms no displacement."""
        b = branch.index if isinstance(branch, Branch) else int(branch)
        if b in self._lam:
            lam1, lam2 = self._lam[b]
            return (1.0 - alpha) * lam1 + alpha * lam2
        return self.branch_y(b, alpha)[self.n:]

    def _point_lam(self, i):
        y = list.__getitem__(self._ys, i)
        if y is not None:
            return y[self.n:]
        return self.branch_lam(self._point_branch[i], self._alphas[i])

    def _branch_indicators(self, b, alpha):
        """(a, bp, bm) of (17) on branch b at alpha (from the stored indicators of a lazy branch)."""
        if b in self._ind:
            g1, g2 = self._ind[b]
            g = (1.0 - alpha) * g1 + alpha * g2
            m = self.m
            return g[:m], g[m:2 * m], g[2 * m:]
        return self._indicators(self.branch_y(b, alpha))

    def _indicators(self, y):
        n, m = self.n, self.m
        u, ln, lt = y[:n], y[n:n + m], y[n + m:]
        F = np.broadcast_to(np.asarray(self.friction, dtype=float), (m,))
        a = ln + self.rho * (self.N @ u)
        b = lt + self.rho * (self.T @ u)
        return a, b - F * ln, b + F * ln

    def _consistent(self, y, sets, slack=1e-9, ind=None):
        """Z(y) agrees with ``sets`` up to ties within ``slack`` (relative); ``ind`` = (a, bp, bm) of y if known."""
        a, bp, bm = self._indicators(y) if ind is None else ind
        scale = max(np.abs(a).max(initial=0), np.abs(bp).max(initial=0), np.abs(bm).max(initial=0), 1e-300)
        tol = slack * scale
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

    def branch_extent(self, branch) -> tuple:
        """(lo, hi) of alpha covered by the path on this branch (transition to transition)."""
        b = self.branches[branch] if not isinstance(branch, Branch) else branch
        vals = [self._alphas[i] for i in b.points]
        for a in (b.alpha_enter, b.alpha_exit):
            if np.isfinite(a):
                vals.append(a)
        return (min(vals), max(vals)) if vals else (np.nan, np.nan)

    def solutions_at(self, alpha: float, rtol: float = 1e-9) -> list:
        """Every distinct solution the path has at ``alpha``, evaluated exactly on each branch crossing it.

        Returns a list of :class:`Solution` sorted by branch order.
        """
        alpha = float(alpha)
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
        for j in np.flatnonzero((extents[:, 0] <= alpha) & (alpha <= extents[:, 1])):
            b = self.branches[j]
            if b.index in self._Y:
                y = self.branch_y(b, alpha)
                if not self._consistent(y, b.sets):
                    continue
                key = (y, False)
            else:
                if not self._consistent(None, b.sets, ind=self._branch_indicators(b.index, alpha)):
                    continue
                key = (self.branch_lam(b.index, alpha), True)
            if any(_same_point(key, z, self.n, rtol) for z in keys):
                continue
            keys.append(key)
            out.append(b)
        return out

    def multiplicity(self, alpha: float) -> int:
        """Number of distinct solutions of the path at alpha."""
        return len(self._solution_branches(float(alpha)))

    def max_multiplicity(self, samples: int = 0):
        """(max multiplicity, an alpha where it occurs), checked at the midpoints between all branch ends."""
        extents = np.array([self.branch_extent(b) for b in self.branches], dtype=float).reshape(-1, 2)
        ends = sorted({float(e) for e in extents.ravel() if np.isfinite(e)})
        cands = [0.5 * (a + b) for a, b in zip(ends[:-1], ends[1:]) if b > a]
        if samples:
            cands += list(np.linspace(min(ends), max(ends), samples))
        best = (0, float("nan"))
        for a in cands:
            k = len(self._solution_branches(float(a), extents=extents))
            if k > best[0]:
                best = (k, a)
        return best

    def component(self, spec) -> np.ndarray:
        """Values of one component at every point: ("lam_n", i), ("lam_t", i), ("u", dof) or an index of y."""
        idx = self.component_index(spec)
        if idx >= self.n:  # a multiplier: no displacement needed
            return self.lams[:, idx - self.n]
        return self.ys[:, idx]

    def component_index(self, spec) -> int:
        n, m = self.n, self.m
        if isinstance(spec, (int, np.integer)):
            idx = int(spec)
            limit = n + 2 * m
        else:
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

    def summary(self) -> dict:
        mult, at = self.max_multiplicity()
        return {"method": self.method, "status": self.status, "points": len(self._alphas),
                "branches": len(self.branches), "transitions": len(self.transitions),
                "transversal": sum(t.kind == "transversal" for t in self.transitions),
                "folds": len(self.folds), "max_multiplicity": mult, "alpha_of_max": at,
                "events": len(self.events), **self.stats}

    def __repr__(self):
        return (f"SolutionPath(method={self.method!r}, status={self.status!r}, points={len(self._alphas)}, "
                f"branches={len(self.branches)}, transitions={len(self.transitions)}, folds={len(self.folds)})")

    # ------------------------------------------------------------ save / load
    def save(self, path) -> str:
        """Write the path to a directory ``path`` (created; replaced atomically if it exists).

        Format (version 1): ``path.json`` holds the structure (method, options, status, stats,
        branches with sets and orientation, transitions, events); ``fields.npz`` holds the
        arrays (alphas, ys, point_branch, per-branch Y1/Y2, N and T in CSR form, friction,
        geometry of a FEM model).  Lazy branches are formed first (one batched solve), so
        the saved file is the same as for an eagerly formed path.
        """
        path = os.fspath(path)
        parent = os.path.dirname(os.path.abspath(path))
        os.makedirs(parent, exist_ok=True)
        tmp = tempfile.mkdtemp(prefix=".cfpath-", dir=parent)
        try:
            meta = {"format": "cfcontact-path", "version": FORMAT_VERSION, "n": self.n, "m": self.m,
                    "rho": self.rho, "method": self.method, "alpha_start": self.alpha_start,
                    "alpha_end": self.alpha_end, "options": self.options, "status": self.status,
                    "stats": self.stats, "branches": [b.to_dict() for b in self.branches],
                    "transitions": [t.to_dict() for t in self.transitions],
                    "events": [e.to_dict() for e in self.events], "has_geometry": self.geometry is not None}
            with open(os.path.join(tmp, "path.json"), "w") as fh:
                json.dump(meta, fh, indent=1, default=_json_default)
            self.form()
            arrays = {"alphas": self.alphas, "ys": self.ys, "point_branch": self.point_branch,
                      "friction": np.asarray(self.friction, dtype=float),
                      "N_data": self.N.data, "N_indices": self.N.indices, "N_indptr": self.N.indptr,
                      "T_data": self.T.data, "T_indices": self.T.indices, "T_indptr": self.T.indptr}
            if self.branches:
                arrays["Y1"] = np.stack([self._Y[b.index][0] for b in self.branches])
                arrays["Y2"] = np.stack([self._Y[b.index][1] for b in self.branches])
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

    @classmethod
    def load(cls, path) -> "SolutionPath":
        """Read a path written by :meth:`save`."""
        path = os.fspath(path)
        jpath = os.path.join(path, "path.json")
        if not os.path.isfile(jpath):
            raise InputError(f"{path!r} is not a saved cfcontact path (no path.json inside)")
        with open(jpath) as fh:
            meta = json.load(fh)
        if meta.get("format") != "cfcontact-path" or meta.get("version") != FORMAT_VERSION:
            raise InputError(f"{path!r}: unsupported format {meta.get('format')!r} version {meta.get('version')!r}")
        with np.load(os.path.join(path, "fields.npz")) as z:
            arrays = {k: z[k] for k in z.files}
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
                meta["options"], geometry)
        p._alphas = [float(a) for a in arrays["alphas"]]
        ys = arrays["ys"]
        p._ys = _Points(p, [ys[i] for i in range(ys.shape[0])])
        p._point_branch = [int(b) for b in arrays["point_branch"]]
        p.branches = [Branch.from_dict(d) for d in meta["branches"]]
        for b in p.branches:
            p._Y[b.index] = (arrays["Y1"][b.index], arrays["Y2"][b.index])
        p.transitions = [Transition.from_dict(d) for d in meta["transitions"]]
        p.events = [PathEvent(**d) for d in meta["events"]]
        p.status = meta["status"]
        p.stats = meta["stats"]
        return p


def _same_point(a, b, n, rtol) -> bool:
    """Same solution?  a, b = (vector, is_multipliers_only); a full y against multipliers compares
    the multiplier parts (the multipliers determine u for a given load)."""
    (x, xl), (z, zl) = a, b
    if xl != zl:
        x, z = (x if xl else x[n:]), (z if zl else z[n:])
    return bool(np.abs(x - z).max(initial=0.0) <= rtol * max(np.abs(x).max(initial=0.0),
                                                             np.abs(z).max(initial=0.0), 1e-300))


def _json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serializable: {type(o)}")


# ====================================================================== tracing
def trace_path(system: ContactSystem, alpha_start: float = 0.0, alpha_end: float = 1.0, method: str = "seed",
               y0=None, options: Optional[PathOptions] = None, solver=None, resume=None, backend: str = "auto",
               **kwargs) -> SolutionPath:
    """Follow the solution path of (4) along f(alpha) from alpha_start towards alpha_end.

    Parameters
    ----------
    method : "seed" (the seed's Section 4) or "exact" (exact piecewise-affine continuation)
    solver : a DirNeu backend object (overrides ``backend``)
    backend : "full" (PETSc :class:`~cfcontact.ssnm.DirNeuSolver`: one factorization of J(Z) per
        branch), "condensed" (:class:`~cfcontact.condensed.CondensedSolver`: K factored once,
        dense systems in the contact unknowns) or "auto" (default: condensed for the exact method
        when m <= CONDENSED_MAX_M, full otherwise; the seed method uses full, as the seed does)
    y0 : start solution or guess (Solution or flat vector); SSNM at alpha_start is run from it
    options : PathOptions; keyword arguments override its fields (e.g. ``h_min=1e-6``)
    resume : continue a run stopped by its callback instead of starting anew: a dict
        ``{"path": SolutionPath, "state": path.resume_state}`` (the stopped run's path, possibly
        saved and loaded, and the state it left in ``path.resume_state``: for "seed" the loop
        state -- step h, step count, cycle detector --, for "exact" the branch being followed --
        sets, orientation, entry alpha -- and the cycle detector).  The method must be the
        path's.  New points are appended to that path; the result equals an uninterrupted run.
    """
    if method not in ("seed", "exact"):
        raise InputError(f"unknown method {method!r}; valid: 'seed', 'exact'")
    if not (np.isfinite(alpha_start) and np.isfinite(alpha_end)) or alpha_start == alpha_end:
        raise InputError(f"alpha range is empty: alpha_start={alpha_start}, alpha_end={alpha_end} "
                         f"(need two different finite numbers)")
    opts = options or PathOptions()
    if kwargs:
        valid = set(PathOptions.__dataclass_fields__)
        unknown = sorted(set(kwargs) - valid)
        if unknown:
            raise InputError(f"unknown path option(s) {unknown}; valid: {sorted(valid)}")
        opts = replace(opts, **kwargs)
    opts.validate()
    if resume is not None and isinstance(resume, dict) and isinstance(resume.get("path"), SolutionPath) \
            and resume["path"].method != method:
        raise InputError(f"cannot resume a {resume['path'].method!r} path with method {method!r}")
    solver = solver if solver is not None else select_solver(system, method, backend)
    if method == "exact":
        from cfcontact.exact import trace_exact

        return trace_exact(system, alpha_start, alpha_end, y0=y0, options=opts, solver=solver, resume=resume)
    return _trace_seed(system, alpha_start, alpha_end, y0, opts, solver, resume)


#: ``backend="auto"`` uses the condensed solver for the exact method up to this many contact
#: nodes (its dense matrices are (2m)^2: 128 MB at m = 2000).
CONDENSED_MAX_M = 2000
BACKENDS = ("auto", "full", "condensed")


def select_solver(system: ContactSystem, method: str = "exact", backend: str = "auto"):
    """The system's cached DirNeu backend for ``method`` (see :func:`trace_path`'s ``backend``)."""
    if backend not in BACKENDS:
        raise InputError(f"unknown backend {backend!r}; valid: {', '.join(map(repr, BACKENDS))}")
    if backend == "auto":
        backend = "condensed" if method == "exact" and system.m <= CONDENSED_MAX_M else "full"
    if backend == "condensed":
        from cfcontact.condensed import get_condensed_solver

        return get_condensed_solver(system)
    return get_solver(system)


def _alpha_range(opts, alpha_start, alpha_end):
    lo = min(alpha_start, alpha_end) if opts.alpha_min is None else opts.alpha_min
    hi = max(alpha_start, alpha_end) if opts.alpha_max is None else opts.alpha_max
    if not lo < hi:
        raise InputError(f"alpha range is empty: [alpha_min, alpha_max] = [{lo}, {hi}]")
    if not (lo <= alpha_start <= hi):
        raise InputError(f"alpha_start={alpha_start} lies outside [alpha_min, alpha_max] = [{lo}, {hi}]")
    return lo, hi


#: Factors of rho tried by :func:`start_point` when SSNM fails with the system's own rho.
START_RHO_FACTORS = (0.01, 100.0, 0.1, 10.0, 0.001, 1000.0)


def start_point(system, alpha, y0, opts, solver) -> Solution:
    """SSNM at alpha from y0.  Without y0 SSNM starts from 0 and, should that fail (SSNM is only
    locally convergent, and at large F it can cycle), from the frictionless solution (a convex
    problem where SSNM is robust), from the solution with every node open (u = K^-1 f), and
    with other augmentation parameters rho (START_RHO_FACTORS): SSNM's convergence depends on
    rho, the solutions of (1)-(3) do not.  The first that converges is returned, with its sets
    taken for the system's own rho; ConvergenceError of the first attempt when none does."""
    from cfcontact.errors import ConvergenceError

    tol, max_iter = opts.tol, opts.max_iter
    try:
        return ssnm(system, alpha, y0=y0, tol=tol, max_iter=max_iter, solver=solver)
    except ConvergenceError as first:
        if y0 is not None:
            raise
        failure = first

    def attempts():
        yield "from the frictionless solution", lambda: ssnm(
            system, alpha, y0=ssnm(system.with_friction(0.0), alpha, tol=tol, max_iter=max_iter).y,
            tol=tol, max_iter=max_iter, solver=solver)
        open_sets = InactiveSets.from_states(["open"] * system.m)
        yield "from the open solution", lambda: ssnm(
            system, alpha, y0=(solver or get_solver(system)).solve(open_sets, system.load(alpha)),
            tol=tol, max_iter=max_iter, solver=solver)
        for factor in START_RHO_FACTORS:
            yield f"with rho x {factor:g}", lambda factor=factor: Solution.from_y(
                system, ssnm(system.with_rho(system.rho * factor), alpha, tol=tol, max_iter=max_iter).y, alpha)

    for what, attempt in attempts():
        log.info("SSNM from 0 failed at alpha=%g; trying %s", alpha, what)
        try:
            return attempt()
        except ConvergenceError:
            continue
    raise failure


def branch_endpoints(system, solver, sets):
    """(Y1, Y2) = (DirNeu(Z, f1), DirNeu(Z, f2)): y(alpha) = (1 - alpha) Y1 + alpha Y2 on the branch."""
    f1, f2 = system.loads_numpy()
    return solver.solve(sets, f1), solver.solve(sets, f2)


def _ranked_toggles(system, y, sets, limit=8):
    """Non-trivial single toggles ordered by |indicator| (rule (17)), at most ``limit``.

    Toggles that cannot change DirNeu's solution (the tangential set of an open node, or of a
    node with F = 0 between I_t^+ and I_t^-) are skipped.  Returns [(value, node, kind, Z_new)].
    """
    a, bp, bm = indicators(system, y)
    if np.any(sets.nu):
        # The tangential sets of an open node do not change DirNeu's solution, so they go stale
        # along a branch (T u may change sign).  Refresh them from y, so that closing the node
        # (toggling I_nu) starts it slipping in the direction of its current T u.
        tm = np.where(sets.nu, bm < 0, sets.tm)
        sets = InactiveSets(sets.nu, np.where(sets.nu, ~tm, sets.tp), tm)
    vals = np.concatenate([np.abs(a), np.abs(bp), np.abs(bm)])
    out = []
    for k in np.argsort(vals, kind="stable"):
        kind, i = SET_NAMES[k // system.m], int(k % system.m)
        new = toggle(sets, i, kind)
        if not new.equivalent(sets, system.friction):
            out.append((float(vals[k]), i, kind, new))
            if len(out) >= limit:
                break
    return out


def _branching(system, solver, y, Z, alpha, s, h_fail, lo, hi):
    """The seed's branching algorithm, made robust.

    First the seed's own choice (the minimizer of (17)): transversal if DirNeu(Z_new) at
    alpha + s h_fail is a fixed point, else a fold if DirNeu(Z_new) at alpha is one.  When
    neither holds (two indicators vanish within one step, or the minimizer is misleading),
    the next candidates of (17) and pairs of the first ones are tried the same way, keeping
    only continuations that join the old branch continuously.  Returns
    (kind, node, set, Z_new, s_new, alpha_next, y_next, verified, changes) or None.
    """
    f1, f2 = system.loads_numpy()
    load = lambda a: (1.0 - a) * f1 + a * f2  # noqa: E731
    singles = _ranked_toggles(system, y, Z)
    if not singles:
        return None
    a1 = alpha + s * h_fail
    cands = [(c[3], [(c[1], c[2])]) for c in singles]
    top = singles[:4]
    for i in range(len(top)):
        for j in range(i + 1, len(top)):
            if top[i][1] == top[j][1] and top[i][2] == top[j][2]:
                continue
            Zp = toggle(top[i][3], top[j][1], top[j][2])
            cands.append((Zp, [(top[i][1], top[i][2]), (top[j][1], top[j][2])]))
    y_old_1 = None
    for rank, (Zn, changes) in enumerate(cands):
        node, kind = changes[0]
        y1 = solver.solve(Zn, load(a1)) if lo <= a1 <= hi else None
        y2 = None
        if rank > 0:
            # continuity with the old branch: the two affine branches meet at the transition
            if y_old_1 is None:
                y_old_1 = solver.solve(Z, load(a1)) if y1 is not None else None
            y2 = solver.solve(Zn, load(alpha))
            jump = np.linalg.norm(y2 - y)
            scale = np.linalg.norm(y) + 1e-300
            if y1 is not None and y_old_1 is not None:
                slope_gap = np.linalg.norm((y1 - y2) - (y_old_1 - y)) / max(h_fail, 1e-300) * h_fail
                if jump > 2.0 * slope_gap + 1e-9 * scale:
                    continue
        if y1 is not None and is_fixed_point(system, y1, Zn):
            return ("transversal", node, kind, Zn, s, a1, y1, True, [{"node": n, "set": k} for n, k in changes])
        if y2 is None:
            y2 = solver.solve(Zn, load(alpha))
        if is_fixed_point(system, y2, Zn):
            return ("fold", node, kind, Zn, -s, alpha, y2, True, [{"node": n, "set": k} for n, k in changes])
    Zn, changes = cands[0]
    node, kind = changes[0]
    return ("fold", node, kind, Zn, -s, alpha, solver.solve(Zn, load(alpha)), False,
            [{"node": node, "set": kind}])


def toggle(sets: InactiveSets, i: int, kind: str) -> InactiveSets:
    """Move node i between the active and inactive set named by kind (rule (18))."""
    nu, tp, tm = sets.nu.copy(), sets.tp.copy(), sets.tm.copy()
    if kind == "nu":
        nu[i] = not nu[i]
    elif kind == "tp":
        tp[i] = not tp[i]
    elif kind == "tm":
        tm[i] = not tm[i]
    else:
        raise ValueError(kind)
    return InactiveSets(nu, tp, tm)


def resume_parts(system, alpha_start, alpha_end, resume, method):
    """(path, state) of a ``resume`` argument, checked against the system, the alpha range and
    the method (InputError naming what does not match)."""
    usage = "resume must be a dict {'path': SolutionPath, 'state': path.resume_state}"
    try:
        path, state = resume["path"], resume["state"]
    except (TypeError, KeyError):
        raise InputError(usage) from None
    if not isinstance(path, SolutionPath) or not isinstance(state, dict):
        raise InputError(usage)
    if path.method != method or not path.branches or not path._alphas:
        raise InputError(f"cannot resume from {path!r}: not a started {method} path")
    if (path.n, path.m) != (system.n, system.m):
        raise InputError(f"cannot resume: the path has n={path.n}, m={path.m}, the system n={system.n}, m={system.m}")
    if (path.alpha_start, path.alpha_end) != (float(alpha_start), float(alpha_end)):
        raise InputError(f"cannot resume: the path runs from {path.alpha_start} to {path.alpha_end}, "
                         f"not from {alpha_start} to {alpha_end}")
    return path, state


def _resume_seed(system, alpha_start, alpha_end, resume):
    """(path, h, steps, last_seen, done, stats before) of a seed run stopped by its callback."""
    path, state = resume_parts(system, alpha_start, alpha_end, resume, "seed")
    last_seen = {(bytes.fromhex(k), int(sg), int(r)): int(c) for k, sg, r, c in state.get("last_seen", [])}
    before = {k: v for k, v in path.stats.items() if isinstance(v, (int, float))}
    return path, float(state["h"]), int(state["steps"]), last_seen, bool(state.get("done", False)), before


def _trace_seed(system, alpha_start, alpha_end, y0, opts: PathOptions, solver=None, resume=None) -> SolutionPath:
    solver = solver or get_solver(system)
    t0 = time.perf_counter()
    stats0 = solver.stats.as_dict()
    lo, hi = _alpha_range(opts, alpha_start, alpha_end)
    f1, f2 = system.loads_numpy()
    if resume is None:
        s = 1 if alpha_end > alpha_start else -1
        path = SolutionPath.for_system(system, "seed", alpha_start, alpha_end, opts.to_dict())
        start = start_point(system, alpha_start, y0, opts, solver)
        Z, alpha, y = start.sets, float(alpha_start), start.y
        branch = path.add_branch(Z, s, *branch_endpoints(system, solver, Z), alpha_enter=alpha)
        path.add_point(branch, alpha, y)
        h = opts.h0
        steps = 0
        last_seen = {}
        done, stats_before = False, {}
    else:  # continue exactly where the stopped run's callback stopped it
        path, h, steps, last_seen, done, stats_before = _resume_seed(system, alpha_start, alpha_end, resume)
        branch = path.branches[-1]
        Z, s = branch.sets, branch.orientation
        alpha, y = path._alphas[-1], path._ys[-1]
        path.status = "running"

    def finish(status, done=False):
        branch.alpha_exit = alpha
        path.status = status
        st = solver.stats.as_dict()
        path.stats = {k: st[k] - stats0[k] + stats_before.get(k, 0) for k in st}
        path.stats["wall_time"] = time.perf_counter() - t0 + stats_before.get("wall_time", 0.0)
        # loop state for trace_path(resume=...); done: the run had ended when the callback stopped it
        path.resume_state = {"h": h, "steps": steps, "done": bool(done),
                             "last_seen": [[k.hex(), sg, r, c] for (k, sg, r), c in last_seen.items()]}
        log.info("seed path: %s", path)
        return path

    def emit(point_index):
        if opts.callback is not None:
            sol = Solution.from_y(system, path._ys[point_index], path._alphas[point_index], sets=Z)
            if opts.callback(PathPoint(point_index, path._alphas[point_index], branch.index, sol, path)):
                return True
        return False

    if resume is not None and done:
        return finish("completed")
    if resume is None and emit(0):
        return finish("stopped by callback")
    while True:
        steps += 1
        if steps > opts.max_steps:
            path.events.append(PathEvent("max_steps", alpha, f"step cap {opts.max_steps} reached", branch.index))
            return finish("max_steps")
        a_new = alpha + s * h
        clipped = False
        if a_new >= hi or a_new <= lo:
            a_new = min(max(a_new, lo), hi)
            clipped = True
        step = abs(a_new - alpha)
        y_pred = solver.solve(Z, (1.0 - a_new) * f1 + a_new * f2) if step > 0 else y
        if step > 0 and is_fixed_point(system, y_pred, Z):
            alpha, y = a_new, y_pred
            idx = path.add_point(branch, alpha, y)
            h = min(opts.c_p * h, opts.h_max)
            if emit(idx):
                return finish("stopped by callback", done=clipped)
            if clipped:
                return finish("completed")
            continue
        if h > opts.h_min and step > 0:
            h = max(opts.c_s * h, opts.h_min)
            continue
        # ---- branching algorithm at the last point (alpha, y) of the branch
        h_fail = step if step > 0 else h
        if len(path.transitions) >= opts.max_transitions:
            path.events.append(PathEvent("max_transitions", alpha, f"transition cap {opts.max_transitions} reached",
                                         branch.index))
            return finish("max_transitions")
        choice = _branching(system, solver, y, Z, alpha, s, h_fail, lo, hi)
        if choice is None:
            path.events.append(PathEvent("no_indicator", alpha, "no set change available at the branch end",
                                         branch.index))
            return finish("stuck")
        tkind, node, kind, Z_new, s_new, a_next, y_next, verified, changes = choice
        a1 = alpha + s * h_fail
        if not verified:
            path.events.append(PathEvent(
                "unverified_transition", alpha,
                "no candidate set change gives a solution on either side; the seed's rule (a fold) was applied "
                "with the smallest indicator", branch.index, {"node": node, "set": kind}))
        key = (Z_new.canonical_key(system.friction), s_new, round(a_next / max(opts.h_min, 1e-300)))
        last_seen[key] = last_seen.get(key, 0) + 1
        if last_seen[key] > 2:
            path.events.append(PathEvent("cycling", alpha, "the branching algorithm returns to the same branch at "
                                         "the same alpha; the transition cannot be resolved by the seed's indicator",
                                         branch.index, {"node": node, "set": kind}))
            return finish("cycling")
        branch.alpha_exit = alpha
        tr = Transition(len(path.transitions), alpha, tkind, node, kind, branch.index, len(path.branches),
                        bracket=(min(alpha, a1), max(alpha, a1)),
                        changes=changes)
        path.transitions.append(tr)
        log.info("alpha=%.8g %s transition: node %d set %s", alpha, tkind, node, kind)
        branch = path.add_branch(Z_new, s_new, *branch_endpoints(system, solver, Z_new), origin=tr.index,
                                 parent=branch.index, alpha_enter=alpha)
        Z, s, alpha, y = Z_new, s_new, a_next, y_next
        idx = path.add_point(branch, alpha, y)
        if emit(idx):
            return finish("stopped by callback", done=tkind == "transversal" and (alpha >= hi or alpha <= lo))
        if tkind == "transversal" and (alpha >= hi or alpha <= lo):
            return finish("completed")
