"""Placeholder until this benchmark lands (replaced by its implementation)."""

from nasset_sdk.errors import UsageError


def add_args(p) -> None:
    pass


def run(args) -> int:
    raise UsageError("this benchmark is not implemented yet")
