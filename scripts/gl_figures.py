#!/usr/bin/env python3
"""Plots the GL tests' images (tests/support/testing.hpp, write_gl_figure) side by side: the
shipped shader's render on llvmpipe, the host's double evaluation, and |GL - host| / bound per
pixel. One figure per kind: <out>/gl-vs-host-<kind>.png.

Usage: gl_figures.py WORK_DIR OUT_DIR
"""
import json
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

FIGURES = {  # kind -> the images the GL tests write, one row each
    "atmosphere": ["atmosphere-fisheye-20", "atmosphere-planet"],
    "diffraction": ["diffraction-full", "diffraction-fast", "diffraction-fast-specular"],
    "dispersion": ["dispersion-slit"],
}


def load(work, name):
    meta = json.loads((work / f"{name}.json").read_text())
    w, h = meta["width"], meta["height"]
    data = np.fromfile(work / f"{name}.f32", dtype="<f4")
    n = w * h
    gl = data[: 3 * n].reshape(h, w, 3)
    host = data[3 * n: 6 * n].reshape(h, w, 3)
    ratio = data[6 * n: 7 * n].reshape(h, w)
    return meta, gl, host, ratio


def display(img, scale):
    """1 - exp(-x·scale) per channel, then the sRGB curve; both panels share the scale."""
    x = 1.0 - np.exp(-np.clip(img, 0.0, None) * scale)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def main():
    work, out = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
    for kind, names in FIGURES.items():
        rows = [load(work, name) for name in names]
        aspect = max(meta["height"] / meta["width"] for meta, *_ in rows)
        fig, axes = plt.subplots(len(rows), 3, figsize=(11, 0.8 + (3.3 * aspect + 0.5) * len(rows)), squeeze=False,
                                 gridspec_kw={"width_ratios": [1, 1, 1.25]})
        for r, (meta, gl, host, ratio) in enumerate(rows):
            lum = host @ np.array([0.2126, 0.7152, 0.0722])
            lit = lum[lum > 0]
            scale = 2.0 / np.percentile(lit, 99) if lit.size else 1.0  # the host's 99th percentile at 1 - e^-2
            for c, (img, label) in enumerate([(gl, "GL: " + meta["gl"]), (host, "host: " + meta["host"])]):
                axes[r][c].imshow(display(img, scale), origin="lower", interpolation="nearest")
                axes[r][c].set_title(label, fontsize=9)
            im = axes[r][2].imshow(ratio, origin="lower", cmap="viridis", vmin=0.0, vmax=1.0,
                                   interpolation="nearest")
            axes[r][2].set_title(f"|GL - host| / bound (worst {ratio.max():.3g})", fontsize=9)
            fig.colorbar(im, ax=axes[r][2], fraction=0.046)
            axes[r][0].set_ylabel(meta["title"], fontsize=9)
            for a in axes[r]:
                a.set_xticks([])
                a.set_yticks([])
        fig.suptitle(f"{kind}: the shipped shader on a real GL (left) against the host (middle), every pixel",
                     fontsize=11)
        fig.tight_layout()
        fig.savefig(out / f"gl-vs-host-{kind}.png", dpi=100)
        plt.close(fig)
        print(out / f"gl-vs-host-{kind}.png")


if __name__ == "__main__":
    main()
