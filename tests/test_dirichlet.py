"""Boundary conditions real problems need (issue #12, item 4): prescribed non-zero displacements
along the load path, u_D(alpha) = (1 - alpha) u_D^1 + alpha u_D^2, and constraints on one
component (rollers, symmetry planes).

References: a rigid translation (a free body moved by its prescribed edge moves as a whole), the
lifting -K_fD u_D formed from the unreduced stiffness (``full_stiffness``), and a half model
with a symmetry plane against the full model.
"""

import os
import subprocess
import sys

import numpy as np
import pytest

import cfcontact
from cfcontact.assembly import assemble_contact_system, full_stiffness
from cfcontact.errors import InputError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_prescribed_translation_moves_a_free_block_rigidly():
    """A block above a rigid foundation, held only by its top edge moved by (0.1, 0.2) alpha: it
    lifts off, every node moves by exactly that, no contact force."""
    system = cfcontact.two_blocks(nx=4, ny=2, foundation=True, clamp=(), tractions1={}, tractions2={},
                                  dirichlet={"top1": {"x": (0.0, 0.1), "y": (0.0, 0.2)}})
    for alpha in (0.5, 1.0):
        sol = cfcontact.ssnm(system, alpha)
        U = system.geometry.displacement_field(sol.u, alpha)
        assert np.allclose(U, alpha * np.array([0.1, 0.2]), rtol=1e-10, atol=0)
        assert set(sol.states()) == {"open"} and not sol.lam_n.any()
    assert system.info["dirichlet"] == {"top1=12": {"x": [0.0, 0.1], "y": [0.0, 0.2]}}
    geo = system.geometry
    assert geo.prescribed.shape == (2 * 5, 4)  # five top nodes, two non-zero components
    # without alpha the prescribed nodes show 0 (as clamped ones always did)
    assert np.abs(geo.displacement_field(sol.u)[geo.prescribed[:, 0].astype(int)]).max() == 0.0


@pytest.mark.slow  # (a subprocess)
def test_lifting_against_the_unreduced_stiffness(tmp_path):
    """f_k = -K_fD u_D^k (no tractions): compared with the full stiffness of all DOFs."""
    msh = str(tmp_path / "blocks.msh")
    subprocess.run([sys.executable, "-m", "cfcontact.meshes.two_blocks", msh, "--nx", "5", "--ny", "2",
                    "--cell", "triangle"], check=True, capture_output=True,
                   env=dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")))
    dirichlet = {"top1": {"x": (1e-3, 2e-3), "y": (-1e-3, -3e-3)}, "right2": {"x": 0.0}}
    system = assemble_contact_system(msh, clamp=("bottom2",), dirichlet=dirichlet, tractions1={}, tractions2={},
                                     E=1e3, nu=0.25)
    Kf, points, _, _ = full_stiffness(msh, E=1e3, nu=0.25)
    geo = system.geometry
    free = 2 * geo.dof_node + geo.dof_comp
    uD = np.zeros((2, 2 * len(points)))
    for node, comp, v1, v2 in geo.prescribed:
        uD[:, 2 * int(node) + int(comp)] = v1, v2
    top = np.isclose(points[:, 1], 1.0)
    assert np.count_nonzero(uD[1]) == 2 * np.count_nonzero(top)
    for k, f in enumerate(system.loads_numpy()):
        ref = -(Kf @ uD[k])[free]
        assert np.abs(f - ref).max() <= 1e-12 * np.abs(ref).max()
    # the roller on right2 removed exactly the x components of its nodes
    right2 = np.isclose(points[:, 0], 3.0) & (points[:, 1] < 0)
    right2_x = np.flatnonzero(right2)
    assert not np.isin(2 * right2_x, free).any() and np.isin(2 * right2_x + 1, free[geo.dof_comp == 1]).any()


@pytest.mark.parametrize("kwargs,words", [
    (dict(clamp=("left2",), dirichlet={"left1": {"x": 0.0, "y": (0.0, -1e-3)}}),
     "non-zero prescribed displacement on 1 contact node(s) at (0, 0)"),
    (dict(dirichlet={"left1": {"x": 1e-3}}), "two prescribed x displacements: clamp left1=14"),
    (dict(clamp=("left2",), dirichlet={"top1": {"x": 0.0}}), "can move freely in y"),
    (dict(dirichlet={"top1": {"z": 0.0}}), "unknown component 'z'"),
    (dict(dirichlet={"top1": {"y": (0.0, 1.0, 2.0)}}), "a number or a pair"),
    (dict(dirichlet={"top1": {"y": "down"}}), "a number or a pair"),
    (dict(dirichlet={"top1": 0.0}), "must be a dict with the components"),
    (dict(dirichlet={"top9": {"y": 0.0}}), "unknown boundary piece"),
    (dict(dirichlet=[("top1", 0.0)]), "dirichlet must be a dict"),
])
def test_bad_dirichlet_input(kwargs, words):
    with pytest.raises(InputError) as info:
        cfcontact.two_blocks(nx=3, ny=1, **kwargs)
    assert words in str(info.value), str(info.value)


def test_zero_components_on_contact_nodes_are_fine():
    """A roller through a contact node (its x held at 0 in both bodies): the node stays a contact
    node; its row of T is zero, so it has no tangential unknown (lam_t = 0 when it sticks)."""
    system = cfcontact.two_blocks(nx=4, ny=2, clamp=("bottom2",), friction=0.3,
                                  dirichlet={"left1": {"x": 0.0}, "left2": {"x": 0.0}, "top1": {"y": (0.0, -1e-3)}},
                                  tractions1={}, tractions2={"top1": (1e7, 0.0)})
    assert system.m == 5 and system.no_tangent.tolist() == [True, False, False, False, False]
    sol = cfcontact.ssnm(system, 1.0)
    assert cfcontact.verify(system, sol, 1.0).ok(1e-9) and sol.lam_t[0] == 0.0 and sol.lam_n[0] > 0


# ------------------------------------------------------------------ symmetry
def _block_on_disc(length, nx, friction, half):
    """A 0.5 high block pressed by its top (u_y = -delta alpha, u_x = 0) onto a rigid disc centred
    below x = 1: the full model spans [0, 2], the half model [0, 1] with a symmetry plane
    (u_x = 0) on its right edge x = 1."""
    R, d, delta = 2.0, 1e-4, 1e-2
    dirichlet = {"top1": {"x": 0.0, "y": (0.0, -delta)}}
    if half:
        dirichlet["right1"] = {"x": 0.0}
    return cfcontact.two_blocks(nx=nx, ny=4, length=length, height=0.5, foundation=True, clamp=(),
                                dirichlet=dirichlet, tractions1={}, tractions2={}, friction=friction,
                                obstacle={"kind": "circle", "center": (1.0, -R - d), "radius": R},
                                search_distance=0.05)


@pytest.mark.filterwarnings("ignore::cfcontact.errors.PairingWarning")  # the block's ends miss the disc
@pytest.mark.parametrize("friction", [0.0, 0.3])
def test_half_model_with_symmetry_plane_gives_the_full_solution(friction):
    full = _block_on_disc(2.0, 40, friction, half=False)
    half = _block_on_disc(1.0, 20, friction, half=True)
    assert half.no_tangent[-1] and half.geometry.contact_points[-1, 0] == pytest.approx(1.0)
    # SSNM from 0 (every node open: y = 0 leaves the gap) cycles on the full model at F = 0.3; from
    # the frictionless solution it converges (the path methods' start does the same)
    sf, sh = (cfcontact.ssnm(s, 1.0, y0=cfcontact.ssnm(s.with_friction(0.0), 1.0)) for s in (full, half))
    assert cfcontact.verify(half, sh, 1.0).ok(1e-9) and cfcontact.verify(full, sf, 1.0).ok(1e-9)
    closed = np.flatnonzero(sf.lam_n > 0)
    assert closed.size >= 5, "the test needs a contact zone of several nodes"
    Uf = full.geometry.displacement_field(sf.u, 1.0)
    Uh = half.geometry.displacement_field(sh.u, 1.0)
    pf, ph = full.geometry.points, half.geometry.points
    key = lambda p: np.round(p * 1e6).astype(np.int64)  # noqa: E731
    index = {tuple(k): i for i, k in enumerate(key(pf))}
    match = np.array([index[tuple(k)] for k in key(ph)])
    scale = np.abs(Uf).max()
    assert np.abs(Uh - Uf[match]).max() <= 1e-9 * scale
    cf, ch = full.geometry.contact_points[:, 0], half.geometry.contact_points[:, 0]
    jf = np.array([np.flatnonzero(np.isclose(cf, x))[0] for x in ch])
    weight = np.where(np.isclose(ch, 1.0), 0.5, 1.0)  # the half model carries half the centre node's force
    assert np.abs(sh.lam_n - weight * sf.lam_n[jf]).max() <= 1e-8 * sf.lam_n.max()
    assert np.abs(sh.lam_t - weight * sf.lam_t[jf]).max() <= 1e-8 * sf.lam_n.max()
    if friction > 0:  # (at F = 0 stick and slip are one state)
        assert sh.states() == [sf.states()[j] for j in jf]


@pytest.mark.filterwarnings("ignore::cfcontact.errors.PairingWarning")  # the cylinder's sides miss the block
@pytest.mark.parametrize("friction", [0.5, 30.0])
def test_a_curved_slave_on_the_symmetry_plane_gives_the_full_solution(friction):
    """A half cylinder whose curved side is the slave (slave = "contact1"): its node on the axis
    has one facet on its side, whose normal is tilted by half the facet's turn; with u_x held on
    the plane in both bodies, its normal and tangential rows read the same u_y -- J(Z) was
    singular (the condensed backend stopped, the full one stored points 0.47 off (1)-(3)).  The
    normal is now the plane's (cfcontact.pairing.roller_normals), so the half model is the full
    one's half: the same transitions, half the force."""
    common = dict(width=2.0, depth=1.0, size=0.02, size_far=0.3, friction=friction, slave="contact1",
                  indentation=(0.0, 0.02))
    full = cfcontact.cylinder_on_block(**common)
    half = cfcontact.cylinder_on_block(half=True, **common)
    axis = np.flatnonzero(np.isclose(half.geometry.contact_points[:, 0], 0.0, atol=1e-12))
    assert axis.size == 1 and half.no_tangent.tolist() == [j in axis for j in range(half.m)]
    assert np.abs(half.geometry.normals[axis[0]]).tolist() == [0.0, 1.0]
    pf, ph = (cfcontact.trace_path(s, 0.0, 1.0, method="exact") for s in (full, half))
    assert pf.status == ph.status == "completed" and len(pf.transitions) == len(ph.transitions) > 5
    assert np.allclose([t.alpha for t in ph.transitions], [t.alpha for t in pf.transitions], rtol=1e-10)
    for alpha in (0.37, 1.0):
        (sf,), (sh,) = pf.solutions_at(alpha), ph.solutions_at(alpha)
        assert 2.0 * sh.lam_n.sum() == pytest.approx(sf.lam_n.sum(), rel=1e-10)
    assert max(cfcontact.verify(half, y, a).worst() for a, y in ph.iter_points()) < 1e-12
