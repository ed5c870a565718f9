"""The ``qpsolvers`` path (:mod:`comparisons.orca.qp`) against the exact incremental solver.

Random instances (seeded) of the three kinds of the issue: feasible lines (disc active or
not, ``pref`` inside or outside the disc), with hard lines, and infeasible lines (least
violation), plus lines of a random ORCA crowd. Both solvers must agree to 1e-6 m/s on the
velocity, except for least-violation instances whose minimax optimum is not a single point,
where only the largest violation is compared.
"""

import logging

import numpy as np
import pytest
import qpsolvers
from scipy.optimize import nnls

from comparisons.orca import qp as qp_module
from comparisons.orca.lines import agent_lines
from comparisons.orca.lp import FEASIBLE, LEAST_VIOLATION, solve_lines
from comparisons.orca.qp import SOLVER_FAIL, solve_lines_qp, solver_options

TOL = 1e-6  # m/s, agreement required by the issue


def _unit(angle):
    return np.stack([np.cos(angle), np.sin(angle)], -1)


def _left(d):
    return np.stack([-d[..., 1], d[..., 0]], -1)


def _hard_lines(rng, n_hard, v0, v_max):
    """Hard lines containing v = 0 and ``v0`` (like obstacles), some close to them."""
    d = _unit(rng.uniform(0, 2 * np.pi, n_hard))
    n = _left(d)
    c = np.minimum(0.0, n @ v0) - rng.uniform(1e-3, 0.3, n_hard) * v_max
    return c[:, None] * n, d


def _feasible(rng, n_hard):
    """Lines tangent-ish around ``pref``, all containing a strictly feasible ``v0``."""
    v_max = rng.uniform(0.5, 2.0)
    pref = _unit(rng.uniform(0, 2 * np.pi)) * v_max * rng.uniform(0.0, 1.6)
    v0 = _unit(rng.uniform(0, 2 * np.pi)) * v_max * rng.uniform(0.0, 0.8)
    k = rng.integers(1, 9)
    d = _unit(rng.uniform(0, 2 * np.pi, k))
    n = _left(d)
    # margin of v0 behind each line: from 0 up to the line through pref, plus a little
    m = np.maximum(n @ (v0 - pref), 0.0) * rng.uniform(0, 1, k) + rng.uniform(1e-3, 0.2, k)
    p = v0 - m[:, None] * n
    if n_hard:
        hp, hd = _hard_lines(rng, n_hard, v0, v_max)
        p, d = np.vstack([hp, p]), np.vstack([hd, d])
    return p, d, n_hard, pref, v_max


def _infeasible(rng, n_hard):
    """Allowed sides facing away from a point ``c`` in all directions: empty intersection."""
    v_max = rng.uniform(0.5, 2.0)
    pref = _unit(rng.uniform(0, 2 * np.pi)) * v_max * rng.uniform(0.0, 1.6)
    c = _unit(rng.uniform(0, 2 * np.pi)) * v_max * rng.uniform(0.0, 0.5)
    k = rng.integers(3, 9)
    n = _unit(rng.uniform(0, 2 * np.pi) + rng.uniform(0, 2 * np.pi, k))
    d = np.stack([n[:, 1], -n[:, 0]], -1)  # left normal of d is n
    p = c + rng.uniform(0.05, 1.0, k)[:, None] * v_max * n
    if n_hard:
        hp, hd = _hard_lines(rng, n_hard, np.zeros(2), v_max)
        p, d = np.vstack([hp, p]), np.vstack([hd, d])
    return p, d, n_hard, pref, v_max


def _crowd(rng, n_agents=60, radius=0.4, v_max=1.5, tau=2.0, dt=0.25, max_nbr=10):
    """ORCA lines of every agent of a random dense crowd (some pairs overlap)."""
    pos = rng.uniform(-4.0, 4.0, (n_agents, 2))
    vel = _unit(rng.uniform(0, 2 * np.pi, n_agents)) * rng.uniform(0, v_max, (n_agents, 1))
    goal = _unit(rng.uniform(0, 2 * np.pi, n_agents))
    out = []
    for i in range(n_agents):
        dist = np.linalg.norm(pos - pos[i], axis=1)
        nbr = [j for j in np.argsort(dist) if j != i and dist[j] < 5.0][:max_nbr]
        P, D = np.empty((len(nbr), 2)), np.empty((len(nbr), 2))
        k = agent_lines(pos[i, 0], pos[i, 1], vel[i, 0], vel[i, 1], radius, pos[nbr],
                        vel[nbr], np.full(len(nbr), radius), len(nbr), 1.0 / tau, 1.0 / dt,
                        P, D, 0)
        out.append((P[:k], D[:k], 0, goal[i] * v_max * rng.uniform(0.5, 1.2), v_max))
    return out


def _batch(instances):
    k = max(len(p) for p, *_ in instances)
    n = len(instances)
    P, D = np.zeros((n, k, 2)), np.zeros((n, k, 2))
    D[..., 0] = 1.0
    count, hard = np.zeros(n, np.int64), np.zeros(n, np.int64)
    pref, v_max = np.zeros((n, 2)), np.zeros(n)
    for r, (p, d, h, pr, vm) in enumerate(instances):
        P[r, :len(p)], D[r, :len(p)] = p, d
        count[r], hard[r], pref[r], v_max[r] = len(p), h, pr, vm
    return P, D, count, hard, pref, v_max


def _viol(p, d, v):
    """``det(d_k, p_k - v)`` of every line, m/s."""
    w = p - v
    return d[:, 0] * w[:, 1] - d[:, 1] * w[:, 0]


def _unique_minimax(p, d, n_hard, v, v_max, tol=1e-7):
    """Is the least-violation optimum at ``v`` the only one (KKT, independent of the solvers)?

    Active rows of the LP in ``(v, t)``: soft lines ``(g_k, -1)`` at the largest violation,
    hard lines ``(g_k, 0)`` at zero, the disc's tangent ``(v/|v|, 0)`` on the circle. With
    multipliers ``lam >= 0``, ``sum lam a = (0, 0, -1)``: the optimum is unique if the rows
    with ``lam > 0`` span R^3 (a sharp vertex), or span a plane and include the disc (its
    curvature then separates every other point).
    """
    viol = _viol(p, d, v)
    g = np.stack([d[:, 1], -d[:, 0]], -1)
    t = viol[n_hard:].max()
    rows, disc = [], []
    for k in range(len(p)):
        if k >= n_hard and viol[k] >= t - tol:
            rows.append([*g[k], -1.0])
            disc.append(False)
        elif k < n_hard and viol[k] >= -tol:
            rows.append([*g[k], 0.0])
            disc.append(False)
    if np.linalg.norm(v) >= v_max - tol:
        rows.append([*(v / np.linalg.norm(v)), 0.0])
        disc.append(True)
    A = np.array(rows).T
    lam, residual = nnls(A, np.array([0.0, 0.0, -1.0]))
    assert residual < 1e-6, "the reference velocity is not a least-violation optimum"
    support = lam > 1e-9
    rank = np.linalg.matrix_rank(A[:, support], tol=1e-6)
    return bool(rank == 3 or (rank == 2 and np.array(disc)[support].any()))


def _both(instances, **kwargs):
    args = _batch(instances)
    return args, solve_lines(*args), solve_lines_qp(*args, **kwargs)


def _check_feasible(instances):
    (P, D, count, hard, pref, v_max), (v_lp, st_lp, sl_lp), (v_qp, st_qp, sl_qp) = \
        _both(instances)
    assert (st_lp == FEASIBLE).all() and (st_qp == FEASIBLE).all()
    dv = np.abs(v_lp - v_qp).max()
    assert dv < TOL, dv
    assert sl_qp.max() < 1e-9 and sl_lp.max() < 1e-9
    speed = np.linalg.norm(v_qp, axis=1)
    assert (speed <= v_max + 1e-9).all()
    return speed, pref, v_max, dv


def test_feasible_instances_agree():
    rng = np.random.default_rng(20240611)
    instances = [_feasible(rng, 0) for _ in range(120)]
    speed, pref, v_max, _ = _check_feasible(instances)
    on_disc = speed > v_max - 1e-9
    # the draw covers all cases: disc active, pref outside the disc, pref itself feasible
    assert on_disc.sum() >= 15
    assert (np.linalg.norm(pref, axis=1) > v_max).sum() >= 20
    assert (~on_disc).sum() >= 30


def test_feasible_instances_with_hard_lines_agree():
    rng = np.random.default_rng(7)
    instances = [_feasible(rng, int(rng.integers(1, 4))) for _ in range(60)]
    _check_feasible(instances)
    # some hard line is active at the optimum in a part of the draw
    active = [np.abs(_viol(p[:h], d[:h], v)).min() < 1e-9
              for (p, d, h, *_), v in zip(instances, solve_lines(*_batch(instances))[0],
                                          strict=True)]
    assert sum(active) >= 10


@pytest.mark.parametrize("max_hard", [0, 2])
def test_infeasible_instances_agree_on_the_least_violation(max_hard):
    rng = np.random.default_rng(11 + max_hard)
    instances = [_infeasible(rng, int(rng.integers(0, max_hard + 1))) for _ in range(70)]
    (P, D, count, hard, pref, v_max), (v_lp, st_lp, _), (v_qp, st_qp, _) = _both(instances)
    assert (st_lp == st_qp).all()
    assert (st_qp == LEAST_VIOLATION).sum() >= 55
    unique = 0
    for r, (p, d, h, _, vm) in enumerate(instances):
        if st_lp[r] == FEASIBLE:
            assert np.abs(v_lp[r] - v_qp[r]).max() < TOL
            continue
        soft_lp, soft_qp = _viol(p, d, v_lp[r])[h:].max(), _viol(p, d, v_qp[r])[h:].max()
        assert abs(soft_lp - soft_qp) < TOL, (r, soft_lp, soft_qp)
        assert (_viol(p, d, v_qp[r])[:h] < 1e-9).all()  # hard lines kept
        assert np.linalg.norm(v_qp[r]) <= vm + 1e-9
        if _unique_minimax(p, d, h, v_lp[r], vm):
            unique += 1
            assert np.abs(v_lp[r] - v_qp[r]).max() < TOL, (r, v_lp[r], v_qp[r])
    assert unique >= 50


def test_orca_crowd_instances_agree():
    rng = np.random.default_rng(3)
    instances = _crowd(rng)
    (P, D, count, hard, pref, v_max), (v_lp, st_lp, sl_lp), (v_qp, st_qp, sl_qp) = \
        _both(instances)
    assert (st_lp == st_qp).all()
    assert (st_lp == LEAST_VIOLATION).sum() >= 30 and (st_lp == FEASIBLE).sum() >= 15
    assert np.abs(sl_lp - sl_qp).max() < TOL
    for r, (p, d, h, _, vm) in enumerate(instances):
        if st_lp[r] == FEASIBLE or _unique_minimax(p, d, h, v_lp[r], vm):
            assert np.abs(v_lp[r] - v_qp[r]).max() < TOL, (r, v_lp[r], v_qp[r])


def test_non_unique_least_violation_keeps_the_objective():
    # x >= 0.5 and x <= -0.5: every v with x = 0 (in the disc) violates both by 0.5
    P = np.array([[[0.5, 0.0], [-0.5, 0.0]]])
    D = np.array([[[0.0, -1.0], [0.0, 1.0]]])
    v, status, slack = solve_lines_qp(P, D, [2], [0], np.array([[0.2, 0.4]]), np.array([2.0]))
    assert status[0] == LEAST_VIOLATION
    assert v[0, 0] == pytest.approx(0.0, abs=1e-9) and np.linalg.norm(v[0]) <= 2.0 + 1e-9
    assert slack[0] == pytest.approx(0.5, abs=1e-9)
    # the first line hard: kept exactly, the other absorbs all
    v, status, slack = solve_lines_qp(P, D, [2], [1], np.array([[0.2, 0.4]]), np.array([2.0]))
    assert status[0] == LEAST_VIOLATION
    assert v[0, 0] == pytest.approx(0.5, abs=1e-9) and slack[0] == pytest.approx(1.0, abs=1e-9)


def test_disc_only_and_line_and_disc_are_exact():
    # no lines, pref outside: the radial projection; one line x >= 0.5: line ∩ circle
    P = np.array([[[0.0, 0.0]], [[0.5, 0.0]]])
    D = np.array([[[1.0, 0.0]], [[0.0, -1.0]]])
    v, status, _ = solve_lines_qp(P, D, [0, 1], [0, 0], np.array([[3.0, 4.0], [0.0, 3.0]]),
                                  1.0)
    np.testing.assert_allclose(v, [[0.6, 0.8], [0.5, np.sqrt(0.75)]], atol=1e-10)
    assert (status == FEASIBLE).all()


def _two_robots():
    P = np.array([[[0.5, 0.0]], [[0.5, 0.0]]])
    D = np.array([[[0.0, -1.0]], [[0.0, -1.0]]])
    return P, D, [1, 1], [0, 0], np.array([[0.0, 3.0], [0.1, 0.2]]), np.array([1.0, 1.0])


def test_unknown_solver_is_a_solver_failure_not_an_exception(caplog):
    P, D, count, hard, pref, v_max = _two_robots()
    with caplog.at_level(logging.WARNING, logger="comparisons.orca.qp"):
        v, status, slack = solve_lines_qp(P, D, count, hard, pref, v_max,
                                          solver="no_such_solver")
    assert (status == SOLVER_FAIL).all()
    np.testing.assert_array_equal(v, pref)  # unchanged, not clipped to the disc
    np.testing.assert_allclose(slack, [0.5, 0.4])  # violation of x >= 0.5 at pref
    assert "2 of 2 robots SOLVER_FAIL" in caplog.text


def test_solver_exception_fails_only_that_robot(monkeypatch):
    P, D, count, hard, pref, v_max = _two_robots()
    real, calls = qpsolvers.solve_qp, []

    def flaky(*args, **kwargs):
        calls.append(kwargs)
        if len(calls) == 1:
            raise RuntimeError("solver crashed")
        return real(*args, **kwargs)

    monkeypatch.setattr(qpsolvers, "solve_qp", flaky)
    v, status, _ = solve_lines_qp(P, D, count, hard, pref, v_max)
    assert status.tolist() == [SOLVER_FAIL, FEASIBLE]
    np.testing.assert_array_equal(v[0], pref[0])
    np.testing.assert_allclose(v[1], [0.5, 0.2], atol=1e-10)
    # tight tolerances passed with every call (OSQP's own defaults are 1e-3)
    assert all(c.pop("solver") == "osqp" for c in calls)
    assert all(c == solver_options("osqp") for c in calls)
    assert calls[0]["eps_abs"] <= 1e-10 and calls[0]["eps_rel"] <= 1e-10


def test_none_for_feasible_lines_is_a_solver_failure_not_infeasibility(monkeypatch):
    """A solver that answers None to the 2D QPs: feasible lines are SOLVER_FAIL (the
    least-violation LP, still solved, shows they are feasible), while truly infeasible
    lines still get their least-violation velocity."""
    real = qpsolvers.solve_qp

    def no_qp(P, q, *args, **kwargs):
        return None if len(q) == 2 else real(P, q, *args, **kwargs)

    monkeypatch.setattr(qpsolvers, "solve_qp", no_qp)
    P = np.array([[[0.5, 0.0], [5.0, 0.0]], [[0.5, 0.0], [-0.5, 0.0]]])
    D = np.array([[[0.0, -1.0], [0.0, -1.0]], [[0.0, -1.0], [0.0, 1.0]]])
    pref = np.array([[0.1, 0.2], [0.2, 0.4]])
    v, status, slack = solve_lines_qp(P, D, [1, 2], [0, 0], pref, np.array([1.0, 2.0]))
    assert status.tolist() == [SOLVER_FAIL, LEAST_VIOLATION]
    np.testing.assert_array_equal(v[0], pref[0])
    assert slack[1] == pytest.approx(0.5, abs=1e-9)


def test_search_failure_is_reported(monkeypatch):
    monkeypatch.setattr(qp_module, "MAX_SEARCH", 0)
    P, D, count, hard, pref, v_max = _two_robots()  # robot 0 needs the disc search
    v, status, _ = solve_lines_qp(P, D, count, hard, pref, v_max)
    assert status.tolist() == [SOLVER_FAIL, FEASIBLE]
    np.testing.assert_array_equal(v[0], pref[0])


def test_stalled_solves_are_retried_with_other_settings(monkeypatch):
    """Every 2D solve with the first settings 'stalls' (None): the retries still give the
    exact projection, onto the circle, with status FEASIBLE."""
    real = qpsolvers.solve_qp

    def stalls(P, q, *args, **kwargs):
        if len(q) == 2 and kwargs == {"solver": "osqp", **solver_options("osqp")}:
            return None
        return real(P, q, *args, **kwargs)

    monkeypatch.setattr(qpsolvers, "solve_qp", stalls)
    P, D, count, hard, pref, v_max = _two_robots()
    v, status, _ = solve_lines_qp(P, D, count, hard, pref, v_max)
    assert status.tolist() == [FEASIBLE, FEASIBLE]
    np.testing.assert_allclose(v, [[0.5, np.sqrt(0.75)], [0.5, 0.2]], atol=1e-10)


def test_hard_lines_missing_the_disc_are_a_solver_failure():
    # the hard line x >= 2 is outside the disc of 1 m/s: the precondition is violated
    P = np.array([[[2.0, 0.0], [0.0, 0.5]]])
    D = np.array([[[0.0, -1.0], [1.0, 0.0]]])
    v, status, _ = solve_lines_qp(P, D, [2], [1], np.array([[0.1, 0.2]]), 1.0)
    assert status[0] == SOLVER_FAIL
    np.testing.assert_array_equal(v[0], [0.1, 0.2])
