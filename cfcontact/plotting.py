"""Plots of a traced solution path (Matplotlib, no pyplot).

Every function builds a :class:`matplotlib.figure.Figure` with an Agg canvas attached and
returns it; nothing touches pyplot's global state or the process-wide backend, so the
module works headless and inside other applications.  Write a figure with
:func:`save_figure` (PNG or PDF, by extension).

* :func:`plot_path` -- load parameter alpha (x axis) against one component of
  y = (u, lam_n, lam_t), like [JL-PF]'s Figure 6 (alpha against lam_n at one contact node),
  with fold transitions marked (red triangles) and transversal transitions (small dots),
  optionally with a zoom window (second panel or inset).
* :func:`plot_multiplicity` -- number of distinct solutions of the path over alpha (steps).
* :func:`default_component` -- the contact node whose lam_n varies most along the path.
* :func:`plot_friction_map` -- the (α, F) plane: solution counts as regions, fold curves, cusps,
  the critical friction (:mod:`cfcontact.fmap`).
"""

from __future__ import annotations

import numbers
import os
import warnings
from typing import Optional

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from cfcontact.errors import InputError

__all__ = ["plot_path", "plot_multiplicity", "plot_friction_map", "save_figure", "default_component",
           "component_label", "path_curve", "SUPPORTED_FORMATS"]

SUPPORTED_FORMATS = (".png", ".pdf")
PATH_COLOR = "#1f4e9c"
FOLD_COLOR = "#d62728"
TRANSVERSAL_COLOR = "#2ca02c"


def _new_figure(figsize, dpi, ncols=1):
    fig = Figure(figsize=figsize, dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    axes = [fig.add_subplot(1, ncols, k + 1) for k in range(ncols)]
    return fig, axes


def default_component(path) -> tuple:
    """("lam_n", i) for the contact node i whose lam_n has the largest range (max - min) along the path.

    Ties go to the lowest node index.  Raises :class:`InputError` for a path without points or
    without contact nodes.
    """
    if path.m == 0:
        raise InputError("the path has no contact nodes; give a component explicitly, e.g. ('u', 0)")
    lams = path.lams  # multipliers only: a lazy path forms no displacement here
    if lams.shape[0] == 0:
        raise InputError("the path has no points to plot")
    lam_n = lams[:, :path.m]
    spread = lam_n.max(axis=0) - lam_n.min(axis=0)
    return ("lam_n", int(np.argmax(spread)))


def component_label(path, component) -> str:
    """Axis label of a component: "λν at node 12", "λτ at node 3", "u at DOF 7 (node 4, y)"."""
    if isinstance(component, (int, np.integer)):
        idx = path.component_index(int(component))
        n, m = path.n, path.m
        if idx < n:
            component = ("u", idx)
        elif idx < n + m:
            component = ("lam_n", idx - n)
        else:
            component = ("lam_t", idx - n - m)
    name, i = component
    if name == "lam_n":
        return f"λν at node {i}"
    if name == "lam_t":
        return f"λτ at node {i}"
    geom = getattr(path, "geometry", None)
    if geom is not None and 0 <= i < len(geom.dof_node):
        return f"u at DOF {i} (node {int(geom.dof_node[i])}, {'xy'[int(geom.dof_comp[i])]})"
    return f"u at DOF {i}"


def _resolve_component(path, component):
    if component is None:
        component = default_component(path)
    elif isinstance(component, (int, np.integer)) and not isinstance(component, bool):
        # a plain integer is an index of y (path.component_index validates it)
        pass
    elif isinstance(component, (tuple, list)) and len(component) == 2:
        component = (str(component[0]), int(component[1]))
    else:
        raise InputError(f"component must be ('lam_n', i), ('lam_t', i), ('u', dof) or an index of y, "
                         f"got {component!r}")
    return component, path.component_index(component)


def path_curve(path, component=None):
    """(alphas, values, branch) of the stored points in path order for one component.

    Branches are affine in alpha, so the polyline through the stored points is the exact
    path between points of one branch (the exact method stores just entry and exit points).
    """
    _, idx = _resolve_component(path, component)
    if len(path.alphas) == 0:
        raise InputError("the path has no points to plot")
    return path.alphas, path.component(idx), path.point_branch


def _transition_points(path, idx, kind):
    a, v = [], []
    for t in path.transitions:
        if t.kind != kind:
            continue
        alpha = float(t.alpha)
        if idx >= path.n:  # a multiplier: no displacement needed
            value = float(path.branch_lam(t.from_branch, alpha)[idx - path.n])
        else:
            value = float(path.branch_y(t.from_branch, alpha)[idx])
        a.append(alpha)
        v.append(value)
    return np.asarray(a, dtype=float), np.asarray(v, dtype=float)


def _clip_range(alphas, values, lo, hi):
    """Values of the polyline inside lo <= alpha <= hi (vertices inside + crossings of lo, hi)."""
    out = list(values[(alphas >= lo) & (alphas <= hi)])
    for k in range(len(alphas) - 1):
        a0, a1 = alphas[k], alphas[k + 1]
        if a0 == a1:
            continue
        for edge in (lo, hi):
            if min(a0, a1) < edge < max(a0, a1):
                s = (edge - a0) / (a1 - a0)
                out.append(values[k] + s * (values[k + 1] - values[k]))
    return np.asarray(out, dtype=float)


def _zoom_limits(zoom, alphas, values):
    if zoom is None:
        return None
    z = tuple(float(x) for x in zoom)
    if len(z) not in (2, 4):
        raise InputError(f"zoom must be (alpha_lo, alpha_hi) or (alpha_lo, alpha_hi, value_lo, value_hi), got {zoom!r}")
    if not all(np.isfinite(z)) or not z[0] < z[1] or (len(z) == 4 and not z[2] < z[3]):
        raise InputError(f"zoom window is empty or not finite: {zoom!r}")
    if len(z) == 4:
        return z
    inside = _clip_range(alphas, values, z[0], z[1])
    if inside.size == 0:
        raise InputError(f"the path has no points with {z[0]} <= α <= {z[1]}; give value limits explicitly")
    vlo, vhi = float(inside.min()), float(inside.max())
    pad = 0.08 * (vhi - vlo) if vhi > vlo else 0.05 * max(abs(vhi), 1e-12)
    return (z[0], z[1], vlo - pad, vhi + pad)


def _draw_path(ax, alphas, values, fa, fv, ta, tv, mark_folds, mark_transitions, linewidth, markersize):
    ax.plot(alphas, values, "-", color=PATH_COLOR, lw=linewidth, label="solution path", gid="path")
    if mark_transitions and ta.size:
        ax.plot(ta, tv, "o", ls="none", color=TRANSVERSAL_COLOR, ms=0.6 * markersize,
                label="transversal transition", gid="transitions", zorder=3)
    if mark_folds and fa.size:
        ax.plot(fa, fv, "^", ls="none", color=FOLD_COLOR, ms=markersize, label="fold", gid="folds", zorder=4)


def plot_path(path, component=None, ax=None, zoom=None, mark_folds: bool = True, mark_transitions: bool = True,
              title: Optional[str] = None, xlabel: str = "α", ylabel: Optional[str] = None,
              figsize=(8.0, 4.5), dpi: int = 100, zoom_style: str = "panel", legend: bool = True,
              linewidth: float = 1.2, markersize: float = 7.0) -> Figure:
    """α (x axis) against one component of the solution along the path ([JL-PF]'s Figure 6).

    Parameters
    ----------
    path : SolutionPath
    component : ("lam_n", i), ("lam_t", i), ("u", dof) or an index of y; default
        :func:`default_component` (the contact node whose λν varies most).
    ax : an existing Matplotlib Axes to draw into (its figure is returned); default a new Figure.
    zoom : (alpha_lo, alpha_hi[, value_lo, value_hi]) -- adds a zoom window: a second panel
        (``zoom_style="panel"``, new figures only) or an inset (``zoom_style="inset"``, or
        always when ``ax`` is given); the value range defaults to the curve's range there.
    mark_folds : red triangles at fold transitions (Line2D with gid "folds", one marker per fold).
    mark_transitions : small green dots at transversal transitions (gid "transitions").
    title, xlabel, ylabel : labels (ylabel default e.g. "λν at node 12").
    figsize, dpi : size of a new figure in inches and dots per inch (PNG pixels = figsize * dpi).
    """
    _check_path(path)
    _check_figure_args(figsize, dpi)
    if zoom_style not in ("panel", "inset"):
        raise InputError(f"zoom_style must be 'panel' or 'inset', got {zoom_style!r}")
    component, idx = _resolve_component(path, component)
    alphas, values, _ = path_curve(path, component)
    fa, fv = _transition_points(path, idx, "fold")
    ta, tv = _transition_points(path, idx, "transversal")
    limits = _zoom_limits(zoom, alphas, values)

    if ax is None:
        panel = limits is not None and zoom_style == "panel"
        fig, axes = _new_figure(figsize, dpi, ncols=2 if panel else 1)
        ax = axes[0]
        zax = axes[1] if panel else None
    else:
        fig = ax.figure
        zax = None
    if ylabel is None:
        ylabel = component_label(path, component)

    _draw_path(ax, alphas, values, fa, fv, ta, tv, mark_folds, mark_transitions, linewidth, markersize)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    if title is not None:
        ax.set_title(title)
    if legend and (mark_folds and fa.size or mark_transitions and ta.size):
        ax.legend(loc="best", fontsize="small")

    if limits is not None:
        if zax is None:
            zax = ax.inset_axes([0.58, 0.08, 0.38, 0.38])
            zax.tick_params(labelsize="x-small")
        else:
            zax.set_xlabel(xlabel)
            zax.set_title(f"zoom: {limits[0]:.4g} ≤ {xlabel} ≤ {limits[1]:.4g}", fontsize="medium")
            zax.grid(True, alpha=0.3)
        _draw_path(zax, alphas, values, fa, fv, ta, tv, mark_folds, mark_transitions, linewidth, markersize)
        zax.set_xlim(limits[0], limits[1])
        zax.set_ylim(limits[2], limits[3])
        ax.indicate_inset_zoom(zax, edgecolor="0.3")
    return fig


def _check_path(path):
    """InputError unless ``path`` is a solution path (a SolutionPath or a FrictionPath)."""
    if not (hasattr(path, "multiplicity_intervals") and hasattr(path, "lams")):
        raise InputError(f"path must be a SolutionPath (trace_path's result or SolutionPath.load), got "
                         f"{type(path).__name__}")


def _check_figure_args(figsize, dpi):
    try:
        ok = len(figsize) == 2 and all(np.isfinite(float(v)) and float(v) > 0 for v in figsize)
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise InputError(f"figsize must be (width, height) in inches, both > 0, got {figsize!r}")
    if dpi is not None and not (isinstance(dpi, numbers.Real) and np.isfinite(dpi) and dpi > 0):
        raise InputError(f"dpi must be a number > 0, got {dpi!r}")


def _multiplicity_steps(path, alpha_range=None):
    """(edges, counts) of the steps of :meth:`SolutionPath.multiplicity_intervals`."""
    intervals = path.multiplicity_intervals(alpha_range)
    if not intervals:
        raise InputError("the path covers no α interval; nothing to plot")
    edges = np.asarray([a for a, _, _ in intervals] + [intervals[-1][1]], dtype=float)
    return edges, np.asarray([k for _, _, k in intervals], dtype=int)


def plot_multiplicity(path, ax=None, title: Optional[str] = None, xlabel: str = "α",
                      ylabel: str = "number of solutions", alpha_range=None, figsize=(8.0, 3.0),
                      dpi: int = 100, color: str = PATH_COLOR) -> Figure:
    """Multiplicity of the path (number of distinct solutions, :meth:`SolutionPath.multiplicity`) over α.

    The multiplicity is constant between consecutive branch ends, so it is evaluated once per
    such interval (at its midpoint) and drawn as steps (``Axes.stairs``, gid "multiplicity").
    Values exactly at branch ends (transition points) are not shown.
    """
    _check_path(path)
    _check_figure_args(figsize, dpi)
    edges, counts = _multiplicity_steps(path, alpha_range)
    if ax is None:
        fig, (ax,) = _new_figure(figsize, dpi)
    else:
        fig = ax.figure
    ax.stairs(counts, edges, color=color, lw=1.5, baseline=None, gid="multiplicity")
    ax.set_xlim(edges[0], edges[-1])
    top = int(counts.max())
    ax.set_ylim(-0.2 if counts.min() == 0 else 0.5, top + 0.5)
    ax.set_yticks(range(0 if counts.min() == 0 else 1, top + 1))
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    if title is not None:
        ax.set_title(title)
    return fig


# ------------------------------------------------------------------ friction map
def plot_friction_map(fmap, curves=None, critical=None, marks=(), ax=None, title: Optional[str] = None,
                      figsize=(8.0, 6.0), dpi: int = 100, cusps: bool = True) -> Figure:
    """The (α, F) plane of a load path: the number of solutions on the traced path at every grid
    point of a :class:`cfcontact.fmap.FrictionMap` as coloured regions (0: the path does not
    reach that α; -1: not traced), the fold curves of a :class:`cfcontact.fmap.FoldCurves` over
    it (black lines through exactly evaluated points; gid "fold_curves"), its cusps (gid
    "cusps"), the critical friction (a red dashed line, gid "critical") and ``marks`` (friction
    values, a grey horizontal line each, gid "marks")."""
    from matplotlib.colors import BoundaryNorm, ListedColormap

    counts = np.asarray(fmap.counts)
    if counts.size == 0:
        raise InputError("the map is empty; nothing to plot")
    if ax is None:
        fig, (ax,) = _new_figure(figsize, dpi)
    else:
        fig = ax.figure
    values = sorted(set(int(v) for v in np.unique(counts)))
    palette = {-1: "#bdbdbd", 0: "#ffffff", 1: "#deebf7", 2: "#c7e9c0", 3: "#9ecae1", 4: "#a1d99b",
               5: "#4292c6", 6: "#41ab5d", 7: "#2171b5", 8: "#238b45"}
    colors = [palette.get(v, "#08306b" if v % 2 else "#00441b") for v in values]
    bounds = [v - 0.5 for v in values] + [values[-1] + 0.5]
    mesh = ax.pcolormesh(fmap.alphas, fmap.frictions, counts, shading="nearest",
                         cmap=ListedColormap(colors), norm=BoundaryNorm(bounds, len(colors)), gid="map")
    cb = fig.colorbar(mesh, ax=ax, ticks=values, fraction=0.05, pad=0.02)
    cb.set_label("solutions on the traced path")
    if curves is not None:
        first = True
        for c in curves.curves:
            pts = c.sample()
            ax.plot(pts[:, 0], pts[:, 1], "-", color="k", lw=1.0, gid="fold_curves",
                    label="fold curves" if first else None)
            first = False
        if cusps and curves.cusps:
            cp = np.asarray(curves.cusps, dtype=float)
            ax.plot(cp[:, 0], cp[:, 1], "o", ls="none", ms=3.5, color="#ff7f0e", gid="cusps", label="cusps")
    if critical is not None and np.isfinite(critical.friction):
        ax.axhline(critical.friction, color=FOLD_COLOR, ls="--", lw=1.2, gid="critical",
                   label=f"critical F = {critical.friction:.6g}")
    for k, F in enumerate(marks):
        ax.axhline(float(F), color="0.35", ls=":", lw=1.2, gid="marks", label="marked F" if k == 0 else None)
        ax.annotate(f"F = {float(F):g}", (1.0, float(F)), xycoords=("axes fraction", "data"), fontsize="x-small",
                    ha="right", va="bottom", color="0.25")
    ax.set_xlim(float(np.min(fmap.alphas)), float(np.max(fmap.alphas)))
    ax.set_ylim(float(np.min(fmap.frictions)), float(np.max(fmap.frictions)))
    ax.set_xlabel("α (load path)")
    ax.set_ylabel("friction coefficient F")
    if title is not None:
        ax.set_title(title)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper right", fontsize="small", framealpha=0.9)
    return fig


def save_figure(fig: Figure, path, dpi: Optional[float] = None) -> str:
    """Write ``fig`` to ``path`` as PNG or PDF (chosen by the extension); parent directories are created.

    The PNG has exactly figsize * dpi pixels (no tight bounding box).  Returns the path written.
    """
    if not isinstance(fig, Figure):
        raise InputError(f"fig must be a matplotlib Figure (plot_path's result), got {type(fig).__name__}")
    _check_figure_args((1.0, 1.0), dpi)
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in SUPPORTED_FORMATS:
        raise InputError(f"unsupported figure format {ext or '(no extension)'!r} for {path!r}; "
                         f"use one of {', '.join(SUPPORTED_FORMATS)}")
    if os.path.isdir(path):
        raise InputError(f"cannot write the figure {path!r}: it is a folder")
    parent = os.path.dirname(os.path.abspath(path))
    try:
        os.makedirs(parent, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot write the figure {path!r}: no folder {parent!r} ({exc.strerror})") from None
    with warnings.catch_warnings():  # (a map of 2 x 2 grid points: matplotlib's layout gives up, harmlessly)
        warnings.filterwarnings("ignore", message="constrained_layout not applied")
        fig.savefig(path, format=ext[1:], dpi=fig.dpi if dpi is None else dpi)
    return path
