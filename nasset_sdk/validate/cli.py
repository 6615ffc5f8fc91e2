"""``nasset validate FILE [--json] [--usd-checks]`` and ``nasset validate --dump-rules [--json]``.

Exit status: 0 when the asset has no error findings, 1 otherwise, 2 for usage errors.
"""

from __future__ import annotations

import json

from ..errors import UsageError
from . import rules_table, validate_file


def format_rules() -> str:
    rows = rules_table()
    w_code = max(len(r["code"]) for r in rows)
    w_spec = max(len(r["spec"]) for r in rows)
    lines = [f"{'code':<{w_code}}  {'severity':<8}  {'spec':<{w_spec}}  description"]
    lines += [f"{r['code']:<{w_code}}  {r['severity']:<8}  {r['spec']:<{w_spec}}  {r['description']}" for r in rows]
    return "\n".join(lines)


def run(args) -> int:
    if getattr(args, "dump_rules", False):
        print(json.dumps(rules_table(), indent=2) if args.json else format_rules())
        return 0
    if not args.file:
        raise UsageError("validate needs a FILE (or --dump-rules)")
    report = validate_file(args.file, usd_checks=bool(getattr(args, "usd_checks", False)))
    print(json.dumps(report.to_dict(), indent=2) if args.json else report.format_text())
    return 0 if report.ok else 1
