"""The compiled kernels (cfcontact.native): built on first use, cached per source/compiler/CPU;
the double-double residual gives the same bits as the NumPy implementation, with a clean
fallback to NumPy when no compiler works; the two-column products and the transposed LU solve
are as accurate as BLAS/LAPACK (checked against exact rational products and getrs)."""

import logging
import os
import subprocess
import sys
from fractions import Fraction

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from cfcontact import linalg, native


@pytest.fixture
def fresh_native(monkeypatch, tmp_path):
    """native with nothing loaded yet and its cache in a temporary folder."""
    monkeypatch.setenv("CFCONTACT_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(native, "_tried", False)
    monkeypatch.setattr(native, "_lib", None)
    return tmp_path / "cache"


def cancelling(n=300, k=7, seed=5):
    """A sparse A with rows of mixed scales, x over 40 decades, b = A x + tiny: a residual that
    double precision gets wrong."""
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=0.03, random_state=seed, format="csr")
    A.data *= np.exp(rng.uniform(-10, 10, A.nnz))
    A = (A + sp.eye(n) * 1e4).tocsr()
    x = rng.standard_normal((n, k)) * np.exp(rng.uniform(-20, 20, (n, k)))
    b = A @ x + rng.standard_normal((n, k)) * 1e-9
    return A, b, x


def test_compiled_kernel_gives_the_numpy_bits(kernels, fresh_native, monkeypatch):
    """k = 7 columns: a block of 4 and three single columns in the kernel; C- and Fortran-ordered
    input; the same bits as NumPy's slots (same operations, same order)."""
    A, b, x = cancelling()
    compiled = linalg.ExactResidual(A)
    assert compiled.compiled
    assert list(fresh_native.glob("kernels-*.so"))
    monkeypatch.setenv("CFCONTACT_NATIVE", "0")
    monkeypatch.setattr(native, "_tried", False)
    plain = linalg.ExactResidual(A)
    assert not plain.compiled
    r1, r2 = compiled(b, x), plain(b, x)
    assert np.array_equal(r1, r2)
    assert np.array_equal(compiled(np.asfortranarray(b), np.asfortranarray(x)), r1)
    assert np.array_equal(compiled(b[:, 2], x[:, 2]), r1[:, 2])
    assert compiled(b[:, :0], x[:, :0]).shape == (A.shape[0], 0)


def test_compiled_kernel_against_rational_arithmetic(kernels, fresh_native):
    """Rows with unsorted CSR indices (the kernel sorts a copy; the caller's matrix is left as
    it is) against Fractions."""
    rng = np.random.default_rng(8)
    A = sp.random(30, 30, density=0.3, random_state=9, format="csr") * 1e6 + sp.eye(30) * 1e6
    A = sp.csr_matrix(A)
    perm = [np.r_[A.indptr[i]:A.indptr[i + 1]][::-1] for i in range(30)]
    U = sp.csr_matrix((A.data[np.concatenate(perm)], A.indices[np.concatenate(perm)], A.indptr), shape=A.shape)
    U.has_sorted_indices = False
    before = U.indices.copy()
    x = rng.standard_normal((30, 2)) * 1e3
    b = A @ x + rng.standard_normal((30, 2)) * 1e-4
    Ad = A.toarray()
    exact = np.array([[float(Fraction(b[i, k]) - sum(Fraction(Ad[i, j]) * Fraction(x[j, k]) for j in range(30)))
                       for k in range(2)] for i in range(30)])
    res = linalg.ExactResidual(U)
    assert res.compiled
    assert np.abs(res(b, x) - exact).max() <= 2.3e-16 * np.abs(exact).max()
    assert np.array_equal(U.indices, before)


def test_the_cache_is_reused_and_keyed(kernels, fresh_native, monkeypatch):
    """A second process loads the cached object without compiling; another CPU (features) gets
    another file."""
    native.dd_residual_kernel()
    files = sorted(fresh_native.glob("kernels-*.so"))
    assert len(files) == 1
    stamp = files[0].stat().st_mtime_ns
    code = "import sys, cfcontact.native as n; sys.exit(0 if n.dd_residual_kernel() is not None else 1)"
    env = dict(os.environ, CFCONTACT_CACHE_DIR=str(fresh_native))  # (the same compiler as here)
    assert subprocess.run([sys.executable, "-c", code], env=env).returncode == 0
    assert sorted(fresh_native.glob("kernels-*.so")) == files
    assert files[0].stat().st_mtime_ns == stamp
    monkeypatch.setattr(native, "_cpu_features", lambda: "another cpu")
    monkeypatch.setattr(native, "_tried", False)
    assert native.dd_residual_kernel() is not None
    assert len(list(fresh_native.glob("kernels-*.so"))) == 2


def test_without_a_compiler_numpy_is_used(kernels, fresh_native, monkeypatch, caplog):
    """$CC that does not exist and no cc/gcc on PATH: None, logged, and ExactResidual still
    works (NumPy); a compiler that fails: None as well, nothing left in the cache."""
    A, b, x = cancelling(n=60, k=2)
    ref = linalg.ExactResidual(A)(b, x)  # (compiled, cached)
    for f in fresh_native.glob("*.so"):
        f.unlink()
    monkeypatch.setattr(native, "_tried", False)
    monkeypatch.setenv("CC", "/nonexistent/cc")
    monkeypatch.setenv("PATH", "/nonexistent")
    with caplog.at_level(logging.INFO, logger="cfcontact.native"):
        assert native.dd_residual_kernel() is None
    assert "no C compiler" in caplog.text
    res = linalg.ExactResidual(A)
    assert not res.compiled
    assert np.array_equal(res(b, x), ref)
    # a "compiler" that always fails
    fake = fresh_native.parent / "badcc"
    fake.write_text("#!/bin/sh\necho 'cc: error: broken' >&2\nexit 1\n")
    fake.chmod(0o755)
    monkeypatch.setenv("CC", str(fake))
    monkeypatch.setattr(native, "_tried", False)
    with caplog.at_level(logging.INFO, logger="cfcontact.native"):
        assert native.dd_residual_kernel() is None
    assert "broken" in caplog.text
    assert not list(fresh_native.glob("*.so"))


@pytest.mark.parametrize("rows, cols", [(1, 1), (7, 3), (401, 13), (420, 1728), (1001, 1002)])
def test_two_column_product(kernels, rows, cols):
    """gemv2 (both columns in one pass over A) against exact products: row counts not multiples of
    4 (a short last block of rows), column counts not multiples of 4 (the scalar tail), entries over 10 decades; as
    accurate as BLAS' gemv.  Other layouts or column counts: None (the caller multiplies)."""
    rng = np.random.default_rng(rows + cols)
    A = rng.standard_normal((rows, cols)) * np.exp(rng.uniform(-12, 12, (rows, cols)))
    X = rng.standard_normal((cols, 2))
    Y = native.gemv2(A, X)
    assert Y is not None and Y.shape == (rows, 2)
    exact = np.array([[float(sum(Fraction(a) * Fraction(x) for a, x in zip(A[i], X[:, k]))) for k in range(2)]
                      for i in range(min(rows, 40))]) if cols <= 16 else None
    bound = np.abs(A) @ np.abs(X)
    if exact is not None:
        assert np.all(np.abs(Y[:len(exact)] - exact) <= 4 * cols * 1.2e-16 * bound[:len(exact)])
    assert np.all(np.abs(Y - A @ X) <= 2e-15 * bound)
    assert np.array_equal(native.gemv2(A, np.asfortranarray(X)), Y)
    assert native.gemv2(np.asfortranarray(A), X) is None or rows == 1 or cols == 1
    assert native.gemv2(A, np.column_stack([X, X[:, :1]])) is None


@pytest.mark.parametrize("n", [1, 2, 3, 5, 8, 13, 401, 1003])
def test_two_column_transposed_lu_solve(kernels, n):
    """getrs2t (A^-T B, both columns in one pass over getrf's factor) against LAPACK's getrs with
    trans = 1: sizes that are not multiples of the kernel's four-row blocks, a matrix that needs
    row interchanges (its largest entries below the diagonal), residuals as small as getrs'.
    Other layouts or column counts: None (the caller solves)."""
    rng = np.random.default_rng(n)
    A = rng.standard_normal((n, n)) + np.diag(rng.uniform(0.5, 1.0, n)) * np.sqrt(n)
    A = np.roll(A, 1, axis=0)  # the dominant entries one row down: partial pivoting swaps rows
    lu, piv, info = sla.lapack.dgetrf(A)
    assert info == 0 and (n == 1 or np.any(piv != np.arange(n)))
    B = rng.standard_normal((n, 2)) * np.array([1.0, 1e8])
    X = native.getrs2t(lu, piv, B)
    assert X is not None and X.shape == (n, 2)
    ref = sla.lapack.dgetrs(lu, piv, B, trans=1)[0]
    for k in range(2):
        scale = np.abs(A.T) @ np.abs(X[:, k]) + np.abs(B[:, k])
        assert np.max(np.abs(A.T @ X[:, k] - B[:, k]) / scale) <= 8 * n * 1.2e-16
        assert np.allclose(X[:, k], ref[:, k], rtol=1e-10, atol=1e-12 * np.abs(ref[:, k]).max())
    assert native.getrs2t(np.ascontiguousarray(lu), piv, B) is None or n == 1
    assert native.getrs2t(lu, piv, np.column_stack([B, B[:, :1]])) is None


@pytest.mark.parametrize("rows, cols, picked", [(5, 1, 1), (9, 7, 3), (500, 401, 6), (2000, 1003, 401)])
def test_two_column_product_with_gathered_rows(kernels, rows, cols, picked):
    """gemv2t (A[idx].T X without gathering A's rows, both columns in one pass) against exact
    products: row counts not multiples of the kernel's four, unsorted and repeated row numbers,
    entries over 10 decades.  Other layouts: None; row numbers out of range: IndexError."""
    rng = np.random.default_rng(rows + picked)
    A = rng.standard_normal((rows, cols)) * np.exp(rng.uniform(-12, 12, (rows, cols)))
    idx = rng.integers(0, rows, picked)
    X = rng.standard_normal((picked, 2))
    Y = native.gemv2t(A, idx, X)
    assert Y is not None and Y.shape == (cols, 2)
    bound = np.abs(A[idx].T) @ np.abs(X)
    exact = np.array([[float(sum(Fraction(A[i, j]) * Fraction(x) for i, x in zip(idx, X[:, k]))) for k in range(2)]
                      for j in range(min(cols, 20))])
    assert np.all(np.abs(Y[:len(exact)] - exact) <= 2 * picked * 1.2e-16 * bound[:len(exact)])
    assert np.all(np.abs(Y - A[idx].T @ X) <= 2 * picked * 1.2e-16 * bound)
    assert native.gemv2t(np.asfortranarray(A), idx, X) is None or rows == 1 or cols == 1
    assert native.gemv2t(A, idx, np.column_stack([X, X[:, :1]])) is None
    with pytest.raises(IndexError, match="outside"):
        native.gemv2t(A, np.append(idx, rows), np.vstack([X, X[:1]]))


@pytest.mark.parametrize("n", [1, 2, 3, 5, 7, 8, 13, 401, 1730])
def test_two_column_symmetric_product(kernels, n):
    """symv2 (A X from A's upper triangle only) against exact products: sizes that are not
    multiples of the kernel's four-row blocks (a scalar last block, rows whose segment right of
    the block starts unaligned), zero rows in X (the multipliers of open nodes), entries over 10
    decades; as accurate as gemv2.  The lower triangle is never read (NaN there changes nothing).
    Other layouts or column counts: None (the caller multiplies)."""
    rng = np.random.default_rng(n)
    G = rng.standard_normal((n, n)) * np.exp(rng.uniform(-12, 12, (n, n)))
    A = np.ascontiguousarray(np.triu(G) + np.triu(G, 1).T)
    X = rng.standard_normal((n, 2))
    X[rng.random(n) < 0.3] = 0.0
    Y = native.symv2(A, X)
    assert Y is not None and Y.shape == (n, 2)
    bound = np.abs(A) @ np.abs(X)
    rows = range(0, n, max(1, n // 25))
    exact = np.array([[float(sum(Fraction(A[i, j]) * Fraction(X[j, k]) for j in range(n))) for k in range(2)]
                      for i in rows])
    assert np.all(np.abs(Y[list(rows)] - exact) <= 4 * n * 1.2e-16 * bound[list(rows)])
    assert np.all(np.abs(Y - A @ X) <= 2e-15 * bound)
    if n >= 401:  # as accurate as the full product (four partial sums, not one chain per entry)
        err = lambda Z: np.max(np.abs(Z[list(rows)] - exact) / np.maximum(bound[list(rows)], 1e-300))
        assert err(Y) <= 2.0 * err(native.gemv2(A, X)) + 1e-17
    lower = A.copy()
    lower[np.tril_indices(n, -1)] = np.nan
    assert np.array_equal(native.symv2(lower, X), Y)
    assert native.symv2(np.asfortranarray(A), X) is None or n == 1
    assert native.symv2(A, np.column_stack([X, X[:, :1]])) is None
    assert native.symv2(A[:, :-1].copy(), X[:-1]) is None or n == 1


def _mixed_system(m=24, seed=3):
    """A random lumped model whose nodes have F > 0, F = 0 and (two) no tangential unknown."""
    from cfcontact.system import ContactSystem

    rng = np.random.default_rng(seed)
    n = 2 * m + 3
    A = rng.standard_normal((n, n))
    K = A @ A.T / n + np.eye(n)
    N = np.zeros((m, n))
    T = np.zeros((m, n))
    for i in range(m):
        T[i, 2 * i], N[i, 2 * i + 1] = 1.0, 1.0
    T[[4, 11]] = 0.0  # no tangential unknown
    F = rng.uniform(0.1, 3.0, m)
    F[[2, 7]] = 0.0
    return ContactSystem.from_arrays(K, N, T, rng.standard_normal(n), rng.standard_normal(n), F)


def test_compiled_branch_data_equals_numpy_and_lapack(kernels, monkeypatch):
    """cfc_branch_small (reduced matrix, unblocked LU, solve, one refinement step, indicators in
    one call) against CondensedSolver.branch_data's NumPy/LAPACK path on 200 random states of a
    model with frictionless and tangent-free nodes: the same multipliers and indicators to
    rounding, the same kept factorization (its rows, slipping nodes and coefficients; its LU
    solves as LAPACK's does), the refinement's change of the indicators at rounding level; a
    cached factorization is used as formed; singular states are refused both ways."""
    import cfcontact
    from cfcontact import condensed
    from cfcontact.condensed import CondensedSolver
    from cfcontact.exact import canonical_codes, sets_from_codes
    from cfcontact.ssnm import SolverOptions

    system = _mixed_system()
    m = system.m
    compiled = CondensedSolver(system, SolverOptions(updates=False))
    plain = CondensedSolver(system, SolverOptions(updates=False))
    assert compiled._branch_kernel() is not None
    W = compiled.load_data_many(list(system.loads_numpy()))
    W = np.ascontiguousarray(np.column_stack([0.6 * W[:, 0] + 0.4 * W[:, 1], W[:, 1] - W[:, 0]]))
    rng = np.random.default_rng(0)
    checked = 0
    for t in range(200):
        codes = rng.integers(0, 4, m).astype(np.int8)
        codes = canonical_codes(sets_from_codes(codes), system.friction, system.no_tangent).astype(np.int8)
        key = b"t" + codes.tobytes()
        monkeypatch.setattr(condensed, "BRANCH_KERNEL_MAX_ROWS", 0)
        try:
            Lp, Gp, Ep = plain.branch_data(W, key, codes, refine=True)
        except cfcontact.SingularSystemError:
            monkeypatch.setattr(condensed, "BRANCH_KERNEL_MAX_ROWS", 10 ** 9)
            with pytest.raises(cfcontact.SingularSystemError):
                compiled.branch_data(W, key, codes, refine=True)
            continue
        monkeypatch.setattr(condensed, "BRANCH_KERNEL_MAX_ROWS", 10 ** 9)
        n0 = compiled.stats.dense_factorizations
        Lc, Gc, Ec = compiled.branch_data(W, key, codes, refine=True)
        assert compiled.stats.dense_factorizations == n0 + 1
        scale = np.abs(Lp).max(axis=0) + system.rho * np.abs(W).max(axis=0)
        assert np.all(np.abs(Lc - Lp) <= 1e-12 * scale)
        assert np.all(np.abs(Gc - Gp) <= 1e-12 * scale)
        assert np.all(Ec <= 1e-12 * scale) and np.all(Ep <= 1e-12 * scale)
        (luc, pivc, rc, sc, cc, supc), (lup, pivp, rp, sp_, cp, supp) = compiled._lu[key], plain._lu[key]
        for a, b in ((rc, rp), (sc, sp_), (cc, cp), (supc, supp)):
            np.testing.assert_array_equal(a, b)
        B = rng.standard_normal((rc.size, 2))
        np.testing.assert_allclose(sla.lu_solve((luc, pivc), B, trans=1), sla.lu_solve((lup, pivp), B, trans=1),
                                   rtol=1e-9, atol=1e-12 * np.abs(B).max())
        again = compiled.branch_data(W, key, codes, refine=True)  # from the kept factorization
        assert compiled.stats.dense_factorizations == n0 + 1
        for a, b in zip(again, (Lc, Gc, Ec)):
            np.testing.assert_array_equal(a, b)
        checked += 1
    assert checked > 100


def _line_model(seed):
    from cfcontact import exact
    from cfcontact.condensed import CondensedSolver
    from cfcontact.ssnm import SolverOptions

    system = _mixed_system(seed=seed)
    solver = CondensedSolver(system, SolverOptions(updates=False))
    W = solver.load_data_many(list(system.loads_numpy()))
    kinds = np.ascontiguousarray(exact.node_kinds(system), dtype=np.int64)
    return system, solver, exact._CondensedData(solver, W), kinds


def _random_codes(system, rng):
    from cfcontact.exact import canonical_codes, sets_from_codes

    codes = rng.integers(0, 4, system.m).astype(np.int8)
    return canonical_codes(sets_from_codes(codes), system.friction, system.no_tangent).astype(np.int8)


def test_compiled_line_equals_numpy(kernels, monkeypatch):
    """A branch of the exact method formed with the compiled kernels (cfc_branch_line: the
    branch, its per-indicator scales and data floors, tolerances and constraints in one call)
    against the NumPy/LAPACK form (exact._CondensedData.make_line without the kernels), on random
    states of a model with frictionless and tangent-free nodes: the same constraints, values,
    rates and tolerances to rounding (the multipliers' solves differ in their rounding only)."""
    import cfcontact
    from cfcontact import condensed, exact

    system, solver, data, kinds = _line_model(8)
    rng = np.random.default_rng(2)
    calls = []
    fused = native.BranchKernel.line
    monkeypatch.setattr(native.BranchKernel, "line", lambda *a: calls.append(1) or fused(*a))
    checked = 0
    for t in range(60):
        codes = _random_codes(system, rng)
        key, alpha = b"s" + codes.tobytes(), float(rng.uniform(-1.0, 2.0))
        solver._lu.clear()
        n0 = len(calls)
        try:
            ln = data.make_line(codes, key, alpha, 1e-10, kinds)
        except cfcontact.SingularSystemError:
            continue
        assert len(calls) == n0 + 1  # (formed by the fused kernel)
        with monkeypatch.context() as mp:
            mp.setattr(condensed, "BRANCH_KERNEL_MAX_ROWS", 0)
            mp.setattr(native, "line_scales", lambda *a: None)
            solver._lu.clear()
            ref = data.make_line(codes, key, alpha, 1e-10, kinds)
        for name in ("cidx", "cnode", "csgn"):
            np.testing.assert_array_equal(getattr(ln, name), getattr(ref, name))
        size = np.abs(ref.lam).max() + system.rho * np.abs(data.w1).max() + np.abs(data.w2).max()
        for name in ("lam", "dlam", "g", "dg", "c", "dc"):
            assert np.all(np.abs(getattr(ln, name) - getattr(ref, name)) <= 1e-12 * size), name
        for name in ("ind_tv", "ind_ts", "tol_v", "tol_s"):  # (they hold the refinement's measured rounding,
            np.testing.assert_allclose(getattr(ln, name), getattr(ref, name), rtol=1e-2, err_msg=name)  # its own)
        assert ln.scale == pytest.approx(ref.scale, rel=1e-12)
        assert np.any(ref.ind_tv > 1e-10 * ref.scale)  # (the data floors and error estimates count)
        checked += 1
    assert checked > 30


def test_compiled_constraints_give_the_numpy_bits(kernels):
    """cfc_line_constraints (tolerances and constraints of a branch from its scales) and the same
    in the fused branch kernel against exact._Line's NumPy arithmetic on the same inputs:
    bitwise equal (the same operations in the same order)."""
    import cfcontact
    from cfcontact import exact

    system, solver, data, kinds = _line_model(5)
    kernel = solver._branch_kernel()
    m = system.m
    rng = np.random.default_rng(7)
    request = native.LineRequest(data.sqrt_diag, kinds, exact._CONS_SIGN, exact.DATA_ULPS * exact._EPS * system.rho,
                                 3e-10, exact.ERROR_FACTOR)
    checked = 0
    for t in range(60):
        codes = _random_codes(system, rng)
        alpha = float(rng.uniform(-3.0, 3.0))
        W = np.ascontiguousarray(np.column_stack([(1 - alpha) * data.w1 + alpha * data.w2, data.dw]))
        imposed = solver.imposed_rows(codes)
        around = exact.ALPHA_ULPS * exact._alpha_ulp(alpha)
        res = kernel.line(imposed, codes, W, system.rho, None, request, around)
        if res is None:
            continue
        _, L, G, E, (fused, inputs) = res
        # the addresses the ordinary step reads are those of the returned arrays
        assert inputs == native.OrdinaryStep.inputs(fused[5], fused[6], fused[7], fused[8], fused[2], fused[4],
                                                    G[:, 0], G[:, 1], fused[0], fused[1], codes)
        scales = native.line_scales(W, L, data.sqrt_diag, imposed, system.rho, request.unit)
        alone = native.line_constraints(scales, codes, kinds, exact._CONS_SIGN, G, E, 3e-10, exact.ERROR_FACTOR, around)
        ref = exact._Line(codes, b"", alpha, L[:, 0], L[:, 1], G[:, 0], G[:, 1], scales[0], scales[1], 3e-10, kinds,
                          eg=E, floor=(scales[2], scales[3]))
        expect = (ref.ind_tv, ref.ind_ts, ref.cidx, ref.csgn, ref.cnode, ref.c, ref.dc, ref.tol_v, ref.tol_s, ref.scale)
        for got in (alone, fused):
            for a, b in zip(got, expect):
                np.testing.assert_array_equal(a, b)
        assert alone[2].size == np.count_nonzero(exact._CONS_SIGN[codes, kinds])
        checked += 1
    assert checked > 30
    with pytest.raises(ValueError):
        native.line_constraints(scales, np.full(m, 7, dtype=np.int8), kinds, exact._CONS_SIGN, G, E, 1e-10, 16.0, 0.0)


def test_compiled_first_root_gives_the_numpy_bits(monkeypatch):
    """The first root of a branch's decreasing constraints (cfc_exit) against exact._exit's NumPy
    arithmetic on random branches with repeated roots, roots behind the start, flat constraints
    and roots beyond the end of the range: the same alpha*, tied set and uncertainty, bitwise."""
    from types import SimpleNamespace

    from cfcontact import exact

    rng = np.random.default_rng(11)
    seen = {"none": 0, "tied": 0, "single": 0}
    for t in range(400):
        k = int(rng.integers(1, 40))
        ln = exact._Line.__new__(exact._Line)
        ln.alpha = float(rng.uniform(-1, 1))
        ln.dc = rng.standard_normal(k) * 10.0 ** rng.integers(-3, 3, k)
        ln.dc[rng.random(k) < 0.2] = 0.0
        roots = rng.choice(rng.uniform(-0.5, 2.0, 4), k)  # (repeated roots)
        ln.c = -ln.dc * (roots - ln.alpha)
        ln.tol_v = 1e-12 * rng.random(k)
        ln.tol_s = 1e-12 * rng.random(k)
        ctx = SimpleNamespace(lo=-1.0, hi=float(rng.uniform(0.5, 3.0)))
        s = int(rng.choice([-1, 1]))
        alpha0 = ln.alpha + float(rng.uniform(0, 0.3)) * s
        got = exact._exit(ctx, ln, alpha0, s)
        with monkeypatch.context() as mp:
            mp.setattr(native, "first_root", lambda *a: False)
            ref = exact._exit(ctx, ln, alpha0, s)
        assert type(got[0]) is type(ref[0]) and got[0] == ref[0] and got[2] == ref[2]
        if ref[0] is None:
            seen["none"] += 1
        else:
            np.testing.assert_array_equal(got[1], ref[1])
            seen["tied" if ref[1].size > 1 else "single"] += 1
    assert min(seen.values()) > 20, seen


def _spd(n, seed, density=0.02):
    """A sparse SPD matrix on a random graph (its RCM envelope is not a band of the given order),
    scaled over eight decades (diagonal scaling keeps it SPD)."""
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=density, random_state=seed, format="csr")
    A = A + A.T
    A = (A + sp.diags(np.abs(A).sum(axis=1).A1 + 1.0)).tocsr()
    d = sp.diags(np.exp(rng.uniform(-9, 9, n)))
    return (d @ A @ d).tocsr()


@pytest.mark.parametrize("n,seed", [(1, 0), (7, 1), (120, 2), (400, 3)])
def test_envelope_cholesky_against_dense_solves(kernels, n, seed):
    """linalg.EnvelopeCholesky (cfcontact.native's kernels) against NumPy's dense solve: solves of
    one and of several columns (one by one, two at a time, and row-major in one and in several
    blocks), and the forward substitutions of sparse rows -- some empty, some starting late in RCM
    order -- with dense columns beside: their Gram matrix [B; f^T] A^-1 [B^T, f], and the backward
    substitution of a column."""
    A = _spd(n, seed)
    E = linalg.EnvelopeCholesky.factor(A)
    assert E is not None and E.entries >= n
    Ad = A.toarray()
    rng = np.random.default_rng(seed)
    b = rng.standard_normal((n, 7))
    x_ref = np.linalg.solve(Ad, b)
    tol = 1e-9 * np.abs(x_ref).max()
    assert np.abs(E.solve(b) - x_ref).max() <= tol
    assert np.abs(E.solve(b[:, 3]) - x_ref[:, 3]).max() <= tol
    # two columns at a time, interleaved (fewer than SOLVE_ROWS_MIN_COLUMNS): the bits of single solves
    ones = np.column_stack([E.solve(b[:, j]) for j in range(7)])
    assert np.array_equal(E.solve(b), ones) and np.array_equal(E.solve(np.asfortranarray(b[:, 2:4])), ones[:, 2:4])
    with pytest.MonkeyPatch.context() as mp:  # the seven columns row-major too
        mp.setattr(linalg, "SOLVE_ROWS_MIN_COLUMNS", 2)
        assert np.abs(E.solve(b) - x_ref).max() <= tol
    # more columns than one group of the row-major kernels (native.ENV_ROW_COLS), in several blocks
    wide = rng.standard_normal((n, 2 * native.ENV_ROW_COLS + 5))
    ref = np.linalg.solve(Ad, wide)
    for entries in (linalg.SOLVE_BLOCK_ENTRIES, 1):
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(linalg, "SOLVE_BLOCK_ENTRIES", entries)
            assert np.abs(E.solve(wide) - ref).max() <= 1e-9 * np.abs(ref).max()
    k = 9
    B = sp.random(k, n, density=min(1.0, 3.0 / n), random_state=seed + 1, format="lil")
    B[0, :] = 0.0
    B[0, n - 1] = 2.0  # a row whose only entry may come last in RCM order
    if k > 3:
        B[3, :] = 0.0  # an empty row: its column of Y stays zero
    B = sp.csr_matrix(B)
    f = rng.standard_normal((2, n))
    G, y0 = E.forward_gram(B, list(f))
    assert G.shape == (k + 2, k + 2) and np.array_equal(G, G.T)
    Bd = B.toarray()
    Y = np.linalg.solve(Ad, np.column_stack([Bd.T, f.T]))
    ref = np.vstack([Bd, f]) @ Y
    assert np.abs(G - ref).max() <= 1e-9 * np.abs(ref).max()
    assert not G[3].any()
    z = E.backward_row(y0)
    assert np.abs(z - Y[:, 0]).max() <= 1e-9 * np.abs(Y[:, 0]).max()
    # more columns than one group of the kernel (native.ENV_ROW_COLS), some starting late
    B2 = sp.random(2 * native.ENV_ROW_COLS + 3, n, density=min(1.0, 2.0 / n), random_state=seed + 2, format="csr")
    G2, _ = E.forward_gram(B2)
    B2d = B2.toarray()
    ref2 = B2d @ np.linalg.solve(Ad, B2d.T)
    assert np.abs(G2 - ref2).max() <= 1e-9 * max(np.abs(ref2).max(), 1e-300)
    # an order given by the caller: its own RCM order gives the same factor, any order the solves
    same = linalg.EnvelopeCholesky.factor(A, linalg.rcm_order(A))
    assert np.array_equal(same._v, E._v) and np.array_equal(same.perm, E.perm)
    assert linalg.rcm_envelope(A, same.perm) == linalg.rcm_envelope(A) == E.entries
    other = linalg.EnvelopeCholesky.factor(A, rng.permutation(n))
    assert np.abs(other.solve(b) - x_ref).max() <= tol


def test_envelope_cholesky_refuses_what_is_not_positive_definite(kernels):
    """A singular and an indefinite matrix: SingularSystemError naming the DOF where the
    factorization broke down; a matrix that is not square: ValueError."""
    from cfcontact.errors import SingularSystemError

    A = _spd(30, 4).tolil()
    A[5, :] = 0.0
    A[:, 5] = 0.0
    with pytest.raises(SingularSystemError, match="DOF 5 "):
        linalg.EnvelopeCholesky.factor(A.tocsr())
    A = sp.diags([1.0, -2.0, 3.0]).tocsr()
    with pytest.raises(SingularSystemError, match="not positive definite.*DOF 1 "):
        linalg.EnvelopeCholesky.factor(A)
    with pytest.raises(ValueError, match="square"):
        linalg.EnvelopeCholesky.factor(sp.csr_matrix(np.ones((2, 3))))
    for perm in (np.arange(2), np.array([0, 2, 2]), np.array([0, 1, 3])):
        with pytest.raises(ValueError, match=r"permutation of 0 \.\. 2 \(K has 3 rows\), got"):
            linalg.EnvelopeCholesky.factor(A, perm)


def test_envelope_cholesky_needs_the_compiled_kernels(monkeypatch):
    """Without them: None (the condensed backend lets PETSc factor K then)."""
    monkeypatch.setattr(native, "_tried", True)
    monkeypatch.setattr(native, "_lib", None)
    assert linalg.EnvelopeCholesky.factor(_spd(10, 5)) is None
