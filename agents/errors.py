"""Errors shared by the policies and the command line."""

__all__ = ["MissingExtra"]


class MissingExtra(RuntimeError):
    """An optional dependency (the ``rl`` or ``ray`` extra) is not installed; the message says how
    to install it."""
