"""Stage 5, the display: the moderngl renderer, the interactive viewer and the pictures (compare, diff,
turntable). Draws run-time frames; the only stage with OpenGL (docs/ARCHITECTURE.md)."""
