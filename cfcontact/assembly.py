"""FEM assembly: a tagged gmsh model + material + loads -> :class:`ContactSystem`.

The only layer (with :mod:`cfcontact.compat`) that imports dolfinx and ufl.

Pipeline (every step runs on all ranks of ``comm``; gmsh is used on rank 0 only):

1. the gmsh model (or a ``.msh`` file) is read with its physical groups
   (``dolfinx.io.gmshio.model_to_mesh``); the 2-D groups are bodies, the 1-D groups
   boundary pieces (DESIGN.md: ``body1``=1, ``body2``=2, ``contact1``=10,
   ``contact2``=20, anything else may be clamped or loaded);
2. the linear-elasticity stiffness matrix K (plane strain or plane stress) of a
   vector P1/Q1 space and the load vectors f1, f2 (surface tractions on tagged
   boundary pieces, body forces) are assembled by dolfinx, in parallel;
3. everything is renumbered to the project's rank-independent numbering: nodes in
   the order of the gmsh node tags (compressed to ``0..P-1``), free DOFs ordered by
   (node, component) after elimination of the Dirichlet DOFs: both components of every
   node of a clamped piece, and the components named in ``dirichlet`` (rollers, symmetry
   planes, prescribed displacements u_D(alpha) = (1 - alpha) u_D^1 + alpha u_D^2, which enter
   the loads as f_k -= K_fD u_D^k: affine in alpha like the loads themselves);
4. the contact pairs (:mod:`cfcontact.pairing`): ``pairing="node"`` matches the nodes
   of ``contact1`` and ``contact2`` by coordinates (a conforming interface, no gap), the
   normal at a pair being the normalised average of the outer normals of body 1 on its
   adjacent ``contact1`` facets; ``pairing="segment"`` projects each node of the slave
   boundary (``contact1`` or ``contact2``) along its outer normal onto the other boundary
   (node to segment, with the initial gap), or onto a rigid ``obstacle`` (a line or a
   circle) for a single body; ``t = (-n_y, n_x)``.  Pairs whose normal row would be zero
   (every DOF prescribed) are dropped; pairs are ordered along the interface.  Without
   ``body2`` / ``contact2`` and without an obstacle the contact is against a rigid
   foundation along ``contact1`` (N, T have body-1 entries only, no gap).
"""

from __future__ import annotations

import os
import time
import warnings
from typing import Mapping

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI

import ufl

from cfcontact import compat, linalg, pairing as pairing_mod
from cfcontact.errors import GeometryError, InputError, MeshWarning, PairingWarning
from cfcontact.material import check_material, lame_parameters
from cfcontact.meshes.common import CONVENTION, convention_mismatch, volume_problem
from cfcontact.system import MAGNITUDE_LIMIT, ContactGeometry, ContactSystem, default_rho

BODY1, BODY2 = 1, 2
CONTACT1, CONTACT2 = 10, 20

#: VTK order of a dolfinx quadrilateral (tensor-product order -> counter-clockwise)
_QUAD_TO_VTK = np.array([0, 1, 3, 2])

__all__ = ["assemble_contact_system", "check_material", "full_stiffness", "lame_parameters", "material_per_body"]


# ======================================================================= input
def material_per_body(E, nu, plane, groups, bodies):
    """{body number: (lambda, mu)} for the given bodies; E, nu numbers or {body name/number: value}.

    A dict must give a value for every body (GeometryError names a missing or unknown body).
    """
    def resolve(value, what):
        if not isinstance(value, Mapping):
            return {int(b): value for b in bodies}
        out = {}
        for spec, val in value.items():
            out[_resolve_tag(spec, groups, 2, what)] = val
        missing = [int(b) for b in bodies if int(b) not in out]
        if missing:
            raise GeometryError(f"{what} gives no value for body {', '.join(_tag_label(groups, 2, b) for b in missing)}; "
                                f"give one per body ({_describe(groups, 2)}) or a single number")
        return out

    e_of, nu_of = resolve(E, "E"), resolve(nu, "nu")
    return {int(b): lame_parameters(e_of[int(b)], nu_of[int(b)], plane) for b in bodies}


def _material_meta(value, groups):
    if isinstance(value, Mapping):
        return {_tag_label(groups, 2, _resolve_tag(k, groups, 2, "material")): float(v) for k, v in value.items()}
    return float(value)


def _vector2(value, what):
    flat = [value] if isinstance(value, (str, bytes)) else np.asarray(value, dtype=object).reshape(-1)
    if any(isinstance(v, (bool, np.bool_, str, bytes)) for v in flat):  # (float() takes True and "1e6")
        raise InputError(f"{what} must be a 2-vector (x, y) of numbers, got {value!r}")
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be a 2-vector (x, y) of numbers, got {value!r}") from None
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise InputError(f"{what} must be a finite 2-vector (x, y), got {value!r}")
    return arr


def _describe(groups, dim):
    items = sorted((num, name) for (d, num), name in groups.items() if d == dim)
    return ", ".join(f"{name}={num}" if name else str(num) for num, name in items) or "(none)"


def _resolve_tag(spec, groups, dim, what):
    """A physical group given by name or number -> its number; GeometryError listing valid ones."""
    kind = "boundary piece (1-D physical group)" if dim == 1 else "body (2-D physical group)"
    valid = f"valid {'1-D' if dim == 1 else '2-D'} physical groups: {_describe(groups, dim)}"
    if isinstance(spec, (bool, np.bool_)):
        raise GeometryError(f"unknown {kind} {spec!r} in {what}; {valid}")
    if isinstance(spec, (int, np.integer)):
        if (dim, int(spec)) in groups:
            return int(spec)
    elif isinstance(spec, str):
        hits = [num for (d, num), name in groups.items() if d == dim and name == spec]
        if len(hits) == 1:
            return hits[0]
        if len(hits) > 1:
            raise GeometryError(f"{kind} name {spec!r} in {what} is ambiguous (numbers {sorted(hits)}); use a number")
        convention = {name: key for key, name in CONVENTION.items()}.get(spec)
        if convention is not None and convention[0] == dim and convention in groups:
            return convention[1]  # (a convention group named otherwise: "Contact1", "interface" on 10)
    raise GeometryError(f"unknown {kind} {spec!r} in {what}; {valid}")


def _tag_label(groups, dim, num):
    name = groups.get((dim, num), "")
    return f"{name}={num}" if name else str(num)


# ================================================================ gmsh reading
def _physical_groups(model):
    """{(dim, number): name} of the current gmsh model, plus an error text or None (rank 0)."""
    groups = {}
    for dim, num in model.getPhysicalGroups():
        groups[(int(dim), int(num))] = model.getPhysicalName(dim, num)
    problem = volume_problem(model, groups)
    if problem:
        return groups, problem
    if not groups:
        return groups, "the gmsh model has no physical groups (DESIGN.md: body1=1, contact1=10, ...)"
    problem = convention_mismatch(groups)
    if problem:
        return groups, problem
    if (2, BODY1) not in groups:
        return groups, f"the gmsh model has no 2-D physical group {BODY1} (body1); 2-D groups: {_describe(groups, 2)}"
    if (1, CONTACT1) not in groups:
        return groups, f"the gmsh model has no 1-D physical group {CONTACT1} (contact1); 1-D groups: {_describe(groups, 1)}"
    if ((2, BODY2) in groups) != ((1, CONTACT2) in groups):
        return groups, ("body2 (2-D group 2) and contact2 (1-D group 20) must be given together "
                        "(neither for a rigid foundation)")
    etypes = set()
    for dim, num in groups:
        if dim != 2:
            continue
        for ent in model.getEntitiesForPhysicalGroup(dim, num):
            types, tags, _ = model.mesh.getElements(dim, ent)
            for t, tg in zip(types, tags):
                if len(tg):
                    etypes.add(int(t))
    if not etypes:
        return groups, "the gmsh model has no 2-D elements in its physical groups (call gmsh.model.mesh.generate(2))"
    if not etypes <= {2, 3} or len(etypes) != 1:
        return groups, ("only meshes of linear triangles or of linear quadrilaterals (one type) are supported; "
                        f"gmsh element types found: {sorted(etypes)}")
    problem = _loose_lines(model, groups)
    if problem:
        return groups, problem
    tags, coords, _ = model.mesh.getNodes()
    tags = np.asarray(tags)
    if tags.size and not np.array_equal(np.sort(tags), np.arange(1, tags.size + 1)):
        return groups, ("gmsh node tags are not contiguous 1..N; call gmsh.model.mesh.renumberNodes() first (a .msh "
                        "file is renumbered as it is read)")
    xyz = np.asarray(coords).reshape(-1, 3)
    extent = float(np.ptp(xyz[:, :2], axis=0).max(initial=0.0)) if xyz.size else 0.0
    if xyz.size and np.ptp(xyz[:, 2]) > 1e-10 * extent:
        return groups, (f"the mesh is not planar: its nodes' z runs from {xyz[:, 2].min():.6g} to {xyz[:, 2].max():.6g} "
                        "(a 2-D model in a plane z = constant is expected)")
    return groups, None


def _edge_keys(cells, width) -> np.ndarray:
    """One integer per edge of each cell, row by row (cells: (C, k) corner nodes in cyclic order,
    numbers below ``width``): min * width + max of the edge's two nodes, the same from either cell."""
    ends = np.stack([cells, np.roll(cells, -1, axis=1)], axis=2).reshape(-1, 2)
    return ends.min(axis=1) * width + ends.max(axis=1)


def _loose_lines(model, groups):
    """A text naming a 1-D physical group with line elements that are no edge of any 2-D cell (a
    curve drawn over a surface without being embedded in its mesh; dolfinx would abort on it),
    else None."""
    def corner_pairs(dim, entity=-1):
        types, _, nodes = model.mesh.getElements(dim, entity)
        for etype, tags in zip(types, nodes):
            _, _, _, k, _, corners = model.mesh.getElementProperties(int(etype))
            yield np.asarray(tags, dtype=np.int64).reshape(-1, k)[:, :corners]

    width = 1 << 31  # (gmsh node tags < 2^31)
    edges = [_edge_keys(c, width) for c in corner_pairs(2)]
    if not edges:
        return None
    known = np.unique(np.concatenate(edges))
    for (dim, num), name in sorted(groups.items()):
        if dim != 1:
            continue
        for entity in model.getEntitiesForPhysicalGroup(dim, num):
            for lines in corner_pairs(1, entity):
                loose = ~np.isin(_edge_keys(lines[:, :2], width)[::2], known)
                if loose.any():
                    label = f"{name}={num}" if name else str(num)
                    return (f"{int(loose.sum())} line element(s) of the 1-D group {label} are no edge of any 2-D cell: "
                            "the curve is not part of the surface mesh (gmsh: embed it in the surface, "
                            "gmsh.model.mesh.embed, or make the geometry coherent)")
    return None


def _read_model(model_or_path, comm, root=0):
    """(mesh, cell_tags, facet_tags, groups, source) from a gmsh model (rank 0) or a .msh path."""
    gmsh = compat.import_gmsh()

    is_path = isinstance(model_or_path, (str, os.PathLike))
    source = os.fspath(model_or_path) if is_path else "gmsh model"

    def _finish(model):
        groups, err = (None, None)
        if comm.rank == root:
            try:
                groups, err = _physical_groups(model)
            except Exception as exc:  # gmsh errors (not initialised...)
                groups, err = {}, f"cannot read the gmsh model: {exc}"
        groups, err = comm.bcast((groups, err), root=root)
        if err:
            raise GeometryError(f"{source}: {err}")
        mesh, ct, ft = compat.model_to_mesh(model if comm.rank == root else None, comm, root, gdim=2)
        return mesh, ct, ft, groups

    if not is_path:
        model = gmsh.model if model_or_path is None else model_or_path
        if comm.rank == root and not compat.gmsh_is_initialized():
            comm.bcast(({}, "gmsh is not initialised: build the model first"), root=root)
            raise GeometryError("gmsh model: gmsh is not initialised: build the model first")
        mesh, ct, ft, groups = _finish(model)
        return mesh, ct, ft, groups, source

    if comm.rank == root:
        with compat.gmsh_model("cfcontact-input") as model:
            err = None
            if not os.path.isfile(source):
                err = f"no such mesh file: {source!r}"
            else:
                try:
                    gmsh.merge(source)
                    model.mesh.renumberNodes()  # (a valid file may number its nodes with gaps: 1002, 1004, ...)
                except Exception as exc:
                    err = f"gmsh cannot read {source!r}: {exc}"
            if err:
                comm.bcast(({}, err), root=root)
                raise GeometryError(err)
            mesh, ct, ft, groups = _finish(model)
    else:
        mesh, ct, ft, groups = _finish(None)
    return mesh, ct, ft, groups, source


# ============================================================ the FEM model
def _allgather_rows(comm, arr, width, dtype):
    arr = np.asarray(arr, dtype=dtype).reshape(-1, width)
    if comm.size == 1:
        return arr
    return np.concatenate(comm.allgather(arr), axis=0)


class _FemModel:
    """A distributed dolfinx mesh with its data gathered in rank-independent form."""

    def __init__(self, model_or_path, comm):
        t0 = time.perf_counter()
        self.comm = comm
        self.mesh, self.ct, self.ft, self.groups, self.source = _read_model(model_or_path, comm)
        mesh = self.mesh
        self.V = compat.vector_p1_space(mesh)
        self.bs = int(self.V.dofmap.index_map_bs)
        if self.bs != 2:
            raise GeometryError(f"expected a 2-D mesh, got a vector space of block size {self.bs}")
        self.cell_type = compat.cell_type_name(mesh)

        # local geometry: node coordinates and input (gmsh) indices
        gd = compat.geometry_dofmap(mesh)
        igi = compat.input_global_indices(mesh)
        xy = compat.geometry_points(mesh)
        cv = compat.cell_vertices(mesh)
        if cv.shape != gd.shape:
            raise GeometryError("only linear (P1/Q1) meshes are supported")
        # topological vertex -> geometry node (linear cells: same local order)
        v2g = np.full(int(cv.max()) + 1 if cv.size else 0, -1, dtype=np.int64)
        v2g[cv.ravel()] = gd.ravel()
        self._v2orig = igi[v2g]
        # block dof -> input node index, via the cell dofmaps
        dm = compat.dofmap_array(self.V)
        im = self.V.dofmap.index_map
        nblocks = im.size_local + im.num_ghosts
        dof_orig = np.full(nblocks, -1, dtype=np.int64)
        dof_orig[dm.ravel()] = igi[gd.ravel()]
        if np.any(dof_orig < 0):
            raise GeometryError("some degrees of freedom are not attached to a mesh node")
        self.dof_orig = dof_orig

        # all nodes (gathered): input index -> compressed index 0..P-1 (same order)
        nodes = _allgather_rows(comm, np.column_stack([igi, xy]), 3, float)
        orig = nodes[:, 0].astype(np.int64)
        self.orig_nodes, first = np.unique(orig, return_index=True)
        self.points = nodes[first, 1:3].copy()

        # global block index -> compressed node
        owned = np.arange(im.size_local)
        gblocks = compat.index_map_local_to_global(im, owned)
        pairs = _allgather_rows(comm, np.column_stack([gblocks, self.node_index(dof_orig[owned])]), 2, np.int64)
        self.block_node = np.full(int(im.size_global), -1, dtype=np.int64)
        self.block_node[pairs[:, 0]] = pairs[:, 1]

        # cells (owned), gathered, in input order, VTK node order, counter-clockwise
        ncells = compat.num_owned(mesh, mesh.topology.dim)
        self.num_owned_cells = ncells
        cidx, cval = compat.meshtags_arrays(self.ct)
        body = np.zeros(gd.shape[0], dtype=np.int64)
        body[cidx] = cval
        cells = self.node_index(igi[gd[:ncells]])
        if self.cell_type == "quadrilateral":
            cells = cells[:, _QUAD_TO_VTK]
        occ = compat.original_cell_index(mesh)
        key = occ[:ncells] if occ is not None else np.zeros(ncells, dtype=np.int64)
        k = cells.shape[1]
        rows = _allgather_rows(comm, np.column_stack([key, body[:ncells], cells]), k + 2, np.int64)
        if occ is not None:
            order = np.argsort(rows[:, 0], kind="stable")
        else:  # rank-independent fallback: lexicographic by node indices
            order = np.lexsort(rows[:, :1:-1].T)
        rows = rows[order]
        cells = rows[:, 2:]
        P = self.points[cells]
        area = 0.5 * np.sum(P[:, :, 0] * np.roll(P[:, :, 1], -1, axis=1) - np.roll(P[:, :, 0], -1, axis=1) * P[:, :, 1], axis=1)
        flip = area < 0
        if np.any(flip):
            cells[flip] = cells[flip][:, ::-1]
        self.cells = np.ascontiguousarray(cells)
        self.cell_body = rows[:, 1].copy()

        # tagged facets (gathered, deduplicated): tag, node a, node b, centroid of the adjacent cell
        fidx, fval = compat.meshtags_arrays(self.ft)
        if fidx.size:
            fv = compat.facet_vertices(mesh)[fidx]
            fa = self.node_index(self._v2orig[fv[:, 0]])
            fb = self.node_index(self._v2orig[fv[:, 1]])
            fc_arr, fc_off = compat.facet_cells(mesh)
            cell_of = fc_arr[fc_off[fidx]]
            cent = xy[gd[cell_of]].mean(axis=1)
        else:
            fa = fb = np.empty(0, dtype=np.int64)
            cent = np.empty((0, 2))
        frows = _allgather_rows(comm, np.column_stack([fval, fa, fb, cent]), 5, float)
        ftag = frows[:, 0].astype(np.int64)
        fab = frows[:, 1:3].astype(np.int64)
        lo, hi = fab.min(axis=1), fab.max(axis=1)
        _, uniq = np.unique(np.column_stack([ftag, lo, hi]), axis=0, return_index=True)
        self.facet_tag = ftag[uniq]
        self.facet_nodes = fab[uniq]
        self.facet_centroid = frows[uniq, 3:5]

        # body of each node and of each boundary piece
        self.node_body = np.zeros(len(self.points), dtype=np.int64)
        self.node_body[self.cells.ravel()] = np.repeat(self.cell_body, self.cells.shape[1])
        self._check_cells(np.abs(area))
        # the edges of the cells (cell_edge: each cell's, row by row, as indices into the edges);
        # facets with a cell on both sides (a line inside a body) are not on the boundary
        P = len(self.points)
        edges, cell_edge, count = np.unique(_edge_keys(self.cells, P), return_inverse=True, return_counts=True)
        self.cell_edge = cell_edge.ravel()
        key = _edge_keys(self.facet_nodes, P)[::2] if self.facet_nodes.size else np.empty(0)
        at = np.searchsorted(edges, key)
        self.facet_interior = (at < edges.size) & (edges[np.minimum(at, edges.size - 1)] == key) & \
            (count[np.minimum(at, edges.size - 1)] > 1)
        self.timings = {"read": time.perf_counter() - t0}

    def _check_cells(self, area):
        """GeometryError for a cell of (nearly) zero area (its stiffness would be inf/nan) and for nodes
        shared by cells of two bodies (bodies meshed as one coherent geometry: glued, not in contact)."""
        P = self.points[self.cells]
        longest = np.max(np.sum((P - np.roll(P, -1, axis=1)) ** 2, axis=2), axis=1)
        flat = np.flatnonzero(area <= 1e-10 * longest)
        if flat.size:
            c = flat[0]
            corners = "; ".join(f"({x:.6g}, {y:.6g})" for x, y in P[c])
            raise GeometryError(f"{flat.size} cell(s) of (nearly) zero area, e.g. one of body {int(self.cell_body[c])} "
                                f"with corners {corners}: remesh (a degenerate cell has no stiffness)")
        # (other 2-D groups may share nodes with a body: parts of it of another material, bonded)
        shared = np.intersect1d(self.cells[self.cell_body == BODY1], self.cells[self.cell_body == BODY2])
        if shared.size:
            where = "; ".join(f"({x:.6g}, {y:.6g})" for x, y in self.points[shared[:4]])
            raise GeometryError(
                f"body1 and body2 share {shared.size} mesh node(s), e.g. at {where}: they would be glued there, not in "
                "contact. Mesh each body with its own nodes along the interface (in gmsh, do not fragment or make "
                "coherent the two surfaces: contact1 and contact2 are two curves)")

    # --------------------------------------------------------------- helpers
    def node_index(self, orig):
        """Compressed node index of input (gmsh) node indices."""
        return np.searchsorted(self.orig_nodes, np.asarray(orig, dtype=np.int64))

    def facet_tag_nodes(self, tag):
        return self.facet_nodes[self.facet_tag == tag]

    def tag_bodies(self):
        """{1-D tag number: sorted list of bodies it touches}."""
        out = {}
        for (dim, num) in self.groups:
            if dim == 1:
                nodes = self.facet_tag_nodes(num).ravel()
                out[num] = sorted(set(self.node_body[nodes].tolist()))
        return out

    # -------------------------------------------------------------- assembly
    def stiffness_triplets(self, E, nu, plane):
        """Owned rows of K as (node_r, comp_r, node_c, comp_c, value), compressed node indices.

        ``E`` and ``nu``: numbers, or dicts {body name/number: value} (see :func:`material_per_body`).
        """
        V = self.V
        u, v = ufl.TrialFunction(V), ufl.TestFunction(V)

        def eps(w):
            return ufl.sym(ufl.grad(w))

        def energy(lam, mu, measure):
            lam_c = compat.constant(self.mesh, lam)
            mu_c = compat.constant(self.mesh, mu)
            sigma = 2.0 * mu_c * eps(u) + lam_c * ufl.tr(eps(u)) * ufl.Identity(2)
            return ufl.inner(sigma, eps(v)) * measure

        per_body = material_per_body(E, nu, plane, self.groups, np.unique(self.cell_body))
        if len(set(per_body.values())) == 1:
            a = energy(*next(iter(per_body.values())), ufl.dx)
        else:
            dx = ufl.Measure("dx", domain=self.mesh, subdomain_data=self.ct)
            a = sum(energy(lam, mu, dx(int(body))) for body, (lam, mu) in sorted(per_body.items()))
        A = compat.assemble_matrix(compat.form(a))
        ai, aj, av = A.getValuesCSR()
        r0, r1 = A.getOwnershipRange()
        rows = np.repeat(np.arange(r0, r1, dtype=np.int64), np.diff(ai))
        cols = np.asarray(aj, dtype=np.int64)
        vals = np.array(av, dtype=float, copy=True)
        A.destroy()
        bs = self.bs
        return (self.block_node[rows // bs], rows % bs, self.block_node[cols // bs], cols % bs, vals)

    def load_forms(self, traction_keys, body_numbers):
        """One linear form with a Constant per traction (tag, window) and per body force domain.
        A window (x0, x1, y0, y1) restricts the traction to the part of the piece inside it (the
        integrand is multiplied by its indicator; exact when the window ends on mesh nodes)."""
        V = self.V
        v = ufl.TestFunction(V)
        ds = ufl.Measure("ds", domain=self.mesh, subdomain_data=self.ft)
        dx = ufl.Measure("dx", domain=self.mesh, subdomain_data=self.ct)
        X = ufl.SpatialCoordinate(self.mesh)
        consts = {}
        L = None
        for tag, window in traction_keys:
            c = compat.constant(self.mesh, np.zeros(2))
            consts[("t", (tag, window))] = c
            integrand = ufl.dot(c, v)
            if window is not None:
                # the bounds are a Constant too (infinite ends compare as such), so that the compiled
                # form depends only on how many windows there are, not on where they lie
                w = compat.constant(self.mesh, np.asarray(window, dtype=float))
                inside = ufl.And(ufl.And(ufl.ge(X[0], w[0]), ufl.le(X[0], w[1])),
                                 ufl.And(ufl.ge(X[1], w[2]), ufl.le(X[1], w[3])))
                integrand = ufl.conditional(inside, integrand, 0.0)
            term = integrand * ds(tag)
            L = term if L is None else L + term
        for body in body_numbers:
            c = compat.constant(self.mesh, np.zeros(2))
            consts[("b", body)] = c
            term = ufl.dot(c, v) * (dx if body is None else dx(body))
            L = term if L is None else L + term
        if L is None:
            c = compat.constant(self.mesh, np.zeros(2))
            L = ufl.dot(c, v) * ufl.dx
        return compat.form(L), consts

    def assemble_load(self, compiled, consts, values):
        """Owned load entries as (node, comp, value) for the given Constant values."""
        for key, c in consts.items():
            c.value[...] = values.get(key, np.zeros(2))
        b = compat.assemble_vector(compiled)
        vals = compat.owned_vector_values(b, self.V)
        b.destroy()
        j = np.arange(vals.size)
        nodes = self.node_index(self.dof_orig[j // self.bs])
        return nodes, j % self.bs, vals


# ================================================================== public
def full_stiffness(model_or_path=None, *, E=2.1e11, nu=0.3, plane="strain", comm=None):
    """Stiffness of all DOFs (no elimination), for checks: whole on every rank.

    Returns ``(K, points, cells, cell_body)``: K a SciPy CSR matrix of size 2P
    with DOF ``2 * node + comp`` (nodes in the order of the gmsh node tags), and
    the node coordinates, cells (VTK order) and cell bodies.
    """
    comm = MPI.COMM_WORLD if comm is None else comm
    fem = _FemModel(model_or_path, comm)
    nr, cr, nc, cc, v = fem.stiffness_triplets(E, nu, plane)
    n = 2 * len(fem.points)
    K = linalg.mat_from_triplets(2 * nr + cr, 2 * nc + cc, v, (n, n), comm)
    Ks = linalg.gather_mat(K)
    K.destroy()
    return Ks, fem.points.copy(), fem.cells.copy(), fem.cell_body.copy()


#: keys of a windowed traction (a "patch"): {"value": (tx, ty), "x": (x0, x1), "y": (y0, y1)}
PATCH_KEYS = ("value", "x", "y")


def _window(value, what):
    """(lo, hi) with lo < hi (infinite ends allowed)."""
    try:
        lo, hi = (float(t) for t in value)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be an interval (lo, hi) of two numbers, got {value!r}") from None
    if not (lo < hi) or np.isnan(lo) or np.isnan(hi):
        raise InputError(f"{what} must be an interval (lo, hi) with lo < hi, got {value!r}")
    return lo, hi


def _is_vector_like(value):
    try:
        return np.asarray(value, dtype=float).ndim == 1
    except (TypeError, ValueError):
        return False


def _traction_terms(value, what):
    """One tag's traction -> [(window, vector)]; window None (the whole piece) or
    (x0, x1, y0, y1): the part of the piece with x0 <= x <= x1 and y0 <= y <= y1."""
    if isinstance(value, Mapping):
        unknown = sorted(set(map(str, value)) - set(PATCH_KEYS))
        if unknown or "value" not in value:
            raise InputError(f"{what}: a windowed traction is a dict with keys 'value' (tx, ty) and 'x' and/or 'y' "
                             f"(intervals), got keys {sorted(map(str, value))}")
        if "x" not in value and "y" not in value:
            raise InputError(f"{what}: a windowed traction needs 'x' = (x0, x1) and/or 'y' = (y0, y1)")
        x = _window(value["x"], f"{what}['x']") if "x" in value else (-np.inf, np.inf)
        y = _window(value["y"], f"{what}['y']") if "y" in value else (-np.inf, np.inf)
        return [(x + y, _vector2(value["value"], f"{what}['value']"))]
    if isinstance(value, (list, tuple)) and value and not _is_vector_like(value):
        return [t for k, item in enumerate(value) for t in _traction_terms(item, f"{what}[{k}]")]
    return [(None, _vector2(value, what))]


def _parse_tractions(tractions, groups, what):
    """{tag: (tx, ty) | {"value": ..., "x": ..., "y": ...} | [several]} -> {(tag, window): vector}."""
    out = {}
    if tractions is None:
        return out
    if not isinstance(tractions, Mapping):
        raise InputError(f"{what} must be a dict {{boundary tag: (tx, ty)}}, got {type(tractions).__name__}")
    for spec, value in tractions.items():
        tag = _resolve_tag(spec, groups, 1, what)
        for window, vec in _traction_terms(value, f"{what}[{spec!r}]"):
            out[(tag, window)] = out.get((tag, window), 0.0) + vec
    return out


def _check_windows(fem, trac, groups, what):
    """InputError for a traction window that misses its boundary piece (it would load nothing)."""
    for tag, window in trac:
        if window is None:
            continue
        facets = fem.facet_tag_nodes(tag)
        if not len(facets):
            continue
        pts = fem.points[np.unique(facets)]
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        x0, x1, y0, y1 = window
        if x1 < lo[0] or x0 > hi[0] or y1 < lo[1] or y0 > hi[1]:
            box = ", ".join(f"{a} in [{l:.6g}, {h:.6g}]" for a, l, h, on in (("x", x0, x1, np.isfinite([x0, x1]).any()),
                                                                           ("y", y0, y1, np.isfinite([y0, y1]).any()))
                            if on)
            raise InputError(f"{what}[{_tag_label(groups, 1, tag)!r}]: the window {box} misses the piece, which spans "
                             f"x in [{lo[0]:.6g}, {hi[0]:.6g}], y in [{lo[1]:.6g}, {hi[1]:.6g}]: it would load nothing")


def _tractions_meta(trac, label):
    """{label: [tx, ty]} for uniform tractions; a list of {"value", "x", "y"} items for a tag with windows."""
    out = {}
    for (tag, window), vec in trac.items():
        if window is None and not any(t == tag and w is not None for t, w in trac):
            out[label[tag]] = vec.tolist()
            continue
        item = {"value": vec.tolist()}
        if window is not None:
            for key, lo, hi in (("x", window[0], window[1]), ("y", window[2], window[3])):
                if np.isfinite(lo) or np.isfinite(hi):
                    item[key] = [lo, hi]
        out.setdefault(label[tag], []).append(item)
    return out


def _parse_body_force(force, groups, what):
    """None | (bx, by) on every body | {body: (bx, by)} -> {body number or None: vector}."""
    if force is None:
        return {}
    if isinstance(force, Mapping):
        out = {}
        for spec, vec in force.items():
            body = _resolve_tag(spec, groups, 2, what)
            out[body] = out.get(body, 0.0) + _vector2(vec, f"{what}[{spec!r}]")
        return out
    return {None: _vector2(force, what)}


def assemble_contact_system(
    model_or_path=None,
    *,
    E=2.1e11,
    nu=0.3,
    plane="strain",
    clamp=("left1", "left2"),
    tractions1=None,
    tractions2=None,
    body_force1=None,
    body_force2=None,
    friction=0.0,
    rho=None,
    comm=None,
    match_tol=1e-8,
    info=None,
    dirichlet=None,
    pairing=None,
    slave="contact1",
    search_distance=None,
    obstacle=None,
) -> ContactSystem:
    """Assemble the discrete contact problem of a tagged 2-D gmsh model.

    Parameters
    ----------
    model_or_path : the gmsh model (``gmsh.model``, meshed, on rank 0; None means
        ``gmsh.model``) or the path of a ``.msh`` file.  Physical groups per DESIGN.md.
    E, nu : Young's modulus and Poisson's ratio (default steel-like 2.1e11 Pa, 0.3): numbers, or
        dicts ``{body name/number: value}`` with one value per body (bimaterial contact)
    plane : ``"strain"`` (default) or ``"stress"`` (thickness 1)
    clamp : boundary pieces (1-D group names or numbers) where u = 0 (both components)
    tractions1, tractions2 : ``{boundary piece: (tx, ty)}`` surface tractions of the
        load vectors f1 and f2 (force per unit length).  A piece's value may instead be a
        windowed traction ``{"value": (tx, ty), "x": (x0, x1), "y": (y0, y1)}`` (either window
        may be left out) acting only on the part of the piece with x0 <= x <= x1 and
        y0 <= y <= y1 (mesh coordinates; exact when the window ends on mesh nodes), or a list
        of such values (summed), e.g. ``{"top1": [(0, -1e6), {"value": (0, -5e6), "x": (2.2, 2.3)}]}``
    body_force1, body_force2 : body forces of f1 and f2 (force per unit area): None,
        one vector ``(bx, by)`` on all bodies, or ``{body name/number: (bx, by)}``
    friction : Coulomb coefficient F (scalar or one per contact node)
    rho : augmentation parameter (default :func:`cfcontact.system.default_rho`)
    comm : mpi4py communicator (default COMM_WORLD)
    match_tol : contact nodes pair up when closer than ``match_tol * h`` (h: the
        shortest contact1 facet); node-to-segment pairing snaps a slave node that close to a
        master node onto it (node to node, no gap), and a gap to a rigid obstacle that small is 0
    info : extra entries for ``ContactSystem.info``
    dirichlet : ``{boundary piece: {"x": value, "y": value}}`` prescribed displacement
        components (either or both): a number (the same along the path) or a pair
        ``(value at alpha = 0, value at alpha = 1)``, so that u_D(alpha) = (1 - alpha) u_D^1 +
        alpha u_D^2, e.g. ``{"left1": {"x": 0}, "top1": {"y": (0, -1e-3)}}`` (a roller on left1,
        an indentation depth growing along the path on top1).  Pieces also in ``clamp`` must
        agree (clamped: both components 0).  Non-zero values on a contact boundary are refused
        (they would make the gap depend on alpha); zero ones (symmetry planes) are fine.
    pairing : ``"node"`` (default without an obstacle: matching interface, nodes coincide pairwise)
        or ``"segment"`` (default with an obstacle: node-to-segment projection with an initial
        gap, non-matching meshes allowed; see :mod:`cfcontact.pairing`)
    slave : the boundary whose nodes are projected with ``pairing="segment"``: ``"contact1"``
        (default) or ``"contact2"`` (name or number); its nodes are the contact nodes
    search_distance : node-to-segment pairing leaves out slave nodes farther than this from the
        master (measured along their normal); None: no limit.  Left-out nodes get one warning
        (:class:`~cfcontact.errors.PairingWarning`) and are listed in ``info["contact"]``.
    obstacle : a rigid obstacle as master of body 1 (the model has no body2):
        ``{"kind": "line", "point": (x, y), "normal": (nx, ny)}`` (the half-plane behind the
        line; ``normal`` points out of it, toward the body) or ``{"kind": "circle", "center":
        (x, y), "radius": R}`` (a rigid disc; with ``"inside": True`` a rigid bore, the body in
        its hole), or a :class:`cfcontact.pairing.Line` /
        :class:`~cfcontact.pairing.Circle`.  Its rows of N and T involve body 1's DOFs only.

    Returns a :class:`ContactSystem` whose ``gap`` is the initial gap of each pair and whose
    ``info["contact"]`` describes the pairing (pairs, excluded nodes, gap range).

    Raises
    ------
    GeometryError : missing mandatory groups, unknown tags, non-matching interface (with
        ``pairing="node"``), a slave that is not a contact boundary, an obstacle that does not face
        the body
    InputError : bad material, load, Dirichlet or pairing data, a body without Dirichlet condition,
        a non-zero prescribed displacement on a contact node
    """
    t_start = time.perf_counter()
    comm = MPI.COMM_WORLD if comm is None else comm
    check_material(E, nu, plane)  # validate before any collective work
    obstacle = pairing_mod.make_obstacle(obstacle)
    pairing = pairing_mod.check_pairing(("segment" if obstacle is not None else "node") if pairing is None else pairing)
    if obstacle is not None and pairing != "segment":
        raise InputError("an obstacle is paired node to segment: use pairing='segment' (or leave pairing out)")
    search_distance = pairing_mod.check_search_distance(search_distance)
    _check_dirichlet_shape(dirichlet)
    fem = _FemModel(model_or_path, comm)
    groups = fem.groups
    P = len(fem.points)
    rigid = (2, BODY2) not in groups
    if obstacle is not None and not rigid:
        raise GeometryError("an obstacle is the master of a single body, but the model has body2 (2-D group 2); "
                            "leave body2/contact2 out, or pair the two bodies (pairing='segment', no obstacle)")
    contacts = "contact1=10" + ("" if rigid else " or contact2=20")
    try:
        slave_tag = _resolve_tag(slave, groups, 1, "slave")
    except GeometryError:
        raise GeometryError(f"slave must be a contact boundary ({contacts}), got {slave!r}, which is not a "
                            f"boundary piece of the model") from None
    if slave_tag not in (CONTACT1, CONTACT2):
        raise GeometryError(f"slave must be a contact boundary ({contacts}), got {slave!r} "
                            f"({_tag_label(groups, 1, slave_tag)})")
    if slave_tag == CONTACT2 and obstacle is not None:
        raise GeometryError("with an obstacle the slave is contact1 (the body's contact boundary)")

    # ---------------------------------------------------------------- inputs
    if isinstance(clamp, (str, int, np.integer)):
        clamp = (clamp,)
    clamp_tags = [_resolve_tag(c, groups, 1, "clamp") for c in (clamp or ())]
    dir_items = _parse_dirichlet(dirichlet, groups)
    trac = [_parse_tractions(tractions1, groups, "tractions1"), _parse_tractions(tractions2, groups, "tractions2")]
    for k, t in enumerate(trac):
        _check_windows(fem, t, groups, f"tractions{k + 1}")
        for tag in sorted({tag for tag, _ in t}):
            inside = fem.facet_interior[fem.facet_tag == tag]
            if inside.any():
                raise GeometryError(f"tractions{k + 1}: {_tag_label(groups, 1, tag)} (1-D group) lies inside a body "
                                    f"({int(inside.sum())} of its {inside.size} facets have a cell on both sides); "
                                    "tractions act on boundary pieces (a force inside a body: split it along the line)")
    bforce = [_parse_body_force(body_force1, groups, "body_force1"), _parse_body_force(body_force2, groups, "body_force2")]

    # ------------------------------------------------------ Dirichlet / bodies
    fixed, u_D = _prescribed_dofs(fem, clamp_tags, dir_items, groups)
    constrained = fixed.any(axis=1)  # nodes with some prescribed component
    _check_supports(fem, fixed, groups, clamp_tags)
    contact_nodes_all = np.unique(np.concatenate([fem.facet_tag_nodes(t).ravel() for t in (CONTACT1, CONTACT2)]))
    moving = fixed & ((u_D[0] != 0.0) | (u_D[1] != 0.0))
    bad = contact_nodes_all[moving[contact_nodes_all].any(axis=1)]
    if bad.size:
        where = "; ".join(f"({x:.6g}, {y:.6g})" for x, y in fem.points[bad[:6]]) + ("; ..." if bad.size > 6 else "")
        raise InputError(f"non-zero prescribed displacement on {bad.size} contact node(s) at {where}: it would make "
                         "the initial gap depend on alpha; prescribe displacements away from contact1/contact2 "
                         "(zero components there, e.g. symmetry planes or rollers, are fine)")

    # canonical numbering: free DOFs by (node, component)
    free = ~fixed.ravel()
    canon = np.full(2 * P, -1, dtype=np.int64)
    n = int(np.count_nonzero(free))
    canon[free] = np.arange(n)
    dof_node = np.repeat(np.arange(P), 2)[free]
    dof_comp = np.tile([0, 1], P)[free]

    # ------------------------------------------------------------- stiffness
    t0 = time.perf_counter()
    nr, cr, nc, cc, v = fem.stiffness_triplets(E, nu, plane)
    lift = _lifting(canon, 2 * nr + cr, 2 * nc + cc, v, u_D)  # K_fD u_D^k of the prescribed displacements
    _check_lifting(lift, comm)
    r = canon[2 * nr + cr]
    c = canon[2 * nc + cc]
    keep = (r >= 0) & (c >= 0)
    r, c, v = r[keep], c[keep], 0.5 * v[keep]
    # symmetric by construction: K = (A + A^T) / 2 (A is symmetric up to rounding)
    K = linalg.mat_from_triplets(np.concatenate([r, c]), np.concatenate([c, r]), np.concatenate([v, v]), (n, n), comm)

    # ----------------------------------------------------------------- loads
    traction_keys = sorted(set(trac[0]) | set(trac[1]), key=lambda k: (k[0], k[1] is not None, k[1] or ()))
    tag_numbers = sorted({tag for tag, _ in traction_keys})
    body_numbers = sorted(set(bforce[0]) | set(bforce[1]), key=lambda b: -1 if b is None else b)
    compiled, consts = fem.load_forms(traction_keys, body_numbers)
    loads = []
    for k in range(2):
        values = {("t", t): vec for t, vec in trac[k].items()}
        values.update({("b", b): vec for b, vec in bforce[k].items()})
        ln, lc, lv = fem.assemble_load(compiled, consts, values)
        idx = canon[2 * ln + lc]
        keep = idx >= 0
        li, lval = lift[k]
        loads.append(linalg.vec_from_triplets(np.concatenate([idx[keep], li]), np.concatenate([lv[keep], -lval]), n, comm))
    t_assemble = time.perf_counter() - t0

    # --------------------------------------------------------------- contact
    pr = _contact_pairing(fem, rigid, pairing, slave_tag, search_distance, obstacle, match_tol, fixed)
    # drop pairs whose normal row would be zero (every DOF it touches is prescribed)
    pair_of, node_of, fac_of = pr.entries()
    live = np.zeros(pr.m, dtype=bool)
    for comp in (0, 1):
        ok = (canon[2 * node_of + comp] >= 0) & (pr.normals[pair_of, comp] != 0.0)
        live[pair_of[ok]] = True
    dropped = int(np.count_nonzero(~live))
    pr = pr.select(live)
    pr = pr.select(pairing_mod.order_along_interface(fem.points, pr.slave, pr.tangents))
    m = pr.m
    normals, tangents = pr.normals, pr.tangents
    rows, cols, nvals, tvals = [], [], [], []
    if comm.rank == 0:
        pair_of, node_of, fac_of = pr.entries()
        order = np.lexsort((node_of, pair_of))  # per pair: its nodes in index order (fixed)
        for i, node, fac in zip(pair_of[order], node_of[order], fac_of[order]):
            for comp in (0, 1):
                d = canon[2 * node + comp]
                if d >= 0:
                    rows.append(i)
                    cols.append(d)
                    nvals.append(fac * normals[i, comp])
                    tvals.append(fac * tangents[i, comp])
    rows = np.asarray(rows, dtype=np.int64)
    cols = np.asarray(cols, dtype=np.int64)
    nvals = np.asarray(nvals, dtype=float)
    tvals = np.asarray(tvals, dtype=float)
    nk, tk = nvals != 0.0, tvals != 0.0
    N = linalg.mat_from_triplets(rows[nk], cols[nk], nvals[nk], (m, n), comm)
    T = linalg.mat_from_triplets(rows[tk], cols[tk], tvals[tk], (m, n), comm)
    contact_meta = _pairing_meta(pr, fem.points, pairing, slave_tag, groups, search_distance, obstacle, dropped)
    if pr.excluded.size and comm.rank == 0:
        master = "the obstacle" if obstacle is not None else _tag_label(groups, 1, CONTACT1 + CONTACT2 - slave_tag)
        warnings.warn(pr.exclusion_message(fem.points, _tag_label(groups, 1, slave_tag), master), PairingWarning,
                      stacklevel=2)

    if rho is None:
        diag = linalg.gather_vec(K.getDiagonal())
        NT = None
        if comm.rank == 0:
            NT = (sp.csr_matrix((nvals[nk], (rows[nk], cols[nk])), shape=(m, n)),
                  sp.csr_matrix((tvals[tk], (rows[tk], cols[tk])), shape=(m, n)))
        NT = comm.bcast(NT, root=0)
        rho = default_rho(sp.diags(diag), *NT)

    pair_array = pr.body_nodes()
    geometry = ContactGeometry(
        points=fem.points.copy(),
        cells=fem.cells.copy(),
        cell_body=fem.cell_body.copy(),
        dof_node=dof_node,
        dof_comp=dof_comp,
        contact_nodes=pair_array,
        contact_points=fem.points[pr.slave].reshape(m, 2),
        normals=normals,
        tangents=tangents,
        tributary=pr.tributary.copy(),
        prescribed=_prescribed_table(fixed, u_D),
        obstacle=None if obstacle is None else obstacle.to_dict(),
    )
    label = {t: _tag_label(groups, 1, t) for t in set(clamp_tags) | set(tag_numbers)}
    meta = {
        "source": fem.source,
        "cell_type": fem.cell_type,
        "E": _material_meta(E, groups),
        "nu": _material_meta(nu, groups),
        "plane": plane,
        "clamp": [label[t] for t in clamp_tags],
        "dirichlet": _dirichlet_meta(dir_items, groups),
        "contact": contact_meta,
        "tractions1": _tractions_meta(trac[0], label),
        "tractions2": _tractions_meta(trac[1], label),
        "body_force1": {str(b): vec.tolist() for b, vec in bforce[0].items()},
        "body_force2": {str(b): vec.tolist() for b, vec in bforce[1].items()},
        "rigid_foundation": rigid,
        "num_nodes": P,
        "num_cells": len(fem.cells),
        "physical_groups": {f"{d}:{num}": name for (d, num), name in sorted(groups.items())},
        "dolfinx": ".".join(map(str, compat.DOLFINX_VERSION)),
        "mpi_size": comm.size,
        "owned_cells": fem.num_owned_cells,  # cells owned by this rank (differs between ranks)
        "timings": {"read": fem.timings["read"], "assemble": t_assemble, "total": time.perf_counter() - t_start},
    }
    if info:
        meta.update(info)
    geometry.material = {"E": meta["E"], "nu": meta["nu"], "plane": meta["plane"]}  # saved with a path
    return ContactSystem(K=K, N=N, T=T, f1=loads[0], f2=loads[1], friction=friction, rho=rho,
                         geometry=geometry, info=meta, gap=pr.gap)


def _contact_pairing(fem, rigid, pairing, slave_tag, search_distance, obstacle, match_tol, fixed=None):
    """The contact pairs (:class:`cfcontact.pairing.Pairing`) of the model, in slave node order;
    ``fixed``: the prescribed displacement components (P, 2) (rollers turn the slave normals,
    :func:`cfcontact.pairing.roller_normals`)."""
    pts = fem.points
    f1, cent1 = _contact_facets(fem, CONTACT1, BODY1)
    _, length1 = pairing_mod.facet_normals(pts, f1, cent1)
    h = float(length1.min())
    tol = float(match_tol) * h
    if obstacle is not None:
        return pairing_mod.obstacle_pairing(pts, f1, cent1, obstacle, search_distance=search_distance, snap=tol,
                                            fixed=fixed)
    nodes1, normal1 = pairing_mod.node_normals(pts, f1, cent1, "contact1", fixed)
    trib1 = pairing_mod.tributary_lengths(pts, f1, nodes1)
    k = len(nodes1)
    if rigid:
        if pairing == "segment":
            raise GeometryError("pairing='segment' needs a master: contact2 (body2) or an obstacle")
        return pairing_mod.Pairing(nodes1, np.full((k, 2), -1, dtype=np.int64), np.zeros((k, 2)), normal1,
                                   np.zeros(k), trib1, 1)
    f2, cent2 = _contact_facets(fem, CONTACT2, BODY2)
    if pairing == "node":
        partner = pairing_mod.match_nodes(pts, nodes1, np.unique(f2), tol, match_tol, h)
        master = np.column_stack([partner, np.full(k, -1)]).astype(np.int64)
        weights = np.column_stack([np.ones(k), np.zeros(k)])
        return pairing_mod.Pairing(nodes1, master, weights, normal1, np.zeros(k), trib1, 1)
    if slave_tag == CONTACT1:
        return pairing_mod.node_to_segment(pts, f1, cent1, f2, cent2, slave_body=1, search_distance=search_distance,
                                           snap=tol, slave_name="contact1", master_name="contact2", fixed=fixed)
    return pairing_mod.node_to_segment(pts, f2, cent2, f1, cent1, slave_body=2, search_distance=search_distance,
                                       snap=tol, slave_name="contact2", master_name="contact1", fixed=fixed)


def _check_supports(fem, fixed, groups, clamp_tags):
    """InputError when the prescribed displacements leave part of the mesh free to move as a rigid
    body (its stiffness would be singular: every part needs supports, contact does not hold it).
    The mesh is cut into rigid pieces -- cells joined through shared edges, across 2-D groups (a
    part of another material bonded to a body moves with it) --; pieces that share nodes are joined
    there (one node: a hinge), and each prescribed component holds its node: the free motions are
    the null space of those conditions on the pieces' rigid motions (three per piece).  A body
    whose pieces share no node while some of their nodes coincide (surfaces meshed without being
    joined) is named as such: in the error, or in a MeshWarning when everything is held."""
    piece = _edge_pieces(fem.cell_edge, fem.cells.shape[1])
    free = _free_motions(fem.points, fem.cells, piece, fixed)
    body_name = lambda body: f"body {int(body)} ({groups.get((2, int(body)), '') or 'unnamed'})"  # noqa: E731
    joined = {}  # body -> (its pieces, the note on coinciding nodes between them)
    for body in np.unique(fem.cell_body):
        mine = np.unique(piece[fem.cell_body == body])
        if mine.size > 1:
            joined[int(body)] = (mine.size, _coinciding(fem.points, fem.cells, piece, fem.cell_body == body))
    if free is not None:
        moving, what = free
        cells = np.isin(piece, moving)
        at = np.unique(fem.cells[cells])
        bodies = np.unique(fem.cell_body[cells])
        where = " bonded to ".join(body_name(b) for b in bodies)
        split = [int(b) for b in bodies if int(b) in joined]
        if split:
            lo, hi = fem.points[at].min(axis=0), fem.points[at].max(axis=0)
            count, note = joined[split[0]]
            where = (f"the part of {where} within x in [{lo[0]:.6g}, {hi[0]:.6g}], y in [{lo[1]:.6g}, {hi[1]:.6g}] "
                     f"({body_name(split[0])} has {count} pieces{note or ' joined at single nodes or not at all'})")
        held_at = np.intersect1d(at, fem.cells[~cells])  # (nodes it shares with parts that do not move)
        if not fixed[at].any() and not held_at.size:
            tag_bodies = fem.tag_bodies()
            on_it = [_tag_label(groups, 1, t) for t, bs in sorted(tag_bodies.items())
                     if set(bs) <= set(bodies.tolist()) and t not in (CONTACT1, CONTACT2)]
            used = ", ".join(_tag_label(groups, 1, t) for t in clamp_tags) or "none"
            raise InputError(
                f"{where} has no Dirichlet condition: none of the clamped boundary pieces ({used}) lies on it, so "
                f"its stiffness is singular (rigid-body motions). Clamp one of its boundary pieces"
                + (f", e.g. one of: {', '.join(on_it)}" if on_it and not split else ""))
        raise InputError(f"{where} {what}: its stiffness is singular; clamp one of its boundary pieces or prescribe "
                         "more displacement components (dirichlet)")
    for body, (count, note) in joined.items():
        if note:
            warnings.warn(f"{body_name(body)} is made of {count} pieces that share no edge{note}; each piece is held "
                          "by its own supports", MeshWarning, stacklevel=3)


def _edge_pieces(cell_edge, k) -> np.ndarray:
    """The rigid piece of each cell: cells joined through shared edges (connected components);
    ``cell_edge``: the edge index of each of the k edges of each cell, row by row."""
    from scipy.sparse.csgraph import connected_components

    C = cell_edge.size // k
    owner = np.repeat(np.arange(C), k)
    incidence = sp.csr_matrix((np.ones(cell_edge.size), (owner, cell_edge)), shape=(C, int(cell_edge.max()) + 1))
    _, piece = connected_components(incidence @ incidence.T, directed=False)
    return piece


def _free_motions(points, cells, piece, fixed):
    """None when the rigid pieces (``piece``: each cell's), joined at their shared nodes and held by
    the prescribed components ``fixed`` (P, 2), admit no rigid motion; else (the pieces that move,
    what the motion is: "can move freely in x", "can rotate about (x, y)")."""
    pieces, index = np.unique(piece, return_inverse=True)
    pairs = np.unique(cells.ravel() * pieces.size + np.repeat(index.ravel(), cells.shape[1]))
    node, owner = pairs // pieces.size, pairs % pieces.size  # every (node, piece it belongs to), by node
    centre = points.mean(axis=0)
    size = max(float(np.ptp(points, axis=0).max(initial=0.0)), 1e-300)
    r = (points - centre) / size
    width = 3 * pieces.size

    def motion_rows(nodes, owners, comp):  # u_comp at the nodes as their pieces move: u = (a - c r_y, b + c r_x)
        out = np.zeros((nodes.size, width))
        out[np.arange(nodes.size), 3 * owners + comp] = 1.0
        out[np.arange(nodes.size), 3 * owners + 2] = -r[nodes, 1] if comp == 0 else r[nodes, 0]
        return out

    # a node in several pieces joins them: its motion is the same in each (pairs sorted by node)
    first = np.r_[True, node[1:] != node[:-1]]
    lead = np.maximum.accumulate(np.where(first, np.arange(node.size), 0))
    again = ~first
    blocks = [motion_rows(node[again], owner[lead[again]], comp) - motion_rows(node[again], owner[again], comp)
              for comp in (0, 1)]
    blocks += [motion_rows(node[fixed[node, comp]], owner[fixed[node, comp]], comp) for comp in (0, 1)]
    A = np.vstack(blocks)
    if A.shape[0] >= width:
        _, sv, vt = np.linalg.svd(A, full_matrices=False)
    else:
        _, sv, vt = np.linalg.svd(A) if A.size else (None, np.zeros(0), np.eye(width))
    if sv.size == width and sv[-1] > 1e-9 * sv[0]:
        return None
    motion = vt[-1].reshape(-1, 3)
    amount = np.abs(motion).max(axis=1)
    moves = amount > 1e-6 * amount.max()
    moving = pieces[moves]
    scale = max(float(sv[0]) if sv.size else 1.0, 1e-300)
    for comp, axis in ((0, "x"), (1, "y")):  # (the plainest free motion first: those pieces sliding in x or y)
        slide = np.zeros((pieces.size, 3))
        slide[moves, comp] = 1.0
        if np.linalg.norm(A @ slide.ravel()) <= 1e-9 * scale * np.linalg.norm(slide):
            return moving, f"can move freely in {axis}"
    a, b, c = motion[int(np.argmax(amount))]
    if abs(c) <= 1e-9 * max(abs(a), abs(b)):
        if abs(b) <= 1e-9 * abs(a) or abs(a) <= 1e-9 * abs(b):
            return moving, f"can move freely in {'x' if abs(b) <= 1e-9 * abs(a) else 'y'}"
        return moving, f"can move freely along ({a:.3g}, {b:.3g})"
    pivot = centre + size * np.array([-b / c, a / c])
    pivot = np.where(np.abs(pivot) <= 1e-12 * (size + np.abs(centre).max()), 0.0, pivot)  # (rounding of a zero)
    return moving, f"can rotate about ({pivot[0]:.6g}, {pivot[1]:.6g}) (its supports do not hold the rotation)"


def _coinciding(points, cells, piece, mine) -> str:
    """"; nodes of different pieces coincide at (x, y), ...: surfaces meshed without being joined"
    when nodes of the cells ``mine`` (a mask) in different pieces coincide (else "")."""
    nodes = np.unique(cells[mine])
    node_piece = np.empty(len(points), dtype=np.int64)
    node_piece[cells[mine].ravel()] = np.repeat(piece[mine], cells.shape[1])
    from scipy.spatial import cKDTree

    xy = points[nodes]
    scale = max(float(np.ptp(xy, axis=0).max(initial=0.0)), 1e-300)
    close = cKDTree(xy).query_pairs(1e-10 * scale, output_type="ndarray")
    pairs = close[node_piece[nodes[close[:, 0]]] != node_piece[nodes[close[:, 1]]]]
    if not len(pairs):
        return ""
    pairs = pairs[np.lexsort((xy[pairs[:, 0], 1], xy[pairs[:, 0], 0]))]
    where = "; ".join(f"({xy[i, 0]:.6g}, {xy[i, 1]:.6g})" for i in pairs[:3, 0])
    return (f"; nodes of different pieces coincide at {len(pairs)} point(s), e.g. {where}: surfaces meshed without "
            "being joined -- make the geometry coherent if they are one body")


def _contact_facets(fem, tag, body):
    """(facets (F, 2), centroids of their cells (F, 2)) of a contact boundary, checked."""
    name = f"contact{body} (1-D group {tag})"
    facets = fem.facet_tag_nodes(tag)
    if len(facets) == 0:
        raise GeometryError(f"{name} has no facets in the mesh")
    if np.any(fem.node_body[facets.ravel()] != body):
        raise GeometryError(f"{name} must lie on the boundary of body{body} (2-D group {body})")
    inside = fem.facet_interior[fem.facet_tag == tag]
    if inside.any():
        raise GeometryError(f"{name} lies inside body{body}: {int(inside.sum())} of its {len(facets)} facets have a cell "
                            "on both sides; a contact boundary is a piece of the body's boundary")
    return facets, fem.facet_centroid[fem.facet_tag == tag]


def _pairing_meta(pr, points, pairing, slave_tag, groups, search_distance, obstacle, dropped):
    """``info["contact"]``: how the contact pairs were formed (for ``cfcontact info``)."""
    excluded = np.asarray(points)[pr.excluded]
    slave = slave_tag if pairing == "segment" and obstacle is None else CONTACT1
    return {
        "pairing": pairing,
        "slave": _tag_label(groups, 1, slave),
        "master": ("obstacle" if obstacle is not None else "rigid foundation" if (1, CONTACT2) not in groups
                   else _tag_label(groups, 1, CONTACT1 + CONTACT2 - slave)),
        "search_distance": search_distance,
        "obstacle": None if obstacle is None else obstacle.to_dict(),
        "pairs": pr.m,
        "excluded": int(pr.excluded.size),
        "excluded_points": excluded[:50].tolist(),
        "excluded_reasons": {r: int(np.sum(pr.excluded_reason == r)) for r in np.unique(pr.excluded_reason)},
        "dropped_prescribed": dropped,
        "gap_range": [float(pr.gap.min()), float(pr.gap.max())] if pr.m else [0.0, 0.0],
    }


# ======================================================== Dirichlet conditions
DIRICHLET_COMPONENTS = {"x": 0, "y": 1}


def _check_dirichlet_shape(dirichlet):
    """Validate the form of ``dirichlet`` before any collective work (tags are resolved later)."""
    if dirichlet is None:
        return
    if not isinstance(dirichlet, Mapping):
        raise InputError(f"dirichlet must be a dict {{boundary piece: {{'x': value, 'y': value}}}}, "
                         f"got {type(dirichlet).__name__}")
    for spec, comps in dirichlet.items():
        _dirichlet_components(comps, f"dirichlet[{spec!r}]")


def _dirichlet_components(comps, what):
    """{"x": v, "y": v} -> {component: (value at alpha = 0, value at alpha = 1)}."""
    if not isinstance(comps, Mapping) or not comps:
        raise InputError(f"{what} must be a dict with the components 'x' and/or 'y', e.g. {{'y': 0}}, got {comps!r}")
    out = {}
    for key, value in comps.items():
        if key not in DIRICHLET_COMPONENTS:
            raise InputError(f"{what}: unknown component {key!r}; use 'x' and/or 'y'")
        try:
            if isinstance(value, (bool, np.bool_)) or isinstance(value, str):
                raise TypeError
            arr = np.asarray(value, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            arr = np.zeros(0)
        if arr.size == 1:
            arr = np.repeat(arr, 2)
        if arr.shape != (2,) or not np.all(np.isfinite(arr)):
            raise InputError(f"{what}[{key!r}] must be a number or a pair (value at alpha = 0, value at alpha = 1), "
                             f"got {value!r}")
        out[DIRICHLET_COMPONENTS[key]] = (float(arr[0]), float(arr[1]))
    return out


def _parse_dirichlet(dirichlet, groups):
    """{(tag, component): (v1, v2)} of ``dirichlet`` (tags by name or number)."""
    out = {}
    for spec, comps in (dirichlet or {}).items():
        tag = _resolve_tag(spec, groups, 1, "dirichlet")
        for comp, vals in _dirichlet_components(comps, f"dirichlet[{spec!r}]").items():
            if (tag, comp) in out and out[(tag, comp)] != vals:
                raise InputError(f"dirichlet gives {_tag_label(groups, 1, tag)} two values for {'xy'[comp]}")
            out[(tag, comp)] = vals
    return out


def _prescribed_dofs(fem, clamp_tags, dir_items, groups):
    """(fixed (P, 2) bool, (u_D^1, u_D^2) (P, 2) each) of the clamped pieces and ``dirichlet``;
    InputError when two pieces prescribe different values on one node component."""
    P = len(fem.points)
    fixed = np.zeros((P, 2), dtype=bool)
    vals = np.zeros((2, P, 2))
    source = {}
    items = [((t, c), (0.0, 0.0), f"clamp {_tag_label(groups, 1, t)}") for t in clamp_tags for c in (0, 1)]
    items += [(key, v, f"dirichlet {_tag_label(groups, 1, key[0])}") for key, v in dir_items.items()]
    for (tag, comp), (v1, v2), label in items:
        nodes = np.unique(fem.facet_tag_nodes(tag))
        clash = nodes[fixed[nodes, comp] & ((vals[0, nodes, comp] != v1) | (vals[1, nodes, comp] != v2))]
        if clash.size:
            x, y = fem.points[clash[0]]
            other = source[(int(clash[0]), comp)]
            raise InputError(f"node ({x:.6g}, {y:.6g}) gets two prescribed {'xy'[comp]} displacements: {other} "
                             f"{tuple(vals[:, clash[0], comp].tolist())} and {label} {(v1, v2)} (values at alpha = 0 "
                             f"and 1); make them agree or leave the node to one piece")
        fixed[nodes, comp] = True
        vals[0, nodes, comp], vals[1, nodes, comp] = v1, v2
        for node in nodes.tolist():
            source.setdefault((node, comp), label)
    return fixed, vals


def _lifting(canon, gr, gc, v, u_D):
    """For each load k: (free DOF, value) triplets of K_fD u_D^k, with K's symmetrisation
    ((A + A^T) / 2 of the owned stiffness triplets (gr, gc, v), full DOF indices 2 node + comp)."""
    out = []
    for k in range(2):
        uk = u_D[k].ravel()
        if not uk.any():
            out.append((np.zeros(0, dtype=np.int64), np.zeros(0)))
            continue
        r, c = canon[gr], canon[gc]
        a = (r >= 0) & (c < 0) & (uk[gc] != 0.0)  # A_fD
        b = (c >= 0) & (r < 0) & (uk[gr] != 0.0)  # (A_Df)^T
        out.append((np.concatenate([r[a], c[b]]), 0.5 * np.concatenate([v[a] * uk[gc[a]], v[b] * uk[gr[b]]])))
    return out


def _check_lifting(lift, comm):
    """InputError naming the prescribed displacements (dirichlet) when the loads K_fD u_D^k of the prescribed displacements
    overflow or exceed MAGNITUDE_LIMIT: then the prescribed displacements, not the tractions or
    body forces, are what is too large (collective under MPI)."""
    for k, (_, lval) in enumerate(lift):
        lval = np.asarray(lval, dtype=float)
        big = float(np.abs(lval).max(initial=0.0)) if np.all(np.isfinite(lval)) else float("inf")
        big = comm.allreduce(big, op=MPI.MAX)
        if big > MAGNITUDE_LIMIT:
            size = "overflow (inf)" if not np.isfinite(big) else f"reach {big:.3g}"
            raise InputError(f"the prescribed displacements (dirichlet) are too large: their loads K u_D at "
                             f"alpha = {k} {size}, beyond {MAGNITUDE_LIMIT:g}; rescale the units")


def _prescribed_table(fixed, u_D):
    """(k, 4) [node, component, value at alpha = 0, value at alpha = 1] of the non-zero prescribed
    displacements (``ContactGeometry.prescribed``), or None."""
    nz = fixed & ((u_D[0] != 0.0) | (u_D[1] != 0.0))
    node, comp = np.nonzero(nz)
    if not node.size:
        return None
    return np.column_stack([node, comp, u_D[0][node, comp], u_D[1][node, comp]]).astype(float)


def _dirichlet_meta(dir_items, groups):
    out = {}
    for (tag, comp), (v1, v2) in sorted(dir_items.items()):
        out.setdefault(_tag_label(groups, 1, tag), {})["xy"[comp]] = [v1, v2]
    return out
