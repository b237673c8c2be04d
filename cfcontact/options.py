"""Options of the path-following layer, validated once where a path is asked for.

:class:`PathOptions` is a frozen dataclass: constructing it (also through
:func:`dataclasses.replace`) validates it, so the steppers take it as it is.  The callback is
not an option: :func:`cfcontact.path.trace_path` takes it separately.  :class:`AlphaSpan` is
the validated alpha range of one path.  Every field's metadata (``kind``, ``doc``,
``methods``) generates the ``[path]`` section of the case-file schema
(:mod:`cfcontact.case`).

Nothing here imports PETSc or dolfinx.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field, fields
from typing import Optional

from cfcontact.errors import InputError

#: Path-following methods (:func:`cfcontact.path.trace_path`).
METHODS = ("seed", "exact")
#: DirNeu backends (:func:`cfcontact.backend.select_solver`).
BACKENDS = ("auto", "full", "condensed")
#: The largest |alpha| of a path's range (alpha_start, alpha_end, alpha_min, alpha_max): the load
#: f(alpha) = (1 - alpha) f1 + alpha f2 grows like |alpha|, so a longer range only repeats the
#: asymptotic regime (and the seed method's steps of at most h_max could not cover it).
ALPHA_LIMIT = 1e6

#: The largest friction coefficient a case or a friction map takes ([contact] friction, [path]
#: friction_start / friction_end, map --friction-range): Coulomb coefficients of real materials are
#: below 10, and F = 30 already sticks every node of the seed's models
MAX_FRICTION = 1e6

#: The largest SSNM tolerance of a path's start point ([path] tol): a start solved more coarsely
#: leaves the branch it lies on unverified (the seed then ends "cycling")
MAX_TOL = 1e-2

#: Default relative tolerance of the exact method deciding that an indicator value or rate
#: "vanishes": relative to the local size of the indicators, on top of their rounding error measured
#: by iterative refinement (see :mod:`cfcontact.exact`).
TIE_RTOL = 1e-13


def _option(default, kind, doc, methods=METHODS):
    """A dataclass field with its case-file type (``kind``), a one-line doc and the methods using it."""
    return field(default=default, metadata={"kind": kind, "doc": doc, "methods": tuple(methods)})


def unused_options(method: str, names) -> list:
    """The names among ``names`` of PathOptions fields that ``method`` does not use, each with why:
    ["tree: used by the exact method only; ignored with method = 'seed'", ...]."""
    out = []
    for f in fields(PathOptions):
        if f.name in names and method not in f.metadata["methods"]:
            out.append(f"{f.name}: used by the {' and '.join(f.metadata['methods'])} method only; ignored "
                       f"with method = {method!r}")
    return out


@dataclass(frozen=True)
class PathOptions:
    """Options of the path-following layer (seed defaults, its Figure 6); validated on construction.

    h_min, h_max, c_p, c_s: step-size range and prolongation / shortening rates (seed).
    h0: initial step (seed).  max_steps, max_transitions: caps (the run stops with that status).
    alpha_min, alpha_max: the path stops when alpha leaves [alpha_min, alpha_max]
        (default: the interval between alpha_start and alpha_end).
    tol, max_iter: SSNM options for the start point.
    tie_rtol: relative tolerance under which an indicator counts as zero, beyond its measured
        rounding error (exact).
    tree: after the path, follow every alternative of every branch point (exact; see
        :func:`cfcontact.exact.trace_tree`).
    """

    h_min: float = _option(1e-5, "float", "smallest step; a failure at h_min is a transition", ("seed",))
    h_max: float = _option(5.0, "float", "largest step", ("seed",))
    c_p: float = _option(1.3, "float", "step prolongation factor after an accepted step (> 1)", ("seed",))
    c_s: float = _option(0.5, "float", "step shortening factor after a rejected step (in (0, 1))", ("seed",))
    h0: float = _option(1e-2, "float", "initial step", ("seed",))
    max_steps: int = _option(200000, "int", "step cap (status max_steps)", ("seed",))
    max_transitions: int = _option(1000000, "int", "transition cap (status max_transitions)")
    alpha_min: Optional[float] = _option(None, "float", "stop when alpha < alpha_min (default: min(start, end))")
    alpha_max: Optional[float] = _option(None, "float", "stop when alpha > alpha_max (default: max(start, end))")
    tol: float = _option(1e-9, "float", f"SSNM tolerance of the start point, in (0, {MAX_TOL:g}]")
    max_iter: int = _option(100, "int", "SSNM iterations of the start point")
    tree: bool = _option(False, "bool", "follow every alternative of every branch point too (the whole tree "
                                        "reachable from the start)", ("exact",))
    tie_rtol: float = _option(TIE_RTOL, "float", "indicator values within their rounding error plus tie_rtol x "
                                                 "their local scale vanish, in (0, 1e-2)", ("exact",))

    def __post_init__(self):
        bad = []
        for f in fields(self):  # the types first: the comparisons below need numbers
            v, kind = getattr(self, f.name), f.metadata.get("kind")
            if v is None and f.default is None:
                continue
            if kind == "float" and not (isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v)):
                raise InputError(f"PathOptions: {f.name} must be a finite number, got {v!r}")
            if kind == "int" and not (isinstance(v, numbers.Integral) and not isinstance(v, bool)):
                raise InputError(f"PathOptions: {f.name} must be an integer, got {v!r}")
            if kind == "bool" and v not in (True, False):
                raise InputError(f"PathOptions: {f.name} must be true or false, got {v!r}")
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
        if not (0 < self.tol <= MAX_TOL):
            bad.append(f"tol must be in (0, {MAX_TOL:g}], got {self.tol!r}")
        if not (0 < self.tie_rtol < 1e-2):
            bad.append(f"tie_rtol must be in (0, 1e-2), got {self.tie_rtol!r}")
        if bad:
            raise InputError("invalid path options: " + "; ".join(bad))

    @classmethod
    def names(cls) -> tuple:
        return tuple(f.name for f in fields(cls))

    @classmethod
    def with_overrides(cls, options: Optional["PathOptions"] = None, **overrides) -> "PathOptions":
        """``options`` (default: the defaults) with some fields replaced; InputError names unknown fields."""
        if options is not None and not isinstance(options, cls):
            raise InputError(f"options must be PathOptions, got {type(options).__name__}")
        unknown = sorted(set(overrides) - set(cls.names()))
        if unknown:
            raise InputError(f"unknown path option(s) {unknown}; valid: {sorted(cls.names())}")
        if options is None:
            return cls(**overrides)
        return cls(**{**options.to_dict(), **overrides}) if overrides else options

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @classmethod
    def from_dict(cls, d: dict) -> "PathOptions":
        """The options of a saved path (its ``options`` dict; keys of other versions are ignored)."""
        return cls(**{k: v for k, v in d.items() if k in cls.names()})


@dataclass(frozen=True)
class AlphaSpan:
    """The alpha range of one path: from ``start`` towards ``end``, stopping outside [lo, hi]."""

    start: float
    end: float
    lo: float
    hi: float

    @classmethod
    def of(cls, alpha_start, alpha_end, options: PathOptions) -> "AlphaSpan":
        """Validated span (InputError for an empty range or a start outside [alpha_min, alpha_max])."""
        try:
            a0, a1 = float(alpha_start), float(alpha_end)
        except (TypeError, ValueError):
            raise InputError(f"alpha_start and alpha_end must be numbers, got {alpha_start!r}, {alpha_end!r}") from None
        if not (math.isfinite(a0) and math.isfinite(a1)) or a0 == a1:
            raise InputError(f"alpha range is empty: alpha_start={alpha_start}, alpha_end={alpha_end} "
                             f"(need two different finite numbers)")
        for name, value in (("alpha_start", a0), ("alpha_end", a1), ("alpha_min", options.alpha_min),
                            ("alpha_max", options.alpha_max)):
            if value is not None and not (abs(float(value)) <= ALPHA_LIMIT):
                raise InputError(f"{name}={value!r} is out of range: |alpha| must be <= {ALPHA_LIMIT:g} (the load "
                                 f"grows like |alpha|; rescale f1 and f2 for a longer range)")
        lo = min(a0, a1) if options.alpha_min is None else float(options.alpha_min)
        hi = max(a0, a1) if options.alpha_max is None else float(options.alpha_max)
        if not lo < hi:
            raise InputError(f"alpha range is empty: [alpha_min, alpha_max] = [{lo}, {hi}]")
        if not (lo <= a0 <= hi):
            raise InputError(f"alpha_start={alpha_start} lies outside [alpha_min, alpha_max] = [{lo}, {hi}]")
        return cls(a0, a1, lo, hi)

    @property
    def direction(self) -> int:
        """+1 when the path runs towards larger alpha, else -1."""
        return 1 if self.end > self.start else -1


def check_method(method) -> str:
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; valid: {', '.join(map(repr, METHODS))}")
    return method


def check_backend(backend) -> str:
    if backend not in BACKENDS:
        raise InputError(f"unknown backend {backend!r}; valid: {', '.join(map(repr, BACKENDS))}")
    return backend
