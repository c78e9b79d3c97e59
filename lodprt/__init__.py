"""lodprt: level-of-detail based precomputed local radiance transfer.

Public API (everything else may change)::

    scene = lodprt.load_scene("demo")                 # or a TOML scene file or a mesh path
    result = lodprt.bake(scene, "out.zarr", sh_order=4, device="cpu")   # 5-degree light cut, as lodprt bake;
                                                      # full=True: every vertex (lodprt bake --full)
    store = lodprt.open_store("out.zarr")
    rgb = store.radiance(sample=0, eye=(0.0, 0.5, 1.0))   # (V, 3) float32
    rt = lodprt.Runtime(store)                        # moving lights, view cut (criterion "screen")
    rt.set_lights([(0.1, 0.3, 0.0)]); rt.set_camera((0, 0.4, 1.2), (0, 0.1, 0), fov=40, width=800, height=600)
    frame = rt.update()                               # positions, triangles, coefficients, radiance, stats
    with lodprt.Renderer() as r:                      # offscreen EGL (docs/DISPLAY.md)
        png = r.image(frame)                          # (H, W, 3) uint8 sRGB; linear=True: float32 radiance

    env = lodprt.load_environment("sky")              # or a lat-long .hdr/.exr/.npy, a cube map (docs/ENVIRONMENT.md)
    lodprt.bake_transfer(scene, "env.zarr", sh_order=3, mode="interreflected", environment=env)
    rgb = lodprt.relit_radiance(lodprt.open_transfer("env.zarr"), env.project(3), eye=(0, 0.5, 1))  # (V, 3)

    lodprt.export_glb(store, "lit.glb", sample=0, eye=(0, 0.5, 1))  # mesh, COLOR_0, _SH_i (docs/EXPORT.md)

    vol = lodprt.load_volume("cloud")                 # or a .npy density grid + bounds (docs/VOLUMES.md)
    lodprt.bake_volume(vol, "cloud.zarr", sh_order=3, rays=128, bounces=2)
    lodprt.bake_neighbourhood(scene, "bunny", "near.zarr", grid=(16, 16, 16))   # transfer around one object

Names are imported on first use, so ``import lodprt`` stays cheap (Warp loads only when a kernel is needed).
"""

import importlib

from lodprt.errors import LodprtError, SceneError, StoreError

_LAZY = {
    "Scene": "lodprt.model.scene",
    "load_scene": "lodprt.model.scene",
    "bake": "lodprt.precompute.bake",
    "BakeResult": "lodprt.precompute.bake",
    "Store": "lodprt.store.bake_store",
    "open_store": "lodprt.store.bake_store",
    "Runtime": "lodprt.runtime.session",
    "ScreenCriterion": "lodprt.runtime.criteria",
    "ThesisCriterion": "lodprt.runtime.criteria",
    "Camera": "lodprt.runtime.camera",
    "Frame": "lodprt.runtime.frames",
    "LightInterpolator": "lodprt.runtime.lights",
    "Renderer": "lodprt.display.render",
    "Environment": "lodprt.model.environment",
    "load_environment": "lodprt.model.environment",
    "bake_transfer": "lodprt.precompute.transfer",
    "open_transfer": "lodprt.runtime.environment_relight",
    "relit_radiance": "lodprt.runtime.environment_relight",
    "export_glb": "lodprt.display.export",
    "Volume": "lodprt.model.volume",
    "load_volume": "lodprt.model.volume",
    "bake_volume": "lodprt.precompute.volume",
    "VolumeStore": "lodprt.store.volume_store",
    "bake_neighbourhood": "lodprt.precompute.neighbourhood",
    "NeighbourhoodStore": "lodprt.store.neighbourhood_store",
}

__all__ = ["LodprtError", "SceneError", "StoreError", *_LAZY]

from lodprt.version import __version__  # noqa: E402  (re-exported)


def __getattr__(name):
    if name == "open":  # deprecated: it shadows the builtin; kept for one release
        import warnings

        warnings.warn("lodprt.open is deprecated; use lodprt.open_store", DeprecationWarning, stacklevel=2)
        name = "open_store"
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'lodprt' has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
