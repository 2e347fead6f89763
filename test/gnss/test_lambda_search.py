"""LAMBDA integer least squares against an exhaustive search (independent truth)."""
import itertools

import numpy as np
import pytest

from ins_gnss_ros.gnss.lambda_search import (
    decorrelate, enumerate_ellipsoid, integer_least_squares, ltdl, partial_fix, ratio_test)

_MAX_BOX = 200_000


def _sqnorm(a_float, Qinv, cands):
    r = a_float - cands
    return np.einsum("ij,jk,ik->i", r, Qinv, r)


def brute_force_ils(a_float, Q, extra_seeds):
    """Two nearest integer vectors by enumerating a box that provably contains them.

    The second-smallest distance among any set of distinct integer vectors (here the rounded
    vector, its 2n unit neighbours and ``extra_seeds``) bounds the runner-up's distance chi²;
    any a with ||â - a||²_Q <= chi² has |a_i - â_i| <= sqrt(chi² Q_ii), so the box of those
    half-widths holds the best two whatever the seeds were. Returns None if the box is too big.
    """
    n = a_float.size
    Qinv = np.linalg.inv(Q)
    r = np.rint(a_float)
    seeds = np.unique(np.vstack([r, r + np.eye(n), r - np.eye(n), extra_seeds]), axis=0)
    chi2 = np.sort(_sqnorm(a_float, Qinv, seeds))[1] * (1 + 1e-9)
    half = np.sqrt(chi2 * np.diag(Q))
    ranges = [np.arange(np.ceil(a - h), np.floor(a + h) + 1) for a, h in zip(a_float, half)]
    size = np.prod([len(x) for x in ranges])
    if size > _MAX_BOX:
        return None
    grid = np.array(list(itertools.product(*ranges)))
    dist = _sqnorm(a_float, Qinv, grid)
    i = np.argsort(dist)[:2]
    return grid[i], dist[i]


def _random_problem(rng):
    n = int(rng.integers(2, 7))
    kind = rng.integers(3)
    if kind == 0:      # well conditioned
        A = rng.normal(size=(n, n))
        Q = A @ A.T * rng.uniform(0.02, 0.5) + 0.01 * np.eye(n)
    elif kind == 1:    # float ambiguities of a short baseline: 3 geometry directions dominate
        G = rng.normal(size=(n, 3))
        Q = G @ np.diag(rng.uniform(0.5, 5.0, 3)) @ G.T + rng.uniform(1e-4, 1e-2) * np.eye(n)
    else:              # strongly correlated (condition number up to ~1e6)
        V, _ = np.linalg.qr(rng.normal(size=(n, n)))
        ev = 10.0 ** rng.uniform(-4, 1, n)
        Q = V @ np.diag(ev) @ V.T
    a_float = rng.uniform(-50, 50, n)
    return a_float, 0.5 * (Q + Q.T)


def test_ltdl_reconstructs_covariance():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(6, 6))
    Q = A @ A.T + np.eye(6)
    L, d = ltdl(Q)
    assert np.allclose(np.triu(L, 1), 0.0) and np.allclose(np.diag(L), 1.0)
    assert np.allclose(L.T @ np.diag(d) @ L, Q)
    # The last conditional variance is a marginal one.
    assert np.isclose(d[-1], Q[-1, -1])


def test_ltdl_rejects_indefinite():
    with pytest.raises(np.linalg.LinAlgError):
        ltdl(np.array([[1.0, 2.0], [2.0, 1.0]]))


def test_decorrelation_is_unimodular_and_consistent():
    rng = np.random.default_rng(2)
    for _ in range(50):
        a, Q = _random_problem(rng)
        Z, L, d, zf = decorrelate(Q, a)
        assert abs(round(np.linalg.det(Z))) == 1
        assert np.allclose(Z.T @ Q @ Z, L.T @ np.diag(d) @ L, rtol=1e-8, atol=1e-10)
        assert np.allclose(zf, Z.T @ a)
        assert np.all(np.abs(np.tril(L, -1)) <= 0.5 + 1e-9)


def test_lambda_matches_brute_force_on_random_problems():
    rng = np.random.default_rng(12345)
    checked, conds = 0, []
    while checked < 1200:
        a, Q = _random_problem(rng)
        res = integer_least_squares(a, Q)
        # LAMBDA's own candidates only tighten the box; the enumeration stays exhaustive.
        bf = brute_force_ils(a, Q, res.candidates)
        if bf is None:             # box too large to enumerate: draw another problem
            continue
        np.testing.assert_array_equal(res.best, bf[0][0])
        np.testing.assert_allclose(res.sqnorms, bf[1], rtol=1e-7, atol=1e-9)
        assert res.ratio == pytest.approx(bf[1][1] / bf[1][0], rel=1e-7)
        checked += 1
        conds.append(np.linalg.cond(Q))
    assert max(conds) > 1e4     # the accepted set does include ill-conditioned problems


def test_more_candidates_are_sorted_and_distinct():
    rng = np.random.default_rng(3)
    a, Q = _random_problem(rng)
    res = integer_least_squares(a, Q, n_candidates=10)
    assert np.all(np.diff(res.sqnorms) >= 0)
    assert len({tuple(c) for c in res.candidates}) == 10
    np.testing.assert_allclose(res.sqnorms, _sqnorm(a, np.linalg.inv(Q), res.candidates),
                               rtol=1e-8)


def test_ratio_test_and_partial_fixing_recover_truth():
    rng = np.random.default_rng(4)
    n = 8
    a_true = rng.integers(-1000, 1000, n)
    # Six precise ambiguities (0.05 cycle) and two poor ones (1.5 cycles), correlated.
    sig = np.r_[np.full(6, 0.05), 1.5, 1.5]
    C = 0.3 * np.ones((n, n)) + 0.7 * np.eye(n)
    Q = np.outer(sig, sig) * C
    a_float = a_true + np.linalg.cholesky(Q) @ rng.normal(size=n)
    full = integer_least_squares(a_float, Q)
    assert not ratio_test(full, 3.0)
    pf = partial_fix(a_float, Q, threshold=3.0, min_fixed=3)
    assert pf is not None and pf.ratio >= 3.0 and pf.values.size >= 6
    np.testing.assert_array_equal(pf.values, pf.combinations.T @ a_true)


def test_enumerate_ellipsoid_finds_every_vector_inside():
    rng = np.random.default_rng(6)
    done = 0
    while done < 200:
        a, Q = _random_problem(rng)
        chi2 = rng.uniform(0.5, 10.0)
        half = np.sqrt(chi2 * np.diag(Q))
        ranges = [np.arange(np.ceil(x - h), np.floor(x + h) + 1) for x, h in zip(a, half)]
        if np.prod([len(r) for r in ranges]) > _MAX_BOX:
            continue
        grid = np.array(list(itertools.product(*ranges))).reshape(-1, a.size)
        dist = _sqnorm(a, np.linalg.inv(Q), grid)
        inside = {tuple(g) for g in grid[dist < chi2]}
        cands, sq, complete = enumerate_ellipsoid(a, Q, chi2)
        assert complete and {tuple(c) for c in cands} == inside
        assert np.all(np.diff(sq) >= 0) and np.all(sq < chi2)
        done += 1
    cands, _, complete = enumerate_ellipsoid(np.zeros(3), np.eye(3), 50.0, max_count=10)
    assert not complete and len(cands) == 10
