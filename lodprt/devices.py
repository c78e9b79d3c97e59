"""Warp start-up and device choice: one place that initialises Warp quietly and resolves ``cpu``/``cuda`` names."""

from __future__ import annotations

import functools
import logging
import os
import sys
import tempfile

from lodprt.errors import LodprtError

log = logging.getLogger(__name__)

#: what Warp's native start-up wrote on stderr about CUDA (e.g. "Warp CUDA warning: Could not find or load the
#: NVIDIA CUDA driver ..." on a machine without a GPU): logged at INFO (shown with ``lodprt -v``) and named in the
#: error when a CUDA device is asked for, never printed otherwise
CUDA_NOTES: list[str] = []


@functools.cache
def warp():
    """Import and initialise Warp once, without its start-up banner and without its CUDA driver note on a CPU
    machine (kept in ``CUDA_NOTES``; any other line Warp's native start-up writes on stderr is passed on)."""
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING  # no banner, no per-module load lines
    for line in native_stderr(wp.init):
        if "CUDA" in line:
            CUDA_NOTES.append(line)
            log.info("%s", line)
        else:
            print(line, file=sys.stderr)
    return wp


def native_stderr(call) -> list[str]:
    """Run ``call()`` with file descriptor 2 (where native code prints) sent to a temporary file; its lines. When
    descriptor 2 cannot be redirected (closed), ``call()`` runs as it is and nothing is captured."""
    sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:
        call()
        return []
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        try:
            os.dup2(tmp.fileno(), 2)
            call()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        tmp.seek(0)
        text = tmp.read().decode("utf-8", "replace")
    return [line for line in text.splitlines() if line.strip()]


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
        why = f"; Warp: {' '.join(CUDA_NOTES)}" if alias.startswith("cuda") and CUDA_NOTES else ""
        raise LodprtError(f"device {name!r} is not available here (available: {', '.join(devices)}){why}")
    return alias


def load_kernels(device: str, *modules) -> float:
    """Compile or load the Warp modules ``modules`` (``lodprt.kernels.*`` module objects) on ``device`` before any
    thread launches them; returns the seconds it took. The one place kernels are loaded ahead of use: the point-light
    bake passes :func:`lodprt.precompute.baker.bake_kernels`, the transfer and volume bakes their own module."""
    import time

    wp = warp()
    t0 = time.perf_counter()
    for module in modules:
        wp.load_module(module, device=device)
    return time.perf_counter() - t0
