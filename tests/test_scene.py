"""Scene loading: vertex order, floor, lights, normals, and clear errors for bad input."""

import textwrap

import numpy as np
import pytest

from lodprt.errors import SceneError
from lodprt.scene import Lights, floor_mesh, load_mesh, load_scene, vertex_normals

QUAD_OBJ = """\
v 0 0 0
v 1 0 0
v 1 0 1
v 0 0 1
v 5 5 5
f 1 4 3 2
"""


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


def scene_toml(tmp_path, mesh="m.obj", extra=""):
    write(tmp_path, "m.obj", QUAD_OBJ)
    return write(tmp_path, "s.toml", f'[[object]]\nmesh = "{mesh}"\n' + extra)


def test_bunny_keeps_file_vertex_order(bunny_path):
    """Store vertex i is the file's i-th 'v' line, unreferenced vertices included (no merging, no reordering)."""
    pos, faces = load_mesh(bunny_path)
    lines = [ln.split() for ln in open(bunny_path) if ln.startswith("v ")]
    ref = np.array([[float(t) for t in ln[1:4]] for ln in lines])
    assert pos.shape == ref.shape == (35947, 3)
    np.testing.assert_array_equal(pos, ref)
    assert len(np.unique(faces)) == 34834


def test_quads_triangulated_and_unreferenced_vertex_has_finite_normal(tmp_path):
    """A quad becomes two triangles; an unreferenced vertex is kept, unbaked, with the +y fallback normal."""
    scene = load_scene(write(tmp_path, "q.obj", QUAD_OBJ))
    assert scene.faces.shape == (2, 3)
    assert scene.num_vertices == 5
    assert scene.referenced.tolist() == [True, True, True, True, False]
    assert np.isfinite(scene.normals).all()
    np.testing.assert_allclose(scene.normals[4], [0, 1, 0])
    np.testing.assert_allclose(np.abs(scene.normals[:4, 1]), 1.0)


def test_degenerate_faces_give_no_nan_normals():
    """Zero-area and repeated-index faces contribute nothing; a vertex only on them gets the fallback normal."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1], [2, 0, 0], [3, 0, 0.0]])
    faces = np.array([[0, 2, 1], [1, 3, 4], [3, 3, 4]])  # second is collinear, third repeats an index
    n = vertex_normals(pos, faces)
    assert np.isfinite(n).all()
    np.testing.assert_allclose(n[0], [0, 1, 0])
    np.testing.assert_allclose(n[4], [0, 1, 0])  # fallback


def test_normals_scale_invariant():
    """Normals of a mesh scaled by 1e-4 and 1e4 equal those at scale 1 (no underflow to the fallback)."""
    rng = np.random.default_rng(1)
    pos = rng.normal(size=(30, 3))
    faces = rng.integers(0, 30, size=(40, 3))
    n1 = vertex_normals(pos, faces)
    for s in (1e-4, 1e4):
        np.testing.assert_allclose(vertex_normals(pos * s, faces), n1, atol=1e-9)


def test_floor_grid_faces_up_and_counts():
    """The floor has R*R vertices, 2(R-1)^2 triangles, all with +y geometric normals, at the objects' lowest y."""
    bounds = np.array([[-1, 0.5, -2], [1, 3, 2.0]])
    pos, faces = floor_mesh(bounds, 5, 1.0, 4.0)
    assert pos.shape == (25, 3) and faces.shape == (32, 3)
    fn = np.cross(pos[faces[:, 1]] - pos[faces[:, 0]], pos[faces[:, 2]] - pos[faces[:, 0]])
    assert (fn[:, 1] > 0).all()
    np.testing.assert_allclose(pos[:, 1], 0.5)
    np.testing.assert_allclose(pos[:, 0].min(), -5.0)
    np.testing.assert_allclose(pos[:, 2].max(), 6.0)


def test_light_grid_cell_centres():
    """grid n per axis puts samples at the centres of n equal cells of the box, x fastest."""
    lights = Lights(grid=(3, 1, 2), box=(0, 0, 0, 3, 1, 4), intensity=(1, 1, 1), falloff="none", radius=1e-3)
    p = lights.positions
    assert p.shape == (6, 3)
    np.testing.assert_allclose(p[:3, 0], [0.5, 1.5, 2.5])
    np.testing.assert_allclose(p[:, 1], 0.5)
    np.testing.assert_allclose(p[[0, 3], 2], [1.0, 3.0])


def test_toml_scene_with_floor_and_materials(tmp_path):
    """A TOML scene: mesh relative to the file, floor last, materials and lights as written."""
    path = scene_toml(
        tmp_path,
        extra=textwrap.dedent(
            """\
            kd = [0.5, 0.2, 0.1]
            ks = 0.0
            shininess = 10
            [floor]
            resolution = 4
            margin = 0.5
            [lights]
            grid = [2, 1, 2]
            box = [-1, 1, -1, 1, 2, 1]
            intensity = [2.0, 2.0, 2.0]
            falloff = "none"
            """
        ),
    )
    scene = load_scene(path)
    assert scene.num_vertices == 5 + 16
    assert scene.object_names == ["m", "floor"]
    assert scene.materials[0].kd == (0.5, 0.2, 0.1) and scene.materials[0].ks == 0.0
    assert scene.material_id[-1] == 1 and scene.materials[1].ks == pytest.approx(0.19)
    assert scene.lights.grid == (2, 1, 2) and scene.lights.falloff == "none"
    assert scene.lights.positions.shape == (4, 3)


@pytest.mark.parametrize(
    "extra, field",
    [
        ("kdd = 1\n", "kdd"),
        ("ks = -0.1\n", "ks"),
        ("shininess = -2\n", "shininess"),
        ("kd = [0.1, -0.2, 0.3]\n", "kd[1]"),
        ("[lights]\nbox = [0, 0, 0, 1, 0, 1]\n", "box"),
        ("[lights]\nbox = [0, 0, 0, -1, 1, 1]\n", "box"),
        ("[lights]\ngrid = [0, 1, 1]\n", "grid"),
        ("[lights]\nfalloff = \"cubic\"\n", "falloff"),
        ("[lights]\ncolour = 1\n", "colour"),
        ("[floor]\nresolution = 1\n", "resolution"),
        ("[camera]\nfov = 3\n", "camera"),
    ],
)
def test_bad_toml_fields_name_file_and_field(tmp_path, extra, field):
    """Unknown keys, negative materials, empty light boxes ... raise SceneError naming the file and the field."""
    path = scene_toml(tmp_path, extra=extra)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    msg = str(info.value)
    assert str(path) in msg and field in msg


def test_missing_and_unreadable_files(tmp_path):
    """Missing scene, missing mesh, unparsable TOML: SceneError naming the file."""
    with pytest.raises(SceneError, match="nope.toml"):
        load_scene(tmp_path / "nope.toml")
    with pytest.raises(SceneError, match="absent.obj"):
        load_scene(scene_toml(tmp_path, mesh="absent.obj"))
    bad = write(tmp_path, "bad.toml", "[[object]\nmesh=")
    with pytest.raises(SceneError, match="bad.toml"):
        load_scene(bad)


def test_empty_and_nan_meshes(tmp_path):
    """An OBJ without faces and one with a NaN coordinate are refused with the file and field named."""
    with pytest.raises(SceneError, match=r"empty\.obj.*(faces|vertices)"):
        load_scene(write(tmp_path, "empty.obj", "v 0 0 0\nv 1 0 0\n"))
    with pytest.raises(SceneError, match=r"nan\.obj.*vertices.*vertex 1"):
        load_scene(write(tmp_path, "nan.obj", "v 0 0 0\nv nan 0 0\nv 0 0 1\nf 1 2 3\n"))


def test_demo_scene_loads():
    """The embedded demo needs no download and carries the thesis material on object and floor."""
    scene = load_scene("demo")
    assert scene.object_names[-1] == "floor"
    assert all(m.kd == (0.88, 0.88, 0.88) and m.ks == 0.19 and m.shininess == 2 for m in scene.materials)
    assert np.isfinite(scene.normals).all()
    assert scene.lights.positions.shape == (9, 3)
    top = scene.positions[scene.object_id == 0, 1].max()
    assert (scene.lights.positions[:, 1] > top).all()


def test_procedural_demo_fallback_builds():
    """Without pymeshlab's sample bunny the demo falls back to a torus over a slab: a valid, closed-ish mesh."""
    from lodprt.scene import _procedural_mesh

    pos, faces = _procedural_mesh()
    assert np.isfinite(pos).all() and faces.max() < len(pos)
    n = vertex_normals(pos, faces)
    assert np.isfinite(n).all() and np.allclose(np.linalg.norm(n, axis=1), 1)
    assert pos[:, 1].min() >= -1e-12 and pos[:, 1].max() > 0.8  # stands on y = 0, the ring upright above the slab
