"""Evaluator metrics on hand-computed cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from clusterfilter_ros.core.evaluation import (
    acquisition,
    evaluate,
    false_alarm_seconds,
    interpolate_predictions,
    observable_mask,
)
from clusterfilter_ros.core.frame import TimedPositions


def tp(stamps, xyz):
    return TimedPositions(np.asarray(stamps, float), np.asarray(xyz, float))


def test_interpolation_rule():
    pred = tp([0.0, 0.2, 1.0], [[0, 0, 0], [2, 0, 0], [10, 0, 0]])
    out = interpolate_predictions(pred, np.array([0.1, 0.2, 0.6, -0.1, 1.2]), max_gap=0.3)
    assert np.allclose(out[0], [1, 0, 0])  # halfway between rows 0 and 1
    assert np.allclose(out[1], [2, 0, 0])  # exact match
    assert np.isnan(out[2]).all()  # neighbours 0.4 s away
    assert np.isnan(out[3]).all() and np.isnan(out[4]).all()  # outside the span


def test_metrics_hand_computed():
    gt = tp([0, 1, 2, 3, 4], [[0, 0, 0]] * 5)
    # Predictions at the GT stamps with errors 1, 3, 0 (3D), none at 3 and 4.
    pred = tp([0, 1, 2], [[1, 0, 0], [0, 3, 0], [0, 0, 0]])
    r = evaluate(pred, gt, max_gap=0.3, hit_radius=2.0)
    assert r.n_gt == 5 and r.n_matched == 3
    assert r.coverage == pytest.approx(0.6)
    assert r.detection_rate == pytest.approx(0.4)  # errors 1 and 0 are within 2 m
    assert r.mean_error == pytest.approx(4 / 3)
    assert r.mse == pytest.approx(10 / 3)
    assert r.rmse == pytest.approx(math.sqrt(10 / 3))
    assert r.median_error == pytest.approx(1.0)
    assert r.p95_error == pytest.approx(np.percentile([1, 3, 0], 95))
    # The prediction 3 m off is a false alarm; the next row is 1 s later, so it
    # covers min(1, max_gap) = 0.3 s.
    assert r.false_alarm_seconds == pytest.approx(0.3)
    d = r.as_dict()
    assert d["coverage"] == pytest.approx(0.6) and "errors" not in d


def test_observable_mask_and_rate():
    gt = tp([0, 1, 2, 3], [[0, 0, 0]] * 4)
    pred = tp([0, 1], [[0, 0, 0], [0, 0, 0]])
    obs = observable_mask(gt.stamps, hit_stamps=np.array([0.1, 0.9, 1.2]), window=1.0)
    assert obs.tolist() == [True, True, False, False]
    r = evaluate(pred, gt, observable=obs)
    assert r.n_observable == 2 and r.observable_detection_rate == 1.0
    assert r.detection_rate == 0.5
    with pytest.raises(ValueError):
        evaluate(pred, gt, observable=np.ones(3, bool))


def test_drone_free_false_alarms():
    empty_gt = tp(np.empty(0), np.empty((0, 3)))
    pred = tp([10.0, 10.1, 10.2, 15.0], [[0, 0, 20]] * 4)
    assert false_alarm_seconds(pred, 0.3) == pytest.approx(0.1 + 0.1 + 0.3 + 0.3)
    r = evaluate(pred, empty_gt, duration=20.0)
    assert r.false_alarm_seconds == pytest.approx(0.8)
    assert r.false_alarm_fraction == pytest.approx(0.04)
    assert math.isnan(r.coverage) and r.as_dict()["rmse"] is None
    quiet = evaluate(tp(np.empty(0), np.empty((0, 3))), empty_gt, duration=20.0)
    assert quiet.false_alarm_seconds == 0.0 and quiet.false_alarm_fraction == 0.0


def test_false_alarms_near_the_ends_of_the_ground_truth():
    gt = tp([1.0, 1.1, 1.2], [[0, 0, 10], [0.1, 0, 10], [0.2, 0, 10]])
    # Just before / after the GT, on the drone: not a false alarm.
    near = evaluate(tp([0.95, 1.0, 1.25], [[0, 0, 10], [0, 0, 10], [0.2, 0, 10]]), gt)
    assert near.false_alarm_seconds == 0.0
    # Just before the GT but 5 m off, and long before it: both are false alarms.
    off = evaluate(tp([0.0, 0.95], [[0, 0, 10], [5, 0, 10]]), gt, duration=10.0)
    assert off.false_alarm_seconds == pytest.approx(0.3 + 0.3)


def test_acquisition_delay_and_tracked_rate():
    # Two appearances (a 3 s gap): hits from 1.0 s in the first, from 11.5 s in the
    # second, where the track drops one sample after acquisition.
    stamps = np.array([0.0, 0.5, 1.0, 1.5, 2.0, 10.0, 10.5, 11.0, 11.5, 12.0, 12.5])
    hit = np.array([0, 0, 1, 1, 1, 0, 0, 0, 1, 0, 1], bool)
    acq = acquisition(stamps, hit, reacquire_gap=2.0)
    assert acq.n_appearances == 2 and acq.n_acquired == 2
    assert acq.delays.tolist() == pytest.approx([1.0, 1.5])
    assert acq.tracked_rate == pytest.approx(5 / 6)
    # A shorter gap than reacquire_gap keeps one appearance.
    one = acquisition(stamps, hit, reacquire_gap=10.0)
    assert one.n_appearances == 1 and one.delays.tolist() == pytest.approx([1.0])
    assert one.tracked_rate == pytest.approx(5 / 9)
    missed = acquisition(np.array([0.0, 0.5]), np.zeros(2, bool))
    assert missed.n_appearances == 1 and missed.n_acquired == 0 and missed.delays.size == 0
    assert math.isnan(missed.tracked_rate)
    empty = acquisition(np.empty(0), np.empty(0, bool))
    assert empty.n_appearances == 0 and math.isnan(empty.tracked_rate)


def test_acquisition_in_evaluate_uses_the_observable_samples():
    stamps = np.arange(0.0, 6.0, 0.5)
    gt = tp(stamps, np.zeros((stamps.size, 3)))
    # The drone is observable from 1.0 s; reports start at 2.5 s.
    obs = stamps >= 1.0
    pred = tp(stamps[stamps >= 2.5], np.zeros((int((stamps >= 2.5).sum()), 3)))
    r = evaluate(pred, gt, observable=obs)
    assert r.n_appearances == 1 and r.n_acquired == 1
    assert r.mean_acquisition_delay == pytest.approx(1.5)
    assert r.max_acquisition_delay == pytest.approx(1.5)
    assert r.tracked_detection_rate == 1.0
    d = r.as_dict()
    assert d["mean_acquisition_delay"] == pytest.approx(1.5)
    quiet = evaluate(tp(np.empty(0), np.empty((0, 3))), gt, observable=obs).as_dict()
    assert quiet["n_acquired"] == 0 and quiet["mean_acquisition_delay"] is None


def test_absurd_but_finite_positions_give_infinite_errors_without_warnings():
    import warnings

    t = np.arange(0.0, 1.0, 0.1)
    gt = TimedPositions(t[:-1] + 0.05, np.zeros((t.size - 1, 3)))  # between predictions
    xyz = np.full((t.size, 3), 1e308)
    xyz[::2] *= -1  # neighbours 2e308 apart: their difference overflows
    pred = TimedPositions(t, xyz)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        matched = interpolate_predictions(pred, gt.stamps, 0.3)
        res = evaluate(pred, gt)
    # Halfway between +1e308 and -1e308: about 0 (to rounding), not inf or NaN.
    assert np.isfinite(matched).all() and np.abs(matched).max() < 1e300
    assert res.rmse == np.inf  # reported as infinite, not NaN, and without a warning
    assert res.false_alarm_seconds > 0
