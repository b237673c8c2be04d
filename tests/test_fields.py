"""Derived fields (cfcontact.fields): von Mises stress against analytic references, XDMF output read back
by independent readers (xml.etree, dolfinx, VTK's XDMF reader or meshio), and the CLI (render --stress,
export, [output] stress / xdmf)."""

import glob
import json
import os
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import cfcontact
from cfcontact import cli, fields
from cfcontact.errors import InputError
from cfcontact.path import SolutionPath
from cfcontact.ssnm import InactiveSets, Solution
from cfcontact.system import ContactGeometry

E_BODY = {"body1": 2.1e11, "body2": 7.0e10}
NU_BODY = {"body1": 0.3, "body2": 0.12}


# ------------------------------------------------------------------ models
@pytest.fixture(scope="module", params=["triangle", "quadrilateral"])
def system(request):
    """A real two_blocks mesh (coarse), one material per body, plane strain."""
    return cfcontact.two_blocks(nx=6, ny=3, height2=0.5, cell=request.param, E=E_BODY, nu=NU_BODY, friction=2.0)


def _all_free(geometry):
    """The same mesh with every node free (clamped nodes keep their displacement in a linear field)."""
    P = len(geometry.points)
    return ContactGeometry(**{**geometry.to_dict(), "dof_node": np.repeat(np.arange(P), 2),
                              "dof_comp": np.tile([0, 1], P)})


def _node_body(geometry):
    nb = np.zeros(len(geometry.points), dtype=int)
    for cell, body in zip(np.asarray(geometry.cells), np.asarray(geometry.cell_body)):
        cell = cell[cell >= 0]
        assert np.all((nb[cell] == 0) | (nb[cell] == body)), "a node shared by two bodies"
        nb[cell] = body
    return nb


def _reference_von_mises(A, E, nu, plane):
    """Textbook 3-D Hooke's law for the strain sym(A) (+ the out-of-plane condition), then sqrt(3/2 s:s)."""
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))
    eps = np.zeros((3, 3))
    eps[:2, :2] = 0.5 * (A + A.T)
    if plane == "stress":  # sigma_zz = 0  ->  eps_zz = -lam / (lam + 2 mu) (eps_xx + eps_yy)
        eps[2, 2] = -lam / (lam + 2 * mu) * (eps[0, 0] + eps[1, 1])
    sigma = lam * np.trace(eps) * np.eye(3) + 2 * mu * eps
    if plane == "stress":
        assert abs(sigma[2, 2]) <= 1e-9 * np.abs(sigma).max()
    s = sigma - np.trace(sigma) / 3 * np.eye(3)
    return np.sqrt(1.5 * np.sum(s * s))


# ------------------------------------------------------------------ von Mises
def test_material_is_stored_with_the_geometry(system):
    mat = system.geometry.material
    assert mat == {"E": {"body1=1": 2.1e11, "body2=2": 7.0e10}, "nu": {"body1=1": 0.3, "body2=2": 0.12},
                   "plane": "strain"}
    assert fields.material_of(system) == mat
    d = system.geometry.to_dict()  # an .npz-able dict: the material as JSON text, no pickling
    assert d["material"].dtype.kind == "U"
    assert ContactGeometry.from_dict(d).material == mat
    old = {k: v for k, v in d.items() if k != "material"}  # a path saved before the material was stored
    assert ContactGeometry.from_dict(old).material is None


@pytest.mark.parametrize("plane", ["strain", "stress"])
def test_von_mises_of_a_linear_field_is_exact(system, plane):
    """u = A_b x + c_b on each body b: every cell has the analytic von Mises stress of sym(A_b)."""
    geom = _all_free(system.geometry)
    material = {**system.geometry.material, "plane": plane}
    nb = _node_body(geom)
    rng = np.random.default_rng(5)
    A = {b: rng.normal(size=(2, 2)) * 1e-3 for b in (1, 2)}
    c = {b: rng.normal(size=2) * 1e-2 for b in (1, 2)}
    U = np.zeros_like(geom.points, dtype=float)
    for b in (1, 2):
        sel = nb == b
        U[sel] = geom.points[sel, :2] @ A[b].T + c[b]
    u = U[geom.dof_node, geom.dof_comp]
    vm = fields.von_mises(geom, u, material)
    names = {1: "body1", 2: "body2"}
    for b in (1, 2):
        ref = _reference_von_mises(A[b], E_BODY[names[b]], NU_BODY[names[b]], plane)
        got = vm[np.asarray(geom.cell_body) == b]
        assert got.size > 0
        np.testing.assert_allclose(got, ref, rtol=1e-10, atol=0)
    # the stress tensor too: plane strain sigma_zz = lambda tr(eps), plane stress 0
    s = fields.cell_stress(geom, u, material)
    b1 = np.asarray(geom.cell_body) == 1
    E, nu = E_BODY["body1"], NU_BODY["body1"]
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    expect_zz = lam * np.trace(A[1]) if plane == "strain" else 0.0
    np.testing.assert_allclose(s[b1, 2], expect_zz, rtol=1e-10, atol=1e-12 * np.abs(s).max())


def test_von_mises_rigid_motion_is_zero(system):
    geom = _all_free(system.geometry)
    theta = 1e-6
    R = np.array([[0.0, -theta], [theta, 0.0]])  # infinitesimal rotation: sym(R) = 0
    U = geom.points[:, :2] @ R.T + [1e-3, -2e-3]
    vm = fields.von_mises(geom, U[geom.dof_node, geom.dof_comp])
    assert np.abs(vm).max() <= 1e-9 * E_BODY["body1"] * theta


def test_quadrilateral_gradient_is_taken_at_the_cell_centre():
    """u_x = x y (bilinear, exact in Q1): grad u at the centre of a rectangle is (y_c, x_c)."""
    s = cfcontact.two_blocks(nx=5, ny=2, cell="quadrilateral", friction=0.0)
    geom = _all_free(s.geometry)
    P = geom.points[:, :2]
    U = np.column_stack([P[:, 0] * P[:, 1], np.zeros(len(P))])
    G = fields.displacement_gradients(geom, U[geom.dof_node, geom.dof_comp])
    centre = P[np.asarray(geom.cells)].mean(axis=1)
    np.testing.assert_allclose(G[:, 0, 0], centre[:, 1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(G[:, 0, 1], centre[:, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(G[:, 1], 0.0, atol=1e-15)


def test_von_mises_bad_input(system):
    geom = system.geometry
    n = len(geom.dof_node)
    with pytest.raises(InputError, match=f"shape \\({n - 1},\\).*expected \\({n},\\)"):
        fields.von_mises(geom, np.zeros(n - 1))
    with pytest.raises(InputError, match="'plain'"):
        fields.von_mises(geom, np.zeros(n), {**geom.material, "plane": "plain"})
    with pytest.raises(InputError, match="no value for body 2"):
        fields.von_mises(geom, np.zeros(n), {"E": {"body1": 1.0}, "nu": 0.3, "plane": "strain"})
    with pytest.raises(InputError, match="nu must lie in"):
        fields.von_mises(geom, np.zeros(n), {"E": 1.0, "nu": 0.5, "plane": "strain"})
    with pytest.raises(InputError, match="'steel'"):
        fields.von_mises(geom, np.zeros(n), {"E": {"steel": 1.0, 2: 1.0}, "nu": 0.3})
    with pytest.raises(InputError, match="material is unknown"):
        fields.von_mises(ContactGeometry(**{**geom.to_dict(), "material": None}), np.zeros(n))


# ------------------------------------------------------------------ XDMF
def _solutions(system, alphas=(0.2, 0.5, 0.9)):
    return [cfcontact.ssnm(system, a) for a in alphas]


def _data(item):
    dims = [int(d) for d in item.get("Dimensions").split()]
    typ = int if item.get("NumberType") == "Int" else float
    vals = np.array([typ(x) for x in item.text.split()])
    return vals.reshape(dims)


def _grids(fn):
    root = ET.parse(fn).getroot()
    coll = root.find("Domain/Grid")
    assert coll.get("GridType") == "Collection" and coll.get("CollectionType") == "Temporal"
    return coll.findall("Grid")


def _expected_node_fields(geom, sol):
    """contact_state / lam_n / lam_t per node, built by hand from the pairs."""
    code = {"open": 0, "stick": 1, "slip+": 2, "slip-": 3}
    P = len(geom.points)
    state, ln, lt = np.full(P, -1), np.zeros(P), np.zeros(P)
    for i, (a, b) in enumerate(np.asarray(geom.contact_nodes)):
        for node in (a, b):
            if node >= 0:
                state[node] = code[sol.states()[i]]
                ln[node], lt[node] = sol.lam_n[i], sol.lam_t[i]
    return state, ln, lt


def test_xdmf_attributes_equal_the_source_exactly(system, tmp_path):
    sols = _solutions(system)
    fn = fields.write_xdmf(tmp_path / "s.xdmf", system.geometry, sols)
    geom = system.geometry
    grids = _grids(fn)
    assert len(grids) == len(sols)
    k = geom.cells.shape[1]
    topo = grids[0].find("Topology")
    assert topo.get("TopologyType") == {3: "Triangle", 4: "Quadrilateral"}[k]
    np.testing.assert_array_equal(_data(topo.find("DataItem")), geom.cells)
    pts = _data(grids[0].find("Geometry/DataItem"))
    np.testing.assert_array_equal(pts[:, :2], geom.points[:, :2])
    np.testing.assert_array_equal(pts[:, 2], 0.0)
    for t, (grid, sol) in enumerate(zip(grids, sols)):
        assert float(grid.find("Time").get("Value")) == t
        info = grid.find("Information")
        assert info.get("Name") == "alpha" and float(info.get("Value")) == sol.alpha
        assert grid.get("Name") == fields.grid_name(t, sol.alpha) and repr(sol.alpha) in grid.get("Name")
        att = {a.get("Name"): (a.get("Center"), a.get("AttributeType"), _data(a.find("DataItem")))
               for a in grid.findall("Attribute")}
        assert set(att) == {"displacement", "contact_state", "lam_n", "lam_t", "contact_pressure", "contact_shear",
                            "body", "von_mises"}
        U = np.zeros((len(geom.points), 3))
        U[geom.dof_node, geom.dof_comp] = sol.u
        state, ln, lt = _expected_node_fields(geom, sol)
        expect = {"displacement": ("Node", "Vector", U), "contact_state": ("Node", "Scalar", state),
                  "lam_n": ("Node", "Scalar", ln), "lam_t": ("Node", "Scalar", lt),
                  "body": ("Cell", "Scalar", geom.cell_body),
                  "von_mises": ("Cell", "Scalar", fields.von_mises(geom, sol.u))}
        for name, (center, kind, values) in expect.items():
            assert att[name][:2] == (center, kind), name
            np.testing.assert_array_equal(att[name][2], values, err_msg=name)
        assert np.sum(state >= 0) == 2 * system.m  # both nodes of every pair
        # the tractions: on the slave nodes only; times the tributary lengths they give back the
        # contact forces, so their integral over the slave boundary is the total (no double count)
        slave = np.asarray(geom.contact_nodes)[:, 0]
        for name, lam in (("contact_pressure", sol.lam_n), ("contact_shear", sol.lam_t)):
            assert att[name][:2] == ("Node", "Scalar"), name
            values = att[name][2].ravel()
            np.testing.assert_allclose(values[slave] * geom.tributary, lam, rtol=1e-14, atol=0, err_msg=name)
            assert not np.any(np.delete(values, slave)), name
        assert np.sum(att["contact_pressure"][2].ravel()[slave] * geom.tributary) == pytest.approx(sol.lam_n.sum())
        assert sol.lam_n.max() > 0


def test_xdmf_read_by_dolfinx(system, tmp_path):
    """dolfinx (0.5 and 0.9 alike) reads the mesh grid of the file (XML data items, ASCII encoding)."""
    from mpi4py import MPI
    import dolfinx.io

    fn = fields.write_xdmf(tmp_path / "s.xdmf", system.geometry, _solutions(system, (0.3, 0.6)))
    name = fields.grid_name(0, 0.3)
    with dolfinx.io.XDMFFile(MPI.COMM_SELF, str(fn), "r", encoding=dolfinx.io.XDMFFile.Encoding.ASCII) as f:
        mesh = f.read_mesh(name=name, xpath="/Xdmf/Domain/Grid[@Name='solutions']")
    tdim = mesh.topology.dim
    assert mesh.topology.index_map(tdim).size_local == len(system.geometry.cells)
    assert mesh.geometry.x.shape[0] == len(system.geometry.points)
    assert mesh.topology.cell_type.name == ("triangle" if system.geometry.cells.shape[1] == 3 else "quadrilateral")
    got = np.sort(np.round(mesh.geometry.x[:, :2], 12), axis=0)
    np.testing.assert_array_equal(got, np.sort(np.round(system.geometry.points[:, :2], 12), axis=0))


def _read_with_vtk_or_meshio(fn, nsteps):
    """[(points, cell count, point arrays, cell arrays)] per time step, by VTK's XDMF reader or meshio."""
    try:
        from vtkmodules.util.numpy_support import vtk_to_numpy
        from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline as SDDP
        from vtkmodules.vtkIOXdmf2 import vtkXdmfReader
    except ImportError:
        vtkXdmfReader = None
    if vtkXdmfReader is not None:
        r = vtkXdmfReader()
        r.SetFileName(str(fn))
        r.UpdateInformation()
        times = r.GetOutputInformation(0).Get(SDDP.TIME_STEPS())
        assert list(times) == list(range(nsteps))
        out = []
        for t in times:
            r.UpdateTimeStep(t)
            g = r.GetOutputDataObject(0)
            pd, cd = g.GetPointData(), g.GetCellData()
            out.append((vtk_to_numpy(g.GetPoints().GetData()), g.GetNumberOfCells(),
                        {pd.GetArrayName(i): vtk_to_numpy(pd.GetArray(i)) for i in range(pd.GetNumberOfArrays())},
                        {cd.GetArrayName(i): vtk_to_numpy(cd.GetArray(i)) for i in range(cd.GetNumberOfArrays())}))
        return out
    meshio = pytest.importorskip("meshio", reason="neither VTK's vtkXdmfReader nor meshio is available")
    out = []
    with meshio.xdmf.TimeSeriesReader(str(fn)) as reader:
        points, cells = reader.read_points_cells()
        for k in range(reader.num_steps):
            t, pdata, cdata = reader.read_data(k)
            out.append((points, sum(len(c.data) for c in cells), pdata,
                        {k: np.concatenate(v) for k, v in cdata.items()}))
    return out


def test_xdmf_read_by_vtk_or_meshio(system, tmp_path):
    sols = _solutions(system)
    fn = fields.write_xdmf(tmp_path / "s.xdmf", system.geometry, sols)
    geom = system.geometry
    steps = _read_with_vtk_or_meshio(fn, len(sols))
    assert len(steps) == len(sols)
    for (pts, ncells, pdata, cdata), sol in zip(steps, sols):
        assert pts.shape == (len(geom.points), 3) and ncells == len(geom.cells)
        np.testing.assert_allclose(pts[:, :2], geom.points[:, :2], rtol=0, atol=1e-12)
        U = geom.displacement_field(sol.u)
        scale = np.abs(U).max()
        np.testing.assert_allclose(pdata["displacement"][:, :2], U, rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(pdata["lam_n"].ravel(), _expected_node_fields(geom, sol)[1], rtol=1e-12,
                                   atol=1e-12 * max(np.abs(sol.lam_n).max(), 1.0))
        np.testing.assert_array_equal(cdata["body"].ravel(), geom.cell_body)
        vm = fields.von_mises(geom, sol.u)
        np.testing.assert_allclose(cdata["von_mises"].ravel(), vm, rtol=1e-12)


def _mixed_geometry():
    """One quadrilateral and two triangles (cells padded with -1), all nodes free, two contact pairs."""
    points = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [2, 0], [2, 1], [0, -1], [1, -1], [1, 0], [0, 0]], float)
    cells = np.array([[0, 1, 2, 3], [1, 4, 5, -1], [1, 5, 2, -1], [6, 7, 8, 9]])
    P = len(points)
    return ContactGeometry(points=points, cells=cells, cell_body=np.array([1, 1, 1, 2]),
                           dof_node=np.repeat(np.arange(P), 2), dof_comp=np.tile([0, 1], P),
                           contact_nodes=np.array([[0, 9], [1, 8]]), contact_points=points[[0, 1]],
                           normals=np.tile([0.0, -1.0], (2, 1)), tangents=np.tile([1.0, 0.0], (2, 1)),
                           material={"E": 1e3, "nu": 0.25, "plane": "stress"})


def test_xdmf_mixed_cells(tmp_path):
    geom = _mixed_geometry()
    rng = np.random.default_rng(1)
    sols = [Solution(rng.normal(size=20), np.array([1.0, 0.0]), np.array([0.5, 0.0]), a,
                     InactiveSets.from_states(["slip+", "open"]), 0) for a in (0.1, 0.2)]
    fn = fields.write_xdmf(tmp_path / "mixed.xdmf", geom, sols)
    topo = _grids(fn)[0].find("Topology")
    assert topo.get("TopologyType") == "Mixed"
    np.testing.assert_array_equal(_data(topo.find("DataItem")), [5, 0, 1, 2, 3, 4, 1, 4, 5, 4, 1, 5, 2, 5, 6, 7, 8, 9])
    steps = _read_with_vtk_or_meshio(fn, 2)
    for (pts, ncells, pdata, cdata), sol in zip(steps, sols):
        assert ncells == 4
        np.testing.assert_allclose(pdata["displacement"][:, :2], geom.displacement_field(sol.u), atol=1e-12)
        np.testing.assert_array_equal(pdata["contact_state"].ravel(), [2, 0, -1, -1, -1, -1, -1, -1, 0, 2])
        np.testing.assert_allclose(cdata["von_mises"].ravel(), fields.von_mises(geom, sol.u), rtol=1e-12)


def test_xdmf_is_atomic_and_checks_input(system, tmp_path):
    geom = system.geometry
    sols = _solutions(system, (0.4,))
    target = tmp_path / "s.xdmf"
    target.write_text("old")

    def broken():
        yield sols[0]
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError, match="boom"):
        fields.write_xdmf(target, geom, broken())
    assert target.read_text() == "old" and sorted(os.listdir(tmp_path)) == ["s.xdmf"]
    bad = Solution(sols[0].u[:-1], sols[0].lam_n, sols[0].lam_t, 0.4, sols[0].sets, 0)
    with pytest.raises(InputError, match="expected"):
        fields.write_xdmf(target, geom, [bad])
    with pytest.raises(InputError, match=r"\.xdmf"):
        fields.write_xdmf(tmp_path / "s.h5", geom, sols)
    with pytest.raises(InputError, match="'plain'"):
        fields.write_xdmf(target, geom, sols, material={**geom.material, "plane": "plain"})
    with pytest.raises(InputError, match="no solutions"):
        fields.write_xdmf(target, geom, [])
    with pytest.raises(InputError, match="ContactGeometry"):
        fields.write_xdmf(target, None, sols)
    assert target.read_text() == "old" and sorted(os.listdir(tmp_path)) == ["s.xdmf"]
    # without a material: no von_mises attribute
    fn = fields.write_xdmf(tmp_path / "nomat.xdmf", ContactGeometry(**{**geom.to_dict(), "material": None}), sols)
    assert "von_mises" not in {a.get("Name") for a in _grids(fn)[0].findall("Attribute")}
    assert oct(os.stat(fn).st_mode & 0o777) == oct(0o666 & ~_umask())


def _umask():
    m = os.umask(0)
    os.umask(m)
    return m


# ------------------------------------------------------------------ CLI
SMALL = """
title = "fields"
[geometry]
kind = "two_blocks"
nx = 12
ny = 4
cell = "triangle"
[material]
E = {body1 = 2.1e11, body2 = 2.1e9}
nu = {body1 = 0.3, body2 = 0.2}
plane = "stress"
[contact]
friction = 1.5
[output]
window_size = [480, 320]
stress = true
xdmf = true
"""


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("fields_cli")
    case = d / "case.toml"
    case.write_text(SMALL)
    assert cli.main(["run", "-q", str(case)]) == 0
    return d / "case_out"


def _picture(fn):
    from matplotlib.image import imread

    img = imread(fn)
    if img.dtype != np.uint8:
        img = (img[..., :3] * 255).round()
    return np.asarray(img[..., :3], dtype=int)


@pytest.mark.slow
def test_run_writes_stress_panel_and_xdmf(run_dir):
    summary = json.loads((run_dir / "summary.json").read_text())
    assert "solutions.xdmf" in summary["files"] and "panel.png" in summary["files"]
    path = SolutionPath.load(run_dir / "path")
    assert path.geometry.material == {"E": {"body1=1": 2.1e11, "body2=2": 2.1e9},
                                      "nu": {"body1=1": 0.3, "body2=2": 0.2}, "plane": "stress"}
    from cfcontact.run import panel_solutions

    sols = panel_solutions(path)  # (the run's pictures and XDMF: largest multiplicity, else the last point)
    grids = _grids(run_dir / "solutions.xdmf")
    assert len(grids) == len(sols)
    vm = {g.get("Name"): _data([x for x in g.findall("Attribute") if x.get("Name") == "von_mises"][0]
                               .find("DataItem")) for g in grids}
    np.testing.assert_array_equal(vm[fields.grid_name(0, sols[0].alpha)], fields.von_mises(path.geometry, sols[0].u))


@pytest.mark.slow
def test_render_stress(run_dir, tmp_path, capsys):
    pytest.importorskip("pyvista", reason="pyvista is not installed (scripts/install.sh installs it)")
    plain, stress = tmp_path / "plain.png", tmp_path / "stress.png"
    assert cli.main(["render", str(run_dir), "--alpha", "0.5", "--window-size", "420", "260", "-o", str(plain)]) == 0
    assert cli.main(["render", str(run_dir), "--alpha", "0.5", "--stress", "--window-size", "420", "260",
                     "-o", str(stress)]) == 0
    a, b = _picture(plain), _picture(stress)
    assert b.shape == (260, 420, 3)
    flat = b.reshape(-1, 3)
    assert flat.std() > 5 and len(np.unique(flat, axis=0)) >= 20  # not blank
    assert np.abs(a - b).sum() > 0  # the cells are coloured differently
    # a path saved without its material: render --stress takes the [material] of the run's case.toml
    old = tmp_path / "old_out"
    path = SolutionPath.load(run_dir / "path")
    path.geometry.material = None
    path.save(old / "path")
    (old / "case.toml").write_text(SMALL)
    again = tmp_path / "again.png"
    assert cli.main(["render", str(old), "--alpha", "0.5", "--stress", "--window-size", "420", "260",
                     "-o", str(again)]) == 0
    np.testing.assert_array_equal(_picture(again), b)
    os.remove(old / "case.toml")
    capsys.readouterr()
    assert cli.main(["render", str(old), "--alpha", "0.5", "--stress", "-o", str(again)]) == 2
    assert "stores no material" in capsys.readouterr().err


@pytest.mark.slow
def test_render_animation_stress(run_dir, tmp_path):
    """render --animation --stress: frames coloured by the von Mises stress, on one scale; the
    plain animation's frames differ from them."""
    pytest.importorskip("pyvista", reason="pyvista is not installed (scripts/install.sh installs it)")
    plain, stress = tmp_path / "plain_frames", tmp_path / "stress_frames"
    for folder, extra in ((plain, []), (stress, ["--stress"])):
        assert cli.main(["render", str(run_dir), "--animation", str(folder), "--frames", "2",
                         "--window-size", "420", "260", "-q", *extra]) == 0
    for k in range(2):
        a, b = _picture(plain / f"frame_{k:04d}.png"), _picture(stress / f"frame_{k:04d}.png")
        assert b.shape == (260, 420, 3) and len(np.unique(b.reshape(-1, 3), axis=0)) >= 20
        assert np.abs(a - b).sum() > 0
    from cfcontact import render

    with pytest.raises(InputError, match="callable"):
        render.render_animation(SolutionPath.load(run_dir / "path"), tmp_path / "x", frames=2, stress=np.ones(3))


@pytest.mark.slow
def test_export_cli(run_dir, tmp_path, capsys):
    path = SolutionPath.load(run_dir / "path")
    out = tmp_path / "e.xdmf"
    assert cli.main(["export", str(run_dir), "-o", str(out)]) == 0
    from cfcontact.run import default_alpha  # (render's default: the alpha of largest multiplicity, else the end)

    a = default_alpha(path)
    assert [float(g.find("Information").get("Value")) for g in _grids(out)] == [s.alpha for s in path.solutions_at(a)]
    assert cli.main(["export", str(run_dir), "--alpha", "0.25", "-o", str(out)]) == 0
    g = _grids(out)
    assert len(g) == len(path.solutions_at(0.25)) and float(g[0].find("Information").get("Value")) == 0.25
    pts = tmp_path / "points.xdmf"
    assert cli.main(["export", str(run_dir / "path"), "--points", "-o", str(pts)]) == 0
    g = _grids(pts)
    assert [float(x.find("Information").get("Value")) for x in g] == list(path.alphas)
    disp = [x for x in g[-1].findall("Attribute") if x.get("Name") == "displacement"][0]
    np.testing.assert_array_equal(_data(disp.find("DataItem"))[:, :2],
                                  path.geometry.displacement_field(path.ys[-1][:path.n]))
    # bad input: exit 2, one message naming the value, nothing written
    capsys.readouterr()
    bad = tmp_path / "bad.xdmf"
    assert cli.main(["export", str(run_dir), "--alpha", "7", "-o", str(bad)]) == 2
    assert "alpha 7" in capsys.readouterr().err and not bad.exists()
    assert cli.main(["export", str(run_dir), "-o", str(tmp_path / "bad.vtu")]) == 2
    assert ".xdmf" in capsys.readouterr().err
    assert cli.main(["export", str(run_dir), "--alpha", "0.5", "--points"]) == 2
    lumped = cfcontact.ContactSystem.from_arrays(np.eye(2), [[0, 1]], [[1, 0]], [0.0, -1.0], [0.1, -1.0], 0.5)
    lp = cfcontact.trace_path(lumped, 0, 1, method="exact")
    lp.save(tmp_path / "lumped")
    capsys.readouterr()
    assert cli.main(["export", str(tmp_path / "lumped"), "-o", str(bad)]) == 2
    assert "no geometry" in capsys.readouterr().err and not bad.exists()
    assert not glob.glob(str(tmp_path / ".*.tmp"))


ONE_SOLUTION = """
[geometry]
kind = "two_blocks"
nx = 6
ny = 2
[contact]
friction = 1.5
[output]
plot = false
render_panel = false
xdmf = true
"""


def test_export_default_alpha_is_renders(tmp_path, capsys):
    """export without --alpha writes the solutions at render's default alpha (run.default_alpha):
    on a path with one solution everywhere, its last point, as the run's own solutions.xdmf --
    not the middle of its first interval (summary.json's alpha_of_max)."""
    from cfcontact.run import default_alpha

    case = tmp_path / "case.toml"
    case.write_text(ONE_SOLUTION)
    assert cli.main(["run", "-q", str(case)]) == 0
    out = tmp_path / "case_out"
    path = SolutionPath.load(out / "path")
    assert path.max_multiplicity()[0] == 1 and default_alpha(path) == path.alphas[-1]
    exported = tmp_path / "e.xdmf"
    assert cli.main(["export", str(out), "-o", str(exported)]) == 0
    alphas = [float(g.find("Information").get("Value")) for g in _grids(exported)]
    assert alphas == [float(g.find("Information").get("Value")) for g in _grids(out / "solutions.xdmf")]
    assert alphas == [float(path.alphas[-1])]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["summary"]["alpha_of_max"] != path.alphas[-1]


@pytest.mark.parametrize("key, value", [("stress", '"yes"'), ("xdmf", "1")])
def test_output_keys_are_validated(tmp_path, capsys, key, value):
    case = tmp_path / "bad.toml"
    case.write_text(SMALL.replace(f"{key} = true", f"{key} = {value}"))
    assert cli.main(["run", str(case)]) == 2
    err = capsys.readouterr().err
    assert f"[output] {key}" in err and "boolean" in err
    assert not (tmp_path / "bad_out").exists() and not (tmp_path / "bad_out.partial").exists()


def test_xdmf_tractions_sit_on_the_slave_nodes_of_body_2(tmp_path):
    """Node-to-segment pairing with contact2 as the slave (body 2's nodes at x = 0.75, 1.5, ...;
    body 1's at 0.5, 1.0, ...): contact_pressure and contact_shear are lam / tributary length on
    body 2's slave nodes, every one of them, and 0 on body 1's."""
    system = cfcontact.two_blocks(nx=6, ny=2, nx2=4, pairing="segment", slave="contact2", friction=0.5)
    geom = system.geometry
    sol = cfcontact.ssnm(system, 0.5)
    assert sol.lam_n.max() > 0
    fn = fields.write_xdmf(tmp_path / "s.xdmf", geom, [sol])
    att = {a.get("Name"): _data(a.find("DataItem")).ravel() for a in _grids(fn)[0].findall("Attribute")}
    P, body = geom.points[:, :2], _node_body(geom)
    slave = [int(np.flatnonzero((np.hypot(*(P - x).T) <= 1e-12) & (body == 2))[0]) for x in geom.contact_points[:, :2]]
    assert len(set(slave)) == system.m
    for name, lam in (("contact_pressure", sol.lam_n), ("contact_shear", sol.lam_t)):
        np.testing.assert_allclose(att[name][slave] * geom.tributary, lam, rtol=1e-14, atol=0, err_msg=name)
        assert not np.any(np.delete(att[name], slave)), name


@pytest.mark.parametrize("kw, body", [({}, 1), ({"nx2": 4, "pairing": "segment"}, 1),
                                      ({"nx2": 4, "pairing": "segment", "slave": "contact2"}, 2),
                                      ({"foundation": True}, 1)])
def test_slave_nodes_are_at_the_contact_points_on_the_slave_body(kw, body):
    """ContactGeometry.slave_nodes (where the tractions and the rendered states go): each pair's
    node at its contact point, on the slave body (body 1 for a matching interface, a rigid
    foundation and contact1 as slave; body 2 for contact2 as slave, although body 1 has nodes at
    some of those points too), one per pair."""
    geom = cfcontact.two_blocks(nx=6, ny=2, **kw).geometry
    nodes = geom.slave_nodes()
    np.testing.assert_array_equal(geom.points[nodes, :2], geom.contact_points[:, :2])
    assert np.all(_node_body(geom)[nodes] == body) and np.unique(nodes).size == len(nodes)
