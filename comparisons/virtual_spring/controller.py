"""Paper 004's virtual-spring consensus formation: ``virtual_spring`` and ``virtual_spring_basic``.

Every robot returns a world velocity (``command = "velocity"``), the paper's
``v_i(t+1)``. On ``robots.model = "double_integrator"`` with a large ``a_max``
the adapter turns it into ``u_i(t) = (v_i(t+1) - v_i(t))/T`` and the model
integrates eq 3 as printed (``p(t+1) = p(t) + T v(t)``, ``v(t+1) = v(t) + T u``);
on ``"single_integrator"`` the new velocity moves the robot in the same step.
One step, row i from row i of the observation (equations:
:mod:`comparisons.virtual_spring.equations`):

1. **Leader robot** (``leader_index``, slot offset (0, 0)): eq 6 towards
   ``obs.goal`` plus its spring force (eq 7), i.e. eq 8.
2. **Followers**: eq 9, the leader robot's broadcast velocity plus the
   consistency velocity ``beta u_i`` (eq 10-11 of the eq 4 input over Fig 1's
   neighbours: the leader and the adjacent followers) plus the spring force.
3. **Dynamic speed limit** (eq 12-13, followers, ``speed_limit``).
4. **Conflict resolution** (eq 15-17, every robot, ``conflict_resolution``)
   against the robots in communication range and the sensed moving obstacles.
5. The speed is capped at ``v_max``.

``virtual_spring_basic`` is the paper's "without improvement" model (Figs 5
and 8): the same controller with ``speed_limit = false`` and
``conflict_resolution = false`` by default.

Decisions (the paper's words, the choice and the reason:
``docs/methods/virtual_spring.md``):

1. Model: eq 6/8/9 give velocities ``v(t+1)``; the command is that velocity
   (see above) rather than eq 4's ``u``, which eq 10 turns into a velocity.
2. Topology (Fig 1, "each follower shares information with both the leader and
   the adjacent robots"): followers in index order without the leader; follower
   k hears the leader and followers k-1, k+1 (if within communication range).
   The Laplacian uses row sums (eq 2), not the text's column sums.
3. Formation offsets: ``E_i = R(theta_0) (offsets[i] - offsets[leader_index])``
   as fixed world vectors, ``theta_0`` the virtual leader's start heading
   (``offset_frame = "world"``, Table 1; the simulator's slots coincide with
   them while the virtual leader keeps that heading), or turned with the
   leader robot's heading (``"leader"``).
4. Leader state: the ``obs.neighbours`` entry of ``leader_index``; without it
   the virtual leader's point of that robot's slot (``obs.leader``).
5. Eq 8's ``v_l(t)`` is eq 6's velocity (not the robot's current velocity,
   which would integrate ``f`` every step); eq 9's ``v_l_a(t+1)`` is the
   leader's broadcast velocity, i.e. its eq 8 velocity one step earlier.
6. Eq 10-11: ``E_s = |u_i|`` and ``phi`` = the direction of ``u_i``, so
   ``v_fi = beta u_i``; the printed "angle between robot position i and the x
   axis" would push robots away from the world origin.
7. Eq 7: every static circle and polygon (their nearest boundary point), every
   sensed moving obstacle and every robot in range is a source; ``d`` is the
   body clearance (centre distance minus both radii), floored at
   ``spring_min_distance``; sources farther than ``spring_range`` are ignored;
   ``spring_gain`` scales the force (the paper's 1 with unknown units).
8. Eq 12-13 ("dynamic speed-limiting function") caps the eq 9 speed of the
   followers; the error is ``|p_i - p_l - E_i|``; eq 13's ``v_i(t)`` is the
   robot's previous limit, starting at v_max (``limit_memory = "limit"``; or
   its current speed, ``"speed"``); the denominator is at least
   ``error_floor`` and the limit at least ``min_speed_limit`` (as printed, a
   follower at rest with a constant error could never move again).
9. Eq 15-16 with a finite ``vo_horizon`` and ``vo_margin`` on the radii; eq 17
   (a scalar added to a vector) as a speed change along the pair's mean
   direction of motion; a non-cooperating moving obstacle makes robot i take
   ``obstacle_share`` times its half.
10. Eq 14's ideal position is the robot's slot around the virtual leader,
    which runs the obstacle-free route (``log.slots``):
    :func:`dfcoa_opt.metrics.robots.mse_per_robot`.

Batched (:class:`~dfcoa_opt.control.base.BatchedController`): one object
steps every run of a batch in one pass, per-run values in rows ``env * N +
robot``; each run gets the bits of the run simulated alone.

Measured (details in the doc): eq 12-13 lowers a follower's limit whenever its
error shrinks, so followers of a leader at v_max keep their gaps; on the test
courses both improvements raised the formation error relative to
``virtual_spring_basic``, while eq 17 kept obstacle robots farther away.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from comparisons.virtual_spring.equations import (
    cap_speed,
    consensus_input,
    consistency_velocity,
    dynamic_speed_limit,
    error_trend,
    fig1_adjacency,
    follower_avoidance_velocity,
    inverse_cube,
    leader_avoidance_velocity,
    leader_velocity,
    norm2,
)
from comparisons.virtual_spring.kernels import (
    conflict_changes,
    spring_sources,
    static_sources,
    weighted_sum,
)
from dfcoa_opt.control.base import BatchedController, Observation, as_batch, slot_velocity
from dfcoa_opt.control.registry import register
from dfcoa_opt.core.geometry import body_to_world, rotate
from dfcoa_opt.core.params import param

#: Below this broadcast speed the leader robot's heading is the virtual leader's, m/s.
_STILL = 1e-3


@register("virtual_spring")
class VirtualSpring(BatchedController):
    """Paper 004: virtual-spring consensus formation with speed limit and VO conflict resolution.

    Batched: one object for the E runs of a batch (or one run).

    Attributes:
        last_conflicts: ``(R,)`` number of eq 15-16 conflicts each row resolved
            at the latest step.
        last_limit: ``(R,)`` eq 13 speed limits of the latest step, m/s (``v_max``
            for the leader and when ``speed_limit`` is off).
    """

    command = "velocity"
    uses_scan = False  # sources: the map's circles and polygons, neighbours, moving obstacles

    @dataclass(frozen=True)
    class Params:
        """Parameters of ``virtual_spring`` (the paper gives none of their values)."""

        leader_index: int = param(0, doc="Robot index of the paper's leader robot (slot offset "
                                         "(0, 0)).", ge=0,
                                  robot_index=True)
        offset_frame: Literal["world", "leader"] = param(
            "world", doc="E_i = offsets[i] - offsets[leader_index] turned by the virtual "
                         "leader's start heading, then fixed world vectors (Table 1), or "
                         "turned with the leader robot's heading.")
        v_max: float | None = param(None, doc="Largest speed of eq 6, 12-13 and the final "
                                              "cap; default robots.v_max.", unit="m/s", gt=0.0)
        alpha: float = param(0.2, doc="Eq 6 coefficient: leader speed = min(alpha d, v_max).",
                             unit="1/s", gt=0.0, tune=(0.05, 1.0), scale="log")
        beta: float = param(0.15, doc="Eq 10 adjustment coefficient: v_fi = beta u_i.",
                            unit="1/s", gt=0.0, tune=(0.03, 1.0), scale="log")
        velocity_weight: float = param(1.0, doc="Weight k_v of the velocity differences in "
                                                "eq 4 (printed: 1).", unit="s", ge=0.0,
                                       tune=(0.0, 3.0))
        spring_gain: float = param(0.02, doc="Eq 7 gain: f = gain (p_i - p_k)/d^3.",
                                   unit="m^3/s", ge=0.0, tune=(0.002, 0.2), scale="log")
        spring_range: float = param(1.0, doc="Sources with a body clearance above this add no "
                                             "eq 7 force.", unit="m", gt=0.0, finite=False,
                                    tune=(0.3, 3.0))
        spring_min_distance: float = param(0.05, doc="Eq 7's d is at least this (contact and "
                                                     "overlap).", unit="m", gt=0.0)
        speed_limit: bool = param(True, doc="Apply eq 12-13's dynamic speed limit to the "
                                            "followers.")
        error_floor: float = param(0.2, doc="Eq 12's denominator E_i(t) is at least this.",
                                   unit="m", ge=0.0)
        min_speed_limit: float = param(0.1, doc="Eq 13's limit is at least this (0: as "
                                                "printed).", unit="m/s", ge=0.0)
        limit_memory: Literal["limit", "speed"] = param(
            "limit", doc="Eq 13's v_i(t): the robot's previous limit (starting at v_max) or "
                         "its current speed |v_i(t)|.")
        conflict_resolution: bool = param(True, doc="Apply eq 15-17 against robots and moving "
                                                    "obstacles.")
        vo_horizon: float = param(3.0, doc="Largest tau of eq 15's ray (inf: as printed).",
                                  unit="s", gt=0.0, finite=False)
        vo_margin: float = param(0.1, doc="Added to r_i + r_ck in eq 16's Minkowski sum.",
                                 unit="m", ge=0.0)
        obstacle_share: float = param(2.0, doc="Robot i's eq 17 change against a moving "
                                               "obstacle, in halves of |v_i - v_ck| (it does "
                                               "not take its half).", ge=0.0)

    def __init__(self, params: Params) -> None:
        self.p = params
        self._n = 1
        self._rel = np.zeros((1, 2))
        self._adj = np.zeros((1, 1))
        self._lead_offset = np.zeros((1, 2))
        self._v_max = 0.5
        self._radius = 0.2
        self._static = static_sources([((), (), [])])
        self._world_of = np.zeros(1, dtype=np.intp)
        self._circles, self._circle_r = self._static.circles, self._static.circle_r
        self._polygons: list[np.ndarray] = []
        self._t_seen = np.zeros(0)
        self._e_prev, self._e_last = np.zeros(0), np.zeros(0)
        self._lim_prev, self._lim_last = np.zeros(0), np.zeros(0)
        self.last_conflicts = np.zeros(0, dtype=int)
        self.last_limit = np.zeros(0)

    def reset_batch(self, scenarios, rngs) -> None:
        """Keep each run's offsets and static obstacles, Fig 1's adjacency, limits; clear eq 12.

        Run ``e``'s values are in rows ``e * N .. e * N + N - 1`` of the per-robot
        tables (offsets ``E_i``, eq 12-13's memory), its static obstacles those
        of its world (:func:`~comparisons.virtual_spring.kernels.static_sources`).
        The runs share the robots and the team size (one scenario file).
        ``rngs`` are not used (nothing is drawn).

        Raises:
            ValueError: ``leader_index`` is not a robot of the scenario.
        """
        p, spec, n = self.p, scenarios[0].spec, scenarios[0].n
        if p.leader_index >= n:
            raise ValueError(f"{self.name}: leader_index = {p.leader_index} but the scenario "
                             f"has {n} robot(s) (0..{n - 1})")
        self._n, runs = n, len(scenarios)
        offsets = np.stack([np.asarray(sc.offsets, dtype=float) for sc in scenarios])
        self._lead_offset = offsets[:, p.leader_index].copy()  # (E, 2)
        rel = offsets - self._lead_offset[:, None]
        if p.offset_frame == "world":
            rel = rotate(rel, np.array([sc.leader_heading for sc in scenarios])[:, None])
        self._rel = rel.reshape(runs * n, 2)
        adj = fig1_adjacency(n, p.leader_index)
        adj[:, p.leader_index] = 0.0  # the leader term is added from the leader state
        self._adj = adj
        self._v_max = spec.robots.v_max if p.v_max is None else min(p.v_max, spec.robots.v_max)
        self._radius = spec.robots.radius
        worlds: dict[int, int] = {}  # runs of one world (all but a seeded clutter field) share it
        for sc in scenarios:
            worlds.setdefault(id(sc.world), len(worlds))
        self._world_of = np.array([worlds[id(sc.world)] for sc in scenarios], dtype=np.intp)
        shapes = {id(sc.world): sc.world for sc in scenarios}.values()
        self._static = static_sources([([c.center for c in w.circles],
                                        [c.radius for c in w.circles], list(w.polygons))
                                       for w in shapes])  # static: built once
        # every world's circles and polygons, one after the other (one run: its world's)
        self._circles, self._circle_r = self._static.circles, self._static.circle_r
        self._polygons = [np.asarray(v, dtype=float) for w in shapes for v in w.polygons]
        rows = runs * n
        self._t_seen = np.full(rows, -np.inf)
        self._e_prev, self._e_last = np.full(rows, np.nan), np.full(rows, np.nan)
        self._lim_prev, self._lim_last = np.full(rows, self._v_max), np.full(rows, self._v_max)
        self.last_conflicts = np.zeros(rows, dtype=int)
        self.last_limit = np.full(rows, self._v_max)

    # ------------------------------------------------------------------ pieces
    def leader_state(self, obs: Observation) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each row's view of the leader robot: position, velocity (m, m/s) and heading (rad).

        The leader's own row uses its own state; a follower uses the
        ``obs.neighbours`` entry of ``leader_index``, or, when the leader robot is
        out of range, the virtual leader's point of that robot's slot and its
        velocity (the virtual leader of the row's run).
        """
        obs = as_batch(obs)
        nb = obs.neighbours
        rows = np.arange(obs.n)
        hit = self._neighbour_robots(obs, -1) == self.p.leader_index
        seen = hit.any(axis=1)
        if hit.shape[1]:
            k = np.argmax(hit, axis=1)
            nb_p, nb_v = nb.position[rows, k], nb.velocity[rows, k]
        else:  # no neighbour columns (a team of one): nobody sees the leader robot
            nb_p = nb_v = np.zeros((obs.n, 2))
        own = (obs.robot_ids == self.p.leader_index)[:, None]
        lead = obs.row_leader()
        virt = v_virt = np.zeros(2)  # only used by the rows that neither are nor see the leader
        if not (seen | own[:, 0]).all():
            virt = body_to_world(lead[:, :3], self._lead_offset[obs.env])
            v_virt = slot_velocity(lead, virt)
        p_l = np.where(own, obs.pose[:, :2], np.where(seen[:, None], nb_p, virt))
        v_l = np.where(own, obs.velocity, np.where(seen[:, None], nb_v, v_virt))
        moving = np.hypot(v_l[:, 0], v_l[:, 1]) > _STILL
        heading = np.where(moving, np.arctan2(v_l[:, 1], v_l[:, 0]), lead[:, 2])
        return p_l, v_l, heading

    def _neighbour_robots(self, obs: Observation, pad: int) -> np.ndarray:
        """``(R, K)`` robot index (within its run) of each neighbour, ``pad`` where there is none.

        A batch's neighbour indices are rows (blocks of N per run), a single
        run's are robots: either way the robot is the index modulo N.
        """
        nb = obs.neighbours
        return np.where(nb.mask, nb.index % self._n, pad)

    def desired_offsets(self, index: np.ndarray, heading: np.ndarray) -> np.ndarray:
        """World ``E`` of the robots ``index`` (``(R,)`` or ``(R, K)``) for each row, m.

        ``index`` are rows of the per-robot tables: ``env * N + robot``.
        """
        rel = self._rel[index]
        if self.p.offset_frame == "world":
            return rel
        th = heading.reshape(heading.shape + (1,) * (index.ndim - 1))
        return rotate(rel, th)

    def spring(self, obs: Observation) -> np.ndarray:
        """Eq 7 for every row: static discs and polygons, robots in range, moving obstacles.

        The sources are, in this order, the static circles, the polygons' nearest
        boundary points (edges built at reset) of the row's own world, the
        neighbours and the moving obstacles: one compiled pass
        (:func:`~comparisons.virtual_spring.kernels.spring_sources`, the operations
        of ``disc_normals``, ``polygon_normals`` and ``spring_force``), numpy's
        inverse cube, then eq 7's sum in numpy's order.
        """
        obs = as_batch(obs)
        nb, mo, st = obs.neighbours, obs.obstacles, self._static
        world = self._world_of[obs.env]
        static = np.diff(st.circle_ptr) + np.diff(st.polygon_ptr)
        shape = (obs.n, int(static[world].max(initial=0)) + nb.index.shape[1]
                 + mo.mask.shape[1])
        delta, dist, use = np.empty((*shape, 2)), np.empty(shape), np.empty(shape, dtype=bool)
        count = np.empty(obs.n, dtype=np.int64)
        spring_sources(np.ascontiguousarray(obs.pose[:, :2]), world, st.circles, st.circle_r,
                       st.circle_ptr, st.edges.a, st.edges.b, st.edge_count, st.polygon_ptr,
                       nb.position, nb.mask, mo.position, mo.radius, mo.mask, self._radius,
                       self.p.spring_range, self.p.spring_min_distance, delta, dist, use, count)
        f = np.empty((obs.n, 2))
        weighted_sum(inverse_cube(dist, use), delta, count, self.p.spring_gain, f)
        return f

    def _trend(self, t: float, ids: np.ndarray, err: np.ndarray) -> np.ndarray:
        """Eq 12's epsilon from each robot's own error history (``ids``: ``env * N + robot``).

        The memory moves on only when ``t`` is later than the robot's last call,
        so calling ``act`` again within a step (``assert_distributed``) gives the
        same result. Without a previous error (first step), epsilon is 0.
        """
        newer = t > self._t_seen[ids]
        for prev, last in ((self._e_prev, self._e_last), (self._lim_prev, self._lim_last)):
            prev[ids] = np.where(newer, last[ids], prev[ids])
        self._e_last[ids] = err
        self._t_seen[ids] = t
        prev = self._e_prev[ids]
        known = ~np.isnan(prev)
        return np.where(known, error_trend(err, np.where(known, prev, err), self.p.error_floor),
                        0.0)

    def resolve(self, obs: Observation, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eq 15-17 on planned velocities ``v`` (R, 2): the changes and the conflict counts.

        The other robots (Minkowski radius ``2 r``) and the moving obstacles
        (their radius ``+ r``, ``obstacle_share``) within range, through
        :func:`~comparisons.virtual_spring.kernels.conflict_changes`: the operations
        of :func:`~comparisons.virtual_spring.conflict.vo_conflict` and
        :func:`~comparisons.virtual_spring.conflict.conflict_resolution`, compiled,
        run by run.
        """
        obs = as_batch(obs)
        nb, mo, n = obs.neighbours, obs.obstacles, obs.n
        dv, count = np.empty((n, 2)), np.empty(n, dtype=np.int64)
        conflict_changes(np.ascontiguousarray(obs.pose[:, :2]), np.ascontiguousarray(v),
                         np.ascontiguousarray(obs.env), nb.position, nb.velocity, nb.mask,
                         mo.position, mo.velocity, mo.radius, mo.mask, self._radius,
                         self.p.vo_margin, self.p.vo_horizon, self.p.obstacle_share, dv, count)
        return dv, count

    # --------------------------------------------------------------------- act
    def act(self, obs: Observation) -> np.ndarray:
        """``(R, 2)`` world velocities ``v_i(t+1)``, row i from row i of ``obs``.

        ``obs`` is a batch's (every row of every active run) or one run's.
        """
        obs = as_batch(obs)
        p = self.p
        pos, vel, ids = obs.pose[:, :2], obs.velocity, obs.robot_ids
        base_row = obs.env * self._n
        key = base_row + ids  # the row's robot in the per-robot tables
        lead = ids == p.leader_index
        p_l, v_l, heading = self.leader_state(obs)
        nb = obs.neighbours
        nb_idx = self._neighbour_robots(obs, 0)
        e_own = self.desired_offsets(key, heading)
        # eq 4 over Fig 1's neighbours: the adjacent followers in range, plus the leader
        a = np.column_stack((self._adj[ids[:, None], nb_idx] * nb.mask, (~lead).astype(float)))
        p_j = np.concatenate((nb.position, p_l[:, None]), axis=1)
        v_j = np.concatenate((nb.velocity, v_l[:, None]), axis=1)
        e_j = np.concatenate((self.desired_offsets(base_row[:, None] + nb_idx, heading),
                              np.zeros((obs.n, 1, 2))), axis=1)
        u = consensus_input(pos, vel, e_own, p_j, v_j, e_j, a, p.velocity_weight)
        f = self.spring(obs)
        v_lead = leader_avoidance_velocity(leader_velocity(pos, obs.goal, p.alpha, self._v_max),
                                           f)
        v_fol = follower_avoidance_velocity(v_l, consistency_velocity(u, p.beta), f)
        v = np.where(lead[:, None], v_lead, v_fol)
        # eq 12-13, followers
        err = norm2(pos - p_l - e_own)
        eps = self._trend(obs.t, key, err)
        base = (self._lim_prev[key] if p.limit_memory == "limit"
                else np.hypot(vel[:, 0], vel[:, 1]))
        limit = np.where(lead, self._v_max,
                         dynamic_speed_limit(base, eps, self._v_max, p.min_speed_limit))
        self._lim_last[key] = limit
        if p.speed_limit:
            v = cap_speed(v, limit)
        else:
            limit = np.full(obs.n, self._v_max)
        self.last_limit = limit
        # eq 15-17, every robot
        if p.conflict_resolution:
            dv, count = self.resolve(obs, v)
            v = v + dv
            self.last_conflicts = count
        else:
            self.last_conflicts = np.zeros(obs.n, dtype=int)
        return cap_speed(v, np.full(obs.n, self._v_max))


@register("virtual_spring_basic")
class VirtualSpringBasic(VirtualSpring):
    """Paper 004 "without improvement" (Figs 5, 8): spring force and consensus only."""

    @dataclass(frozen=True)
    class Params(VirtualSpring.Params):
        """Parameters of ``virtual_spring_basic``: ``virtual_spring``'s, both improvements off."""

        speed_limit: bool = param(False, doc="Apply eq 12-13's dynamic speed limit (off: the "
                                             "paper's model without improvement).")
        conflict_resolution: bool = param(False, doc="Apply eq 15-17 (off: the paper's model "
                                                     "without improvement).")
