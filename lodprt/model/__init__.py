"""Stage 1, the model: scenes and meshes, SH maths, the vertex hierarchy's data and construction, environment maps,
coefficient completion (T-15), irradiance maths. No OpenGL and no Warp launches; imports only ``lodprt.errors``
and ``lodprt.devices`` above itself (docs/ARCHITECTURE.md)."""
