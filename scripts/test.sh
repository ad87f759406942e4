#!/usr/bin/env bash
# Installs what is missing, builds (with tests), and runs the whole test suite with CTest.
# Reference data is read from ../shared/refdata (override: SPECBAKE_CMAKE_ARGS=-DSPECBAKE_REFDATA_DIR=...).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/setup.sh"
cd "$root/build"
exec ctest --output-on-failure -j "$(nproc)" "$@"
