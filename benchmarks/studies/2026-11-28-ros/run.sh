#!/usr/bin/env bash
# The ROS 2 node and the bags against the offline run (needs `pip install -e '.[ros]'`).
set -euo pipefail
cd "$(dirname "$0")/../../.."
here=benchmarks/studies/2026-11-28-ros
.venv/bin/python benchmarks/ros_node.py --frames 150 --rate 10 --json "$here/node_150_10hz.json"
.venv/bin/python benchmarks/ros_node.py --bags --frames 300 --json "$here/bags_300.json"
