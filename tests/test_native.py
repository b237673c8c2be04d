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


def test_compiled_kernel_gives_the_numpy_bits(fresh_native, monkeypatch):
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


def test_compiled_kernel_against_rational_arithmetic(fresh_native):
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


def test_the_cache_is_reused_and_keyed(fresh_native, monkeypatch):
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


def test_without_a_compiler_numpy_is_used(fresh_native, monkeypatch, caplog):
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
def test_two_column_product(rows, cols):
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
def test_two_column_transposed_lu_solve(n):
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
def test_two_column_product_with_gathered_rows(rows, cols, picked):
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
def test_two_column_symmetric_product(n):
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


def test_compiled_branch_data_equals_numpy_and_lapack(monkeypatch):
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


def test_compiled_line_scales_equal_numpy(monkeypatch):
    """The exact method's per-indicator scales and data floors of a branch (cfc_line_scales)
    against the NumPy form of exact._CondensedData.line, on random states of a model with
    frictionless and tangent-free nodes (values and rates of the data of different sizes)."""
    from cfcontact import exact
    from cfcontact.condensed import CondensedSolver
    from cfcontact.exact import canonical_codes, sets_from_codes
    from cfcontact.ssnm import SolverOptions

    system = _mixed_system(seed=8)
    solver = CondensedSolver(system, SolverOptions(updates=False))
    W = solver.load_data_many(list(system.loads_numpy()))
    data = exact._CondensedData(solver, W)
    rng = np.random.default_rng(2)
    for t in range(40):
        codes = rng.integers(0, 4, system.m).astype(np.int8)
        codes = canonical_codes(sets_from_codes(codes), system.friction, system.no_tangent).astype(np.int8)
        key, alpha = b"s" + codes.tobytes(), float(rng.uniform(-1.0, 2.0))
        try:
            with_kernel = data.line(codes, key, alpha)
        except Exception as exc:  # (a singular state: the same both ways)
            monkeypatch.setattr(native, "line_scales", lambda *a: None)
            with pytest.raises(type(exc)):
                data.line(codes, key, alpha)
            monkeypatch.undo()
            continue
        monkeypatch.setattr(native, "line_scales", lambda *a: None)
        plain = data.line(codes, key, alpha)
        monkeypatch.undo()
        # (lam, dlam, g, dg, scale_v, scale_s, full, source, eg, floor)
        for i in (0, 1, 2, 3, 4, 5, 8):
            np.testing.assert_allclose(with_kernel[i], plain[i], rtol=1e-13, atol=0)
        for a, b in zip(with_kernel[9], plain[9]):
            np.testing.assert_array_equal(a, b)
        assert np.all(plain[4] > 0) and np.any(plain[9][0] == 0) and np.any(plain[9][0] > 0)
