#!/usr/bin/env python3
"""Draws a specbake sweep: error against bake time on log axes (sweep_plot.py SWEEP.json OUT.png).

`specbake sweep` writes this script next to sweep.json and runs it; run it again to redraw.
One marker per measured point, labelled with its --vary values (in the title's key order); the Pareto front (no other point
is both faster and more accurate) in red and joined, the other points in blue; the tolerance,
when there is one, as a dashed green line. Failed points are listed under the axes.
The figure is 1200 x 825 pixels (8 x 5.5 in at 150 dpi).
"""
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

FRONT, OTHER, FRONT_LINE, TOLERANCE = "#d62728", "#1f77b4", "#ff9896", "#2ca02c"
WIDTH_IN, HEIGHT_IN, DPI = 8.0, 5.5, 150


def label(point, keys):
    """The point's values in the order of the title's keys ("7, chebyshev")."""
    return ", ".join(str(point["values"][k]) for k in keys)


def main(src, dst):
    with open(src) as f:
        sweep = json.load(f)
    keys = [v["key"] for v in sweep["varies"]]
    measured = [p for p in sweep["points"] if p["status"] == "measured"]
    failed = [p for p in sweep["points"] if p["status"] != "measured"]

    fig, ax = plt.subplots(figsize=(WIDTH_IN, HEIGHT_IN), dpi=DPI)
    floor = 1e-300  # a zero error or time cannot sit on a log axis; it is drawn at the axis' floor
    xs = [max(p["bake_s"], 1e-3) for p in measured]
    ys = [max(p["error"], floor) for p in measured]
    front = sorted((x, y) for x, y, p in zip(xs, ys, measured) if p["pareto"])
    if len(front) > 1:
        ax.step([x for x, _ in front], [y for _, y in front], where="post", color=FRONT_LINE, lw=1.5, zorder=1,
                label="Pareto front")
    for x, y, p in zip(xs, ys, measured):
        colour = FRONT if p["pareto"] else OTHER
        ax.plot([x], [y], "o", ms=7, color=colour, mec=colour, zorder=3)
        ax.annotate(label(p, keys), (x, y), textcoords="offset points", xytext=(7, 6), fontsize=7, zorder=4)
    ax.plot([], [], "o", color=FRONT, label="on the front")
    ax.plot([], [], "o", color=OTHER, label="dominated")
    tolerances = {p["tolerance"] for p in measured if p.get("tolerance") is not None}
    for t in sorted(tolerances):
        ax.axhline(t, color=TOLERANCE, ls="--", lw=1.2, zorder=2, label=f"tolerance {t:g}")
    ax.margins(x=0.12, y=0.08)
    ax.set_xscale("log")
    ax.set_yscale("log")
    unit = measured[0]["unit"] if measured and measured[0].get("unit") else ""
    record = measured[0]["record"] if measured else "error"
    ax.set_xlabel("bake time without the check (s, wall)")
    metric = measured[0].get("metric", "") if measured else ""
    ax.set_ylabel(record + (f" ({unit})" if unit else ""))
    ax.set_title(f"{sweep['job']} ({sweep['kind']}): points labelled " + ", ".join(keys) +
                 (f"\n{record}: {metric[:110]}" if metric else ""), fontsize=9)
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    ax.legend(fontsize=7, loc="best")
    if failed:
        lines = [f"failed: {label(p, keys)}: {p.get('reason', '')[:90]}" for p in failed[:4]]
        if len(failed) > 4:
            lines.append(f"... and {len(failed) - 4} more (sweep.json)")
        fig.text(0.01, 0.005, "\n".join(lines), fontsize=6, va="bottom")
    fig.subplots_adjust(bottom=0.12 + 0.02 * min(len(failed), 5))
    fig.savefig(dst, dpi=DPI)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: sweep_plot.py SWEEP.json OUT.png")
    main(sys.argv[1], sys.argv[2])
