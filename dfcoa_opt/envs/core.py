"""The engine of both environments: E runs of one scenario as E episodes (numpy and numba).

:class:`TeamBatch` owns one :class:`~dfcoa_opt.sim.stepper.Stepper` whose E
slots are the E episodes: one :meth:`~dfcoa_opt.sim.stepper.Stepper.sense` and
one :meth:`~dfcoa_opt.sim.stepper.Stepper.apply` per step for all of them, the
observation of every robot of every slot flattened in one compiled call
(:func:`~dfcoa_opt.control.features.flatten`) and every run scored (formation
errors, arc length, contacts, reward, stall test) in another
(:func:`~dfcoa_opt.envs.kernels.score_runs`; :mod:`dfcoa_opt.envs.rewards` has
the definitions and numpy references). Python loops run only over the runs
that end. A slot's episode is the run :func:`dfcoa_opt.run` gives for its seed
with the same commands, bit for bit; its log stays in the Stepper until the
slot starts its next episode (:meth:`TeamBatch.episode_log`).

The environments change three settings of the scenario they are given
(:func:`env_scenario`): ``stop_on_collision = true`` (a contact ends the
episode), ``leader.wait_for_formation = true`` (success needs the formation
settled at the goal) and ``stop_on_deadlock`` (the environment's option,
default true: a stalled run ends as a deadlock). The stall test is
:class:`~dfcoa_opt.sim.stall.StallMonitor`'s, computed for every run at once
(:class:`~dfcoa_opt.envs.rewards.BatchStall`, whose flags are the Stepper's
``stall_flags``): the per-run monitors would cost a Python loop over the runs
at every step (about half of a step at E = 1024).
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.control.base import Observation
from dfcoa_opt.control.features import ObservationSpec, flatten
from dfcoa_opt.core.errors import DfcoaError
from dfcoa_opt.core.runtime import dispatch
from dfcoa_opt.envs.kernels import score_runs
from dfcoa_opt.envs.rewards import PathTable, RewardSpec, end_bonus, end_of_episode
from dfcoa_opt.envs.spaces import action_bounds, observation_bounds
from dfcoa_opt.metrics.outcome import OUTCOMES
from dfcoa_opt.scenario.scenario import Scenario
from dfcoa_opt.scenario.schema import MetricSpec
from dfcoa_opt.sim.batch import BatchSimulator
from dfcoa_opt.sim.log import RunLog
from dfcoa_opt.sim.stall import BatchStall
from dfcoa_opt.sim.stepper import Ended, Stepper, is_batched
from dfcoa_opt.world.robots.models import CommandKind, make_model

FloatArray = NDArray[np.float64]

#: An episode's outcome as the environments' infos give it, by code: ``OUTCOME_NAMES[code]``.
#: Code 0 (``running``) while the episode goes on, then :data:`dfcoa_opt.metrics.outcome.OUTCOMES`
#: in their order: 1 success, 2 collision, 3 deadlock, 4 timeout.
OUTCOME_NAMES: tuple[str, ...] = ("running", *OUTCOMES)
#: The code of each outcome name (:data:`OUTCOME_NAMES` inverted).
OUTCOME_CODES: dict[str, int] = {name: code for code, name in enumerate(OUTCOME_NAMES)}

#: What :func:`~dfcoa_opt.envs.kernels.score_runs` gets without a stall test.
_NO_STALL = BatchStall(0, 0, 1.0, 0.0, MetricSpec())


class _ActionSource:
    """What :class:`BatchSimulator` takes as the controller: the actions come from ``step``."""

    batched = True
    name = "env"

    def __init__(self, command: CommandKind, uses_scan: bool) -> None:
        self.command = command
        self.uses_scan = uses_scan

    def reset_batch(self, scenarios: list[Scenario], rngs: list[np.random.Generator]) -> None:
        """Nothing to prepare."""

    def reset(self, scenario: Scenario, rng: np.random.Generator) -> None:
        """Nothing to prepare."""

    def act(self, obs: Observation) -> FloatArray:
        """Never called: the environment applies its actions itself."""
        raise DfcoaError("an environment's actions come from its step()")


def env_scenario(scenario: Scenario | str | Path, stop_on_deadlock: bool = True,
                 overrides: Mapping[str, Any] | None = None) -> Scenario:
    """The scenario an environment runs: ``scenario`` with the episode-end settings.

    Args:
        scenario: A loaded scenario or the path of a scenario file.
        stop_on_deadlock: End a stalled run (outcome ``deadlock``).
        overrides: More scenario keys, dotted (``{"t_max": 20.0}``) or with ``__``
            for the dot (``leader__speed``), applied first.

    Returns:
        The scenario with ``stop_on_collision = true``,
        ``leader.wait_for_formation = true`` and ``stop_on_deadlock``.

    Raises:
        ScenarioError: A bad file or key.
        DfcoaError: Overrides for a scenario built without its file's data.
    """
    from dfcoa_opt.scenario.loader import load_scenario, scenario_from_dict
    from dfcoa_opt.scenario.overrides import apply_overrides

    keys = {k.replace("__", "."): v for k, v in (overrides or {}).items()}
    keys.update({"stop_on_collision": True, "leader.wait_for_formation": True,
                 "stop_on_deadlock": bool(stop_on_deadlock)})
    if isinstance(scenario, str | Path):
        return load_scenario(scenario, None, keys)
    spec = scenario.spec
    if (len(keys) == 3 and spec.stop_on_collision and spec.leader.wait_for_formation
            and spec.stop_on_deadlock == bool(stop_on_deadlock)):
        return scenario
    if scenario.data is not None:
        data = copy.deepcopy(dict(scenario.data))
        apply_overrides(data, keys, scenario.source)
        return scenario_from_dict(data, scenario.source, scenario.base_dir)
    if len(keys) > 3:
        raise DfcoaError(f"{scenario.source}: built without its file's data, so it takes no "
                         f"overrides ({sorted(keys)[:3]}...); load it from its file")
    return replace(scenario, spec=replace(spec, stop_on_collision=True,
                                          stop_on_deadlock=bool(stop_on_deadlock),
                                          leader=replace(spec.leader, wait_for_formation=True)))


def team_observation(stepper: Stepper) -> Observation:
    """The observation of every active run of ``stepper``, whatever their clocks.

    :meth:`Stepper.batch_observation` without the one-clock requirement: runs
    restarted at different steps have no common time, so ``t`` is NaN then
    (:func:`flatten` does not read it). Call after ``sense()``.
    """
    return stepper.batch_observation(one_clock=False)


@dataclass
class StepResult:
    """What one step of every slot gave.

    Attributes:
        reward: ``(E,)`` rewards (0 for a slot without a run).
        terminated: ``(E,)`` episodes that ended in success, collision or deadlock.
        truncated: ``(E,)`` episodes that ran out of time (``t_max``).
        outcomes: The outcome of every slot whose episode ended, by slot.
    """

    reward: FloatArray
    terminated: NDArray[np.bool_]
    truncated: NDArray[np.bool_]
    outcomes: dict[int, str] = field(default_factory=dict)


class TeamBatch:
    """E episodes of one scenario stepped as one batch (module docstring).

    Args:
        scenario: A loaded scenario or a scenario file.
        reward: The reward's weights.
        observation: The observation vector's layout and scales.
        stop_on_deadlock: End a stalled run as a deadlock.
        overrides: More scenario keys (:func:`env_scenario`).

    Attributes:
        scenario: The scenario the episodes run (:func:`env_scenario`).
        kind: The robots' command kind, the action's.
        n: Robots per episode.
        size: Length of one robot's observation vector.
        observation: The toolkit :class:`Observation` of the latest :meth:`observe`
            (None before); e.g. for an expert controller's ``act``.
    """

    def __init__(self, scenario: Scenario | str | Path, *, reward: RewardSpec | None = None,
                 observation: ObservationSpec | None = None, stop_on_deadlock: bool = True,
                 overrides: Mapping[str, Any] | None = None) -> None:
        self.scenario = env_scenario(scenario, stop_on_deadlock, overrides)
        self.reward_spec = reward if reward is not None else RewardSpec()
        self.obs_spec = observation if observation is not None else ObservationSpec()
        spec = self.scenario.spec
        self.kind: CommandKind = make_model(spec.robots).native
        self.n, self.dt, self.size = spec.team.n, spec.dt, self.obs_spec.size
        self.action_low, self.action_high = action_bounds(spec.robots, self.kind)
        self.obs_low, self.obs_high = observation_bounds(self.obs_spec)
        self.observation: Observation | None = None
        self._stepper: Stepper | None = None
        self._ended: dict[int, Ended] = {}
        self._arc_prev = np.zeros(0)
        self._stall: BatchStall | None = None
        self._paths = PathTable()
        spec_r = self.reward_spec
        self._weights = np.array([spec_r.formation, spec_r.shape, spec_r.progress,
                                  spec_r.contact], dtype=float)
        self._scored: tuple[FloatArray, NDArray[np.bool_]] = (np.zeros(0),
                                                              np.zeros(0, dtype=bool))

    @property
    def stepper(self) -> Stepper:
        """The batch's Stepper (after :meth:`start`)."""
        if self._stepper is None:
            raise DfcoaError("the environment has not been reset")
        return self._stepper

    @property
    def seeds(self) -> list[int]:
        """The seed of each slot's current (or last) episode."""
        return list(self.stepper.sim.seeds)

    def start(self, seeds: Sequence[int]) -> None:
        """New episodes in every slot, one per seed (a new Stepper), sensed: call :meth:`observe`.

        Raises:
            ValueError: A negative seed.
        """
        if any(int(s) < 0 for s in seeds):
            raise ValueError(f"seeds must be >= 0, got {list(seeds)}")
        dispatch.check()
        source = _ActionSource(self.kind, self.obs_spec.beams > 0)
        sim = BatchSimulator(self.scenario, source, [int(s) for s in seeds])
        st = self._stepper = Stepper(sim, scan_wanted=source.uses_scan)
        spec = self.scenario.spec
        self._stall = (BatchStall(len(seeds), st.steps, self.dt, spec.leader.settle_tolerance,
                                  spec.metrics) if spec.stop_on_deadlock else None)
        if self._stall is not None:  # one compiled pass for every run, no monitor per run
            st.stall_flags = self._stall.flags
            st.monitors = [None] * len(seeds)
        self._paths = PathTable()
        for g, sc in enumerate(sim.group_scenarios):
            self._paths.set(g, sc.leader_path)
        st.start_clock()
        self._ended = {}
        self._arc_prev = np.zeros(len(seeds))

    def restart(self, slot: int, seed: int) -> None:
        """A new episode with ``seed`` in ``slot``, whose episode has ended.

        Raises:
            DfcoaError: The slot's episode is still running, or the pose
                estimator is batched (e.g. ``mcl``: it cannot start one run alone).
        """
        if int(seed) < 0:
            raise ValueError(f"seeds must be >= 0, got {seed}")
        st = self.stepper
        st.restart(slot, int(seed))
        g = int(st.sim.group[slot])
        self._paths.set(g, st.sim.group_scenarios[g].leader_path)
        self._ended.pop(slot, None)

    @property
    def restartable(self) -> bool:
        """Whether a slot can start a new episode while the others go on (not ``mcl``)."""
        return not is_batched(self.stepper.estimators[0])

    def observe(self) -> tuple[NDArray[np.intp], FloatArray]:
        """Sense every running episode once and flatten every robot's observation.

        Returns:
            The slots with a running episode ``(A,)``, in increasing order, and
            their observations ``(A, N, size)``.
        """
        st = self.stepper
        active = st.active.copy()
        if not len(active):
            self.observation = None
            return active, np.zeros((0, self.n, self.size))
        st.sense()
        self.observation = team_observation(st)
        return active, flatten(self.observation, self.obs_spec).reshape(len(active), self.n,
                                                                          self.size)

    def step(self, actions: FloatArray) -> StepResult:
        """Apply every running episode's actions, score the instant, end what ended.

        Args:
            actions: ``(E, N, 2)`` one action per robot of every slot (rows of
                slots without a running episode are ignored).

        Returns:
            The rewards, ends and outcomes (:mod:`dfcoa_opt.envs.rewards`).

        Raises:
            ValueError: A NaN or infinite action of a running episode.
        """
        st, spec = self.stepper, self.reward_spec
        slots = len(st.k)
        out = StepResult(np.zeros(slots), np.zeros(slots, dtype=bool),
                         np.zeros(slots, dtype=bool))
        act = st.active
        if not len(act):
            return out
        cmd = actions[act].reshape(len(act) * self.n, -1)
        if not np.isfinite(cmd).all():
            bad = sorted(set((act[np.nonzero(~np.isfinite(actions[act]))[0]]).tolist()))
            raise ValueError(f"NaN or infinite action in sub-environment(s) {bad}")
        ended = st.apply(cmd, self.kind, self._score)
        reward, contact = self._scored
        out.reward[act] = reward
        if ended:
            rows = np.searchsorted(act, [end.slot for end in ended])
            for end, j in zip(ended, rows, strict=True):
                outcome, terminal = end_of_episode(bool(contact[j]), end.reached,
                                                   end.steps == st.steps)
                out.outcomes[end.slot] = outcome
                out.terminated[end.slot], out.truncated[end.slot] = terminal, not terminal
                out.reward[end.slot] += end_bonus(spec, outcome)
                self._ended[end.slot] = end
        return out

    def _score(self, log: Any, active: NDArray[np.intp], kk: NDArray[np.int64]) -> None:
        """Inside ``apply``, the instant's rows logged, before the stop tests: score every run.

        ``log`` is the Stepper's :class:`~dfcoa_opt.sim.log.BatchLog`. One
        compiled pass (:func:`~dfcoa_opt.envs.kernels.score_runs`): the
        formation errors, the centroid's arc length along its world's path and
        the contacts of every active run at its instant, its reward (without
        the end bonus), and the stall flags the stop test reads
        (:class:`~dfcoa_opt.envs.rewards.BatchStall`).
        """
        st, paths = self.stepper, self._paths
        stall = _NO_STALL if self._stall is None else self._stall
        reward, contact, *_ = score_runs(
            log.pose, log.slots, log.robot_contacts, log.obstacle_contacts, log.dynamic_contacts,
            active, kk, st.sim.group, paths.start, paths.count, paths.data, self._arc_prev,
            self._weights, self.dt, stall.progress, stall.flags, self._stall is not None,
            stall.lag, stall.advance, stall.settle, stall.displacement)
        self._scored = (reward, contact)

    def time(self, slot: int) -> float:
        """The time of ``slot``'s next instant, s."""
        return float(self.stepper.k[slot] * self.dt)

    def episode_log(self, slot: int) -> RunLog:
        """The log of ``slot``'s episode that ended, until the slot starts its next one.

        The :class:`RunLog` :func:`dfcoa_opt.run` gives (``meta`` with the
        seed, ``reached_goal``, ...; ``command`` holds the actions), for the
        metrics of :mod:`dfcoa_opt.metrics`.

        Raises:
            DfcoaError: The slot's episode has not ended.
        """
        end = self._ended.get(slot)
        if end is None:
            raise DfcoaError(f"the episode of sub-environment {slot} has not ended")
        st = self.stepper
        return st.sim._finish(st, end, _ActionSource(self.kind, False))
