"""SSNM and path following on the FEM two-block model, against independent references."""

import os
import sys

import numpy as np
import pytest

import cfcontact
from reference import frictionless_dual

HERE = os.path.dirname(os.path.abspath(__file__))


@pytest.fixture(scope="module")
def default_model():
    return cfcontact.two_blocks(friction=0.6)


@pytest.mark.parametrize("alpha", [0.0, 0.5, 1.0])
def test_default_model_ssnm_satisfies_contact_conditions(default_model, alpha):
    system = default_model
    sol = cfcontact.ssnm(system, alpha)
    v = cfcontact.verify(system, sol, alpha)
    assert v.equilibrium <= 1e-8 and v.ok(1e-8), v
    # per node, independently of verify(): complementarity, cone, slip direction
    N, T = system.contact_maps()
    gap, slip = N @ sol.u, T @ sol.u
    scale_u = np.abs(sol.u).max()
    scale_l = max(np.abs(sol.lam_n).max(), 1.0)
    F = system.friction
    for i in range(system.m):
        ln, lt = sol.lam_n[i], sol.lam_t[i]
        assert gap[i] <= 1e-10 * scale_u and ln >= -1e-10 * scale_l
        assert abs(ln * gap[i]) <= 1e-10 * scale_l * scale_u
        assert abs(lt) <= F * ln + 1e-10 * scale_l
        if abs(lt) < F * ln - 1e-8 * scale_l:
            assert abs(slip[i]) <= 1e-10 * scale_u
        elif ln > 1e-8 * scale_l:
            assert np.sign(lt) * slip[i] >= -1e-10 * scale_u


def test_default_model_consistent_dirneu_is_one_iteration_fixed_point(default_model):
    system = default_model
    sol = cfcontact.ssnm(system, 1.0)
    y = cfcontact.dirneu(system, sol.sets, 1.0)
    assert cfcontact.is_fixed_point(system, y, sol.sets)
    again = cfcontact.ssnm(system, 1.0, y0=y)
    assert again.iterations == 1 and np.allclose(again.y, y.y, rtol=1e-12, atol=0)


def test_frictionless_fem_against_dual_qp():
    system = cfcontact.two_blocks(nx=12, ny=4, friction=0.0)
    K, N, T, f1, f2 = system.to_scipy()
    for alpha in (0.0, 1.0):
        f = (1 - alpha) * f1 + alpha * f2
        u_ref, lam_ref = frictionless_dual(K, N, f)
        sol = cfcontact.ssnm(system, alpha)
        assert np.allclose(sol.u, u_ref, rtol=0, atol=1e-8 * np.abs(u_ref).max())
        assert np.allclose(sol.lam_n, lam_ref, rtol=0, atol=1e-8 * np.abs(lam_ref).max())


def test_fem_seed_path_points_verify():
    system = cfcontact.two_blocks(nx=10, ny=4, friction=0.6)
    path = cfcontact.trace_path(system, 0.0, 1.0)
    assert path.status == "completed"
    for (alpha, y), b in zip(path.points, path.point_branch):
        assert cfcontact.is_fixed_point(system, y, path.branches[b].sets)
        assert cfcontact.verify(system, y, alpha).ok(1e-8)


@pytest.mark.mpi
def test_mpi_ssnm_and_path_match_serial(tmp_path, run_mpi):
    sys.path.insert(0, HERE)
    try:
        import mpi_solve_script as script
    finally:
        sys.path.remove(HERE)
    out = tmp_path / "mpi.npz"
    run_mpi(2, os.path.join(HERE, "mpi_solve_script.py"), str(out))
    par = np.load(out)
    assert int(par["size"]) == 2
    for name, kwargs in script.cases().items():
        ranges = par[f"{name}:ranges"]
        assert 0 < ranges[1] < ranges[2], "the DOFs must really be split over 2 ranks"
        serial = script.solve(cfcontact.two_blocks(**kwargs))
        for key, ref in serial.items():
            got = par[f"{name}:{key}"]
            assert got.shape == ref.shape, (name, key, got.shape, ref.shape)
            if key.startswith(("codes", "path_kinds", "path_nodes", "iterations")):
                assert np.array_equal(got, ref), (name, key)
            elif key.startswith(("u", "lam", "path_u", "path_lam")):
                assert np.abs(got - ref).max() <= 1e-10 * np.abs(ref).max(), (name, key)
            else:
                assert np.allclose(got, ref, rtol=1e-12, atol=1e-14), (name, key)
