"""Factor + solve time of SkylineLU (envelope LU, fixed pattern) against scipy's splu.

Patterns: synthetic chains of dense 36×36 element blocks sharing 9 DOFs (randomly numbered),
a synthetic Stewart-like pattern (6 legs, 2 per platform vertex, platform triangle), and — when the
scene compiler is importable — real Stewart-platform tangents ``K + 4/Δt² M`` (Δt = 1 ms) with
1–8 cubic frame elements per leg and the tangents of the shipped ``scenes/*.yaml``. Medians over many repetitions, single-threaded BLAS.

    .venv/bin/python benchmarks/bench_linear_solvers.py [--repeats 400] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("NUMBA_CACHE_DIR", str(ROOT / ".cache" / "numba"))

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from scipy.sparse.linalg import splu  # noqa: E402

from flexmb_core.solvers.banded import SkylineLU  # noqa: E402

NODE_DOFS, ELEMENT_NODES = 9, 4


def _synthetic(chains, n_nodes, seed=0):
    """chains: list of element node lists → (n, CSR matrix with SPD element blocks)."""
    rng = np.random.default_rng(seed)
    n = n_nodes * NODE_DOFS
    numbering = rng.permutation(n)
    rows, cols, vals = [], [], []
    for el in chains:
        d = numbering[(NODE_DOFS * np.asarray(el)[:, None] + np.arange(NODE_DOFS)).ravel()]
        r = rng.standard_normal((d.size, d.size))
        rows.append(np.repeat(d, d.size))
        cols.append(np.tile(d, d.size))
        vals.append((r @ r.T / d.size + 0.1 * np.eye(d.size)).ravel())
    a = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    a.sum_duplicates()
    a.sort_indices()
    return n, a


def _chain_elements(count, start, end, n_el):
    els, cur = [], start
    for e in range(n_el):
        el = [cur] + list(range(count, count + ELEMENT_NODES - 2))
        count += ELEMENT_NODES - 2
        if e == n_el - 1 and end is not None:
            el.append(end)
        else:
            el.append(count)
            count += 1
        els.append(el)
        cur = el[-1]
    return els, count


def synthetic_chain(n_el):
    els, count = _chain_elements(1, 0, None, n_el)
    return _synthetic(els, count)


def synthetic_stewart(leg_el, plat_el):
    count, els = 3, []
    for leg in range(6):
        e, count = _chain_elements(count + 1, count, leg // 2, leg_el)
        els += e
    for a, b in ((0, 1), (1, 2), (2, 0)):
        e, count = _chain_elements(count, a, b, plat_el)
        els += e
    return _synthetic(els, count)


def stewart_scene(leg_elements):
    """Real flexmb Stewart tangent (K at the reference configuration + 4/Δt² M, Δt = 1 ms)."""
    from flexmb_core.model.assembly import assemble
    from flexmb_core.model.compile import compile_scene
    from flexmb_core.model.workspace import State, Workspace
    from flexmb_core.scene import scene_from_dict

    nodes, members = {}, {}
    for k, name in enumerate("ABC"):
        a = math.pi / 2 + 2 * math.pi * k / 3
        nodes[name] = [0.5 * math.cos(a), 0.5 * math.sin(a), 1.0]
    for i in range(6):
        a = math.pi / 2 + 2 * math.pi * (i // 2) / 3 + math.pi / 3 + (0.35 if i % 2 else -0.35)
        nodes[f"b{i + 1}"] = [math.cos(a), math.sin(a), 0.0]
        members[f"leg{i + 1}"] = {"kind": "actuator", "from": f"b{i + 1}", "to": "ABC"[i // 2],
                                  "elements": leg_elements, "order": 3, "material": "steel",
                                  "section": "act", "actuator": {"variant": "frame"}}
    for a, b in ("AB", "BC", "CA"):
        members[f"p{a}{b}"] = {"kind": "frame", "from": a, "to": b, "elements": 1, "order": 3,
                               "material": "steel", "section": "plat", "up": [0, 0, 1]}
    d = {"name": "stewart_bench", "materials": {"steel": {"E": 2.1e11, "nu": 0.3, "rho": 7850.0}},
         "sections": {"act": {"shape": "tube", "outer_radius": 0.02, "thickness": 0.003},
                      "plat": {"shape": "rectangle", "width": 0.05, "height": 0.05}},
         "nodes": nodes, "members": members,
         "supports": [{"node": f"b{i + 1}", "type": "ball"} for i in range(6)],
         "loads": {}, "solver": {"analysis": "dynamic", "dt": 1e-3, "until": 0.01}, "outputs": {}}
    model = compile_scene(scene_from_dict(d, source="<bench>"))
    ws, st = Workspace(model), State.at_rest(model)
    assemble(model, ws, st.q, st.lam, True)
    data = np.ascontiguousarray(ws.kdata + model.mass_kdata / (0.25 * 1e-3 ** 2))
    return model.nfree, sp.csr_matrix((data, model.indices, model.indptr), shape=(model.nfree,) * 2)


def shipped_scene(path):
    """Tangent of a shipped scene at its reference configuration + 4/Δt² M (Δt = 1 ms)."""
    from flexmb_core.model.assembly import assemble
    from flexmb_core.model.compile import compile_scene
    from flexmb_core.model.workspace import State, Workspace
    from flexmb_core.scene import load_scene

    model = compile_scene(load_scene(path))
    ws, st = Workspace(model), State.at_rest(model)
    assemble(model, ws, st.q, st.lam, True)
    data = np.ascontiguousarray(ws.kdata + model.mass_kdata / (0.25 * 1e-3 ** 2))
    return model.nfree, sp.csr_matrix((data, model.indices, model.indptr), shape=(model.nfree,) * 2)


def _median_us(fn, repeats):
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e6 * statistics.median(times)


def bench(name, n, a, repeats):
    b = np.random.default_rng(1).standard_normal(n)
    t0 = time.perf_counter()
    lu = SkylineLU(n, a.indptr, a.indices)
    setup_ms = 1e3 * (time.perf_counter() - t0)
    x = np.empty(n)
    a_t = sp.csc_matrix((a.data, a.indices, a.indptr), shape=(n, n))   # CSR of A = CSC of Aᵀ (no copy)

    def sky_both():
        lu.factor(a.data)
        lu.solve(b, out=x)

    def splu_both():
        splu(a_t).solve(b, trans="T")

    row = {
        "case": name, "n": n, "nnz": int(a.nnz), "ordering": lu.ordering_name,
        "bandwidth": lu.bandwidth, "factor_fma": lu.factor_fma, "setup_ms": setup_ms,
        "sky_factor_us": _median_us(lambda: lu.factor(a.data), repeats),
        "sky_solve_us": _median_us(lambda: lu.solve(b, out=x), repeats),
        "sky_total_us": _median_us(sky_both, repeats),
        "splu_total_us": _median_us(splu_both, max(repeats // 4, 20)),
    }
    lu.factor(a.data)
    ref = splu(a_t).solve(b, trans="T")
    row["rel_err"] = float(np.linalg.norm(lu.solve(b) - ref) / np.linalg.norm(ref))
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=400)
    ap.add_argument("--json", type=Path, default=None, help="also write the rows to this file")
    args = ap.parse_args(argv)

    cases = [("chain 8 el", *synthetic_chain(8)), ("chain 16 el", *synthetic_chain(16)),
             ("chain 37 el", *synthetic_chain(37)), ("chain 111 el", *synthetic_chain(111)),
             ("stewart-like 6x3+3x2 el", *synthetic_stewart(3, 2)),
             ("stewart-like 6x8+3x3 el", *synthetic_stewart(8, 3))]
    try:
        for le in (1, 2, 4, 8):
            cases.append((f"flexmb stewart {le} el/leg", *stewart_scene(le)))
        for path in sorted((ROOT / "scenes").glob("*.yaml")):
            cases.append((f"scene {path.stem}", *shipped_scene(path)))
    except Exception as exc:   # the scene compiler is optional here
        print(f"(flexmb scenes skipped: {type(exc).__name__}: {exc})")

    SkylineLU(2, [0, 2, 4], [0, 1, 0, 1]).factor(np.array([2.0, 1.0, 1.0, 2.0]))   # JIT / cache load
    head = (f"{'case':28s} {'n':>5s} {'ordering':>22s} {'bw':>5s} {'MFMA':>6s} {'factor':>8s} "
            f"{'solve':>7s} {'f+s':>8s} {'splu f+s':>9s} {'speed-up':>8s} {'rel.err':>8s} {'setup':>7s}")
    print(head + "\n" + "-" * len(head))
    rows = []
    for name, n, a in cases:
        r = bench(name, n, a, args.repeats)
        rows.append(r)
        print(f"{name:28s} {n:5d} {r['ordering']:>22s} {r['bandwidth']:5d} {r['factor_fma'] / 1e6:6.2f} "
              f"{r['sky_factor_us']:7.1f}µ {r['sky_solve_us']:6.1f}µ {r['sky_total_us']:7.1f}µ "
              f"{r['splu_total_us']:8.1f}µ {r['splu_total_us'] / r['sky_total_us']:7.1f}× "
              f"{r['rel_err']:8.1e} {r['setup_ms']:5.1f}ms", flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
