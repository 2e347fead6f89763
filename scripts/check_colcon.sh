#!/usr/bin/env bash
# Checks the ament layout the way a full ROS 2 install builds it: `colcon build` of a clean clone
# against the venv's ROS wheels, then looks for the node executables where `ros2 run` finds them.
# Not part of `make test` (it rebuilds the messages, ~2 min); run it after layout changes.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
WS="$(mktemp -d)"
trap 'rm -rf "$WS"' EXIT
bash "$ROOT/scripts/setup.sh"
python3 -m venv "$WS/colcon-venv"
"$WS/colcon-venv/bin/pip" install -q "colcon-common-extensions==0.3.0"
git clone -q "$ROOT" "$WS/src"
cd "$WS/src"
PATH="$ROOT/.venv/bin:$PATH" AMENT_PREFIX_PATH="$ROOT/.venv" CMAKE_PREFIX_PATH="$ROOT/.venv" \
  "$WS/colcon-venv/bin/colcon" build --base-paths src --build-base "$WS/build" --install-base "$WS/install"
for exe in $(sed -n 's/^ *"\([a-z_]*\) = ins_gnss_ros\.nodes\..*/\1/p' src/ins_gnss_ros/setup.py); do
  test -x "$WS/install/ins_gnss_ros/lib/ins_gnss_ros/$exe" || { echo "missing $exe"; exit 1; }
done
test -f "$WS/install/ins_gnss_ros/share/ins_gnss_ros/config/default.yaml"
test -d "$WS/install/ins_gnss_msgs/share/ins_gnss_msgs/msg"
echo "colcon layout ok: $(ls "$WS/install/ins_gnss_ros/lib/ins_gnss_ros" | tr '\n' ' ')"
