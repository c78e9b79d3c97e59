"""Shadow-ray visibility kernel against an independent ray caster (embreex), and its extreme cases."""

import numpy as np
import pytest

from lodprt.precompute import reference
from lodprt.devices import load_kernels
from lodprt.precompute.baker import Baker, bake_kernels, ray_offset
from lodprt.kernels.visibility import BACK_FACING, LIT, SHADOWED
from lodprt.model.scene import THESIS_MATERIAL, assemble_scene, load_mesh

embreex = pytest.importorskip("embreex")


def embree_visibility(scene, light, offset):
    """Independent oracle: Embree's occlusion query on the same rays as the kernel (origin p + offset n)."""
    return reference.visibility(reference.EmbreeCaster(scene), scene, light, offset)


def bunny_floor(bunny_path, resolution=200, scale=1.0):
    pos, faces = load_mesh(bunny_path, scale=scale)
    return assemble_scene([("bunny", pos, faces, THESIS_MATERIAL)], (resolution, 1.0, THESIS_MATERIAL), {}, "lights", "bunny")


def kernel_visibility(scene, device, light):
    load_kernels(device, *bake_kernels())
    ids = np.arange(scene.num_vertices, dtype=np.int32)
    baker = Baker(scene, 2, device, ids)
    return baker.visibility(light).numpy(), baker.offset


@pytest.mark.parametrize("scale", [1.0, 1e-4, 1e4])
def test_visibility_matches_embree_on_bunny_and_floor(device, bunny_path, scale):
    """Warp any-hit shadow rays agree with Embree on bunny + floor, at scene scales 1, 1e-4, 1e4, bar <= 0.1% grazing rays."""
    scene = bunny_floor(bunny_path, scale=scale)
    for light in scene.lights.positions[[0, 4, 8]]:
        ours, offset = kernel_visibility(scene, device, light)
        ref = embree_visibility(scene, light, offset)
        ref[~scene.referenced] = ours[~scene.referenced]
        mismatch = np.mean(ours != ref)
        assert mismatch <= 1e-3, f"{mismatch:.4%} of vertices disagree at scale {scale}"
        shadowed = np.mean(ours == SHADOWED)
        assert 0.02 < shadowed < 0.9  # the bunny does shadow the floor and itself


@pytest.mark.warp_debug
def test_light_on_a_vertex_and_on_the_surface(device):
    """A light exactly at a vertex or on a face counts as lit there (finite, no ray through itself)."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1.0]])
    faces = np.array([[0, 2, 1], [1, 2, 3]])
    scene = assemble_scene([("quad", pos, faces, THESIS_MATERIAL)], None, {}, "lights", "quad")
    vis, _ = kernel_visibility(scene, device, pos[0])
    assert vis[0] == LIT
    vis, _ = kernel_visibility(scene, device, np.array([0.5, 0.0, 0.5]))
    assert (vis != SHADOWED).all()


def test_back_facing_vertices_cast_no_ray(device):
    """A light below a single upward triangle makes every vertex BACK_FACING (decided by the normal alone)."""
    pos = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0.0]])
    scene = assemble_scene([("tri", pos, np.array([[0, 1, 2]]), THESIS_MATERIAL)], None, {}, "lights", "tri")
    assert np.allclose(scene.normals, [0, 1, 0])
    vis, _ = kernel_visibility(scene, device, np.array([0.3, -1.0, 0.3]))
    assert (vis == BACK_FACING).all()
    vis, _ = kernel_visibility(scene, device, np.array([0.3, 1.0, 0.3]))
    assert (vis == LIT).all()


@pytest.mark.warp_debug
def test_occluder_between_light_and_vertex(device):
    """A small triangle hovering between a floor vertex and the light shadows exactly that vertex."""
    floor = np.array([[-1, 0, -1], [-1, 0, 1], [1, 0, -1], [1, 0, 1.0], [0, 0, 0]])
    ffaces = np.array([[0, 1, 4], [1, 3, 4], [3, 2, 4], [2, 0, 4]])
    occ = np.array([[-0.1, 0.5, -0.1], [-0.1, 0.5, 0.1], [0.1, 0.5, 0.0]])
    objects = [("floor", floor, ffaces, THESIS_MATERIAL), ("occ", occ, np.array([[0, 2, 1]]), THESIS_MATERIAL)]
    scene = assemble_scene(objects, None, {}, "lights", "occ")
    vis, _ = kernel_visibility(scene, device, np.array([0.0, 2.0, 0.0]))
    assert vis[4] == SHADOWED
    assert (vis[:4] == LIT).all()


def test_ray_offset_scales_with_scene(bunny_path):
    """The shadow-ray offset is proportional to the scene size across 8 orders of magnitude."""
    a = ray_offset(bunny_floor(bunny_path, resolution=4, scale=1e-4))
    b = ray_offset(bunny_floor(bunny_path, resolution=4, scale=1e4))
    assert b / a == pytest.approx(1e8, rel=1e-6)


def test_ray_offset_ignores_a_far_unreferenced_vertex():
    """One offset for every bake: the point-light bake's (Scene) and the transfer bake's (Geometry) agree, and a vertex
    no face uses, 1e6 away, changes neither (oracle: 1e-4 of the triangle's own diagonal, worked out by hand)."""
    from lodprt.precompute.transfer import Geometry

    tri = np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, 4.0, 0.0]])
    far = np.vstack([tri, [[1e6, -1e6, 1e6]]])
    faces = np.array([[0, 1, 2]])
    alone = assemble_scene([("tri", tri, faces, THESIS_MATERIAL)], None, {}, "lights", "tri")
    with_far = assemble_scene([("tri", far, faces, THESIS_MATERIAL)], None, {}, "lights", "tri")
    assert not with_far.referenced[3]
    expected = 1e-4 * 5.0  # the triangle's bounding box is 3 x 4 x 0: diagonal 5
    assert ray_offset(alone) == pytest.approx(expected, rel=1e-12)
    assert ray_offset(with_far) == pytest.approx(expected, rel=1e-12)
    normals = np.tile([0.0, 0.0, 1.0], (4, 1))
    geom = Geometry.from_arrays(far, faces, normals, device="cpu")
    assert geom.offset == pytest.approx(expected, rel=1e-12)
    assert Geometry.from_scene(with_far, device="cpu").offset == ray_offset(with_far)
