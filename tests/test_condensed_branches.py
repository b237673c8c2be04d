"""Branches of the condensed backend (and of ssnm.py / seed.py) that the rest of the suite never ran.

Each test makes one such branch run on a small plain-matrix model and checks its result against an
independent reference: a dense NumPy/SciPy solve, the full J(Z) backend (DirNeuSolver), or the
uncapped run of the same path.  Error paths are checked for their exception type and for a message
that names the offending value.
"""

import logging

import numpy as np
import pytest

import cfcontact
from cfcontact import condensed, linalg
from cfcontact.condensed import CondensedSolver
from cfcontact.errors import CfcontactError, ConvergenceError, InputError, SingularSystemError
from cfcontact.lumped import random_system
from cfcontact.ssnm import DirNeuSolver, InactiveSets, SolverOptions
from cfcontact.system import ContactSystem


def dense_parts(system):
    """K, B = [N; T], f1, f2 and the gap of a system as dense NumPy arrays."""
    K = linalg.local_csr(system.K).toarray()  # (one rank: all of K)
    N, T = system.contact_maps()
    B = np.vstack([N.toarray(), T.toarray()])
    f1, f2 = system.loads_numpy()
    return K, B, np.asarray(f1), np.asarray(f2), np.asarray(system.gap, dtype=float)


def path_laplacian_system(n=6, m=2):
    """K = the Laplacian of a chain of springs without support: exactly singular (a rigid motion)."""
    K = 2.0 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)
    K[0, 0] = K[-1, -1] = 1.0
    N, T = np.zeros((m, n)), np.zeros((m, n))
    for i in range(m):
        T[i, 2 * i], N[i, 2 * i + 1] = 1.0, 1.0
    rng = np.random.default_rng(0)
    return ContactSystem.from_arrays(K, N, T, rng.standard_normal(n), rng.standard_normal(n), 0.5)


# --------------------------------------------------------------------------- error paths


@pytest.mark.parametrize("solver_type", [None, "petsc", "mumps"])
def test_singular_K_is_refused_by_every_factorization(solver_type):
    """A body without Dirichlet condition (K exactly singular) must raise SingularSystemError
    whichever factorization of K the condensed backend uses.  (Before the fix, with MUMPS the
    set-up passed and DirNeu returned displacements of 7.5e14 for unit loads, silently.)"""
    system = path_laplacian_system()
    with pytest.raises(SingularSystemError, match="singular"):
        CondensedSolver(system, SolverOptions(solver_type=solver_type))


def test_regular_K_factored_by_mumps_still_solves_as_the_full_backend():
    """The regularity check added for MUMPS' factorization must not refuse a regular, moderately
    ill-conditioned K (cond 1e8): DirNeu by the condensed backend equals DirNeu by the full J(Z)
    backend for every uniform state."""
    rng = np.random.default_rng(3)
    n, m = 12, 3
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    K = (Q * np.logspace(0, 8, n)) @ Q.T
    N, T = rng.standard_normal((m, n)), rng.standard_normal((m, n))
    system = ContactSystem.from_arrays(0.5 * (K + K.T), N, T, rng.standard_normal(n), rng.standard_normal(n), 0.7)
    cond = CondensedSolver(system, SolverOptions(solver_type="mumps"))
    full = DirNeuSolver(system)
    for state in ("open", "stick", "slip+", "slip-"):
        Z = InactiveSets.from_states([state] * m)
        f = system.load(0.4)
        yc, yf = cond.solve(Z, f), full.solve(Z, f)
        assert np.abs(yc - yf).max() <= 1e-6 * np.abs(yf).max(), state


@pytest.mark.parametrize("solver_type", [None, "mumps"])
def test_a_stiffness_contrast_of_1e12_is_not_taken_for_singular(solver_type):
    """Steel bonded on a body 1e12 times softer, on a mesh past the envelope factorization's size
    (n = 5040): K is regular (condition number some 1e14 to 1e15), neither PETSc's Cholesky nor
    MUMPS (which detects null pivots) refuses it, and the condensed multipliers of every uniform
    state agree with the full J(Z) backend's (a bound |K| |x| <= 1e14 |b| on the set-up's probe
    had refused it: 3.4e14)."""
    pytest.importorskip("dolfinx")
    from cfcontact.models import two_blocks

    system = two_blocks(nx=60, ny=20, E={"body1": 2.1e11, "body2": 2.1e-1}, friction=0.6)
    assert system.n == 5040
    cond = CondensedSolver(system, SolverOptions(solver_type=solver_type))
    full = DirNeuSolver(system)
    n = system.n
    for state in ("open", "stick", "slip+", "slip-"):
        Z = InactiveSets.from_states([state] * system.m)
        yc, yf = cond.solve(Z, system.load(0.3)), full.solve(Z, system.load(0.3))
        assert np.abs(yc[n:] - yf[n:]).max() <= 1e-6 * max(np.abs(yf[n:]).max(), 1e-300), state


def test_schur_true_without_mumps_names_the_factorization_asked_for():
    """schur=True with K factored by PETSc's own Cholesky: InputError naming 'petsc' (before the
    fix the message said "not None": the PC's solver type is not set before its set-up)."""
    system = random_system(3, 1)
    with pytest.raises(InputError, match="needs MUMPS.*'petsc'"):
        CondensedSolver(system, SolverOptions(solver_type="petsc"), schur=True)


def _bad_calls():
    system = random_system(3, 1)
    n, m = system.n, system.m
    Z = InactiveSets.from_states(["stick"] * m)
    cs = CondensedSolver(system)
    full = DirNeuSolver(system)
    return [
        ("condensed solve, f of the wrong shape", lambda: cs.solve(Z, np.ones(n - 1)), rf"shape \({n - 1},\)"),
        ("condensed solve, Z of another m", lambda: cs.solve(InactiveSets.from_states(["open"] * 2), np.ones(n)),
         f"length m = {m}"),
        ("condensed displacements, columns vs alphas", lambda: cs.displacements(np.zeros((2 * m, 2)), [0.0, 0.5, 1.0]),
         "2 multiplier columns but 3 alphas"),
        ("full solve, f of the wrong shape", lambda: full.solve(Z, np.ones(n + 2)), rf"shape \({n + 2},\)"),
        ("dirneu, Z of another m", lambda: cfcontact.dirneu(system, InactiveSets.from_states(["open"])),
         f"length m = {m}"),
        ("dirneu, f of the wrong length", lambda: cfcontact.dirneu(system, Z, f=np.ones(n + 1)),
         f"length {n + 1}, expected n = {n}"),
        ("ssnm, tol = 0", lambda: cfcontact.ssnm(system, 0.5, tol=0.0), "tol must be > 0, got 0.0"),
        ("ssnm, max_iter = 0", lambda: cfcontact.ssnm(system, 0.5, max_iter=0), "max_iter must be >= 1, got 0"),
        ("state code 5", lambda: InactiveSets.from_states([0, 5, 1]), r"0\.\.3, got \[0, 5, 1\]"),
    ]


@pytest.mark.parametrize("case", range(9))
def test_bad_input_is_refused_with_the_bad_value_named(case):
    """Bad arguments of the DirNeu/SSNM entry points raise InputError whose message names the
    offending value (shape, length, count or code)."""
    what, call, pattern = _bad_calls()[case]
    with pytest.raises(InputError, match=pattern):
        call()


def test_condensed_ssnm_reports_nonconvergence_as_the_full_backend_does():
    """SSNM in the multipliers (condensed backend) stopped after max_iter iterations raises
    ConvergenceError with iterations = max_iter and the last iterate, which equals the full J(Z)
    backend's last iterate from the same start (SSNM's iterates do not depend on the backend);
    with enough iterations both converge to the same solution."""
    system = random_system(3, 1)
    iters = []
    for max_iter in (1, 2):
        errs = []
        for solver in (CondensedSolver(system), DirNeuSolver(system)):
            with pytest.raises(ConvergenceError, match=f"did not converge in {max_iter} iterations") as info:
                cfcontact.ssnm(system, 0.3, max_iter=max_iter, solver=solver)
            assert info.value.iterations == max_iter
            errs.append(info.value.last.y)
        yc, yf = errs
        assert np.abs(yc - yf).max() <= 1e-10 * np.abs(yf).max()
        iters.append(max_iter)
    yc = cfcontact.ssnm(system, 0.3, solver=CondensedSolver(system)).y
    yf = cfcontact.ssnm(system, 0.3, solver=DirNeuSolver(system)).y
    assert np.abs(yc - yf).max() <= 1e-10 * np.abs(yf).max()


# --------------------------------------------------------------------------- public methods


def test_multipliers_many_without_a_cached_factorization_equals_the_full_backend():
    """multipliers_many(Z, W) without a key (its own factorization of Z) and with a caller's key
    that is not cached yet (factored from Z under that key): lam of both loads equals the
    multipliers of DirNeu(Z, f1) and DirNeu(Z, f2) by the full J(Z) backend, on a model with a
    gap.  A second call with the key reuses the factorization (no new dense factorization)."""
    system = random_system(4, 5, friction=0.6, gap=0.05)
    cs, full = CondensedSolver(system), DirNeuSolver(system)
    f1, f2 = system.loads_numpy()
    W = np.column_stack([cs.load_data(f1), cs.load_data(f2)])
    n = system.n
    for states in (["stick", "slip+", "open", "slip-"], ["slip-", "stick", "stick", "open"]):
        Z = InactiveSets.from_states(states)
        ref = np.column_stack([full.solve(Z, f)[n:] for f in (f1, f2)])
        L0 = cs.multipliers_many(Z, W)
        key = b"caller key " + bytes(str(states), "ascii")
        L1 = cs.multipliers_many(Z, W, key=key)
        before = cs.stats.dense_factorizations
        L2 = cs.multipliers_many(Z, W, key=key)
        assert cs.stats.dense_factorizations == before
        for L in (L0, L1, L2):
            assert np.abs(L - ref).max() <= 1e-10 * np.abs(ref).max(), states


@pytest.mark.parametrize("refine", [False, True])
def test_true_rows_of_full_load_vectors_subtract_the_gap_where_asked(refine):
    """true_rows(loads, L, gap) with full load vectors (not PathLoads) on a system with a gap:
    B K^-1 (f_j - B^T L_j) - (g; 0) gap_j by a dense NumPy solve, for a column with the gap (a
    value) and one without (a rate)."""
    system = random_system(3, 2, friction=0.8, gap=np.array([0.1, 0.0, 0.3]))
    cs = CondensedSolver(system, SolverOptions(refine=refine))
    K, B, f1, f2, g = dense_parts(system)
    rng = np.random.default_rng(7)
    L = rng.standard_normal((2 * system.m, 2))
    loads = np.column_stack([f1, f2 - f1])
    R = cs.true_rows(loads, L, np.array([True, False]))
    ref = B @ np.linalg.solve(K, loads - B.T @ L)
    ref[:system.m] -= np.outer(g, [1.0, 0.0])
    assert np.abs(R - ref).max() <= 1e-12 * np.abs(ref).max()


def test_destroyed_solvers_say_so_when_used_again():
    """destroy() releases the PETSc objects of both backends (K by the envelope kernels and by
    MUMPS); a destroyed condensed solver refuses further solves with an error that says it was
    destroyed (before the fix: "could not broadcast input array from shape (8,) into shape
    (0,)"), while the full backend's destroy only drops its factorizations (solves again, the
    same answer)."""
    system = random_system(3, 1)
    Z = InactiveSets.from_states(["stick", "slip+", "open"])
    f = system.load(0.2)
    for st in (None, "mumps"):
        cs = CondensedSolver(system, SolverOptions(solver_type=st))
        cs.solve(Z, f)
        cs.destroy()
        with pytest.raises(CfcontactError, match="destroyed"):
            cs.solve(Z, f)
    full = DirNeuSolver(system)
    y = full.solve(Z, f)
    full.destroy()
    assert np.array_equal(full.solve(Z, f), y)


def test_inactive_sets_hash_as_they_compare():
    """InactiveSets are usable as dict keys and set members: equal sets (the same states built two
    ways) hash alike and collapse to one entry, different ones do not."""
    a = InactiveSets.from_states(["open", "stick", "slip-"])
    b = InactiveSets.from_states(np.array([0, 1, 3]))
    c = InactiveSets.from_states(["open", "slip+", "slip-"])
    assert a == b and hash(a) == hash(b)
    assert len({a, b, c}) == 2
    assert {a: 1}[b] == 1


# --------------------------------------------------------------------------- numerical branches


def _schur_model():
    return random_system(4, 11, friction=0.9, extra_dofs=30)


def _assert_S_is_B_Kinv_Bt(cs, system, rtol=1e-12):
    K, B, *_ = dense_parts(system)
    ref = B @ np.linalg.solve(K, B.T)
    assert np.abs(cs.S - ref).max() <= rtol * np.abs(ref).max()


@pytest.mark.parametrize("failure", ["inaccurate", "request", "read"])
def test_schur_complement_failures_fall_back_to_solves(failure, monkeypatch, caplog):
    """Where S cannot come from MUMPS' Schur complement (it fails its accuracy probe, PETSc cannot
    be asked for it, or it gives none) and the Schur complement was only the default (schur=None),
    S is formed by solves instead: it equals B K^-1 B^T by a dense solve, and DirNeu equals the
    full backend.  With schur=True the request/read failures raise (InputError /
    SingularSystemError) instead of silently changing method."""
    monkeypatch.setattr(condensed, "SCHUR_MIN_ENTRIES", 0)  # the Schur complement by default here
    monkeypatch.setattr(condensed, "SCHUR_MAX_CONTACT_SHARE", 1.0)
    if failure == "inaccurate":
        monkeypatch.setattr(condensed, "SCHUR_CHECK_RTOL", -1.0)  # every probe "fails"
    elif failure == "request":
        def refuse(fm, dofs):
            raise RuntimeError("this PETSc offers no MatFactorSetSchurIS")
        monkeypatch.setattr(condensed, "factor_set_schur_is", refuse)
    else:
        monkeypatch.setattr(condensed, "factor_schur_complement", lambda fm, k: None)
    system = _schur_model()
    with caplog.at_level(logging.INFO, logger="cfcontact.condensed"):
        cs = CondensedSolver(system, SolverOptions(solver_type="mumps"))
    assert cs.k_factorization == "lu/mumps"
    assert cs.condensation == "solves"
    assert "solves" in caplog.text
    _assert_S_is_B_Kinv_Bt(cs, system)
    full = DirNeuSolver(system)
    Z = InactiveSets.from_states(["stick", "slip-", "open", "slip+"])
    f = system.load(0.6)
    yc, yf = cs.solve(Z, f), full.solve(Z, f)
    assert np.abs(yc - yf).max() <= 1e-10 * np.abs(yf).max()
    if failure == "request":
        with pytest.raises(InputError, match="cannot request the Schur complement.*MatFactorSetSchurIS"):
            CondensedSolver(system, SolverOptions(solver_type="mumps"), schur=True)
    elif failure == "read":
        with pytest.raises(SingularSystemError, match="could not be read"):
            CondensedSolver(system, SolverOptions(solver_type="mumps"), schur=True)


def test_refined_S_by_unsymmetric_solves_is_corrected_to_B_Kinv_Bt():
    """Refinement forced with K factored by MUMPS' LU and 2m larger than the correction's sketch:
    S by (unrefined, unsymmetric) solves is symmetrized and corrected; the result is exactly
    symmetric and equals B K^-1 B^T by a dense solve, and w1 = B K^-1 f1 too."""
    system = random_system(12, 3, extra_dofs=10)
    assert 2 * system.m > condensed.CORRECTION_SKETCH + condensed.CORRECTION_CHECK
    cs = CondensedSolver(system, SolverOptions(solver_type="mumps", refine=True))
    assert cs.condensation == "solves" and cs.refine_steps >= 1
    assert np.array_equal(cs.S, cs.S.T)
    _assert_S_is_B_Kinv_Bt(cs, system, rtol=1e-13)
    K, B, f1, *_ = dense_parts(system)
    w1 = B @ np.linalg.solve(K, f1)
    assert np.abs(cs.load_data(f1) - w1).max() <= 1e-13 * np.abs(w1).max()


# --------------------------------------------------------------------------- seed method


def test_seed_path_stops_at_the_transition_cap_with_its_first_transitions():
    """The seed method with max_transitions = k stops with status "max_transitions" (and an event
    saying so) after exactly k transitions, which are the first k of the uncapped run."""
    system = random_system(3, 3, friction=0.5)
    free = cfcontact.trace_path(system, 0.0, 1.0, method="seed")
    assert free.status == "completed" and len(free.transitions) >= 4
    k = 2
    capped = cfcontact.trace_path(system, 0.0, 1.0, method="seed", max_transitions=k)
    assert capped.status == "max_transitions"
    assert any(e.kind == "max_transitions" for e in capped.events)
    assert len(capped.transitions) == k
    for a, b in zip(capped.transitions, free.transitions):
        assert (a.kind, a.node, a.alpha) == (b.kind, b.node, b.alpha)


def test_seed_start_from_a_given_point_reports_its_failure():
    """A seed path started from a user's y0 from which SSNM does not converge in max_iter
    iterations raises that ConvergenceError (no homotopy replaces a start the user chose); from
    no y0 the same options start the path (by the fallback starts)."""
    system = random_system(3, 1)
    y0 = np.zeros(system.n + 2 * system.m)
    y0[system.n:system.n + system.m] = -1.0  # every node "pulled": far from the solution's sets
    with pytest.raises(ConvergenceError):
        cfcontact.trace_path(system, 0.0, 1.0, method="seed", y0=y0, max_iter=1)


def test_refinement_that_needs_more_steps_warns_with_what_is_left_and_keeps_that_accuracy(caplog):
    """K with cond 8e13 (refinement forced): the probe's corrections shrink a thousandfold per
    step but are still above REFINE_TARGET after REFINE_MAX_STEPS; the warning says what is left
    (the last correction, the solver's refine_floor; before the fix it said the refinement "does
    not contract" and gave no remaining error), and the refined data w1 = B K^-1 f1 agree with a
    40-digit mpmath solve to within ten times that floor (unrefined they are 9e-4 off)."""
    mpmath = pytest.importorskip("mpmath")
    rng = np.random.default_rng(0)
    n, m = 30, 4
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    K = (Q * np.logspace(0, np.log10(8e13), n)) @ Q.T
    K = 0.5 * (K + K.T)
    N, T = rng.standard_normal((m, n)), rng.standard_normal((m, n))
    f1, f2 = rng.standard_normal(n), rng.standard_normal(n)
    system = ContactSystem.from_arrays(K, N, T, f1, f2, 1.0)
    with caplog.at_level(logging.WARNING, logger="cfcontact.condensed"):
        cs = CondensedSolver(system, SolverOptions(refine=True))
    assert cs.refine_steps == condensed.REFINE_MAX_STEPS
    assert cs.refine_floor > condensed.REFINE_TARGET
    warned = [r.getMessage() for r in caplog.records if "refinement of solves with K" in r.getMessage()]
    assert len(warned) == 1 and f"off by about {cs.refine_floor:.1e}" in warned[0], warned
    Kd, B, *_ = dense_parts(system)
    with mpmath.workdps(40):
        x = mpmath.lu_solve(mpmath.matrix(Kd.tolist()), mpmath.matrix(f1.tolist()))
        w_ref = np.array([float(v) for v in mpmath.matrix(B.tolist()) * x])
    w = cs.load_data(f1)
    assert np.abs(w - w_ref).max() <= 10 * cs.refine_floor * np.abs(w_ref).max()
