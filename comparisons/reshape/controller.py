"""``reshape``: a formation that changes its shape, size and place to get through.

Beyond the papers (after Alonso-Mora, Baker & Rus, IJRR 2017: a formation
optimised inside a convex obstacle-free region). Every ``replan_period`` s a
central planner, from the robots' positions as their messages tell it, takes
the formation's progress ``s_c`` along the leader's path (the centroid's
nearest path point) and picks one of three modes (docs/methods/reshape.md):

1. **route** -- the leader's path ahead is blocked for the scenario's
   formation even at the smallest scale (a wall, a circle on the line, a
   clutter field): the rigid formation follows an A* route in its own
   configuration space at the largest scale whose route is within
   ``route_detour`` of the quickest passage, or goes in single file along a
   one-robot route (:mod:`~comparisons.reshape.routes`);
2. **nominal** -- the formation keeps up with the leader and fits on it now
   and 1 m on: every robot to its own slot with the leader's feed-forward
   (``goto_slot`` through the filter);
3. **region** -- otherwise: a convex free region grown around the segment
   from the centroid to the look-ahead goal ``g``
   (:mod:`~comparisons.reshape.region`; static shapes and the sensed moving
   discs swept over ``horizon`` s), and the template, rotation, scale and
   position chosen in it (:mod:`~comparisons.reshape.planner`). When nothing
   fits, the look-ahead is halved (twice), then the formation waits on its
   previous plan: counted as ``shrinks`` and ``waits``.

The planning of a run is :mod:`~comparisons.reshape.central` (one planner per
run). Robots take their own slots in the scenario's shape (success is judged on
those) and the Hungarian assignment otherwise, kept unless a new one is
``hysteresis`` cheaper. Tracking is distributed
(:mod:`~comparisons.reshape.tracking`): each robot drives to its target (to a
waypoint of its A* path when its line is blocked) with a proportional velocity
through the ``cbf`` filter; a robot held still away from its target has its
command turned (``unsticks``). Broadcast per plan: the mode and template id,
``t`` (2 floats), ``theta``, ``s`` and the assignment (N integers) -- 4 N + 24
bytes. The counters are in the run's metrics as ``ctl_*``.

Communication (docs/comms.md): the planner runs at the virtual leader. It
hears the robots through their messages (``Observation.team`` when
``comms.latency`` or ``comms.dropout`` is on), and its plan reaches the robots
with the leader's broadcast: a run whose broadcast is ``leader_age`` s old
follows the plan of ``round(leader_age / dt)`` steps before
(:mod:`~comparisons.reshape.relay`). Each robot tracks from its own pose.

Batched (:class:`~dfcoa_opt.control.base.BatchedController`): one object steps
every run of a batch. The due runs are planned one by one, each from its own
rows; the tracking is one elementwise pass over every row of every run (one
``cbf`` call), so each run's commands and counters are, bit for bit, those of
the run alone (``tests/test_batch.py``).
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from comparisons.cbf.filter import CbfFilter
from comparisons.reshape import planner
from comparisons.reshape.central import CentralPlanner, RunMap
from comparisons.reshape.params import ReshapeParams
from comparisons.reshape.relay import Plan, PlanRelay, depth_for
from comparisons.reshape.tracking import StuckMonitor
from dfcoa_opt.control.base import (
    BatchedController,
    FilterResult,
    MovingObstacles,
    Neighbours,
    Observation,
    as_batch,
    slot_velocity,
)
from dfcoa_opt.control.registry import register
from dfcoa_opt.core.geometry import rotate

if TYPE_CHECKING:
    from dfcoa_opt.scenario.scenario import Scenario
    from dfcoa_opt.world.robots.spec import RobotSpec

FloatArray = NDArray[np.float64]
#: How a run's robots track, by its latest plan: their own slots on the leader ...
NOMINAL = 0
#: ... fixed targets ...
FIXED = 1
#: ... or targets carried along in the leader's frame.
CARRIED = 2


@register("reshape")
class Reshape(BatchedController):
    """Reshaping formation: free region, template choice, assignment, CBF tracking.

    Batched (:class:`~dfcoa_opt.control.base.BatchedController`): one object
    for the E runs of a batch. Each run has its own
    :class:`~comparisons.reshape.central.CentralPlanner` (planning is per run);
    the tracking -- targets, guidance waypoints, stuck robots, the ``cbf``
    filter and the speed clip -- is one elementwise pass over every row of
    every run, with per-row state in row ``env * N + robot``.

    Attributes:
        p: Parameters.
        safety: The tracking filter (built by the reset: it needs the robots' ``v_max``).
        runs: The planner of each run, by ``env``.
        last_result: The filter's result of the latest step, one entry per row.
        last_plan: The plan each row followed at the latest step, as it reached
            the robots (the planner's latest, or an older one when the leader's
            broadcast is late), one entry per row.
    """

    command = "velocity"
    uses_scan = False
    Params = ReshapeParams  # the parameters (comparisons.reshape.params.ReshapeParams)

    def __init__(self, params: ReshapeParams) -> None:
        self.p = params
        self.safety: CbfFilter | None = None
        self.last_result: FilterResult | None = None
        self.last_plan: Plan | None = None
        self.runs: list[CentralPlanner] = []
        self._n = 0
        self._v_max = 1.0
        self._stuck = StuckMonitor(np.zeros((0, 2)), params.unstick_time, params.unstick_angle)
        self._next = np.zeros(0)  # time of each run's next plan, s
        self._mode = np.zeros(0, dtype=np.int8)  # NOMINAL, FIXED or CARRIED, per run
        self._target = np.zeros((0, 2))  # FIXED targets, per row, m
        self._carried = np.zeros((0, 2))  # CARRIED targets in the leader frame, per row, m
        self._waypoint = np.zeros((0, 2))  # guidance waypoints, per row, m
        self._guided = np.zeros(0, dtype=bool)  # rows heading for their waypoint
        self._relay = PlanRelay(0, 0, 1)  # the runs' recent plans, for a late broadcast
        # the assignment's state for :meth:`_assignment` alone (a run's is its planner's)
        self._assign = np.zeros(0, dtype=np.intp)
        self._template: str | None = None

    # ---------------------------------------------------------------------- set-up
    def gamma_for(self, robots: RobotSpec) -> float:
        """The filter's class-K gain for these robots, 1/s.

        The barrier lets a robot close in on an obstacle at ``gamma * h`` (``h``
        the distance beyond the margin, m), so following it decelerates at
        ``gamma * v``. A robot whose wheels brake at most ``a`` (m/s^2,
        ``robots.wheel_accel_max``) cannot follow a gain above ``a / v_max``: it
        overshoots the barrier into the wall. ``reshape_passage`` caps its gain
        there (S1 at 0.5 m/s^2: 12/12 runs, 4/12 uncapped); ``reshape`` keeps
        ``gamma`` as it was published. Without a limit (``inf``) it is ``gamma``.
        """
        if not self.p.coordinate:
            return self.p.gamma
        return min(self.p.gamma, robots.wheel_accel_max / robots.v_max)

    def reset_batch(self, scenarios: list[Scenario], rngs: list[np.random.Generator]) -> None:
        """Build the filter, the stuck-robot monitor and one planner per run.

        Args:
            scenarios: One scenario per run (one file: the same team and robots;
                the worlds differ when a clutter field follows the seed).
            rngs: One generator per run (``reshape`` draws nothing; the filter gets them).
        """
        spec = scenarios[0].spec
        # the box |u_x|, |u_y| <= v_max (the filter's default, v_max / sqrt 2, would hold
        # a formation moving along an axis to 71 % of its speed), the result clipped to
        # |u| <= v_max afterwards: a uniform saturation, which keeps every barrier row
        # reshape_passage keeps the static rows when a program is infeasible: a robot
        # squeezed between a walker and a wall gives way to the walker, never to the wall
        policy = "keep_static" if self.p.coordinate else "least_violation"
        self.safety = CbfFilter(CbfFilter.Params(solver="exact", v_max=spec.robots.v_max,
                                                 gamma=self.gamma_for(spec.robots),
                                                 infeasible=policy),
                                owner="reshape")
        self.safety.reset_batch(scenarios, rngs)
        n, runs = scenarios[0].n, len(scenarios)
        self._n, self._v_max = n, spec.robots.v_max
        start = np.concatenate([np.asarray(sc.initial_pose, float)[:, :2] for sc in scenarios])
        self._stuck = StuckMonitor(start, self.p.unstick_time, self.p.unstick_angle)
        maps: dict[int, RunMap] = {}  # runs of one scenario object share its map objects
        self.runs = [CentralPlanner(self.p, sc, maps, self._stuck, slice(e * n, (e + 1) * n),
                                    self.safety.pair_distance, self.safety.obstacle_distance)
                     for e, sc in enumerate(scenarios)]
        self._next = np.zeros(runs)
        self._mode = np.full(runs, NOMINAL, dtype=np.int8)
        self._target = np.zeros((runs * n, 2))
        self._carried = np.zeros((runs * n, 2))
        self._waypoint = np.zeros((runs * n, 2))
        self._guided = np.zeros(runs * n, dtype=bool)
        self._relay = PlanRelay(runs, n, depth_for(self.p.replan_period))
        self.last_result = self.last_plan = None

    # ------------------------------------------------------------ one run's results
    @property
    def counters(self) -> dict[str, int]:
        """Counters of the first run (of the only one outside a batch); see :meth:`run_counters`."""
        return self.runs[0].counters if self.runs else {}

    @property
    def history(self) -> list[tuple[float, str | None, float]]:
        """``(t, template, scale)`` of every plan of the first run (None: it waited)."""
        return self.runs[0].history if self.runs else []

    @property
    def plan_times(self) -> list[float]:
        """Wall time of every plan of the first run, s."""
        return self.runs[0].plan_times if self.runs else []

    def run_counters(self, env: int) -> dict[str, int]:
        """Run ``env``'s ``replans``, ``shrinks``, ``waits``, ``switches`` and ``unsticks``."""
        return dict(self.runs[env].counters)

    def _assignment(self, pos: FloatArray, slots: FloatArray, template: str) -> NDArray[np.intp]:
        """:func:`~comparisons.reshape.planner.assign` after ``_template`` and ``_assign``.

        The assignment as one run's planner makes it, with this object's
        ``_template`` and ``_assign`` as the previous plan's (set by hand: the
        runs' own are in :attr:`runs`).
        """
        return planner.assign(pos, slots, template, self._template, self._assign,
                              self.p.hysteresis)

    # ------------------------------------------------------------------ each step
    def act(self, obs: Observation) -> FloatArray:
        """Replan the due runs (central, per run), then track: every row of every run at once.

        Args:
            obs: The observation of one run, or of every active run of a batch.

        Returns:
            ``(R, 2)`` velocity commands (vx, vy), m/s, one per row.
        """
        assert self.safety is not None, "reset() first"
        obs = as_batch(obs)
        envs = np.unique(obs.env)
        for e in envs[obs.t >= self._next[envs] - 1e-9]:
            self._plan(obs, int(e))
        pos = obs.pose[:, :2]
        rows = obs.env * self._n + obs.robot_ids
        lead = obs.row_leader()
        plan = self.last_plan = self._heard(obs, rows)
        target = plan.target
        nominal = plan.mode == NOMINAL
        carried = plan.mode == CARRIED
        target[nominal] = obs.slot[nominal]
        if carried.any():  # a plan made while keeping up: carried along in the leader's frame
            target[carried] = lead[carried, :2] + rotate(plan.carried[carried],
                                                         lead[carried, 2])
        ff = slot_velocity(lead, target)  # the leader's feed-forward (nominal and carried)
        ff[~(nominal | carried)] = 0.0
        guided = plan.guided
        target[guided], ff[guided] = plan.waypoint[guided], 0.0
        u = self.p.kp * (target - pos) + ff
        u, turned = self._stuck.turn(obs.t, rows, pos, target, u)
        if turned:
            for e, count in zip(*np.unique(obs.env[self._stuck.turned], return_counts=True),
                                strict=True):
                self.runs[int(e)].counters["unsticks"] += int(count)
        speed = np.hypot(u[:, 0], u[:, 1])
        u = u * np.minimum(1.0, self._v_max / np.maximum(speed, 1e-12))[:, None]
        res = self.safety.filter(self._yielding(obs), u)
        speed = np.hypot(res.command[:, 0], res.command[:, 1])
        over = speed > self._v_max
        if over.any():
            res.command[over] *= (self._v_max / speed[over])[:, None]
        self.last_result = res
        return res.command

    def _yielding(self, obs: Observation) -> Observation:
        """``obs`` with each sensed moving disc grown by its speed times ``yield_time``.

        The filter then keeps a robot farther from a fast disc than from a slow
        one, so the robot gives way before the disc is on it (``yield_time`` 0:
        ``obs`` itself).
        """
        if self.p.yield_time <= 0.0 or not obs.obstacles.mask.any():
            return obs
        mv = obs.obstacles
        speed = np.hypot(mv.velocity[..., 0], mv.velocity[..., 1])
        grown = MovingObstacles(mv.position, mv.velocity,
                                np.where(mv.mask, mv.radius + self.p.yield_time * speed, 0.0),
                                mv.mask)
        return replace(obs, obstacles=grown)

    def _heard(self, obs: Observation, rows: NDArray[np.intp]) -> Plan:
        """The plan each row follows: its run's as of the leader broadcast the row holds.

        Args:
            obs: The batch's observation (``leader_age`` a number or ``(E,)`` by ``env``).
            rows: ``(R,)`` each row's index ``env * N + robot``.

        Returns:
            Fresh per-row arrays: the planner's latest plan where the broadcast
            is current (``leader_age`` 0), else the plan ``round(leader_age / dt)``
            steps older (:class:`~comparisons.reshape.relay.PlanRelay`).
        """
        env = obs.env
        assert env is not None, "as_batch(obs) first"
        age = np.asarray(obs.leader_age, dtype=float)
        lag = np.rint((age[env] if age.ndim else age) / obs.dt).astype(np.int64)
        if not np.any(lag):
            return Plan(self._mode[env], self._target[rows], self._carried[rows],
                        self._guided[rows], self._waypoint[rows])
        step = _step(obs) - np.broadcast_to(lag, env.shape)
        return self._relay.heard(env, obs.robot_ids, step)

    def _plan(self, obs: Observation, e: int) -> None:
        """Run ``e``'s plan, from its own rows; its targets into the batch's rows and relay."""
        run = self.runs[e]
        run.plan(_run_rows(obs, e))
        self._next[e] = obs.t + self.p.replan_period
        rows = slice(e * self._n, (e + 1) * self._n)
        self._mode[e] = NOMINAL if run.nominal else FIXED if run.carried is None else CARRIED
        if not run.nominal:
            if run.carried is None:
                self._target[rows] = run.targets
            else:
                self._carried[rows] = run.carried
        self._guided[rows] = False
        for i, point in run.waypoints.items():
            self._guided[e * self._n + i] = True
            self._waypoint[e * self._n + i] = point
        self._relay.keep(e, _step(obs), Plan(np.full(self._n, self._mode[e]), self._target[rows],
                                             self._carried[rows], self._guided[rows],
                                             self._waypoint[rows]))


def _step(obs: Observation) -> int:
    """The step of ``obs`` (the runs of a batch share one clock)."""
    return int(round(obs.t / obs.dt))


def _run_rows(obs: Observation, e: int) -> Observation:
    """The observation of run ``e`` alone, as its planner gets it: ``leader`` ``(5,)``, no env.

    The rows are views of the batch's (a run's rows are one block); the
    neighbour indices stay rows of the batch, and there is no scan (the
    planner reads neither). ``leader_age`` is the run's; ``team`` and
    ``team_age`` are its rows (None when the batch has none). The planner runs
    at the virtual leader, so it reads the leader's state and slots of now
    (``leader_now``, ``slot_now``) where the robots' broadcast is late.
    """
    at = slice(int(np.searchsorted(obs.env, e)), int(np.searchsorted(obs.env, e, side="right")))
    nb, mv = obs.neighbours, obs.obstacles
    age = np.asarray(obs.leader_age, dtype=float)
    return Observation(obs.t, obs.dt, obs.robot_ids[at], obs.pose[at], obs.velocity[at],
                       obs.twist[at], None,
                       Neighbours(nb.index[at], nb.position[at], nb.velocity[at],
                                  nb.distance[at], None if nb.heading is None else nb.heading[at]),
                       MovingObstacles(mv.position[at], mv.velocity[at], mv.radius[at],
                                       mv.mask[at]),
                       obs.leader[e] if obs.leader_now is None else obs.leader_now[e], obs.goal,
                       obs.slot_offset[at], obs.slot[at] if obs.slot_now is None
                       else obs.slot_now[at],
                       leader_age=float(age[e]) if age.ndim else float(age),
                       team=None if obs.team is None else obs.team[at],
                       team_age=None if obs.team_age is None else obs.team_age[at])
