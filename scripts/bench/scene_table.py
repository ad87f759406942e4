#!/usr/bin/env python3
"""Markdown tables of a scene_bench run, one per scene:
    build/scripts/bench/scene_bench --benchmark_format=json > scene.json
    scripts/bench/scene_table.py scene.json
"""
import json
import sys


def main(path):
    runs = json.load(open(path))["benchmarks"]
    by_scene = {}
    for r in runs:
        scene, setting = r["label"].split(" | ")
        by_scene.setdefault(scene, []).append((setting, r))
    for scene, rows in by_scene.items():
        print(f"**{scene}**\n")
        print("| setting | orders | bake | check | CIEDE2000 p99 / max / mean | rel. p99 | p99 by cause: LUT / orders / spectral | truth se (ΔE mean) |")
        print("|---|---|---|---|---|---|---|---|")
        for setting, r in rows:
            spectral = f"{r['spectral_p99']:.2f}" if "wavelengths" not in setting else "-"
            print(f"| {setting} | {r['orders']:.0f} | {r['bake_s']:.1f} s | {r['check_s']:.1f} s | "
                  f"{r['de_p99']:.2f} / {r['de_max']:.2f} / {r['de_mean']:.2f} | {100 * r['rel_p99']:.1f} % | "
                  f"{r['lut_p99']:.2f} / {r['orders_p99']:.2f} / {spectral} | {r['se_de_mean']:.2f} |")
        print()


if __name__ == "__main__":
    main(sys.argv[1])
