"""Extrinsic parameters: quaternion + translation applied to frames (ROS-free)."""

import numpy as np
import pytest

from clusterfilter_ros.core.frame import Frame
from clusterfilter_ros.errors import ParameterError
from clusterfilter_ros.ros.transforms import Extrinsic


def test_identity_returns_same_frame():
    f = Frame(0.0, "avia", np.ones((4, 3), np.float32))
    assert Extrinsic.from_list([0, 0, 0, 0, 0, 0, 1]).apply(f) is f


def test_rotation_about_z_and_translation():
    s = np.sqrt(0.5)
    ext = Extrinsic.from_list([1.0, 2.0, 3.0, 0.0, 0.0, s, s])  # 90 deg about z
    f = Frame(0.0, "mid360", np.array([[1, 0, 0], [0, 1, 0]], np.float32))
    out = ext.apply(f).xyz
    np.testing.assert_allclose(out, [[1, 3, 3], [0, 2, 3]], atol=1e-6)
    assert out.dtype == np.float32


def test_quaternion_is_normalised():
    a = Extrinsic.from_list([0, 0, 0, 0, 0, 2, 2])
    b = Extrinsic.from_list([0, 0, 0, 0, 0, np.sqrt(0.5), np.sqrt(0.5)])
    np.testing.assert_allclose(a.rotation, b.rotation, atol=1e-12)


@pytest.mark.parametrize(
    "values, match",
    [([0, 0, 0, 0, 0, 0, 0], "zero quaternion"), ([0, 0, 0], "7 values"), ([np.nan] * 7, "finite")],
)
def test_bad_extrinsic_names_parameter(values, match):
    with pytest.raises(ParameterError, match=match):
        Extrinsic.from_list(values, "avia_extrinsic")
