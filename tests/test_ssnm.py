"""Semi-smooth Newton layer against independent references (lumped models)."""

import numpy as np
import pytest

import cfcontact
from cfcontact.lumped import one_node, random_system
from reference import frictionless_dual, one_node_solutions

K1 = np.array([[1.0, 0.5], [0.5, 1.0]])


def load(theta_deg):
    t = np.radians(theta_deg)
    return np.array([np.cos(t), np.sin(t)])


def as_vector(sol):
    """(u_t, u_n, p, lam_t) of a cfcontact Solution of the one-node model."""
    return np.array([sol.u[0], sol.u[1], sol.lam_n[0], sol.lam_t[0]])


def all_fixed_points(system, alpha=0.0):
    """Every state combination tried by DirNeu + Remark 3.1 (the one-node model has 4)."""
    found = []
    for state in ("open", "stick", "slip+", "slip-"):
        Z = cfcontact.InactiveSets.from_states([state])
        sol = cfcontact.dirneu(system, Z, alpha)
        if cfcontact.is_fixed_point(system, sol, Z):
            found.append((state, sol))
    return found


@pytest.mark.parametrize("theta", [22.5, 24.0, 26.0])
def test_one_node_inside_wedge_ssnm_recovers_each_of_three(theta):
    f = load(theta)
    system = one_node(2.5, K1, f1=f, f2=f)
    ref = one_node_solutions(K1, 2.5, f)
    assert sorted(s for s, _ in ref) == ["open", "slip+", "stick"]
    rng = np.random.default_rng(0)
    for state, yref in ref:
        scale = np.abs(yref).max()
        y0 = yref + 1e-3 * scale * rng.standard_normal(4)
        # start near the reference in the sets of that solution
        start = np.array([y0[0], y0[1], y0[2], y0[3]])
        sol = cfcontact.ssnm(system, 0.0, y0=start)
        assert np.allclose(as_vector(sol), yref, rtol=1e-10, atol=1e-12 * scale), (state, as_vector(sol), yref)
        assert cfcontact.verify(system, sol, 0.0).ok(1e-12)


@pytest.mark.parametrize("theta", [5.0, 15.0, 21.0, 27.5, 45.0, 80.0, 120.0, -30.0])
def test_one_node_outside_wedge_unique(theta):
    f = load(theta)
    system = one_node(2.5, K1, f1=f, f2=f)
    ref = one_node_solutions(K1, 2.5, f)
    assert len(ref) == 1
    found = all_fixed_points(system)
    assert len(found) == 1
    assert np.allclose(as_vector(found[0][1]), ref[0][1], atol=1e-12)
    # SSNM is only locally convergent (F k_tn > k_tt here): start near the solution
    start = ref[0][1] + 1e-3 * np.abs(ref[0][1]).max() * np.array([1.0, -1.0, 0.5, -0.5])
    sol = cfcontact.ssnm(system, 0.0, y0=start)
    assert np.allclose(as_vector(sol), ref[0][1], atol=1e-12)


def test_one_node_enumeration_matches_closed_form_on_a_sweep():
    for theta in np.linspace(-170, 170, 69):
        f = load(theta)
        system = one_node(2.5, K1, f1=f, f2=f)
        ref = sorted(s for s, _ in one_node_solutions(K1, 2.5, f))
        got = sorted(s for s, _ in all_fixed_points(system))
        assert got == ref, theta


def test_dirneu_with_consistent_sets_is_one_iteration_fixed_point():
    """Remark 3.1 on random small systems: a consistent Z gives an SSNM fixed point in 1 iteration."""
    checked = 0
    for seed in range(6):
        system = random_system(3, seed, friction=0.8)
        sol = cfcontact.ssnm(system, 0.3)
        again = cfcontact.ssnm(system, 0.3, y0=sol)
        assert again.iterations == 1
        assert np.allclose(again.y, sol.y, rtol=1e-12, atol=1e-14)
        Z = sol.sets
        y = cfcontact.dirneu(system, Z, 0.3)
        assert cfcontact.is_fixed_point(system, y, Z)
        assert cfcontact.ssnm(system, 0.3, y0=y).iterations == 1
        checked += 1
    assert checked == 6


def test_inconsistent_sets_are_not_fixed_points():
    f = load(60.0)  # pressing: separation impossible
    system = one_node(2.5, K1, f1=f, f2=f)
    Z = cfcontact.InactiveSets.from_states(["open"])
    y = cfcontact.dirneu(system, Z, 0.0)
    assert not cfcontact.is_fixed_point(system, y, Z)
    assert cfcontact.inactive_sets(system, y) != Z


@pytest.mark.parametrize("seed", range(5))
def test_frictionless_against_dual_qp(seed):
    system = random_system(4, seed, friction=0.0, extra_dofs=3)
    K, N, T, f1, f2 = system.to_scipy()
    alpha = 0.4
    f = (1 - alpha) * f1 + alpha * f2
    u_ref, lam_ref = frictionless_dual(K, N, f)
    sol = cfcontact.ssnm(system, alpha)
    assert np.allclose(sol.u, u_ref, rtol=1e-8, atol=1e-10 * np.abs(u_ref).max())
    assert np.allclose(sol.lam_n, lam_ref, rtol=1e-8, atol=1e-10 * max(np.abs(lam_ref).max(), 1))
    assert np.allclose(sol.lam_t, 0.0)


def test_solution_satisfies_conditions_random_systems():
    for seed in range(10):
        system = random_system(5, seed, friction=0.5)
        sol = cfcontact.ssnm(system, 0.5)
        v = cfcontact.verify(system, sol, 0.5)
        assert v.ok(1e-10), v


def test_counters_count_factorizations_and_solves():
    system = random_system(3, 1, friction=0.3)
    solver = cfcontact.DirNeuSolver(system)
    Z = cfcontact.InactiveSets.all_stick(3)
    cfcontact.dirneu(system, Z, 0.0, solver=solver)
    cfcontact.dirneu(system, Z, 1.0, solver=solver)
    assert solver.stats.factorizations == 1
    assert solver.stats.linear_solves == 2
    cfcontact.dirneu(system, cfcontact.InactiveSets.from_states(["open", "stick", "slip-"]), 0.0, solver=solver)
    assert solver.stats.factorizations == 2


def test_y0_flat_vector_and_bad_length():
    system = random_system(2, 3, friction=0.3)
    sol = cfcontact.ssnm(system, 0.0)
    assert cfcontact.ssnm(system, 0.0, y0=sol.y).iterations == 1
    with pytest.raises(cfcontact.InputError, match="length n \\+ 2m"):
        cfcontact.ssnm(system, 0.0, y0=np.zeros(3))


def test_nonconvergence_raises_typed_error():
    f = load(24.0)
    system = one_node(2.5, K1, f1=f, f2=f)
    with pytest.raises(cfcontact.ConvergenceError) as info:
        cfcontact.ssnm(system, 0.0, y0=np.array([0.3, -0.2, 0.1, -0.05]), max_iter=1)
    assert info.value.iterations == 1


# ------------------------------------------------------------------ bad input
def test_negative_friction_rejected():
    with pytest.raises(cfcontact.InputError, match="friction coefficient F must be .*>= 0, got -0.5"):
        one_node(-0.5)


def test_wrong_load_length_rejected():
    with pytest.raises(cfcontact.InputError, match="f1 has length 3, expected n = 2"):
        cfcontact.ContactSystem.from_arrays(K1, [[0, 1]], [[1, 0]], [1, 2, 3], [1, 2], 0.3)
    system = one_node(0.3)
    with pytest.raises(cfcontact.InputError, match="expected \\(2,\\)"):
        system.with_loads([1.0], [1.0, 2.0])


def test_mismatched_contact_maps_rejected():
    with pytest.raises(cfcontact.InputError, match="T must have shape"):
        cfcontact.ContactSystem.from_arrays(K1, [[0, 1]], [[1, 0], [0, 1]], [1, 2], [1, 2], 0.3)


def test_singular_stiffness_gives_clear_error():
    # two free DOFs, only one tied to the contact node: the other is a rigid mode
    K = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
    system = cfcontact.ContactSystem.from_arrays(K, [[0, 1, 0]], [[1, 0, 0]], [1, 1, 1], [1, 1, 1], 0.3)
    with pytest.raises(cfcontact.SingularSystemError, match="singular"):
        cfcontact.ssnm(system, 0.0)


def test_inactive_sets_from_rows_keeps_the_array_and_checks_it():
    """InactiveSets.from_rows takes a fresh 3 x m boolean array as the sets' rows (no copies: the
    exact method forms one per branch), read-only like the constructor's, equal to them; anything
    else is refused with what was given."""
    from cfcontact.errors import InputError
    from cfcontact.ssnm import InactiveSets

    table = np.array([[True, False, False], [True, False, True], [False, False, False]])
    sets = InactiveSets.from_rows(table)
    assert sets == InactiveSets(table[0].copy(), table[1].copy(), table[2].copy())
    assert sets.states() == ["open", "stick", "slip+"]
    assert np.shares_memory(sets.nu, table) and not table.flags.writeable
    for bad in (np.zeros((2, 3), dtype=bool), np.zeros((3, 3)), np.zeros(3, dtype=bool)):
        with pytest.raises(InputError, match="3 x m boolean"):
            InactiveSets.from_rows(bad)
