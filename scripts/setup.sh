#!/usr/bin/env bash
# Create .venv (Python 3.11) and install nasset with the extras in NASSET_EXTRAS
# (default: dev,train,mitsuba,view,blender,cluster). Installs Debian's libllvm19 for Mitsuba's llvm_ad_rgb backend
# when it is missing and apt-get is usable. Idempotent. Used by scripts/example.sh and scripts/test.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
EXTRAS=${NASSET_EXTRAS:-dev,train,mitsuba,view,blender,cluster}
PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null 2>&1 || PY=python3
"$PY" -c 'import sys; sys.exit(0 if sys.version_info[:2] >= (3, 11) else 1)' \
  || { echo "setup: Python >= 3.11 required (found $("$PY" --version))" >&2; exit 1; }

if [[ ",$EXTRAS," == *",mitsuba,"* ]] && [ ! -e /usr/lib/x86_64-linux-gnu/libLLVM-19.so ] && [ ! -e /usr/lib/x86_64-linux-gnu/libLLVM-19.so.1 ]; then
  if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    echo "setup: installing libllvm19 (Mitsuba llvm_ad_rgb backend)"
    apt-get update -qq >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19 >/dev/null \
      || echo "setup: WARNING libllvm19 not installed; Mitsuba falls back to scalar_rgb" >&2
  else
    echo "setup: WARNING libllvm19 missing and apt-get unusable; Mitsuba falls back to scalar_rgb" >&2
  fi
fi

[ -x .venv/bin/python ] || "$PY" -m venv .venv
# torch is pinned to the local CPU wheel (an unpinned torch pulls GBs of CUDA packages)
.venv/bin/python -m pip install -q -e ".[${EXTRAS}]" 2> >(grep -v '^WARNING: Location' >&2) \
  || { echo "setup: pip install failed" >&2; exit 1; }
.venv/bin/python -c 'import nasset_sdk, embreex, onnxruntime, OpenEXR' \
  || { echo "setup: install incomplete" >&2; exit 1; }
