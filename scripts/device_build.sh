#!/usr/bin/env bash
# Builds radiometer on a machine prepared by scripts/device_kit.sh (no
# Embree package, no network): compiles the C++ core and bindings with g++
# in parallel into out/devbuild/radiometer/_core*.so and lays the Python
# package out as the wheel does (analysis, benchmarks, reference_scenes
# inside it). Run from the repository root. The library path is an old-style
# RPATH (--disable-new-dtags) so that it also finds libembree's own TBB.
set -euo pipefail
cd "$(dirname "$0")/.."
K=out/devkit
B=out/devbuild
PY=${PYTHON:-python3}
mkdir -p "$B/obj" "$B/site"
$PY -m pip install -q --no-index --no-deps --target "$B/site" "$K"/wheels/*.whl
EXT=$($PY -c 'import sysconfig; print(sysconfig.get_config_var("EXT_SUFFIX"))')
INC="-I renderer -I $K/include $($PY -c 'import sysconfig; print("-I" + sysconfig.get_paths()["include"])')"
FLAGS="-std=c++17 -O3 -fPIC -DNDEBUG"
ls renderer/*/*.cpp bindings/module.cpp | xargs -P "$(nproc)" -I{} sh -c \
  'o='"$B"'/obj/$(echo {} | tr / _).o; g++ '"$FLAGS $INC"' -c {} -o "$o"'
rm -rf "$B/radiometer"
cp -r bindings/radiometer "$B/radiometer"
for d in analysis benchmarks reference_scenes; do cp -r "$d" "$B/radiometer/$d"; done
g++ -shared -o "$B/radiometer/_core$EXT" "$B"/obj/*.o -L "$K/lib" -l:libembree3.so.3 -l:libtbb.so.12 -pthread \
  -Wl,--disable-new-dtags,-rpath,"$(pwd)/$K/lib"
echo "built $B/radiometer/_core$EXT; use PYTHONPATH=$B:$B/site"
