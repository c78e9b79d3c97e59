"""Full-resolution bake: Phong SH kernels against float64 references, extreme cases, layout choices."""

import numpy as np
import pytest

from lodprt.model import sh

from lodprt.precompute import reference
from lodprt.precompute.bake import bake
from lodprt.devices import load_kernels
from lodprt.precompute.baker import Baker, bake_kernels, material_tables
from lodprt.kernels import shading as kshade
from lodprt.kernels.visibility import LIT
from lodprt.devices import warp
from lodprt.errors import LodprtError
from lodprt.model.scene import THESIS_MATERIAL, Material, assemble_scene, load_mesh


def small_scene(bunny_path, material=THESIS_MATERIAL, floor=40, lights=None):
    pos, faces = load_mesh(bunny_path)
    return assemble_scene([("bunny", pos, faces, material)], (floor, 0.5, material), lights or {}, "lights", "bunny")


def bake_one(scene, device, order, light):
    load_kernels(device, *bake_kernels())
    ids = np.arange(scene.num_vertices, dtype=np.int32)
    baker = Baker(scene, order, device, ids)
    return baker.sample(light)


@pytest.mark.parametrize("order", [1, 4, 8])
def test_phong_sh_matches_float64_reference(device, bunny_path, order):
    """Closed-form float32 kernel coefficients equal the float64 numpy closed form on bunny + floor."""
    scene = small_scene(bunny_path)
    light = scene.lights.positions[4]
    coeffs, vis = bake_one(scene, device, order, light)
    assert coeffs.shape == (scene.num_vertices, 1, order * order)
    ref = reference.phong_coefficients(scene, light, order, vis)
    scale = np.abs(ref).max()
    np.testing.assert_allclose(coeffs[:, 0], ref, atol=2e-5 * scale, rtol=1e-4)


@pytest.mark.warp_debug
def test_closed_form_equals_quadrature_kernel(device, bunny_path):
    """The closed-form projection equals the quadrature projection of the same Phong radiance (kernel vs kernel)."""
    wp = warp()
    scene = small_scene(bunny_path, material=Material(kd=(0.88,) * 3, ks=0.19, shininess=7.5))
    light = scene.lights.positions[0]
    order = 4
    coeffs, vis = bake_one(scene, device, order, light)
    sel = np.flatnonzero(vis == LIT)[::50].astype(np.int32)
    dirs, weights = sh.quadrature(96)
    y = sh.basis(dirs, order).astype(np.float32)
    tables = material_tables(scene.materials, order, 1)
    out = wp.zeros((len(sel), 1, order * order), dtype=wp.float32, device=device)
    wp.launch(
        kshade.phong_sh_quadrature,
        dim=len(sel),
        inputs=[
            wp.array(scene.positions.astype(np.float32), dtype=wp.vec3, device=device),
            wp.array(scene.normals.astype(np.float32), dtype=wp.vec3, device=device),
            wp.array(scene.material_id, dtype=wp.int32, device=device),
            wp.array(sel, dtype=wp.int32, device=device),
            wp.array(np.full(len(sel), LIT, np.uint8), dtype=wp.uint8, device=device),
            wp.array(tables["kd"], dtype=wp.float32, device=device),
            wp.array(tables["ks"], dtype=wp.float32, device=device),
            wp.array(tables["shininess"], dtype=wp.float32, device=device),
            wp.vec3(*light),
            1,
            float(scene.lights.radius),
            wp.array(dirs.astype(np.float32), dtype=wp.vec3, device=device),
            wp.array(weights.astype(np.float32), dtype=wp.float32, device=device),
            wp.array(y, dtype=wp.float32, device=device),
        ],
        outputs=[out],
        device=device,
    )
    quad = out.numpy()
    scale = np.abs(coeffs[sel]).max()
    np.testing.assert_allclose(quad, coeffs[sel], atol=2e-3 * scale)


def test_reconstruction_within_truncation_error(device, bunny_path):
    """Baked-then-reconstructed radiance matches direct Phong up to the float64 SH truncation error of the lobe."""
    scene = small_scene(bunny_path)
    light = scene.lights.positions[2]
    order = 6
    coeffs, vis = bake_one(scene, device, order, light)
    lit = np.flatnonzero(vis == LIT)[::7]
    rng = np.random.default_rng(3)
    eyes = rng.normal(size=(len(lit), 3))
    eyes /= np.linalg.norm(eyes, axis=1, keepdims=True)
    p, n = scene.positions[lit], scene.normals[lit]
    to = light - p
    d = np.linalg.norm(to, axis=1)
    l = to / d[:, None]
    e = 1 / d**2
    r = 2 * (n * l).sum(1)[:, None] * n - l
    m = THESIS_MATERIAL
    direct = e * (m.kd[0] * (n * l).sum(1) + m.ks * np.clip((r * eyes).sum(1), 0, None) ** m.shininess)
    y = sh.basis(eyes, order)
    ours = (coeffs[lit, 0] * y).sum(1)
    trunc = e * m.kd[0] * (n * l).sum(1) + e * m.ks * (sh.cosine_power_lobe(r, m.shininess, order) * y).sum(1)
    bound = np.abs(trunc - direct) + 1e-4 * np.abs(direct).max()
    assert (np.abs(ours - direct) <= bound).all()
    # and the truncation error itself falls with the order
    errs = [np.abs(e * m.ks * ((sh.cosine_power_lobe(r, 2, k) * sh.basis(eyes, k)).sum(1)) - (direct - e * m.kd[0] * (n * l).sum(1))).mean() for k in (2, 4, 8)]
    assert errs[0] > errs[1] > errs[2]


@pytest.mark.parametrize("shininess", [1, 2, 10, 100, 1000])
def test_shininess_extremes_finite(device, shininess):
    """Shininess 1 to 1000: coefficients finite, reconstruction at R close to the lobe's captured energy."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1.0]])
    mat = Material(kd=(0.5,) * 3, ks=1.0, shininess=float(shininess))
    scene = assemble_scene([("tri", pos, np.array([[0, 2, 1]]), mat)], None, {}, "lights", "tri")
    coeffs, vis = bake_one(scene, device, 8, np.array([0.3, 1.0, 0.3]))
    assert np.isfinite(coeffs).all()
    assert (vis == LIT).all()
    energy = sh.lobe_energy_captured(shininess, 8)
    assert 0 < energy <= 1


def test_light_on_vertex_and_surface_stays_finite(device):
    """A light exactly at a vertex, on a face and a hair above it: finite coefficients, falloff capped by the radius."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1.0]])
    scene = assemble_scene([("quad", pos, np.array([[0, 2, 1], [1, 2, 3]]), THESIS_MATERIAL)], None, {}, "lights", "quad")
    radius = scene.lights.radius
    for light in (pos[0], np.array([0.4, 0.0, 0.3]), np.array([0.0, 1e-9, 0.0])):
        coeffs, vis = bake_one(scene, device, 4, light)
        assert np.isfinite(coeffs).all()
        c0 = coeffs[0, 0, 0]
        assert c0 <= np.sqrt(4 * np.pi) * 0.88 / radius**2 * 1.0001 + 0.19 * 4 / radius**2


@pytest.mark.warp_debug
def test_single_triangle_duplicated_vertices_nonmanifold(device):
    """A single triangle, duplicated vertices (equal coefficients) and a non-manifold edge bake without NaN."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1], [0, 0, 0], [0, 1, 0.5], [0, -1, 0.5]])
    # faces 0-2 share edge (0, 2)... three faces on one edge (non-manifold); vertex 3 duplicates vertex 0
    faces = np.array([[0, 2, 1], [3, 2, 1], [0, 2, 4], [0, 2, 5]])
    scene = assemble_scene([("nm", pos, faces, THESIS_MATERIAL)], None, {}, "lights", "nm")
    coeffs, vis = bake_one(scene, device, 4, np.array([0.5, 2.0, 0.5]))
    assert np.isfinite(coeffs).all() and np.isfinite(scene.normals).all()
    single = assemble_scene([("tri", pos[:3], faces[:1], THESIS_MATERIAL)], None, {}, "lights", "tri")
    c1, _ = bake_one(single, device, 4, np.array([0.5, 2.0, 0.5]))
    assert np.isfinite(c1).all() and (c1[:, 0, 0] > 0).all()


@pytest.mark.warp_debug
def test_layout_leaves_out_what_the_scene_does_not_need(tmp_path, device):
    """Diffuse-only scenes store 1 coefficient; grey scenes 1 channel; coloured scenes 3 channels in kd's ratio."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1.0]])
    tri = np.array([[0, 2, 1]])
    light = {"box": [0, 1, 0, 1, 2, 1], "grid": [1, 1, 1]}
    diffuse = assemble_scene([("t", pos, tri, Material((0.5,) * 3, 0.0, 2.0))], None, light, "lights", "t")
    res = bake(diffuse, tmp_path / "d.zarr", sh_order=4, device=device, full=True)
    assert (res.coefficients_per_vertex, res.channels) == (1, 1)
    colour = assemble_scene([("t", pos, tri, Material((0.6, 0.3, 0.15), 0.2, 2.0))], None, light, "lights", "t")
    res = bake(colour, tmp_path / "c.zarr", sh_order=3, device=device, full=True)
    assert (res.coefficients_per_vertex, res.channels) == (9, 3)
    from lodprt.store.bake_store import open_store

    _, c = open_store(tmp_path / "c.zarr").sample(0)
    # the specular lobe adds the same to every channel, so channel differences are kd differences
    ratio = (c[:, 0, 0] - c[:, 1, 0]) / (c[:, 1, 0] - c[:, 2, 0])
    np.testing.assert_allclose(ratio, (0.6 - 0.3) / (0.3 - 0.15), rtol=1e-4)
    np.testing.assert_allclose(c[:, 0, 1:], c[:, 2, 1:], rtol=1e-6)


def test_grazing_light_is_finite(device):
    """A light in (or a hair above) the plane of a flat patch: finite, equal to the float64 closed form (specular only)."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1.0]])
    scene = assemble_scene([("quad", pos, np.array([[0, 2, 1], [1, 2, 3]]), THESIS_MATERIAL)], None, {}, "lights", "quad")
    for light in (np.array([3.0, 0.0, 0.5]), np.array([3.0, 1e-6, 0.5])):
        coeffs, vis = bake_one(scene, device, 4, light)
        assert np.isfinite(coeffs).all()
        ref = reference.phong_coefficients(scene, light, 4, vis)
        np.testing.assert_allclose(coeffs[:, 0], ref, atol=1e-6)


@pytest.mark.parametrize("scale", [1e-4, 1e4])
def test_bake_scales_with_the_scene(device, bunny_path, scale):
    """Scaling the scene by s scales every coefficient by 1/s^2 (inverse-square falloff) and keeps visibility."""
    pos, faces = load_mesh(bunny_path)
    ref = assemble_scene([("b", pos, faces, THESIS_MATERIAL)], (30, 0.5, THESIS_MATERIAL), {}, "lights", "b")
    big = assemble_scene([("b", pos * scale, faces, THESIS_MATERIAL)], (30, 0.5, THESIS_MATERIAL), {}, "lights", "b")
    c1, v1 = bake_one(ref, device, 4, ref.lights.positions[4])
    c2, v2 = bake_one(big, device, 4, big.lights.positions[4])
    assert np.mean(v1 != v2) < 1e-3
    same = (v1 == v2)
    np.testing.assert_allclose(c2[same] * scale**2, c1[same], rtol=2e-4, atol=1e-4 * np.abs(c1).max())


def test_lodprt_bake_is_the_function_after_the_module_is_imported():
    """``lodprt.bake(...)`` is the bake function whatever was imported first (the bake module lives in
    ``lodprt.precompute``, so nothing rebinds the public name)."""
    import lodprt
    import lodprt.precompute.bake as module

    assert lodprt.bake is module.bake and callable(lodprt.bake)
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1.0]])
    scene = assemble_scene([("tri", pos, np.array([[0, 2, 1]]), THESIS_MATERIAL)], None, {}, "lights", "tri")
    with pytest.raises(LodprtError, match="threshold_deg"):
        lodprt.bake(scene, None, device="cpu", hierarchy=False, threshold_deg=30.0)


def test_ray_offset_is_a_python_float_far_from_the_origin():
    """A small scene far from the origin: the float32-resolution ray offset is a Python float (attributes are JSON)."""
    from lodprt.precompute.baker import ray_offset

    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1.0]]) * 1e-3 + 1e3
    scene = assemble_scene([("tri", pos, np.array([[0, 2, 1]]), THESIS_MATERIAL)], None, {}, "lights", "tri")
    offset = ray_offset(scene)
    assert type(offset) is float and offset > 1e-4 * scene.diagonal


def test_non_finite_coefficients_stop_the_bake_naming_the_sample():
    """NaN or infinite coefficients (what the scene limits miss) raise a LodprtError naming scene and light sample."""
    from lodprt.precompute.bake import _check_finite

    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1.0]])
    scene = assemble_scene([("tri", pos, np.array([[0, 2, 1]]), THESIS_MATERIAL)], None, {}, "lights", "tri")
    coeffs = np.ones((3, 1, 4), np.float32)
    _check_finite(scene, 0, np.zeros(3), coeffs)
    coeffs[1, 0, 2] = np.inf
    with pytest.raises(LodprtError, match=r"tri: light sample 2 at \[0.0, 1.0, 0.0\]: 1 vertices"):
        _check_finite(scene, 2, np.array([0.0, 1.0, 0.0]), coeffs)
