"""Derived fields of a solution and their export: von Mises stress and XDMF files for ParaView.

NumPy only (no dolfinx, no h5py): everything works from a saved path on any machine.

* :func:`cell_stress` / :func:`von_mises` -- per-cell stress of a free-DOF displacement vector u
  on a :class:`~cfcontact.system.ContactGeometry`: linear triangles use their constant P1 strain,
  quadrilaterals (VTK node order) the bilinear Q1 gradient at the cell centre (ξ = η = 0).
  Linear isotropic elasticity with one E, ν per body; plane strain (σzz = λ tr ε) or plane
  stress (σzz = 0).  The material is a dict ``{"E": ..., "nu": ..., "plane": ...}`` as stored
  in ``ContactSystem.info`` and ``geometry.material`` (E, ν numbers or ``{"body1=1": value, ...}``).
* :func:`write_xdmf` -- solutions as an XDMF 3 file (XML, data inline as text, ``Format="XML"``):
  a temporal collection with one grid per solution, Time = 0, 1, 2, ...  Node attributes
  ``displacement`` (3 components, z = 0), ``contact_state`` (-1 no contact node, 0 open,
  1 stick, 2 slip+, 3 slip-, 4 slip+- (invalid, shown if it occurs); on both nodes of a pair),
  ``lam_n`` and ``lam_t`` (the pair's nodal forces, on both nodes of a pair, 0 elsewhere: summed
  over all nodes they count each force twice), and, when the geometry knows the slave
  boundary's tributary lengths, ``contact_pressure`` and ``contact_shear`` (λν/ℓ and λτ/ℓ on
  the slave node of each pair only, 0 elsewhere: tractions, force per unit length of the slave
  boundary: their sum times ℓ over the slave nodes is the contact force); cell attributes ``body`` and,
  when the material is known, ``von_mises``.  The first grid holds the mesh; the others include
  it (``xi:include``), as dolfinx's own time series do.
* :func:`export_path` -- the same for a :class:`~cfcontact.path.SolutionPath`: all solutions at
  one α (default: the α of largest multiplicity) or every stored path point.
"""

from __future__ import annotations

import os
import re
import tempfile
from collections.abc import Mapping
from typing import Iterable, Optional

import numpy as np

from cfcontact.errors import InputError
from cfcontact.material import check_modulus, check_plane, check_poisson

__all__ = ["cell_material", "cell_stress", "von_mises", "contact_state_codes", "write_xdmf", "export_path",
           "STATE_CODES", "XDMF_TOPOLOGY"]

#: contact_state values of the XDMF output (-1 = not a contact node)
STATE_CODES = {"open": 0, "stick": 1, "slip+": 2, "slip-": 3, "slip+-": 4}
#: XDMF topology type by nodes per cell (XDMF's quadrilateral order is VTK's counter-clockwise one)
XDMF_TOPOLOGY = {3: "Triangle", 4: "Quadrilateral"}
_XDMF_MIXED_ID = {3: 4, 4: 5}  # XDMF cell type numbers inside a Mixed topology

# reference gradients dN/dξ (k, 2): P1 triangle; Q1 quadrilateral at its centre, nodes (-1,-1) (1,-1) (1,1) (-1,1)
_DREF = {3: np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]]),
         4: 0.25 * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])}


# ============================================================================ material
def _body_number(key) -> int:
    """Body number of a material key: 1, "1", "body1=1" (the info format) or "body1" (tag convention)."""
    if isinstance(key, (int, np.integer)) and not isinstance(key, bool):
        return int(key)
    text = str(key).strip()
    if text.isdigit():
        return int(text)
    if "=" in text and text.rsplit("=", 1)[1].strip().isdigit():
        return int(text.rsplit("=", 1)[1])
    m = re.fullmatch(r"body(\d+)", text)
    if m:
        return int(m.group(1))
    raise InputError(f"material: cannot tell the body of key {key!r}; use a body number (1), \"body1=1\" or \"body1\"")


def _per_cell(value, what, cell_body):
    """One float per cell from a number or a {body: number} dict."""
    if isinstance(value, Mapping):
        if not value:
            raise InputError(f"material {what} is an empty dict; give a number or one value per body")
        by_body = {}
        for k, v in value.items():
            by_body[_body_number(k)] = v
        missing = sorted(set(np.unique(cell_body).tolist()) - set(by_body))
        if missing:
            raise InputError(f"material {what} gives no value for body {', '.join(map(str, missing))} "
                             f"(keys {list(value)})")
        out = np.empty(len(cell_body))
        for b, v in by_body.items():
            out[cell_body == b] = _number(v, f"{what}[{b}]")
        return out
    return np.full(len(cell_body), _number(value, what))


def _number(v, what):
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise InputError(f"material {what} must be a number, got {v!r}") from None
    return x


def cell_material(geometry, material):
    """(E, nu, plane) with E and nu one value per cell, checked (E > 0, -1 < nu < 0.5)."""
    if material is None:
        raise InputError("the material is unknown: give material={'E': ..., 'nu': ..., 'plane': 'strain'|'stress'} "
                         "(a path saved before cfcontact stored the material has none)")
    if not isinstance(material, Mapping):
        raise InputError(f"material must be a dict {{'E', 'nu', 'plane'}}, got {type(material).__name__} {material!r}")
    missing = [k for k in ("E", "nu") if k not in material]
    if missing:
        raise InputError(f"material has no {' and no '.join(missing)} (keys {list(material)})")
    try:
        plane = check_plane(material.get("plane", "strain"))
    except InputError as exc:
        raise InputError(f"material {exc}") from None
    cell_body = np.asarray(geometry.cell_body).astype(int)
    E = _per_cell(material["E"], "E", cell_body)
    nu = _per_cell(material["nu"], "nu", cell_body)
    for values, check in ((E, check_modulus), (nu, check_poisson)):
        for body in np.unique(cell_body).tolist():
            for v in np.unique(values[cell_body == body]).tolist():
                try:
                    check(v)
                except InputError as exc:
                    raise InputError(f"material: {exc} (body {body})") from None
    return E, nu, plane


def material_of(obj) -> Optional[dict]:
    """The material dict of a ContactSystem (info), a SolutionPath or a ContactGeometry; None if unknown."""
    info = getattr(obj, "info", None)
    if isinstance(info, Mapping) and "E" in info and "nu" in info:
        return {"E": info["E"], "nu": info["nu"], "plane": info.get("plane", "strain")}
    geometry = getattr(obj, "geometry", obj)
    return getattr(geometry, "material", None)


# ============================================================================ stress
def _check_u(geometry, u):
    u = getattr(u, "u", u)  # a Solution
    try:
        u = np.asarray(u, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"u must be a vector of numbers, got {type(u).__name__}") from None
    n = len(geometry.dof_node)
    if u.shape != (n,):
        raise InputError(f"u has shape {u.shape} ({u.size} values), expected ({n},): one value per free DOF "
                         f"of the geometry")
    return u


def displacement_gradients(geometry, u, alpha=None) -> np.ndarray:
    """(C, 2, 2) displacement gradients G[c, i, j] = ∂u_i/∂x_j (P1 triangle; Q1 at the cell centre).
    Prescribed non-zero displacements (``geometry.prescribed``) enter at ``alpha`` (default: the
    alpha of a Solution ``u``; none for a plain vector)."""
    if geometry is None:
        raise InputError("stresses need the model's ContactGeometry (a lumped model has none)")
    alpha = getattr(u, "alpha", None) if alpha is None else alpha
    u = _check_u(geometry, u)
    P = np.asarray(geometry.points, dtype=float)[:, :2]
    U = geometry.displacement_field(u, alpha)[:, :2]
    cells = np.asarray(geometry.cells)
    if cells.ndim != 2 or cells.shape[1] not in (3, 4):
        raise InputError(f"geometry.cells must be a (C, 3) or (C, 4) array, got shape {cells.shape}")
    counts = (cells >= 0).sum(axis=1)
    if np.any((counts != 3) & (counts != 4)):
        raise InputError("every cell must have 3 (triangle) or 4 (quadrilateral) nodes")
    G = np.empty((len(cells), 2, 2))
    for k, dref in _DREF.items():
        sel = np.flatnonzero(counts == k)
        if not sel.size:
            continue
        idx = cells[sel, :k]
        J = np.einsum("ckd,kr->cdr", P[idx], dref)  # ∂x_d/∂ξ_r
        det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
        scale = np.einsum("cdr,cdr->c", J, J)
        if np.any(np.abs(det) <= 1e-14 * scale):
            raise InputError(f"degenerate cell(s) {sel[np.abs(det) <= 1e-14 * scale][:5].tolist()} (zero area)")
        dN = np.einsum("kr,crd->ckd", dref, np.linalg.inv(J))  # ∂N_k/∂x_d
        G[sel] = np.einsum("cki,ckd->cid", U[idx], dN)
    return G


def cell_stress(geometry, u, material=None, alpha=None) -> np.ndarray:
    """(C, 4) stresses (σxx, σyy, σzz, σxy) per cell; ``material`` defaults to ``geometry.material``;
    ``alpha`` as in :func:`displacement_gradients`."""
    G = displacement_gradients(geometry, u, alpha)
    E, nu, plane = cell_material(geometry, geometry.material if material is None else material)
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = E / (2.0 * (1.0 + nu))
    exx, eyy, exy = G[:, 0, 0], G[:, 1, 1], 0.5 * (G[:, 0, 1] + G[:, 1, 0])
    tr = exx + eyy
    if plane == "strain":
        lam2, szz = lam, lam * tr
    else:
        lam2, szz = 2.0 * lam * mu / (lam + 2.0 * mu), np.zeros_like(tr)
    return np.column_stack([lam2 * tr + 2.0 * mu * exx, lam2 * tr + 2.0 * mu * eyy, szz, 2.0 * mu * exy])


def von_mises(geometry, u, material=None, alpha=None) -> np.ndarray:
    """Per-cell von Mises stress of the free-DOF displacement ``u`` (a vector or a Solution).

    ``material``: ``{"E": ..., "nu": ..., "plane": "strain" | "stress"}`` with E and nu numbers or
    one value per body (``{"body1=1": 2.1e11, "body2=2": 2.1e8}``); default ``geometry.material``
    (stored by the assembly layer and in saved paths).  Returns a (C,) array in the unit of E.
    Prescribed non-zero displacements enter at ``alpha`` (default: a Solution's own alpha).
    """
    s = cell_stress(geometry, u, material, alpha)
    sxx, syy, szz, sxy = s.T
    return np.sqrt(0.5 * ((sxx - syy) ** 2 + (syy - szz) ** 2 + (szz - sxx) ** 2) + 3.0 * sxy ** 2)


# ============================================================================ XDMF
def contact_state_codes(geometry, states) -> np.ndarray:
    """(P,) int: the state code of each node (both nodes of a contact pair), -1 for other nodes."""
    nodes = np.asarray(geometry.contact_nodes, dtype=int).reshape(-1, 2)
    states = list(states)
    if len(states) != len(nodes):
        raise InputError(f"{len(states)} contact states for {len(nodes)} contact nodes")
    codes = np.full(len(geometry.points), -1, dtype=int)
    for (a, b), s in zip(nodes, states):
        if s not in STATE_CODES:
            raise InputError(f"unknown contact state {s!r}")
        codes[a] = STATE_CODES[s]
        if b >= 0:
            codes[b] = STATE_CODES[s]
    return codes


def _pair_field(geometry, values) -> np.ndarray:
    nodes = np.asarray(geometry.contact_nodes, dtype=int).reshape(-1, 2)
    values = np.asarray(values, dtype=float).ravel()
    if values.shape != (len(nodes),):
        raise InputError(f"a multiplier has {values.size} values for {len(nodes)} contact nodes")
    out = np.zeros(len(geometry.points))
    out[nodes[:, 0]] = values
    has2 = nodes[:, 1] >= 0
    out[nodes[has2, 1]] = values[has2]
    return out


def _traction_field(size, slave, trib, values) -> np.ndarray:
    """values / tributary length ``trib`` on the slave nodes ``slave`` of the pairs, 0 elsewhere
    (``size`` nodes)."""
    out = np.zeros(size)
    out[slave] = np.asarray(values, dtype=float).ravel() / trib
    return out


def _fmt(a) -> str:
    """Array as XML text, one row per line; floats with repr (round-trip exact)."""
    a = np.asarray(a)
    if a.ndim == 1:
        a = a[:, None]
    if a.dtype.kind in "iub":
        rows = (" ".join(str(int(x)) for x in row) for row in a)
    else:
        rows = (" ".join(repr(float(x)) for x in row) for row in a)
    return "\n".join(rows)


def _data_item(a, indent) -> str:
    a = np.asarray(a)
    dims = " ".join(str(d) for d in a.shape)
    kind = 'NumberType="Int" Precision="8"' if a.dtype.kind in "iub" else 'NumberType="Float" Precision="8"'
    pad = " " * indent
    return (f'{pad}<DataItem Dimensions="{dims}" {kind} Format="XML">\n{_fmt(a)}\n{pad}</DataItem>\n')


def _topology(geometry, indent) -> str:
    cells = np.asarray(geometry.cells, dtype=np.int64)
    counts = (cells >= 0).sum(axis=1)
    pad = " " * indent
    kinds = sorted(set(counts.tolist()))
    if not set(kinds) <= {3, 4}:
        raise InputError("every cell must have 3 (triangle) or 4 (quadrilateral) nodes")
    if len(kinds) == 1:
        k = kinds[0]
        return (f'{pad}<Topology TopologyType="{XDMF_TOPOLOGY[k]}" NumberOfElements="{len(cells)}" '
                f'NodesPerElement="{k}">\n' + _data_item(cells[:, :k], indent + 2) + f"{pad}</Topology>\n")
    flat = np.concatenate([[_XDMF_MIXED_ID[k], *row[:k]] for row, k in zip(cells, counts)]).astype(np.int64)
    return (f'{pad}<Topology TopologyType="Mixed" NumberOfElements="{len(cells)}">\n'
            + _data_item(flat, indent + 2) + f"{pad}</Topology>\n")


def _attribute(name, center, a, indent) -> str:
    a = np.asarray(a)
    kind = "Vector" if a.ndim == 2 else "Scalar"
    pad = " " * indent
    return (f'{pad}<Attribute Name="{name}" AttributeType="{kind}" Center="{center}">\n'
            + _data_item(a, indent + 2) + f"{pad}</Attribute>\n")


def _states_of(sol):
    if hasattr(sol, "states"):
        return list(sol.states())
    return list(sol.sets.states())


def grid_name(index: int, alpha: float) -> str:
    """Name of the grid of solution ``index`` (``solution_3_alpha_0.105``)."""
    return f"solution_{int(index)}_alpha_{float(alpha)!r}"


def write_xdmf(filename, geometry, solutions: Iterable, alphas=None, material=None, *,
               collection_name: str = "solutions") -> str:
    """Write ``solutions`` (Solution objects: u, lam_n, lam_t, sets, alpha) to an XDMF 3 file.

    A temporal collection ``collection_name`` with one grid per solution: Time = 0, 1, 2, ...;
    grid name :func:`grid_name` (index and α) and an ``<Information Name="alpha">``.  Attributes
    (see the module doc): displacement, contact_state, lam_n, lam_t, contact_pressure and
    contact_shear (when ``geometry.tributary`` is known), body and von_mises (when ``material``
    or ``geometry.material`` is known).  ``solutions`` may be a generator (it is
    written as it comes); ``alphas`` overrides each solution's α.  The file is written to a
    temporary name and renamed: a failure leaves no partial file.  Returns the file name.
    """
    if geometry is None:
        raise InputError("XDMF output needs the model's ContactGeometry (a lumped model has none)")
    filename = os.fspath(filename)
    if os.path.splitext(filename)[1].lower() not in (".xdmf", ".xmf"):
        raise InputError(f"XDMF file names end in .xdmf or .xmf, got {filename!r}")
    material = geometry.material if material is None else material
    if material is not None:
        cell_material(geometry, material)  # check before writing anything
    alphas = None if alphas is None else [float(a) for a in alphas]
    trib = getattr(geometry, "tributary", None)
    trib = None if trib is None else np.asarray(trib, dtype=float).ravel()
    tractions = trib is not None and bool(np.all(trib > 0))
    slave = geometry.slave_nodes() if tractions else None
    P = np.asarray(geometry.points, dtype=float)
    points3 = np.column_stack([P[:, :2], np.zeros(len(P))])
    body = np.asarray(geometry.cell_body).astype(np.int64)
    topology = _topology(geometry, 8)
    directory = os.path.dirname(os.path.abspath(filename))
    os.makedirs(directory, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(filename) + ".", suffix=".tmp", dir=directory)
    count = 0
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write('<?xml version="1.0"?>\n<Xdmf Version="3.0" xmlns:xi="http://www.w3.org/2001/XInclude">\n'
                     f'  <Domain>\n    <Grid Name="{collection_name}" GridType="Collection" '
                     'CollectionType="Temporal">\n')
            for k, sol in enumerate(solutions):
                u = _check_u(geometry, sol)
                if alphas is not None:
                    if k >= len(alphas):
                        raise InputError(f"alphas has {len(alphas)} values, fewer than the solutions")
                    alpha = alphas[k]
                else:
                    alpha = float(getattr(sol, "alpha", k))
                codes = contact_state_codes(geometry, _states_of(sol))
                U = geometry.displacement_field(u, alpha)[:, :2]
                fh.write(f'      <Grid Name="{grid_name(k, alpha)}" GridType="Uniform">\n'
                         f'        <Time Value="{k}"/>\n'
                         f'        <Information Name="alpha" Value="{alpha!r}"/>\n')
                if k == 0:
                    fh.write(topology)
                    fh.write('        <Geometry GeometryType="XYZ">\n' + _data_item(points3, 10)
                             + "        </Geometry>\n")
                else:
                    base = f"/Xdmf/Domain/Grid[@Name='{collection_name}']/Grid[1]"
                    fh.write(f'        <xi:include xpointer="xpointer({base}/Topology)"/>\n'
                             f'        <xi:include xpointer="xpointer({base}/Geometry)"/>\n')
                fh.write(_attribute("displacement", "Node", np.column_stack([U, np.zeros(len(U))]), 8))
                fh.write(_attribute("contact_state", "Node", codes, 8))
                fh.write(_attribute("lam_n", "Node", _pair_field(geometry, sol.lam_n), 8))
                fh.write(_attribute("lam_t", "Node", _pair_field(geometry, sol.lam_t), 8))
                if tractions:
                    for name, lam in (("contact_pressure", sol.lam_n), ("contact_shear", sol.lam_t)):
                        fh.write(_attribute(name, "Node", _traction_field(len(P), slave, trib, lam), 8))
                fh.write(_attribute("body", "Cell", body, 8))
                if material is not None:
                    fh.write(_attribute("von_mises", "Cell", von_mises(geometry, u, material, alpha), 8))
                fh.write("      </Grid>\n")
                count += 1
            if count == 0:
                raise InputError("no solutions to write")
            fh.write("    </Grid>\n  </Domain>\n</Xdmf>\n")
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file the usual permissions
        os.replace(tmp, filename)
    except BaseException:
        try:
            os.remove(tmp)
        except OSError:
            pass
        raise
    return filename


# ============================================================================ paths
def _path_solutions(path, alpha=None, points=False):
    """(solutions or a generator, description) of a path: at one α, or every stored point."""
    from cfcontact.ssnm import Solution

    if path.geometry is None:
        raise InputError("the path has no ContactGeometry (a lumped model): nothing to export")
    if points:
        if alpha is not None:
            raise InputError("give either an alpha or points=True, not both")
        P = len(path.alphas)
        if P == 0:
            raise InputError("the path has no points")
        n, m = path.n, path.m
        branches = list(path.point_branch)
        it = path.iter_points() if hasattr(path, "iter_points") else zip(path.alphas, path.ys)

        def gen():
            for i, (a, y) in enumerate(it):
                y = np.asarray(y, dtype=float)
                yield Solution(y[:n], y[n:n + m], y[n + m:], float(a), path.branches[branches[i]].sets, 0)
        return gen(), f"{P} path points"
    par = path.parameter_name
    if alpha is None:
        k, alpha = path.max_multiplicity()
        if not k:
            raise InputError(f"the path covers no {par} interval; give an alpha")
    try:
        alpha = float(alpha)
    except (TypeError, ValueError):
        raise InputError(f"alpha must be a number, got {alpha!r}") from None
    sols = path.solutions_at(alpha) if np.isfinite(alpha) else []
    if not sols:
        lo, hi = (float(np.min(path.alphas)), float(np.max(path.alphas))) if len(path.alphas) else (np.nan, np.nan)
        raise InputError(f"{par} {alpha:.10g}: the path has no solution there; it covers {par} in "
                         f"[{lo:.10g}, {hi:.10g}]")
    return sols, f"{len(sols)} solution(s) at {par} = {alpha:.10g}"


def export_path(path, filename, alpha=None, points: bool = False, material=None):
    """Write a :class:`~cfcontact.path.SolutionPath` to an XDMF file (:func:`write_xdmf`).

    ``points=False``: every solution at ``alpha`` (default: the α of largest multiplicity), one
    grid each.  ``points=True``: every stored path point in path order (a time series along the
    path; Time = point index).  ``material`` defaults to ``path.geometry.material``.
    Returns (file name, description of what was written).
    """
    sols, what = _path_solutions(path, alpha, points)
    return write_xdmf(filename, path.geometry, sols, material=material), what
