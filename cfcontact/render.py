"""Pictures of deformed configurations with PyVista, off-screen.

PyVista (and VTK) are imported inside the functions: ``import cfcontact`` and
``import cfcontact.render`` never need them.

* :func:`ensure_display` makes off-screen rendering possible on a headless machine.  PyPI's
  VTK wheel (Debian 12 install) renders through EGL/OSMesa without any X server; Debian's VTK
  (Debian 13) is built for X only and needs a display, so without ``DISPLAY`` an ``Xvfb`` is
  started (free display chosen by Xvfb itself through ``-displayfd``, stopped at exit).
  The render functions call it; set ``CFCONTACT_NO_XVFB=1`` to forbid starting Xvfb.
* :func:`render_solution` -- one deformed configuration to a PNG: each body in its own colour
  with mesh edges, contact nodes coloured by state (open / stick / slip+ / slip-, legend),
  optionally cells coloured by a given per-cell stress.
* :func:`render_panel` -- several solutions side by side, each titled with its index, α and
  the counts of open / stick / slip nodes.
* :func:`render_animation` -- frames along a :class:`~cfcontact.path.SolutionPath`; written as
  a GIF (``.gif``: Pillow, which Matplotlib depends on, else imageio), an MP4 (``.mp4``: imageio-ffmpeg), or
  numbered PNG frames in a directory (any other name, or when the requested writer is missing:
  ``<stem>_frames/frame_0000.png``...).  The :class:`AnimationResult` says which.

Magnification: by default displacements are scaled so that the largest one is 10 % of the
model size (the larger side of the bounding box); the factor is printed in the picture.
"""

from __future__ import annotations

import atexit
import logging
import os
import select
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

from cfcontact.errors import InputError

log = logging.getLogger(__name__)

__all__ = ["ensure_display", "render_solution", "render_panel", "render_animation", "to_grid",
           "auto_magnification", "state_counts", "AnimationResult", "STATE_COLORS", "BODY_COLORS"]

# RGB (0-255) of the contact-node states and the bodies (bodies neutral, states saturated).
STATE_COLORS = {
    "open": (31, 90, 230),     # blue
    "stick": (20, 170, 40),    # green
    "slip+": (220, 20, 20),    # red
    "slip-": (240, 130, 0),    # orange
    "slip+-": (150, 0, 150),   # purple (I_t^+ and I_t^- both: not a valid state, shown if it occurs)
}
STATE_LABELS = {"open": "open", "stick": "stick", "slip+": "slip+", "slip-": "slip-", "slip+-": "slip+-"}
BODY_COLORS = {1: (236, 214, 170), 2: (190, 190, 196)}
EDGE_COLOR = (70, 70, 70)
FOUNDATION_COLOR = (60, 60, 60)
VTK_TRIANGLE, VTK_QUAD = 5, 9

_display_state: dict = {}


# ----------------------------------------------------------------------------- display
def _vtk_has_headless_window() -> bool:
    """True when this VTK build has an EGL or OSMesa render window (renders without X)."""
    try:
        import vtkmodules.vtkRenderingOpenGL2 as gl
    except ImportError:  # pragma: no cover - pyvista always brings it
        return False
    return any(hasattr(gl, name) for name in ("vtkEGLRenderWindow", "vtkOSMesaRenderWindow"))


_PROBE = r"""
import os, sys
import vtkmodules.vtkRenderingOpenGL2  # noqa: F401  (registers the OpenGL backend)
from vtkmodules.vtkRenderingCore import vtkRenderWindow, vtkRenderer
from vtkmodules.vtkCommonCore import vtkObject
vtkObject.GlobalWarningDisplayOff()
w = vtkRenderWindow()
w.SetOffScreenRendering(1)
w.SetSize(16, 16)
r = vtkRenderer()
w.AddRenderer(r)
w.Render()
sys.stdout.write(w.GetClassName())
"""


def _probe_offscreen(env=None, timeout=60.0) -> Optional[str]:
    """Render a 16x16 window off-screen in a subprocess; the window class on success, else None.

    A subprocess, because a VTK build that cannot open a window may abort the process.
    """
    try:
        proc = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True,
                              timeout=timeout, env=env)
    except (subprocess.TimeoutExpired, OSError):
        return None
    if proc.returncode != 0:
        return None
    return proc.stdout.strip() or None


def _start_xvfb(screen="1920x1080x24", timeout=20.0):
    """Start Xvfb on a free display (Xvfb picks it, -displayfd); returns (process, ":N")."""
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        raise RuntimeError("rendering needs an X display (this VTK has no EGL/OSMesa window), DISPLAY is "
                           "unset and Xvfb is not installed; install it (Debian: apt-get install xvfb) "
                           "or set DISPLAY")
    rfd, wfd = os.pipe()
    try:
        proc = subprocess.Popen([xvfb, "-displayfd", str(wfd), "-screen", "0", screen, "-nolisten", "tcp",
                                 "-noreset"], pass_fds=(wfd,), stdin=subprocess.DEVNULL,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    finally:
        os.close(wfd)
    data = b""
    deadline = time.monotonic() + timeout
    try:
        while not data.endswith(b"\n"):
            left = deadline - time.monotonic()
            if left <= 0 or proc.poll() is not None:
                break
            ready, _, _ = select.select([rfd], [], [], min(left, 0.5))
            if ready:
                chunk = os.read(rfd, 64)
                if not chunk:
                    break
                data += chunk
    finally:
        os.close(rfd)
    number = data.strip().decode(errors="replace")
    if not number.isdigit():
        err = ""
        if proc.poll() is None:
            proc.kill()
        try:
            err = proc.communicate(timeout=5)[1].decode(errors="replace")[-2000:]
        except Exception:  # noqa: BLE001
            pass
        raise RuntimeError(f"Xvfb did not report a display within {timeout:.0f} s (exit status "
                           f"{proc.poll()}):\n{err}")
    proc.stderr.close()
    return proc, ":" + number


def _stop_xvfb(proc, display):
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)
    if os.environ.get("DISPLAY") == display:
        del os.environ["DISPLAY"]


def ensure_display() -> str:
    """Make off-screen rendering work here; returns how: "display", "headless" or "xvfb".

    * ``DISPLAY`` set: use it ("display").
    * This VTK has an EGL/OSMesa window (PyPI wheel) and a 16x16 off-screen render succeeds in a
      subprocess: nothing to do ("headless").  For VTK >= 9.4 wheels, which try X first and print
      a "bad X server connection" warning, ``VTK_DEFAULT_OPENGL_WINDOW`` is set to the working class.
    * Otherwise start ``Xvfb`` on a free display, wait until it is ready, set ``DISPLAY`` for this
      process (and its children) and stop it at exit ("xvfb").

    The result is cached per process.  ``CFCONTACT_NO_XVFB=1`` turns the Xvfb start into an error.
    """
    if "mode" in _display_state:
        return _display_state["mode"]
    if os.environ.get("DISPLAY"):
        mode = "display"
    else:
        mode = None
        if _vtk_has_headless_window():
            if os.environ.get("VTK_DEFAULT_OPENGL_WINDOW"):  # the user's choice
                if _probe_offscreen(dict(os.environ)) is not None:
                    mode = "headless"
            else:
                for candidate in ("vtkEGLRenderWindow", "vtkOSMesaRenderWindow"):
                    env = dict(os.environ, VTK_DEFAULT_OPENGL_WINDOW=candidate)
                    if _probe_offscreen(env) == candidate:
                        os.environ["VTK_DEFAULT_OPENGL_WINDOW"] = candidate
                        mode = "headless"
                        break
        if mode is None:
            if os.environ.get("CFCONTACT_NO_XVFB") == "1":
                raise RuntimeError("off-screen rendering needs an X display here, DISPLAY is unset and "
                                   "CFCONTACT_NO_XVFB=1 forbids starting Xvfb")
            proc, display = _start_xvfb()
            os.environ["DISPLAY"] = display
            atexit.register(_stop_xvfb, proc, display)
            _display_state["xvfb"] = proc
            log.info("started Xvfb on display %s (pid %d)", display, proc.pid)
            mode = "xvfb"
    _display_state["mode"] = mode
    return mode


# ----------------------------------------------------------------------------- helpers
def _rgb(c):
    return tuple(v / 255.0 for v in c)


def _cells_and_types(cells):
    cells = np.asarray(cells)
    if cells.ndim != 2 or cells.shape[1] not in (3, 4):
        raise InputError(f"geometry.cells must be a (C, 3) or (C, 4) array, got shape {cells.shape}")
    counts = (cells >= 0).sum(axis=1)
    if np.any((counts != 3) & (counts != 4)):
        raise InputError("every cell must have 3 (triangle) or 4 (quadrilateral) nodes")
    flat = []
    for row, k in zip(cells, counts):
        flat.append(k)
        flat.extend(int(v) for v in row[:k])
    types = np.where(counts == 4, VTK_QUAD, VTK_TRIANGLE).astype(np.uint8)
    return np.asarray(flat, dtype=np.int64), types


def _deformed_points(geometry, u, magnification, alpha=None):
    P = np.asarray(geometry.points, dtype=float)[:, :2]
    U = np.zeros_like(P) if u is None else geometry.displacement_field(np.asarray(u, dtype=float), alpha)[:, :2]
    X = P + magnification * U
    return np.column_stack([X, np.zeros(len(X))])


def to_grid(geometry, u=None, magnification: float = 1.0, stress=None, alpha=None):
    """pyvista.UnstructuredGrid of the mesh, points moved by magnification * displacement_field(u, alpha)
    (``alpha``: where prescribed non-zero displacements are taken, see ``ContactGeometry.prescribed``).

    Cell data: "body" (geometry.cell_body) and, if given, "stress" (one value per cell).
    """
    import pyvista as pv

    cells, types = _cells_and_types(geometry.cells)
    grid = pv.UnstructuredGrid(cells, types, _deformed_points(geometry, u, magnification, alpha))
    grid.cell_data["body"] = np.asarray(geometry.cell_body)
    if stress is not None:
        stress = np.asarray(stress, dtype=float).ravel()
        if stress.shape != (grid.n_cells,):
            raise InputError(f"stress must have one value per cell ({grid.n_cells}), got shape {stress.shape}")
        grid.cell_data["stress"] = stress
    return grid


def model_size(geometry) -> float:
    P = np.asarray(geometry.points, dtype=float)[:, :2]
    ext = P.max(axis=0) - P.min(axis=0)
    return float(ext.max()) if P.size else 1.0


def auto_magnification(geometry, us, fraction: float = 0.1, alphas=None) -> float:
    """Scale making the largest nodal displacement of any of ``us`` (at ``alphas``, for prescribed
    displacements) equal ``fraction`` * model size."""
    umax = 0.0
    for k, u in enumerate(us):
        if u is None:
            continue
        U = geometry.displacement_field(np.asarray(u, dtype=float), None if alphas is None else alphas[k])
        umax = max(umax, float(np.linalg.norm(U, axis=1).max(initial=0.0)))
    if umax == 0.0 or not np.isfinite(umax):
        return 1.0
    return fraction * model_size(geometry) / umax


def _states(solution, m):
    if solution is None:
        return []
    sets = getattr(solution, "sets", None)
    states = list(solution.states()) if hasattr(solution, "states") else list(sets.states())
    if len(states) != m:
        raise InputError(f"the solution has {len(states)} contact states but the geometry has {m} contact nodes")
    return states


def state_counts(states) -> dict:
    """{"open": a, "stick": b, "slip": c} (slip+ and slip- together)."""
    states = list(states)
    return {"open": states.count("open"), "stick": states.count("stick"),
            "slip": sum(s.startswith("slip") for s in states)}


def _check_solution(geometry, solution):
    if geometry is None:
        raise InputError("rendering needs the model's ContactGeometry (lumped models have none)")
    u = np.asarray(solution.u, dtype=float)
    n = len(geometry.dof_node)
    if u.shape != (n,):
        raise InputError(f"solution.u has shape {u.shape}, the geometry has {n} DOFs")
    return u


def _contact_xy(geometry, u, magnification, alpha=None):
    """Deformed positions of the slave node of each contact pair (body 1's with matching nodes)."""
    X = _deformed_points(geometry, u, magnification, alpha)
    if np.asarray(geometry.contact_nodes).size == 0:
        return np.zeros((0, 3))
    return X[geometry.slave_nodes()]


def _point_size(window_size, cols=1, rows=1):
    w, h = window_size
    return float(max(7, min(w / cols, h / rows) / 45))


OBSTACLE_SAMPLES = 120


def _obstacle_outline(obstacle, cp):
    """(OBSTACLE_SAMPLES, 2) points of a rigid obstacle's surface (``ContactGeometry.obstacle``) along
    the contact points ``cp``, a little beyond them."""
    if obstacle.get("kind") == "circle":
        c, r = np.asarray(obstacle["center"], dtype=float), float(obstacle["radius"])
        ang = np.unwrap(np.sort(np.arctan2(cp[:, 1] - c[1], cp[:, 0] - c[0])))
        pad = 0.15 * max(ang[-1] - ang[0], 0.2)
        t = np.linspace(ang[0] - pad, ang[-1] + pad, OBSTACLE_SAMPLES)
        return c + r * np.column_stack([np.cos(t), np.sin(t)])
    p, nv = np.asarray(obstacle["point"], dtype=float), np.asarray(obstacle["normal"], dtype=float)
    d = np.array([-nv[1], nv[0]])
    s = (cp - p) @ d
    pad = 0.1 * max(s.max() - s.min(), 1e-12)
    return p + np.outer(np.linspace(s.min() - pad, s.max() + pad, OBSTACLE_SAMPLES), d)


def _draw(plotter, geometry, solution, magnification, stress=None, point_size=10.0, legend=True,
          legend_size=(0.2, 0.2), legend_loc="upper right", clim=None, title=None, text=None, font_size=12, scalar_bar=True):
    """Add one deformed configuration to the current subplot (actors named, so a redraw replaces them)."""
    import pyvista as pv

    u = None if solution is None else _check_solution(geometry, solution)
    alpha = getattr(solution, "alpha", None)
    grid = to_grid(geometry, u, magnification, stress, alpha)
    if stress is not None and clim is None:
        clim = (float(np.min(stress)), float(np.max(stress)))
    bodies = np.asarray(geometry.cell_body)
    for body in sorted(set(bodies.tolist())):
        part = grid.extract_cells(np.flatnonzero(bodies == body))
        kw = dict(show_edges=True, edge_color=_rgb(EDGE_COLOR), line_width=1.0, name=f"body{body}", lighting=False)
        if stress is not None:
            plotter.add_mesh(part, scalars="stress", cmap="viridis", clim=clim, show_scalar_bar=False, **kw)
        else:
            plotter.add_mesh(part, color=_rgb(BODY_COLORS.get(body, (200, 200, 200))), **kw)
    if stress is not None and scalar_bar:
        plotter.add_scalar_bar("von Mises stress", vertical=True, position_x=0.86, position_y=0.08,
                               height=0.45, width=0.07, color="black", title_font_size=14,
                               label_font_size=12, n_labels=4, fmt="%.3g")
    nodes = np.asarray(geometry.contact_nodes)
    if nodes.size and np.all(nodes[:, 1] < 0):
        # rigid foundation: a line through the (undeformed) contact points, or the rigid obstacle
        cp = np.asarray(geometry.contact_points, dtype=float)[:, :2]
        obstacle = getattr(geometry, "obstacle", None)
        if obstacle:
            pts = np.column_stack([_obstacle_outline(obstacle, cp), np.zeros(OBSTACLE_SAMPLES)])
        else:
            tang = np.asarray(geometry.tangents, dtype=float)
            order = np.argsort(cp @ tang[0]) if len(cp) else []
            pts = np.column_stack([cp[order], np.zeros(len(cp))])
        if len(pts) >= 2:
            plotter.add_mesh(pv.lines_from_points(pts), color=_rgb(FOUNDATION_COLOR), line_width=3,
                             name="foundation")
    states = _states(solution, len(nodes)) if solution is not None else []
    if states:
        xy = _contact_xy(geometry, u, magnification, alpha)
        xy[:, 2] = 1e-3 * model_size(geometry)  # in front of the bodies
        labels = []
        for state in STATE_COLORS:
            sel = [k for k, s in enumerate(states) if s == state]
            name = f"contact-{state}"
            if not sel:
                plotter.renderer.remove_actor(name, render=False)  # this subplot only
                continue
            cloud = pv.PolyData(xy[sel])
            plotter.add_mesh(cloud, color=_rgb(STATE_COLORS[state]), point_size=point_size,
                             render_points_as_spheres=True, lighting=False, name=name)
            labels.append([f"{STATE_LABELS[state]} ({len(sel)})", _rgb(STATE_COLORS[state])])
        if legend and labels:
            _legend(plotter, labels, legend_size, legend_loc)
    if title is not None:
        plotter.add_text(title, position="upper_edge", font_size=font_size, color="black", name="title")
    if text is not None:
        plotter.add_text(text, position="lower_left", font_size=max(font_size - 3, 7), color="black",
                         name="info")


def _legend(plotter, labels, size, loc="upper right"):
    """Legend in a corner (keyword sets for older PyVista tried in turn)."""
    tries = (dict(bcolor="white", border=True, size=size, loc=loc, face="circle"),
             dict(bcolor="white", border=True, size=size, loc=loc),
             dict(bcolor="white", size=size))
    for kw in tries:
        try:
            plotter.add_legend(labels, **kw)
            return
        except TypeError:
            continue


def _view(plotter, bounds, aspect, legend=True, top=0.88, right=0.77):
    """2-D parallel view fitting ``bounds`` into the free part of the viewport.

    The model goes into x in [0.03, right] (legend on the right; [0.03, 0.97] without legend) and
    y in [0.08, top] (title above, info text below) of the viewport, ``aspect`` = width / height.
    """
    x0, x1, y0, y1 = bounds[:4]
    rx = (0.03, right if legend else 0.97)
    ry = (0.08, top)
    w, h = max(x1 - x0, 1e-30), max(y1 - y0, 1e-30)
    scale = max(w / ((rx[1] - rx[0]) * 2.0 * aspect), h / ((ry[1] - ry[0]) * 2.0))  # half the visible height
    cx_n, cy_n = 0.5 * (rx[0] + rx[1]), 0.5 * (ry[0] + ry[1])
    fx = 0.5 * (x0 + x1) + (0.5 - cx_n) * 2.0 * scale * aspect
    fy = 0.5 * (y0 + y1) + (0.5 - cy_n) * 2.0 * scale
    dist = 10.0 * max(w, h)
    cam = plotter.camera
    cam.parallel_projection = True
    cam.focal_point = (fx, fy, 0.0)
    cam.position = (fx, fy, dist)
    cam.up = (0.0, 1.0, 0.0)
    cam.parallel_scale = scale
    plotter.renderer.ResetCameraClippingRange()


def _aspect(window_size, rows=1, cols=1):
    return (window_size[0] / cols) / (window_size[1] / rows)


def _bounds(geometry, us, magnification, alphas=None):
    lo = np.full(2, np.inf)
    hi = np.full(2, -np.inf)
    for k, u in enumerate(us):
        X = _deformed_points(geometry, u, magnification, None if alphas is None else alphas[k])[:, :2]
        lo = np.minimum(lo, X.min(axis=0))
        hi = np.maximum(hi, X.max(axis=0))
    pad = 0.04 * max(hi - lo)
    return (lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad, 0.0, 0.0)


def _new_plotter(window_size, shape=(1, 1)):
    ensure_display()
    import pyvista as pv

    plotter = pv.Plotter(off_screen=True, window_size=list(window_size), shape=shape, border=shape != (1, 1))
    plotter.set_background("white")
    return plotter


def _prepare_output(filename, exts=(".png",)):
    filename = os.fspath(filename)
    ext = os.path.splitext(filename)[1].lower()
    if ext not in exts:
        raise InputError(f"unsupported image format {ext or '(no extension)'!r} for {filename!r}; use "
                         f"{', '.join(exts)}")
    os.makedirs(os.path.dirname(os.path.abspath(filename)), exist_ok=True)
    return filename


def _info_text(solution, magnification, parameter="alpha"):
    parts = []
    alpha = getattr(solution, "alpha", None)
    if alpha is not None and np.isfinite(alpha):
        parts.append(f"{parameter} = {alpha:.6g}")
    parts.append(f"displacements × {magnification:.3g}")
    return ",  ".join(parts)


# ----------------------------------------------------------------------------- renders
def render_solution(geometry, solution, filename, magnification: Optional[float] = None,
                    window_size=(1200, 800), show_stress: bool = False, stress=None,
                    title: Optional[str] = None, legend: bool = True, parameter: str = "alpha") -> str:
    """Render one deformed configuration to a PNG and return the file name.

    Parameters
    ----------
    geometry : ContactGeometry of the model (``system.geometry`` / ``path.geometry``)
    solution : Solution (u, lam_n, lam_t, sets) whose ``u`` has one entry per free DOF
    magnification : displacement scale; default :func:`auto_magnification` (largest
        displacement = 10 % of the model size)
    window_size : (width, height) in pixels of the PNG
    stress : optional per-cell values, e.g. ``cfcontact.fields.von_mises(geometry, solution)``;
        cells are then coloured by it with a scalar bar.  ``show_stress=True`` without ``stress``
        is an error (this module does not compute stresses).
    title : text at the top; the lower-left corner shows α and the magnification.
    parameter : the name α is shown under ("F" for a solution of a path over the friction).
    """
    filename = _prepare_output(filename)
    u = _check_solution(geometry, solution)
    if show_stress and stress is None:
        raise InputError("show_stress=True needs stress= (one value per cell, e.g. cfcontact.fields.von_mises)")
    mag = (auto_magnification(geometry, [u], alphas=[getattr(solution, "alpha", None)]) if magnification is None
           else float(magnification))
    plotter = _new_plotter(window_size)
    try:
        _draw(plotter, geometry, solution, mag, stress=stress, point_size=_point_size(window_size),
              legend=legend, title=title, text=_info_text(solution, mag, parameter))
        _view(plotter, _bounds(geometry, [u], mag, [getattr(solution, "alpha", None)]), _aspect(window_size),
              legend=legend, top=0.88 if title else 0.95)
        plotter.screenshot(filename)
    finally:
        plotter.close()
    return filename


def _grid_shape(k, shape):
    if shape is not None:
        rows, cols = int(shape[0]), int(shape[1])
        if rows * cols < k:
            raise InputError(f"panel shape {shape} has fewer than {k} places")
        return rows, cols
    cols = k if k <= 4 else int(np.ceil(np.sqrt(k)))
    return int(np.ceil(k / cols)), cols


def render_panel(geometry, solutions: Sequence, filename, magnification: Optional[float] = None,
                 window_size=None, shape=None, stresses=None, titles=None, legend: bool = True,
                 parameter: str = "alpha") -> str:
    """Several solutions side by side (subplots ``shape``, default (1, k) up to 4, else a near-square grid).

    Every subplot uses the same magnification (default: auto over all solutions) and is titled
    with its index, α (named ``parameter``: "F" for a path over the friction) and the counts of
    open / stick / slip nodes (or ``titles[i]``).
    window_size defaults to 600 x 450 pixels per subplot.  Returns the file name.
    """
    filename = _prepare_output(filename)
    solutions = list(solutions)
    if not solutions:
        raise InputError("render_panel needs at least one solution")
    us = [_check_solution(geometry, s) for s in solutions]
    rows, cols = _grid_shape(len(solutions), shape)
    if window_size is None:
        window_size = (600 * cols, 450 * rows)
    if stresses is not None and len(stresses) != len(solutions):
        raise InputError(f"stresses has {len(stresses)} entries for {len(solutions)} solutions")
    if titles is not None and len(titles) != len(solutions):
        raise InputError(f"titles has {len(titles)} entries for {len(solutions)} solutions")
    alphas = [getattr(s, "alpha", None) for s in solutions]
    mag = auto_magnification(geometry, us, alphas=alphas) if magnification is None else float(magnification)
    clim = None
    if stresses is not None:
        allv = np.concatenate([np.asarray(s, dtype=float).ravel() for s in stresses])
        clim = (float(allv.min()), float(allv.max()))
    bounds = _bounds(geometry, us, mag, alphas)
    plotter = _new_plotter(window_size, shape=(rows, cols))
    try:
        psize = _point_size(window_size, cols, rows)
        for k, sol in enumerate(solutions):
            plotter.subplot(k // cols, k % cols)
            plotter.set_background("white")
            if titles is not None:
                head = titles[k]
            else:
                c = state_counts(sol.states())
                alpha = getattr(sol, "alpha", float("nan"))
                head = (f"#{k}" + (f"  {parameter} = {alpha:.4g}" if np.isfinite(alpha) else "")
                        + f"\nopen {c['open']}, stick {c['stick']}, slip {c['slip']}")
            _draw(plotter, geometry, sol, mag, stress=None if stresses is None else stresses[k],
                  point_size=psize, legend=legend, legend_size=(0.26, 0.26), legend_loc="lower right", clim=clim, title=head,
                  text=f"× {mag:.3g}", font_size=10, scalar_bar=k == len(solutions) - 1)
            _view(plotter, bounds, _aspect(window_size, rows, cols), legend=legend, top=0.80, right=0.70)
        plotter.screenshot(filename)
    finally:
        plotter.close()
    return filename


@dataclass
class AnimationResult:
    """What :func:`render_animation` wrote.

    kind: "gif", "mp4" or "png-frames"; path: the file, or the directory of frames;
    frames: number of frames; files: the frame PNGs (png-frames only); alphas: α of each frame;
    magnification: the (common) displacement scale; note: why a fallback was taken, if one was.
    """

    kind: str
    path: str
    frames: int
    alphas: list
    magnification: float
    files: list = field(default_factory=list)
    note: str = ""


def _frame_states(path, frames):
    """[(alpha, u, Solution-like)] evenly spaced along the path in accumulated |Δα| (exact on branches)."""
    from cfcontact.ssnm import Solution

    alphas = path.alphas
    P = len(alphas)
    if P == 0:
        raise InputError("the path has no points")
    n, m = path.n, path.m
    branches = path.point_branch
    if isinstance(frames, (int, np.integer)):
        k = int(frames)
        if k < 1:
            raise InputError(f"frames must be >= 1, got {frames}")
        s = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(alphas)))])
        picks = []
        if s[-1] > 0 and k > 1:
            for target in np.linspace(0.0, s[-1], k):
                j = int(np.clip(np.searchsorted(s, target, side="right") - 1, 0, max(P - 2, 0)))
                if P > 1 and branches[j] == branches[j + 1] and s[j + 1] > s[j]:
                    t = (target - s[j]) / (s[j + 1] - s[j])
                    a = alphas[j] + t * (alphas[j + 1] - alphas[j])
                    picks.append((a, path.branch_y(int(branches[j]), a), int(branches[j])))
                else:
                    jj = j if target - s[j] <= s[min(j + 1, P - 1)] - target else min(j + 1, P - 1)
                    picks.append((alphas[jj], path.point_y(jj), int(branches[jj])))
        else:
            for j in np.unique(np.linspace(0, P - 1, k).round().astype(int)):
                picks.append((alphas[j], path.point_y(j), int(branches[j])))
    else:
        idx = [int(i) for i in frames]
        bad = [i for i in idx if not 0 <= i < P]
        if bad:
            raise InputError(f"frame point indices {bad} out of range (0..{P - 1})")
        picks = [(alphas[j], path.point_y(j), int(branches[j])) for j in idx]
    out = []
    for a, y, b in picks:
        sets = path.branches[b].sets
        out.append(Solution(y[:n].copy(), y[n:n + m].copy(), y[n + m:].copy(), float(a), sets, 0))
    return out


def render_animation(path, filename, frames=60, magnification: Optional[float] = None,
                     window_size=(960, 640), fps: float = 10.0, title: Optional[str] = None,
                     stress=None) -> AnimationResult:
    """Animate the deformed configuration along a traced path.

    frames : number of frames, spread evenly along the path in accumulated |Δα| (evaluated
        exactly on the branches), or a sequence of stored point indices.
    filename : ``*.gif`` -> animated GIF (Pillow, else imageio; PNG frames if neither is installed);
        ``*.mp4`` -> MP4 through imageio-ffmpeg (PNG frames if it is not installed);
        anything else -> a directory of numbered PNGs ``frame_0000.png``...
        Fallback frames go to ``<stem>_frames/`` next to ``filename``.
    stress : optional callable ``stress(solution)`` -> one value per cell (e.g. ``lambda s:
        cfcontact.fields.von_mises(path.geometry, s)``: at its alpha); the cells are then coloured by it, on one
        colour scale for all frames, with a scalar bar.
    The magnification and the camera are the same in every frame.  Returns an :class:`AnimationResult`.
    """
    geometry = getattr(path, "geometry", None)
    if geometry is None:
        raise InputError("the path has no ContactGeometry (a lumped model); nothing to render")
    filename = os.fspath(filename)
    if stress is not None and not callable(stress):
        raise InputError(f"stress must be a callable solution -> one value per cell, got {type(stress).__name__}")
    sols = _frame_states(path, frames)
    us = [s.u for s in sols]
    for s in sols:
        _check_solution(geometry, s)
    values, clim = None, None
    if stress is not None:
        values = [np.asarray(stress(s), dtype=float).ravel() for s in sols]
        allv = np.concatenate(values)
        clim = (float(allv.min()), float(allv.max()))
    alphas = [getattr(s, "alpha", None) for s in sols]
    mag = auto_magnification(geometry, us, alphas=alphas) if magnification is None else float(magnification)
    ext = os.path.splitext(filename)[1].lower()
    kind, note = "png-frames", ""
    if ext == ".gif":
        if _importable("PIL.Image") or _importable("imageio"):
            kind = "gif"
        else:
            note = "neither Pillow nor imageio is installed: wrote PNG frames instead of a GIF"
    elif ext == ".mp4":
        if _importable("imageio_ffmpeg"):
            kind = "mp4"
        else:
            note = "imageio-ffmpeg is not installed: wrote PNG frames instead of an MP4"
    frame_dir = filename if kind == "png-frames" and ext not in (".gif", ".mp4") else None
    if kind == "png-frames" and frame_dir is None:
        frame_dir = os.path.splitext(filename)[0] + "_frames"
    target = frame_dir if kind == "png-frames" else filename
    os.makedirs(target if kind == "png-frames" else os.path.dirname(os.path.abspath(target)), exist_ok=True)

    bounds = _bounds(geometry, us, mag, alphas)
    images, files = [], []
    plotter = _new_plotter(window_size)
    try:
        for k, sol in enumerate(sols):
            _draw(plotter, geometry, sol, mag, stress=None if values is None else values[k], clim=clim,
                  scalar_bar=k == 0, point_size=_point_size(window_size), legend=True,
                  title=title if title is not None else f"frame {k + 1}/{len(sols)}",
                  text=_info_text(sol, mag, path.parameter_name))
            if k == 0:
                _view(plotter, bounds, _aspect(window_size), legend=True)
            if kind == "png-frames":
                fn = os.path.join(frame_dir, f"frame_{k:04d}.png")
                plotter.screenshot(fn)
                files.append(fn)
            else:
                images.append(np.asarray(plotter.screenshot(return_img=True)))
    finally:
        plotter.close()

    if kind == "gif":
        _write_gif(filename, images, fps)
    elif kind == "mp4":
        import imageio_ffmpeg

        h, w = images[0].shape[:2]
        gen = imageio_ffmpeg.write_frames(filename, (w, h), fps=fps, macro_block_size=1)
        gen.send(None)
        for im in images:
            gen.send(np.ascontiguousarray(im[:, :, :3]))
        gen.close()
    return AnimationResult(kind, target, len(sols), [float(s.alpha) for s in sols], mag, files, note)


def _importable(module) -> bool:
    import importlib

    try:
        importlib.import_module(module)
        return True
    except ImportError:
        return False


def _write_gif(filename, images, fps):
    """Animated GIF with Pillow (always there: Matplotlib depends on it), else imageio."""
    ms = int(round(1000.0 / float(fps)))
    try:
        from PIL import Image
    except ImportError:
        Image = None
    if Image is not None:
        frames = [Image.fromarray(np.ascontiguousarray(im[:, :, :3])) for im in images]
        frames[0].save(filename, save_all=True, append_images=frames[1:], duration=ms, loop=0)
        return
    try:
        import imageio.v3 as iio
    except ImportError as exc:
        raise RuntimeError("writing a GIF needs Pillow or imageio; neither is installed "
                           "(give a file name without .gif to get PNG frames)") from exc
    iio.imwrite(filename, np.stack([im[:, :, :3] for im in images]), duration=ms, loop=0)
