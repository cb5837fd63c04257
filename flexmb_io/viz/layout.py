"""What the rerun logger draws: members, shells, actuators, passive joints, platforms and supports.

A :class:`TwinLayout` comes from a compiled :class:`~flexmb_core.model.model.Model` (a live or
offline run, or a recording that carries its ``scene.yaml``) or grows from what a recording's
messages name (a bag without its scene). It is plain data: no rerun, no ROS.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# One palette for RViz markers (flexmb_io.messages) and rerun, so a member looks the same in both.
from ..messages import MEMBER_RGBA, SHELL_RGBA
from ..shells import shell_triangles

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
class ShellLayout:
    """A shell: name, colour and, when a model says them, its flat triangles ``triangles (nt, 3)``
    in mesh-node indices (:func:`flexmb_io.shells.shell_triangles`) and ``first (N,)``: where each
    mesh node first appears in the triangle list ``triangles.ravel()``, i.e. in the points of the
    shell's TRIANGLE_LIST marker (so a recording's markers give back the node positions)."""

    name: str
    color: tuple[float, float, float, float] = SHELL_RGBA
    triangles: np.ndarray | None = None
    first: np.ndarray | None = None

    @classmethod
    def from_info(cls, info) -> "ShellLayout":
        """From a compiled model's :class:`~flexmb_core.model.model.ShellInfo`."""
        tri = shell_triangles(info.tri)
        ids, first = np.unique(tri.ravel(), return_index=True)
        # a mesh node in no element cannot come back from the markers: then draw the list as is
        ok = ids.size == info.nodes.size
        return cls(info.name, SHELL_RGBA, tri, first if ok else None)


@dataclass
class TwinLayout:
    """Names, colours and static geometry of one twin; lists grow as a recording names more."""

    name: str = "twin"
    member_names: list[str] = field(default_factory=list)
    member_colors: list[tuple[float, float, float, float]] = field(default_factory=list)
    actuator_names: list[str] = field(default_factory=list)
    joint_names: list[str] = field(default_factory=list)
    platforms: list[PlatformLayout] = field(default_factory=list)
    shells: list[ShellLayout] = field(default_factory=list)
    support_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))   # (ns, 3) m
    support_labels: list[str] = field(default_factory=list)
    bounds: np.ndarray | None = None                                                # (2, 3) min, max (m)
    from_scene: bool = False

    @classmethod
    def from_model(cls, model) -> "TwinLayout":
        """Everything a compiled model knows: member kinds, shell meshes, platform nodes, fixed supports."""
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
        # driven supports move with their drive; only the fixed ones are static geometry. A shell
        # edge support holds every node along the edge: one point (and label) per node
        pts, labels = [], []
        for s in scene.supports:
            if s.type == "driven":
                continue
            if s.edge is not None:
                info = model.shell(s.edge[0])
                for j in np.asarray(info.edges[s.edge[1]]).tolist():
                    pts.append(info.x0[j])
                    labels.append(f"{s.edge[0]}.{s.edge[1]}[{j}] ({s.type})")
            else:
                pts.append(model.q0[model.node_ydofs[model.node(s.node)]])   # a scene node or a shell point
                labels.append(f"{s.node} ({s.type})")
        pts = np.array(pts, dtype=float).reshape(-1, 3)
        xyz = np.array(list(scene.nodes.values()), dtype=float).reshape(-1, 3)
        shells = tuple(getattr(model, "shells", ()))
        # shell meshes generate their nodes: the camera must see those too
        xyz = np.concatenate([xyz] + [np.asarray(s.x0, dtype=float).reshape(-1, 3) for s in shells])
        return cls(
            name=scene.name,
            member_names=[m.name for m in model.members],
            member_colors=[MEMBER_RGBA.get(m.kind, DEFAULT_RGBA) for m in model.members],
            actuator_names=list(model.actuators.names),
            joint_names=[o.name for o in scene.outputs if o.kind == "joint_angle"],
            platforms=platforms,
            shells=[ShellLayout.from_info(s) for s in shells],
            support_points=pts,
            support_labels=labels,
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

    def shell(self, name: str, rgba: tuple[float, float, float, float] | None = None) -> ShellLayout:
        """The shell called ``name``, appended (with ``rgba`` or the shell colour, no triangles) if new."""
        for s in self.shells:
            if s.name == name:
                return s
        self.shells.append(ShellLayout(name, tuple(rgba) if rgba is not None else SHELL_RGBA))
        return self.shells[-1]

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
