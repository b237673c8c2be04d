"""FEM assembly layer: each test compares with an independent reference."""

import os
import subprocess
import sys
import time

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp

pytest.importorskip("dolfinx")
pytest.importorskip("gmsh")

from cfcontact import compat  # noqa: E402
from cfcontact.assembly import assemble_contact_system, full_stiffness, lame_parameters  # noqa: E402
from cfcontact.errors import GeometryError, InputError  # noqa: E402
from cfcontact.models import two_blocks  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
E, NU = 2.1e11, 0.3


def geo():
    from cfcontact.meshes import two_blocks as geo

    return geo


def dof(system, node, comp):
    """Index of the free DOF (node, comp), located through the geometry tables."""
    g = system.geometry
    hit = np.flatnonzero((g.dof_node == node) & (g.dof_comp == comp))
    return int(hit[0]) if hit.size else None


# --------------------------------------------------------------- default model
@pytest.mark.parametrize("cell", ["quadrilateral", "triangle"])
def test_default_model_dimensions(cell):
    t0 = time.perf_counter()
    S = two_blocks(cell=cell)
    elapsed = time.perf_counter() - t0
    assert (S.n, S.m) == (1320, 30)
    g = S.geometry
    assert g.points.shape == (2 * 31 * 11, 2)
    ncell = 30 * 10 * (1 if cell == "quadrilateral" else 2)
    assert g.cells.shape == (2 * ncell, 4 if cell == "quadrilateral" else 3)
    assert np.bincount(g.cell_body).tolist() == [0, ncell, ncell]
    # contact points: x = 0.1, 0.2, ..., 3.0 on y = 0 (the clamped x = 0 pair excluded), in order
    np.testing.assert_allclose(g.contact_points[:, 0], 0.1 * np.arange(1, 31), atol=1e-12)
    np.testing.assert_allclose(g.contact_points[:, 1], 0.0, atol=1e-14)
    a, b = g.contact_nodes.T
    np.testing.assert_array_equal(g.points[a], g.points[b])
    assert np.all(g.cell_body[np.any(np.isin(g.cells, a), axis=1)] == 1)
    assert np.all(g.cell_body[np.any(np.isin(g.cells, b), axis=1)] == 2)
    # cells counter-clockwise (shoelace area > 0)
    P = g.points[g.cells]
    area = 0.5 * np.sum(P[:, :, 0] * np.roll(P[:, :, 1], -1, 1) - np.roll(P[:, :, 0], -1, 1) * P[:, :, 1], axis=1)
    np.testing.assert_allclose(area, 0.01 / (1 if cell == "quadrilateral" else 2), rtol=1e-10)
    # DOF table: (node, comp) increasing; clamped nodes are those with x == 0
    key = g.dof_node * 2 + g.dof_comp
    assert np.all(np.diff(key) > 0)
    clamped = np.setdiff1d(np.arange(len(g.points)), g.dof_node)
    np.testing.assert_allclose(g.points[clamped, 0], 0.0, atol=1e-14)
    assert clamped.size == 22
    assert elapsed < 10.0  # (< 2 s once the forms are JIT-compiled; first run compiles)


def test_default_model_fast():
    two_blocks(nx=2, ny=1)  # JIT compile the forms
    t0 = time.perf_counter()
    two_blocks()
    assert time.perf_counter() - t0 < 2.0


def test_contact_rows_flat():
    S = two_blocks(nx=6, ny=2)
    K, N, T, f1, f2 = S.to_scipy()
    g = S.geometry
    np.testing.assert_array_equal(g.normals, np.tile([0.0, -1.0], (S.m, 1)))
    np.testing.assert_array_equal(g.tangents, np.tile([1.0, 0.0], (S.m, 1)))
    Nd, Td = N.toarray(), T.toarray()
    for i, (a, b) in enumerate(g.contact_nodes):
        expected_n = np.zeros(S.n)
        expected_t = np.zeros(S.n)
        # (u1 - u2) . n with n = (0, -1);  (u1 - u2) . t with t = (1, 0)
        expected_n[dof(S, a, 1)] = -1.0
        expected_n[dof(S, b, 1)] = 1.0
        expected_t[dof(S, a, 0)] = 1.0
        expected_t[dof(S, b, 0)] = -1.0
        np.testing.assert_array_equal(Nd[i], expected_n)
        np.testing.assert_array_equal(Td[i], expected_t)


def test_contact_rows_inclined():
    angle = 30.0
    S = two_blocks(nx=6, ny=2, angle=angle, cell="triangle")
    g = S.geometry
    c, s = np.cos(np.radians(angle)), np.sin(np.radians(angle))
    n = np.array([s, -c])  # (0, -1) rotated by +30 degrees
    t = np.array([c, s])
    np.testing.assert_allclose(g.normals, np.tile(n, (S.m, 1)), atol=1e-14)
    np.testing.assert_allclose(g.tangents, np.tile(t, (S.m, 1)), atol=1e-14)
    # contact points along the inclined interface, ordered by arc length
    arc = g.contact_points @ t
    np.testing.assert_allclose(arc, 0.5 * np.arange(1, 7), atol=1e-12)
    np.testing.assert_allclose(g.contact_points @ n, 0.0, atol=1e-14)
    N, T = S.contact_maps()
    for i, (a, b) in enumerate(g.contact_nodes):
        row = N.getrow(i).toarray().ravel()
        assert row[dof(S, a, 0)] == pytest.approx(n[0]) and row[dof(S, a, 1)] == pytest.approx(n[1])
        assert row[dof(S, b, 0)] == pytest.approx(-n[0]) and row[dof(S, b, 1)] == pytest.approx(-n[1])
        assert np.count_nonzero(row) == 4
        trow = T.getrow(i).toarray().ravel()
        assert trow[dof(S, a, 0)] == pytest.approx(t[0]) and trow[dof(S, b, 1)] == pytest.approx(-t[1])


def test_rotation_covariance():
    """K, N, f of the rotated assembly are the rotated ones of the flat assembly."""
    angle = 30.0
    flat = two_blocks(nx=5, ny=2, cell="triangle", body_force1=(1e6, -3e6))
    rot = two_blocks(nx=5, ny=2, cell="triangle", body_force1=(1e6, -3e6), angle=angle)
    K0, N0, T0, f10, f20 = flat.to_scipy()
    K1, N1, T1, f11, f21 = rot.to_scipy()
    np.testing.assert_array_equal(flat.geometry.dof_node, rot.geometry.dof_node)
    c, s = np.cos(np.radians(angle)), np.sin(np.radians(angle))
    R = sp.block_diag([np.array([[c, -s], [s, c]])] * (flat.n // 2)).tocsr()
    scale = abs(K0).max()
    assert abs(R @ K0 @ R.T - K1).max() < 1e-11 * scale
    assert abs(N0 @ R.T - N1).max() < 1e-13
    assert abs(T0 @ R.T - T1).max() < 1e-13
    np.testing.assert_allclose(R @ f10, f11, atol=1e-12 * abs(f10).max())
    np.testing.assert_allclose(R @ f20, f21, atol=1e-12 * abs(f20).max())


# ------------------------------------------------------------------ stiffness
def test_stiffness_spd_symmetric():
    for cell in ("quadrilateral", "triangle"):
        S = two_blocks(nx=6, ny=3, cell=cell)
        K = S.to_scipy()[0]
        assert abs(K - K.T).max() == 0.0
        w = scipy.linalg.eigvalsh(K.toarray())
        assert w[0] > 1e-8 * w[-1]


def _D(plane):
    if plane == "strain":
        f = E / ((1 + NU) * (1 - 2 * NU))
        return f * np.array([[1 - NU, NU, 0], [NU, 1 - NU, 0], [0, 0, (1 - 2 * NU) / 2]])
    f = E / (1 - NU ** 2)
    return f * np.array([[1, NU, 0], [NU, 1, 0], [0, 0, (1 - NU) / 2]])


def _B(dN):
    """Strain-displacement matrix (exx, eyy, gamma_xy) for DOFs (u0x, u0y, u1x, ...)."""
    B = np.zeros((3, 2 * dN.shape[0]))
    B[0, 0::2] = dN[:, 0]
    B[1, 1::2] = dN[:, 1]
    B[2, 0::2] = dN[:, 1]
    B[2, 1::2] = dN[:, 0]
    return B


def _q1_unit_square(plane):
    """B^T D B of the unit square, nodes (0,0), (1,0), (1,1), (0,1), 2x2 Gauss (exact)."""
    xi = np.array([0.5 - 0.5 / np.sqrt(3), 0.5 + 0.5 / np.sqrt(3)])
    D = _D(plane)
    K = np.zeros((8, 8))
    for x in xi:
        for y in xi:
            dN = np.array([[-(1 - y), -(1 - x)], [1 - y, -x], [y, x], [-y, 1 - x]])
            B = _B(dN)
            K += 0.25 * B.T @ D @ B
    return K


def _p1_triangle(xy, plane):
    (x1, y1), (x2, y2), (x3, y3) = xy
    area2 = (x2 - x1) * (y3 - y1) - (x3 - x1) * (y2 - y1)
    dN = np.array([[y2 - y3, x3 - x2], [y3 - y1, x1 - x3], [y1 - y2, x2 - x1]]) / area2
    B = _B(dN)
    return 0.5 * abs(area2) * B.T @ _D(plane) @ B


def _one_cell_full_stiffness(cell, plane):
    with compat.gmsh_model("one-cell"):
        geo().build(nx=1, ny=1, length=1.0, height=1.0, cell=cell)
        import gmsh

        return full_stiffness(gmsh.model, E=E, nu=NU, plane=plane)


@pytest.mark.parametrize("plane", ["strain", "stress"])
def test_one_quadrilateral_against_hand_computation(plane):
    K, points, cells, body = _one_cell_full_stiffness("quadrilateral", plane)
    Kref = _q1_unit_square(plane)
    # body 1 = the unit square: find its nodes by coordinates
    corners = [(0, 0), (1, 0), (1, 1), (0, 1)]
    body1_nodes = np.unique(cells[body == 1])
    nodes = [int(body1_nodes[np.argmin(np.hypot(*(points[body1_nodes] - c).T))]) for c in corners]
    dofs = np.ravel([[2 * v, 2 * v + 1] for v in nodes])
    Kd = K.toarray()
    np.testing.assert_allclose(Kd[np.ix_(dofs, dofs)], Kref, rtol=0, atol=1e-12 * abs(Kref).max())
    # block diagonal: body 1 does not couple to body 2 (separate interface nodes)
    others = np.setdiff1d(np.arange(K.shape[0]), dofs)
    assert abs(Kd[np.ix_(dofs, others)]).max() == 0.0
    # rigid motions are in the kernel of the free (unclamped) element
    lam, mu = lame_parameters(E, NU, plane)
    assert mu == pytest.approx(E / (2 * (1 + NU)))


@pytest.mark.parametrize("plane", ["strain", "stress"])
def test_two_triangles_against_hand_computation(plane):
    K, points, cells, body = _one_cell_full_stiffness("triangle", plane)
    assert cells.shape == (4, 3)
    Kref = np.zeros(K.shape)
    for tri in cells:
        Ke = _p1_triangle(points[tri], plane)
        dofs = np.ravel([[2 * v, 2 * v + 1] for v in tri])
        Kref[np.ix_(dofs, dofs)] += Ke
    np.testing.assert_allclose(K.toarray(), Kref, rtol=0, atol=1e-12 * abs(Kref).max())


# ---------------------------------------------------------------------- loads
@pytest.mark.parametrize("cell", ["quadrilateral", "triangle"])
def test_total_traction_load(cell):
    tx, ty, qx, qy = 3.0e6, -2.0e6, 5.0e5, 7.0e5
    S = two_blocks(nx=6, ny=3, length=3.0, height=1.0, cell=cell,
                   tractions1={"right1": (tx, ty)}, tractions2={23: (qx, qy), "top1": (0.0, -1.0)})
    f1, f2 = S.loads_numpy()
    comp = S.geometry.dof_comp
    # right edges have length 1 and no clamped node
    assert f1[comp == 0].sum() == pytest.approx(tx * 1.0, rel=1e-12)
    assert f1[comp == 1].sum() == pytest.approx(ty * 1.0, rel=1e-12)
    # f2: right2 fully + top1 minus the share of its clamped corner node (h/2 of length 3 - h)
    assert f2[comp == 0].sum() == pytest.approx(qx, rel=1e-12)
    assert f2[comp == 1].sum() == pytest.approx(qy - 1.0 * (3.0 - 0.25), rel=1e-12)
    # the traction on right1 goes to body-1 nodes on x = 3 only
    pts = S.geometry.points[S.geometry.dof_node]
    assert np.all(np.isclose(pts[f1 != 0, 0], 3.0))


@pytest.mark.parametrize("cell", ["quadrilateral", "triangle"])
def test_windowed_traction_load(cell):
    """A traction on a window of a piece equals the hand-made nodal load (value x edge length / 2
    on both ends of every edge inside the window); windows covering the piece add up to the
    uniform traction; the metadata lists the windows."""
    t, q = np.array([2.0e5, -3.0e5]), np.array([-1.0e5, 4.0e5])
    S = two_blocks(nx=6, ny=3, length=3.0, height=1.0, cell=cell,
                   tractions1={"top1": {"value": t, "x": (1.5, 2.5)}, "right2": {"value": q, "y": (-0.6667, 0.0)}},
                   tractions2={"top1": [{"value": t, "x": (0.0, 1.5)}, {"value": t, "x": (1.5, 3.0)}]})
    U = two_blocks(nx=6, ny=3, length=3.0, height=1.0, cell=cell, tractions1={"top1": t}, tractions2={})
    f1, f2 = S.loads_numpy()
    g = S.geometry
    ref = np.zeros(S.n)
    for y_edge, x_edge, lo, hi, val in ((1.0, None, 1.5, 2.5, t), (None, 3.0, -0.6667, 0.0, q)):
        P = g.points
        on = np.flatnonzero(np.isclose(P[:, 1], y_edge) if y_edge is not None else np.isclose(P[:, 0], x_edge))
        if x_edge is not None:  # right2: the nodes of body 2 only (y <= 0)
            on = on[np.isin(on, np.unique(g.cells[g.cell_body == 2]))]
        along = P[on, 0] if y_edge is not None else P[on, 1]
        on = on[np.argsort(along)]
        along = np.sort(along)
        for a, b, sa, sb in zip(on[:-1], on[1:], along[:-1], along[1:]):
            if sa >= lo - 1e-9 and sb <= hi + 1e-9:  # (gmsh coordinates: 1.5 may be 1.5 - 1e-16)
                for node in (a, b):
                    for c in (0, 1):
                        ref[(g.dof_node == node) & (g.dof_comp == c)] += 0.5 * val[c] * (sb - sa)
    np.testing.assert_allclose(f1, ref, rtol=0, atol=1e-9 * np.abs(ref).max())
    np.testing.assert_allclose(f2, U.loads_numpy()[0], rtol=0, atol=1e-9 * np.abs(f2).max())
    assert S.info["tractions1"]["top1=12"] == [{"value": t.tolist(), "x": [1.5, 2.5]}]
    assert S.info["tractions1"]["right2=23"] == [{"value": q.tolist(), "y": [-0.6667, 0.0]}]


def test_windowed_traction_errors():
    for bad, match in (({"top1": {"value": (1.0, 0.0)}}, "needs 'x'"),
                       ({"top1": {"value": (1.0, 0.0), "x": (2.0, 1.0)}}, "lo < hi"),
                       ({"top1": {"value": (1.0, 0.0), "z": (0.0, 1.0)}}, "keys"),
                       ({"top1": {"x": (0.0, 1.0)}}, "keys"),
                       ({"top1": [{"value": (1.0, 0.0), "x": (0.0, 1.0)}, (1.0, 2.0, 3.0)]}, r"\[1\].*2-vector")):
        with pytest.raises(InputError, match=match):
            two_blocks(nx=2, ny=1, tractions1=bad)
    with pytest.raises(InputError, match="angle"):
        two_blocks(nx=2, ny=1, angle=30.0, tractions1={"top1": {"value": (1.0, 0.0), "x": (0.0, 1.0)}})


def test_body_force_load():
    b = np.array([2.0e5, -3.0e5])
    S = two_blocks(nx=6, ny=3, length=3.0, height=1.0, tractions1={}, tractions2={},
                   body_force1={"body2": b}, body_force2=b)
    f1, f2 = S.loads_numpy()
    g = S.geometry
    comp, node = g.dof_comp, g.dof_node
    hx, H, L = 0.5, 1.0, 3.0
    # Q1, uniform grid: the clamped left column of nodes takes hx * H / 2 of the area
    free_area = L * H - hx * H / 2
    on2 = np.isin(node, np.unique(g.cells[g.cell_body == 2]))
    for k in range(2):
        assert f1[comp == k].sum() == pytest.approx(b[k] * free_area, rel=1e-12)
        assert np.all(f1[~on2] == 0)
        assert f2[comp == k].sum() == pytest.approx(2 * b[k] * free_area, rel=1e-12)


# ------------------------------------------------------------ other inputs
def test_rigid_foundation():
    S = two_blocks(nx=6, ny=2, foundation=True)
    g = S.geometry
    assert S.m == 6 and np.all(g.contact_nodes[:, 1] == -1)
    assert np.all(g.cell_body == 1)
    N = S.contact_maps()[0].toarray()
    for i, (a, _) in enumerate(g.contact_nodes):
        expected = np.zeros(S.n)
        expected[dof(S, a, 1)] = -1.0
        np.testing.assert_array_equal(N[i], expected)


@pytest.mark.slow
def test_msh_file_matches_model(tmp_path):
    path = tmp_path / "blocks.msh"
    subprocess.run([sys.executable, "-m", "cfcontact.meshes.two_blocks", str(path),
                    "--nx", "5", "--ny", "2", "--cell", "triangle"], check=True)
    kw = dict(tractions1={"top1": (1.0, -2.0)}, tractions2={"right2": (0.5, 0.0)}, friction=0.4)
    A = assemble_contact_system(str(path), **kw)
    B = two_blocks(nx=5, ny=2, cell="triangle", **kw)
    for X, Y in zip(A.to_scipy(), B.to_scipy()):
        X = X.toarray() if sp.issparse(X) else X
        Y = Y.toarray() if sp.issparse(Y) else Y
        # the .msh file stores coordinates in decimal: agreement up to rounding
        np.testing.assert_allclose(X, Y, rtol=0, atol=1e-12 * np.abs(Y).max())
    np.testing.assert_array_equal(A.geometry.cells, B.geometry.cells)
    assert A.friction == 0.4 and A.rho == pytest.approx(B.rho, rel=1e-12)


def test_a_msh_with_node_numbers_with_gaps_in_the_plane_z_half(tmp_path):
    """A valid MSH 2.2 file whose node numbers run 2, 4, 6, ... and whose nodes lie in the plane
    z = 0.5 (a mesh written by another tool): renumbered as it is read and taken in its plane; the
    same system as the file numbered 1..N in z = 0.  Nodes off one plane are still refused."""
    import gmsh

    original = tmp_path / "blocks.msh"
    with compat.gmsh_model("blocks"):
        geo().build(nx=5, ny=2, cell="triangle")
        gmsh.option.setNumber("Mesh.MshFileVersion", 2.2)
        gmsh.write(str(original))
    lines = original.read_text().splitlines()
    out, section, count = [], None, 0
    for line in lines:
        if line.startswith("$"):
            section, count = line, 0
            out.append(line)
            continue
        count += 1
        words = line.split()
        if section == "$Nodes" and count > 1:
            words = [str(2 * int(words[0])), words[1], words[2], str(float(words[3]) + 0.5)]
        elif section == "$Elements" and count > 1:
            k = 3 + int(words[2])
            words = words[:k] + [str(2 * int(w)) for w in words[k:]]
        out.append(" ".join(words))
    moved = tmp_path / "moved.msh"
    moved.write_text("\n".join(out) + "\n")
    kw = dict(tractions1={"top1": (1.0, -2.0)}, friction=0.4)
    A, B = assemble_contact_system(str(moved), **kw), assemble_contact_system(str(original), **kw)
    for X, Y in zip(A.to_scipy(), B.to_scipy()):
        X = X.toarray() if sp.issparse(X) else X
        Y = Y.toarray() if sp.issparse(Y) else Y
        np.testing.assert_allclose(X, Y, rtol=0, atol=1e-12 * np.abs(Y).max())
    tilted = tmp_path / "tilted.msh"
    tilted.write_text(moved.read_text().replace(" 0.5\n", " 0.5000001\n", 1))
    with pytest.raises(GeometryError, match="the mesh is not planar: its nodes' z runs from 0.5 to 0.5"):
        assemble_contact_system(str(tilted), **kw)


def test_material_per_body():
    """The bodies share no nodes, so K is block diagonal by body: each block must equal the block of a
    one-material model with that body's E and nu."""
    kw = dict(nx=4, ny=2, cell="triangle")
    mixed = two_blocks(E={"body1": 2.0e11, 2: 5.0e9}, nu={"body1": 0.3, "body2": 0.45}, **kw)
    one = two_blocks(E=2.0e11, nu=0.3, **kw)
    two = two_blocks(E=5.0e9, nu=0.45, **kw)
    Km, Ko, Kt = (s.to_scipy()[0].toarray() for s in (mixed, one, two))
    # DOFs of body 1: rows with a coupling to a body-1 contact node's DOF; use the rows where one == mixed
    g = mixed.geometry
    nodes1 = np.unique(g.cells[g.cell_body == 1])
    b1 = np.flatnonzero(np.isin(g.dof_node, nodes1))
    b2 = np.flatnonzero(~np.isin(g.dof_node, nodes1))
    assert b1.size and b2.size
    np.testing.assert_array_equal(Km[np.ix_(b1, b2)], 0.0)
    np.testing.assert_allclose(Km[np.ix_(b1, b1)], Ko[np.ix_(b1, b1)], rtol=0, atol=1e-12 * np.abs(Ko).max())
    np.testing.assert_allclose(Km[np.ix_(b2, b2)], Kt[np.ix_(b2, b2)], rtol=0, atol=1e-12 * np.abs(Kt).max())
    assert mixed.info["E"] == {"body1=1": 2.0e11, "body2=2": 5.0e9}
    # every body needs a value; unknown bodies are named
    with pytest.raises(GeometryError, match="body2=2"):
        two_blocks(nx=2, ny=1, E={"body1": 1e9})
    with pytest.raises(GeometryError, match="'body3'"):
        two_blocks(nx=2, ny=1, nu={"body1": 0.3, "body2": 0.3, "body3": 0.3})
    with pytest.raises(InputError, match=r"nu\['body2'\]"):
        two_blocks(nx=2, ny=1, nu={"body1": 0.3, "body2": 0.6})


# ----------------------------------------------------------------- bad input
def test_unknown_tag_lists_valid_tags():
    with pytest.raises(GeometryError) as exc:
        two_blocks(nx=3, ny=1, clamp=("left1", "nope"))
    assert "'nope'" in str(exc.value) and "left2=24" in str(exc.value) and "top1=12" in str(exc.value)
    with pytest.raises(GeometryError, match="99"):
        two_blocks(nx=3, ny=1, tractions1={99: (1.0, 0.0)})
    with pytest.raises(GeometryError, match="body1=1"):
        two_blocks(nx=3, ny=1, body_force1={"body7": (1.0, 0.0)})


def test_non_matching_interface():
    with pytest.raises(GeometryError) as exc:
        two_blocks(nx=4, ny=1, nx2=5)
    msg = str(exc.value)
    assert "non-matching" in msg
    # contact1 node (0.75, 0): nearest contact2 node is (0.6, 0) -> distance 0.15
    assert "(0.75, 0)" in msg and "distance 0.15" in msg


def test_body_without_dirichlet_condition():
    with pytest.raises(InputError) as exc:
        two_blocks(nx=3, ny=1, clamp=("left1",))
    msg = str(exc.value)
    assert "body 2" in msg and "Dirichlet" in msg and "left2=24" in msg
    with pytest.raises(InputError, match="body 1"):
        two_blocks(nx=3, ny=1, clamp=("bottom2",))


def test_bad_material_and_loads():
    with pytest.raises(InputError, match="plane"):
        two_blocks(nx=2, ny=1, plane="axisymmetric")
    with pytest.raises(InputError, match="Poisson"):
        two_blocks(nx=2, ny=1, nu=0.5)
    with pytest.raises(InputError, match="2-vector"):
        two_blocks(nx=2, ny=1, tractions1={"top1": (1.0, 2.0, 3.0)})
    with pytest.raises(InputError, match="nx"):
        two_blocks(nx=0)
    with pytest.raises(GeometryError, match="no such mesh file"):
        assemble_contact_system("/nonexistent/blocks.msh")


# ----------------------------------------------------------------------- MPI
@pytest.mark.mpi
def test_mpi_matches_serial(tmp_path, run_mpi):
    sys.path.insert(0, HERE)
    try:
        import mpi_assembly_script as script
    finally:
        sys.path.remove(HERE)
    out = tmp_path / "mpi.npz"
    run_mpi(2, os.path.join(HERE, "mpi_assembly_script.py"), str(out), timeout=300)
    par = np.load(out)
    assert int(par["size"]) == 2
    for name, kwargs in script.cases().items():
        owned = par[f"{name}:owned_cells"]
        assert np.all(owned > 0), f"{name}: a rank owns no cell ({owned}), the test would not test MPI"
        assert par[f"{name}:row_ranges"].tolist()[1] not in (0, par[f"{name}:K"].shape[0])
        serial = script.gathered(two_blocks(**kwargs))
        for key, ref in serial.items():
            got = par[f"{name}:{key}"]
            assert got.shape == ref.shape, (name, key)
            if ref.dtype.kind == "U":  # geometry_material: the material as JSON text
                assert str(got) == str(ref), (name, key)
                continue
            scale = max(np.abs(ref).max(), 1e-300) if ref.size else 1.0
            assert np.abs(got - ref).max(initial=0.0) <= 1e-12 * scale, (name, key)


# ------------------------------------------------------------ users' own meshes
def _rect(geo_, x0, y0, x1, y1, nx, ny, structured=True):
    """A rectangle in the current gmsh model, nx x ny cells along its edges (a structured mesh
    unless ``structured`` is False): (surface, [bottom, right, top, left])."""
    p = [geo_.addPoint(x, y, 0.0) for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))]
    lines = [geo_.addLine(p[i], p[(i + 1) % 4]) for i in range(4)]
    surface = geo_.addPlaneSurface([geo_.addCurveLoop(lines)])
    for line, k in zip(lines, (nx, ny, nx, ny)):
        geo_.mesh.setTransfiniteCurve(line, k + 1)
    if structured:
        geo_.mesh.setTransfiniteSurface(surface)
    _rect.points = p  # (its corners, for parts joined to it)
    return surface, lines


def _groups(model, groups):
    for (dim, num), (name, tags) in groups.items():
        model.addPhysicalGroup(dim, tags, num)
        if name:
            model.setPhysicalName(dim, num, name)


def _user_blocks(model, variant):
    """Two 3 x 1 blocks (body1 on top, 6 x 2 triangles each) as a user might mesh them:
    "shared" (the bodies share the interface line and its nodes), "embedded" (a line inside body1,
    group 16 "inner1"), "split" / "split-float" (body1 two rectangles with coinciding but distinct
    nodes at y = 0.5, both held or only the upper one)."""
    geo_ = model.geo
    s2, (b2, r2, t2, l2) = _rect(geo_, 0.0, -1.0, 3.0, 0.0, 6, 2)
    if variant == "shared":  # body1's bottom is body2's top line t2, from (3, 0) (point 3) to (0, 0) (point 4)
        p = [geo_.addPoint(x, y, 0.0) for x, y in ((3.0, 1.0), (0.0, 1.0))]
        r1, top, l1 = geo_.addLine(3, p[0]), geo_.addLine(p[0], p[1]), geo_.addLine(p[1], 4)
        s1 = geo_.addPlaneSurface([geo_.addCurveLoop([-t2, r1, top, l1])])
        for line, k in ((r1, 2), (top, 6), (l1, 2)):
            geo_.mesh.setTransfiniteCurve(line, k + 1)
        geo_.mesh.setTransfiniteSurface(s1)
        bodies1, contact1, tops, lefts = [s1], [t2], [top], [l1]
    elif variant.startswith("split"):
        s1, (c1, r1, _, l1) = _rect(geo_, 0.0, 0.0, 3.0, 0.5, 6, 1)
        s1b, (_, r1b, top, l1b) = _rect(geo_, 0.0, 0.5, 3.0, 1.0, 6, 1)
        bodies1, contact1, tops, lefts = [s1, s1b], [c1], [top], [l1b] if variant == "split-float" else [l1, l1b]
    else:  # (an embedded curve needs an unstructured mesh: a transfinite one ignores it)
        s1, (c1, r1, top, l1) = _rect(geo_, 0.0, 0.0, 3.0, 1.0, 6, 2, structured=variant != "embedded")
        bodies1, contact1, tops, lefts = [s1], [c1], [top], [l1]
        corner_right, corner_left = _rect.points[2], _rect.points[3]
    if variant in ("bonded", "hinged"):  # part 3: a layer on body1's top (bonded along it) or a flap at one corner
        if variant == "bonded":
            q = [geo_.addPoint(x, 1.2, 0.0) for x in (3.0, 0.0)]
            lines = [geo_.addLine(corner_right, q[0]), geo_.addLine(q[0], q[1]), geo_.addLine(q[1], corner_left)]
            loop = [-top] + lines
            tops = [lines[1]]
        else:
            q = [geo_.addPoint(x, y, 0.0) for x, y in ((3.5, 1.0), (3.5, 1.5), (3.0, 1.5))]
            lines = [geo_.addLine(corner_right, q[0]), geo_.addLine(q[0], q[1]), geo_.addLine(q[1], q[2]),
                     geo_.addLine(q[2], corner_right)]
            loop = lines
        part = geo_.addPlaneSurface([geo_.addCurveLoop(loop)])
        geo_.mesh.setTransfiniteCurve(lines[1], 7 if variant == "bonded" else 2)
    groups = {(2, 1): ("body1", bodies1), (2, 2): ("body2", [s2]), (1, 10): ("contact1", contact1),
              (1, 20): ("contact2", [t2]), (1, 12): ("top1", tops), (1, 14): ("left1", lefts),
              (1, 22): ("bottom2", [b2])}
    if variant in ("bonded", "hinged"):
        groups[(2, 3)] = ("part3", [part])
    if variant in ("embedded", "drawn"):  # a line inside body1: embedded in its mesh, or only drawn over it
        a, b = geo_.addPoint(0.5, 0.5, 0.0), geo_.addPoint(2.5, 0.5, 0.0)
        inner = geo_.addLine(a, b)
        geo_.mesh.setTransfiniteCurve(inner, 5)
        geo_.synchronize()
        if variant == "embedded":
            model.mesh.embed(1, [inner], 2, bodies1[0])
        groups[(1, 16)] = ("inner1", [inner])
    geo_.synchronize()
    _groups(model, groups)
    model.mesh.generate(2)


def _assemble_user(variant, **kw):
    kw = {"clamp": ("left1", "bottom2"), "tractions1": {"top1": (0.0, -1e6)}, "tractions2": {}, **kw}
    with compat.gmsh_model(variant) as model:
        _user_blocks(model, variant)
        return assemble_contact_system(model, **kw)


def test_bodies_meshed_with_shared_interface_nodes_are_refused():
    """Bodies meshed as one coherent geometry share their interface nodes: they would be glued
    there.  Named as such, not as a contact boundary off its body."""
    with pytest.raises(GeometryError, match=r"body1 and body2 share 7 mesh node\(s\).*glued.*its own nodes"):
        _assemble_user("shared")


def test_tractions_and_contact_on_a_line_inside_a_body_are_refused():
    """A 1-D group embedded in a body has a cell on both sides of each facet: a traction there
    would be dropped (boundary integrals only) and a contact boundary there has no outside."""
    with pytest.raises(GeometryError, match=r"tractions1: inner1=16 \(1-D group\) lies inside a body \(4 of its 4"):
        _assemble_user("embedded", tractions1={"inner1": (0.0, -1e6)})
    system = _assemble_user("embedded", dirichlet={"inner1": {"x": 0.0}})  # (a support inside a body is fine)
    assert system.m == 7
    # a line drawn over the surface but not embedded: its elements are no cell's edges (dolfinx aborted)
    with pytest.raises(GeometryError, match=r"4 line element\(s\) of the 1-D group inner1=16 are no edge of any 2-D "
                                            r"cell.*embed"):
        _assemble_user("drawn")


def test_a_body_of_two_unjoined_pieces():
    """Body 1 meshed as two rectangles that share no node (coinciding nodes at y = 0.5): with both
    pieces held it is built, with a MeshWarning naming the coinciding nodes; with the lower piece
    free the error names that piece, not the body, and the coinciding nodes."""
    from cfcontact.errors import MeshWarning

    with pytest.warns(MeshWarning, match=r"body 1 \(body1\) is made of 2 pieces that share no edge; nodes of "
                                         r"different pieces coincide at 7 point\(s\), e.g. \(0, 0.5\)"):
        system = _assemble_user("split")
    assert system.m == 7
    with pytest.raises(InputError, match=r"the part of body 1 \(body1\) within x in \[0, 3\], y in \[0, 0.5\] .*"
                                         r"coincide .* has no Dirichlet condition"):
        _assemble_user("split-float")


def test_a_bonded_part_moves_with_its_body_and_a_hinged_one_is_free():
    """A 2-D group of another material meshed onto body1's top (sharing its edge and nodes) is held
    by body1's supports: built, K positive definite (it had been refused for want of a clamp of
    its own); one that touches body1 at a single node turns about it: refused naming the pivot."""
    system = _assemble_user("bonded", E={"body1": 2e11, "body2": 2e11, "part3": 7e10})
    K = system.to_scipy()[0].toarray()
    assert np.linalg.eigvalsh(K).min() > 1e-9 * np.abs(K).max()
    assert sorted(np.unique(system.geometry.cell_body).tolist()) == [1, 2, 3]
    with pytest.raises(InputError, match=r"body 3 \(part3\) can rotate about \(3, 1\)"):
        _assemble_user("hinged", tractions1={})


def test_supports_that_leave_a_rigid_motion_free_are_named():
    """x held on a horizontal edge and y on a vertical one leave the rotation about their meeting
    point free (K singular: it had reached the solvers as a factorization breakdown)."""
    with pytest.raises(InputError, match=r"body 1 \(body1\) can rotate about \(0, 0.5\)"):
        two_blocks(nx=3, ny=1, length=2.0, height=0.5, clamp=("left2",), dirichlet={"top1": {"x": 0.0},
                                                                                        "left1": {"y": 0.0}})
    with pytest.raises(InputError, match=r"body 1 \(body1\) can move freely in y"):
        two_blocks(nx=3, ny=1, clamp=("left2",), dirichlet={"left1": {"x": 0.0}})
    assert two_blocks(nx=3, ny=1, clamp=("left2",), dirichlet={"left1": {"x": 0.0}, "top1": {"y": 0.0}}).m == 4


def _renamed(renames, **kw):
    with compat.gmsh_model("renamed") as model:
        geo().build(nx=3, ny=1, cell="triangle")
        for dim, num in renames:  # (gmsh keeps a name on its group until it is removed)
            model.removePhysicalName(model.getPhysicalName(dim, num))
        for (dim, num), name in renames.items():
            model.setPhysicalName(dim, num, name)
        return assemble_contact_system(model, **kw)


def test_the_tag_convention_is_read_by_number_and_contradicting_names_are_refused():
    """Bodies named against their numbers (body1 on 2) would take one body's material by name and
    the other's geometry by number: refused naming the group.  A convention number with a name of
    its own ("interface" on 10, "Contact2" on 20) is that convention group."""
    with pytest.raises(GeometryError, match=r"physical group 1 \(2-D\) is named 'body2', but the tag convention has "
                                            r"body2=2"):
        _renamed({(2, 1): "body2", (2, 2): "body1"}, E={"body1": 2e11, "body2": 2e8})
    system = _renamed({(1, 10): "interface", (1, 20): "Contact2"})
    assert system.m == _renamed({}).m == 3 and system.info["contact"]["slave"] == "interface=10"
    from cfcontact.report import contact_report

    assert contact_report(system=system)["master"] == "Contact2=20"


def test_a_3d_mesh_is_refused_as_3d():
    with compat.gmsh_model("box") as model:
        box = model.occ.addBox(0, 0, 0, 1, 1, 1)
        model.occ.synchronize()
        model.addPhysicalGroup(3, [box], 1)
        model.setPhysicalName(3, 1, "body1")
        model.mesh.generate(3)
        with pytest.raises(GeometryError, match=r"the mesh is 3-D \(3-D physical groups: body1=1\).*2-D mesh"):
            assemble_contact_system(model)


def test_a_cell_of_zero_area_is_named():
    """Three collinear nodes make a cell without stiffness (its K entries inf/nan, which had been
    blamed on E): refused naming the cell's corners."""
    with compat.gmsh_model("flat") as model:
        surface = model.addDiscreteEntity(2)
        line = model.addDiscreteEntity(1)
        xy = [(0, 0), (1, 0), (1, 1), (0, 1), (0.5, 1.0)]
        model.mesh.addNodes(2, surface, list(range(1, 6)), [c for x, y in xy for c in (x, y, 0.0)])
        model.mesh.addElementsByType(surface, 2, [], [1, 2, 5, 1, 5, 4, 2, 3, 5, 4, 5, 3])  # (the last: flat)
        model.mesh.addElementsByType(line, 1, [], [1, 2])
        _groups(model, {(2, 1): ("body1", [surface]), (1, 10): ("contact1", [line])})
        with pytest.raises(GeometryError, match=r"1 cell\(s\) of \(nearly\) zero area.*corners \(0, 1\); \(0.5, 1\); "
                                                r"\(1, 1\)"):
            assemble_contact_system(model, clamp=(), dirichlet=None)


def test_a_boolean_tag_and_a_piece_given_two_values_are_refused():
    """A boolean where a tag goes, and a dirichlet that gives one piece two values for one
    component (by name and by number): each refused naming the tag and what would do; the same
    value given twice is one condition."""
    with pytest.raises(GeometryError, match=r"unknown boundary piece \(1-D physical group\) True in clamp; valid 1-D "
                                            r"physical groups: .*left1=14"):
        _renamed({}, clamp=(True,))
    with pytest.raises(InputError, match=r"dirichlet gives top1=12 two values for y"):
        _renamed({}, clamp=("bottom2",), dirichlet={"top1": {"x": 0.0, "y": -0.01}, 12: {"y": -0.02}})
    same = _renamed({}, clamp=("bottom2",), dirichlet={"top1": {"x": 0.0, "y": -0.01}, 12: {"y": -0.01}})
    once = _renamed({}, clamp=("bottom2",), dirichlet={"top1": {"x": 0.0, "y": -0.01}})
    assert same.n == once.n and np.array_equal(same.loads_numpy()[1], once.loads_numpy()[1])


def test_loads_of_booleans_or_strings_are_refused():
    """A traction or body force of a boolean or of number strings is refused naming it (float()
    would have taken True as 1 and "1e6" as a number: E = True is refused already)."""
    for kw, words in (({"tractions1": {"top1": (True, -1e7)}}, "tractions1['top1']"),
                      ({"tractions1": {"top1": ("1e6", "-1e7")}}, "tractions1['top1']"),
                      ({"body_force1": (True, 1.0)}, "body_force1"),
                      ({"tractions1": {"top1": {"value": (0.0, "1"), "x": (0.0, 1.0)}}}, "tractions1['top1']['value']")):
        with pytest.raises(InputError, match=r"must be a 2-vector \(x, y\) of numbers, got") as exc:
            two_blocks(nx=2, ny=1, **kw)
        assert words in str(exc.value), (words, str(exc.value))
    ok = two_blocks(nx=2, ny=1, tractions1={"top1": (np.float32(1e6), np.int64(-10 ** 7))})
    ref = two_blocks(nx=2, ny=1, tractions1={"top1": (1e6, -1e7)})
    np.testing.assert_array_equal(ok.loads_numpy()[0], ref.loads_numpy()[0])
