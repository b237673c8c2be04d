"""Version compatibility: the only module that knows dolfinx 0.5 from dolfinx 0.9.

Supported: dolfinx 0.5.x (Debian 12) and 0.9.x (Debian 13); newer versions are
handled where the change is known (0.10 returns a ``MeshData`` from
``model_to_mesh``).  Tests are by feature detection; :data:`DOLFINX_VERSION` is a
parsed tuple for messages and for the few places where a feature test is not
possible.  Gmsh differences (``gmsh.isInitialized`` appeared after 4.8) live here
too.

Everything else in cfcontact calls these helpers instead of the dolfinx API
where the two versions differ:

==========================  ===================================  ===============================
helper                      dolfinx 0.5                          dolfinx 0.9
==========================  ===================================  ===============================
vector_p1_space             ``fem.VectorFunctionSpace``          ``fem.functionspace(.., (gdim,))``
model_to_mesh               tuple (mesh, ct, ft)                 tuple (0.9) / MeshData (0.10)
geometry_dofmap             AdjacencyList -> reshape             2-D array
dofmap_array                ``dofmap.list`` AdjacencyList        2-D array
==========================  ===================================  ===============================
"""

from __future__ import annotations

import contextlib
import inspect
import logging
import os
import re
import sys
import tempfile
import threading
import time

import numpy as np

import dolfinx
import dolfinx.fem
import dolfinx.fem.petsc
import dolfinx.mesh
from petsc4py import PETSc

from cfcontact.interrupts import import_gmsh, python_sigint


def parse_version(text: str) -> tuple:
    """``"0.9.0"`` -> ``(0, 9, 0)``; ``"0.10.0.post1"`` -> ``(0, 10, 0)`` (numeric parts only)."""
    parts = []
    for piece in str(text).split("."):
        m = re.match(r"\d+", piece)
        if not m:
            break
        parts.append(int(m.group()))
    return tuple(parts)


#: the running dolfinx version as a tuple of ints, e.g. (0, 5, 2)
DOLFINX_VERSION = parse_version(dolfinx.__version__)

#: PETSc scalar type (real builds only are supported)
SCALAR = PETSc.ScalarType


def _adjacency_to_2d(adj, width=None) -> np.ndarray:
    """An AdjacencyList with constant link count, or a 2-D array, as a 2-D int array."""
    if isinstance(adj, np.ndarray):
        return adj if adj.ndim == 2 else adj.reshape(-1, width)
    arr = np.asarray(adj.array)
    offsets = np.asarray(adj.offsets)
    n = offsets.size - 1
    if n == 0:
        return arr.reshape(0, width or 0)
    widths = np.diff(offsets)
    if not np.all(widths == widths[0]):
        raise ValueError("mixed cell types are not supported (non-constant links per node)")
    return arr.reshape(n, int(widths[0]))


# ------------------------------------------------------------------ meshes
def model_to_mesh(model, comm, rank: int = 0, gdim: int = 2):
    """``dolfinx.io.gmshio.model_to_mesh`` -> ``(mesh, cell_tags, facet_tags)`` in every version.

    ``facet_tags`` may be None (dolfinx >= 0.10 without 1-D physical groups).
    """
    from dolfinx.io import gmshio

    with quiet_jit("coordinate element"):
        out = gmshio.model_to_mesh(model, comm, rank, gdim=gdim)
    if hasattr(out, "mesh"):  # dolfinx >= 0.10: MeshData
        return out.mesh, out.cell_tags, out.facet_tags
    mesh, ct, ft = out[0], out[1], out[2]
    return mesh, ct, ft


def geometry_dofmap(mesh) -> np.ndarray:
    """Cell -> geometry node indices as a 2-D array (local numbering, owned + ghost cells)."""
    dm = mesh.geometry.dofmap
    if isinstance(dm, (list, tuple)):  # multiple coordinate elements (never for one cell type)
        dm = dm[0]
    return _adjacency_to_2d(dm)


def input_global_indices(mesh) -> np.ndarray:
    """Index of each local geometry node in the input (gmsh) node array, int64."""
    return np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)


def geometry_points(mesh) -> np.ndarray:
    """Local geometry node coordinates (x, y) as a (num_nodes, 2) float array."""
    return np.asarray(mesh.geometry.x)[:, :2].astype(float, copy=True)


def cell_vertices(mesh) -> np.ndarray:
    """Cell -> topological vertex indices as a 2-D array (local numbering)."""
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim, 0)
    return _adjacency_to_2d(mesh.topology.connectivity(tdim, 0))


def facet_vertices(mesh) -> np.ndarray:
    """Facet -> topological vertex indices as a 2-D array (local numbering)."""
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, 0)
    return _adjacency_to_2d(mesh.topology.connectivity(tdim - 1, 0))


def facet_cells(mesh):
    """Facet -> cell connectivity as (array, offsets)."""
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    conn = mesh.topology.connectivity(tdim - 1, tdim)
    return np.asarray(conn.array), np.asarray(conn.offsets)


def num_owned(mesh, dim: int) -> int:
    """Number of entities of dimension ``dim`` owned by this rank."""
    mesh.topology.create_entities(dim)
    return int(mesh.topology.index_map(dim).size_local)


def original_cell_index(mesh):
    """Input (gmsh) index of each local cell, or None if this dolfinx does not provide it."""
    idx = getattr(mesh.topology, "original_cell_index", None)
    if idx is None:
        return None
    if isinstance(idx, (list, tuple)):  # per cell type in mixed-topology builds
        idx = idx[0]
    return np.asarray(idx, dtype=np.int64)


def cell_type_name(mesh) -> str:
    """``"triangle"`` or ``"quadrilateral"``."""
    return mesh.topology.cell_type.name


def meshtags_arrays(tags):
    """(indices, values) of a MeshTags object (empty arrays for None)."""
    if tags is None:
        return np.empty(0, dtype=np.int32), np.empty(0, dtype=np.int32)
    return np.asarray(tags.indices), np.asarray(tags.values)


# ----------------------------------------------------------- function spaces
def vector_p1_space(mesh):
    """Continuous piecewise-linear vector field space (P1 / Q1), value size = gdim."""
    gdim = mesh.geometry.dim
    with quiet_jit("finite element"):  # dolfinx 0.5 JIT-compiles the element of a space
        if hasattr(dolfinx.fem, "functionspace"):  # dolfinx >= 0.7
            try:
                return dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (gdim,)))
            except TypeError:  # pragma: no cover - 0.7 variants without the shape tuple
                pass
        return dolfinx.fem.VectorFunctionSpace(mesh, ("Lagrange", 1))


def dofmap_array(V) -> np.ndarray:
    """Cell -> (block) dof indices of ``V`` as a 2-D array (local numbering)."""
    return _adjacency_to_2d(V.dofmap.list)


def index_map_local_to_global(index_map, local: np.ndarray) -> np.ndarray:
    """Global indices of local indices (owned and ghost) of an IndexMap."""
    local = np.asarray(local, dtype=np.int32)
    return np.asarray(index_map.local_to_global(local), dtype=np.int64)


def constant(mesh, value):
    """A ``fem.Constant`` holding ``value`` (float or array)."""
    return dolfinx.fem.Constant(mesh, np.asarray(value, dtype=SCALAR))


# ------------------------------------------------------------------ JIT compilation
log = logging.getLogger(__name__)


@contextlib.contextmanager
def quiet_jit(what: str = "form"):
    """Silence the just-in-time compilation of FFCx/dolfinx (form and element code through cffi).

    On a fresh form cache FFCx compiles C code with setuptools' distutils, which logs
    ``running build_ext`` and every compiler command line through the *root* logger (FFCx 0.5
    calls ``logging.basicConfig()`` at import and distutils lowers the root level to INFO), and
    the compiler itself writes warnings to file descriptors 1 and 2.  Around compilation only:
    logging up to INFO is disabled, the root logger's level is restored afterwards, and the C-level
    stdout/stderr go to a temporary file whose text is logged at DEBUG (``cfcontact.compat``), or
    attached to the error when the compilation fails.  The same on dolfinx 0.5 and 0.9 (both compile
    through cffi/distutils; 0.9 does not call basicConfig, which makes no difference here)."""
    root = logging.getLogger()
    old_level, old_disable = root.level, logging.root.manager.disable
    logging.disable(max(old_disable, logging.INFO))
    t0 = time.perf_counter()
    with tempfile.TemporaryFile(mode="w+b") as sink:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (AttributeError, OSError, ValueError):  # closed or replaced streams: nothing to flush
                pass
        saved = []
        try:
            for fd in (1, 2):
                try:
                    saved.append((fd, os.dup(fd)))
                except OSError:  # no such descriptor (a daemon): nothing to silence there
                    continue
                os.dup2(sink.fileno(), fd)
            yield
        except Exception as exc:
            for fd, copy in saved:
                os.dup2(copy, fd)
            sink.seek(0)
            text = sink.read().decode("utf-8", "replace").strip()
            if text:
                exc.add_note(f"output of the JIT compilation of a {what}:\n{text}")
            raise
        finally:
            for fd, copy in saved:
                os.dup2(copy, fd)
                os.close(copy)
            root.setLevel(old_level)
            logging.disable(old_disable)
        sink.seek(0)
        text = sink.read().decode("utf-8", "replace").strip()
    elapsed = time.perf_counter() - t0
    if text:
        log.debug("JIT compilation of a %s (%.2f s):\n%s", what, elapsed, text)


# ------------------------------------------------------------------ assembly
def form(ufl_form):
    """``dolfinx.fem.form`` (JIT-compiled on a cache miss, quietly: :func:`quiet_jit`)."""
    with quiet_jit("form"):
        return dolfinx.fem.form(ufl_form)


def assemble_matrix(compiled_form) -> PETSc.Mat:
    """Assembled PETSc matrix of a bilinear form, no boundary conditions."""
    A = dolfinx.fem.petsc.assemble_matrix(compiled_form)
    A.assemble()
    return A


def assemble_vector(compiled_form) -> PETSc.Vec:
    """Assembled PETSc vector of a linear form with ghost contributions summed to owners."""
    b = dolfinx.fem.petsc.assemble_vector(compiled_form)
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    return b


def owned_vector_values(b, V) -> np.ndarray:
    """Owned (unrolled) entries of an assembled vector of space ``V``."""
    im = V.dofmap.index_map
    bs = V.dofmap.index_map_bs
    return np.array(b.array_r[: im.size_local * bs], copy=True)


# --------------------------------------------------------------------- gmsh
def gmsh_is_initialized() -> bool:
    """Whether the gmsh API is initialised (gmsh >= 4.9 has isInitialized; 4.8 does not)."""
    gmsh = import_gmsh()

    if hasattr(gmsh, "isInitialized"):
        return bool(gmsh.isInitialized())
    # gmsh 4.8: model.list() is [] before the first initialize and raises after finalize,
    # printing "Error : Gmsh has not been initialized" on stderr: silence that probe.
    with _silenced_stderr():
        try:
            return len(gmsh.model.list()) > 0
        except Exception:
            return False


@contextlib.contextmanager
def _silenced_stderr():
    """Redirect file descriptor 2 (C-level stderr) to /dev/null for a moment."""
    try:
        sys.stderr.flush()
    except Exception:
        pass
    try:
        saved = os.dup(2)
    except OSError:  # no fd 2: nothing to silence
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


@contextlib.contextmanager
def gmsh_model(name: str = "cfcontact"):
    """Context: a fresh current gmsh model, removed afterwards.

    Initialises gmsh (quietly) if needed and finalises it again only in that case;
    a caller's current model is restored.
    """
    gmsh = import_gmsh()

    started = not gmsh_is_initialized()
    if started:
        if "interruptible" in inspect.signature(gmsh.initialize).parameters:  # gmsh >= 4.9
            gmsh.initialize([], False, interruptible=False)
        else:
            gmsh.initialize([], False)
        python_sigint()
        gmsh.option.setNumber("General.Terminal", 0)
        previous = None
    else:
        previous = gmsh.model.getCurrent()
    gmsh.model.add(name)
    try:
        yield gmsh.model
    finally:
        try:
            gmsh.model.setCurrent(name)
            gmsh.model.remove()
            if previous is not None and previous in gmsh.model.list():
                gmsh.model.setCurrent(previous)
        finally:
            if started:
                _gmsh_finalize(gmsh)


def _gmsh_finalize(gmsh):
    """``gmsh.finalize()``.  gmsh 4.8 puts back there the SIGINT handler it replaced when it was
    imported, and Python sets handlers in the main thread only: in another thread (a model built
    by a worker thread) that step is left out -- the handler is the main thread's business."""
    saved = getattr(gmsh, "oldsig", None)
    if saved is None or threading.current_thread() is threading.main_thread():
        gmsh.finalize()
        return
    gmsh.oldsig = None
    try:
        gmsh.finalize()
    finally:
        gmsh.oldsig = saved
