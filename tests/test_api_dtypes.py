"""One rule for the dtypes the API returns (docs/RUNTIME.md, "What comes back"): radiance and everything a frame
carries are float32, whichever entry point made them; ``Store.coefficients`` / ``Store.complete`` are the float64
T-15 completion (the reference the run time's float32 slots are compared with); ids and triangles are integers."""

import numpy as np
import pytest

import lodprt
from lodprt.model.scene import Material, assemble_scene


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    import trimesh

    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.3)
    m = Material((0.9, 0.5, 0.2), 0.2, 8.0)
    scene = assemble_scene([("ball", ball.vertices + [0, 0.3, 0], ball.faces, m)], (6, 1.0, m),
                           {"intensity": [1.0, 1.0, 1.0]}, "lights", "ball")
    out = tmp_path_factory.mktemp("dtypes") / "s.zarr"
    lodprt.bake(scene, out, sh_order=3, device="cpu")
    return lodprt.open_store(out)


def test_radiance_is_float32_from_every_entry_point(store):
    from lodprt.runtime.frames import light_radiance

    eye, light = (0.3, 0.9, 1.0), store.light_positions[store.num_samples // 2]
    rt = lodprt.Runtime(store, device="cpu")
    rt.set_lights([light])
    rt.set_camera(eye=eye, width=160, height=120)
    frame = rt.update()
    got = {"Store.radiance": store.radiance(0, eye), "Runtime.radiance": rt.radiance(eye),
           "light_radiance": light_radiance(store, [light], eye), "Frame.radiance": frame.radiance,
           "Frame.coefficients": frame.coefficients, "Frame.positions": frame.positions,
           "Frame.normals": frame.normals, "Runtime.coefficients": rt.coefficients(),
           "Store.light_positions": store.light_positions}
    assert {k: v.dtype for k, v in got.items()} == {k: np.dtype(np.float32) for k in got}
    assert frame.triangles.dtype == np.int32 and np.issubdtype(frame.vertex_ids.dtype, np.integer)
    # the same numbers whichever way: the full-resolution radiance of the Runtime and of the function without one
    np.testing.assert_allclose(got["Runtime.radiance"], got["light_radiance"], rtol=1e-5, atol=1e-6)


def test_the_store_completion_is_the_float64_reference(store):
    c = store.coefficients(0)
    assert c.dtype == np.float64 and store.complete(0).dtype == np.float64
    np.testing.assert_array_equal(c, store.complete(0))
