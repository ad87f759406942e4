#!/usr/bin/env bash
# Builds the libFuzzer targets with clang (ASan + UBSan) into build-fuzz/ and runs each for
# SECONDS (default 60) on its seed corpus in tests/fuzz/corpus/<target>/. New inputs go to a
# scratch corpus, not the repository. A crash leaves crash-* files in build-fuzz/ and fails.
#   scripts/fuzz.sh [SECONDS]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
seconds=${1:-60}
CC=clang CXX=clang++ cmake -S "$root" -B "$root/build-fuzz" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DSPECBAKE_FUZZ=ON -DSPECBAKE_BUILD_TESTS=OFF -DSPECBAKE_BUILD_BENCHMARKS=OFF >/dev/null
targets=()
for src in "$root"/tests/fuzz/*_fuzz.cpp; do targets+=("$(basename "${src%.cpp}")"); done
cmake --build "$root/build-fuzz" -j "$(nproc)" --target "${targets[@]}"
export ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1
for t in "${targets[@]}"; do
  seeds="$root/tests/fuzz/corpus/${t%_fuzz}"
  scratch=$(mktemp -d)
  echo "fuzz: $t for ${seconds}s (seeds: $seeds)"
  "$root/build-fuzz/tests/fuzz/$t" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -max_len=65536 \
      -artifact_prefix="$root/build-fuzz/" -print_final_stats=1 "$scratch" "$seeds"
  rm -rf "$scratch"
done
echo "fuzz: all targets ran ${seconds}s without a crash"
