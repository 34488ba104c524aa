"""The multi-arm decomposition (paper V-A, Fig. 4): a common part (the torso) and independent parts (each arm).

Read from the robot spec, never from joint names: the torso joints are the common part, each arm's
joints an independent part, and every hand joint is held at the rest (open) configuration during
transit. A sub-system is the common part with one arm. Collision pairs are sorted by which motions
can change them, so each stage of the Super Graph checks only what no earlier stage has checked.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.collision.checker import CollisionModel
from planner.model.robot import Robot


@dataclass(frozen=True, eq=False)
class Decomposition:
    """Common and independent parts of a two-arm robot, as configuration indices."""

    arms: tuple[str, ...]
    common: np.ndarray
    independent: dict[str, np.ndarray]
    q_hold: np.ndarray  # every joint outside the sub-systems (the hands) stays here during transit

    def subsystem(self, arm: str) -> np.ndarray:
        """Configuration indices of the sub-system 'common part + this arm'."""
        return np.concatenate([self.common, self.independent[arm]])

    @property
    def transit(self) -> np.ndarray:
        """Every configuration index that moves during transit (common part and all arms)."""
        return np.concatenate([self.common, *self.independent.values()])

    def compose(self, arm_values: dict[str, np.ndarray], common: np.ndarray) -> np.ndarray:
        """Full configurations (n, nq) from each arm's joint values (n, k) and the common part's (n, c)."""
        q = np.repeat(self.q_hold[None, :], len(common), axis=0)
        q[:, self.common] = common
        for arm, values in arm_values.items():
            q[:, self.independent[arm]] = values
        return q


def decompose(robot: Robot) -> Decomposition:
    """The decomposition of a robot spec with exactly two arms."""
    arms = tuple(robot.spec.arm_names)
    if len(arms) != 2:
        raise ValueError(f"the Super Graph composes two arms; robot '{robot.spec.name}' has {len(arms)}")
    return Decomposition(arms, robot.torso_idx.copy(), {a: robot.arm_idx[a].copy() for a in arms}, robot.q_rest.copy())


def pair_subsets(cm: CollisionModel, dec: Decomposition) -> dict[str, np.ndarray]:
    """Pair indices (into cm.geometry.collisionPairs) for each roadmap check; see the module docstring.

    'moving': pairs whose relative pose changes in transit (pairs inside a held hand never do);
    'sub/<arm>': moving pairs of the sub-system (the other arm ignored) — elementary roadmaps;
    'cross/<arm>': moving pairs between the arm and anything else — an SG node or edge whose common
    part comes from the other arm's elementary node;
    'mixed': moving pairs not inside one arm — an SG edge whose common part switches source.
    """
    first, second = cm.ends[:, 0], cm.ends[:, 1]
    moving = cm.relative_joints()[:, dec.transit].any(axis=1)
    n_env = len(cm.geometry.geometryObjects) - cm.n_robot_geoms
    group = np.array([p.removesuffix("_hand") for p in cm.parts] + ["env"] * n_env)
    ga, gb = group[first], group[second]
    k = np.arange(len(first))
    out = {"moving": k[moving], "mixed": k[moving & ~((ga == gb) & np.isin(ga, dec.arms))]}
    for arm in dec.arms:
        others = [a for a in dec.arms if a != arm]
        out[f"sub/{arm}"] = k[moving & ~np.isin(ga, others) & ~np.isin(gb, others)]
        out[f"cross/{arm}"] = k[moving & ((ga == arm) != (gb == arm))]
    return out
