#!/usr/bin/env bash
# The foreign DDS peers the ROS 2 node is tested against (pytest -m ros_peers): eProsima Fast DDS (the default
# middleware of ROS 2 Humble and Jazzy: the library, fastddsgen and the headless Java it runs on) and the
# Cyclone DDS C library with its IDL compiler, from Debian. Idempotent: quick when everything is installed.
set -euo pipefail
. "$(dirname "$0")/_apt.sh"
apt_install setup-ros-peers libfastrtps-dev fastddsgen fastdds-tools default-jre-headless cyclonedds-dev \
  cyclonedds-tools cmake g++ make iproute2 util-linux
