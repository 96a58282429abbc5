#!/bin/sh
# Installs the system libraries the stack loads that no Python wheel bundles (the Dockerfile installs
# the same): libusb-1.0 (Open3D does not import without it), libEGL and libGL (Open3D's library links
# them; dense frames are ray-cast with it) and libgomp (OpenMP of Open3D, OpenCV, GTSAM).
set -eu
missing=""
for lib in libusb-1.0.so.0 libEGL.so.1 libGL.so.1 libgomp.so.1; do
  ldconfig -p 2>/dev/null | grep -q "$lib" || missing="$missing $lib"
done
[ -z "$missing" ] && exit 0
echo "installing the system libraries$missing..." >&2
if [ "$(id -u)" = "0" ]; then SUDO=""; elif command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
  echo "error:$missing missing and neither root nor sudo is available; install libusb-1.0, libEGL, libGL and libgomp with your package manager" >&2
  exit 1
fi
if command -v apt-get >/dev/null 2>&1; then
  $SUDO apt-get update -qq && $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 libegl1 libgl1 libgomp1 >/dev/null
elif command -v dnf >/dev/null 2>&1; then
  $SUDO dnf install -y libusbx mesa-libEGL mesa-libGL libgomp
elif command -v apk >/dev/null 2>&1; then
  $SUDO apk add libusb mesa-egl mesa-gl libgomp
else
  echo "error: install libusb-1.0, libEGL, libGL and libgomp with your package manager" >&2
  exit 1
fi
