#!/usr/bin/env bash
# Installs what specbake needs from Debian 12 packages (only what is missing),
# then configures and builds into build/ (Release).
#   scripts/setup.sh            install + build everything (tests, benchmarks, the test venv)
#   scripts/setup.sh specbake   install + build only the binary (what baking needs)
#   SPECBAKE_NO_INSTALL=1 ...   skip the apt step (already provisioned machines)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)

packages=(
  build-essential cmake pkg-config
  ocl-icd-opencl-dev opencl-headers opencl-clhpp-headers pocl-opencl-icd clinfo
  libvkfft-dev libopenexr-dev libpng-dev libglm-dev libboost-math-dev
  libspdlog-dev libyaml-cpp-dev nlohmann-json3-dev libcli11-dev libssl-dev
  libgtest-dev libgmock-dev libbenchmark-dev libfftw3-dev
  clang libclang-rt-14-dev
  python3-numpy python3-matplotlib libzstd-dev python3-venv
  glslang-tools libegl-dev libgles-dev libegl-mesa0 libgl1-mesa-dri
  chromium fonts-dejavu-core libfreetype-dev libfontconfig-dev
)

if [ "${SPECBAKE_NO_INSTALL:-0}" != 1 ]; then
  missing=()
  for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ ${#missing[@]} -gt 0 ]; then
    echo "setup: installing ${missing[*]}"
    sudo_cmd=()
    [ "$(id -u)" -ne 0 ] && sudo_cmd=(sudo)
    "${sudo_cmd[@]}" apt-get update -qq
    DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
  fi
fi

build_type=${SPECBAKE_BUILD_TYPE:-Release}
cmake -S "$root" -B "$root/build" -DCMAKE_BUILD_TYPE="$build_type" ${SPECBAKE_CMAKE_ARGS:-}
if [ $# -gt 0 ]; then
  cmake --build "$root/build" -j "$(nproc)" --target "$@"
  exit 0
fi
cmake --build "$root/build" -j "$(nproc)"

# Test-side Python: a venv at build/pyenv with pyktx2 (an independent KTX2 reader; the version
# its checks are written against) and zstandard, on Debian's Python (numpy from python3-numpy,
# from PyPI if that Python lacks it); made only when missing. Built beside and moved into place
# when complete: a failed install leaves no venv, and the test that needs it reports itself
# skipped. Only for a build with tests (build/tests exists).
pyenv="$root/build/pyenv"
py=/usr/bin/python3
[ -x "$py" ] || py=python3
if [ -d "$root/build/tests" ] && ! "$pyenv/bin/python" -c "import pyktx2, zstandard, numpy" 2>/dev/null; then
  rm -rf "$pyenv" "$pyenv.tmp"
  pip_extra=()
  "$py" -c "import numpy" 2>/dev/null || pip_extra=(numpy)
  if "$py" -m venv --system-site-packages "$pyenv.tmp" &&
     "$pyenv.tmp/bin/python" -m pip install -q pyktx2==0.3.1 zstandard "${pip_extra[@]}" &&
     "$pyenv.tmp/bin/python" -c "import pyktx2, zstandard, numpy"; then
    mv "$pyenv.tmp" "$pyenv"
  else
    rm -rf "$pyenv.tmp"
    echo "setup: no Python venv at $pyenv (pip install pyktx2 zstandard failed); Ktx2.IndependentReader will be skipped" >&2
  fi
fi
