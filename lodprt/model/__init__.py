"""Stage 1, the model: scenes and meshes, SH maths, the vertex hierarchy's data and construction, environment maps,
coefficient completion (T-15), irradiance maths. No OpenGL; its Warp launches (the hierarchy's collapse rounds, the
completion plan's weights and waves) run on the CPU on views of its numpy arrays. Imports only ``lodprt.errors``,
``lodprt.devices``, ``lodprt.launches`` and its kernels (``lodprt.kernels``) above itself (docs/ARCHITECTURE.md)."""
