import numpy as np
import pytest
import shapely
from matplotlib import image as mpimg

from dfcoa_opt.world.grid import OccupancyGrid
from dfcoa_opt.world.shapes import Circle, Polygon, Rectangle


def test_ascii_top_row_is_north():
    g = OccupancyGrid.from_ascii("#..\n...\n..#", resolution=2.0, origin=(1.0, -1.0))
    assert g.shape == (3, 3) and g.size == (1.5, 1.5)
    assert g.occupied[2, 0] and g.occupied[0, 2] and g.occupied.sum() == 2
    # top-left '#' covers x in [1, 1.5), y in [0, 0.5)
    assert g.is_occupied_at([[1.2, 0.2]])[0] and not g.is_occupied_at([[1.2, -0.8]])[0]
    assert not g.is_occupied_at([[100.0, 100.0]])[0]  # outside = free


@pytest.mark.parametrize("text,msg", [("..\n.", "row 2 has 1"), (".x", "unknown character")])
def test_ascii_errors(text, msg):
    with pytest.raises(ValueError, match=msg):
        OccupancyGrid.from_ascii(text, 1.0)


def test_image_roundtrip(tmp_path):
    occ = np.zeros((5, 7), dtype=bool)
    occ[0, 1] = occ[4, 6] = True  # row 0 = bottom
    img = np.where(occ[::-1], 0.0, 1.0)
    path = tmp_path / "map.png"
    mpimg.imsave(path, img, cmap="gray", vmin=0, vmax=1)
    g = OccupancyGrid.from_image(path, resolution=10.0)
    assert np.array_equal(g.occupied, occ)


def test_rectangle_on_cell_boundaries_is_exact():
    g = OccupancyGrid.from_shapes((4.0, 4.0), 2.0, [Rectangle((1.0, 1.0), (2.0, 3.0))])
    expect = np.zeros((8, 8), dtype=bool)
    expect[2:6, 2:4] = True
    assert np.array_equal(g.occupied, expect)
    poly = Rectangle((1.0, 1.0), (2.0, 3.0)).to_polygon()
    g2 = OccupancyGrid.from_shapes((4.0, 4.0), 2.0, [poly])
    assert np.array_equal(g2.occupied, expect)


def test_centre_inside_rule_matches_shapely():
    shapes = [Circle((3.1, 2.2), 1.3), Polygon(((5.0, 0.5), (7.3, 1.0), (6.0, 3.9)))]
    g = OccupancyGrid.from_shapes((8.0, 5.0), 7.3, shapes, origin=(0.2, -0.1))
    c = g.cell_centers().reshape(-1, 2)
    geo = [shapely.Point(3.1, 2.2).buffer(1.3, 256), shapely.Polygon(shapes[1].vertices)]
    ref = np.zeros(len(c), dtype=bool)
    for s in geo:
        ref |= shapely.contains_xy(s, c[:, 0], c[:, 1])
    # the 256-gon differs from the circle only within ~1e-4 m of its edge
    diff = np.nonzero(ref != g.occupied.ravel())[0]
    d = np.abs(np.hypot(c[diff, 0] - 3.1, c[diff, 1] - 2.2) - 1.3)
    assert np.all(d < 1e-3)


def test_rasterising_in_bounding_boxes_tests_every_cell_it_must():
    """Each shape tests only the centres in its bounding box: the same cells as all of them.

    Shapes whose edges fall on cell centres, smaller than a cell, partly or wholly
    outside the grid, at a non-zero origin and a resolution that is not a power of two.
    """
    rng = np.random.default_rng(3)
    # at 4 cells/m the first two have their extreme points exactly on cell centres
    shapes = [Rectangle((0.375, 0.625), (1.125, 2.875)), Circle((2.125, 3.125), 0.5),
              Rectangle((0.25, 0.25), (1.25, 2.75)), Circle((-0.4, 3.0), 0.9),
              Circle((9.9, 5.9), 0.05), Rectangle((-3.0, -3.0), (-1.0, -1.0))]
    for _ in range(60):
        x, y = rng.uniform(-1.0, 9.0), rng.uniform(-1.0, 6.0)
        kind = rng.integers(3)
        if kind == 0:
            shapes.append(Circle((x, y), float(rng.uniform(0.01, 1.5))))
        elif kind == 1:
            w, h = rng.uniform(0.01, 2.0, 2)
            shapes.append(Rectangle((x, y), (x + w, y + h)))
        else:
            ang = np.arange(5) * 2 * np.pi / 5 + rng.uniform(0.0, 1.2, 5)  # star-shaped, CCW
            r = rng.uniform(0.05, 1.5, 5)
            shapes.append(Polygon(tuple((x + ri * np.cos(a), y + ri * np.sin(a))
                                        for ri, a in zip(r, ang, strict=True))))
    for resolution, origin in ((4.0, (0.0, 0.0)), (3.7, (0.13, -0.21))):
        c = OccupancyGrid.empty((9.0, 6.0), resolution, origin).cell_centers().reshape(-1, 2)
        for shape in shapes:  # one at a time: a cell missed by one is not hidden by another
            g = OccupancyGrid.from_shapes((9.0, 6.0), resolution, [shape], origin=origin)
            assert np.array_equal(g.occupied.ravel(), shape.contains(c)), shape
        both = OccupancyGrid.from_shapes((9.0, 6.0), resolution, shapes, origin=origin)
        assert np.array_equal(both.occupied.ravel(),
                              np.any([shape.contains(c) for shape in shapes], axis=0))


def _brute_centre_distance(g):
    c = g.cell_centers().reshape(-1, 2)
    occ = c[g.occupied.ravel()]
    d = np.sqrt(((c[:, None] - occ[None]) ** 2).sum(-1)).min(1)
    return d.reshape(g.shape)


def test_distance_field_and_inflation_match_brute_force():
    rng = np.random.default_rng(3)
    g = OccupancyGrid(rng.random((30, 40)) < 0.05, resolution=4.0)
    ref = _brute_centre_distance(g)
    assert np.allclose(g.distance_field, ref)
    inf = g.inflate(0.6)
    assert np.array_equal(inf.occupied, ref <= 0.6)
    assert np.isinf(OccupancyGrid.empty((2, 2), 1.0).distance_field).all()


def test_clearance_matches_shapely_distance():
    rng = np.random.default_rng(7)
    g = OccupancyGrid(rng.random((25, 30)) < 0.04, resolution=3.0, origin=(-1.0, 2.0))
    cells = [shapely.box(g.origin[0] + j / 3, g.origin[1] + i / 3, g.origin[0] + (j + 1) / 3,
                         g.origin[1] + (i + 1) / 3) for i, j in np.argwhere(g.occupied)]
    union = shapely.unary_union(cells)
    pts = rng.uniform([-3.0, 0.0], [12.0, 12.0], (300, 2))
    ref = np.array([union.distance(shapely.Point(p)) for p in pts])
    cap = 2.5
    ours = g.clearance(pts, cap=cap)
    assert np.allclose(ours, np.minimum(ref, cap), atol=1e-12)


def test_clearance_empty_grid_is_cap():
    g = OccupancyGrid.empty((3.0, 3.0), 2.0)
    assert np.all(g.clearance(np.array([[1.0, 1.0]]), cap=4.0) == 4.0)


def test_grid_is_immutable():
    g = OccupancyGrid.empty((1.0, 1.0), 4.0)
    with pytest.raises(ValueError):
        g.occupied[0, 0] = True
