"""Paper 001's consensus formation controllers: ``consensus`` (eq 14) and ``consensus_ivo`` (eq 15).

Robots are double integrators (eq 1, ``robots.model = "double_integrator"``):
both controllers return accelerations. With the leader-relative errors
``x^_i = x_i - slot_i`` and ``v^_i = v_i - vslot_i`` (``slot_i = x_L + Delta_i``):

* ``consensus`` -- eq 14::

      u_ci = -k1 [sum_j a_ij (x^_i - x^_j) + b_i x^_i] - k2 [sum_j a_ij (v^_i - v^_j) + b_i v^_i]

  which is eq 14 term by term when the leader does not turn
  (``x^_i - x^_j = x_i - x_j - Delta_i + Delta_j`` and ``v^_i - v^_j = v_i - v_j``).
* ``consensus_ivo`` -- eq 15-17: ``u_i = u_ci - k3 (v_i - w_i)`` where ``w_i`` is
  the velocity the ``orca`` filter (:class:`comparisons.orca.filter.OrcaFilter`,
  static obstacles by paper 001's improved VO, mode ``"ivo"``) returns for the
  preferred world velocity ``vslot_i + v_pref_i`` (decision 1).

Decisions (details, the paper's words and the reasons: ``docs/methods/consensus.md``):

1. Frames of eq 15-17. The paper compares ``V_IVO`` with the leader-relative
   ``v^_i = v_i - v_L`` ("- k3 (v^_i - V_IVO)"), but its feasible set IVOA+ (eq 13:
   speed disc, IVO half-planes, ORCA half-planes) constrains the robot's real
   velocity. We read ``V_IVO`` and ``v_pref`` as leader-relative: the safe world
   velocity is ``w_i = argmin_{w in IVOA+} ||w - (vslot_i + v_pref_i)||`` and
   ``V_IVO = w_i - vslot_i``, so the k3 term is ``-k3 (v_i - w_i)``. Otherwise the
   constrained velocity would not be the velocity the robot flies and the
   avoidance would do nothing.
2. Leader and offsets come from the observation. ``obs.leader`` = (x, y, theta,
   v, omega), ``obs.slot[i] = x_L + R(theta) offset_i``; the slot velocity is
   :func:`dfcoa_opt.control.base.slot_velocity` (shared with ``goto_slot``). The
   paper's constant ``Delta_i`` is exact for a leader that does not turn
   (omega = 0); otherwise ``Delta_i = R(theta) offset_i`` turns with the leader and
   all velocities are taken relative to the slot velocities. The formation is
   common knowledge: ``scenario.offsets`` is kept at reset, and a neighbour's slot
   is ``x_L + R(theta) offsets[j]``. ``a_ij = 1`` for every robot in
   ``obs.neighbours`` (``topology = "complete"``: eq 21's A when every robot is
   within communication range of the others), ``b_i = b`` (eq 21's B = 1). Row i
   of the command depends on row i of the observation only.
3. Eq 17's ``v_pref = v_max (x_i - x_L - Delta_i)/||.||`` points away from the
   slot although the text says it "points to the desired position"; we take the
   text (direction ``slot_i - x_i``). It is undefined at the slot and, always at
   full speed, makes the velocity chatter around it. ``pref_law = "unit"``
   (default) is eq 17 with that sign (0 within 1e-9 m of the slot);
   ``"arrival"`` is ``v_max (slot - x)/max(||slot - x||, arrival_radius)`` (it
   slows down within ``arrival_radius`` like RVO2's examples).
4. ``v_max`` of eq 11 and 17 is the filter's ``v_max`` parameter, default the
   robots' ``robots.v_max``.

Both controllers are batched (:class:`~dfcoa_opt.control.base.BatchedController`):
one object serves every run of a batch and one call computes every row of
every run (each row with its own run's leader state, formation and world);
each run's rows are the rows of the run simulated alone, bit for bit.

The paper's gains are the defaults: k1 = 0.25, k2 = 0.45, k3 = 37.5. Explicit
Euler (the simulator's double integrator) of the velocity loop ``-k3 (v - w)``
diverges for ``k3 dt > 2`` and overshoots for ``k3 dt > 1``; with
``k3_step_limit`` (default) the gain used is ``min(k3, 1/dt)`` (the velocity
reaches ``w`` in one step), which leaves the paper's setting (dt 0.01 s,
k3 dt = 0.375) unchanged and lets the controller run on the comparison
scenarios (dt 0.1 s: gain 10 1/s). Without it, ``reset`` refuses ``k3 dt >= 2``.
The paper gives no acceleration limit, so give the robots a large ``a_max``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from comparisons.orca.filter import OrcaFilter
from dfcoa_opt.control.base import (
    BatchedController,
    FilterResult,
    Observation,
    as_batch,
    slot_velocity,
)
from dfcoa_opt.control.registry import register
from dfcoa_opt.core.errors import ScenarioError
from dfcoa_opt.core.geometry import body_to_world
from dfcoa_opt.core.params import param

#: Below this distance to its slot (m), eq 17's direction is undefined: v_pref = 0.
PREF_EPS = 1e-9


def consensus_command(obs: Observation, offsets: np.ndarray, k1: float, k2: float,
                      b: float) -> np.ndarray:
    """Eq 14 for every robot, row i from row i of ``obs`` only.

    Args:
        obs: The step's observation (one run, or the rows of every run of a
            batch); neighbours (``a_ij = 1``) are ``obs.neighbours``.
        offsets: ``(n_team, 2)`` slot offsets of the whole team in the leader frame, m
            (a neighbour's are those of its index within the team), or
            ``(E, n_team, 2)``, those of each run of the batch (``obs.env``).
        k1: Position gain, 1/s^2.
        k2: Velocity gain, 1/s.
        b: Leader weight ``b_i`` (same for every robot), dimensionless.

    Returns:
        ``(N, 2)`` accelerations ``u_ci``, m/s^2.
    """
    obs = as_batch(obs)
    offsets = np.asarray(offsets, dtype=float)
    offsets = offsets if offsets.ndim == 3 else offsets[None]
    lead = obs.row_leader()  # (N, 5): each row's broadcast leader state
    x_hat = obs.pose[:, :2] - obs.slot
    v_hat = obs.velocity - slot_velocity(lead, obs.slot)
    nb = obs.neighbours
    mask = nb.mask
    # a neighbour index is a row of the batch (runs of n_team rows): its robot is index % n_team
    idx = np.where(mask, nb.index, 0) % offsets.shape[1]
    run = obs.env[:, None] if len(offsets) > 1 else 0
    nb_slot = body_to_world(lead[:, None, :3], offsets[run, idx])  # (N, K, 2)
    a = mask.astype(float)[..., None]
    xj_hat = nb.position - nb_slot
    vj_hat = nb.velocity - slot_velocity(lead[:, None, :], nb_slot)
    ex = (a * (x_hat[:, None, :] - xj_hat)).sum(axis=1) + b * x_hat
    ev = (a * (v_hat[:, None, :] - vj_hat)).sum(axis=1) + b * v_hat
    return -k1 * ex - k2 * ev


def preferred_velocity(obs: Observation, v_max: float, law: str,
                       arrival_radius: float) -> np.ndarray:
    """Eq 17, leader-relative: ``v_pref`` towards the own slot.

    Args:
        obs: The step's observation (own pose and slot).
        v_max: Speed of eq 17, m/s.
        law: ``"unit"`` (eq 17, sign as the text says) or ``"arrival"`` (slows down
            within ``arrival_radius``).
        arrival_radius: Radius of the ``"arrival"`` law, m.

    Returns:
        ``(N, 2)`` preferred velocities relative to the slots' motion, m/s.
    """
    vec = obs.slot - obs.pose[:, :2]
    dist = np.linalg.norm(vec, axis=1, keepdims=True)
    if law == "unit":
        return np.where(dist < PREF_EPS, 0.0, vec * (v_max / np.maximum(dist, PREF_EPS)))
    return vec * (v_max / np.maximum(dist, arrival_radius))


@register("consensus")
class Consensus(BatchedController):
    """Paper 001 eq 14: second-order consensus formation control with a virtual leader."""

    command = "acceleration"
    uses_scan = False

    @dataclass(frozen=True)
    class Params:
        """Parameters of ``consensus`` (paper 001 eq 14, eq 21)."""

        k1: float = param(0.25, doc="Position gain k1 of eq 14 (paper: 0.25).", unit="1/s^2",
                          gt=0.0, tune=(0.05, 2.0), scale="log")
        k2: float = param(0.45, doc="Velocity gain k2 of eq 14 (paper: 0.45).", unit="1/s",
                          gt=0.0, tune=(0.1, 3.0), scale="log")
        b: float = param(1.0, doc="Leader weight b_i of every robot (eq 21: B = 1); 0 = no "
                                  "robot uses the leader's state beyond its offsets.", ge=0.0,
                         tune=(0.0, 3.0))
        topology: Literal["complete"] = param(
            "complete", doc="a_ij = 1 for every robot within communication range (eq 21's A "
                            "when every robot is within range of the others).")

    def __init__(self, params: Params) -> None:
        self.p = params
        self._offsets = np.zeros((1, 0, 2))

    def reset_batch(self, scenarios, rngs) -> None:
        """Keep each run's team slot offsets (the formation is common knowledge)."""
        self._offsets = run_offsets(scenarios)

    def act(self, obs: Observation) -> np.ndarray:
        """Eq 14 accelerations ``(N, 2)``, row i from row i of ``obs``."""
        return consensus_command(obs, self._offsets, self.p.k1, self.p.k2, self.p.b)


def run_offsets(scenarios) -> np.ndarray:
    """``(E, n_team, 2)`` the team's slot offsets of each run, m (leader frame)."""
    return np.stack([np.asarray(sc.offsets, dtype=float) for sc in scenarios])


@register("consensus_ivo")
class ConsensusIvo(BatchedController):
    """Paper 001 eq 15-17: eq 14 plus ``-k3 (v_i - w_i)``, ``w_i`` from the IVO/ORCA filter.

    Attributes:
        last_result: The filter's result of the latest step: ``command`` holds the
            safe world velocities ``w_i`` (the simulator logs its status).
    """

    command = "acceleration"
    uses_scan = False

    @dataclass(frozen=True)
    class Params(Consensus.Params, OrcaFilter.Params):
        """Parameters of ``consensus_ivo``: eq 14's, eq 15-17's and the ``orca`` filter's."""

        obstacles: Literal["orca", "ivo", "next_step", "none"] = param(
            "ivo", doc="Static obstacles in IVOA+ (eq 13): 'ivo': paper 001's improved VO "
                       "(default); 'orca', 'next_step', 'none' as in the orca filter.")
        k3: float = param(37.5, doc="Gain k3 of eq 15 on v_i - w_i (paper: 37.5).",
                          unit="1/s", gt=0.0)
        k3_step_limit: bool = param(True, doc="Use min(k3, 1/dt), so that explicit Euler of "
                                              "-k3 (v - w) neither overshoots nor diverges at "
                                              "coarse steps; false: refuse k3 dt >= 2.")
        pref_law: Literal["unit", "arrival"] = param(
            "unit", doc="Eq 17: 'unit' = v_max towards the slot (0 at the slot); 'arrival' = "
                        "v_max (slot - x)/max(|slot - x|, arrival_radius).")
        arrival_radius: float = param(1.0, doc="Slow-down radius of pref_law = 'arrival'.",
                                      unit="m", gt=0.0)

    def __init__(self, params: Params) -> None:
        self.p = params
        fields = {k: getattr(params, k) for k in OrcaFilter.Params.__dataclass_fields__}
        self._filter = OrcaFilter(OrcaFilter.Params(**fields), owner=self.name)
        self._offsets = np.zeros((1, 0, 2))
        self._v_max = 1.0
        self._k3 = params.k3
        self.last_result: FilterResult | None = None

    def reset_batch(self, scenarios, rngs) -> None:
        """Keep the offsets and the speed limit; reset the filter (each run's obstacles).

        Raises:
            ScenarioError: ``k3 dt >= 2`` without ``k3_step_limit``: explicit Euler of
                ``-k3 (v - w)`` diverges.
        """
        scenario = scenarios[0]
        dt = scenario.spec.dt
        self._k3 = min(self.p.k3, 1.0 / dt) if self.p.k3_step_limit else self.p.k3
        if self._k3 * dt >= 2.0:
            raise ScenarioError(scenario.source, f"controllers.{self.name}.k3",
                                f"k3 dt = {self.p.k3 * dt:g} must be < 2 (dt = {dt:g} s): the "
                                "explicit-Euler velocity loop -k3 (v - w) diverges")
        self._offsets = run_offsets(scenarios)
        self._v_max = self.p.v_max if self.p.v_max is not None else scenario.spec.robots.v_max
        self._filter.reset_batch(scenarios, rngs)
        self.last_result = None

    def act(self, obs: Observation) -> np.ndarray:
        """Eq 15 accelerations ``(N, 2)``, row i from row i of ``obs`` (every run of a batch)."""
        obs = as_batch(obs)
        u_c = consensus_command(obs, self._offsets, self.p.k1, self.p.k2, self.p.b)
        pref = preferred_velocity(obs, self._v_max, self.p.pref_law, self.p.arrival_radius)
        self.last_result = self._filter.filter(obs,
                                               slot_velocity(obs.row_leader(), obs.slot) + pref)
        return u_c - self._k3 * (obs.velocity - self.last_result.command)
