#!/usr/bin/env bash
# The foreign DDS peers the ROS 2 node is tested against (pytest -m ros_peers): eProsima Fast DDS (the default
# middleware of ROS 2 Humble and Jazzy: the library, fastddsgen and the headless Java it runs on) and the
# Cyclone DDS C library with its IDL compiler, from Debian. Idempotent: quick when everything is installed.
set -euo pipefail
packages=(libfastrtps-dev fastddsgen fastdds-tools default-jre-headless cyclonedds-dev cyclonedds-tools
          cmake g++ make iproute2 util-linux)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
sudo_=""
[ "$(id -u)" -eq 0 ] || sudo_="sudo"
export DEBIAN_FRONTEND=noninteractive
$sudo_ apt-get update -qq
$sudo_ apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "installed: ${missing[*]}"
