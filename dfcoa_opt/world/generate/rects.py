"""Occupied cells of a (possibly uneven) grid as few axis-aligned rectangles.

Generated worlds are exact geometry: the methods that read shapes (ORCA,
CBF, NMPC, the velocity obstacles) see rectangles, not raster cells. A
family that works on cells (the cellular automaton, the carved corridors)
turns its occupied cells into rectangles with :func:`mask_rectangles`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dfcoa_opt.world.shapes import Rectangle


def _runs(row: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """``[(c0, c1), ...]``: the maximal runs of True in ``row`` (columns ``c0 .. c1 - 1``)."""
    padded = np.concatenate(([False], row, [False])).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def mask_rectangles(mask: ArrayLike, xs: ArrayLike, ys: ArrayLike) -> tuple[Rectangle, ...]:
    """The True cells of ``mask`` as rectangles that cover exactly them.

    Cell ``(i, j)`` spans ``[xs[j], xs[j + 1]] x [ys[i], ys[i + 1]]``. Each row's
    maximal runs of True cells are rectangles, and a run with the same columns
    in the next row extends the rectangle above it, so a block of cells becomes
    one rectangle. The rectangles do not overlap, and their order depends only
    on ``mask`` (bottom row first, then by column).

    Args:
        mask: ``(R, C)`` booleans, True = occupied.
        xs: ``(C + 1,)`` strictly increasing column edges, m.
        ys: ``(R + 1,)`` strictly increasing row edges, m.

    Returns:
        The rectangles.

    Raises:
        ValueError: Edges that do not match the mask's shape.
    """
    m = np.asarray(mask, dtype=bool)
    x = np.asarray(xs, dtype=float)
    y = np.asarray(ys, dtype=float)
    if m.ndim != 2 or x.shape != (m.shape[1] + 1,) or y.shape != (m.shape[0] + 1,):
        raise ValueError(f"mask {m.shape} needs {m.shape[1] + 1} x edges and {m.shape[0] + 1} "
                         f"y edges, got {x.shape} and {y.shape}")
    done: list[tuple[int, int, int, int]] = []  # (row0, row1, c0, c1), rows row0 .. row1 - 1
    open_: dict[tuple[int, int], int] = {}      # run -> first row of its rectangle
    for i in range(m.shape[0]):
        runs = set(_runs(m[i]))
        for run in [r for r in open_ if r not in runs]:
            done.append((open_.pop(run), i, *run))
        for run in runs:
            open_.setdefault(run, i)
    done += [(r0, m.shape[0], *run) for run, r0 in open_.items()]
    done.sort()
    return tuple(Rectangle((float(x[c0]), float(y[r0])), (float(x[c1]), float(y[r1])))
                 for r0, r1, c0, c1 in done)
