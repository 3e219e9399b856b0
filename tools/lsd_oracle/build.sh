#!/usr/bin/env bash
# Build upstream LSD-SLAM's lsd_slam_core (no ROS) plus our driver `lsd_oracle` — a developer test oracle.
#
# Not part of dmtrack, of its install or of CI. LSD-SLAM is GPL-3.0: its sources are cloned into the build
# folder by this script and never enter the dmtrack repository. What lives here is ours: this script, the
# CMake file, the driver main (lsd_oracle_main.cpp) and the compile-only source edits applied below.
#
#   tools/lsd_oracle/build.sh                      # clones from GitHub into tools/lsd_oracle/_build
#   LSD_SLAM_REPO=/path/to/lsd_slam.git G2O_REPO=/path/to/g2o.git tools/lsd_oracle/build.sh   # local mirrors
#   BUILD_DIR=/tmp/lsd JOBS=4 tools/lsd_oracle/build.sh
#
# Needs (Debian 12): g++ cmake git libeigen3-dev libsuitesparse-dev libboost-thread-dev libboost-system-dev
# libopencv-dev. g2o takes ~10 min with 2 cores, the LSD-SLAM library ~1.5 min.
set -euo pipefail
HERE="$(cd "$(dirname "$0")" && pwd)"
BUILD_DIR="${BUILD_DIR:-$HERE/_build}"
JOBS="${JOBS:-$(nproc)}"
LSD_SLAM_REPO="${LSD_SLAM_REPO:-https://github.com/tum-vision/lsd_slam.git}"
LSD_SLAM_COMMIT="d1e6f0e1a027889985d2e6b4c0fe7a90b0c75067"
G2O_REPO="${G2O_REPO:-https://github.com/RainerKuemmerle/g2o.git}"
G2O_COMMIT="17fce87df9d5b2aa7b4239be1fbac9d40c95d72f"   # tag 20170730_git

mkdir -p "$BUILD_DIR/src"
fetch() {  # fetch URL COMMIT DIR
    if [ ! -d "$3/.git" ]; then git clone --quiet --no-checkout "$1" "$3"; fi
    git -C "$3" -c advice.detachedHead=false checkout --quiet --force "$2"
}
fetch "$G2O_REPO" "$G2O_COMMIT" "$BUILD_DIR/src/g2o"
fetch "$LSD_SLAM_REPO" "$LSD_SLAM_COMMIT" "$BUILD_DIR/src/lsd_slam"

# ---- g2o (last release with the raw-pointer solver API LSD-SLAM calls) ----
if [ ! -f "$BUILD_DIR/g2o-install/lib/libg2o_core.so" ]; then
    cmake -S "$BUILD_DIR/src/g2o" -B "$BUILD_DIR/g2o-build" -DCMAKE_BUILD_TYPE=Release \
        -DCMAKE_INSTALL_PREFIX="$BUILD_DIR/g2o-install" -DG2O_BUILD_APPS=OFF -DG2O_BUILD_EXAMPLES=OFF \
        -DG2O_USE_OPENGL=OFF -DBUILD_WITH_MARCH_NATIVE=ON -DCMAKE_CXX_FLAGS="-w" > "$BUILD_DIR/g2o-cmake.log"
    cmake --build "$BUILD_DIR/g2o-build" -j "$JOBS" > "$BUILD_DIR/g2o-build.log"
    cmake --install "$BUILD_DIR/g2o-build" > /dev/null
fi

# ---- compile-only edits to LSD-SLAM for OpenCV 4 / Boost 1.74 (no algorithmic change) ----
CORE="$BUILD_DIR/src/lsd_slam/lsd_slam_core"
grep -rl 'CV_GRAY2RGB' "$CORE/src" | xargs -r sed -i 's/CV_GRAY2RGB/cv::COLOR_GRAY2RGB/g'
grep -rl 'cvPoint\|CV_FONT_HERSHEY_SIMPLEX' "$CORE/src" | xargs -r sed -i \
    -e 's/cvPoint(/cv::Point(/g' -e 's/CV_FONT_HERSHEY_SIMPLEX/cv::FONT_HERSHEY_SIMPLEX/g'
grep -q 'boost/bind.hpp' "$CORE/src/util/IndexThreadReduce.h" || \
    sed -i 's|#include "boost/thread.hpp"|#include "boost/thread.hpp"\n#include <boost/bind.hpp>|' \
        "$CORE/src/util/IndexThreadReduce.h"
# Trace hooks: one call at the end of SE3Tracker::trackFrame, one at the end of DepthMap::updateKeyframe and
# DepthMap::createKeyFrame (the driver implements them; they read only public state).
if ! grep -q lsdOracleTraceTrack "$CORE/src/Tracking/SE3Tracker.cpp"; then
    python3 "$HERE/add_hooks.py" "$CORE"
fi

# ---- the library and the driver (our CMake file) ----
cmake -S "$HERE" -B "$BUILD_DIR/lsd-build" -DCMAKE_BUILD_TYPE=Release -DLSD_CORE="$CORE" \
    -DG2O_ROOT="$BUILD_DIR/g2o-install" > "$BUILD_DIR/lsd-cmake.log"
cmake --build "$BUILD_DIR/lsd-build" -j "$JOBS"
ln -sf "$BUILD_DIR/lsd-build/lsd_oracle" "$BUILD_DIR/lsd_oracle"
echo "built $BUILD_DIR/lsd_oracle"
