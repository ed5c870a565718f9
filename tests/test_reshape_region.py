"""IRIS-style free regions of reshape: obstacle-free (shapely oracle), seed and ellipse inside."""

import math

import numpy as np
import pytest
import shapely
from shapely.geometry import LineString, Point, Polygon

from comparisons.reshape.region import (
    disc_segments,
    grow_region,
    shape_segments,
    swept_disc_segments,
)
from dfcoa_opt.world.shapes import Circle, Rectangle

BOUNDS = (0.0, 20.0, 0.0, 12.0)


def _random_world(rng, n_discs=12, n_boxes=4):
    shapes = []
    for _ in range(n_discs):
        shapes.append(Circle(tuple(rng.uniform([1, 1], [19, 11])), float(rng.uniform(0.2, 1.0))))
    for _ in range(n_boxes):
        lo = rng.uniform([1, 1], [17, 9])
        shapes.append(Rectangle(tuple(lo), tuple(lo + rng.uniform(0.5, 2.5, 2))))
    return shapes


def _oracle(shape):
    if isinstance(shape, Circle):
        return Point(shape.center).buffer(shape.radius, quad_segs=64)
    return Polygon(shape.to_polygon().as_array())


def _free_seed(rng, obstacles):
    for _ in range(1000):
        a = rng.uniform([1, 1], [19, 11])
        b = a + rng.uniform(-3, 3, 2)
        line = LineString([a, b])
        if all(line.distance(o) > 0.05 for o in obstacles) and 0 < b[0] < 20 and 0 < b[1] < 12:
            return np.array([a, b])
    raise AssertionError("no free seed")


@pytest.mark.parametrize("seed_no", range(25))
def test_region_is_obstacle_free_contains_its_seed_and_its_ellipse(seed_no):
    rng = np.random.default_rng(seed_no)
    shapes = _random_world(rng)
    obstacles = [_oracle(s) for s in shapes]
    seed = _free_seed(rng, obstacles)
    region = grow_region(seed, shape_segments(shapes), BOUNDS)
    poly = Polygon(region.vertices())
    assert poly.is_valid and poly.area > 0
    for o in obstacles:  # the interiors never overlap (touching is allowed)
        assert poly.intersection(o).area < 1e-9
    assert region.contains(seed).all()
    assert poly.buffer(1e-7).contains(LineString(seed))
    # the ellipse lies in the polygon: its boundary points do
    t = np.linspace(0, 2 * math.pi, 64)
    pts = (region.C @ np.stack([np.cos(t), np.sin(t)])).T + region.d
    assert region.contains(pts).all()


def test_region_in_a_doorway_is_the_doorway():
    walls = [Rectangle((10.0, 0.0), (11.5, 6.3)), Rectangle((10.0, 7.7), (11.5, 14.0))]
    seed = np.array([[8.0, 7.0], [13.0, 7.0]])
    region = grow_region(seed, shape_segments(walls), (0.0, 22.0, 0.0, 14.0))
    poly = Polygon(region.vertices())
    for w in walls:
        assert poly.intersection(_oracle(w)).area < 1e-9
    inside = poly.intersection(shapely.box(10.0, 0.0, 11.5, 14.0))
    assert inside.bounds[1] >= 6.3 - 1e-6 and inside.bounds[3] <= 7.7 + 1e-6
    assert region.contains(seed).all()


def test_disc_segments_circumscribe_and_sweeps_cover_the_motion():
    segs = disc_segments(np.array([[1.0, 2.0]]), np.array([0.5]))
    assert segs.shape == (16, 2, 2)
    poly = Polygon(segs[:, 0])
    assert poly.contains(Point(1.0, 2.0).buffer(0.5, quad_segs=64).buffer(-1e-9))
    swept = swept_disc_segments(np.array([[0.0, 0.0]]), np.array([[1.0, 0.0]]), np.array([0.3]),
                                horizon=2.0)
    capsule = LineString([(0, 0), (2, 0)]).buffer(0.3, quad_segs=64).buffer(-1e-9)
    # every point of the capsule is inside the union of the covering polygons' hull
    hull = shapely.MultiPoint(swept.reshape(-1, 2)).convex_hull
    assert hull.contains(capsule)
