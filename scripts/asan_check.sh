#!/usr/bin/env bash
# Builds the C++ core with AddressSanitizer and UndefinedBehaviorSanitizer
# into out/asan/ (a package laid out as the wheel does, beside the normal
# build), and runs the loader, stress and short estimator tests against it.
# Python itself is not instrumented: libasan is preloaded, leak checking is
# off (CPython's allocations at exit are not ours), and any ASan or UBSan
# report fails the run. Needs .venv from install.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
B=out/asan
VPY=.venv/bin/python
mkdir -p "$B"
PYB=$("$VPY" -c "import pybind11; print(pybind11.get_cmake_dir())")
SAN="-fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer"
.venv/bin/cmake -S . -B "$B/build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_FLAGS="$SAN -O1" -DCMAKE_SHARED_LINKER_FLAGS="$SAN" \
  -DCMAKE_MAKE_PROGRAM="$(pwd)/.venv/bin/ninja" -Dpybind11_DIR="$PYB" -DPython_EXECUTABLE="$VPY" > "$B/cmake.log"
.venv/bin/cmake --build "$B/build" -j "$(nproc)" > "$B/build.log" || { tail -30 "$B/build.log"; exit 1; }
rm -rf "$B/pkg" && mkdir -p "$B/pkg"
cp -r bindings/radiometer "$B/pkg/radiometer"
for d in analysis benchmarks reference_scenes; do cp -r "$d" "$B/pkg/radiometer/$d"; done
cp "$B"/build/_core*.so "$B/pkg/radiometer/"
# A venv that sees .venv's packages through a path entry but not its editable
# finder (a .pth inside a path entry is not processed), so `radiometer`
# resolves to the instrumented copy.
if [ ! -x "$B/venv/bin/python" ]; then "$VPY" -m venv --without-pip "$B/venv"; fi
SITE=$("$B/venv/bin/python" -c "import sysconfig; print(sysconfig.get_paths()['purelib'])")
echo "$(pwd)/$B/pkg" > "$SITE/00_asan_pkg.pth"
"$VPY" -c "import sysconfig; print(sysconfig.get_paths()['purelib'])" > "$SITE/01_venv_site.pth"
# The sanitizer runtimes first in every process that loads the instrumented core
# (importing radiometer loads it).
export LD_PRELOAD="$(g++ -print-file-name=libasan.so):$(g++ -print-file-name=libubsan.so)"
export ASAN_OPTIONS=detect_leaks=0:abort_on_error=1:halt_on_error=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
"$B/venv/bin/python" -c "import radiometer, sys; p = radiometer.__file__; print('instrumented radiometer:', p); sys.exit(0 if '/out/asan/' in p else 1)"
if [ "$#" -eq 0 ]; then
  set -- tests/test_loader.py tests/test_stress.py tests/test_render.py tests/test_float_range.py tests/test_effects.py \
    tests/test_textures.py tests/test_roughplastic.py tests/test_radiosity.py tests/test_radiosity_hierarchical.py \
    tests/test_rays.py tests/test_shapes.py tests/test_normalmap.py tests/test_principled.py \
    tests/test_emitter_textures.py
  # equiangular sampling's code paths on small renders (its statistical
  # comparisons run in the suite: they take minutes here and exercise the same code)
  for t in single_scattering_point_light_closed_form single_scattering_spot_light_closed_form \
    degenerate_segments_are_finite light_behind_the_ray_agrees_with_free_flight media_stress_scenes \
    classes_and_masks off_by_default_and_deterministic warns_where_it_cannot_help bad_value_is_refused; do
    set -- "$@" "tests/test_media_equiangular.py::test_$t"
  done
fi
"$B/venv/bin/python" -m pytest -q -p no:cacheprovider "$@"
