#!/usr/bin/env bash
# Build upstream DSO's `dso_dataset` headless (no Pangolin) — a developer reference, not part of dmtrack.
#
# Not part of dmtrack, of its install or of CI. DSO (Direct Sparse Odometry, J. Engel, TUM) is GPL-3.0: its
# sources are cloned into the build folder by this script and never enter the dmtrack repository. What lives here
# is ours: this script, run_dso.py, the README, and the edits below, applied to the clone with sed. The edits are
# compile / headless ones plus one command-line switch that selects which poses result.txt lists; none changes
# DSO's estimation (README.md lists them).
#
#   tools/dso_oracle/build.sh                                   # clones from GitHub into tools/dso_oracle/_build
#   DSO_REPO=/path/to/dso(.git) tools/dso_oracle/build.sh        # a local clone or bare mirror (offline)
#   BUILD_DIR=/tmp/dso JOBS=2 tools/dso_oracle/build.sh
#
# Needs (Debian 12; the script installs nothing):
#   apt-get install g++ cmake git libeigen3-dev libsuitesparse-dev libboost-system-dev libboost-thread-dev \
#       libopencv-dev zlib1g-dev
# Pangolin (viewer) and libzip (zipped image folders) are not needed. ~3 min on 2 cores.
set -euo pipefail
HERE="$(cd "$(dirname "$0")" && pwd)"
BUILD_DIR="${BUILD_DIR:-$HERE/_build}"
JOBS="${JOBS:-2}"
DSO_REPO="${DSO_REPO:-https://github.com/JakobEngel/dso.git}"
DSO_COMMIT="7b0c99f01d238f801c625beaff90240bcb007198"   # master, 2021-03-08 ("Merge pull request #235")
SRC="$BUILD_DIR/dso"

mkdir -p "$BUILD_DIR"
if [ ! -d "$SRC/.git" ]; then git clone --quiet --no-checkout "$DSO_REPO" "$SRC"; fi
if [ "$(git -C "$SRC" rev-parse HEAD 2>/dev/null || true)" != "$DSO_COMMIT" ] || [ ! -f "$SRC/CMakeLists.txt" ]; then
    git -C "$SRC" -c advice.detachedHead=false checkout --quiet --force "$DSO_COMMIT"
fi

# ---- edits (idempotent; `git -C _build/dso diff` shows them) ----
edit() {  # edit PATTERN FILE SED-ARGS…: sed -i only where PATTERN is still found (files not edited keep their mtime)
    local pattern="$1" file="$2"; shift 2
    if grep -q -- "$pattern" "$file"; then sed -i "$@" "$file"; fi
}
# 1. OpenCV 4 names of the imread flags (the C constants were removed).
edit 'CV_LOAD_IMAGE_' "$SRC/src/IOWrapper/OpenCV/ImageRW_OpenCV.cpp" -e 's/CV_LOAD_IMAGE_GRAYSCALE/cv::IMREAD_GRAYSCALE/g' \
    -e 's/CV_LOAD_IMAGE_COLOR/cv::IMREAD_COLOR/g' -e 's/CV_LOAD_IMAGE_UNCHANGED/cv::IMREAD_UNCHANGED/g'
# 2. Boost 1.74: boost/thread.hpp no longer brings in boost/bind.hpp, whose global placeholders _1.._4 the
#    thread-reduce calls use; include it (placeholders kept global, as before) where they are first needed.
grep -q 'boost/bind.hpp' "$SRC/src/util/IndexThreadReduce.h" || sed -i \
    's|^#include "boost/thread.hpp"$|#define BOOST_BIND_GLOBAL_PLACEHOLDERS\n#include <boost/bind.hpp>\n&|' \
    "$SRC/src/util/IndexThreadReduce.h"
# 3. C++ standard: gnu++14 instead of c++0x (Eigen 3.4 / current libstdc++); flags otherwise upstream's.
edit '-std=c++0x -march=native' "$SRC/CMakeLists.txt" 's/-std=c++0x -march=native/-std=gnu++14 -march=native/'
# 4. Build dso_dataset with OpenCV alone (upstream also requires Pangolin, only for the viewer).
edit '^if (OpenCV_FOUND AND Pangolin_FOUND)$' "$SRC/CMakeLists.txt" 's/^if (OpenCV_FOUND AND Pangolin_FOUND)$/if (OpenCV_FOUND)/'
# 5. main_dso_pangolin.cpp without Pangolin: the viewer header is replaced by a stub class of the same name that
#    does nothing (with nogui=1, as run_dso.py runs it, the viewer is never constructed).
STUB='namespace dso { namespace IOWrap { struct PangolinDSOViewer : public Output3DWrapper { PangolinDSOViewer(int, int, bool) { printf("headless build (dso_oracle): no viewer\\n"); } void run() {} }; } }'
edit '^#include "IOWrapper/Pangolin/PangolinDSOViewer.h"' "$SRC/src/main_dso_pangolin.cpp" \
    "s|^#include \"IOWrapper/Pangolin/PangolinDSOViewer.h\"|$STUB|"
# 6. A command-line switch `kfposes=0|1` for setting_onlyLogKFPoses (upstream: fixed true, so result.txt lists only
#    keyframes already marginalised). kfposes=0 lists every frame with a valid pose; the variable is read only by
#    FullSystem::printResult, so the estimation is unchanged. Without the switch the upstream default holds.
if ! grep -q 'kfposes=%d' "$SRC/src/main_dso_pangolin.cpp"; then
    sed -i 's|^    if(1==sscanf(arg,"quiet=%d",&option))$|    if(1==sscanf(arg,"kfposes=%d",\&option)) { setting_onlyLogKFPoses = (option==1); printf("ONLY KEYFRAME POSES IN result.txt: %d\\n", option); return; }\n&|' \
        "$SRC/src/main_dso_pangolin.cpp"
fi
grep -q 'kfposes=%d' "$SRC/src/main_dso_pangolin.cpp" && grep -q 'struct PangolinDSOViewer' "$SRC/src/main_dso_pangolin.cpp" \
    && grep -q '^if (OpenCV_FOUND)$' "$SRC/CMakeLists.txt" \
    && grep -q 'boost/bind.hpp' "$SRC/src/util/IndexThreadReduce.h" && grep -q 'gnu++14 -march=native' "$SRC/CMakeLists.txt" \
    && ! grep -q 'CV_LOAD_IMAGE_' "$SRC/src/IOWrapper/OpenCV/ImageRW_OpenCV.cpp" || { echo "build.sh: an edit did not apply" >&2; exit 1; }

# ---- build (upstream's CMake, Release: -O3 -g -march=native -DENABLE_SSE) ----
cmake -S "$SRC" -B "$BUILD_DIR/build" -DCMAKE_BUILD_TYPE=Release > "$BUILD_DIR/cmake.log" 2>&1
grep -- '^---' "$BUILD_DIR/cmake.log" || true
cmake --build "$BUILD_DIR/build" -j "$JOBS" --target dso_dataset
ln -sf "$BUILD_DIR/build/bin/dso_dataset" "$BUILD_DIR/dso_dataset"
echo "built $BUILD_DIR/dso_dataset (DSO $DSO_COMMIT)"
