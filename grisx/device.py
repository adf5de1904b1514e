"""Warp initialisation and device selection, shared by every layer.

grisx runs its kernels on ``"cpu"`` by default and on ``"cuda"`` (or
``"cuda:N"``) when Warp finds a GPU. Asking for a device that is not there is a
:class:`~grisx.errors.DeviceError`, never a silent fall-back.
"""

from __future__ import annotations

import functools

import warp as wp

from grisx.errors import DeviceError

__all__ = ["init", "resolve_device", "cuda_available", "synchronize"]


@functools.cache
def init() -> None:
    """Initialise Warp once, quietly (kernel-load messages off)."""
    wp.config.quiet = True
    wp.init()


def cuda_available() -> bool:
    init()
    return wp.get_cuda_device_count() > 0


def resolve_device(device: str | None = "cpu") -> wp.context.Device:
    """Return the Warp device for a user-facing name (``cpu``, ``cuda``, ``cuda:N``)."""
    init()
    name = "cpu" if device is None else str(device)
    if name == "cpu":
        return wp.get_device("cpu")
    if name == "cuda" or name.startswith("cuda:"):
        if not cuda_available():
            raise DeviceError(f"device '{name}' requested but Warp found no CUDA device on this machine")
        try:
            return wp.get_device(name)
        except (RuntimeError, ValueError) as exc:
            raise DeviceError(f"device '{name}' is not available: {exc}") from None
    raise DeviceError(f"unknown device '{name}' (use cpu, cuda or cuda:N)")


def synchronize(device: wp.context.Device) -> None:
    """Wait for all work on ``device``; call before reading a clock."""
    wp.synchronize_device(device)
