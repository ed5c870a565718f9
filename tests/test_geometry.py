import numpy as np
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from dfcoa_opt.core.geometry import (
    body_to_world,
    clip_segments_to_box,
    pairwise_distances,
    point_segment_distance,
    points_in_polygon,
    polygon_signed_area,
    rotate,
    take_rows,
    wrap_angle,
)


@given(st.floats(-1e4, 1e4, allow_nan=False))
def test_wrap_angle_range_and_equivalence(a):
    w = float(wrap_angle(a))
    assert -np.pi < w <= np.pi
    assert abs(np.sin(w) - np.sin(a)) < 1e-8 and abs(np.cos(w) - np.cos(a)) < 1e-8


def test_wrap_angle_pi_maps_to_plus_pi():
    assert wrap_angle(-np.pi) == np.pi and wrap_angle(3 * np.pi) == np.pi


def test_rotate_and_body_to_world():
    assert np.allclose(rotate([1.0, 0.0], np.pi / 2), [0.0, 1.0])
    # eq 4: x = xc + d cos(theta_i + theta_c)
    d, th_i, pose = 2.0, 0.3, np.array([1.0, -2.0, 0.7])
    p = body_to_world(pose, [d * np.cos(th_i), d * np.sin(th_i)])
    assert np.allclose(p, [1.0 + d * np.cos(th_i + 0.7), -2.0 + d * np.sin(th_i + 0.7)])
    # broadcasting (T, 1, 3) x (N, 2)
    poses = np.array([[0, 0, 0], [1, 1, np.pi]], dtype=float)
    out = body_to_world(poses[:, None, :], np.array([[1.0, 0.0], [0.0, 1.0]]))
    assert out.shape == (2, 2, 2) and np.allclose(out[1, 0], [0.0, 1.0])


def test_polygon_tools_match_shapely():
    rng = np.random.default_rng(0)
    for _ in range(20):
        ang = np.sort(rng.uniform(0, 2 * np.pi, 7))
        rad = rng.uniform(0.5, 2.0, 7)
        verts = np.stack((rad * np.cos(ang), rad * np.sin(ang)), 1)  # star-shaped, CCW
        poly = shapely.Polygon(verts)
        assert abs(polygon_signed_area(verts) - poly.area) < 1e-12
        assert polygon_signed_area(verts[::-1]) < 0
        pts = rng.uniform(-2.5, 2.5, (400, 2))
        ours = points_in_polygon(pts, verts)
        ref = shapely.contains_xy(poly, pts[:, 0], pts[:, 1])
        assert np.array_equal(ours, ref)
        a, b = verts[0], verts[1]
        seg = shapely.LineString([a, b])
        ref_d = np.array([seg.distance(shapely.Point(p)) for p in pts[:50]])
        assert np.allclose(point_segment_distance(pts[:50], a, b), ref_d, atol=1e-12)


def test_pairwise_distances_diagonal_inf():
    d = pairwise_distances(np.array([[0.0, 0.0], [3.0, 4.0]]))
    assert d[0, 1] == 5.0 and np.isinf(d[0, 0])


@settings(max_examples=50)
@given(st.floats(-50, 50), st.floats(-50, 50))
def test_point_in_unit_square_half_open(x, y):
    sq = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    inside = bool(points_in_polygon([[x, y]], sq)[0])
    assert inside == (0.0 <= x < 1.0 and 0.0 <= y < 1.0) or x in (0.0, 1.0) or y in (0.0, 1.0)


def test_take_rows_picks_what_take_along_axis_picks():
    rng = np.random.default_rng(5)
    values = rng.normal(size=(6, 9, 2))
    index = np.argsort(rng.random((6, 9)), axis=1)[:, :4]
    np.testing.assert_array_equal(take_rows(values, index),
                                  np.take_along_axis(values, index[..., None], axis=1))
    np.testing.assert_array_equal(take_rows(values[..., 0], index),
                                  np.take_along_axis(values[..., 0], index, axis=1))
    assert take_rows(values, index[:, :0]).shape == (6, 0, 2)


def test_polygon_arrays_are_each_shapes_polygon_bit_for_bit():
    from dfcoa_opt.world.shapes import Circle, Polygon, Rectangle, polygon_arrays

    rng = np.random.default_rng(4)
    shapes = [Circle(tuple(rng.uniform(-50, 50, 2)), float(rng.uniform(0.05, 3.0)))
              for _ in range(40)]
    shapes.insert(3, Rectangle((0.0, 0.0), (2.0, 1.0)))
    shapes.insert(10, Polygon(((0.0, 0.0), (1.0, 0.0), (0.0, 1.0))))
    got = polygon_arrays(shapes)
    assert len(got) == len(shapes)
    for shape, ring in zip(shapes, got, strict=True):
        assert np.array_equal(ring, shape.to_polygon().as_array())
    assert polygon_arrays([]) == []


def test_clip_segments_to_box_matches_shapely():
    rng = np.random.default_rng(3)
    box = (-1.0, -2.0, 3.0, 4.0)
    a, b = rng.uniform(-6.0, 6.0, (2, 600, 2))
    a[:40, 0] = b[:40, 0]  # vertical segments
    a[40:80, 1] = b[40:80, 1]  # horizontal ones
    a[80:120], b[80:120] = rng.uniform(-1.0, 3.0, (2, 40, 2))  # segments inside
    start, end, hit = clip_segments_to_box(a, b, box)
    inside = np.all((a >= box[:2]) & (a <= box[2:]) & (b >= box[:2]) & (b <= box[2:]), axis=1)
    assert inside.sum() > 20 and (~hit).sum() > 50  # every case occurs
    np.testing.assert_array_equal(start[inside], a[inside])  # kept exactly
    np.testing.assert_array_equal(end[inside], b[inside])
    for k in range(len(a)):
        part = shapely.LineString([a[k], b[k]]).intersection(shapely.box(*box))
        assert part.is_empty == (not hit[k]), k
        if hit[k]:
            assert abs(part.length - np.hypot(*(end[k] - start[k]))) < 1e-9, k
            assert shapely.box(*box).buffer(1e-9).contains(shapely.Point(start[k]))
