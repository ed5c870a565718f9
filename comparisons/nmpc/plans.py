"""The plan buffers of the ``nmpc`` controller (:mod:`comparisons.nmpc.controller`).

The controller owns one :class:`PlanBuffers` per batch of runs (made by its reset).

Every robot's last plan (made at ``t``: controls, poses, multipliers) is kept in
arrays indexed by **global id**: ``env * N + robot`` in a batch of runs of ``N``
robots (one run: the robot index; a hand-made observation without ``env``: its
``robot_ids``). Plans are written to ``_w`` and read from ``_r``, a copy of
``_w`` taken when a new step begins, so every robot reads its neighbours' plans
of the previous step, whatever the order of the rows.

A plan travels with its robot's state message. With late or lost messages
(``obs.neighbours.age`` set) an entry ``a`` s old carries the plan its sender
had when it sent it, the readable plan of the step ``a`` s ago: the buffers
keep the readable plans of the last steps (:func:`relayed_plans`).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from comparisons.nmpc.geometry import entry_predictions, neighbour_predictions
from comparisons.nmpc.model import rollout
from dfcoa_opt.core.geometry import take_rows

if TYPE_CHECKING:
    from comparisons.nmpc.spec import ProblemSpec
    from dfcoa_opt.control.base import Observation

FloatArray = NDArray[np.float64]
#: A step's readable plans: ``(time of the step s, plan times (G,) s, poses (G, H + 1, 3))``.
Snapshot = tuple[float, FloatArray, FloatArray]


def relayed_plans(snapshots: Iterable[Snapshot], t: float, dt: float, ids: NDArray[np.intp],
                  age: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The plan each neighbour entry carries: its sender's readable plan when it was sent.

    Entry ``(i, k)``, a message ``age[i, k]`` s old (``A`` steps), was sent at
    step ``t - age``; the plan it carries is the one its sender had stored then,
    the readable plan of that step (made at ``A + 1`` steps before now, or
    earlier when kept by the ``shift`` fallback). A step no snapshot holds, a
    padded entry or an id beyond a snapshot's buffers gives no plan.

    Args:
        snapshots: The readable plans of some steps (:data:`Snapshot`), any order.
        t: Now, s.
        dt: Simulation step, s (a message's age is a whole number of steps).
        ids: ``(N, K)`` the senders' global ids (-1 padded).
        age: ``(N, K)`` the messages' ages, s.

    Returns:
        ``(plan_t (N, K) s, NaN = no plan; plans (N, K, H + 1, 2) m, 0 without)``.
    """
    sent = t - age
    plan_t = np.full(ids.shape, np.nan)
    plans: FloatArray | None = None
    for when, times, poses in snapshots:  # a few steps: vectorised over the entries
        if plans is None:
            plans = np.zeros((*ids.shape, poses.shape[1], 2))
        sel = (ids >= 0) & (ids < len(times)) & (np.abs(sent - when) < 0.5 * dt)
        if sel.any():
            g = ids[sel]
            plan_t[sel], plans[sel] = times[g], poses[g, :, :2]
    if plans is None:
        plans = np.zeros((*ids.shape, 0, 2))
    return plan_t, plans


class PlanBuffers:
    """Every robot's last plan by global id (module docstring), empty; no step yet.

    Owned by :class:`~comparisons.nmpc.controller.Nmpc`, one per batch of runs.

    Args:
        spec: The problem's shape (horizon ``H``, constraint rows, variables per stage).
        tau: Prediction step, s.
        n: Robots per run ``N`` (a row's global id is ``env * N + robot``).
        size: Global ids to make room for (runs times ``N``; more are added on demand).

    Attributes:
        spec: The problem's shape.
        tau: Prediction step, s.
        n: Robots per run.
        _w: Written plans: ``t`` (s, NaN = none), ``u`` ``(G, H, 2)``, ``x``
            ``(G, H + 1, 3)``, ``lam_x``, ``lam_g`` and ``lam_ok`` (multipliers kept).
        _r: Readable plans (same keys): ``_w`` as it was when the step began.
        _t: Time of the current step, s (None before the first).
        _t_prev: Time of the step before it, s (NaN before the second).
        _past: The readable plans of the steps before the current one, newest
            first (:data:`Snapshot`; None until a step with late or lost messages).
    """

    def __init__(self, spec: ProblemSpec, tau: float, n: int, size: int) -> None:
        self.spec, self.tau, self.n = spec, tau, n
        h, rows = spec.horizon, spec.rows
        self._w: dict[str, np.ndarray] = {
            "t": np.full(size, np.nan), "u": np.zeros((size, h, 2)),
            "x": np.zeros((size, h + 1, 3)), "lam_x": np.zeros((size, spec.nw * h)),
            "lam_g": np.zeros((size, rows * h)), "lam_ok": np.zeros(size, dtype=bool)}
        self._r: dict[str, np.ndarray] = {k: v.copy() for k, v in self._w.items()}
        self._t: float | None = None
        self._t_prev: float = np.nan
        self._past: deque[Snapshot] | None = None

    def _grow(self, n: int) -> None:
        """Make room for global ids below ``n`` (hand-made observations)."""
        have = len(self._w["t"])
        if n <= have:
            return
        for buf in (self._w, self._r):
            for k, v in buf.items():
                fill = np.nan if k == "t" else 0
                buf[k] = np.concatenate((v, np.full((n - have, *v.shape[1:]), fill, v.dtype)))

    def advance(self, t: float, dt: float | None = None) -> None:
        """At a new step (``t`` later than the last), last step's plans become readable.

        Args:
            t: Time of the step, s.
            dt: The simulation step, s, when messages are late or lost: the
                readable plans of the last ``ceil(H tau / dt)`` steps are then kept
                (older ones would be at least ``H`` stages old when they arrive).
        """
        if self._t is None or t > self._t + 1e-9:
            if dt is not None:
                if self._past is None:
                    self._past = deque(maxlen=math.ceil(self.spec.horizon * self.tau / dt))
                if self._t is not None:  # _r is replaced, never written: kept as it is
                    self._past.appendleft((self._t, self._r["t"], self._r["x"]))
            self._r = {k: v.copy() for k, v in self._w.items()}
            self._t_prev = np.nan if self._t is None else self._t
            self._t = t

    def solved_last_step(self, ids: NDArray[np.intp]) -> NDArray[np.bool_]:
        """Which of ``ids`` have a readable plan solved at the previous step.

        Solved: with multipliers (not a ``stop`` or ``goto`` fallback's); at the
        previous step (not one kept by ``shift``, nor an older one).
        """
        return self._r["lam_ok"][ids] & (self._r["t"][ids] == self._t_prev)

    def global_ids(self, obs: Observation) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Global ids ``(R,)`` of the rows and ``(R, K)`` of their neighbours (-1 padded).

        In a batch (``obs.env`` set) a row is ``env * N + robot_ids`` and a
        neighbour index is a row of ``obs``; without ``env`` both ``robot_ids``
        and the neighbour indices are global ids already (a hand-made observation
        may hold any robots, e.g. :meth:`Observation.take`). Grows the buffers.
        """
        index = np.asarray(obs.neighbours.index, dtype=np.intp)
        if obs.env is None:
            ids = np.asarray(obs.robot_ids, dtype=np.intp)
            nb = index
        else:
            ids = np.asarray(obs.env, dtype=np.intp) * self.n + obs.robot_ids
            nb = np.where(index >= 0, ids[np.maximum(index, 0)], -1)
        self._grow(int(max(ids.max(initial=-1), nb.max(initial=-1))) + 1)
        return ids, nb

    def _age(self, t: float, ids: NDArray[np.intp]) -> FloatArray:
        """Age of the readable plans of ``ids`` at ``t``, in stages (``inf`` = none)."""
        return self._stages(t, self._r["t"][ids])

    def _stages(self, t: float, made: FloatArray) -> FloatArray:
        """Age at ``t`` (s) of plans made at ``made`` (s, NaN = none) in stages (``inf``: none)."""
        age = (t - made) / self.tau
        return np.where(np.isfinite(age) & (age >= -1e-9), np.maximum(age, 0.0), np.inf)

    def predictions(self, obs: Observation, nb_ids: NDArray[np.intp], count: int
                     ) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Predicted centres ``(R, K, H, 2)`` (m) of each row's ``count`` nearest neighbours.

        Fresh messages (``obs.neighbours.age`` None): every neighbour's readable
        plan (:func:`~comparisons.nmpc.geometry.neighbour_predictions`). Late or
        lost ones: the plan each entry carries (:func:`relayed_plans`, from this
        step's readable plans and the kept ones), sampled from now on
        (:func:`~comparisons.nmpc.geometry.entry_predictions`).

        Args:
            obs: This step's observation.
            nb_ids: ``(R, K')`` the neighbours' global ids (-1 padded).
            count: Neighbour slots ``K``.

        Returns:
            ``(pred (R, K, H, 2) m, mask (R, K))``.
        """
        t, h, nb = float(obs.t), self.spec.horizon, obs.neighbours
        if nb.age is None:
            every = np.arange(len(self._r["t"]))
            return neighbour_predictions(nb, count, self._r["x"][..., :2], self._age(t, every),
                                         self.tau, h, nb_ids)
        now: Snapshot = (t, self._r["t"], self._r["x"])  # only the entries used are gathered
        plan_t, plans = relayed_plans((now, *(self._past or ())), t, float(obs.dt),
                                      nb_ids[:, :count], nb.age[:, :count])
        return entry_predictions(nb, count, plans, self._stages(t, plan_t), self.tau, h, nb_ids)

    def shifted(self, t: float, ids: NDArray[np.intp]) -> tuple[FloatArray, FloatArray]:
        """Own previous controls shifted to ``t`` (zeros without a plan), and their age."""
        h = self.spec.horizon
        age = self._age(t, ids)
        u = np.zeros((len(ids), h, 2))
        live = age < h
        if live.any():
            idx = np.minimum(np.floor(age[live][:, None] + 1e-6).astype(np.intp)
                             + np.arange(h), h - 1)
            u[live] = take_rows(self._r["u"][ids[live]], idx)
        return u, age

    def shifted_multipliers(self, ids: NDArray[np.intp], age: FloatArray
                             ) -> tuple[FloatArray, FloatArray]:
        """The robots' last multipliers shifted by ``age`` stages (zeros without them)."""
        h, n = self.spec.horizon, len(ids)
        live = (age < h) & self._r["lam_ok"][ids]
        shift = np.floor(np.where(live, age, 0.0) + 1e-6).astype(np.intp)
        idx = np.minimum(np.arange(h) + shift[:, None], h - 1)
        out = []
        for key in ("lam_x", "lam_g"):
            lam = take_rows(self._r[key][ids].reshape(n, h, -1), idx)
            lam[~live] = 0.0
            out.append(lam.reshape(n, -1))
        return out[0], out[1]

    def store(self, g: NDArray[np.intp], t: float, pose: FloatArray, u: FloatArray,
               x: FloatArray | None = None,
               lam: tuple[FloatArray, FloatArray] | None = None) -> None:
        """Write the plans made at ``t`` of global ids ``g`` ``(R,)``.

        Controls ``u`` ``(R, H, 2)``; poses ``x`` ``(R, H + 1, 3)`` (rolled out from
        ``pose`` ``(R, 3)`` when not given); multipliers ``(lam_x, lam_g)`` or None.
        """
        w = self._w
        w["t"][g], w["u"][g] = t, u
        w["x"][g] = x if x is not None else rollout(pose, u, self.tau)
        w["lam_ok"][g] = lam is not None
        if lam is not None:
            w["lam_x"][g], w["lam_g"][g] = lam

    def keep(self, g: int) -> None:
        """Global id ``g`` keeps its readable plan (the ``shift`` fallback)."""
        for key, buf in self._w.items():
            buf[g] = self._r[key][g]
