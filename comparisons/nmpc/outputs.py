"""The results of :class:`comparisons.nmpc.problem.NmpcProblem`'s solves.

:class:`SolveOutput` is one solve; :class:`BatchOutput` the solves of many packed
inputs (one compiled call), row by row. Controls in m/s and rad/s, poses in m, m,
rad, slacks in m, times in s.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

__all__ = ["BatchOutput", "SolveOutput"]

FloatArray = NDArray[np.float64]


@dataclass
class SolveOutput:
    """One solve's result.

    Attributes:
        w: ``(nw H,)`` decision vector (see the module layout).
        lam_x: Bound multipliers.
        lam_g: Constraint multipliers.
        success: The solver reported success and every value is finite.
        iterations: Solver iterations (-1 when unknown: the compiled solver does not count).
        u: ``(H, 2)`` planned controls (v m/s, omega rad/s).
        x: ``(H, 3)`` planned poses at stages 1 .. H (m, m, rad).
        slack: ``(H,)`` slacks ``s_1 .. s_H``, m.
    """

    w: FloatArray
    lam_x: FloatArray
    lam_g: FloatArray
    success: bool
    iterations: int
    u: FloatArray | None = None
    x: FloatArray | None = None
    slack: FloatArray | None = None


@dataclass
class BatchOutput:
    """The solves of ``N`` packed inputs (:meth:`NmpcProblem.solve_rows`), row by row.

    Attributes:
        w: ``(N, nw H)`` decision vectors.
        lam_x: ``(N, nw H)`` bound multipliers.
        lam_g: ``(N, rows H)`` constraint multipliers.
        x: ``(N, H, 3)`` planned poses at stages 1 .. H (m, m, rad).
        success: ``(N,)`` the solver's success test passed and every value is finite.
        iterations: ``(N,)`` solver iterations (-1 when unknown, as compiled).
        seconds: ``(N,)`` wall time of each row's solve, s.
    """

    w: FloatArray
    lam_x: FloatArray
    lam_g: FloatArray
    x: FloatArray
    success: NDArray[np.bool_]
    iterations: NDArray[np.intp]
    seconds: FloatArray

    @property
    def u(self) -> FloatArray:
        """``(N, H, 2)`` planned controls (v m/s, omega rad/s)."""
        return self.w.reshape(len(self.w), self.x.shape[1], -1)[..., :2]

    @property
    def slack(self) -> FloatArray:
        """``(N, H)`` slacks ``s_1 .. s_H``, m."""
        return self.w.reshape(len(self.w), self.x.shape[1], -1)[..., -1]

    def row(self, i: int) -> SolveOutput:
        """Row ``i`` as a :class:`SolveOutput` (copies)."""
        return SolveOutput(self.w[i].copy(), self.lam_x[i].copy(), self.lam_g[i].copy(),
                           bool(self.success[i]), int(self.iterations[i]), self.u[i].copy(),
                           self.x[i].copy(), self.slack[i].copy())

    @classmethod
    def gather(cls, n: int, parts: list[tuple[NDArray[np.intp], BatchOutput]]) -> BatchOutput:
        """``n`` rows from ``(rows, output)`` parts, each row given by exactly one part.

        Args:
            n: Rows of the result.
            parts: The row indices of each part (into the result) and its solves.

        Returns:
            Row ``rows[j]`` of the result is row ``j`` of that part's output (copies).
        """
        first = parts[0][1]
        out = cls(*(np.empty((n, *getattr(first, f.name).shape[1:]),
                             getattr(first, f.name).dtype) for f in fields(cls)))
        for rows, part in parts:
            for f in fields(cls):
                getattr(out, f.name)[rows] = getattr(part, f.name)
        return out

    def put(self, rows: NDArray[np.intp], other: BatchOutput) -> None:
        """Overwrite ``rows`` with ``other``'s rows (same layout); their times add up."""
        for key in ("w", "lam_x", "lam_g", "x", "success", "iterations"):
            getattr(self, key)[rows] = getattr(other, key)
        self.seconds[rows] += other.seconds
