#!/usr/bin/env bash
# The code passes its formatters and linters: ruff for Python (pyproject.toml),
# clang-format for C++ (.clang-format). CI runs this; `--fix` applies both.
set -euo pipefail
cd "$(dirname "$0")/.."
CPP=$(git ls-files 'renderer/*.cpp' 'renderer/*.h' 'bindings/*.cpp' 'bindings/*.h')
if [ "${1:-}" = "--fix" ]; then
  .venv/bin/ruff check --fix .
  .venv/bin/clang-format -i $CPP
  exit 0
fi
.venv/bin/ruff check .
.venv/bin/clang-format --dry-run --Werror $CPP
echo "lint: ruff and clang-format clean"
