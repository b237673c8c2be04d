"""Matplotlib plots of a solution path (cfcontact.plotting)."""

import os
import subprocess
import sys

import numpy as np
import pytest
from matplotlib.image import imread

import cfcontact
from cfcontact.errors import InputError
from cfcontact.lumped import one_node, random_system
from cfcontact.plotting import (
    default_component,
    plot_multiplicity,
    plot_path,
    save_figure,
)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope="module")
def one_node_path():
    return cfcontact.trace_path(one_node(), 0.0, 1.0)


@pytest.fixture(scope="module")
def transversal_path():
    """Three contact nodes, transversal transitions only (no folds)."""
    path = cfcontact.trace_path(random_system(3, 0, friction=1.0), 0.0, 1.0)
    assert path.status == "completed"
    return path


def _line(ax, gid):
    lines = [ln for ln in ax.get_lines() if ln.get_gid() == gid]
    assert len(lines) <= 1
    return lines[0] if lines else None


def _png_ok(fn, size):
    img = imread(fn)
    assert img.shape[1] == size[0] and img.shape[0] == size[1], img.shape
    rgb = img[..., :3].reshape(-1, 3)
    assert rgb.std() > 0.02, "image is blank"
    assert len(np.unique((rgb * 255).round().astype(int), axis=0)) > 10
    return img


def test_default_component_is_node_with_largest_lam_n_range(transversal_path):
    path = transversal_path
    lam_n = path.ys[:, path.n:path.n + path.m]
    spread = lam_n.max(0) - lam_n.min(0)
    assert default_component(path) == ("lam_n", int(np.argmax(spread)))
    assert default_component(cfcontact.trace_path(one_node(), 0, 1)) == ("lam_n", 0)


def test_plot_path_png_size_and_fold_markers(one_node_path, tmp_path):
    path = one_node_path
    assert len(path.folds) == 2
    fig = plot_path(path, figsize=(6, 4), dpi=100, title="one node")
    ax = fig.axes[0]
    folds = _line(ax, "folds")
    assert folds is not None and len(folds.get_xdata()) == len(path.folds)
    assert np.allclose(sorted(folds.get_xdata()), sorted(t.alpha for t in path.folds))
    assert _line(ax, "transitions") is None  # no transversal transitions on this path
    curve = _line(ax, "path")
    assert np.allclose(curve.get_xdata(), path.alphas)
    assert np.allclose(curve.get_ydata(), path.component(("lam_n", 0)))
    assert ax.get_xlabel() == "α" and ax.get_ylabel() == "λν at node 0"
    fn = save_figure(fig, tmp_path / "sub" / "path.png")
    _png_ok(fn, (600, 400))


@pytest.mark.slow
def test_no_pyplot_state(tmp_path):
    """Plotting and saving never import pyplot nor change the process-wide backend."""
    code = (
        "import sys, matplotlib\n"
        "raw = lambda: dict.__getitem__(matplotlib.rcParams, 'backend')  # no auto-resolution\n"
        "backend = raw()\n"
        "import cfcontact\n"
        "from cfcontact.plotting import plot_path, plot_multiplicity, save_figure\n"
        "p = cfcontact.trace_path(cfcontact.one_node(), 0, 1)\n"
        f"save_figure(plot_path(p, zoom=(0.3, 0.6)), {str(tmp_path / 'x.png')!r})\n"
        f"save_figure(plot_multiplicity(p), {str(tmp_path / 'x.pdf')!r})\n"
        "assert 'matplotlib.pyplot' not in sys.modules\n"
        "assert raw() == backend\n"
        "print('ok')\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")})
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr


def test_fold_marker_values_on_path(one_node_path):
    path = one_node_path
    fig = plot_path(path, component=("u", 1))
    folds = _line(fig.axes[0], "folds")
    idx = path.component_index(("u", 1))
    for a, v in zip(folds.get_xdata(), folds.get_ydata()):
        t = min(path.folds, key=lambda t: abs(t.alpha - a))
        assert v == pytest.approx(path.branch_y(t.from_branch, t.alpha)[idx])


def test_marks_can_be_switched_off(one_node_path):
    fig = plot_path(one_node_path, mark_folds=False)
    assert _line(fig.axes[0], "folds") is None


def test_transversal_markers(transversal_path, tmp_path):
    path = transversal_path
    n_tr = sum(t.kind == "transversal" for t in path.transitions)
    assert n_tr > 0
    fig = plot_path(path, component=("lam_t", 1), ylabel="tangential", dpi=80, figsize=(5, 3))
    ax = fig.axes[0]
    assert len(_line(ax, "transitions").get_xdata()) == n_tr
    assert _line(ax, "folds") is None
    assert ax.get_ylabel() == "tangential"
    _png_ok(save_figure(fig, tmp_path / "tr.png"), (400, 240))


def test_zoom_panel_and_inset(one_node_path, tmp_path):
    path = one_node_path
    lo, hi = sorted(t.alpha for t in path.folds)
    fig = plot_path(path, zoom=(lo - 0.02, hi + 0.02), figsize=(9, 4), dpi=100)
    assert len(fig.axes) == 2
    zax = fig.axes[1]
    assert zax.get_xlim() == pytest.approx((lo - 0.02, hi + 0.02))
    assert len(_line(zax, "folds").get_xdata()) == len(path.folds)
    _png_ok(save_figure(fig, tmp_path / "zoom.png"), (900, 400))

    fig2 = plot_path(path, zoom=(0.3, 0.6, -0.1, 0.5), zoom_style="inset")
    inset = fig2.axes[0].child_axes
    assert len(inset) == 1 and inset[0].get_ylim() == pytest.approx((-0.1, 0.5))

    with pytest.raises(InputError):
        plot_path(path, zoom=(0.6, 0.3))
    with pytest.raises(InputError):
        plot_path(path, zoom=(2.0, 3.0))


def test_user_axes(one_node_path):
    from matplotlib.figure import Figure

    fig = Figure()
    ax = fig.add_subplot(1, 1, 1)
    assert plot_path(one_node_path, ax=ax) is fig
    assert plot_multiplicity(one_node_path, ax=ax) is fig


def test_pdf_and_bad_extension(one_node_path, tmp_path):
    fig = plot_path(one_node_path)
    fn = save_figure(fig, tmp_path / "a" / "b" / "path.pdf")
    with open(fn, "rb") as fh:
        assert fh.read(5) == b"%PDF-"
    with pytest.raises(InputError, match="unsupported figure format"):
        save_figure(fig, tmp_path / "path.svgz")
    with pytest.raises(InputError):
        save_figure(fig, tmp_path / "noext")


def test_bad_component(one_node_path):
    with pytest.raises(InputError):
        plot_path(one_node_path, component=("lam_n", 5))
    with pytest.raises(InputError):
        plot_path(one_node_path, component=("sigma", 0))
    with pytest.raises(InputError):
        plot_path(one_node_path, component="lam_n")


def test_multiplicity_steps(one_node_path, tmp_path):
    path = one_node_path
    fig = plot_multiplicity(path, figsize=(6, 3), dpi=100)
    ax = fig.axes[0]
    stairs = [p for p in ax.patches if p.get_gid() == "multiplicity"]
    assert len(stairs) == 1
    values, edges = stairs[0].get_data()[:2]
    assert list(values) == [1, 3, 1]
    lo, hi = sorted(t.alpha for t in path.folds)
    assert edges[1] == pytest.approx(lo) and edges[2] == pytest.approx(hi)
    assert edges[0] == pytest.approx(0.0) and edges[-1] == pytest.approx(1.0)
    assert max(values) == path.max_multiplicity()[0]
    _png_ok(save_figure(fig, tmp_path / "mult.png"), (600, 300))
