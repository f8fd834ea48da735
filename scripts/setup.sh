#!/usr/bin/env bash
# Installs what building, running and testing isoserve need on Debian 12, and nothing
# when it is all there already. Root runs apt-get directly; anyone else goes through sudo.
set -euo pipefail

packages=(build-essential pkg-config zlib1g-dev libmicrohttpd-dev libjansson-dev
          libdraco-dev draco libnifti2-dev python3-numpy python3-vtk9 mricron-data
          chromium wrk curl nginx python3-yaml libgdcm-dev libcurl4-openssl-dev
          python3-pydicom orthanc orthanc-dicomweb python3-matplotlib clang libmeshoptimizer-dev)
# strace holds a hierarchy write in fsync, so that tests/http kills the server inside it.
packages+=(strace)
# The web client's packages come from npm; a machine without Node.js gets Debian's.
command -v npm >/dev/null 2>&1 || packages+=(nodejs npm)

missing=()
for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    echo "setup: installing ${missing[*]}"
    sudo=""
    [ "$(id -u)" -eq 0 ] || sudo="sudo"
    export DEBIAN_FRONTEND=noninteractive
    $sudo apt-get update -qq
    $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
