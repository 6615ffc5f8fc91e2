"""Asset validation (spec/validation.md): a list of rules with stable codes, run over one file.

    report = validate_file("asset.usdc")
    report.ok, report.counts, report.findings, report.to_dict()
"""

from __future__ import annotations

import os

from .report import SEVERITIES, Finding, Report
from .rules import RULE_BY_CODE, RULES, Rule, Validation, path_escapes


def validate_file(path: str | os.PathLike, *, usd_checks: bool = False, probe: bool = True,
                  probe_timeout: float | None = None, network_probe_timeout: float | None = None) -> Report:
    """Validate an asset file; never raises for a malformed file, every problem is a finding.

    ``probe`` first opens the file in a child process (nasset_sdk.safeopen) so a corrupted crate
    that crashes usd-core yields FILE_UNREADABLE instead of killing this process; turn it off only
    for files this process wrote. ``usd_checks`` adds OpenUSD's own validators (USD_CHECK).
    ``network_probe_timeout`` bounds the child that runs every network (nasset_sdk.netprobe).
    """
    from ..errors import path_arg

    path = path_arg(path, "validate_file: the asset")
    kw = {} if probe_timeout is None else {"probe_timeout": float(probe_timeout)}
    if network_probe_timeout is not None:
        kw["network_probe_timeout"] = float(network_probe_timeout)
    return Validation(os.fspath(path), usd_checks=usd_checks, probe=probe, **kw).run()


def rules_table() -> list[dict]:
    """Every rule as a dict: code, severity, description, spec."""
    return [r.to_dict() for r in RULES]


__all__ = ["Finding", "Report", "Rule", "RULES", "RULE_BY_CODE", "SEVERITIES", "path_escapes", "rules_table", "validate_file"]
