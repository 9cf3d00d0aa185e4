"""The error split tells a trailing estimator (lag) from a scattering one (no lag)."""

from __future__ import annotations

import numpy as np
import pytest


def _straight_flight():
    t = np.arange(0.0, 10.0, 0.01)
    xyz = np.stack([3.0 * t, np.zeros_like(t), np.full_like(t, 20.0)], 1)  # 3 m/s along x
    return t, xyz


def test_an_estimate_from_0_2_s_ago_shows_a_lag_of_0_2_s(benchmark_module):
    ec = benchmark_module("error_components")
    t, xyz = _straight_flight()
    stamps = np.arange(1.0, 9.0, 0.1)
    late = np.stack([3.0 * (stamps - 0.2), np.zeros_like(stamps), np.full_like(stamps, 20.0)], 1)
    c = ec.error_components(stamps, late, t, xyz)
    assert c["hits"] == stamps.size and c["moving"] == stamps.size
    assert c["lag"] == pytest.approx(-0.2, abs=1e-6)
    assert c["along_mean"] == pytest.approx(-0.6, abs=1e-6)
    assert c["along_sd"] == pytest.approx(0.0, abs=1e-6)
    assert c["cross_rms"] == pytest.approx(0.0, abs=1e-6)


def test_scatter_across_the_path_is_not_lag_and_misses_stay_out(benchmark_module):
    ec = benchmark_module("error_components")
    t, xyz = _straight_flight()
    stamps = np.arange(1.0, 9.0, 0.1)
    est = np.stack([3.0 * stamps, np.zeros_like(stamps), np.full_like(stamps, 20.0)], 1)
    est[::2, 1] += 0.3
    est[1::2, 1] -= 0.3
    est[5] += [0.0, 50.0, 0.0]  # another object: not a hit, not in the split
    c = ec.error_components(stamps, est, t, xyz)
    assert c["hits"] == stamps.size - 1
    assert c["lag"] == pytest.approx(0.0, abs=1e-6)
    assert c["cross_rms"] == pytest.approx(0.3, abs=1e-6)
    assert c["rmse"] == pytest.approx(0.3, abs=1e-6)


def test_no_estimates_give_counts_of_zero_and_nan_statistics(benchmark_module):
    ec = benchmark_module("error_components")
    t, xyz = _straight_flight()
    c = ec.error_components(np.empty(0), np.empty((0, 3)), t, xyz)
    assert c["n"] == 0 and c["hits"] == 0
    assert np.isnan(c["rmse"]) and np.isnan(c["lag"])


def test_return_age_counts_the_frames_own_scan_and_is_inf_before_any_return(benchmark_module):
    ec = benchmark_module("error_components")
    returns = np.array([1.05, 2.0, 2.02])
    ages = ec.return_ages(np.array([0.5, 1.0, 1.5, 2.0, 3.0]), returns, horizon=0.1)
    # 0.5: nothing up to 0.6; 1.0: the return at 1.05 lies in its own scan (age -0.05);
    # 1.5: 1.05 is 0.45 s old; 2.0: 2.02 is in its scan; 3.0: 2.02 is 0.98 s old.
    assert np.isinf(ages[0])
    assert ages[1:] == pytest.approx([-0.05, 0.45, -0.02, 0.98])


def test_error_by_age_puts_each_hit_in_its_bin_and_leaves_misses_out(benchmark_module):
    ec = benchmark_module("error_components")
    t, xyz = _straight_flight()
    stamps = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    est = np.stack([3.0 * stamps, np.zeros_like(stamps), np.full_like(stamps, 20.0)], 1)
    est[:, 1] += [0.1, 0.2, 0.4, 0.4, 30.0]  # the last is another object
    ages = np.array([-0.02, 0.05, 0.4, 0.45, 0.05])
    bins = ec.error_by_age(stamps, est, t, xyz, ages, edges=(0.0, 0.1, 0.5))
    assert [b["hits"] for b in bins] == [1, 1, 2, 0]
    assert bins[0]["rmse"] == pytest.approx(0.1)
    assert bins[1]["rmse"] == pytest.approx(0.2)
    assert bins[2]["rmse"] == pytest.approx(0.4)
    assert np.isnan(bins[3]["rmse"])
    assert ec.error_by_age(np.empty(0), np.empty((0, 3)), t, xyz, np.empty(0))[0]["hits"] == 0
