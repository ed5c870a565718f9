"""The formation choice of ``reshape``: template, rotation, scale and position in a free region.

A candidate formation is a template's offsets ``o_j`` (``(N, 2)`` in the
formation frame, m), a rotation ``theta`` (rad), a scale ``s`` in
``[s_min, 1]`` and a translation ``t`` (m): slot ``j`` is ``t + s R(theta) o_j``.
Every robot's disc must lie in the region shrunk by the radius and a margin:
``a_k . (t + s R o_j) <= b_k - r_m`` for all half-planes ``k`` and slots ``j``.
For fixed ``theta`` and ``s`` this is, per half-plane, one row in ``t``:

    a_k . t <= b_k - r_m - s max_j (a_k . R o_j)

so the best ``t`` -- the point nearest the look-ahead goal ``g`` -- is the
projection of ``g`` on a convex polygon, which ORCA's exact 2D solver
(:func:`comparisons.orca.lp.solve_lines`) computes for every candidate in one
batched call. The candidates are every template x rotation x scale of a small
grid; the cost of each is

    w_progress |t - g|^2 + w_scale (1 - s)^2 + w_rotation (theta - psi)^2
    + template cost + switching cost (a template other than the previous one)

and the cheapest feasible one wins. A grid over ``(theta, s)`` keeps the choice
exact per cell and its cost independent of the team size (the maximum over
slots is one matrix product per candidate). :func:`assign` gives the robots
their slots.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from comparisons.orca.lp import FEASIBLE, solve_lines
from comparisons.reshape.region import Region

FloatArray = NDArray[np.float64]
#: Radius of the "speed disc" of the exact 2D solver: large, so only the half-planes bind, m.
FREE_RADIUS = 1e4


@dataclass(frozen=True)
class Candidate:
    """A formation: template, rotation (rad), scale, translation (m) and its cost."""

    template: str
    theta: float
    scale: float
    t: FloatArray
    cost: float

    def slots(self, offsets: FloatArray) -> FloatArray:
        """``(N, 2)`` slot positions of the template's offsets, m."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        rot = np.array([[c, -s], [s, c]])
        return self.t + self.scale * np.asarray(offsets, float) @ rot.T


@dataclass(frozen=True)
class Weights:
    """Cost weights of the formation choice (module docstring).

    Attributes:
        progress: Weight of ``|t - g|^2``, 1/m^2.
        scale: Weight of ``(1 - s)^2``.
        rotation: Weight of ``(theta - psi)^2``, 1/rad^2.
        switch: Cost of a template other than the previous one.
    """

    progress: float = 1.0
    scale: float = 4.0
    rotation: float = 0.5
    switch: float = 0.5


def choose(region: Region, templates: Mapping[str, FloatArray], template_cost: Mapping[str, float],
           goal: FloatArray, psi: float, rotations: FloatArray, scales: FloatArray,
           clearance: float, previous: str | None, weights: Weights) -> Candidate | None:
    """The cheapest formation that fits the region (module docstring), or None.

    Args:
        region: The free region.
        templates: Template name -> ``(N, 2)`` offsets, m.
        template_cost: Template name -> its fixed cost (0 for the scenario's shape).
        goal: ``(2,)`` the look-ahead goal ``g``, m.
        psi: Reference heading (the look-ahead direction), rad.
        rotations: Rotations tried, relative to ``psi``, rad.
        scales: Scales tried, in ``(0, 1]``.
        clearance: Robot radius plus margin ``r_m``, m.
        previous: The template of the previous plan (switching cost), or None.
        weights: Cost weights.

    Returns:
        The chosen :class:`Candidate`, None when no candidate fits.
    """
    A, b = region.A, region.b
    names, thetas, ss, cst, rows = [], [], [], [], []
    for name, off in templates.items():
        fixed = template_cost.get(name, 0.0) + (weights.switch if previous not in (None, name)
                                                 else 0.0)
        for dth in rotations:
            th = psi + float(dth)
            c, s = math.cos(th), math.sin(th)
            support = (np.asarray(off, float) @ np.array([[c, s], [-s, c]])) @ A.T  # (N, K)
            reach = support.max(axis=0)
            for sc in scales:
                names.append(name)
                thetas.append(th)
                ss.append(float(sc))
                cst.append(fixed + weights.rotation * float(dth) ** 2
                           + weights.scale * (1.0 - float(sc)) ** 2)
                rows.append(b - clearance - float(sc) * reach)
    if not rows:
        return None
    e = np.array(rows) - A @ region.d  # a_k . v <= e_k with v = t - d (the region's centre)
    n_cand, k = e.shape
    points = e[..., None] * A[None]
    dirs = np.broadcast_to(np.stack([-A[:, 1], A[:, 0]], axis=1), (n_cand, k, 2))
    v, status, _ = solve_lines(points, dirs, np.full(n_cand, k), np.zeros(n_cand, int),
                               np.broadcast_to(np.asarray(goal, float) - region.d, (n_cand, 2)),
                               np.full(n_cand, FREE_RADIUS))
    t = v + region.d
    ok = (status == FEASIBLE) & np.all(v @ A.T <= e + 1e-9, axis=1)
    if not ok.any():
        return None
    total = np.array(cst) + weights.progress * np.sum((t - goal) ** 2, axis=1)
    total[~ok] = np.inf
    i = int(np.argmin(total))
    return Candidate(names[i], thetas[i], ss[i], t[i].copy(), float(total[i]))


def assign(pos: FloatArray, slots: FloatArray, template: str, previous_template: str | None,
           previous: NDArray[np.intp], hysteresis: float,
           reorder: bool = False) -> NDArray[np.intp]:
    """Robot i -> slot index: its own in the scenario's template, else Hungarian.

    The Hungarian assignment on squared distances; the previous one is kept,
    in the same template, unless the new one is ``hysteresis`` cheaper.

    Args:
        pos: ``(N, 2)`` robot positions, m.
        slots: ``(N, 2)`` the template's slots, m.
        template: The slots' template (``"scenario"``: every robot its own slot).
        previous_template: The template of the previous plan, or None.
        previous: ``(N,)`` the previous assignment.
        hysteresis: A new assignment must be this fraction cheaper.
        reorder: The scenario's template too by the Hungarian assignment
            (``reshape_passage``'s recovering team: robots that met head-on in
            a passage trade slots instead of pushing).

    Returns:
        ``(N,)`` the slot of each robot.
    """
    n = len(pos)
    if template == "scenario" and not reorder:
        return np.arange(n)
    cost = np.sum((pos[:, None, :] - slots[None]) ** 2, axis=2)
    from scipy.optimize import linear_sum_assignment  # here: ~0.15 s to import

    _, best = linear_sum_assignment(cost)
    if template == previous_template and \
            cost[np.arange(n), previous].sum() <= (1.0 + hysteresis) * \
            cost[np.arange(n), best].sum():
        return previous
    return best
