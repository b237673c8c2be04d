"""Off-screen PyVista renders (cfcontact.render) on a hand-made two-block geometry."""

import os
import subprocess
import sys

import numpy as np
import pytest
import scipy.sparse as sp

pv = pytest.importorskip("pyvista", reason="pyvista is not installed (scripts/install.sh installs it)")

from matplotlib.image import imread  # noqa: E402

from cfcontact import render  # noqa: E402
from cfcontact.errors import InputError  # noqa: E402
from cfcontact.path import SolutionPath  # noqa: E402
from cfcontact.ssnm import InactiveSets, Solution  # noqa: E402
from cfcontact.system import ContactGeometry  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


# ------------------------------------------------------------------ synthetic model
def _block(x0, y0, nx, ny, w, h, offset):
    xs = np.linspace(x0, x0 + w, nx + 1)
    ys = np.linspace(y0, y0 + h, ny + 1)
    X, Y = np.meshgrid(xs, ys)
    pts = np.column_stack([X.ravel(), Y.ravel()])
    cells = [[offset + j * (nx + 1) + i, offset + j * (nx + 1) + i + 1,
              offset + (j + 1) * (nx + 1) + i + 1, offset + (j + 1) * (nx + 1) + i]
             for j in range(ny) for i in range(nx)]
    return pts, np.array(cells)


def two_blocks_geometry(nx=4, ny=2):
    """Body 1 = [0, 2] x [0, 1] on top of body 2 = [0, 2] x [-1, 0], 4 x 2 quads each, every node free."""
    p1, c1 = _block(0.0, 0.0, nx, ny, 2.0, 1.0, 0)
    p2, c2 = _block(0.0, -1.0, nx, ny, 2.0, 1.0, len(p1))
    points = np.vstack([p1, p2])
    bottom1 = np.arange(nx + 1)
    top2 = len(p1) + ny * (nx + 1) + np.arange(nx + 1)
    m = nx + 1
    return ContactGeometry(
        points=points, cells=np.vstack([c1, c2]), cell_body=np.array([1] * len(c1) + [2] * len(c2)),
        dof_node=np.repeat(np.arange(len(points)), 2), dof_comp=np.tile([0, 1], len(points)),
        contact_nodes=np.column_stack([bottom1, top2]), contact_points=points[bottom1],
        normals=np.tile([0.0, -1.0], (m, 1)), tangents=np.tile([1.0, 0.0], (m, 1)))


def displacement(geom, scale):
    """Shear of body 1 to the right, slight tilt; body 2 sheared the other way."""
    P = geom.points
    U = np.zeros_like(P)
    upper = P[:, 1] > 0 - 1e-12
    upper[len(P) // 2:] = False
    U[upper, 0] = scale * (P[upper, 1] + 0.5)
    U[upper, 1] = -0.3 * scale * P[upper, 0]
    U[~upper, 0] = -0.3 * scale * (P[~upper, 1] + 1.0)
    return U[geom.dof_node, geom.dof_comp]


def make_solution(geom, states, scale=1e-3, alpha=0.5):
    m = len(states)
    return Solution(displacement(geom, scale), np.linspace(0.0, 1.0, m), np.zeros(m), alpha,
                    InactiveSets.from_states(states), 0)


MIXED = ["open", "stick", "slip+", "slip-", "stick"]


@pytest.fixture(scope="module")
def geom():
    return two_blocks_geometry()


@pytest.fixture(scope="module")
def synthetic_path(geom):
    """A made-up path with geometry: two affine branches (no solver involved)."""
    n, m = len(geom.dof_node), len(geom.contact_nodes)
    N = sp.csr_matrix((m, n))
    T = sp.csr_matrix((m, n))
    path = SolutionPath(n, m, N, T, 0.5, 1.0, "seed", 0.0, 1.0, geometry=geom)
    u = displacement(geom, 1e-3)
    y = lambda s: np.concatenate([s * u, np.ones(m), np.zeros(m)])  # noqa: E731
    b0 = path.add_branch(InactiveSets.from_states(["stick"] * m), 1, y(0.2), y(1.0), alpha_enter=0.0)
    for a in (0.0, 0.25, 0.5):
        path.add_point(b0, a, path.branch_y(b0, a))
    b0.alpha_exit = 0.5
    b1 = path.add_branch(InactiveSets.from_states(["open", "slip+", "slip+", "stick", "stick"]), 1,
                         y(0.2), y(-1.0), alpha_enter=0.5)
    for a in (0.5, 0.75, 1.0):
        path.add_point(b1, a, path.branch_y(b1, a))
    b1.alpha_exit = 1.0
    return path


# ------------------------------------------------------------------ helpers
def _rgb(fn):
    return (imread(fn)[..., :3] * 255).round().astype(int)


def _count(img, color, tol=10):
    return int((np.abs(img - np.asarray(color)).max(axis=-1) <= tol).sum())


def _not_blank(img, min_colors=20):
    flat = img.reshape(-1, 3)
    assert flat.std() > 5, "image is blank"
    assert len(np.unique(flat, axis=0)) >= min_colors


# ------------------------------------------------------------------ tests
def test_ensure_display_mode():
    mode = render.ensure_display()
    assert mode in ("display", "headless", "xvfb")
    if mode == "xvfb":
        assert os.environ.get("DISPLAY", "").startswith(":")
    assert render.ensure_display() == mode  # cached


def test_to_grid_types_and_displacement(geom):
    u = displacement(geom, 1e-3)
    grid = render.to_grid(geom, u, magnification=10.0)
    assert grid.n_cells == len(geom.cells) and grid.n_points == len(geom.points)
    assert set(np.asarray(grid.celltypes).tolist()) == {render.VTK_QUAD}
    assert np.allclose(grid.points[:, :2], geom.points + 10.0 * geom.displacement_field(u))
    tri = ContactGeometry(**{**geom.to_dict(), "cells": np.array([[0, 1, 6, -1], [0, 6, 5, -1]]),
                             "cell_body": np.array([1, 1])})
    assert set(np.asarray(render.to_grid(tri).celltypes).tolist()) == {render.VTK_TRIANGLE}


def test_auto_magnification(geom):
    u = displacement(geom, 1e-3)
    mag = render.auto_magnification(geom, [u])
    umax = np.linalg.norm(geom.displacement_field(u), axis=1).max()
    assert mag * umax == pytest.approx(0.1 * 2.0)  # model size: 2 x 2
    assert render.auto_magnification(geom, [np.zeros_like(u)]) == 1.0


@pytest.mark.slow
def test_render_solution_png(geom, tmp_path):
    sol = make_solution(geom, MIXED)
    fn = render.render_solution(geom, sol, tmp_path / "out" / "sol.png", window_size=(640, 400), title="two blocks")
    assert os.path.isfile(fn)
    img = _rgb(fn)
    assert img.shape == (400, 640, 3)
    _not_blank(img)
    for body, color in render.BODY_COLORS.items():
        assert _count(img, color) > 2000, f"body {body} not visible"
    for state in ("open", "stick", "slip+", "slip-"):
        assert _count(img, render.STATE_COLORS[state]) > 20, f"no {state} colour"
    assert _count(img, render.STATE_COLORS["slip+-"]) == 0


@pytest.mark.slow
def test_render_solution_state_colours_follow_states(geom, tmp_path):
    sol = make_solution(geom, ["stick"] * 5)
    img = _rgb(render.render_solution(geom, sol, tmp_path / "stick.png", window_size=(500, 400)))
    assert _count(img, render.STATE_COLORS["stick"]) > 20
    for state in ("open", "slip+", "slip-"):
        assert _count(img, render.STATE_COLORS[state]) == 0, state


@pytest.mark.slow
def test_render_solution_deformation_changes_picture(geom, tmp_path):
    sol0 = make_solution(geom, MIXED, scale=0.0)
    sol1 = make_solution(geom, MIXED, scale=1e-3)
    a = _rgb(render.render_solution(geom, sol0, tmp_path / "a.png", magnification=1.0, window_size=(400, 300)))
    b = _rgb(render.render_solution(geom, sol1, tmp_path / "b.png", magnification=200.0, window_size=(400, 300)))
    assert (np.abs(a - b).max(axis=-1) > 30).mean() > 0.01


@pytest.mark.slow
def test_render_solution_stress(geom, tmp_path):
    sol = make_solution(geom, MIXED)
    stress = np.linspace(0.0, 1.0, len(geom.cells))
    img = _rgb(render.render_solution(geom, sol, tmp_path / "s.png", stress=stress, window_size=(600, 400)))
    _not_blank(img, min_colors=50)
    assert _count(img, render.BODY_COLORS[1]) == 0  # cells coloured by stress, not by body
    with pytest.raises(InputError):
        render.render_solution(geom, sol, tmp_path / "bad.png", stress=np.ones(3))
    with pytest.raises(InputError):
        render.render_solution(geom, sol, tmp_path / "bad.png", show_stress=True)


def test_render_errors(geom, tmp_path):
    sol = make_solution(geom, MIXED)
    with pytest.raises(InputError, match="unsupported image format"):
        render.render_solution(geom, sol, tmp_path / "x.jpg")
    with pytest.raises(InputError):
        render.render_solution(geom, make_solution(geom, ["stick"] * 3), tmp_path / "x.png")
    bad = Solution(np.zeros(7), np.zeros(5), np.zeros(5), 0.0, InactiveSets.all_stick(5))
    with pytest.raises(InputError):
        render.render_solution(geom, bad, tmp_path / "x.png")
    with pytest.raises(InputError):
        render.render_solution(None, sol, tmp_path / "x.png")


@pytest.mark.slow
def test_render_panel_of_three(geom, tmp_path):
    sols = [make_solution(geom, ["stick"] * 5, 1e-3, 0.1),
            make_solution(geom, ["open", "open", "stick", "slip+", "slip+"], 2e-3, 0.5),
            make_solution(geom, ["slip-"] * 4 + ["open"], -1e-3, 0.9)]
    fn = render.render_panel(geom, sols, tmp_path / "panel.png", window_size=(1200, 400))
    img = _rgb(fn)
    assert img.shape == (400, 1200, 3)
    _not_blank(img)
    thirds = [img[:, k * 400:(k + 1) * 400] for k in range(3)]
    for part in thirds:
        assert _count(part, render.BODY_COLORS[1]) > 1000 and _count(part, render.BODY_COLORS[2]) > 1000
    # each subplot shows its own states (regression: actors removed from every subplot)
    assert _count(thirds[0], render.STATE_COLORS["stick"]) > 20
    assert _count(thirds[0], render.STATE_COLORS["open"]) == 0
    assert _count(thirds[1], render.STATE_COLORS["slip+"]) > 20
    assert _count(thirds[2], render.STATE_COLORS["slip-"]) > 20
    assert _count(thirds[2], render.STATE_COLORS["stick"]) == 0
    # default size: 600 x 450 per subplot, grid for many solutions
    fn = render.render_panel(geom, sols + sols[:2], tmp_path / "panel5.png")
    assert _rgb(fn).shape == (900, 1800, 3)
    assert render.state_counts(MIXED) == {"open": 1, "stick": 2, "slip": 2}


@pytest.mark.slow
def test_render_animation_frames(synthetic_path, tmp_path):
    res = render.render_animation(synthetic_path, tmp_path / "anim", frames=5, window_size=(320, 240))
    assert res.kind == "png-frames" and res.frames == 5 and len(res.files) == 5
    assert res.path == str(tmp_path / "anim")
    assert sorted(os.listdir(res.path)) == [f"frame_{k:04d}.png" for k in range(5)]
    assert res.alphas == pytest.approx([0.0, 0.25, 0.5, 0.75, 1.0])
    imgs = [_rgb(f) for f in res.files]
    assert all(im.shape == (240, 320, 3) for im in imgs)
    for im in imgs:
        _not_blank(im)
    assert _count(imgs[0], render.STATE_COLORS["open"]) == 0
    assert _count(imgs[-1], render.STATE_COLORS["open"]) > 5  # second branch has an open node
    assert np.abs(imgs[0] - imgs[-1]).max() > 0

    by_index = render.render_animation(synthetic_path, tmp_path / "sel", frames=[0, 5], window_size=(200, 160))
    assert by_index.alphas == [0.0, 1.0] and by_index.frames == 2


@pytest.mark.slow
def test_render_animation_gif(synthetic_path, tmp_path):
    from PIL import Image

    res = render.render_animation(synthetic_path, tmp_path / "a.gif", frames=4, window_size=(240, 160), fps=5)
    assert res.kind == "gif" and os.path.isfile(res.path)
    with Image.open(res.path) as im:
        assert im.size == (240, 160) and getattr(im, "n_frames", 1) == 4


@pytest.mark.slow
def test_render_animation_mp4_or_fallback(synthetic_path, tmp_path):
    res = render.render_animation(synthetic_path, tmp_path / "a.mp4", frames=2, window_size=(160, 120))
    try:
        import imageio_ffmpeg  # noqa: F401
    except ImportError:
        assert res.kind == "png-frames" and res.path == str(tmp_path / "a_frames") and "imageio-ffmpeg" in res.note
        assert len(os.listdir(res.path)) == 2
    else:
        assert res.kind == "mp4" and os.path.getsize(res.path) > 0


def test_render_animation_needs_geometry(tmp_path):
    import cfcontact

    path = cfcontact.trace_path(cfcontact.one_node(), 0, 1)
    with pytest.raises(InputError, match="(?i)geometry"):
        render.render_animation(path, tmp_path / "x.gif")


@pytest.mark.slow
def test_import_cfcontact_does_not_import_pyvista():
    code = ("import sys, cfcontact, cfcontact.render, cfcontact.plotting\n"
            "assert 'pyvista' not in sys.modules and 'vtk' not in sys.modules\n"
            "assert 'vtkmodules' not in sys.modules\nprint('ok')")
    env = {**os.environ, "PYTHONPATH": ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr


@pytest.mark.slow
def test_start_and_stop_xvfb():
    """The Xvfb helper used when VTK needs an X server (Debian's VTK) and DISPLAY is unset."""
    import shutil

    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed (scripts/install.sh installs xvfb)")
    saved = os.environ.get("DISPLAY")
    proc, display = render._start_xvfb(screen="64x64x24")
    try:
        assert proc.poll() is None and display.startswith(":") and display[1:].isdigit()
        assert os.path.exists(f"/tmp/.X11-unix/X{display[1:]}")
    finally:
        os.environ["DISPLAY"] = display
        render._stop_xvfb(proc, display)
        if saved is not None:
            os.environ["DISPLAY"] = saved
    assert proc.poll() is not None
    assert os.environ.get("DISPLAY") == saved
