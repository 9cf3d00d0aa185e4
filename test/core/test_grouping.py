"""Per-group extremes by one sort equal the ufunc.at reference, empty groups included."""

from __future__ import annotations

import numpy as np
import pytest

from clusterfilter_ros.core.grouping import group_bounds, lex_order, stable_order


def test_group_bounds_match_ufunc_at():
    rng = np.random.default_rng(3)
    k = 50
    ids = rng.integers(0, k - 5, 2000)  # the last five groups stay empty
    xyz = rng.normal(size=(2000, 3)).astype(np.float32)
    t = rng.uniform(0, 10, 2000)
    (lo, hi), (tlo, thi) = group_bounds(ids, k, xyz, t)
    ref_lo, ref_hi = np.full((k, 3), np.inf), np.full((k, 3), -np.inf)
    np.minimum.at(ref_lo, ids, xyz)
    np.maximum.at(ref_hi, ids, xyz)
    ref_tlo, ref_thi = np.full(k, np.inf), np.full(k, -np.inf)
    np.minimum.at(ref_tlo, ids, t)
    np.maximum.at(ref_thi, ids, t)
    assert lo.dtype == np.float64 and lo.shape == (k, 3) and tlo.shape == (k,)
    for got, ref in ((lo, ref_lo), (hi, ref_hi), (tlo, ref_tlo), (thi, ref_thi)):
        assert np.array_equal(got, ref)
    assert np.all(np.isinf(lo[-5:])) and np.all(lo[-5:] > 0) and np.all(hi[-5:] < 0)


def test_group_bounds_of_nothing():
    ((lo, hi),) = group_bounds(np.empty(0, np.int64), 3, np.empty((0, 3)))
    assert lo.shape == (3, 3) and np.all(lo == np.inf) and np.all(hi == -np.inf)
    assert group_bounds(np.array([0, 1]), 2) == []


@pytest.mark.parametrize("high", [1, 300, 65_536, 70_000])
def test_stable_order_and_lex_order_equal_numpy(high):
    rng = np.random.default_rng(high)
    ids = rng.integers(0, high, 5000)
    t = np.round(rng.uniform(0, 2, 5000), 1)  # many ties: the stable order must hold
    t[::97] = np.nan
    assert np.array_equal(stable_order(ids), np.argsort(ids, kind="stable"))
    assert np.array_equal(lex_order(t, ids), np.lexsort((t, ids)))
    negative = ids - high // 2
    assert np.array_equal(stable_order(negative), np.argsort(negative, kind="stable"))
    assert np.array_equal(lex_order(t, negative), np.lexsort((t, negative)))


def test_stable_order_of_nothing():
    assert stable_order(np.empty(0, np.int64)).size == 0
    assert lex_order(np.empty(0), np.empty(0, np.int64)).size == 0
