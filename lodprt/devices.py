"""Warp start-up and device choice: one place that initialises Warp quietly and resolves ``cpu``/``cuda`` names."""

from __future__ import annotations

import functools

from lodprt.errors import LodprtError


@functools.cache
def warp():
    """Import and initialise Warp once, without its start-up banner."""
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING  # no banner, no per-module load lines
    wp.init()
    return wp


def available_devices() -> list[str]:
    """Aliases of every Warp device here, e.g. ``["cpu", "cuda:0"]``."""
    return [d.alias for d in warp().get_devices()]


def resolve_device(name: str | None = None) -> str:
    """``None`` -> the first CUDA device when there is one, else ``cpu``; ``cuda`` -> ``cuda:0``.

    Raises LodprtError with the list of devices when the name is not available here.
    """
    devices = available_devices()
    if name is None:
        return next((d for d in devices if d.startswith("cuda")), "cpu")
    alias = "cuda:0" if name == "cuda" else name
    if alias not in devices:
        raise LodprtError(f"device {name!r} is not available here (available: {', '.join(devices)})")
    return alias
