#!/usr/bin/env bash
# Create .venv (Python 3.11) and install nasset with the extras in NASSET_EXTRAS
# (default: dev,render,bench,train,mitsuba,view,blender,cluster). Installs Debian's libllvm19 for Mitsuba's llvm_ad_rgb backend
# when it is missing and apt-get is usable, and the Node.js host of the portable evaluation graph
# (tools/portable-host: onnxruntime-web from npm, pinned by its package-lock.json, into its ignored
# node_modules; Debian's nodejs + npm when node is missing), and for the web viewer's tests Debian's chromium
# and tools/web-viewer's npm packages (three.js, onnxruntime-web, esbuild, playwright-core; no browser is
# downloaded: the tests drive /usr/bin/chromium). Idempotent. Used by scripts/example.sh and scripts/test.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
EXTRAS=${NASSET_EXTRAS:-dev,render,bench,train,mitsuba,view,blender,cluster}
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
.venv/bin/python -c 'import sys, nasset_sdk, onnxruntime, OpenEXR
from nasset_sdk.extras import missing_packages
missing = missing_packages(*sys.argv[1].split(","))
sys.exit(f"missing: {missing}" if missing else 0)' "$EXTRAS" \
  || { echo "setup: install incomplete" >&2; exit 1; }

# Node.js host of the portable evaluation graph (tests/sdk/test_portable_host.py; docs/interop.md)
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
  if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    echo "setup: installing nodejs and npm (portable graph host)"
    apt-get update -qq >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq nodejs npm >/dev/null \
      || echo "setup: WARNING nodejs/npm not installed; the portable host test fails in CI" >&2
  else
    echo "setup: WARNING node/npm missing and apt-get unusable; the portable host test skips outside CI" >&2
  fi
fi
HOST=tools/portable-host
if command -v npm >/dev/null 2>&1 && { [ ! -d "$HOST/node_modules/onnxruntime-web" ] \
     || [ "$HOST/package-lock.json" -nt "$HOST/node_modules/.package-lock.json" ]; }; then
  # --ignore-scripts: no install scripts run; the host needs only the packages' JavaScript and WASM files
  (cd "$HOST" && npm ci --ignore-scripts --no-audit --no-fund --loglevel=error >/dev/null) \
    || { echo "setup: npm ci in $HOST failed" >&2; exit 1; }
fi

# Web viewer (nasset web; tests/sdk/test_web.py): Debian's chromium for the headless page tests, and the page's
# npm packages (build: three, onnxruntime-web, esbuild; test driver: playwright-core, which never downloads a browser)
if [ ! -x /usr/bin/chromium ]; then
  if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    echo "setup: installing chromium (headless tests of the web viewer)"
    apt-get update -qq >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium >/dev/null \
      || echo "setup: WARNING chromium not installed; the web viewer's browser tests fail in CI" >&2
  else
    echo "setup: WARNING /usr/bin/chromium missing and apt-get unusable; the web viewer's browser tests skip outside CI" >&2
  fi
fi
VIEWER=tools/web-viewer
if command -v npm >/dev/null 2>&1 && { [ ! -d "$VIEWER/node_modules/playwright-core" ] \
     || [ "$VIEWER/package-lock.json" -nt "$VIEWER/node_modules/.package-lock.json" ]; }; then
  # --ignore-scripts: no install scripts (playwright-core's would not download browsers anyway; esbuild finds its binary package)
  (cd "$VIEWER" && npm ci --ignore-scripts --no-audit --no-fund --loglevel=error >/dev/null) \
    || { echo "setup: npm ci in $VIEWER failed" >&2; exit 1; }
fi
