"""Shared helpers and independent oracles of the A* tests (not a test module).

MovingAI problems, a scipy Dijkstra, move-rule checks, an independent
plain-Python eq 13 search, and map builders, used by ``test_astar.py``,
``test_astar_improved.py``, ``test_jps.py`` and ``test_properties_planning.py``.
"""

from __future__ import annotations

import heapq
import math
from pathlib import Path

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from dfcoa_opt.planning.astar import obstacle_term
from dfcoa_opt.world.grid import OccupancyGrid

# A copy of ../shared/data/movingai (MovingAI benchmark, movingai.com), kept in the
# repository so the oracle test runs on every checkout.
MOVINGAI = Path(__file__).resolve().parent / "data" / "movingai"
SQRT2 = math.sqrt(2.0)


def load_movingai_map(path: Path) -> OccupancyGrid:
    """Parse a MovingAI .map: '.' and 'G' passable, anything else blocked; row 0 at the bottom."""
    lines = path.read_text().splitlines()
    height = int(lines[1].split()[1])
    width = int(lines[2].split()[1])
    assert lines[0].strip() == "type octile" and lines[3].strip() == "map"
    rows = lines[4:4 + height]
    assert len(rows) == height and all(len(r) == width for r in rows)
    occ = np.array([[ch not in ".G" for ch in r] for r in rows])
    return OccupancyGrid(occ[::-1], resolution=1.0)


def movingai_problems() -> list[tuple[int, int, int, int, float]]:
    """(start_x, start_y, goal_x, goal_y, optimal length) of arena.map.scen (y from the top)."""
    lines = (MOVINGAI / "arena.map.scen").read_text().splitlines()
    assert lines[0].startswith("version")
    out = []
    for ln in lines[1:]:
        f = ln.split("\t")
        if len(f) >= 9:
            out.append((int(f[4]), int(f[5]), int(f[6]), int(f[7]), float(f[8])))
    return out


def dijkstra_cost(occ: np.ndarray, s: tuple[int, int], g: tuple[int, int],
                  corner_cutting: bool = False) -> float:
    """Independent oracle: scipy Dijkstra on the 8-connected graph."""
    n_rows, n_cols = occ.shape
    idx = np.arange(occ.size).reshape(occ.shape)
    src, dst, w = [], [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1), (-1, 0), (0, -1)):
        for r in range(n_rows):
            for c in range(n_cols):
                vr, vc = r + dr, c + dc
                if not (0 <= vr < n_rows and 0 <= vc < n_cols) or occ[r, c] or occ[vr, vc]:
                    continue
                if dr and dc:
                    a, b = occ[r, vc], occ[vr, c]
                    if (a and b) if corner_cutting else (a or b):
                        continue
                src.append(idx[r, c])
                dst.append(idx[vr, vc])
                w.append(SQRT2 if dr and dc else 1.0)
    graph = coo_matrix((w, (src, dst)), shape=(occ.size, occ.size)).tocsr()
    return float(dijkstra(graph, indices=idx[s])[idx[g]])


def random_free_pair(rng: np.random.Generator, occ: np.ndarray) -> tuple[tuple, tuple]:
    free = np.argwhere(~occ)
    a, b = rng.choice(len(free), 2, replace=False)
    return tuple(int(v) for v in free[a]), tuple(int(v) for v in free[b])


def assert_valid_moves(occ: np.ndarray, cells: np.ndarray, corner_cutting: bool = False) -> None:
    """Consecutive 8-neighbours on free cells; diagonals obey the corner rule."""
    assert not occ[cells[:, 0], cells[:, 1]].any(), "path crosses a blocked cell"
    steps = np.diff(cells, axis=0)
    assert np.abs(steps).max(initial=0) <= 1 and (np.abs(steps).sum(1) > 0).all()
    for (r, c), (dr, dc) in zip(cells[:-1], steps, strict=True):
        if dr and dc:
            a, b = occ[r, c + dc], occ[r + dr, c]
            assert not (a and b), "squeezes between two blocked cells"
            if not corner_cutting:
                assert not (a or b), "cuts a corner"


def sampled_segment_free(occ: np.ndarray, p: np.ndarray, q: np.ndarray) -> bool:
    """Dense sampling (cell coordinates (x, y)): every sample lies in a free cell."""
    t = np.linspace(0.0, 1.0, 2001)[:, None]
    pts = p + t * (q - p)
    col, row = np.floor(pts[:, 0]).astype(int), np.floor(pts[:, 1]).astype(int)
    return not occ[row, col].any()


def scenario_dict(**leader: object) -> dict:
    """A minimal valid scenario with a wall between start and goal."""
    return {
        "world": {"size": [20.0, 10.0], "resolution": 5,
                  "obstacles": [{"type": "rectangle", "min": [9.0, 0.0], "max": [10.0, 7.0]}]},
        "robots": {"model": "unicycle", "radius": 0.2},
        "team": {"n": 3},
        "formation": {"shape": "line", "spacing": 0.8},
        "leader": {"start": [2.0, 2.0], "goal": [17.0, 2.0], **leader},
    }


def heapq_eq13(occ: np.ndarray, s: tuple[int, int], t: tuple[int, int], h_gain: float,
               o_gain: float, window: float) -> tuple[float, int, list[tuple[int, int]]]:
    """Independent plain-Python A* with eq 13's priority: a binary heapq, lazy deletion.

    f = g + h - h_gain h (R - r) / R + o_gain sum 1 / d_i (cells; octile h, Euclidean r,
    R = |start - goal|), popped by f - 1e-9 g, FIFO among equal keys. Returns
    ``(cost, expanded, path cells)``.
    """
    n_rows, n_cols = occ.shape
    obst = obstacle_term(occ, window)
    big_r = math.hypot(s[0] - t[0], s[1] - t[1])

    def priority(v: tuple[int, int], g: float) -> float:
        dr, dc = abs(v[0] - t[0]), abs(v[1] - t[1])
        h = max(dr, dc) + (SQRT2 - 1.0) * min(dr, dc)
        return g + h - h_gain * h * (big_r - math.hypot(dr, dc)) / big_r + o_gain * obst[v]

    g, parent, closed = {s: 0.0}, {s: s}, set()
    heap, count, expanded = [(priority(s, 0.0), 0, s)], 1, 0
    while heap:
        u = heapq.heappop(heap)[2]
        if u in closed:
            continue
        closed.add(u)
        expanded += 1
        if u == t:
            path = [u]
            while path[-1] != s:
                path.append(parent[path[-1]])
            return g[t], expanded, path[::-1]
        for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)):
            v = (u[0] + dr, u[1] + dc)
            if not (0 <= v[0] < n_rows and 0 <= v[1] < n_cols) or occ[v] or v in closed:
                continue
            if dr and dc and (occ[u[0] + dr, u[1]] or occ[u[0], u[1] + dc]):
                continue
            ng = g[u] + (SQRT2 if dr and dc else 1.0)
            if ng < g.get(v, math.inf):
                g[v], parent[v] = ng, u
                heapq.heappush(heap, (priority(v, ng) - 1e-9 * ng, count, v))
                count += 1
    return math.inf, expanded, []


def maze(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """Corridors one cell wide (every other row free, random gaps in the walls between)."""
    occ = np.ones(shape, dtype=bool)
    occ[::2] = False
    occ[1::2] = rng.random((shape[0] // 2, shape[1])) > 0.3
    return occ

