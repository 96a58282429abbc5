#!/bin/sh
# Installs the one system library the stack needs: libusb-1.0 (Open3D will not import without it).
set -eu
if ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
  exit 0
fi
echo "installing libusb-1.0-0 (needed by Open3D)..." >&2
if [ "$(id -u)" = "0" ]; then SUDO=""; elif command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
  echo "error: libusb-1.0-0 is missing and neither root nor sudo is available; install it with your package manager" >&2
  exit 1
fi
if command -v apt-get >/dev/null 2>&1; then
  $SUDO apt-get update -qq && $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null
elif command -v dnf >/dev/null 2>&1; then
  $SUDO dnf install -y libusbx
elif command -v apk >/dev/null 2>&1; then
  $SUDO apk add libusb
else
  echo "error: install libusb-1.0 with your package manager" >&2
  exit 1
fi
