"""The timed trajectory (trajectory.py), its parabolic ramps (ramps.py) and the collision check of a curve (segments.py).

The ramps' shortest durations are checked against a linear program over the discretised double integrator
(scipy's HiGHS), which shares nothing with the closed forms: no faster motion exists, and the ramp found is at most
as slow as the program's. Curves the check accepts are re-checked densely by the independent oracle (python-fcl, full
link meshes).
"""
from __future__ import annotations

import numpy as np
import pytest
from oracle import Oracle
from scipy.optimize import linprog

from planner.collision.validity import Profile, make_validity
from planner.motion.ramps import first_plans, min_times, moving, plan, positions, ramp
from planner.motion.trajectory import Trajectory, rest_to_rest, trapezoid


def test_trapezoid_durations_analytic():
    vmax, amax = np.array([1.0, 2.0]), np.array([2.0, 2.0])
    # joint 0 moves 2 rad: cruise at 1 rad/s after 0.5 s of acceleration -> 0.5 + 1.5 + 0.5 = 2.5 s
    assert trapezoid(np.array([2.0, 0.0]), vmax, amax)[0] == pytest.approx(2.5)
    # 0.2 rad never reaches the speed limit: triangle, 2 sqrt(0.2 / 2) s
    assert trapezoid(np.array([0.2, 0.0]), vmax, amax)[0] == pytest.approx(2 * np.sqrt(0.1))


def _dense(traj: Trajectory, n: int = 20001) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.linspace(0.0, traj.duration, n)
    q, v = traj.states(t)
    return t, q, v


def test_rest_to_rest_stops_on_every_vertex_and_stays_on_the_segments():
    rng = np.random.default_rng(3)
    path = np.cumsum(rng.normal(0, 0.6, (6, 4)), axis=0)
    vmax, amax = np.array([1.0, 0.5, 2.0, 1.5]), np.array([2.0, 1.0, 3.0, 2.5])
    traj = rest_to_rest(path, vmax, amax)
    t, q, v = _dense(traj)
    assert np.all(np.abs(v) <= vmax * (1 + 1e-9))
    assert np.all(np.abs(np.diff(v, axis=0) / np.diff(t)[:, None]) <= amax * (1 + 1e-6))
    assert traj.duration == pytest.approx(sum(trapezoid(b - a, vmax, amax)[0] for a, b in zip(path[:-1], path[1:])))
    for w in path[1:]:
        k = np.argmin(np.linalg.norm(q - w, axis=1))
        assert np.linalg.norm(q[k] - w) < 1e-3 and np.linalg.norm(v[k]) < 1e-2
    for qi in q[::50]:  # every configuration on one of the segments
        d = min(np.linalg.norm(a + np.clip(np.dot(qi - a, b - a) / np.dot(b - a, b - a), 0, 1) * (b - a) - qi)
                for a, b in zip(path[:-1], path[1:]))
        assert d < 1e-9


def _lp_feasible(d: float, v0: float, v1: float, vmax: float, amax: float, T: float, steps: int = 400) -> bool:
    """Whether a double integrator can move by d from v0 to v1 in T with |v| <= vmax, |a| <= amax (accelerations held
    constant over `steps` intervals: a linear feasibility problem)."""
    h = T / steps
    # unknowns: the accelerations; v_k = v0 + h sum a, x_T = sum over intervals of (v_k h + a_k h^2 / 2)
    lower = np.tril(np.ones((steps, steps)))
    vel = h * lower  # v after each interval
    pos = np.array([h * h * (steps - k - 0.5) for k in range(steps)])  # x_T - v0 T from each a_k
    a_eq = np.vstack([pos, h * np.ones(steps)])
    b_eq = np.array([d - v0 * T, v1 - v0])
    a_ub = np.vstack([vel, -vel])
    b_ub = np.concatenate([np.full(steps, vmax - v0), np.full(steps, vmax + v0)])
    res = linprog(np.zeros(steps), A_ub=a_ub, b_ub=b_ub, A_eq=a_eq, b_eq=b_eq, bounds=[(-amax, amax)] * steps, method="highs")
    return res.status == 0


@pytest.mark.parametrize("case", range(12))
def test_shortest_ramp_duration_matches_a_linear_program(case):
    rng = np.random.default_rng(case)
    d, v0, v1 = rng.uniform(-2, 2), rng.uniform(-1, 1) * (case % 3 != 0), rng.uniform(-1, 1) * (case % 3 != 0)
    vmax, amax = 1.0, 2.0
    T = float(min_times(np.array([d]), np.array([v0]), np.array([v1]), np.array([vmax]), np.array([amax]))[0])
    assert np.isfinite(T)
    assert not _lp_feasible(d, v0, v1, vmax, amax, 0.97 * T)  # nothing faster
    assert _lp_feasible(d, v0, v1, vmax, amax, 1.01 * T)


def test_synchronised_ramps_reach_the_goal_state_within_the_limits():
    rng = np.random.default_rng(7)
    vmax, amax = np.array([1.0, 0.7, 1.3, 1.0, 0.5, 2.0]), np.array([2.0, 1.5, 3.0, 2.0, 1.0, 4.0])
    for _ in range(300):
        q0, q1 = rng.uniform(-2, 2, 6), rng.uniform(-2, 2, 6)
        v0, v1 = rng.uniform(-1, 1, 6) * vmax, rng.uniform(-1, 1, 6) * vmax
        r = ramp(q0, v0, q1, v1, vmax, amax)
        assert r is not None
        fastest = float(np.max(min_times(q1 - q0, v0, v1, vmax, amax)))
        assert fastest - 1e-9 <= r.duration <= 3.0 * fastest
        t, q, v = _dense(r)
        assert np.allclose(q[0], q0) and np.allclose(v[0], v0, atol=1e-9)
        assert np.allclose(q[-1], q1) and np.allclose(v[-1], v1, atol=1e-7)
        assert np.allclose(r.positions(np.array([r.duration * (1 - 1e-12)]))[0], q1, atol=1e-8)  # no jump at the end
        assert np.all(np.abs(v) <= vmax * (1 + 1e-9))
        assert np.all(np.abs(np.diff(v, axis=0) / np.diff(t)[:, None]) <= amax * (1 + 1e-6))
        assert np.abs(np.diff(q, axis=0)).max() < 1e-3  # continuous


def test_ramps_planned_at_once_are_the_ramps_made_one_by_one():
    """The random pass judges a chunk of ramps at once and checks their probes before any is made: the plans made at
    once are bit for bit those `plan` makes alone (where the slowest joint's shortest duration admits one), their
    positions in closed form are the made trajectory's, and the joints they move are those whose trajectory moves."""
    rng = np.random.default_rng(5)
    vmax, amax = np.array([1.0, 1.0, 0.7]), np.array([2.0, 2.0, 1.5])
    n = 3000
    q0, q1 = np.zeros((n, 3)), rng.uniform(-1, 1, (n, 3))
    v0, v1 = rng.uniform(-1, 1, (n, 3)) * vmax, rng.uniform(-1, 1, (n, 3)) * vmax
    still = rng.random((n, 3)) < 0.2  # joints a ramp leaves at rest
    q1[still], v0[still], v1[still] = 0.0, 0.0, 0.0
    within = np.where(rng.random(n) < 0.2, rng.uniform(0.0, 2.0, n), np.inf)
    fastest, T, a, vc, planned = first_plans(q0, v0, q1, v1, vmax, amax, within)
    assert np.array_equal(fastest[planned], T[planned])
    taus = T[:, None] * np.array([0.5, 0.25, 0.75, 0.0, 1.0])
    at = positions(q0, v0, v1, a, vc, T, taus)
    stretched = 0  # ramps whose slowest joint's shortest duration is in another joint's inoperative interval
    for i in range(n):
        alone = plan(q0[i], v0[i], q1[i], v1[i], vmax, amax, within[i])
        if not planned[i]:
            assert alone is None or alone[0] > T[i] or not T[i] < within[i]
            stretched += alone is not None
            continue
        assert alone[0] == T[i] and np.array_equal(alone[1], a[i]) and np.array_equal(alone[2], vc[i])
        made = ramp(q0[i], v0[i], q1[i], v1[i], vmax, amax, within[i])
        assert np.allclose(at[i], made.positions(taus[i]), atol=1e-12, rtol=0)
        assert np.array_equal(moving(v0[i], v1[i], a[i], vc[i]), np.any(made.v != 0, axis=0) | np.any(made.a != 0, axis=0))
    assert planned.sum() > 0.5 * n and stretched > 10


def test_a_spliced_ramp_keeps_the_trajectory_continuous():
    rng = np.random.default_rng(5)
    vmax, amax = np.ones(3), np.full(3, 2.0)
    traj = rest_to_rest(np.cumsum(rng.normal(0, 1, (5, 3)), axis=0), vmax, amax)
    t1, t2 = 0.3 * traj.duration, 0.8 * traj.duration
    (qa, qb), (va, vb) = traj.states(np.array([t1, t2]))
    r = ramp(qa, va, qb, vb, vmax, amax)
    spliced = traj.splice(t1, t2, r)
    assert spliced.duration == pytest.approx(traj.duration - (t2 - t1) + r.duration)
    t, q, v = _dense(spliced, 50001)
    assert np.abs(np.diff(q, axis=0)).max() < 1e-3 and np.abs(np.diff(v, axis=0)).max() < 1e-3
    assert np.allclose(q[-1], traj.end) and np.allclose(spliced.positions(np.array([t1 + r.duration]))[0], qb)


@pytest.fixture(scope="module")
def transit_validity(default_scene, default_collision):
    return make_validity(default_collision, Profile("transit", 0.03, 0.01, 0.015, 0.0, 0.015, 0.0))


def test_a_curve_is_checked_at_least_as_densely_as_the_straight_segment_it_follows(default_scene, transit_validity):
    robot = default_scene.robot
    qa = default_scene.q_initial.copy()
    qb = qa.copy()
    qb[robot.arm_idx["right"][1]] -= 0.4  # clear of the obstacles all the way
    assert transit_validity.seg.segment_free(qa, qb, "env")
    curve = rest_to_rest(np.stack([qa, qb]), np.ones(robot.nq), np.full(robot.nq, 2.0))
    seg = transit_validity.seg
    before = seg.checks
    assert seg.curve_first_hit(curve, "env") is None  # the arm clear of the obstacles: every check made
    curve_checks = seg.checks - before
    straight = int(seg.steps(qa, qb, "env")[0])
    assert straight <= curve_checks <= 1.25 * straight + 2  # the speed bound is loose only while accelerating


def test_curves_the_check_accepts_are_free_by_the_oracle(default_scene, transit_validity):
    """Random ramps through the workspace from the rest pose, checked against the obstacles: those accepted keep the
    robot off them at 200 configurations each (a link's hull holds its mesh, so the oracle's meshes are free where hulls keep clearance)."""
    robot, oracle = default_scene.robot, Oracle(default_scene)
    rng = np.random.default_rng(11)
    idx = np.concatenate([robot.torso_idx, robot.arm_idx["right"], robot.arm_idx["left"]])
    vmax, amax = np.ones(robot.nq), np.full(robot.nq, 2.0)
    seg = transit_validity.seg
    accepted = rejected = 0
    for _ in range(40):
        qa, qb = default_scene.q_initial.copy(), default_scene.q_initial.copy()
        qb[idx] = np.clip(qa[idx] + rng.normal(0, 0.7, len(idx)), robot.lower[idx], robot.upper[idx])
        va = np.zeros(robot.nq)
        va[idx] = rng.uniform(-0.5, 0.5, len(idx))
        r = ramp(qa, va, qb, np.zeros(robot.nq), vmax, amax)
        if r is None:
            continue
        if seg.curve_first_hit(r, "env") is not None:
            rejected += 1
            continue
        accepted += 1
        for q in r.positions(np.linspace(0, r.duration, 200)):
            assert not oracle._environment_hits(*oracle._posed(q))
    assert accepted >= 5 and rejected >= 5  # both kinds were tried


def test_random_shortcuts_are_attempted_most_promising_first():
    """The random pass takes its draws a chunk at a time and attempts, on the trajectory as it is, the draw whose ramp
    could save the most first: a bound that no ramp beats (each ramp found, and the linear program's shortest motion
    above, take at least the slowest joint's shortest move), draws that cannot save the least gain never attempted,
    and the draws left judged again once a shortcut changed the trajectory."""
    from types import SimpleNamespace

    from planner.motion.smoothing import CHUNK, _Run

    rng = np.random.default_rng(11)
    vmax, amax = np.array([1.0, 0.7, 1.3]), np.array([2.0, 1.5, 3.0])
    traj = rest_to_rest(np.cumsum(rng.normal(0, 1, (8, 3)), axis=0), vmax, amax)
    run = object.__new__(_Run)
    run.smoother = SimpleNamespace(vmax=vmax, amax=amax, min_gain=0.02)
    run.traj, run.drawn, run.pending, run.gains, run.judged = traj, 0, None, None, {}
    draws = rng.random((CHUNK + 40, 2))
    order, bounds = [], []
    while (k := run.next_draw(draws)) is not None:
        t1, t2 = np.sort(draws[k] * traj.duration)
        (qa, qb), (va, vb) = traj.states(np.array([t1, t2]))
        bound = run._judge(draws[k][None])[0][0]
        r = ramp(qa, va, qb, vb, vmax, amax)
        assert r is not None and t2 - t1 - r.duration <= bound + 1e-9, "a ramp saved more than its bound"
        assert bound > 0
        order.append(k)
        bounds.append(bound)
    first = [b for k, b in zip(order, bounds) if k < CHUNK]
    assert len(first) and all(k < CHUNK for k in order[:len(first)]), "a chunk is done before the next is judged"
    assert np.all(np.diff(first) <= 1e-12), "within a chunk, the most promising first"
    every = run._judge(draws)[0]
    assert sorted(order) == sorted(np.flatnonzero(every > 0).tolist()), "exactly the draws that could save the least gain"

    run.drawn, run.pending, run.gains = 0, None, None
    k = run.next_draw(draws)
    run.traj = traj.scaled(2.0)  # a kept shortcut changed the trajectory: what is left is judged on the new one
    run.gains = None
    k2 = run.next_draw(draws)
    left = np.delete(np.arange(CHUNK), k)
    again = run._judge(draws[left])[0]
    assert k2 == left[int(np.argmax(again))]
