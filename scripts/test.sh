#!/usr/bin/env bash
# Install into .venv, check style and the import layering, and run the default test suite (long benchmarks are marked `slow` and skipped;
# run them with: scripts/test.sh -m slow). Extra arguments go to pytest. Tests run in NASSET_TEST_WORKERS processes
# (default 2, pytest-xdist; 0 = in this process), a test file at a time, so module fixtures are built once; the
# longest files first (tests/conftest.py: LONGEST_FILES, kept in that order by --no-loadscope-reorder).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/ruff check .
.venv/bin/lint-imports  # the layering contract in pyproject.toml: every import points down
exec .venv/bin/python -m pytest -q -p no:cacheprovider -n "${NASSET_TEST_WORKERS:-2}" --dist loadfile --no-loadscope-reorder "$@"
