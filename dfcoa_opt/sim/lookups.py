"""Per-run lookups of a batch: each run's leader, moving discs, disturbances, clearance.

Runs whose worlds follow their seed (a seeded clutter field, a generated world)
have a world, a leader track, shapes and moving discs of their own.
:class:`RunLookups` holds every world group's leader track and moving discs
over a run and serves every active run in one array operation where it can,
with each run's own numbers. The :class:`~dfcoa_opt.sim.stepper.Stepper` owns
one and tells it of a world placed in a slot (:meth:`RunLookups.place`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.sim.leader import leader_track
from dfcoa_opt.world.shape_clearance import shape_clearance_worlds

if TYPE_CHECKING:
    from dfcoa_opt.scenario.scenario import Scenario
    from dfcoa_opt.scenario.schema import ScenarioSpec
    from dfcoa_opt.sim.leader import LeaderTrack

FloatArray = NDArray[np.float64]

#: Seeded worlds' leader slots are gathered from one stacked array up to this size.
TRACKS_STACKED_BYTES = 64 * 2**20


class Batch(Protocol):
    """What the lookups read of their batch (a :class:`~dfcoa_opt.sim.batch.BatchSimulator`).

    Read at each call: a world placed in a slot changes ``group`` and
    ``group_scenarios``.
    """

    group: NDArray[np.intp]  # each slot's world group
    group_scenarios: list[Scenario]  # each world group's scenario
    disturbances: dict[str, list[tuple[int, float, float, Any]]]  # by kind

    def world_shapes(self) -> tuple[NDArray[Any], ...] | None:
        """Every group's static shapes stacked, or None (a world with a map raster)."""


class RunLookups:
    """Lookups over the active runs of a batch, by each run's world group.

    Args:
        sim: The batch (its slots' world groups, worlds, disturbances).
        spec: Its scenario spec (the clearance cap).
        n: Robots of a run.
        dt: Step, s.
        steps: Instants of a run (the leader tracks' and moving discs' length).
    """

    def __init__(self, sim: Batch, spec: ScenarioSpec, n: int, dt: float, steps: int) -> None:
        self.sim, self.spec, self.n, self.dt, self.steps = sim, spec, n, dt, steps
        #: each world group's leader track
        self.tracks: list[LeaderTrack] = [leader_track(sc, dt, steps)
                                          for sc in sim.group_scenarios]
        self._stacked: tuple[Any, ...] | None = None  # the tracks stacked, for leader()
        #: each world group's moving discs over the run: positions, velocities ``(K, M, 2)``
        #: and radii ``(M,)``
        self.movers = [self._movers(sc) for sc in sim.group_scenarios]
        self._movers_stacked: tuple[FloatArray, ...] | None = None  # for moving()

    def _movers(self, scenario: Any) -> tuple[FloatArray, FloatArray, FloatArray]:
        """A world's moving discs at every instant: positions, velocities and radii."""
        dyn = scenario.world.dynamic
        return (*dyn.state(np.arange(self.steps) * self.dt), dyn.radii)

    def place(self, g: int, scenario: Any) -> None:
        """World group ``g`` is now ``scenario``'s world (a group reused, or one more)."""
        track = leader_track(scenario, self.dt, self.steps)
        if g < len(self.tracks):  # the freed world's group, reused
            self.tracks[g], self.movers[g] = track, self._movers(scenario)
        else:
            self.tracks.append(track)
            self.movers.append(self._movers(scenario))
        self._stacked = self._movers_stacked = None

    def leader(self, active: NDArray[np.intp],
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

    @property
    def one_mover_table(self) -> bool:
        """Whether every run reads one table of moving discs (one world group)."""
        return len(self.movers) == 1

    def moving(self, active: NDArray[np.intp], kk: NDArray[np.int64]
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

    def moving_rows(self, radii: FloatArray) -> FloatArray:
        """:meth:`moving`'s radii per robot row: ``(1, M)`` for one world, else ``(A*N, M)``."""
        return radii[:1] if len(self.movers) == 1 else np.repeat(radii, self.n, axis=0)

    def disturbance(self, kind: str, kk: NDArray[np.int64]) -> FloatArray | None:
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

    def clearance(self, pos: FloatArray, active: NDArray[np.intp]) -> FloatArray:
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
