"""Mirror (caustic) paths of the transfer bake (C-1, C-2): the ``mirror`` material flag, a flat mirror against a
float64 ray-plane oracle, energy bounds, a parabolic dish focusing a tilted sun where geometry says."""

import numpy as np
import pytest

from lodprt.errors import LodprtError, SceneError
from lodprt.model import sh
from lodprt.model.scene import Material, assemble_scene, floor_mesh, scene_from_toml
from lodprt.precompute import transfer as T

FOCAL = 0.5
MIRROR = Material((0.0, 0.0, 0.0), 0.9, 1000.0, mirror=True)
MATTE = Material((0.8, 0.8, 0.8), 0.0, 1.0)


def grid(half, res, height, flip=False):
    """A res x res grid over [-half, half]^2 in x, z at y = height(positions); faces up (+y) unless ``flip``."""
    pos, faces = floor_mesh(np.array([[-half, 0.0, -half], [half, 0.0, half]]), res, 0.0, 1.0)
    pos[:, 1] = height(pos)
    return pos, (faces[:, ::-1].copy() if flip else faces)


def wall_scene(ks=1.0, mirror=True):
    """A receiver patch (y = 0, facing +y, x in [0.1, 0.3]) beside a tall flat mirror wall at x = 0 facing +x."""
    rec, rf = grid(0.1, 5, lambda p: np.zeros(len(p)))
    rec[:, 0] += 0.2
    wall = np.array([[0.0, -0.01, -1.0], [0.0, -0.01, 1.0], [0.0, 0.8, 1.0], [0.0, 0.8, -1.0]])
    wf = np.array([[0, 2, 1], [0, 3, 2]])  # (2 - 0) x (1 - 0) = (0, 0.81, 2) x (0, 0, 2) = (1.62, 0, 0): +x
    m = Material((0.0, 0.0, 0.0), ks, 1000.0, mirror=mirror)
    return assemble_scene([("receiver", rec, rf, MATTE), ("wall", wall, wf, m)], None, {}, "lights", "wall")


def wall_oracle(p, dirs, ks, order):
    """C-1 on the wall by float64 ray-plane intersection: rays toward -x that meet the wall's rectangle reflect
    (x -> -x) with weight ks and escape; all others escape as they are."""
    w = 4 * np.pi / len(dirs)
    c = dirs[:, 1]
    up = c > 0
    t = -p[0] / np.where(dirs[:, 0] < 0, dirs[:, 0], -1.0)
    y, z = p[1] + t * dirs[:, 1], p[2] + t * dirs[:, 2]
    hits = (dirs[:, 0] < 0) & (y > -0.01) & (y < 0.8) & (np.abs(z) < 1.0)
    out = dirs * np.array([-1.0, 1.0, 1.0])
    s = np.where(hits[:, None], out, dirs)
    weight = np.where(hits, ks, 1.0) * c * up * w
    return weight @ sh.basis(s, order)


@pytest.mark.warp_debug
def test_flat_mirror_matches_a_ray_plane_oracle(device):
    """The direct pass with mirror paths of a receiver beside a mirror wall equals the float64 oracle (the
    environment seen in the wall with reflectance ks) to float32 precision."""
    scene = wall_scene(ks=0.7)
    g = T.Geometry.from_scene(scene, device=device)
    assert g.mirror is not None and g.mirror.max() == pytest.approx(0.7)
    got = T.mirror_transfer(g, order=4, rays=512)
    dirs = T.fibonacci_directions(512)
    rec = np.flatnonzero(scene.object_id == 0)
    for v in rec:
        expect = wall_oracle(scene.positions[v] + g.offset * scene.normals[v], dirs, 0.7, 4)
        assert np.abs(got[v] - expect).max() < 2e-4 * np.abs(expect).max() + 1e-5, v


@pytest.mark.warp_debug
def test_mirror_pass_adds_no_more_energy_than_the_mirror_reflects(device):
    """Per vertex under a white sky: shadowed <= with mirrors <= shadowed + ks (unshadowed - shadowed); equality
    on the right for a perfect wall every blocked ray escapes from. Bounce passes shrink."""
    for ks in (1.0, 0.5):
        scene = wall_scene(ks=ks)
        g = T.Geometry.from_scene(scene, device=device)
        rec = np.flatnonzero(scene.object_id == 0)
        m = T.mirror_transfer(g, order=2, rays=256)[rec, 0]
        s = T.geometric_transfer(g, order=2, rays=256, shadowed=True)[rec, 0]
        u = T.geometric_transfer(g, order=2, rays=256, shadowed=False)[rec, 0]
        assert (m >= s - 1e-6).all() and (m <= s + ks * (u - s) + 1e-6).all()
        assert np.allclose(m, s + ks * (u - s), atol=1e-5)
    dish = dish_scene()
    res = T.diffuse_transfer(T.Geometry.from_scene(dish, device=device), order=2, mode="interreflected", rays=128,
                             bounces=3, threshold=0.0)
    e = res.energy
    assert len(e) == 4 and all(b < a for a, b in zip(e, e[1:])), e


def dish_scene(mirror=True):
    """A parabolic dish y = (x^2 + z^2) / (4 f) (a mirror, reflectance 0.9) and a receiver plate facing down in
    its focal plane y = f."""
    dish = grid(0.5, 31, lambda p: (p[:, 0] ** 2 + p[:, 2] ** 2) / (4 * FOCAL))
    plate = grid(0.12, 25, lambda p: np.full(len(p), FOCAL), flip=True)
    m = MIRROR if mirror else Material((0.0, 0.0, 0.0), 0.9, 1000.0)
    return assemble_scene([("dish", *dish, m), ("plate", *plate, MATTE)], None, {}, "lights", "dish")


@pytest.mark.parametrize("degrees", [10.0, -8.0])
def test_dish_focuses_a_tilted_sun_where_geometry_predicts(degrees):
    """A sun tilted by theta about z focuses in the focal plane at x = -f tan(theta) (the paraboloid's image point):
    the brightest plate vertex under an order-8 sun lobe lies within 2 cm of it (plate spacing 1 cm); without the
    mirror flag the dish only shadows and the plate's underside stays dark."""
    scene = dish_scene()
    g = T.Geometry.from_scene(scene, device="cpu")
    plate = np.flatnonzero(scene.object_id == 1)
    t = T.diffuse_transfer(g, order=8, mode="interreflected", rays=768, bounces=0).transfer[plate, 0]
    th = np.radians(degrees)
    sun = sh.cosine_power_lobe(np.array([np.sin(th), np.cos(th), 0.0]), 200.0, 8)
    rad = t @ sun
    peak = scene.positions[plate[np.argmax(rad)]]
    assert abs(peak[0] - (-FOCAL * np.tan(th))) <= 0.02 and abs(peak[2]) <= 0.03, peak
    assert rad.max() > 1.2 * np.median(rad)
    dark = T.diffuse_transfer(T.Geometry.from_scene(dish_scene(False), device="cpu"), order=8, mode="interreflected",
                              rays=768, bounces=0).transfer[plate, 0] @ sun
    assert dark.max() < 0.05 * rad.max()


def test_mirror_flag_in_scene_files(tmp_path):
    """``mirror = true`` reads into Material.mirror; a non-boolean or a mirror with ks > 1 is refused by name."""
    mesh = tmp_path / "tri.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 0 -1\nf 1 2 3\n")
    path = tmp_path / "s.toml"
    path.write_text('[[object]]\nmesh = "tri.obj"\nks = 0.8\nmirror = true\n[floor]\nresolution = 4\n')
    scene = scene_from_toml(path)
    assert scene.materials[0].mirror and not scene.materials[-1].mirror
    path.write_text('[[object]]\nmesh = "tri.obj"\nmirror = "yes"\n')
    with pytest.raises(SceneError, match=r"object\[0\]\.mirror: expected true or false"):
        scene_from_toml(path)
    path.write_text('[[object]]\nmesh = "tri.obj"\nks = 2\nmirror = true\n')
    with pytest.raises(SceneError, match=r"object\[0\]\.ks: a mirror reflects"):
        scene_from_toml(path)
    with pytest.raises(LodprtError, match="mirror reflectance"):
        T.Geometry.from_arrays(scene.positions, scene.faces, scene.normals, mirror=1.5)
