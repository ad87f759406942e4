#!/usr/bin/env python3
"""Draws a specbake sweep: error against two costs, bake time and bundle size, on log axes
(sweep_plot.py SWEEP.json OUT.png).

`specbake sweep` writes this script next to sweep.json and runs it; run it again to redraw.
Left: error against bake time; right: the same errors against the bundle's size (its files as the
bake made them), the y axis shared. One marker per measured point, labelled with its --vary values
(in the title's key order), each label placed where it overlaps no other label or marker when
such a place is near; the Pareto front in time (no other point is both faster and more accurate)
in red and joined on the left, the other points in blue; the tolerance, when there is one, as a
dashed green line. Where the ground truth is itself an estimate with a standard error (the
atmosphere's path-traced scene check records `details.standard_error`), grey error bars show it:
± the p99 over the scene's points of the error the truth's standard error alone makes, in the
record's own measure (CIEDE2000 for a CIEDE2000 record, else relative). Failed points are listed
under the axes. The figure is 1200 x 825 pixels (8 x 5.5 in at 150 dpi).
"""
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib import ticker  # noqa: E402

FRONT, OTHER, FRONT_LINE, TOLERANCE, BARS = "#d62728", "#1f77b4", "#ff9896", "#2ca02c", "#7f7f7f"
WIDTH_IN, HEIGHT_IN, DPI = 8.0, 5.5, 150
# label offsets tried in order (points from the marker's centre)
OFFSETS = [(7, 6), (7, -13), (-9, 6), (-9, -13), (7, 16), (-9, 16), (7, -23), (-9, -23), (0, 26), (0, -33)]


def label(point, keys):
    """The point's values in the order of the title's keys ("7, chebyshev")."""
    return ", ".join(str(point["values"][k]) for k in keys)


def truth_se(point):
    """± the truth's own error in the record's measure, or None where the truth is exact."""
    for a in point.get("accuracy", []):
        if a.get("name") != point.get("record"):
            continue
        se = (a.get("details") or {}).get("standard_error")
        if not isinstance(se, dict):
            return None
        measure = se.get("de2000" if "CIEDE2000" in (point.get("unit") or "") else "relative")
        if isinstance(measure, dict) and isinstance(measure.get("p99"), (int, float)):
            return measure["p99"]
    return None


def place_labels(fig, ax, xs, ys, texts):
    """Each label at the first offset whose box overlaps no placed label and no marker."""
    renderer = fig.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    markers = [ax.transData.transform((x, y)) for x, y in zip(xs, ys)]
    taken = []
    for (x, y), text, (mx, my) in zip(zip(xs, ys), texts, markers):
        chosen = None
        for dx, dy in OFFSETS:
            ann = ax.annotate(text, (x, y), textcoords="offset points", xytext=(dx, dy), fontsize=7, zorder=4,
                              ha="left" if dx >= 0 else "right")
            box = ann.get_window_extent(renderer).expanded(1.05, 1.1)
            hits_marker = any(box.x0 - 4 <= px <= box.x1 + 4 and box.y0 - 4 <= py <= box.y1 + 4
                              for px, py in markers)
            inside = frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1
            if inside and not hits_marker and not any(box.overlaps(t) for t in taken):
                chosen = (ann, box)
                break
            ann.remove()
        if chosen is None:  # crowded: the first place, drawn anyway
            dx, dy = OFFSETS[0]
            ann = ax.annotate(text, (x, y), textcoords="offset points", xytext=(dx, dy), fontsize=7, zorder=4)
            chosen = (ann, ann.get_window_extent(renderer))
        taken.append(chosen[1])


def panel(ax, xs, ys, measured, errs, front_line):
    if front_line:
        front = sorted((x, y) for x, y, p in zip(xs, ys, measured) if p["pareto"])
        if len(front) > 1:
            ax.step([x for x, _ in front], [y for _, y in front], where="post", color=FRONT_LINE, lw=1.5, zorder=1,
                    label="Pareto front (time)")
    for x, y, p, e in zip(xs, ys, measured, errs):
        if e:
            ax.errorbar([x], [y], yerr=[[min(e, y * 0.999)], [e]], fmt="none", ecolor=BARS, elinewidth=1, capsize=3,
                        zorder=2)
        spread = p.get("bake_s_spread")
        if front_line and spread and p.get("runs", 1) > 1 and spread[1] > spread[0]:
            # the fastest run is the point; the bar reaches the slowest of its repeats
            ax.errorbar([x], [y], xerr=[[0], [max(spread[1] - x, 0)]], fmt="none", ecolor=BARS, elinewidth=1,
                        capsize=2, zorder=2)
    for x, y, p in zip(xs, ys, measured):
        colour = FRONT if p["pareto"] else OTHER
        ax.plot([x], [y], "o", ms=7, color=colour, mec=colour, zorder=3)
    tolerances = {p["tolerance"] for p in measured if p.get("tolerance") is not None}
    for t in sorted(tolerances):
        ax.axhline(t, color=TOLERANCE, ls="--", lw=1.2, zorder=2, label=f"tolerance {t:g}")
    ax.margins(x=0.15, y=0.1)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    plain_log_ticks(ax.xaxis, ax.get_xlim)
    plain_log_ticks(ax.yaxis, ax.get_ylim)


def plain_log_ticks(axis, limits):
    """Plain numbers ("0.5", "20") on a log axis; over less than ~1.5 decades the minor ticks at 2, 3,
    5 and 7 are labelled too (else such an axis shows one number or none), the others never."""
    axis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))

    def minor(v, _):
        lo, hi = limits()
        return f"{v:g}" if hi / lo < 30 and f"{v:.0e}"[0] in "2357" else ""
    axis.set_minor_formatter(ticker.FuncFormatter(minor))

def main(src, dst):
    with open(src) as f:
        sweep = json.load(f)
    keys = [v["key"] for v in sweep["varies"]]
    measured = [p for p in sweep["points"] if p["status"] == "measured"]
    failed = [p for p in sweep["points"] if p["status"] != "measured"]

    fig, (ax, ax_size) = plt.subplots(1, 2, figsize=(WIDTH_IN, HEIGHT_IN), dpi=DPI, sharey=True,
                                      gridspec_kw={"width_ratios": [3, 2], "wspace": 0.06})
    floor = 1e-300  # a zero error or time cannot sit on a log axis; it is drawn at the axis' floor
    xs = [max(p["bake_s"], 1e-3) for p in measured]
    sizes = [max(p.get("bundle_bytes", 0), 1) / 2**20 for p in measured]
    ys = [max(p["error"], floor) for p in measured]
    errs = [truth_se(p) for p in measured]
    panel(ax, xs, ys, measured, errs, True)
    panel(ax_size, sizes, ys, measured, errs, False)
    ax.plot([], [], "o", color=FRONT, label="on the front")
    ax.plot([], [], "o", color=OTHER, label="dominated")
    if any(errs):
        ax.errorbar([], [], yerr=[], fmt="none", ecolor=BARS, capsize=3, label="± the truth's own error (p99)")
    unit = measured[0]["unit"] if measured and measured[0].get("unit") else ""
    record = measured[0]["record"] if measured else "error"
    ax.set_xlabel("bake time: plan + compute (s, wall; bars to the slowest repeat)")
    ax_size.set_xlabel("bundle size (MiB)")
    metric = measured[0].get("metric", "") if measured else ""
    ax.set_ylabel(record + (f" ({unit})" if unit else ""))
    fig.suptitle(f"{sweep['job']} ({sweep['kind']}): points labelled " + ", ".join(keys) +
                 (f"\n{record}: {metric[:110]}" if metric else ""), fontsize=9)
    ax.legend(fontsize=7, loc="best")
    fig.subplots_adjust(left=0.1, right=0.98, top=0.88, bottom=0.12 + 0.02 * min(len(failed), 5))
    fig.canvas.draw()
    texts = [label(p, keys) for p in measured]
    place_labels(fig, ax, xs, ys, texts)
    place_labels(fig, ax_size, sizes, ys, texts)
    if failed:
        lines = [f"failed: {label(p, keys)}: {p.get('reason', '')[:90]}" for p in failed[:4]]
        if len(failed) > 4:
            lines.append(f"... and {len(failed) - 4} more (sweep.json)")
        fig.text(0.01, 0.005, "\n".join(lines), fontsize=6, va="bottom")
    fig.savefig(dst, dpi=DPI)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: sweep_plot.py SWEEP.json OUT.png")
    main(sys.argv[1], sys.argv[2])
