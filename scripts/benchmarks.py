#!/usr/bin/env python3
"""The benchmarks page: measure the speed targets on this machine, keep every run's record, and
write docs/benchmarks.md from the records (one current table per target).

    scripts/benchmarks.py measure [--only ID ...] [--repeats N] [--slow] [--device D]
    scripts/benchmarks.py render
    scripts/benchmarks.py list

`measure` runs each target of scripts/bench/targets.json through the built `specbake` (or a
fresh clone, for the clone target) and appends one record per target to
scripts/bench/records.jsonl: the machine, the date, the version, the figure with its spread over
the repeats, the load average it ran under, and the details the figure came from. Targets marked
slow (the settings search, the fresh clone) run only with --slow or --only. `render` rewrites
docs/benchmarks.md: per target the newest record of each machine, beside the newest record of
that machine from an earlier version. Only the standard library is used.
"""
import argparse
import datetime
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TARGETS = ROOT / "scripts" / "bench" / "targets.json"
RECORDS = ROOT / "scripts" / "bench" / "records.jsonl"
PAGE = ROOT / "docs" / "benchmarks.md"


def load_targets():
    return json.loads(TARGETS.read_text())["targets"]


def load_records():
    if not RECORDS.exists():
        return []
    out = []
    for n, line in enumerate(RECORDS.read_text().splitlines(), 1):
        if line.strip():
            try:
                out.append(json.loads(line))
            except json.JSONDecodeError as e:
                sys.exit(f"{RECORDS}:{n}:{e.colno}: not a JSON record: {e.msg}")
    return out


def version():
    """specbake's version and the commit measured (+dirty when the tree has changes)."""
    def git(*a):
        return subprocess.run(["git", "-C", str(ROOT), *a], capture_output=True, text=True).stdout.strip()
    sha = git("rev-parse", "--short=7", "HEAD") or "unknown"
    # the records and the page this script writes do not make a tree dirty
    dirty = "-dirty" if git("status", "--porcelain", "--untracked-files=no", "--", ".",
                            ":!scripts/bench/records.jsonl", ":!docs/benchmarks.md") else ""
    return f"{sha}{dirty}"


def cpu_name():
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def machine_of(device):
    """The machine a record belongs to: the host's CPU and core count, and the OpenCL device."""
    cores = os.cpu_count() or 0
    kind = device.get("type", "cpu")
    cls = ("cpu%d" % cores) if kind == "cpu" else kind
    return {"class": cls, "cpu": cpu_name(), "cores": cores, "device": device.get("name", "?"),
            "platform": device.get("platform", "?")}


class Failed(Exception):
    """A measured run that failed: its wall time and why (the record says so)."""
    def __init__(self, wall, why):
        super().__init__(why)
        self.wall, self.why = wall, why


def run(cmd, **kw):
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, **kw)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        sys.stderr.write(p.stdout[-4000:] + p.stderr[-4000:])
        out = (p.stdout + "\n" + p.stderr).splitlines()
        # the job's own failure line first (warnings also say "standard error")
        lines = [l for l in out if ": failed:" in l] or [l for l in out if "failed" in l or "error" in l]
        raise Failed(wall, f"exit {p.returncode}: " + (lines[-1][:300] if lines else "see its output"))
    return wall


def latest_manifest(out, job):
    return json.loads((Path(out) / job / "latest" / "manifest.json").read_text())


def record_of(manifest, kind):
    for a in manifest.get("accuracy", []):
        if a.get("name") == kind:
            return a
    return None


def bake_facts(m, process_wall):
    """What one run's manifest says about its time."""
    t = m.get("timings_s", {})
    steps = t.get("steps", {})
    device = sum(s.get("device_s", 0.0) for s in steps.values())
    facts = {"bake_s": t.get("bake"), "process_s": process_wall,
             "steps_wall_s": {k: round(v.get("wall_s", 0.0), 3) for k, v in steps.items()},
             "device_share": (device / t["bake"]) if t.get("bake") else None}
    for kind in ("atmosphere", "diffraction"):
        stages = m.get(kind, {}).get("timings_s", {})
        stages = stages.get("total", stages) if isinstance(stages, dict) else {}
        if stages:
            facts["stages"] = {k: {x: round(y, 4) for x, y in v.items()} for k, v in stages.items()
                               if isinstance(v, dict) and "wall_s" in v}
    check = record_of(m, "vs_path_traced")
    if check:
        d = check.get("details", {})
        truths = [d.get("truth", {}), d.get("spectral_truth", {})]
        facts["truth_s"] = sum(x.get("seconds", 0.0) for x in truths if x and not x.get("reused"))
        facts["truth_reused"] = any(x.get("reused") for x in truths if x)
        se = d.get("standard_error", {})
        facts["truth_se_relative_p99"] = se.get("relative", {}).get("p99")
        # per point and channel of what relative_se targets (X, Y, Z of a spectrum), both traces
        facts["truth_se_target_p99"] = se.get("target_channels", {}).get("p99")
        facts["reference_se_xyz_p99"] = se.get("reference_xyz_relative", {}).get("p99")
        facts["truth_se_target_max"] = se.get("target_channels", {}).get("max")
        for band, key in (("below", "sun_below_-6_deg"), ("from", "sun_from_-6_deg")):
            facts[f"truth_se_target_p99_sun_{band}_-6"] = se.get("target_channels_by_sun", {}).get(key, {}).get("p99")
            facts[f"truth_se_target_max_sun_{band}_-6"] = se.get("target_channels_by_sun", {}).get(key, {}).get("max")
        facts["truth_se_de2000_p99"] = se.get("de2000", {}).get("p99")
        facts["points_at_walk_cap"] = se.get("points_at_max_paths")
        facts["vs_path_traced"] = check.get("value")
    held = record_of(m, "vs_path_traced_held_out")
    if held:
        facts["held_out"] = held.get("value")
    auto = m.get("parameters", {}).get("auto")
    if isinstance(auto, dict) and "tries" in auto:
        facts["tries"] = len(auto["tries"])
    return facts


_baked = {}


def measure_bake(spec, args):
    """`cold_runs` cold runs, each into an empty output folder, then `repeats` warm runs (--force,
    kept truth) after the first; targets that read the same job share its runs."""
    repeats = spec.get("repeats", args.repeats)
    cold_runs = args.cold_runs or spec.get("cold_runs", 1)
    key = (spec["config"], spec["job"], repeats, cold_runs)
    if key not in _baked:
        _baked[key] = bake_runs(spec, repeats, cold_runs, args)
    return _baked[key]


def warm_truth_program(spec, args, tmp):
    """Builds the path tracer's OpenCL program once (a one-point trace), so that a cold run's check
    measures the walks rather than the device compiler's first build of a changed kernel (the
    driver caches it; a nightly finds it built). Not an atmosphere job: nothing to build."""
    points = Path(tmp) / "points.csv"
    points.write_text("altitude_km,view_zenith_deg,sun_zenith_deg,view_sun_azimuth_deg\n1,60,60,0\n")
    cmd = [str(Path(args.specbake)), "-q", "truth", str(ROOT / spec["config"]), "--job", spec["job"],
           "--points", str(points), "--out", str(Path(tmp) / "result.csv"), "--paths", "64"]
    if args.device:
        cmd += ["--device", args.device]
    subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)


def bake_runs(spec, repeats, cold_runs, args):
    """The device, the cold runs' facts and the warm runs' facts."""
    exe = Path(args.specbake)
    colds, warm, device = [], [], {}
    with tempfile.TemporaryDirectory(prefix="specbake-warm-") as tmp:
        warm_truth_program(spec, args, tmp)
        for i in range(cold_runs):
            with tempfile.TemporaryDirectory(prefix="specbake-bench-") as out:
                cmd = [str(exe), "-q", "run", str(ROOT / spec["config"]), "--only", spec["job"], "--out", out]
                if args.device:
                    cmd += ["--device", args.device]
                cold_wall = run(cmd)
                cold_m = latest_manifest(out, spec["job"])
                device = device or cold_m.get("device", {})
                colds.append(bake_facts(cold_m, cold_wall))
                for _ in range(repeats if i == 0 else 0):
                    w = run(cmd + ["--force"])
                    warm.append(bake_facts(latest_manifest(out, spec["job"]), w))
    return device, colds, warm


def check_share(cold):
    """A cold run's check step as a percentage of the rest of its job."""
    check = cold["steps_wall_s"].get("check", 0.0)
    rest = cold["bake_s"] - check
    return 100.0 * check / rest if rest > 0 else None


def figure_of(target, colds, warm):
    """The target's figure (the median of its runs), its spread and the runs it came from."""
    f = target["figure"]
    if f == "bake_s":
        runs = [r["bake_s"] for r in warm] or [c["bake_s"] for c in colds]
    elif f == "truth_s":
        runs = [c["truth_s"] for c in colds]
    elif f == "check_share_cold":
        runs = [check_share(c) for c in colds]
    else:
        raise SystemExit(f"{TARGETS}: target {target['id']}: unknown figure '{f}'")
    return statistics.median(runs), [min(runs), max(runs)], len(runs)


def measure_clone(args):
    with tempfile.TemporaryDirectory(prefix="specbake-clone-") as tmp:
        clone = Path(tmp) / "specbake"
        subprocess.run(["git", "clone", "-q", "--no-local", str(ROOT), str(clone)], check=True)
        env = dict(os.environ, CCACHE_DISABLE="1", SPECBAKE_NO_INSTALL="1")
        env.pop("SPECBAKE_CMAKE_ARGS", None)
        t0 = time.perf_counter()
        run([str(clone / "scripts" / "bake.sh")] + (["--device", args.device] if args.device else []), env=env)
        wall = time.perf_counter() - t0
        manifests = list((clone / "assets").glob("*/latest/manifest.json"))
        device = json.loads(manifests[0].read_text()).get("device", {}) if manifests else {}
    return device, {"clone_s": wall, "bundles": len(manifests)}


def measure_run(spec, args):
    """Every config in a folder in one `specbake run`: a cold run into an empty output folder (the
    scene truths traced), then `repeats` warm runs with --force (the truths kept). The figure is
    the warm runs' wall time; beside it the jobs' own seconds summed (manifest `timings_s.bake`,
    whichever thread did the work): a run's wall time below that sum is work overlapped."""
    repeats = spec.get("repeats", args.repeats)
    with tempfile.TemporaryDirectory(prefix="specbake-run-") as out:
        cmd = [str(Path(args.specbake)), "-q", "run", str(ROOT / spec["configs"]), "--out", out]
        if args.device:
            cmd += ["--device", args.device]
        cold = run(cmd)
        warm = [run(cmd + ["--force"]) for _ in range(max(repeats, 1))]
        manifests = [json.loads(m.read_text()) for m in sorted(Path(out).glob("*/latest/manifest.json"))]
    jobs_s = sum(m.get("timings_s", {}).get("bake", 0.0) for m in manifests)
    device = next((m.get("device", {}) for m in manifests if m.get("device", {}).get("type")), {})
    return device, {"cold_s": cold, "warm_s": warm, "bundles": len(manifests), "jobs_s": jobs_s}


def measure(args):
    targets = load_targets()
    if args.only:
        chosen = [t for t in targets if t["id"] in args.only]
    else:
        chosen = [t for t in targets if args.slow or not t["measure"].get("slow")]
    unknown = set(args.only or []) - {t["id"] for t in targets}
    if unknown:
        sys.exit(f"unknown target(s) {', '.join(sorted(unknown))}; `scripts/benchmarks.py list` shows them")
    ver = args.version or version()
    for t in chosen:
        load = os.getloadavg()[0]
        print(f"{t['id']}: measuring ({t['measure']['kind']}), load {load:.1f} ...", flush=True)
        kind = t["measure"]["kind"]
        failed = None
        if kind == "bake":
            try:
                device, colds, warm = measure_bake(t["measure"], args)
                fig, spread, n = figure_of(t, colds, warm)
                details = {"cold": colds[0], "warm": warm}
                if len(colds) > 1:
                    details["more_cold"] = colds[1:]
            except Failed as e:  # recorded: how long it ran before it failed, and why
                failed = e.why
                device, fig, spread, n, details = {"type": "cpu" if args.device in (None, "cpu", "auto") else "gpu",
                                                   "name": "?"}, e.wall, [e.wall, e.wall], 1, {"failed": e.why}
        elif kind == "run":
            device, facts = measure_run(t["measure"], args)
            runs = facts["warm_s"]
            fig, spread, n, details = statistics.median(runs), [min(runs), max(runs)], len(runs), facts
        elif kind == "clone":
            device, facts = measure_clone(args)
            fig, spread, n, details = facts["clone_s"], [facts["clone_s"]] * 2, 1, facts
        else:
            sys.exit(f"{TARGETS}: target {t['id']}: unknown measure kind '{kind}'")
        rec = {"target": t["id"], "date": datetime.date.today().isoformat(), "version": ver,
               "machine": machine_of(device), "figure": fig, "unit": t["unit"], "spread": spread, "runs": n,
               "load_before": round(load, 2), "load_after": round(os.getloadavg()[0], 2), "details": details}
        if failed:
            rec["failed"] = failed
        with RECORDS.open("a") as f:
            f.write(json.dumps(rec, sort_keys=True) + "\n")
        print(f"{t['id']}: {fig:.4g} {t['unit']} (spread {spread[0]:.4g}–{spread[1]:.4g}, {n} runs)"
              + (f" FAILED: {failed}" if failed else ""), flush=True)


def shown(v, unit):
    if v is None:
        return "—"
    if unit == "s" and v >= 120:
        return f"{v / 60:.1f} min"
    return f"{v:.3g} {unit}" if unit != "%" else f"{v:.3g} %"


def extra_of(rec):
    """The figures beside the headline that say what it bought or cost."""
    d = rec.get("details", {})
    cold = d.get("cold", d)
    bits = []
    if cold.get("device_share") is not None and rec["machine"]["class"] != "cpu%d" % rec["machine"]["cores"]:
        bits.append(f"device {100 * cold['device_share']:.0f} %")
    if cold.get("tries") is not None:
        bits.append(f"{cold['tries']} tries")
    if cold.get("vs_path_traced") is not None:
        bits.append(f"ΔE p99 {cold['vs_path_traced']:.3g}")
    if cold.get("held_out") is not None:
        bits.append(f"held out {cold['held_out']:.3g}")
    if rec["target"] == "twilight-truth" and cold.get("truth_se_relative_p99") is not None:
        bits.append(f"truth se p99 {100 * cold['truth_se_relative_p99']:.2g} % (sRGB)")
        if cold.get("truth_se_target_p99") is not None:
            bands = [f"{name} {100 * cold[k]:.3g} %" for name, k in
                     (("sun below −6°", "truth_se_target_p99_sun_below_-6"), ("from −6°", "truth_se_target_p99_sun_from_-6"))
                     if cold.get(k) is not None]
            bits.append(f"XYZ {100 * cold['truth_se_target_p99']:.3g} %" + (f" ({', '.join(bands)})" if bands else ""))
            worst = [f"{name} {100 * cold[k]:.3g} %" for name, k in
                     (("sun below −6°", "truth_se_target_max_sun_below_-6"), ("from −6°", "truth_se_target_max_sun_from_-6"))
                     if cold.get(k) is not None]
            if worst:
                bits.append("largest " + ", ".join(worst))
        if cold.get("reference_se_xyz_p99") is not None:
            bits.append(f"the 48-wavelength reference's XYZ {100 * cold['reference_se_xyz_p99']:.3g} %")
        bits.append(f"{cold.get('points_at_walk_cap')} at cap")
    if cold.get("bundles") is not None:
        bits.append(f"{cold['bundles']} bundles")
    if cold.get("jobs_s") is not None:
        bits.append(f"the jobs' own seconds {cold['jobs_s']:.3g} s (last run)")
    if rec.get("failed"):
        bits.append("the job failed after this time: " + rec["failed"])
    if rec.get("source"):
        bits.append(rec["source"])
    return "; ".join(bits)


def profile_of(target, by_machine):
    """Where the newest run's time went, per stage of the job's own timings (device and host)."""
    out = []
    for key in sorted(by_machine):
        cur = sorted(by_machine[key], key=lambda r: r["date"])[-1]
        runs = cur.get("details", {}).get("warm") or [cur.get("details", {}).get("cold", {})]
        stages = runs[-1].get("stages") if runs and runs[-1] else None
        steps = runs[-1].get("steps_wall_s") if runs and runs[-1] else None
        if not stages:
            continue
        m = cur["machine"]
        out += [f"Where the time of `{cur['version']}` went on {m['class']} ({m['device']}), one warm run: the job's steps "
                + ", ".join(f"{k} {v:.3g} s" for k, v in sorted((steps or {}).items())) + "; its stages, summed over "
                "passes and orders (`device_s`: the stage's OpenCL commands; `host_s`: the rest of its wall time):", "",
                "| stage | device_s | host_s | wall_s |", "|---|---|---|---|"]
        for name, v in sorted(stages.items(), key=lambda kv: -kv[1].get("wall_s", 0.0)):
            out.append(f"| {name} | {v.get('device_s', 0):.3g} | {v.get('host_s', 0):.3g} | {v.get('wall_s', 0):.3g} |")
        out.append("")
    return out


def render(args):
    targets = load_targets()
    records = load_records()
    lines = [
        "# Benchmarks",
        "",
        "<!-- generated by scripts/benchmarks.py render from scripts/bench/records.jsonl; do not edit -->",
        "",
        "Speed targets and where they stand, one table per target: per machine the newest run, beside",
        "that machine's newest run of an earlier version. Measure with `scripts/benchmarks.py measure`",
        "(`--slow` adds the settings search and the fresh clone) and rewrite this page with",
        "`scripts/benchmarks.py render`; the records (every run, with its details) are in",
        "`scripts/bench/records.jsonl`, the targets in `scripts/bench/targets.json`.",
        "",
        "Times are the job's own seconds from its manifest (`timings_s.bake`), which the tool measures",
        "honestly on asynchronous devices: each step's `device_s` sums its OpenCL commands' profiled",
        "start-to-end times, `host_s` is the step's wall time less the time blocked waiting for the device.",
        "Wall times on a shared machine move with its load: each run's load average is recorded, and",
        "figures are compared within a machine, not across.",
        "",
        "Machines: `cpu2` is a 2-core CPU through PoCL (the CI machine's class), `gpu` a GPU through its",
        "vendor's OpenCL driver.",
        "",
    ]
    for t in targets:
        mine = [r for r in records if r["target"] == t["id"]]
        lines += [f"## {t['title']}", "", t["note"], ""]
        if not mine:
            lines += ["Not measured yet.", ""]
            continue
        lines += ["| machine | date | version | figure (spread, runs) | load | target | met | earlier version | details |",
                  "|---|---|---|---|---|---|---|---|---|"]
        by_machine = {}
        for r in mine:
            key = (r["machine"]["class"], r["machine"]["cpu"], r["machine"]["device"])
            by_machine.setdefault(key, []).append(r)
        for key in sorted(by_machine):
            runs = sorted(by_machine[key], key=lambda r: r["date"])
            cur = runs[-1]
            earlier = [r for r in runs if r["version"] != cur["version"]]
            prev = earlier[-1] if earlier else None
            cls = cur["machine"]["class"]
            goal = t["target"].get(cls) if cls in ("cpu2", "gpu") else None
            met = "—" if goal is None else ("yes" if cur["figure"] <= goal else "**no**")
            if cur.get("failed"):
                met = "**failed**"
            lo, hi = cur["spread"]
            fig = shown(cur["figure"], t["unit"])
            if cur["runs"] > 1:
                fig += f" ({lo:.3g}–{hi:.3g}, {cur['runs']} runs)"
            m = cur["machine"]
            machine = f"{cls}: {m['cpu']}" + ("" if cls.startswith("cpu") else f" + {m['device']}")
            lines.append(" | ".join([
                "| " + machine, cur["date"], f"`{cur['version']}`", fig,
                "—" if cur.get("load_before") is None else f"{cur['load_before']:.1f}", "—" if goal is None else f"≤ {shown(goal, t['unit'])}", met,
                f"{shown(prev['figure'], t['unit'])} (`{prev['version']}`, {prev['date']})" if prev else "—",
                extra_of(cur)]) + " |")
        lines.append("")
        if t.get("profile"):
            lines += profile_of(t, by_machine)
    text = "\n".join(lines)
    if args.check:
        if not PAGE.exists() or PAGE.read_text() != text:
            sys.exit(f"{PAGE} is not what `scripts/benchmarks.py render` makes of {RECORDS}: run it and commit both")
        print(f"{PAGE} is up to date")
        return
    PAGE.write_text(text)
    print(f"wrote {PAGE} ({len(records)} records, {len(targets)} targets)")


def list_targets(_args):
    for t in load_targets():
        slow = " (slow)" if t["measure"].get("slow") else ""
        print(f"{t['id']:20} {t['title']}{slow}")


def main():
    global RECORDS, PAGE
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    m = sub.add_parser("measure", help="run the targets here and append their records")
    m.add_argument("--only", nargs="+", metavar="ID", help="these targets (slow ones included)")
    m.add_argument("--repeats", type=int, default=3, help="warm runs after the cold one (default 3)")
    m.add_argument("--cold-runs", type=int, help="cold runs, each into an empty output folder (default: the "
                   "target's `cold_runs`, else 1); figures read from cold runs are their median")
    m.add_argument("--slow", action="store_true", help="also the slow targets (settings search, fresh clone)")
    m.add_argument("--device", help="OpenCL device, as `specbake run --device`")
    m.add_argument("--specbake", default=str(ROOT / "build" / "specbake"), help="the binary (default build/specbake)")
    m.add_argument("--version", help="the version measured, when --specbake is a build of another commit "
                                     "(default: this tree's)")
    m.set_defaults(fn=measure)
    r = sub.add_parser("render", help="write docs/benchmarks.md from the records")
    r.add_argument("--check", action="store_true", help="only check that the page is up to date (exit 1 if not)")
    r.set_defaults(fn=render)
    sub.add_parser("list", help="the targets").set_defaults(fn=list_targets)
    ap.add_argument("--records", default=str(RECORDS), help="the records file (default scripts/bench/records.jsonl)")
    ap.add_argument("--page", default=str(PAGE), help="the page render writes (default docs/benchmarks.md)")
    args = ap.parse_args()
    RECORDS, PAGE = Path(args.records), Path(args.page)
    if args.cmd == "measure" and not Path(args.specbake).exists() and not (args.only == ["fresh-clone"]):
        sys.exit(f"{args.specbake}: no such binary; build it first (scripts/setup.sh specbake)")
    args.fn(args)


if __name__ == "__main__":
    main()
