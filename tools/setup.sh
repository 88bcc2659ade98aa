#!/usr/bin/env bash
# Installs the system packages voxdag needs on Debian 12 (idempotent; uses sudo when not root):
# glslc (shader compiler), the Vulkan loader, lavapipe (Mesa software Vulkan) and the validation layers.
set -euo pipefail
packages=(glslc libvulkan1 mesa-vulkan-drivers vulkan-validationlayers)
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
