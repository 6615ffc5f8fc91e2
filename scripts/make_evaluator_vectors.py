"""Regenerate the evaluator test vectors shipped in nasset_sdk/evaluator_cases/ (spec/evaluator-vectors.md).

Deterministic: fixed seeds, tiny random assets, the SDK's answers. tests/sdk/test_evaluator_vectors.py
checks that the shipped files equal a fresh generation.

    python scripts/make_evaluator_vectors.py [CASE ...]
"""

from __future__ import annotations

import sys

from nasset_sdk.evaluator_vectors import VECTORS_DIR, generate

if __name__ == "__main__":
    for folder in generate(VECTORS_DIR, sys.argv[1:] or None):
        print(f"wrote {folder}")
