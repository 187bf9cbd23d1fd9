#!/usr/bin/env bash
# Install the Debian packages kesbrdf's optional parts need (idempotent).
#   libllvm19  - Dr.Jit's LLVM backend for Mitsuba 3 (LLVM 15/16 crash, DESIGN §7)
#   chromium   - headless browser for the viewer's end-to-end tests
#   glslang-tools - glslangValidator, compiles the BRDF Explorer export's GLSL in the tests
#   ffmpeg     - not needed: imageio-ffmpeg ships its own binary
set -euo pipefail
need=()
[ -e /usr/lib/x86_64-linux-gnu/libLLVM-19.so ] || [ -e /usr/lib/aarch64-linux-gnu/libLLVM-19.so ] || need+=(libllvm19)
command -v glslangValidator >/dev/null 2>&1 || need+=(glslang-tools)
if [ "${KESBRDF_NO_BROWSER:-0}" != 1 ]; then
  command -v chromium >/dev/null 2>&1 || need+=(chromium)
fi
if [ ${#need[@]} -eq 0 ]; then
  exit 0
fi
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi
echo "kesbrdf setup: installing Debian packages: ${need[*]}"
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need[@]}" >/dev/null
