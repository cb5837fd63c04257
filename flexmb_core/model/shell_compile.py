"""Compile the shell parts of a scene: meshes → global nodes and DOFs, element groups, mass,
edge supports and edge loads (called by :func:`flexmb_core.model.compile.compile_scene`)."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from ..kernels.shell import N_SMAT, SMAT_H, SMAT_LAMBDA, SMAT_MU
from ..scene.schema import Scene, Shell
from . import shell_mesh
from .model import ShellGroup, ShellInfo
from .shell_geometry import shell_element_geometry, shell_element_mass, shell_rule

MASS_RULE = (4, 3)      # exact for the mass integrand (degree 6 in-plane, ζ⁴ through the thickness)


@dataclass
class ShellDraft:
    """A shell between node numbering and DOF compaction: its mesh, global node ids and the
    (uncompacted) ids of its G and a unknowns."""

    spec: Shell
    mesh: shell_mesh.ShellMesh
    nodes: np.ndarray           # (N,) global node ids
    gdofs: np.ndarray           # (N, 3)
    adofs: np.ndarray           # (N,)


def generate_mesh(spec: Shell, nodes: dict) -> shell_mesh.ShellMesh:
    """The mesh a shell's generator describes (positions from the scene's named nodes)."""
    m = spec.mesh
    if m.kind == "rectangle":
        return shell_mesh.rectangle([nodes[c] for c in m.corners], m.divisions, m.pattern)
    if m.kind == "triangle":
        return shell_mesh.triangle([nodes[c] for c in m.corners], m.divisions[0])
    if m.kind == "annulus":
        return shell_mesh.annulus(m.center, m.axis, m.reference, m.inner_radius, m.outer_radius, m.angles,
                                  m.divisions, m.pattern)
    return shell_mesh.cylinder(m.center, m.axis, m.reference, m.radius, m.length, m.angles, m.divisions,
                               m.pattern)


def number_shell_nodes(scene: Scene, node_lookup: dict, node_names: list, node_x: list, ydof: list,
                       member_nodes: dict[str, np.ndarray], take) -> list[ShellDraft]:
    """Give every shell mesh node a global node (new, a named corner, or the coincident node of an
    edge or member it is hinged to) and allocate positions (shared per node), G and a (per shell).

    ``take(values, kind)`` allocates DOFs (kind 0 position, 1 vector/scalar) and returns the first id.
    """
    drafts: list[ShellDraft] = []
    built_edges: dict[tuple[str, str], np.ndarray] = {}
    size = _model_size(node_x)
    for spec in scene.shells.values():
        mesh = generate_mesh(spec, scene.nodes)
        where = f"{scene.source}:shells.{spec.name}"
        ids = np.full(mesh.x.shape[0], -1, dtype=np.int64)
        for k, name in zip(mesh.corners, spec.mesh.corners):
            ids[k] = node_lookup[name]
        for j in scene.shell_joints:
            if j.type != "hinge_line":
                continue
            mine = [e for e in j.edges if e[0] == spec.name]
            if not mine:
                continue
            anchor = None
            if j.member is not None:
                anchor = member_nodes[j.member]
            else:
                done = [e for e in j.edges if e in built_edges]
                if done:
                    anchor = built_edges[done[0]]
            if anchor is None:
                continue
            edge_nodes = mesh.edges[mine[0][1]]
            other = j.member if j.member is not None else f"edge {done[0][0]}.{done[0][1]}"
            if anchor.size != edge_nodes.size:
                raise SceneError(where, f"edge '{mine[0][1]}' has {edge_nodes.size} nodes but {other} has "
                                        f"{anchor.size}; a hinge line pairs nodes one to one (a cubic member "
                                        "needs 'elements' equal to the edge's divisions)")
            anchor_x = np.array([node_x[n] for n in anchor])
            for k in edge_nodes:
                dist = np.linalg.norm(anchor_x - mesh.x[k], axis=1)
                m = int(np.argmin(dist))
                if dist[m] > 1e-9 * size:
                    raise SceneError(where, f"edge '{mine[0][1]}' node at {np.round(mesh.x[k], 9).tolist()} has no "
                                            f"coincident node on {other} (nearest {dist[m]:.3g} m away)")
                if ids[k] >= 0 and ids[k] != anchor[m]:
                    raise SceneError(where, f"corner node '{node_names[ids[k]]}' coincides with node "
                                            f"'{node_names[anchor[m]]}' of {other}; name the same node in both")
                ids[k] = anchor[m]
        for k in range(ids.size):
            if ids[k] < 0:
                name = f"{spec.name}/{k}"
                node_lookup[name] = len(node_names)
                node_names.append(name)
                node_x.append(mesh.x[k])
                ydof.append(-1)
                ids[k] = node_lookup[name]
        gdofs = np.empty((ids.size, 3), dtype=np.int64)
        adofs = np.empty(ids.size, dtype=np.int64)
        for k, n in enumerate(ids):
            if ydof[n] < 0:
                ydof[n] = take(list(node_x[n]), 0)
            gdofs[k] = take(list(mesh.normal[k]), 1) + np.arange(3)
            adofs[k] = take([0.0], 1)
        for e, nodes_e in mesh.edges.items():
            built_edges[(spec.name, e)] = ids[nodes_e]
        drafts.append(ShellDraft(spec, mesh, ids, gdofs, adofs))
    return drafts


def _model_size(node_x: list) -> float:
    if not node_x:
        return 1.0
    x = np.asarray(node_x)
    return max(float(np.linalg.norm(x.max(0) - x.min(0))), 1e-300)


def compact_drafts(drafts: list[ShellDraft], compact: np.ndarray) -> None:
    """Renumber the G and a ids after the joint DOF map merged and compacted the DOF vector."""
    for d in drafts:
        d.gdofs = compact[d.gdofs]
        d.adofs = compact[d.adofs]


def shell_infos(drafts: list[ShellDraft], node_ydofs: np.ndarray) -> tuple[ShellInfo, ...]:
    return tuple(ShellInfo(d.spec.name, d.nodes, node_ydofs[d.nodes], d.gdofs, d.adofs, d.mesh.tri,
                           d.mesh.edges, d.mesh.x, d.mesh.normal) for d in drafts)


def build_shell_groups(scene: Scene, infos: tuple[ShellInfo, ...], scatter_map,
                       mass_rows: list, mass_cols: list, mass_vals: list) -> tuple[ShellGroup, ...]:
    """Element groups (one per quadrature) with their scatter maps; appends the element masses."""
    build: dict[tuple[int, int], dict[str, list]] = defaultdict(lambda: defaultdict(list))
    rules = {}
    mass_rule = shell_rule(*MASS_RULE)
    for info in infos:
        spec = scene.shells[info.name]
        mat = scene.materials[spec.material]
        lam = mat.E * mat.nu / ((1.0 + mat.nu) * (1.0 - 2.0 * mat.nu))
        mu = mat.E / (2.0 * (1.0 + mat.nu))
        hh = 0.5 * spec.thickness
        row = np.zeros(N_SMAT)
        row[SMAT_LAMBDA], row[SMAT_MU], row[SMAT_H] = lam, mu, hh
        if spec.quadrature not in rules:
            rules[spec.quadrature] = shell_rule(*spec.quadrature)
        phi, dphi, zeta, wts = rules[spec.quadrature]
        b = build[spec.quadrature]
        for e, tri in enumerate(info.tri):
            x, v0 = info.x0[tri], info.normal0[tri]
            where = f"{scene.source}:shells.{info.name} (element {e})"
            try:
                a0inv, w = shell_element_geometry(x, v0, hh, phi, dphi, zeta, wts, where)
                _, wm = shell_element_geometry(x, v0, hh, mass_rule[0], mass_rule[1], mass_rule[2], mass_rule[3],
                                               where)
            except ValueError as exc:
                raise SceneError(where, str(exc).split(": ", 1)[1]) from None
            edofs = element_dofs(info, tri)
            b["edofs"].append(edofs)
            b["a0inv"].append(a0inv)
            b["w"].append(w)
            b["mat"].append(row)
            b["shell"].append(info.name)
            me = shell_element_mass(mass_rule[0], mass_rule[2], wm, mat.rho, hh)
            mass_rows.append(np.repeat(edofs, edofs.size))
            mass_cols.append(np.tile(edofs, edofs.size))
            mass_vals.append(me.ravel())
    groups = []
    for quad, b in sorted(build.items()):
        phi, dphi, zeta, _ = rules[quad]
        edofs = np.asarray(b["edofs"], dtype=np.int64)
        g = ShellGroup(quad, edofs, np.ascontiguousarray(phi), np.ascontiguousarray(dphi), np.ascontiguousarray(zeta),
                       np.ascontiguousarray(b["a0inv"]), np.ascontiguousarray(b["w"]),
                       np.ascontiguousarray(b["mat"], dtype=float),
                       np.ascontiguousarray([scatter_map(ed) for ed in edofs], dtype=np.int64))
        for a in (g.edofs, g.phi, g.dphi, g.zeta, g.a0inv, g.w, g.mat, g.smap):
            a.setflags(write=False)
        groups.append(g)
    return tuple(groups)


def shell_element_pairs(infos: tuple[ShellInfo, ...]) -> list[np.ndarray]:
    """Element DOF lists of every shell element (for the sparsity pattern), before the groups exist."""
    return [element_dofs(info, tri) for info in infos for tri in info.tri]


def element_dofs(info: ShellInfo, tri: np.ndarray) -> np.ndarray:
    """Global ids of one element's 70 unknowns, [Y, G, a] node by node (the kernel's order)."""
    return np.column_stack((info.ydofs[tri], info.gdofs[tri], info.adofs[tri])).ravel()


def edge_support_dofs(scene: Scene, infos: tuple[ShellInfo, ...]) -> list[np.ndarray]:
    """Prescribed DOF ids of the edge supports: clamp fixes Y and G of every edge node, ball fixes Y
    (a fixed hinge line). The strain rate a stays free (the thickness may still change)."""
    by_name = {i.name: i for i in infos}
    out = []
    for s in scene.supports:
        if s.edge is None:
            continue
        info = by_name[s.edge[0]]
        k = info.edges[s.edge[1]]
        out.append(info.ydofs[k].ravel())
        if s.type == "clamp":
            out.append(info.gdofs[k].ravel())
    return out


def clamp_node_gdofs(infos: tuple[ShellInfo, ...], node_id: int) -> list[np.ndarray]:
    """G ids of every shell node at global node ``node_id`` (a clamp there fixes them too)."""
    return [info.gdofs[k] for info in infos for k in np.nonzero(info.nodes == node_id)[0]]


def edge_load_patterns(scene: Scene, infos: tuple[ShellInfo, ...], ndof: int) -> tuple[list, list, list]:
    """Edge forces as nodal force patterns (ndof,) with their signals, and edge moments as
    conservative moment entries (vector ids, axes, magnitude, signal) on the directors G.

    Weights are the consistent ∫φ_k ds of the cubic edge (:func:`shell_mesh.edge_weights`).
    """
    by_name = {i.name: i for i in infos}
    patterns, signals, moments = [], [], []
    for load in scene.edge_loads:
        info = by_name[load.edge[0]]
        k = info.edges[load.edge[1]]
        wts = shell_mesh.edge_weights(info.x0[k])
        val = np.asarray(load.value, dtype=float)
        if load.kind == "force":
            f = np.zeros(ndof)
            for kk, wk in zip(k, wts):
                f[info.ydofs[kk]] += wk * val
            patterns.append(f)
            signals.append(load.signal)
            continue
        mag = float(np.linalg.norm(val))
        if mag == 0.0:
            continue
        n = val / mag
        for kk, wk in zip(k, wts):
            g0 = info.normal0[kk]
            a = g0 - (g0 @ n) * n
            if np.linalg.norm(a) < 1e-6:
                raise SceneError(f"{scene.source}:loads.edge_moments.{load.name}",
                                 f"moment {val.tolist()} is about the shell normal (drilling) at "
                                 f"{np.round(info.x0[kk], 6).tolist()}: a shell carries no drilling moment")
            a /= np.linalg.norm(a)
            moments.append((info.gdofs[kk], np.array([a, np.cross(n, a), n]), mag * wk, load.signal))
    return patterns, signals, moments


def shell_point_node(info: ShellInfo, at, where: str, edge: str | None = None) -> int:
    """Index (in the shell) of the mesh node at the reference position ``at`` (on ``edge`` only,
    when given: the two edges of a slit coincide)."""
    cand = info.edges[edge] if edge is not None else np.arange(info.x0.shape[0])
    d = np.linalg.norm(info.x0[cand] - np.asarray(at, dtype=float), axis=1)
    k = int(cand[int(np.argmin(d))])
    d = np.linalg.norm(info.x0 - np.asarray(at, dtype=float), axis=1)
    size = float(np.linalg.norm(info.x0.max(0) - info.x0.min(0)))
    if d[k] > 1e-6 * max(size, 1e-300):
        raise SceneError(where, f"no node of shell '{info.name}' at {list(at)} (nearest {d[k]:.3g} m away, at "
                                f"{np.round(info.x0[k], 6).tolist()})")
    return k
