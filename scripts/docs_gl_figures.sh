#!/usr/bin/env bash
# The docs' GL-against-host figures (docs/atmosphere.md, docs/dispersion.md, docs/diffraction.md,
# "Use it in an engine"): runs the three GL tests on Mesa's llvmpipe with SPECBAKE_GL_FIGURES
# set, so each writes the images it compared (the shipped shader's, the host's and their
# difference over the per-pixel bound), and plots them into docs/figures/gl-vs-host-<kind>.png.
# Needs a build (scripts/test.sh or scripts/bake.sh) and python3-matplotlib.
# Usage: scripts/docs_gl_figures.sh [WORK_DIR]   (default: build/gl-figures)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
work=${1:-"$root/build/gl-figures"}
rm -rf "$work"
mkdir -p "$work" "$root/docs/figures"
for t in atmosphere_gl_test diffraction_gl_test dispersion_gl_test; do
  SPECBAKE_GL_FIGURES="$work" "$root/build/tests/$t" --gtest_brief=1
done
py=/usr/bin/python3  # Debian's, where python3-matplotlib installs
[ -x "$py" ] || py=python3
"$py" "$root/scripts/gl_figures.py" "$work" "$root/docs/figures"
