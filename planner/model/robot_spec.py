"""The robot spec: a TOML file naming the URDFs, the parts (torso, arms, hands, fingers) and the rest pose.

The planner reads everything it knows about a robot from here; no joint or link name of a
particular robot appears in the code.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from planner.core.paths import ASSETS, robot_data_file
from planner.core.tomlread import Table, load_toml

# names the planner gives its own parts and collision subsets: an arm may not take one (nor end in '_hand' or '_env',
# nor hold a '/'), or its subsets would overwrite theirs
RESERVED_NAMES = ("self", "env", "all", "hands", "torso", "object", "moving", "changed", "mixed", "robot")


@dataclass(frozen=True)
class FingerSpec:
    """One finger: its joints (hand-URDF names), fingertip frame and radius, open configuration."""

    name: str
    joints: tuple[str, ...]
    tip_frame: str
    tip_radius: float
    open: tuple[float, ...]


@dataclass(frozen=True)
class HandSpec:
    """A hand URDF mounted on an arm's frame; its names get `prefix` so two copies can coexist."""

    urdf: Path
    prefix: str
    mount_frame: str
    mount_xyz: tuple[float, float, float]
    mount_rpy: tuple[float, float, float]
    palm_frame: str
    thumb: str
    fingers: tuple[FingerSpec, ...]

    def prefixed(self, name: str) -> str:
        return self.prefix + name

    @property
    def finger_names(self) -> tuple[str, ...]:
        return tuple(f.name for f in self.fingers)


@dataclass(frozen=True)
class ArmSpec:
    """An arm: its joints in chain order, its rest configuration, and the hand at its end."""

    name: str
    joints: tuple[str, ...]
    rest: tuple[float, ...]
    shoulder_frame: str
    hand: HandSpec


@dataclass(frozen=True)
class RobotSpec:
    """A whole robot: a body URDF (torso + arms) with hands appended."""

    source: Path
    name: str
    description: str
    body_urdf: Path
    base_xyz: tuple[float, float, float]
    base_rpy: tuple[float, float, float]
    drop_geometry: tuple[str, ...]
    allowed_collisions: tuple[tuple[str, str], ...]  # link pairs never checked against each other (as an SRDF's disable_collisions)
    locked_joints: tuple[tuple[str, float], ...]
    torso_joints: tuple[str, ...]
    torso_rest: tuple[float, ...]
    arms: tuple[ArmSpec, ...]

    def arm(self, name: str) -> ArmSpec:
        for a in self.arms:
            if a.name == name:
                return a
        raise KeyError(f"robot '{self.name}' has no arm '{name}' (arms: {', '.join(self.arm_names)})")

    @property
    def arm_names(self) -> tuple[str, ...]:
        return tuple(a.name for a in self.arms)

    def text(self) -> str:
        """The spec file's text: part of every cache key that depends on the robot."""
        return self.source.read_text()


def resolve_urdf(value: str, spec_dir: Path, tab: Table, key: str) -> Path:
    """A URDF given relative to the spec file, or else inside example-robot-data's robots/ folder."""
    local = (spec_dir / value).resolve()
    if local.is_file():
        return local
    packaged = robot_data_file(value)
    if packaged.is_file():
        return packaged
    raise tab.error(key, f"URDF '{value}' found neither beside the spec nor in example-robot-data's robots/ folder")


def _triple(tab: Table, key: str) -> tuple[float, float, float]:
    return tuple(tab.vector(key, 3, default=[0.0, 0.0, 0.0]).tolist())  # type: ignore[return-value]


def _finger(tab: Table) -> FingerSpec:
    tab.check_keys({"name", "joints", "tip_frame", "tip_radius", "open"})
    joints = tuple(tab.str_list("joints"))
    return FingerSpec(
        name=tab.str("name"),
        joints=joints,
        tip_frame=tab.str("tip_frame"),
        tip_radius=tab.float("tip_radius", positive=True),
        open=tuple(tab.vector("open", len(joints)).tolist()),
    )


def _hand(tab: Table, spec_dir: Path) -> HandSpec:
    tab.check_keys({"urdf", "prefix", "mount_frame", "mount_xyz", "mount_rpy", "palm_frame", "thumb", "fingers"})
    fingers = tuple(_finger(t) for t in tab.tables("fingers"))
    names = [f.name for f in fingers]
    if len(set(names)) != len(names):
        raise tab.error("fingers", "finger names must be unique")
    thumb = tab.str("thumb")
    if thumb not in names:
        raise tab.error("thumb", f"'{thumb}' is not one of the fingers ({', '.join(names)})")
    return HandSpec(
        urdf=resolve_urdf(tab.str("urdf"), spec_dir, tab, "urdf"),
        prefix=tab.str("prefix"),
        mount_frame=tab.str("mount_frame"),
        mount_xyz=_triple(tab, "mount_xyz"),
        mount_rpy=_triple(tab, "mount_rpy"),
        palm_frame=tab.str("palm_frame"),
        thumb=thumb,
        fingers=fingers,
    )


def _arm_name(name: str, arms: Table) -> str:
    """`name` if an arm may be called so; else an error naming the file and the field."""
    if name in RESERVED_NAMES or name.endswith(("_hand", "_env")) or "/" in name or not name:
        raise arms.error(name, f"'{name}' cannot name an arm: the names {', '.join(RESERVED_NAMES)}, names ending in '_hand' "
                               "or '_env' and names with '/' are the planner's own parts and collision subsets; rename the arm")
    return name


def _arm(name: str, tab: Table, spec_dir: Path) -> ArmSpec:
    tab.check_keys({"joints", "rest", "shoulder_frame", "hand"})
    joints = tuple(tab.str_list("joints"))
    return ArmSpec(
        name=name,
        joints=joints,
        rest=tuple(tab.vector("rest", len(joints)).tolist()),
        shoulder_frame=tab.str("shoulder_frame"),
        hand=_hand(tab.table("hand"), spec_dir),
    )


def load_robot_spec(path: str | Path) -> RobotSpec:
    """Read and validate a robot spec TOML (names are checked against the URDFs when the robot is built)."""
    path = Path(path)
    if not path.is_absolute() and not path.exists() and (ASSETS / "robots" / path).exists():
        path = ASSETS / "robots" / path
    root = Table(load_toml(path), path)
    root.check_keys({"name", "description", "body", "arms"})
    body = root.table("body")
    body.check_keys({"urdf", "base_xyz", "base_rpy", "drop_geometry", "allowed_collisions", "locked_joints", "torso_joints",
                     "torso_rest"})
    torso = tuple(body.str_list("torso_joints", default=[]))
    arms_tab = root.table("arms")
    arms = tuple(_arm(_arm_name(name, arms_tab), arms_tab.table(name), path.parent) for name in arms_tab.data)
    if len(arms) != 2:
        raise arms_tab.error(None, f"expected exactly two arms (a picking and a placing arm), got {len(arms)}")
    return RobotSpec(
        source=path.resolve(),
        name=root.str("name"),
        description=root.data.get("description", ""),
        body_urdf=resolve_urdf(body.str("urdf"), path.parent, body, "urdf"),
        base_xyz=_triple(body, "base_xyz"),
        base_rpy=_triple(body, "base_rpy"),
        drop_geometry=tuple(body.str_list("drop_geometry", default=[])),
        allowed_collisions=tuple(body.name_pairs("allowed_collisions")),
        locked_joints=tuple(sorted(body.number_map("locked_joints", default={}).items())),
        torso_joints=torso,
        torso_rest=tuple(body.vector("torso_rest", len(torso), default=[0.0] * len(torso)).tolist()),
        arms=arms,
    )


def rest_configuration_of(spec: RobotSpec) -> dict[str, float]:
    """The rest configuration as joint name -> value (hand joints prefixed)."""
    out = dict(zip(spec.torso_joints, spec.torso_rest))
    for arm in spec.arms:
        out.update(zip(arm.joints, arm.rest))
        for finger in arm.hand.fingers:
            out.update(zip((arm.hand.prefixed(j) for j in finger.joints), finger.open))
    return out
