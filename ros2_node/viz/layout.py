"""What the rerun logger draws: members, actuators, passive joints, platforms and supports.

A :class:`TwinLayout` comes from a compiled :class:`~flexmb_core.model.model.Model` (a live or
offline run, or a recording that carries its ``scene.yaml``) or grows from what a recording's
messages name (a bag without its scene). It is plain data: no rerun, no ROS.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# One palette for RViz markers (ros2_node.messages) and rerun, so a member looks the same in both.
from ..messages import MEMBER_RGBA

DEFAULT_RGBA = MEMBER_RGBA["frame"]
SUPPORT_RGBA = (0.85, 0.20, 0.20, 1.0)
PLATFORM_RGBA = (0.55, 0.55, 0.60, 0.55)


@dataclass
class PlatformLayout:
    """A platform (a ``platform_pose`` output).

    ``locators[i] = (k, j)``: node ``nodes[i]`` is point ``j`` of member ``k``'s polyline, so the
    platform's outline follows the deformed members. Empty when the nodes are unknown (a recording
    without its scene): only the pose is drawn then.
    """

    name: str
    nodes: tuple[str, ...] = ()
    locators: tuple[tuple[int, int], ...] = ()


@dataclass
class TwinLayout:
    """Names, colours and static geometry of one twin; lists grow as a recording names more."""

    name: str = "twin"
    member_names: list[str] = field(default_factory=list)
    member_colors: list[tuple[float, float, float, float]] = field(default_factory=list)
    actuator_names: list[str] = field(default_factory=list)
    joint_names: list[str] = field(default_factory=list)
    platforms: list[PlatformLayout] = field(default_factory=list)
    support_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))   # (ns, 3) m
    support_labels: list[str] = field(default_factory=list)
    bounds: np.ndarray | None = None                                                # (2, 3) min, max (m)
    from_scene: bool = False

    @classmethod
    def from_model(cls, model) -> "TwinLayout":
        """Everything a compiled model knows: member kinds, platform nodes, fixed supports."""
        scene = model.scene
        where: dict[int, tuple[int, int]] = {}
        for k, m in enumerate(model.members):
            for j, node in enumerate(m.nodes.tolist()):
                where.setdefault(int(node), (k, j))
        platforms = []
        for o in scene.outputs:
            if o.kind != "platform_pose":
                continue
            locs = tuple(where[model.node(n)] for n in o.nodes if model.node(n) in where)
            # a node on no member cannot be followed: draw the pose alone rather than a wrong outline
            platforms.append(PlatformLayout(o.name, tuple(o.nodes), locs if len(locs) == len(o.nodes) else ()))
        # driven supports move with their drive; only the fixed ones are static geometry
        fixed = [s for s in scene.supports if s.type != "driven"]
        pts = np.array([scene.nodes[s.node] for s in fixed], dtype=float).reshape(-1, 3)
        xyz = np.array(list(scene.nodes.values()), dtype=float).reshape(-1, 3)
        return cls(
            name=scene.name,
            member_names=[m.name for m in model.members],
            member_colors=[MEMBER_RGBA.get(m.kind, DEFAULT_RGBA) for m in model.members],
            actuator_names=list(model.actuators.names),
            joint_names=[o.name for o in scene.outputs if o.kind == "joint_angle"],
            platforms=platforms,
            support_points=pts,
            support_labels=[f"{s.node} ({s.type})" for s in fixed],
            bounds=np.array([xyz.min(axis=0), xyz.max(axis=0)]) if xyz.size else None,
            from_scene=True,
        )

    # -- growing from a recording ------------------------------------------------------------
    def member_index(self, name: str, rgba: tuple[float, float, float, float] | None = None) -> int:
        """Index of member ``name``, appended (with ``rgba`` or the default colour) if new."""
        try:
            return self.member_names.index(name)
        except ValueError:
            self.member_names.append(name)
            self.member_colors.append(tuple(rgba) if rgba is not None else DEFAULT_RGBA)
            return len(self.member_names) - 1

    def platform(self, name: str) -> PlatformLayout:
        """The platform called ``name``, appended (pose only) if new."""
        for p in self.platforms:
            if p.name == name:
                return p
        self.platforms.append(PlatformLayout(name))
        return self.platforms[-1]

    def include_points(self, pts: np.ndarray) -> None:
        """Grow :attr:`bounds` to contain ``pts (n, 3)`` (used for the camera when no scene is known)."""
        pts = np.asarray(pts, dtype=float).reshape(-1, 3)
        if pts.size == 0:
            return
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        if self.bounds is None:
            self.bounds = np.array([lo, hi])
        else:
            self.bounds = np.array([np.minimum(self.bounds[0], lo), np.maximum(self.bounds[1], hi)])

    def size(self) -> float:
        """Largest extent of the bounds (m); 1 m when nothing is known."""
        if self.bounds is None:
            return 1.0
        return float(max(np.max(self.bounds[1] - self.bounds[0]), 1e-3))


def rgba8(rgba) -> list[int]:
    """RGBA in [0, 1] → 8-bit RGBA (rerun's colour encoding)."""
    return [int(round(255 * min(max(float(c), 0.0), 1.0))) for c in rgba]
