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
    "SceneFileError",
    "GrisxWarning",
    "INT32_MAX",
]

#: the largest integer a kernel argument holds (Warp passes ``int`` as int32); larger values would wrap
INT32_MAX = 2**31 - 1


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


class SceneFileError(GrisxError):
    """A scene file that is malformed or uses something grisx does not support.

    The message starts with ``file:line:`` and names the element and, where
    one is at fault, the attribute or parameter; the fields hold them too.
    """

    def __init__(self, message: str, *, path: str | None = None, line: int | None = None,
                 element: str | None = None, attribute: str | None = None):
        self.path, self.line, self.element, self.attribute = path, line, element, attribute
        where = path or "<string>"
        if line is not None:
            where += f":{line}"
        what = f" <{element}>" if element else ""
        super().__init__(f"{where}:{what} {message}")


class GrisxWarning(UserWarning):
    """Something the user should know that did not stop the work (e.g. non-finite samples dropped).

    The CLI prints each as one line ``grisx: warning: ...`` on stderr.
    """
