#!/usr/bin/env bash
# Packs what a machine without Embree's Debian packages or network needs to
# build and run radiometer from this tree (used for the lent GPU machine,
# whose 16 cores measure thread scaling and run long benchmarks): Embree 3's
# headers and library, TBB, pybind11's headers, and wheels of the Python
# packages it lacks, into out/devkit (ignored by git). Then, there:
#   bash scripts/device_build.sh   # builds out/devbuild/radiometer
#   PYTHONPATH=out/devbuild python3 -m radiometer.benchmarks.studies.bdpt_efficiency
# Usage: bash scripts/device_kit.sh [PYTHON_VERSION (default 3.12)]
set -euo pipefail
cd "$(dirname "$0")/.."
PYV="${1:-3.12}"
K=out/devkit
rm -rf "$K" && mkdir -p "$K/include" "$K/lib" "$K/wheels"
cp -r /usr/include/embree3 "$K/include/"
for l in libembree3.so.3 libtbb.so.12 libtbbmalloc.so.2; do
  cp -L "/lib/x86_64-linux-gnu/$l" "$K/lib/"
done
cp -r "$(.venv/bin/python -c 'import pybind11; print(pybind11.get_include())')/pybind11" "$K/include/"
.venv/bin/python -m pip download -q --only-binary=:all: --python-version "$PYV" --no-deps -d "$K/wheels" OpenEXR plyfile
du -sh "$K"
