#!/bin/sh
# run_in_venv.sh VENV_PYTHON SCRIPT ARGS...: runs SCRIPT with the test venv's Python, or reports
# the test skipped (exit 77, CTest SKIP_RETURN_CODE) when scripts/setup.sh made no venv.
py=$1
shift
if [ ! -x "$py" ]; then
  echo "skipped: no Python venv at $py (scripts/setup.sh creates it with pyktx2 and zstandard)"
  exit 77
fi
exec "$py" "$@"
