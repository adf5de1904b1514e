"""Errors raised at grisx's boundary.

Every problem with user input (an unknown name, a malformed parameter, an
impossible size, a NaN or negative value where the estimator needs a finite,
non-negative one) raises a :class:`GrisxError` whose message names the
offending thing. The CLI prints that message on one line and exits non-zero.
"""

from __future__ import annotations

__all__ = [
    "GrisxError",
    "UnknownNameError",
    "InvalidParameterError",
    "InvalidValueError",
    "DeviceError",
]


class GrisxError(ValueError):
    """Base class of every error grisx raises on bad input."""


class UnknownNameError(GrisxError):
    """A problem, method, scene, parameter or metric name that grisx does not know."""

    def __init__(self, kind: str, name: str, known: list[str] | tuple[str, ...]):
        self.kind, self.name, self.known = kind, name, tuple(known)
        super().__init__(f"unknown {kind} '{name}' (known: {', '.join(self.known) or 'none'})")


class InvalidParameterError(GrisxError):
    """A parameter whose value is malformed or out of range."""


class InvalidValueError(GrisxError):
    """Data that an estimator cannot accept: NaN/Inf, negative targets or weights."""


class DeviceError(GrisxError):
    """A device that is not available (e.g. ``cuda`` on a machine without a GPU)."""
