import numpy as np
import pytest

from dfcoa_opt.sim import neighbours
from dfcoa_opt.sim.neighbours import neighbour_table, proximity


def brute(points, radius, k, contact):
    n = len(points)
    d = np.hypot(*(points[:, None] - points[None]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    idx = np.full((n, min(k, n - 1)), -1)
    for i in range(n):
        o = [j for j in np.argsort(d[i]) if d[i, j] <= radius][: idx.shape[1]]
        idx[i, : len(o)] = o
    pairs = sorted(i * n + j for i in range(n) for j in range(i + 1, n) if d[i, j] < contact)
    return idx, d.min(), pairs


@pytest.mark.parametrize("n", [3, 30, 120])
def test_dense_and_tree_paths_agree_with_brute_force(n, monkeypatch):
    rng = np.random.default_rng(n)
    pts = rng.uniform(0, 10, (n, 2))
    ref_idx, ref_min, ref_pairs = brute(pts, 2.5, 6, 0.8)
    for dense_max in (0, 10_000):  # the tree path, then the dense paths (numpy and compiled)
        monkeypatch.setattr(neighbours, "DENSE_MAX", dense_max)
        monkeypatch.setattr(neighbours, "KERNEL_MAX", dense_max)
        p = proximity(pts, 2.5, 6, 0.8)
        assert np.array_equal(p.index, ref_idx)
        assert np.isclose(p.min_distance, ref_min)
        assert sorted(p.contact_keys.tolist()) == ref_pairs
        idx, dist = neighbour_table(pts, 2.5, 6)
        assert np.array_equal(idx, ref_idx)
        assert np.all(np.isinf(dist[idx < 0]))


def test_single_robot_has_no_neighbours():
    p = proximity(np.zeros((1, 2)), 5.0, 4, 0.4)
    assert p.index.shape == (1, 0) and np.isinf(p.min_distance)


@pytest.mark.parametrize("radius", [1e-3, 3.0, np.inf])  # 1e-3: nobody in range
def test_proximity_closest_pair_matches_brute_force_on_the_tree_path(radius):
    """The closest pair comes from the table when it can, else from a full query."""
    rng = np.random.default_rng(9)
    pts = rng.uniform(0.0, 60.0, (neighbours.KERNEL_MAX + 40, 2))
    d = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    prox = neighbours.proximity(pts, radius, 5, 0.5)
    assert prox.min_distance == pytest.approx(d.min(), rel=1e-12)
    i, j = np.nonzero(np.triu(d < 0.5, 1))
    np.testing.assert_array_equal(prox.contact_keys, np.sort(i * len(pts) + j))
    assert len(i) >= 1
    assert (radius < d.min()) == (not np.isfinite(prox.distance).any())


@pytest.mark.parametrize("k_max", [0, 1, 4, 100])
@pytest.mark.parametrize("layout", ["random", "grid"])  # grid: many equal distances (ties)
def test_dense_kernel_matches_numpy_table_bit_for_bit(k_max, layout):
    """The numba dense path gives the numpy path's table, distances and keys exactly."""
    rng = np.random.default_rng(k_max)
    pts = (rng.uniform(0.0, 8.0, (40, 2)) if layout == "random"
           else np.stack(np.meshgrid(np.arange(6.0), np.arange(6.0)), -1).reshape(-1, 2))
    prox = proximity(pts, 2.0, k_max, 1.01)
    idx, dist, _ = neighbours._table(pts, 2.0, k_max)  # the numpy reference (dense matrix)
    np.testing.assert_array_equal(prox.index, idx)
    np.testing.assert_array_equal(prox.distance, dist)
    d = neighbours.pairwise_distances(pts)
    assert prox.min_distance == d.min()
    i, j = np.nonzero(np.triu(d < 1.01, 1))
    np.testing.assert_array_equal(prox.contact_keys, i * len(pts) + j)
    assert layout == "random" or len(i) == 60  # the grid's 60 unit-distance pairs


@pytest.mark.parametrize("k", [0, 1, 5])
def test_gather_copies_the_neighbours_rows_and_zeroes_the_padding(k):
    rng = np.random.default_rng(k)
    n = 9
    pose, vel = rng.normal(size=(n, 3)), rng.normal(size=(n, 2))
    index = rng.integers(-1, n, size=(n, k))
    pos, v, heading = neighbours.gather(index, pose, vel)
    pad = index < 0
    safe = np.where(pad, 0, index)
    np.testing.assert_array_equal(pos, np.where(pad[..., None], 0.0, pose[safe, :2]))
    np.testing.assert_array_equal(v, np.where(pad[..., None], 0.0, vel[safe]))
    np.testing.assert_array_equal(heading, np.where(pad, 0.0, pose[safe, 2]))
    assert pos.shape == (n, k, 2) and heading.shape == (n, k)
    assert not np.signbit(pos[pad]).any()  # +0, not a copied -0
