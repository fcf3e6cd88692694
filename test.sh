#!/usr/bin/env bash
# Runs the whole test suite. Extra arguments go to pytest.
set -uo pipefail
cd "$(dirname "$0")"
if [ ! -x .venv/bin/python ]; then
  echo "test.sh: no .venv here; run 'bash install.sh --setup-only' first" >&2
  exit 2
fi
.venv/bin/python -m pytest "$@"
rc=$?
if [ "$rc" = "5" ]; then
  echo "test.sh: pytest collected no tests; that is a failure" >&2
  exit 1
fi
exit "$rc"
