"""``sweep.png``: every chosen output part against every parameter (max ▲, RMS ●, min ▼ over
time; one row of panels per part, one column per parameter; failed runs left out)."""

from __future__ import annotations

import math
from pathlib import Path

MAX_PARTS = 24                     # rows of panels; a whole shape would be unreadable anyway


def plot_sweep(path: Path, records: list[dict], param_keys: list[str]) -> Path | None:
    """Write the figure; None when matplotlib is not installed."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        return None
    ok = [r for r in records if r.get("ok")]
    parts = list(dict.fromkeys(k[4:] for r in ok for k in r if k.startswith("max.")))[:MAX_PARTS]
    nrow, ncol = max(1, len(parts)), max(1, len(param_keys))
    fig = Figure(figsize=(3.2 * ncol + 0.6, 2.1 * nrow + 0.6), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrow, ncol, squeeze=False)
    if not ok or not parts or not param_keys:
        axes[0][0].text(0.5, 0.5, "no completed run to plot", ha="center", va="center")
        axes[0][0].set_axis_off()
    for j, key in enumerate(param_keys):
        xs, ticks = _positions([r.get(key) for r in ok])
        for i, part in enumerate(parts):
            ax = axes[i][j]
            for stat, marker in (("max", "^"), ("rms", "o"), ("min", "v")):
                ys = [r.get(f"{stat}.{part}", math.nan) for r in ok]
                ax.plot(xs, [math.nan if y is None else y for y in ys], marker, ms=4, ls="none", label=stat)
            if ticks:
                ax.set_xticks(range(len(ticks)), ticks, fontsize=7)
            else:
                ax.locator_params(axis="x", nbins=4)
            ax.tick_params(labelsize=7)
            if i == nrow - 1:
                ax.set_xlabel(key, fontsize=8)
            if j == 0:
                ax.set_ylabel(part, fontsize=8)
    if ok and parts and param_keys:
        axes[0][0].legend(fontsize=7, loc="best")
    fail = len(records) - len(ok)
    fig.suptitle(f"{len(ok)} completed runs" + (f" ({fail} failed, not shown)" if fail else ""), fontsize=9)
    fig.savefig(path, dpi=90)
    return path


def _positions(values: list) -> tuple[list[float], list[str]]:
    """x positions: the values when all are numbers, else category indices (with tick labels)."""
    if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
        return [float(v) for v in values], []
    labels = list(dict.fromkeys(str(v) for v in values))
    return [float(labels.index(str(v))) for v in values], labels
