"""Whole-arm IK and the exchange-grid cost (groundwork of the double-grasp issue)."""
from __future__ import annotations

import numpy as np

from planner.handover.arm_ik import ArmIK
from planner.handover.exchange_grid import PalmWaypoints, best_nodes, exchange_costs, grid_nodes


def test_ik_reaches_poses_of_random_configurations(default_scene):
    robot = default_scene.robot
    rng = np.random.default_rng(4)
    for arm in robot.spec.arm_names:
        ik = ArmIK(robot, arm)
        solved = 0
        for _ in range(40):
            q = robot.q_rest.copy()
            q[ik.idx] = rng.uniform(robot.lower[ik.idx], robot.upper[ik.idx])
            target = ik.palm(q).homogeneous.copy()
            start = robot.q_rest.copy()
            start[ik.idx] = robot.clip(q + rng.normal(0.0, 0.4, robot.nq))[ik.idx]
            res = ik.solve(target, start)
            assert robot.within_limits(res.q)
            untouched = np.setdiff1d(np.arange(robot.nq), ik.idx)
            assert np.array_equal(res.q[untouched], start[untouched])
            if res.within(1e-3, 1e-2):
                solved += 1
                assert np.allclose(ik.palm(res.q).homogeneous[:3, 3], target[:3, 3], atol=1e-3)
        assert solved >= 36


def test_exchange_cost_is_minimal_over_free_nodes_by_brute_force():
    rng = np.random.default_rng(0)
    w = PalmWaypoints(*(rng.uniform(-0.5, 0.5, 3) for _ in range(6)))
    nodes = grid_nodes(np.array([-0.3, -0.3, 0.0]), np.array([0.3, 0.3, 0.4]), 0.1)
    assert nodes.shape == (7 * 7 * 5, 3)
    free = rng.random(len(nodes)) > 0.3
    costs = exchange_costs(nodes, w)
    best = best_nodes(costs, free, keep=3)
    d = lambda a, b: float(np.linalg.norm(a - b))
    brute = [(d(w.pick_initial, w.pick_grasp) + d(w.pick_grasp, e) + d(e, w.pick_final)
              + d(w.place_initial, e) + d(e, w.place_place) + d(w.place_place, w.place_final), i)
             for i, e in enumerate(nodes) if free[i]]
    assert [i for _, i in sorted(brute)[:3]] == best.tolist()
    assert np.isclose(costs[best[0]], min(c for c, _ in brute))
