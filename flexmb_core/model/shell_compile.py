"""Compile the shell parts of a scene: meshes → global nodes and DOFs, element groups, mass,
edge supports and edge loads (called by :func:`flexmb_core.model.compile.compile_scene`)."""

from __future__ import annotations

import dataclasses
from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from ..kernels.shell import N_SMAT, SMAT_GM, SMAT_GS, SMAT_H, SMAT_LAMBDA, SMAT_MU, const_rows, shell_constants
from ..scene.schema import Scene, Shell
from . import shell_mesh
from .model import ShellGroup, ShellInfo
from .shell_geometry import membrane_weight, shell_element_geometry, shell_element_mass, shell_rule

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
                                  m.divisions, m.pattern, m.closed)
    if m.kind == "spherical_cap":
        return shell_mesh.spherical_cap(m.center, m.axis, m.reference, m.radius, m.polar_angles, m.angles,
                                        m.divisions, m.pattern, m.closed)
    return shell_mesh.cylinder(m.center, m.axis, m.reference, m.radius, m.length, m.angles, m.divisions,
                               m.pattern, m.closed)


def number_shell_nodes(scene: Scene, node_lookup: dict, node_names: list, node_x: list, ydof: list,
                       member_nodes: dict[str, np.ndarray], take) -> list[ShellDraft]:
    """Give every shell mesh node a global node (new, a named corner, or the coincident node of an
    edge or member it is hinged to) and allocate positions (shared per node), G and a (per shell).
    A hinge line listing two edges of one shell closes it onto itself: their coincident nodes share
    a global node (a position), each keeping its own G and a. The scene's shell points are then
    registered in ``node_lookup`` under their names (:func:`resolve_shell_points`).

    ``take(values, kind)`` allocates DOFs (kind 0 position, 1 vector/scalar) and returns the first id.
    """
    drafts: list[ShellDraft] = []
    built_edges: dict[tuple[str, str], np.ndarray] = {}
    size = _model_size(node_x)
    for spec in scene.shells.values():
        mesh = generate_mesh(spec, scene.nodes)
        where = f"{scene.source}:shells.{spec.name}"
        ids = np.full(mesh.x.shape[0], -1, dtype=np.int64)
        alias = np.arange(mesh.x.shape[0])          # mesh node → the mesh node whose position it shares
        for k, name in zip(mesh.corners, spec.mesh.corners):
            ids[k] = node_lookup[name]
        for j in scene.shell_joints:
            if j.type != "hinge_line":
                continue
            mine = [e for e in j.edges if e[0] == spec.name]
            if not mine:
                continue
            anchor, other = None, ""
            if j.member is not None:
                anchor, other = member_nodes[j.member], j.member
            else:
                done = [e for e in j.edges if e in built_edges]
                if done:
                    anchor, other = built_edges[done[0]], f"edge {done[0][0]}.{done[0][1]}"
            if anchor is None:
                for e in mine[1:]:                   # the shell closed onto itself along mine[0]
                    _pair_self(mesh, mine[0][1], e[1], alias, size, where)
                continue
            anchor_x = np.array([node_x[n] for n in anchor])
            for e in mine:
                edge_nodes = mesh.edges[e[1]]
                if anchor.size != edge_nodes.size:
                    raise SceneError(where, f"edge '{e[1]}' has {edge_nodes.size} nodes but {other} has "
                                            f"{anchor.size}; a hinge line pairs nodes one to one (a cubic member "
                                            "needs 'elements' equal to the edge's divisions)")
                for k in edge_nodes:
                    m = _coincident(anchor_x, mesh.x[k], size, where, f"edge '{e[1]}'", other)
                    if ids[k] >= 0 and ids[k] != anchor[m]:
                        raise SceneError(where, f"corner node '{node_names[ids[k]]}' coincides with node "
                                                f"'{node_names[anchor[m]]}' of {other}; name the same node in both")
                    ids[k] = anchor[m]
        for k in range(ids.size):
            if ids[k] < 0 and alias[k] == k:
                name = f"{spec.name}/{k}"
                node_lookup[name] = len(node_names)
                node_names.append(name)
                node_x.append(mesh.x[k])
                ydof.append(-1)
                ids[k] = node_lookup[name]
        for k in range(ids.size):
            if alias[k] != k:
                if ids[k] >= 0 and ids[k] != ids[alias[k]]:
                    raise SceneError(where, f"corner node '{node_names[ids[k]]}' lies on both edges of the "
                                            "self-closing hinge line; name no corner there")
                ids[k] = ids[alias[k]]
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
    resolve_shell_points(scene, drafts, node_lookup)
    return drafts


def _coincident(candidates: np.ndarray, x: np.ndarray, size: float, where: str, what: str, other: str) -> int:
    """Index of the candidate position at ``x`` (within 10⁻⁹ of the model size), else a SceneError."""
    dist = np.linalg.norm(candidates - x, axis=1)
    m = int(np.argmin(dist))
    if dist[m] > 1e-9 * size:
        raise SceneError(where, f"{what} node at {np.round(x, 9).tolist()} has no coincident node on {other} "
                                f"(nearest {dist[m]:.3g} m away)")
    return m


def _pair_self(mesh: shell_mesh.ShellMesh, first: str, second: str, alias: np.ndarray, size: float,
               where: str) -> None:
    """Let every node of edge ``second`` share the position of its coincident node on ``first``."""
    a, b = mesh.edges[first], mesh.edges[second]
    if a.size != b.size:
        raise SceneError(where, f"edge '{second}' has {b.size} nodes but edge '{first}' has {a.size}; a hinge line "
                                "pairs nodes one to one")
    size = max(size, float(np.ptp(mesh.x, axis=0).max()))
    for k in b:
        m = a[_coincident(mesh.x[a], mesh.x[k], size, where, f"edge '{second}'", f"edge '{first}'")]
        if m != k:
            alias[k] = alias[m]


def resolve_shell_points(scene: Scene, drafts: list[ShellDraft], node_lookup: dict) -> None:
    """Register every shell point (:class:`~flexmb_core.scene.schema.ShellPoint`) in ``node_lookup``:
    its name → the global node of the mesh node nearest to ``at`` (on its edge when given); a
    SceneError naming the point's key when none lies within its tolerance."""
    by_name = {d.spec.name: d for d in drafts}
    for p in scene.shell_points:
        d = by_name[p.shell]
        cand = d.mesh.edges[p.edge] if p.edge is not None else np.arange(d.mesh.x.shape[0])
        dist = np.linalg.norm(d.mesh.x[cand] - np.asarray(p.at, dtype=float), axis=1)
        i = int(np.argmin(dist))
        tol = p.tolerance if p.tolerance is not None else 1e-6 * max(float(np.ptp(d.mesh.x, axis=0).max()), 1e-300)
        if dist[i] > tol:
            on = f" on edge '{p.edge}'" if p.edge else ""
            raise SceneError(f"{scene.source}:{p.where}",
                             f"no mesh node of shell '{p.shell}'{on} within {tol:.3g} m of {list(p.at)} (nearest "
                             f"{dist[i]:.3g} m away, at {np.round(d.mesh.x[cand[i]], 6).tolist()}); refine the mesh "
                             "so that a node falls there, or give a 'tolerance' (m)")
        node_lookup[p.name] = int(d.nodes[cand[i]])


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
            # assumed strains: the membrane part beyond P1 weighted by s, the shear projected on P2
            row_e = row.copy()
            row_e[SMAT_GM] = 1.0 - membrane_weight(x, v0, spec.thickness, dphi)
            row_e[SMAT_GS] = 1.0
            b["mat"].append(row_e)
            b["shell"].append(info.name)
            me = shell_element_mass(mass_rule[0], mass_rule[2], wm, mat.rho, hh)
            mass_rows.append(np.repeat(edofs, edofs.size))
            mass_cols.append(np.tile(edofs, edofs.size))
            mass_vals.append(me.ravel())
    groups = []
    for quad, b in sorted(build.items()):
        phi, dphi, zeta, _ = rules[quad]
        edofs = np.asarray(b["edofs"], dtype=np.int64)
        phi, dphi, zeta = np.ascontiguousarray(phi), np.ascontiguousarray(dphi), np.ascontiguousarray(zeta)
        a0inv, w = np.ascontiguousarray(b["a0inv"]), np.ascontiguousarray(b["w"])
        for a in (phi, dphi, zeta, a0inv, w):
            a.setflags(write=False)     # read-only, as the kernels see them: one signature each
        g = ShellGroup(quad, edofs, phi, dphi, zeta, a0inv, w, np.ascontiguousarray(b["mat"], dtype=float),
                       element_constants(phi, dphi, zeta, a0inv, w, quad[1]),
                       np.ascontiguousarray([scatter_map(ed) for ed in edofs], dtype=np.int64))
        for a in (g.edofs, g.phi, g.dphi, g.zeta, g.a0inv, g.w, g.mat, g.const, g.smap):
            a.setflags(write=False)
        groups.append(g)
    return tuple(groups)


def element_constants(phi: np.ndarray, dphi: np.ndarray, zeta: np.ndarray, a0inv: np.ndarray, w: np.ndarray,
                      n_thickness: int) -> np.ndarray:
    """``(ne, rows, 9)``: each element's :func:`~flexmb_core.kernels.shell.shell_constants` (the
    rule's ``phi, dphi, zeta`` with ``n_thickness`` points through the thickness at each in-plane
    point, consecutive; per element ``a0inv (ne, npt, 3, 3)``, ``w (ne, npt)``)."""
    ne, npt = w.shape
    nip = npt // n_thickness
    out = np.zeros((ne, const_rows(nip, npt), 9))
    for e in range(ne):
        got = shell_constants(phi, dphi, zeta, np.ascontiguousarray(a0inv[e]), np.ascontiguousarray(w[e]), out[e])
        if got != nip:      # shell_rule orders the points by in-plane point: a broken rule, not a scene's fault
            raise RuntimeError(f"shell rule: {got} runs of in-plane points, expected {nip} ({npt} points, "
                               f"{n_thickness} through the thickness)")
    return out


def shell_element_pairs(infos: tuple[ShellInfo, ...]) -> list[np.ndarray]:
    """Element DOF lists of every shell element (for the sparsity pattern), before the groups exist."""
    return [element_dofs(info, tri) for info in infos for tri in info.tri]


def element_dofs(info: ShellInfo, tri: np.ndarray) -> np.ndarray:
    """Global ids of one element's 70 unknowns, [Y, G, a] node by node (the kernel's order)."""
    return np.column_stack((info.ydofs[tri], info.gdofs[tri], info.adofs[tri])).ravel()


def edge_support_dofs(scene: Scene, infos: tuple[ShellInfo, ...]) -> list[np.ndarray]:
    """Prescribed DOF ids of the edge supports: clamp fixes Y and G of every edge node, ball fixes Y
    (a fixed hinge line), roller with the normal n = ±e_i fixes Y_i, symmetry with the plane normal n = ±e_i fixes Y_i and G_i (the node stays
    in the plane, the director too: see :func:`~flexmb_core.scene.shells.parse_edge_support`). The
    strain rate a stays free (the thickness may still change)."""
    by_name = {i.name: i for i in infos}
    out = []
    for i, s in enumerate(scene.supports):
        if s.edge is None:
            continue
        info = by_name[s.edge[0]]
        k = info.edges[s.edge[1]]
        if s.type in ("symmetry", "roller"):
            comp = int(np.argmax(np.abs(s.normal)))
            out.append(info.ydofs[k, comp])
            if s.type == "symmetry":
                _check_symmetry_edge(f"{scene.source}:supports[{i}]", s, info, k, comp)
                out.append(info.gdofs[k, comp])
            continue
        out.append(info.ydofs[k].ravel())
        if s.type == "clamp":
            out.append(info.gdofs[k].ravel())
    return out


def _check_symmetry_edge(where: str, s, info: ShellInfo, k: np.ndarray, comp: int) -> None:
    """A symmetry edge lies in one plane x_i = const and the shell crosses it at a right angle
    (its reference director in the plane), else fixing x_i and G_i is no symmetry: a SceneError."""
    xi = info.x0[k, comp]
    size = max(float(np.ptp(info.x0, axis=0).max()), 1e-300)
    axis = "xyz"[comp]
    if np.ptp(xi) > 1e-9 * size:
        raise SceneError(where, f"edge {s.edge[0]}.{s.edge[1]} is not in a plane {axis} = const ({axis} from {xi.min():.6g} to "
                                f"{xi.max():.6g} m); a symmetry edge lies in its symmetry plane")
    off = np.abs(info.normal0[k, comp])
    if off.max() > 1e-6:
        j = int(np.argmax(off))
        raise SceneError(where, f"shell '{s.edge[0]}' does not meet the plane {axis} = {xi[0]:.6g} at a right angle (normal "
                                f"{np.round(info.normal0[k[j]], 6).tolist()} at {np.round(info.x0[k[j]], 6).tolist()}); "
                                "across a symmetry plane the surface continues as its mirror image")


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


def without_assumed_strains(model):
    """A copy of the compiled ``model`` whose shell elements have both assumed-strain weights 0:
    the unprojected element (the shell before issue 16's locking remedy), bit for bit — what the
    locking benchmark and test compare the remedy against."""
    groups = []
    for g in model.shell_groups:
        mat = g.mat.copy()
        mat[:, SMAT_GM] = 0.0
        mat[:, SMAT_GS] = 0.0
        mat.setflags(write=False)
        groups.append(dataclasses.replace(g, mat=mat))
    return dataclasses.replace(model, shell_groups=tuple(groups))
