"""
Summary of a sweep's results.

Statistics per output, parameters ranked by correlation, a tornado plot and histograms (PNG, Agg
backend).

Per output, over the designs that solved and gave a value: count, mean, sample standard
deviation (ddof 1), 1st and 99th percentiles (numpy's linear interpolation), min, max, and
for each parameter the Pearson correlation coefficient r with the output, ranked by |r|
(parameters that do not vary have none).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from flexure_sim.engine.analysis.study import Study
from flexure_sim.tools.design.sweep_outputs import OK, columns


def correlation(x: np.ndarray, y: np.ndarray) -> float:
    """Pearson's r = cov(x, y) / (std(x) std(y)); NaN if either does not vary."""
    dx, dy = x - x.mean(), y - y.mean()
    den = np.sqrt(np.sum(dx * dx) * np.sum(dy * dy))
    return float(np.sum(dx * dy) / den) if den > 0 else float("nan")


def _ok(table: pa.Table) -> np.ndarray:
    """Return which designs solved, as a bool array (no Python string per row)."""
    return pc.equal(table.column("status"), OK).to_numpy(zero_copy_only=False)


def summarize(table: pa.Table, study: Study) -> dict:
    """
    Return the summary of a study's results.

    {"designs", "failed", "errors" (the most common messages), "outputs": {column: stats}}, per
    output column (``sweep_outputs.columns``).
    """
    ok = _ok(table)
    failed = pc.value_counts(table.column("error").filter(pa.array(~ok)))
    errors = {e["values"].as_py(): e["counts"].as_py() for e in failed}
    params = {p.name: table.column(p.name).to_numpy() for p in study.parameters}
    outputs = {}
    for column in columns(study):
        name = column.name
        y = table.column(name).to_numpy()
        valid = ok & np.isfinite(y)
        v = y[valid]
        stats: dict = {"unit": column.unit, "count": int(valid.sum())}
        if v.size:
            stats.update(mean=float(v.mean()), std=float(v.std(ddof=1)) if v.size > 1 else 0.0,
                         p01=float(np.percentile(v, 1)), p99=float(np.percentile(v, 99)),
                         min=float(v.min()), max=float(v.max()))
            ranks = [(p, correlation(x[valid], v)) for p, x in params.items()]
            ranks = [(p, r) for p, r in ranks if np.isfinite(r)]
            ranks.sort(key=lambda pr: -abs(pr[1]))
            stats["correlation"] = [{"parameter": p, "r": r} for p, r in ranks]
        outputs[name] = stats
    top = sorted(errors.items(), key=lambda kv: -kv[1])[:5]
    return {"designs": len(table), "failed": int((~ok).sum()),
            "errors": [{"error": e, "count": c} for e, c in top], "outputs": outputs}


def print_summary(result: dict, study: Study) -> None:
    print(f"study {study.name}: {result['designs']} designs "
          f"({'Monte Carlo, seed ' + str(study.seed) if study.monte_carlo else 'grid'}), "
          f"{result['failed']} failed; {result['computed']} computed in {result['wall_s']:.1f} s "
          f"({result['designs_per_s']:.0f} designs/s)"
          + (f", {result['resumed']} resumed" if result["resumed"] else ""))
    print(f"results: {result['output']}")
    for name, s in result["outputs"].items():
        unit = f" {s['unit']}" if s["unit"] else ""
        if not s["count"]:
            print(f"\n{name}: no values")
            continue
        print(f"\n{name}{unit}: mean {s['mean']:.6g}, std {s['std']:.4g}, 1st-99th percentile "
              f"{s['p01']:.6g} .. {s['p99']:.6g}  ({s['count']} values)")
        for c in s.get("correlation", [])[:10]:
            print(f"  r = {c['r']:+.3f}  {c['parameter']}")
    for e in result.get("errors", []):
        print(f"failed x{e['count']}: {e['error']}")
    if result["plots"]:
        print("\nplots: " + ", ".join(result["plots"]))


def plot(table: pa.Table, study: Study, summary: dict, output: Path) -> list[Path]:
    """
    Write ``<output stem>_tornado.png`` and ``<output stem>_histograms.png``.

    The tornado shows r of each parameter, per output. Returns the paths written.
    """
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    names = [n for n, s in summary["outputs"].items() if s["count"]]
    if not names:
        return []
    ok = _ok(table)
    paths = []
    top = 12
    # Per output: its title, x tick labels and gaps (0.9 in) and 0.3 in per bar; the figure's
    # title and x label 0.9 in. (Sized by the bars alone, one parameter and a few outputs left
    # no room for the titles: matplotlib's "Tight layout not applied".) Constrained layout
    # keeps the figure's title clear of the first axes' title in a tall figure.
    height = 0.9 + (0.9 + 0.3 * min(top, len(study.parameters))) * len(names)
    fig, axes = plt.subplots(len(names), 1, figsize=(7, height), squeeze=False,
                             layout="constrained")
    for ax, name in zip(axes[:, 0], names):
        ranks = summary["outputs"][name].get("correlation", [])[:top][::-1]
        r = [c["r"] for c in ranks]
        ax.barh([c["parameter"] for c in ranks], r, color=["C3" if v < 0 else "C0" for v in r])
        ax.set_xlim(-1, 1)
        ax.axvline(0, color="k", lw=0.8)
        ax.set_title(f"{name}: correlation with each parameter", fontsize=10)
        ax.tick_params(axis="y", labelsize=8)
    axes[-1, 0].set_xlabel("Pearson r")
    paths.append(_save(fig, output, "tornado", f"{study.name}: tornado (parameter correlations)"))
    plt.close(fig)

    cols = min(3, len(names))
    rows = -(-len(names) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False,
                             layout="constrained")
    for ax in axes.ravel()[len(names):]:
        ax.set_visible(False)
    for ax, name in zip(axes.ravel(), names):
        y = table.column(name).to_numpy()
        y = y[ok & np.isfinite(y)]
        s = summary["outputs"][name]
        ax.hist(y, bins=min(60, max(10, int(np.sqrt(y.size)))), color="C0")
        for v, style in ((s["mean"], "-"), (s["p01"], "--"), (s["p99"], "--")):
            ax.axvline(v, color="C3", ls=style, lw=1)
        unit = f" [{s['unit']}]" if s["unit"] else ""
        ax.set_xlabel(f"{name}{unit}")
        ax.set_title(f"mean {s['mean']:.5g}, std {s['std']:.3g}", fontsize=9)
        ax.ticklabel_format(axis="x", style="sci", scilimits=(-3, 4), useOffset=False)
    axes[0, 0].set_ylabel("designs")
    paths.append(_save(fig, output, "histograms",
                       f"{study.name}: histograms (mean, 1st/99th percentile)"))
    plt.close(fig)
    return paths


def _save(fig, output: Path, what: str, title: str) -> Path:
    fig.suptitle(title, fontsize=11)
    path = output.with_name(f"{output.stem}_{what}.png")
    fig.savefig(path, dpi=110, metadata={"Title": title, "Software": "flexure_sim"})
    return path
