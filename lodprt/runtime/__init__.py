"""Stage 4, the run time: light interpolation (T-12), the camera, the view-dependent cut (T-13, T-14, S-1, S-2)
with its incremental triangulation, relighting (T-7), and environment relighting of transfer stores (P-10..P-12).
Reads stores; no OpenGL (docs/ARCHITECTURE.md)."""

from lodprt.runtime.camera import Camera
from lodprt.runtime.frames import Frame, light_coefficients, light_radiance
from lodprt.runtime.session import Runtime

__all__ = ["Camera", "Frame", "Runtime", "light_coefficients", "light_radiance"]
