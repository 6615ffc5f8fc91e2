"""Validation findings and the report (JSON form documented in spec/validation.md#report)."""

from __future__ import annotations

from dataclasses import dataclass, field

SEVERITIES = ("error", "warning", "info")


@dataclass(frozen=True)
class Finding:
    """One rule violation, located by prim path and attribute (either may be None)."""

    code: str
    severity: str
    message: str
    prim: str | None = None
    attribute: str | None = None

    def location(self) -> str:
        loc = self.prim or ""
        if self.attribute:
            loc += f".{self.attribute}"
        return loc

    def to_dict(self) -> dict:
        return {"code": self.code, "severity": self.severity, "message": self.message,
                "prim": self.prim, "attribute": self.attribute}

    def __str__(self) -> str:
        loc = self.location()
        return f"{self.severity:<7} [{self.code}] {loc + ': ' if loc else ''}{self.message}"


@dataclass
class Report:
    """Findings of one validation run. ``ok`` is True when no finding is an error."""

    file: str
    findings: list[Finding] = field(default_factory=list)
    spec_version: str | None = None
    kind: str | None = None
    variant: str | None = None
    checked: dict = field(default_factory=dict)  # what was covered: components, qualities, networks, tensors
    _keys: set = field(default_factory=set, repr=False, compare=False)  # of the findings: one lookup per add

    def add(self, finding: Finding) -> None:
        key = (finding.code, finding.prim, finding.attribute, finding.message)
        if key not in self._keys:
            self._keys.add(key)
            self.findings.append(finding)

    @property
    def counts(self) -> dict[str, int]:
        out = {s: 0 for s in SEVERITIES}
        for f in self.findings:
            out[f.severity] += 1
        return out

    @property
    def ok(self) -> bool:
        return not any(f.severity == "error" for f in self.findings)

    @property
    def errors(self) -> list[Finding]:
        return [f for f in self.findings if f.severity == "error"]

    def codes(self, severity: str | None = None) -> set[str]:
        return {f.code for f in self.findings if severity is None or f.severity == severity}

    def to_dict(self) -> dict:
        return {
            "file": self.file,
            "ok": self.ok,
            "specVersion": self.spec_version,
            "kind": self.kind,
            "variant": self.variant,
            "counts": self.counts,
            "checked": self.checked,
            "findings": [f.to_dict() for f in self.findings],
        }

    def format_text(self) -> str:
        c = self.counts
        head = f"{self.file}: {'valid' if self.ok else 'INVALID'} ({c['error']} errors, {c['warning']} warnings, {c['info']} info)"
        return "\n".join([head] + [f"  {f}" for f in self.findings])
