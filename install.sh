#!/usr/bin/env bash
# The whole set-up on a fresh Debian 12 machine, then the main job.
#   bash install.sh               set up, build, run the main job
#   bash install.sh --setup-only  set up and build only (CI)
# Re-running it is cheap: packages already present are skipped and the C++
# build folder (build/) is kept, so only changed files recompile.
set -euo pipefail
cd "$(dirname "$0")"

RUN_MAIN=1
for arg in "$@"; do
  case "$arg" in
    --setup-only) RUN_MAIN=0 ;;
    *) echo "install.sh: unknown option '$arg' (known: --setup-only)" >&2; exit 2 ;;
  esac
done

# 1. Debian packages: Embree 3 for the renderer, LLVM 19 for Mitsuba 3's llvm
#    variants (older LLVMs crash or are refused), EGL/GL for pyvista off-screen,
#    Chromium (the test that opens the benchmark report headless), a C++
#    toolchain and Python's venv.
APT_PACKAGES=(libembree-dev libllvm19 libegl1 libgl1 libgl1-mesa-dri libosmesa6 libxrender1 chromium
              g++ make python3-dev python3-venv)
missing=()
for p in "${APT_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ "${#missing[@]}" -gt 0 ]; then
  if [ "$(id -u)" = "0" ]; then
    echo "==> apt-get install ${missing[*]}"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
  else
    echo "install.sh needs root to install Debian packages. Run:" >&2
    echo "  sudo apt-get update && sudo apt-get install -y ${missing[*]}" >&2
    echo "then run install.sh again." >&2
    exit 1
  fi
fi

# 2. Virtual environment with the Python packages.
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  echo "==> creating .venv"
  "$PY" -m venv .venv
fi
VPY=.venv/bin/python
"$VPY" -m pip install -q --upgrade pip
"$VPY" -m pip install -q "scikit-build-core>=0.10" "pybind11>=2.12" "cmake>=3.18" ninja

# 3. Build the C++ core and install radiometer (editable; build/ persists).
echo "==> building radiometer (C++ core through scikit-build-core)"
"$VPY" -m pip install -q --no-build-isolation -e ".[reference,test]"
"$VPY" -c "import radiometer, radiometer._core; print('radiometer', radiometer.__version__, 'ready')"

# 4. The main job: the default benchmark matrix (benchmarks/default.toml),
#    every canonical scene with every estimator that supports it; prints the
#    per-effect error table and the HTML report's path. Results accumulate in
#    out/results/bench.sqlite.
if [ "$RUN_MAIN" = "1" ]; then
  echo "==> main job: radiometer bench (default matrix, about 30 minutes on 2 cores the first time)"
  .venv/bin/radiometer bench
fi
