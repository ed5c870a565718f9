"""Paper 002's leader-follower V formation with a sampled velocity obstacle: ``lf_vo``.

Every robot is a unicycle (``command = "unicycle"``, rows ``(v, omega)``) and
runs the same law on its own observation row:

1. **Target.** The paper's leader robot is robot ``leader_index`` (default 0,
   the apex of ``formation.shape = "v"``, slot offset (0, 0)). Its target is its
   slot, i.e. the broadcast virtual leader, which the simulator moves along the
   planned path by pure pursuit. A follower's target is eq 5-6 applied to the
   leader robot's broadcast state (``follow = "robot"``, default): position from
   ``obs.neighbours`` (the entry whose index is ``leader_index``), heading
   ``atan2`` of its broadcast velocity (a unicycle with ``v > 0`` moves along
   its heading). The observation carries no neighbour heading, so when the
   leader robot moves slower than 1 mm/s the virtual leader's heading is used;
   when it is out of communication range the follower uses its own slot
   ``obs.slot`` (the virtual-leader-relative target). ``follow = "virtual"``
   always uses ``obs.slot``.
2. **Preferred command.** Eq 7-11 (distance ``l``, direction ``theta_T``, angle
   ``alpha``) and eq 4: ``v = min(l / t, v_max)``, ``omega = 2 v sin(-alpha) / l``.
3. **Sampled velocity obstacle (eq 12).** ``(v, omega)`` samples on a grid over
   ``[0, v_max] x [-w_max, w_max]`` (plus the preferred command) are rolled out
   over ``horizon`` s; a sample is rejected when its path comes closer than the
   robot radius + ``safety_margin`` to a static disc (``scenario.world.circles``),
   another robot (``obs.neighbours``, constant velocity) or a moving human
   (``obs.obstacles``, constant velocity). The safe sample with the least
   penalty (:func:`comparisons.lf_vo.equations.vo_cost`) is applied.
4. **Fallback.** When every sample is rejected: ``"least_penetration"``
   (default) applies the sample whose path keeps the largest clearance;
   ``"stop"`` applies (0, 0). ``last_fallbacks`` counts the robots that fell
   back at the latest step (the simulator does not log it).

Speed: ``kernel = "numba"`` (default) computes step 3 with
:func:`comparisons.lf_vo.kernel.vo_clearance` (one call and one rollout per
robot for robots, humans and discs, each checked over its own horizon; exact
clearances with culling of obstacles that cannot be the nearest, and, since the
choice reads only their sign and the negative values, of those that cannot
bring a clearance below 0) and the choice with
:func:`comparisons.lf_vo.choose.vo_choose` (costs of the safe samples only,
trigonometry once per turn rate); ``kernel = "numpy"`` is the dense reference
(:func:`comparisons.lf_vo.equations.rollout`, :func:`~comparisons.lf_vo.equations.path_clearance`,
:func:`~comparisons.lf_vo.equations.vo_cost`). Both give the same commands.

Batches: the controller is batched (one object and one :meth:`~LeaderFollowerVO.act`
per step for every run of a batch, every row through the same kernel calls);
each row's command is the one the run simulated alone gives, bit for bit.

Decisions (the paper's words, the choice and the reason; also in
``docs/methods/lf_vo.md``):

* Follower v_max. Table I: "Maximum Linear Velocity for Followers 6.5 m/s",
  13 times the leader's 0.5 m/s, while Tables II-IV report follower mean speeds
  of 0.45-0.49 m/s. We read it as a misprint of 0.65 m/s (``follower_v_max``
  default): followers need a little more speed than the leader to catch up.
* Time interval t of eq 4 ("calculated based on the distance towards the
  target, given the time interval t"): no value is given. ``reach_time``
  defaults to 0.5 s: with t = dt = 0.1 s the law is dead-beat, the leader
  robot weaved at +-w_max around the virtual leader and the followers (whose
  targets turn with it) lost the formation. Cost: a steady lag of
  ``v * reach_time`` (0.2 m at 0.4 m/s) behind each target.
* Eq 4's ``alpha`` (target minus heading, eq 1) and eq 11's (heading minus
  target) have opposite signs; ``omega`` turns towards the target. A target
  behind the robot (``cos alpha < 0``) makes pure pursuit drive away (its
  ``sin`` vanishes); ``turn_when_behind`` (default) turns in place instead.
* Eq 12 is an infinite-horizon cone on a straight-line velocity; a unicycle
  sample ``(v, omega)`` turns for ``turn_time`` (1 s) and then goes straight,
  and the cone test is done on that predicted path over ``horizon`` (the
  paper gives none; 3 s), against constant-velocity obstacles. Holding
  ``omega`` over the whole horizon (circles) left no escape from a head-on
  human.
* Penalties: "distance to the optimum selected velocity and consistency with
  the target direction" -- norms and weights are not given. We use the
  distance between world velocities and the shortfall of the progress towards
  the target (:func:`comparisons.lf_vo.equations.vo_cost`); an angle penalty made
  stopping in front of a static disc cheaper than going round it (deadlock).
* The preferred command (eq 4) is added to the samples
  (``include_preferred``), so in free space the robot runs eq 4 exactly.
* Speed limits are also capped at the scenario's ``robots.v_max``/``w_max``
  (the model clips there, and predictions must match what the robot does).
* Only circular static obstacles are avoided (the paper's static obstacles are
  discs); polygons and map cells are not seen by this controller.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from comparisons.lf_vo.choose import vo_choose
from comparisons.lf_vo.equations import (
    formation_target,
    path_clearance,
    reference_command,
    rollout,
    target_error,
    vo_cost,
)
from comparisons.lf_vo.kernel import vo_clearance
from dfcoa_opt.control.base import BatchedController, Observation, as_batch
from dfcoa_opt.control.registry import register
from dfcoa_opt.core.params import param

if TYPE_CHECKING:
    from dfcoa_opt.scenario.scenario import Scenario

#: Below this broadcast speed the leader robot's heading is taken from the virtual leader, m/s.
_STILL = 1e-3


@register("lf_vo")
class LeaderFollowerVO(BatchedController):
    """Leader-follower V formation (eq 4-11) with a sampled velocity obstacle (eq 12).

    Batched (:class:`~dfcoa_opt.control.base.BatchedController`): one object
    steps every run of a batch in one :meth:`act`. Every row's command is
    computed as in a single run (elementwise, the kernels per row); what is
    per run is kept by ``obs.env``: the leader robot's offset, and the static
    discs of the run's world (a seeded clutter field differs between runs).
    A follower finds its leader robot among its neighbours by row: in a
    batch, neighbour indices are rows, and the leader robot of row ``i`` is
    row ``i - robot_ids[i] + leader_index`` (runs are blocks of N rows).
    """

    command = "unicycle"
    uses_scan = False  # obstacles come from the map's discs, obs.neighbours and obs.obstacles

    @dataclass(frozen=True)
    class Params:
        """Parameters of ``lf_vo`` (Table I for the speed limits)."""

        leader_index: int = param(0, doc="Robot index of the paper's leader robot (its slot "
                                         "should be the formation apex).", ge=0,
                                  robot_index=True)
        leader_v_max: float = param(0.5, doc="Leader robot's largest speed (Table I).",
                                    unit="m/s", gt=0.0)
        follower_v_max: float = param(0.65, doc="Followers' largest speed (Table I's 6.5 m/s "
                                                "read as 0.65).", unit="m/s", gt=0.0)
        w_max: float = param(1.0, doc="Largest turn rate (Table I).", unit="rad/s", gt=0.0)
        reach_time: float = param(0.5, doc="Time interval t of eq 4, v = min(l/t, v_max) "
                                           "(not given by the paper).", unit="s", gt=0.0,
                                  tune=(0.2, 3.0), scale="log")
        arrival_radius: float = param(0.1, doc="Within this distance of its target a robot "
                                               "prefers (0, 0) and holds its place: it does not "
                                               "give way to other robots (not in the paper).",
                                      unit="m", ge=0.0)
        turn_when_behind: bool = param(True, doc="Turn in place (v = 0, |omega| = w_max) "
                                                 "towards a target behind the robot.")
        follow: Literal["robot", "virtual"] = param(
            "robot", doc="Followers' eq 5-6 reference: the leader robot's broadcast state "
                         "('robot') or the virtual leader ('virtual', i.e. obs.slot).")
        v_samples: int = param(11, doc="Speed samples in [0, v_max].", ge=2, le=1000)
        w_samples: int = param(21, doc="Turn-rate samples in [-w_max, w_max] (odd: includes "
                                       "0).", ge=2, le=1000)
        include_preferred: bool = param(True, doc="Add the eq 4 preferred command as a sample.")
        horizon: float = param(5.0, doc="Prediction horizon of the velocity obstacle "
                                        "against static discs and humans.", unit="s", gt=0.0,
                               tune=(1.0, 8.0))
        turn_time: float = param(1.0, doc="A sample turns at omega for this long, then goes "
                                           "straight (rollout and heading penalty).", unit="s",
                                 gt=0.0)
        robot_horizon: float = param(2.0, doc="Prediction horizon against the other robots "
                                              "(at most horizon).", unit="s", gt=0.0,
                                     tune=(0.5, 4.0))
        horizon_steps: int = param(50, doc="Prediction steps over the horizon.", ge=1,
                                   le=10_000)
        safety_margin: float = param(0.05, doc="Clearance added to robot + obstacle radii.",
                                     unit="m", ge=0.0, tune=(0.0, 0.3))
        avoid_robots: bool = param(True, doc="Treat neighbours as constant-velocity obstacles.")
        pref_weight: float = param(1.0, doc="Weight of the distance to the preferred "
                                            "velocity.", unit="s/m", ge=0.0)
        heading_weight: float = param(1.0, doc="Weight of the progress shortfall towards the "
                                               "target direction.", unit="s/m", ge=0.0,
                                      tune=(0.1, 10.0), scale="log")
        turn_weight: float = param(0.01, doc="Weight of the turn-rate distance to eq 4's "
                                             "(breaks ties: a stopped robot does not spin).",
                                   unit="s/rad", ge=0.0)
        escape_turn: bool = param(False, doc="Not in the paper: a robot away from its target "
                                             "whose only safe samples stand still turns at the "
                                             "rate whose forward samples are least blocked, "
                                             "instead of the (0, 0) the penalties pick.")
        fallback: Literal["least_penetration", "stop"] = param(
            "least_penetration", doc="Command when every sample is rejected.")
        kernel: Literal["numba", "numpy"] = param(
            "numba", doc="Clearance code: the numba kernel (comparisons.lf_vo.kernel) or the "
                         "numpy reference (rollout + path_clearance); same decisions.")

    def __init__(self, params: Params) -> None:
        self.p = params
        self.last_fallbacks = 0
        self.last_fell = np.zeros(0, dtype=bool)
        self._radius = 0.2
        self._v_lead, self._v_fol, self._w_max = (params.leader_v_max, params.follower_v_max,
                                                  params.w_max)
        self._lead_offset = np.zeros((1, 2))  # (E, 2): each run's leader robot's slot offset
        self._discs = np.zeros((0, 3))  # every world's discs (cx, cy, reach), world after world
        self._disc_ptr = np.zeros(2, dtype=np.intp)  # world g's: rows ptr[g]:ptr[g + 1]
        self._world_of = np.zeros(1, dtype=np.intp)  # (E,) each run's world
        self._grid: tuple[float, np.ndarray, np.ndarray] = (np.nan, np.zeros(0), np.zeros(0))

    def reset_batch(self, scenarios: list[Scenario], rngs: list[np.random.Generator]) -> None:
        """Keep the robot radius, speed limits, and per run the leader's offset and the discs.

        Args:
            scenarios: Run ``e``'s scenario (the same file and overrides; runs with a
                seeded clutter field have their own world).
            rngs: Run ``e``'s generator (unused: ``lf_vo`` draws nothing).

        Raises:
            ValueError: ``leader_index`` is not a robot of the scenario.
        """
        p, sc0 = self.p, scenarios[0]
        spec = sc0.spec
        if p.leader_index >= sc0.n:
            raise ValueError(f"lf_vo: leader_index = {p.leader_index} but the scenario has "
                             f"{sc0.n} robot(s) (0..{sc0.n - 1})")
        self._radius = spec.robots.radius
        self._v_lead = min(p.leader_v_max, spec.robots.v_max)
        self._v_fol = min(p.follower_v_max, spec.robots.v_max)
        self._w_max = min(p.w_max, spec.robots.w_max)
        self._lead_offset = np.array([np.asarray(sc.offsets[p.leader_index], dtype=float)
                                      for sc in scenarios]).reshape(len(scenarios), 2)
        worlds: dict[int, int] = {}  # runs of one world (all but a seeded clutter field) share
        tables = []
        for sc in scenarios:
            if id(sc.world) not in worlds:
                worlds[id(sc.world)] = len(tables)
                tables.append(np.array([(*c.center, c.radius) for c in sc.world.circles],
                                       dtype=float).reshape(-1, 3))
        discs = np.concatenate(tables)
        discs[:, 2] = discs[:, 2] + (self._radius + p.safety_margin)  # radius -> reach
        self._discs = discs
        self._disc_ptr = np.concatenate(([0], np.cumsum([len(t) for t in tables])))
        self._world_of = np.array([worlds[id(sc.world)] for sc in scenarios], dtype=np.intp)
        self.last_fallbacks = 0
        self.last_fell = np.zeros(0, dtype=bool)

    def targets(self, obs: Observation) -> np.ndarray:
        """``(N, 2)`` eq 5-6 targets, m: the slot for the leader robot, else around its state.

        In a batch (``obs.env`` set) the leader robot is looked up by row among
        the neighbours (``i - robot_ids[i] + leader_index``); in one run's
        observation neighbour indices are robot indices.
        """
        target = obs.slot.copy()
        if self.p.follow == "virtual":
            return target
        nb, lead = obs.neighbours, self.p.leader_index
        rows = np.arange(obs.n)
        lead_row = lead if obs.env is None else (rows - obs.robot_ids + lead)[:, None]
        hit = nb.index == lead_row  # (N, K)
        seen = hit.any(axis=1) & (obs.robot_ids != lead)
        if not seen.any():
            return target
        obs = as_batch(obs)
        k = np.argmax(hit, axis=1)
        pos = nb.position[rows, k]
        vel = nb.velocity[rows, k]
        moving = np.hypot(vel[:, 0], vel[:, 1]) > _STILL
        heading = np.where(moving, np.arctan2(vel[:, 1], vel[:, 0]), obs.row_leader()[:, 2])
        lead_pose = np.column_stack((pos, heading))
        around = formation_target(lead_pose, obs.slot_offset - self._lead_offset[obs.env])
        return np.where(seen[:, None], around, target)

    def _robots(self, obs: Observation) -> tuple[np.ndarray, ...]:
        """Neighbours as obstacles: ``(N, K, ...)`` centres, velocities, reach and mask.

        The mask is all False unless ``avoid_robots``.
        """
        nb, r = obs.neighbours, 2.0 * self._radius + self.p.safety_margin
        mask = nb.mask if self.p.avoid_robots else np.zeros_like(nb.mask)

        return nb.position, nb.velocity, np.full(nb.index.shape, r), mask

    def _humans(self, obs: Observation) -> tuple[np.ndarray, ...]:
        """Sensed moving obstacles: ``(N, M, ...)`` as in :meth:`_robots`."""
        mo = obs.obstacles
        return mo.position, mo.velocity, mo.radius + self._radius + self.p.safety_margin, mo.mask

    def _static(self, env: np.ndarray) -> tuple[np.ndarray, ...]:
        """Each row's static discs (its run's world): ``(N, C, ...)`` as in :meth:`_robots`.

        ``C`` is the most discs of a row's world; a row of a world with fewer
        is padded (mask False), which leaves the reference's minimum as it is.
        """
        world = self._world_of[env]
        first, count = self._disc_ptr[world], np.diff(self._disc_ptr)[world]
        j = np.arange(count.max(initial=0))
        mask = j < count[:, None]
        table = self._discs[np.where(mask, first[:, None] + j, 0)] if len(self._discs) else \
            np.zeros((len(env), len(j), 3))
        return table[..., :2], np.zeros((*mask.shape, 2)), table[..., 2], mask

    def clearance(self, obs: Observation, v: np.ndarray, w: np.ndarray,
                  hold: np.ndarray | None = None, exact_below: float = np.inf) -> np.ndarray:
        """``(N, S)`` clearance of each sample, m (< 0: inside the velocity obstacle).

        Static discs and humans are checked over ``horizon``, the other robots
        over ``robot_horizon`` (the first steps of the same rollout). Rows where
        ``hold`` is True (robots at their target) do not check the other robots:
        an arrived robot holds its place and the moving ones give way. With the
        numba kernel, clearances of at least ``exact_below`` (m) are only known
        to be at least it (:func:`~comparisons.lf_vo.kernel.vo_clearance`).
        """
        p, pose = self.p, obs.pose
        env = as_batch(obs).env
        step = p.horizon / p.horizon_steps
        steps_r = min(p.horizon_steps, max(1, round(p.robot_horizon / step)))
        robots = self._robots(obs)
        if hold is not None:
            robots = (*robots[:3], robots[3] & ~np.asarray(hold, dtype=bool)[:, None])
        if p.kernel == "numpy":  # the reference: the robots over the first steps_r steps
            pts = rollout(pose, v, w, step, p.horizon_steps, p.turn_time)
            parts = [np.concatenate(pair, axis=1) for pair in zip(self._static(env),
                                                                  self._humans(obs), strict=True)]
            far = path_clearance(pts, step, *parts)
            near = path_clearance(pts[:, :, :steps_r], step, *robots)
            return np.minimum(far, near)
        # numba: one pass, the robots' columns checked over their first steps_r steps
        humans = self._humans(obs)
        cols = [np.concatenate(pair, axis=1) for pair in zip(humans, robots, strict=True)]
        limit = np.concatenate((np.full(humans[3].shape[1], p.horizon_steps),
                                np.full(robots[3].shape[1], steps_r)))
        return vo_clearance(pose, v, w, step, p.horizon_steps, p.turn_time, *cols,
                            self._discs[:, :2], self._discs[:, 2], w_stride=p.w_samples,
                            limit=limit, static_ptr=self._disc_ptr, static_of=self._world_of[env],
                            exact_below=exact_below)

    def samples(self, v_max: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(N, S)`` grid of (v, omega) samples for per-robot speed limits ``v_max`` (m/s)."""
        if self._grid[0] != self._w_max:  # the grid only changes with w_max (reset)
            self._grid = (self._w_max, np.linspace(0.0, 1.0, self.p.v_samples),
                          np.tile(np.linspace(-self._w_max, self._w_max, self.p.w_samples),
                                  self.p.v_samples))
        _, frac, w_row = self._grid
        v = np.repeat(v_max[:, None] * frac, self.p.w_samples, axis=1)
        w = np.broadcast_to(w_row, v.shape).copy()
        return v, w

    @staticmethod
    def _escape(cmd: np.ndarray, v: np.ndarray, w: np.ndarray, clear: np.ndarray,
                skip: np.ndarray) -> np.ndarray:
        """``escape_turn``: rows whose safe samples all stand still turn in place.

        The turn rate is that of the moving sample with the largest clearance
        (the direction least blocked); rows in ``skip`` (no safe sample, or at
        the target) keep their command.
        """
        safe = clear >= 0.0
        moving = v > 0.0
        stuck = ~skip & safe.any(axis=1) & ~(safe & moving).any(axis=1) & moving.any(axis=1)
        if not stuck.any():
            return cmd
        k = np.argmax(np.where(moving, clear, -np.inf), axis=1)
        out = cmd.copy()
        out[stuck] = np.column_stack((np.zeros(int(stuck.sum())), w[stuck, k[stuck]]))
        return out

    def act(self, obs: Observation) -> np.ndarray:
        """``(R, 2)`` commands (v m/s, omega rad/s) of every row of one run or of a batch.

        Row i uses robot i's pose, neighbours, sensed humans, slot, the leader
        state its run broadcast, and its run's static discs; all rows of all
        runs go through the kernels in one call. Sets ``last_fell`` ``(R,)``
        (the rows without a safe sample) and ``last_fallbacks`` (their number).
        """
        p = self.p
        pose = obs.pose
        lead = obs.robot_ids == p.leader_index
        v_max = np.where(lead, self._v_lead, self._v_fol)
        dist, theta_t, alpha = target_error(pose, self.targets(obs))
        v_ref, w_ref = reference_command(dist, alpha, v_max, self._w_max, p.reach_time,
                                         p.turn_when_behind, p.arrival_radius)
        v, w = self.samples(v_max)
        if p.include_preferred:
            v = np.column_stack((v, v_ref))
            w = np.column_stack((w, w_ref))
        # the choice reads the clearances' signs, and values only of negative ones (the
        # fallback's argmax when none is safe, escape_turn's among unsafe moving samples)
        clear = self.clearance(obs, v, w, hold=dist <= p.arrival_radius, exact_below=0.0)
        weights = (p.turn_time, p.pref_weight, p.heading_weight, p.turn_weight)
        if p.kernel == "numba":
            best, fell = vo_choose(pose[:, 2], v, w, v_ref, w_ref, theta_t, clear, *weights,
                                   w_stride=p.w_samples)
        else:  # the numpy reference
            cost = vo_cost(pose[:, 2], v, w, v_ref, w_ref, theta_t, *weights)
            safe = clear >= 0.0
            best = np.argmin(np.where(safe, cost, np.inf), axis=1)
            fell = ~safe.any(axis=1)
            best = np.where(fell, np.argmax(clear, axis=1), best)
        rows = np.arange(obs.n)
        cmd = np.column_stack((v[rows, best], w[rows, best]))
        if p.escape_turn:
            cmd = self._escape(cmd, v, w, clear, fell | (dist <= p.arrival_radius))
        if p.fallback == "stop":
            cmd[fell] = 0.0
        self.last_fell = fell
        self.last_fallbacks = int(fell.sum())
        return cmd
