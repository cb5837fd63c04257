"""Outputs of ``flexmb bench``: per case a CSV, a JSON of run facts and a PNG; one markdown report
rendered from every case file present in the output directory (so ``--case b1`` refreshes B1's part
and keeps the others).

matplotlib (extra ``bench``) is imported inside :func:`write_png` only.
"""

from __future__ import annotations

import csv
import json
import math
import re
from pathlib import Path

from . import core

CASE_ORDER = ("b1", "spin_up", "stewart")
NUMERIC = {"elements", "order", "rho_inf", "dt", "sim_time_s", "steps", "t_reached_s", "repeats", "wall_s",
           "wall_min_s", "substepped_steps",
           "wall_per_sim_s", "rtf", "steps_per_s", "newton_iterations_mean", "error", "error_final",
           "error_closed_form", "error_orientation_rad"}
PEER_STYLE = {"exudyn": ("s", "0.15"), "mujoco": ("D", "tab:red"), "pyelastica": ("^", "tab:purple")}


def _used(meta: dict) -> str:
    """How many runs went at once (``flexmb bench --workers N``; files from before issue 17: one)."""
    n = meta.get("workers", 1)
    return "one used" if n == 1 else f"up to {n} runs at a time on Dask workers"


def csv_path(out: Path, case: str) -> Path:
    return out / f"workprecision_{case}.csv"


def write_csv(path: Path, rows: list[dict]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=core.COLUMNS)
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) and k != "dt" else v) for k, v in r.items()})


def read_csv(path: Path) -> list[dict]:
    """Rows of :func:`write_csv`, numbers parsed (empty → NaN), ``completed`` as bool."""
    rows = []
    with path.open() as f:
        for r in csv.DictReader(f):
            for k in NUMERIC:
                r[k] = float(r[k]) if r.get(k) not in (None, "") else math.nan
            r["completed"] = r["completed"] == "True"
            rows.append(r)
    return rows


def is_flexmb(r: dict) -> bool:
    return r["code"] == "flexmb"


def _num(x: float, spec: str = ".2e") -> str:
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)


# -- ratios at equal error ----------------------------------------------------------------------
def cheapest(rows: list[dict], column: str, tol: float) -> dict | None:
    """The completed row with the least wall time per simulated second among those with
    ``column`` ≤ ``tol``."""
    ok = [r for r in rows if r["completed"] and r[column] <= tol and not math.isnan(r["wall_per_sim_s"])]
    return min(ok, key=lambda r: r["wall_per_sim_s"]) if ok else None


def equal_error_table(rows: list[dict], column: str, tolerances: tuple[float, ...], unit: str) -> list[str]:
    """Markdown lines: per tolerance, flexmb's cheapest run and each peer's, and the speed ratio."""
    peers = sorted({r["code"] for r in rows if not is_flexmb(r)})
    if not peers:
        return []
    lines = [f"| {column} ≤ | flexmb cheapest (wall/sim-s, RTF) | " + " | ".join(
        f"{p} cheapest (wall/sim-s) | flexmb speed-up vs {p.split()[0]}" for p in peers) + " |",
        "|---|---|" + "---|---|" * len(peers)]
    own = [r for r in rows if is_flexmb(r)]
    for tol in tolerances:
        f = cheapest(own, column, tol)
        cells = [f"{tol:g}{unit}",
                 "none" if f is None else f"{f['family']}, Δt {f['dt']:g}: {f['wall_per_sim_s']:.3g} s/s, RTF {f['rtf']:.3g}"]
        for p in peers:
            g = cheapest([r for r in rows if r["code"] == p], column, tol)
            cells.append("none" if g is None else f"{g['family']}, Δt {g['dt']:g}: {g['wall_per_sim_s']:.3g} s/s")
            if f is None or g is None:
                cells.append("–")
            else:
                cells.append(f"**{g['wall_per_sim_s'] / f['wall_per_sim_s']:.2g}×**")
        lines.append("| " + " | ".join(cells) + " |")
    return lines


# -- the plot -----------------------------------------------------------------------------------
def _series(r: dict) -> tuple[str, str]:
    """The line a row belongs to: a flexmb family (Δt varies along it); for a peer with a mesh, its
    family without the element count at one Δt (the mesh varies along it), else its family."""
    if r["code"] == "flexmb" or not r["elements"] or math.isnan(r["elements"]):
        return r["code"], r["family"]
    fam = re.sub(r",? ?\d+ el\.(/leg)?", "", r["family"])
    return r["code"], f"{fam}, Δt {r['dt'] * 1e3:.3g} ms"


def _point_label(r: dict) -> str:
    """Δt (ms) on a flexmb point; the element count on a peer's mesh line."""
    if r["code"] == "flexmb" or not r["elements"] or math.isnan(r["elements"]):
        return f"{r['dt'] * 1e3:.3g}"
    return f"{r['elements']:.0f} el"


def write_png(path: Path, rows: list[dict], panels: list[tuple[str, str]],
              target: tuple[float, str] | None) -> bool:
    """Work-precision diagram(s): ``panels`` = [(column, y label)]; one line per flexmb family (Δt
    varies along it) and per peer model and Δt (the mesh varies along it), peers dashed in
    black/red/purple; failed runs listed in the legend. False without matplotlib."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    series: dict[tuple[str, str], list[dict]] = {}
    for r in rows:
        series.setdefault(_series(r), []).append(r)
    fig, axes = plt.subplots(1, len(panels), figsize=(7.5 * len(panels) + 3.5, 6.0), squeeze=False)
    cmap = plt.get_cmap("tab20")
    n_own = sum(1 for code, _ in series if code == "flexmb")
    for ax, (column, ylabel) in zip(axes[0], panels):
        ci = 0
        for (code, label), rs in series.items():
            own = code == "flexmb"
            rs = sorted(rs, key=(lambda r: -r["dt"]) if own else (lambda r: (r["elements"], -r["dt"])))
            ok = [r for r in rs if r["completed"] and not math.isnan(r[column])]
            failed = [r for r in rs if not r["completed"]]
            if failed:
                label += "  — failed: " + ", ".join(_point_label(r) for r in failed)
            if own:
                style = dict(marker="o", color=cmap(ci % 20), ls="-", ms=5)
                ci += 1
            else:
                mk, color = PEER_STYLE.get(code.split()[0], ("v", "k"))
                style = dict(marker=mk, color=color, ls="--", ms=6, mfc="none")
            if ok:
                ax.loglog([r["wall_per_sim_s"] for r in ok], [r[column] for r in ok], label=label, **style)
                if not own or n_own < 12 or ci == 1:
                    for r in ok:
                        ax.annotate(_point_label(r), (r["wall_per_sim_s"], r[column]), fontsize=6,
                                    xytext=(3, 2), textcoords="offset points", color=style["color"])
            elif failed:
                ax.plot([], [], label=label, **style)
        ax.axvline(1.0, color="k", lw=0.8, ls="--")
        ax.axvline(0.05, color="g", lw=0.8, ls=":")
        if target is not None:
            ax.axhline(target[0], color="r", lw=0.8, ls=":")
        ylo = ax.get_ylim()[0]
        ax.text(1.0, ylo, " real time", fontsize=7, va="bottom")
        ax.text(0.05, ylo, " RTF 20", fontsize=7, va="bottom", color="g")
        if target is not None:
            ax.text(ax.get_xlim()[0], target[0], f" {target[1]}", fontsize=7, va="bottom", color="r")
        ax.set_xlabel("wall time per simulated second (s/s) = 1/RTF")
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].set_title("labels on points: Δt (ms) for flexmb (one line per family); element count on a "
                         "peer's mesh line", fontsize=8, loc="left")
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="center right", fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0, 1.0 - 3.4 / fig.get_figwidth(), 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


# -- markdown -----------------------------------------------------------------------------------
def case_table(rows: list[dict], columns: list[tuple[str, str]]) -> list[str]:
    head = ["code", "family", "Δt (s)", "steps/s", "RTF", "wall/sim-s", "Newton it./step"] + [c[1] for c in columns] + ["note"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        note = r["note"] if r["completed"] else f"**failed** at t = {r['t_reached_s']:.4g} s: {r['note']}"
        note = note.replace("|", "/").replace("\n", " ")
        if len(note) > 160:
            note = note[:157] + "…"
        lines.append("| " + " | ".join([r["code"], r["family"], f"{r['dt']:g}", _num(r["steps_per_s"], ".0f"),
                                          _num(r["rtf"], ".3g"), _num(r["wall_per_sim_s"], ".3g"),
                                          _num(r["newton_iterations_mean"], ".2f")]
                                         + [_num(r[c[0]]) for c in columns] + [note]) + " |")
    return lines


def write_json(path: Path, meta: dict) -> None:
    path.write_text(json.dumps(meta, indent=2, default=str) + "\n")


def write_markdown(out: Path, cases: dict) -> Path:
    """``workprecision.md`` from every ``workprecision_<case>.csv`` / ``.json`` in ``out``.

    ``cases`` maps case name → its module (TITLE, ERROR_MEASURE, ERROR_UNIT, ``report_spec()``).
    """
    lines = ["# Work-precision: error against wall time per simulated second", "",
             "Generated by `flexmb bench` (`benchmarks/workprecision/`); each case's section comes from "
             "`workprecision_<case>.csv` (every run, all columns) and `workprecision_<case>.json` (run facts). "
             "Wall time = `Simulator.run` (or the peer's stepping loop) only, JIT warm-up and initialization "
             "excluded, median of the repeats; the machine is shared, so compare **ratios within one case** "
             "(one run of `flexmb bench`), not absolute numbers across runs. A failed run is listed with the "
             "solver's message, never dropped. Lines connect the Δt values of one family; dashed lines are peers.", ""]
    for name in CASE_ORDER:
        if name not in cases or not csv_path(out, name).exists():
            continue
        mod = cases[name]
        rows = read_csv(csv_path(out, name))
        meta_path = out / f"workprecision_{name}.json"
        meta = json.loads(meta_path.read_text()) if meta_path.exists() else {}
        spec = mod.report_spec()
        lines += [f"## {mod.TITLE}", ""]
        m = meta.get("machine", {})
        lines.append(f"Run {meta.get('date', '?')}{' (--quick)' if meta.get('quick') else ''}, commit "
                     f"{m.get('commit', '?')}, {m.get('cpu', '?')}, {m.get('cpus', '?')} cores ({_used(meta)}), 1-min load "
                     f"average {meta.get('load_start', '?')} at start, {meta.get('load_end', '?')} at end; "
                     f"{meta.get('runtime_s', 0):.0f} s. Simulated time {meta.get('sim_time_s', '?')} s.")
        lines += ["", f"**error** = {mod.ERROR_MEASURE}. {spec['errors']}", ""]
        if meta.get("reference"):
            lines += [f"Reference: `{meta['reference'].get('file', '')}` — {meta['reference'].get('model', '')}.", ""]
        for note in meta.get("notes", []):
            lines.append(f"- {note}")
        if meta.get("notes"):
            lines.append("")
        png = out / f"workprecision_{name}.png"
        if png.exists():
            lines += [f"![{mod.TITLE}](workprecision_{name}.png)", ""]
        for column, tols, unit, *dt in spec["ratios"]:
            sel = rows if not dt else [r for r in rows if abs(r["dt"] - dt[0]) < 1e-12]
            t = equal_error_table(sel, column, tols, unit)
            if t:
                at = "" if not dt else f", runs at Δt = {dt[0]:g} s only"
                lines += [f"Equal-error comparison on `{column}`{at} (cheapest run of each code whose {column} is "
                          f"within the bound; speed-up = peer wall time / flexmb wall time, same run):", ""] + t + [""]
        lines += case_table(rows, spec["columns"]) + [""]
        lines += spec.get("reading", [])
    path = out / "workprecision.md"
    path.write_text("\n".join(lines) + "\n")
    return path
