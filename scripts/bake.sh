#!/usr/bin/env bash
# Installs what is missing, builds, and bakes every bundled config in configs/ into assets/.
# Extra arguments go to `specbake run` (e.g. --force, --only NAME, --device cpu).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/setup.sh" specbake
exec "$root/build/specbake" run "$root/configs" "$@"
