#!/usr/bin/env bash
# Install into .venv, check style and the import layering, and run the default test suite (long benchmarks are marked `slow` and skipped;
# run them with: scripts/test.sh -m slow). Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/ruff check .
.venv/bin/lint-imports  # the layering contract in pyproject.toml: every import points down
exec .venv/bin/python -m pytest -q -p no:cacheprovider "$@"
