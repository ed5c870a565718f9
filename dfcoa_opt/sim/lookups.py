"""Per-run lookups of a batch's stepper: each run's leader, moving discs, disturbances, clearance.

A mixin of :class:`~dfcoa_opt.sim.stepper.Stepper`. Runs whose worlds follow
their seed (a seeded clutter field, a generated world) have a world, a leader
track, shapes and moving discs of their own; these lookups serve every active
run in one array operation where they can, with each run's own numbers.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.world.shape_clearance import shape_clearance_worlds

if TYPE_CHECKING:
    from dfcoa_opt.scenario.schema import ScenarioSpec
    from dfcoa_opt.sim.batch import BatchSimulator
    from dfcoa_opt.sim.leader import LeaderTrack

FloatArray = NDArray[np.float64]

#: Seeded worlds' leader slots are gathered from one stacked array up to this size.
TRACKS_STACKED_BYTES = 64 * 2**20


class RunLookups:
    """Lookups over the active runs (the stepper's ``sim``, ``spec``, ``n``, ``dt``, ``tracks``)."""

    sim: BatchSimulator
    spec: ScenarioSpec
    n: int
    dt: float
    tracks: list[LeaderTrack]
    movers: list[tuple[FloatArray, FloatArray, FloatArray]]
    _stacked: tuple[Any, ...] | None
    _movers_stacked: tuple[FloatArray, ...] | None = None

    def _leader(self, active: NDArray[np.intp],
                kk: NDArray[np.int64]) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
        """Each active run's leader state ``(A, 5)``, slots ``(A, N, 2)``, at-goal flag ``(A,)``."""
        if len(self.tracks) == 1:
            tr = self.tracks[0]
            return tr.state[kk], tr.slots[kk], tr.at_goal[kk]
        if self._stacked is None:  # every world's track, as (G, K, ...) arrays
            tracks = self.tracks
            slots = (np.stack([tr.slots for tr in tracks])
                     if sum(tr.slots.nbytes for tr in tracks) <= TRACKS_STACKED_BYTES else None)
            self._stacked = (np.stack([tr.state for tr in tracks]),
                             np.stack([tr.at_goal for tr in tracks]), slots)
        states, at_goal, slots = self._stacked
        g = self.sim.group[active]
        if slots is None:
            return states[g, kk], np.stack([self.tracks[w].slots[k] for w, k in
                                            zip(g, kk, strict=True)]), at_goal[g, kk]
        return states[g, kk], slots[g, kk], at_goal[g, kk]

    def _moving(self, active: NDArray[np.intp], kk: NDArray[np.int64]
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Each active run's moving discs: positions and velocities ``(A, M, 2)``, radii ``(A, M)``.

        One world (or worlds whose discs the file sets, the same in every run)
        reads its one table; worlds drawn with moving discs of their own
        (``[world.generate]`` family ``crowd``) read each run's row of the
        stacked tables.
        """
        if len(self.movers) == 1:
            pos, vel, radii = self.movers[0]
            return pos[kk], vel[kk], np.broadcast_to(radii, (len(active), len(radii)))
        if self._movers_stacked is None:
            self._movers_stacked = tuple(np.stack([mv[f] for mv in self.movers])
                                         for f in range(3))
        pos, vel, radii = self._movers_stacked
        g = self.sim.group[active]
        return pos[g, kk], vel[g, kk], radii[g]

    def _moving_rows(self, radii: FloatArray) -> FloatArray:
        """:meth:`_moving`'s radii per robot row: ``(1, M)`` for one world, else ``(A*N, M)``."""
        return radii[:1] if len(self.movers) == 1 else np.repeat(radii, self.n, axis=0)

    def _disturbance(self, kind: str, kk: NDArray[np.int64]) -> FloatArray | None:
        """``(A*N, 2)`` disturbances of ``kind`` at each active run's time (None without any)."""
        table = self.sim.disturbances[kind]
        if not table:
            return None
        clocks = np.unique(kk)
        out = np.zeros((len(clocks), self.n, 2))
        for c, k in enumerate(clocks):
            t = int(k) * self.dt
            for robot, t0, t1, value in table:
                if t0 <= t < t1:
                    out[c, robot] += value
        return out[np.searchsorted(clocks, kk)].reshape(-1, 2)

    def _clearance(self, pos: FloatArray, active: NDArray[np.intp]) -> FloatArray:
        """Every row's clearance to the static obstacles of its own run's world, m."""
        sim, n, cap = self.sim, self.n, self.spec.metrics.clearance_cap
        if len(sim.group_scenarios) == 1:
            return sim.group_scenarios[0].world.clearance(pos, cap)
        shapes = sim.world_shapes()
        if shapes is not None:  # seeded worlds: one call, each row in its own run's world
            return shape_clearance_worlds(np.ascontiguousarray(pos),
                                          np.repeat(sim.group[active], n), *shapes, float(cap))
        return np.concatenate([sim.group_scenarios[sim.group[e]].world.clearance(
            pos[j * n:(j + 1) * n], cap) for j, e in enumerate(active)])
