#!/usr/bin/env bash
# Install Debian's ROS 1 tools (roscore, rostopic) for the TCPROS interoperability tests (pytest -m ros_peers).
# Idempotent: does nothing when roscore and rostopic are already on PATH. Needs root or passwordless sudo.
set -euo pipefail
if command -v roscore >/dev/null 2>&1 && command -v rostopic >/dev/null 2>&1; then
  echo "ros1 peers: $(command -v roscore) $(command -v rostopic)"
  exit 0
fi
. "$(dirname "$0")/_apt.sh"
apt_install setup-ros1-peers ros-core python3-rospy python3-rostopic python3-sensor-msgs
command -v roscore
command -v rostopic
