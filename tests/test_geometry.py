import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from gatmo.geometry import (
    compose,
    interpolate_poses,
    inverse,
    path_length_m,
    relative,
    transform_points,
    wrap_angle,
)

pose = st.tuples(
    st.floats(-50, 50), st.floats(-50, 50), st.floats(-np.pi, np.pi)
).map(np.array)


def test_compose_known_answer():
    a = np.array([1.0, 2.0, np.pi / 2])
    b = np.array([1.0, 0.0, 0.0])
    np.testing.assert_allclose(compose(a, b), [1.0, 3.0, np.pi / 2 - 2 * np.pi * 0], atol=1e-12)


@given(pose, pose)
@settings(max_examples=100)
def test_relative_inverts_compose(a, b):
    c = compose(a, b)
    r = relative(a, c)
    np.testing.assert_allclose(r[:2], b[:2], atol=1e-9)
    assert abs(wrap_angle(r[2] - b[2])) < 1e-9


@given(pose)
def test_inverse_is_identity(a):
    e = compose(a, inverse(a))
    np.testing.assert_allclose(e[:2], 0.0, atol=1e-9)
    assert abs(wrap_angle(e[2])) < 1e-9


def test_transform_points_matches_compose():
    T = np.array([2.0, -1.0, 0.3])
    pts = np.array([[1.0, 0.0], [0.0, 2.0]])
    out = transform_points(T, pts)
    for p, o in zip(pts, out, strict=True):
        np.testing.assert_allclose(compose(T, np.array([*p, 0.0]))[:2], o)


def test_interpolate_short_arc_and_clamp():
    stamps = np.array([0.0, 1.0])
    poses = np.array([[0.0, 0.0, np.pi - 0.1], [2.0, 0.0, -np.pi + 0.1]])
    mid = interpolate_poses(stamps, poses, np.array([0.5, -1.0, 3.0]))
    np.testing.assert_allclose(mid[0, :2], [1.0, 0.0])
    assert abs(abs(mid[0, 2]) - np.pi) < 1e-9  # through pi, not through 0
    np.testing.assert_allclose(mid[1], poses[0])
    np.testing.assert_allclose(mid[2, :2], poses[1, :2])


def test_path_length():
    p = np.array([[0, 0, 0], [3, 4, 0], [3, 5, 1.0]])
    assert path_length_m(p) == 6.0
    assert path_length_m(p[:1]) == 0.0


def test_nearest_index_and_points_to_beams():
    from gatmo.geometry import nearest_index, points_to_beams

    v = np.array([0.0, 1.0, 2.0, 4.0])
    q = np.array([-1.0, 0.4, 0.5, 2.9, 3.1, 9.0])
    assert nearest_index(v, q).tolist() == [0, 0, 0, 2, 3, 3]
    angles = np.radians(np.arange(-90.0, 91.0, 1.0))
    # a laser at (1, 1) facing +y: a point 2 m ahead is on beam 0 deg, one 1 m to its left at 90
    pts = np.array([[1.0, 3.0], [0.0, 1.0]])
    rng, bearing, j = points_to_beams(pts, np.array([1.0, 1.0, np.pi / 2]), angles)
    np.testing.assert_allclose(rng, [2.0, 1.0])
    np.testing.assert_allclose(bearing, [0.0, np.pi / 2], atol=1e-12)
    assert j.tolist() == [90, 180]


def test_one_pose_compose_and_inverse_are_the_batched_ones_to_the_bit():
    # compose / inverse of single poses skip np.stack: the values must be the batched path's
    from gatmo.geometry import compose, inverse

    rng = np.random.default_rng(7)
    a = rng.normal(size=(2000, 3)) * [10.0, 10.0, 4.0]
    b = rng.normal(size=(2000, 3)) * [10.0, 10.0, 4.0]
    one = np.array([compose(x, y) for x, y in zip(a, b, strict=True)])
    np.testing.assert_array_equal(one, np.array([compose(x[None], y[None])[0]
                                                 for x, y in zip(a, b, strict=True)]))
    np.testing.assert_array_equal(np.array([inverse(x) for x in a]),
                                  np.array([inverse(x[None])[0] for x in a]))
    assert compose(a[0], b[0]).shape == (3,) and inverse(a[0]).dtype == np.float64
