#!/usr/bin/env bash
# Install the Debian packages kesbrdf's optional parts need (idempotent).
#   libllvm19  - Dr.Jit's LLVM backend for Mitsuba 3 (LLVM 15/16 crash, docs/architecture.md, "Tools it runs on")
#   chromium   - headless browser for the viewer's end-to-end tests
#   glslang-tools - glslangValidator, compiles the BRDF Explorer export's GLSL in the tests
#   libx11-6 libxrender1 libxfixes3 libxi6 libxkbcommon0 - X client libraries bpy (Blender 4.5
#                as a module, kesbrdf.export.looks) links against, even headless
#   ffmpeg     - not needed: imageio-ffmpeg ships its own binary
set -euo pipefail
need=()
[ -e /usr/lib/x86_64-linux-gnu/libLLVM-19.so ] || [ -e /usr/lib/aarch64-linux-gnu/libLLVM-19.so ] || need+=(libllvm19)
command -v glslangValidator >/dev/null 2>&1 || need+=(glslang-tools)
for lib in libX11.so.6:libx11-6 libXrender.so.1:libxrender1 libXfixes.so.3:libxfixes3 libXi.so.6:libxi6 \
           libxkbcommon.so.0:libxkbcommon0; do
  [ -e "/usr/lib/$(uname -m)-linux-gnu/${lib%%:*}" ] || need+=("${lib##*:}")
done
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
