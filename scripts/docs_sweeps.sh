#!/usr/bin/env bash
# Sweeps every bundled config (speed against error) and copies each picture to docs/figures/
# (docs/sweep.md, "The bundled configs"). Run on an idle machine: the times are the pictures'
# x axis. Usage: scripts/docs_sweeps.sh [WORK_DIR]   (default: build/docs-sweeps)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
bin="$root/build/specbake"
work=${1:-"$root/build/docs-sweeps"}
mkdir -p "$work" "$root/docs/figures"

sweep() {  # sweep CONFIG JOB[:NAME] VARY...   (NAME: the figure's name, default JOB)
  local config=$1 job=${2%%:*} name=${2#*:}
  shift 2
  local args=()
  for v in "$@"; do args+=(--vary "$v"); done
  echo "== $job: $*"
  local t0=$SECONDS
  "$bin" sweep "$root/configs/$config" --job "$job" "${args[@]}" --out "$work/$name" -q
  echo "$name: $((SECONDS - t0)) s wall"
  cp "$work/$name/sweep.png" "$root/docs/figures/sweep-$name.png"
}

# dispersion: sample count and placement
sweep bk7-prism.yaml bk7-prism "samples=4,8,12,16,24,32,48" "sampling=uniform,gauss-legendre"
sweep sf11-prism.yaml sf11-prism "samples=4,8,12,16,24,32,48" "sampling=uniform,gauss-legendre"
# diffraction: term count and expansion
sweep sine-grating.yaml sine-grating "terms=3..10" "expansion=taylor,chebyshev"
sweep elaphe-diffraction.yaml elaphe "terms=4,6,8,10,12,16" "expansion=taylor,chebyshev"
# atmosphere: sizes (at most the defaults), orders, spectrum, against each config's scene
sweep earth-rgb.yaml earth-rgb "sizes=50%,100%" "orders=2,4,6"
sweep earth-spectral.yaml earth-spectral "spectrum.count=8,16,32,48" "sizes=50%"
sweep hazy-earth.yaml hazy-earth "orders=2,4,8,auto" "sizes=50%"
sweep mars.yaml mars "sizes=50%,100%" "orders=2,4"
# diffraction tables: size and mapping, and the coherence length (sun: 39.9 µm), on the bundled
# Elaphe scan and the sine grating (docs/diffraction-method.md, "Coherence and tables")
sweep elaphe-diffraction.yaml elaphe:elaphe-table "table.size=64,96,128,192,256,384" "table.mapping=linear,power"
sweep elaphe-diffraction.yaml elaphe:elaphe-coherence "coherence.length_um=10,20,40,80" "table.size=128,256"
sweep sine-grating.yaml sine-grating:sine-grating-table "table.size=64,128,256,384" "table.mapping=linear,power"
