"""Size limits of a scene, checked before any per-element work so that an oversized or hostile
scene is refused in milliseconds. Users raise them per call (``load_scene(..., limits=)``,
``compile_scene(..., limits=)``) or on the command line (``flexmb check --max-elements N``)."""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import SceneError, thousands


@dataclass(frozen=True)
class Limits:
    """``max_elements``: frame, bar and shell elements in all; ``max_dofs``: DOFs before joints merge
    shared ones; ``max_yaml_nodes``: YAML values after alias expansion (refuses alias bombs);
    ``max_file_bytes``: size of the scene file."""

    max_elements: int = 5_000
    max_dofs: int = 150_000
    max_yaml_nodes: int = 100_000
    max_file_bytes: int = 4_000_000


DEFAULT_LIMITS = Limits()
FLAGS = {"max_elements": "--max-elements", "max_dofs": "--max-dofs", "max_yaml_nodes": "--max-yaml-nodes",
         "max_file_bytes": "--max-file-bytes"}


def over_limit(where: str, what: str, count: int, field: str, limits: Limits, detail: str = "") -> SceneError:
    """The error for ``count`` > ``limits.<field>``: the count, the limit and how to raise it."""
    limit = getattr(limits, field)
    return SceneError(where, f"{what}: {thousands(count)}{' (' + detail + ')' if detail else ''} exceeds the "
                             f"limit of {thousands(limit)}; raise it with `flexmb check|run {FLAGS[field]} N` "
                             f"or Limits({field}=N) in load_scene/compile_scene")


def check_size(scene, limits: Limits | None = None) -> tuple[int, int]:
    """Element and DOF counts of a validated scene from its generators alone (no mesh is built);
    a :class:`SceneError` naming the count, the limit and the flag when one is exceeded."""
    limits = limits or DEFAULT_LIMITS
    elements, dofs, biggest = 0, 3 * len(scene.nodes), ("", 0)
    for mem in scene.members.values():
        m = mem.elements * mem.order + 1
        elements += mem.elements
        dofs += 3 * (m - 2 - len(mem.via))
        if mem.kind == "frame" or (mem.kind == "actuator" and mem.actuator.variant == "frame"):
            dofs += 6 * m
        biggest = max(biggest, (f"members.{mem.name}", mem.elements), key=lambda b: b[1])
    for sh in scene.shells.values():
        ne, nn = _shell_counts(sh.mesh)
        elements += ne
        dofs += 7 * nn                       # position, director, thickness stretch per node
        biggest = max(biggest, (f"shells.{sh.name}", ne), key=lambda b: b[1])
    key = "members" if biggest[0].startswith("members") or not biggest[0] else "shells"
    detail = f"largest: {biggest[0]} with {thousands(biggest[1])}" if biggest[0] else ""
    if elements > limits.max_elements:
        raise over_limit(f"{scene.source}:{key}", "total number of elements", elements, "max_elements", limits,
                         f"{len(scene.members)} members, {len(scene.shells)} shells; {detail}")
    if dofs > limits.max_dofs:
        raise over_limit(f"{scene.source}:{key}", "number of DOFs", dofs, "max_dofs", limits, detail)
    return elements, dofs


def _shell_counts(mesh) -> tuple[int, int]:
    """(elements, nodes) of a shell mesh spec: quads split in two cubic triangles, or n² triangles."""
    if mesh.kind == "triangle":
        d = mesh.divisions[0]
        return d * d, (3 * d + 1) * (3 * d + 2) // 2
    nu, nv = mesh.divisions
    return 2 * nu * nv, (3 * nu + 1) * (3 * nv + 1)
