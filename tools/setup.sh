#!/usr/bin/env bash
# Installs the system packages voxdag needs on Debian 12 (idempotent; uses sudo when not root):
# glslc (shader compiler), the Vulkan loader, lavapipe (Mesa software Vulkan) and the validation layers,
# plus what `voxdag view` and its tests (tests/viewer.rs) need: a virtual X server (Xvfb, xauth), xdotool
# to resize/close windows, and the libraries winit's X11 backend dlopens at run time (checked with
# LD_DEBUG=files: libX11, libX11-xcb, libXcursor, libXi, libxkbcommon, libxkbcommon-x11; lavapipe's
# X11 presentation needs the libxcb-* libraries that mesa-vulkan-drivers already depends on).
set -euo pipefail
packages=(glslc libvulkan1 mesa-vulkan-drivers vulkan-validationlayers
  xvfb xauth xdotool libx11-6 libx11-xcb1 libxcursor1 libxi6 libxkbcommon0 libxkbcommon-x11-0)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  echo "installing: ${missing[*]}"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
# Mitsuba 3 (scalar_rgb) for the independent-renderer check of the path tracer (tests/pathtrace.rs
# `matches_mitsuba`, which skips without it): a ~200 MB wheel, about 45 s; optional, so a failure
# (no Python, no network) only warns.
if command -v python3 >/dev/null && ! python3 -c "import mitsuba" 2>/dev/null; then
  python3 -m pip install --quiet mitsuba || echo "warning: pip install mitsuba failed: tests/pathtrace.rs matches_mitsuba will skip"
fi
