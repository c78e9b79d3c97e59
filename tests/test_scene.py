"""Scene loading: vertex order, floor, lights, normals, and clear errors for bad input."""

import gzip
import lzma
import textwrap

import numpy as np
import pytest

from lodprt.errors import SceneError
from lodprt.model.scene import Lights, floor_mesh, load_mesh, load_scene, vertex_normals

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
    lines = [ln.split() for ln in lzma.open(bunny_path, "rt") if ln.startswith("v ")]
    ref = np.array([[float(t) for t in ln[1:4]] for ln in lines])
    assert pos.shape == ref.shape == (35947, 3)
    np.testing.assert_array_equal(pos, ref)
    assert len(np.unique(faces)) == 34834


def test_obj_with_several_materials_keeps_file_vertices(tmp_path):
    """An OBJ with two usemtl groups (trimesh splits it per material) keeps its 5 vertices in file order, both faces."""
    write(tmp_path, "m.mtl", "newmtl a\nKd 1 0 0\nnewmtl b\nKd 0 1 0\n")
    groups = "usemtl a\nf 1 4 3\nusemtl b\nf 1 3 2\n"
    path = write(tmp_path, "mm.obj", "mtllib m.mtl\n" + QUAD_OBJ.replace("f 1 4 3 2\n", groups))
    pos, faces = load_mesh(path)
    np.testing.assert_array_equal(pos, [[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1], [5, 5, 5]])
    assert sorted(map(tuple, faces.tolist())) == [(0, 2, 1), (0, 3, 2)]


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
        ("[lights]\ngrid = [100000, 100000, 100000]\n", "lights.grid"),
        ("[lights]\nbox = [-1e300, 0, 0, 1e300, 1, 1]\n", "lights.box"),
        ("[floor]\nresolution = 100000\n", "floor.resolution"),
        ("[floor]\nmargin = 1e300\n", "floor.margin"),
        ("up = \"w\"\n", "object[0].up"),
        ("up = 3\n", "object[0].up"),
        ("rotate = [1, 2]\n", "object[0].rotate"),
        ("rotate = [0, nan, 0]\n", "object[0].rotate[1]"),
        ("name = 3\n", "object[0].name"),
        ("scale = 1e300\n", "vertices"),
        ("ks = 1e999999\n", "ks"),
        ("shininess = 1" + "0" * 400 + "\n", "shininess"),
        ("[lights]\ngrid = 5\n", "lights.grid"),
        ("kd = 2e6\n", "kd[0]"),
        ("[lights]\nintensity = [1, 1, 1e13]\n", "lights.intensity[2]"),
        ("[lights]\nradius = 1e-13\n", "lights.radius"),
        ("scale = 1e-12\n", "diagonal"),
    ],
)
def test_bad_toml_fields_name_file_and_field(tmp_path, extra, field):
    """Unknown keys, negative materials, empty light boxes ... raise SceneError naming the file and the field."""
    path = scene_toml(tmp_path, extra=extra)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    msg = str(info.value)
    assert str(path) in msg and field in msg


def test_empty_mesh_path_named(tmp_path):
    """An empty 'mesh' string is refused as such, naming the file and field (not read as the scene's folder)."""
    with pytest.raises(SceneError, match=r"s\.toml: object\[0\]\.mesh: required.*got ''"):
        load_scene(write(tmp_path, "s.toml", '[[object]]\nmesh = ""\n'))


def test_missing_and_unreadable_files(tmp_path):
    """Missing scene, missing mesh, unparsable TOML: SceneError naming the file."""
    with pytest.raises(SceneError, match="nope.toml"):
        load_scene(tmp_path / "nope.toml")
    with pytest.raises(SceneError, match="absent.obj"):
        load_scene(scene_toml(tmp_path, mesh="absent.obj"))
    bad = write(tmp_path, "bad.toml", "[[object]\nmesh=")
    with pytest.raises(SceneError, match="bad.toml"):
        load_scene(bad)


def test_compressed_meshes_read_as_their_inner_format(tmp_path):
    """m.obj.gz / .xz / .bz2 give exactly the plain file's arrays and the plain name; a compressed tristrip PLY goes
    through pymeshlab; a garbled archive and a name without its inner format are errors naming the file."""
    import bz2

    plain = load_mesh(write(tmp_path, "m.obj", QUAD_OBJ))
    for suffix, codec in ((".gz", gzip), (".xz", lzma), (".bz2", bz2)):
        path = tmp_path / f"m.obj{suffix}"
        path.write_bytes(codec.compress(QUAD_OBJ.encode()))
        got = load_mesh(path)
        np.testing.assert_array_equal(got[0], plain[0])
        np.testing.assert_array_equal(got[1], plain[1])
        assert load_scene(path).object_names == ["m"]
    ref, _ = strip_grid_ply(tmp_path / "strips.ply")
    (tmp_path / "strips.ply.xz").write_bytes(lzma.compress((tmp_path / "strips.ply").read_bytes()))
    np.testing.assert_array_equal(load_mesh(tmp_path / "strips.ply.xz")[0], ref)
    (tmp_path / "bad.obj.gz").write_bytes(b"not gzip at all")
    with pytest.raises(SceneError, match=r"bad\.obj\.gz: cannot decompress the mesh file \(\.gz\)"):
        load_mesh(tmp_path / "bad.obj.gz")
    (tmp_path / "m.xz").write_bytes(lzma.compress(QUAD_OBJ.encode()))
    with pytest.raises(SceneError, match=r"m\.xz: mesh file: a compressed mesh names its format"):
        load_mesh(tmp_path / "m.xz")


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
    from lodprt.model.scene import _procedural_mesh

    pos, faces = _procedural_mesh()
    assert np.isfinite(pos).all() and faces.max() < len(pos)
    n = vertex_normals(pos, faces)
    assert np.isfinite(n).all() and np.allclose(np.linalg.norm(n, axis=1), 1)
    assert pos[:, 1].min() >= -1e-12 and pos[:, 1].max() > 0.8  # stands on y = 0, the ring upright above the slab


# ---------------------------------------------------------------------------------------------------------------
# triangle strips, zero-area objects, up axis


def strip_grid_ply(path, n=30, m=30, width=2.0, depth=3.0, seed=0):
    """An ASCII PLY of an n x m vertex grid in the x-z plane as triangle strips, vertices stored in shuffled order.

    Returns (positions as stored in the file (V, 3), number of grid triangles). Two extra vertices follow the grid:
    a duplicate of the first and an unreferenced one, so a reader that merges or drops vertices is caught. Strips
    are separated by -1, except one pair joined by repeated indices (degenerate triangles) as strippers write them.
    """
    rng = np.random.default_rng(seed)
    xs, zs = np.meshgrid(np.linspace(0, width, n), np.linspace(0, depth, m), indexing="xy")
    grid = np.stack([xs.ravel(), np.zeros(n * m), zs.ravel()], axis=1)
    perm = rng.permutation(n * m)  # file vertex k is grid vertex perm[k]
    file_of = np.argsort(perm)
    pos = np.concatenate([grid[perm], grid[perm[:1]], [[9.0, 9.0, 9.0]]])
    flat = []
    for j in range(m - 1):
        strip = [int(file_of[g]) for i in range(n) for g in (j * n + i, (j + 1) * n + i)]
        if j == 0:
            flat += strip
        elif j == 1:  # joined to the previous strip: repeat its last and this one's first index (even length kept)
            flat += [flat[-1], strip[0]] + strip
        else:
            flat += [-1] + strip
    lines = [
        "ply", "format ascii 1.0", f"element vertex {len(pos)}", "property double x", "property double y",
        "property double z", "element tristrips 1", "property list int int vertex_indices", "end_header",
    ]
    lines += [" ".join(repr(float(c)) for c in p) for p in pos]
    lines.append(" ".join(map(str, [len(flat)] + flat)))
    path.write_text("\n".join(lines) + "\n")
    return pos, 2 * (n - 1) * (m - 1)


def test_tristrip_ply_read_with_file_vertex_order(tmp_path, caplog):
    """A PLY of triangle strips is read (via pymeshlab): every vertex in file order and count, the grid's area."""
    path = tmp_path / "strips.ply"
    ref, triangles = strip_grid_ply(path)
    with caplog.at_level("INFO", logger="lodprt.model.meshio"):
        scene = load_scene(path)
    assert "pymeshlab" in caplog.text
    assert scene.num_vertices == len(ref) == 902
    np.testing.assert_array_equal(scene.positions, ref)  # duplicate and unreferenced vertices kept, not reordered
    p, f = scene.positions, scene.faces
    cross = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    real = np.linalg.norm(cross, axis=1) > 0
    assert real.sum() == triangles
    assert 0.5 * np.linalg.norm(cross, axis=1).sum() == pytest.approx(2.0 * 3.0, rel=1e-12)
    assert (cross[real, 1] > 0).all()  # strip parity handled: every triangle faces +y
    assert scene.referenced.tolist()[-2:] == [False, False]


def test_tristrip_index_past_last_vertex_is_an_error_not_a_crash(tmp_path):
    """A strip index past the last vertex (pymeshlab segfaults on it) gives a SceneError naming file and faces."""
    path = tmp_path / "bad.ply"
    header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    path.write_text(header + "element tristrips 1\nproperty list int int vertex_indices\nend_header\n"
                    "0 0 0\n1 0 0\n0 1 0\n5 0 1 2 1000 -7\n")
    with pytest.raises(SceneError, match=r"bad\.ply: field 'faces': no faces: trimesh read 3 vertices.*pymeshlab"):
        load_scene(path)


def test_point_cloud_error_says_what_each_reader_found(tmp_path):
    """A PLY point cloud: the error says neither trimesh nor pymeshlab found faces, and why it cannot be baked."""
    path = tmp_path / "cloud.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                    "end_header\n0 0 0\n1 0 0\n0 1 0\n")
    with pytest.raises(SceneError, match=r"cloud\.ply.*trimesh read 3 vertices and no faces, pymeshlab read 3 "
                                         r"vertices and no faces; point clouds cannot be baked"):
        load_scene(path)


FLAT_OBJ = "v 0 0 0\nv 1 1 1\nv 2 2 2\nv 5 5 5\nf 1 2 3\nf 1 3 4\nf 2 2 4\n"


def test_zero_area_mesh_refused_naming_file_and_object(tmp_path):
    """A mesh whose every face has zero area is refused, in a TOML scene and as a bare path, naming file and object."""
    write(tmp_path, "flat.obj", FLAT_OBJ)
    toml = write(tmp_path, "s.toml", '[[object]]\nmesh = "flat.obj"\nname = "x"\n')
    with pytest.raises(SceneError) as info:
        load_scene(toml)
    assert str(info.value).startswith(f"{toml}: object[0] (name 'x'): every face of flat.obj has zero area after "
                                      "placement; nothing to bake")
    with pytest.raises(SceneError, match=r"flat\.obj: every face of the mesh has zero area"):
        load_scene(tmp_path / "flat.obj")


def test_zero_area_second_object_named_and_single_degenerate_face_allowed(tmp_path):
    """The zero-area check is per object (object[1] is named); one degenerate face among good ones is allowed."""
    write(tmp_path, "flat.obj", FLAT_OBJ)
    write(tmp_path, "m.obj", QUAD_OBJ + "f 1 1 2\n")
    scene = load_scene(write(tmp_path, "ok.toml", '[[object]]\nmesh = "m.obj"\n'))
    assert scene.faces.shape == (3, 3) and np.isfinite(scene.normals).all()
    toml = write(tmp_path, "two.toml", '[[object]]\nmesh = "m.obj"\n[[object]]\nmesh = "flat.obj"\n')
    with pytest.raises(SceneError, match=r"object\[1\] \(name 'flat'\): every face of flat\.obj has zero area"):
        load_scene(toml)


# a closed pyramid standing on z = 0.5, apex up +z, faces wound outward
PYRAMID_Z_UP = np.array([[-1, -1, 0.5], [1, -1, 0.5], [1, 1, 0.5], [-1, 1, 0.5], [0, 0, 2.0]])
PYRAMID_FACES = np.array([[0, 2, 1], [0, 3, 2], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])


def write_obj(path, pos, faces):
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in pos]
    lines += [f"f {a} {b} {c}" for a, b, c in faces + 1]
    path.write_text("\n".join(lines) + "\n")
    return path


def signed_volume(pos, faces):
    return np.einsum("ij,ij->i", pos[faces[:, 0]], np.cross(pos[faces[:, 1]], pos[faces[:, 2]])).sum() / 6


def test_up_z_equals_prerotated_mesh_and_floor_lies_under_it(tmp_path):
    """up = "z" gives the positions of the same mesh pre-rotated (x, z, -y), stands on the floor, keeps winding."""
    assert signed_volume(PYRAMID_Z_UP, PYRAMID_FACES) > 0  # outward winding
    write_obj(tmp_path / "z.obj", PYRAMID_Z_UP, PYRAMID_FACES)
    rotated = PYRAMID_Z_UP[:, [0, 2, 1]] * [1, 1, -1]
    write_obj(tmp_path / "y.obj", rotated, PYRAMID_FACES)
    floor = "[floor]\nresolution = 3\n"
    a = load_scene(write(tmp_path, "a.toml", '[[object]]\nmesh = "z.obj"\nup = "z"\nscale = 2\n' + floor))
    b = load_scene(write(tmp_path, "b.toml", '[[object]]\nmesh = "y.obj"\nscale = 2\n' + floor))
    obj = a.object_id == 0
    np.testing.assert_array_equal(a.positions[obj], b.positions[obj])
    np.testing.assert_allclose(a.positions[obj], 2 * rotated)
    np.testing.assert_allclose(a.positions[~obj, 1], a.positions[obj, 1].min())  # floor at the base, y = 1
    assert a.positions[4, 1] == a.positions[obj, 1].max() == 4.0  # apex on top
    assert signed_volume(a.positions[obj], a.faces[: len(PYRAMID_FACES)]) > 0  # winding still outward
    np.testing.assert_allclose(a.normals, b.normals)
    assert a.normals[4, 1] > 0.99  # the apex normal points up


def test_up_axes_are_proper_rotations_to_y_and_rotate_order():
    """Every up axis maps to +y with det +1; rotate is about x, then y, then z (fixed axes, right-handed)."""
    from lodprt.model.meshio import UP_AXES, rotation_matrix

    for axis in UP_AXES:
        m = rotation_matrix(axis)
        v = np.zeros(3)
        v["xyz".index(axis[-1])] = -1.0 if axis.startswith("-") else 1.0
        np.testing.assert_allclose(m @ v, [0, 1, 0], atol=1e-15)
        assert np.linalg.det(m) == pytest.approx(1.0) and np.allclose(m @ m.T, np.eye(3))
    np.testing.assert_allclose(rotation_matrix("y", (0, 90, 0)) @ [1, 0, 0], [0, 0, -1], atol=1e-15)
    np.testing.assert_allclose(rotation_matrix("y", (90, 0, 0)) @ [0, 1, 0], [0, 0, 1], atol=1e-15)
    # x first, then y: +y -> +z (about x) -> +x (about y)
    np.testing.assert_allclose(rotation_matrix("y", (90, 90, 0)) @ [0, 1, 0], [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(rotation_matrix("z", (0, 0, 90)) @ [0, 0, 1], [-1, 0, 0], atol=1e-15)


def test_rotate_key_applied_after_up_before_translate(tmp_path):
    """rotate = [0, 90, 0] on a z-up mesh: up conversion, then the rotation, then scale and translate."""
    write_obj(tmp_path / "z.obj", PYRAMID_Z_UP, PYRAMID_FACES)
    scene = load_scene(write(tmp_path, "r.toml", '[[object]]\nmesh = "z.obj"\nup = "z"\nrotate = [0, 90, 0]\n'
                                                 'scale = 3\ntranslate = [10, 0, 0]\n'))
    upright = PYRAMID_Z_UP[:, [0, 2, 1]] * [1, 1, -1]
    turned = np.stack([upright[:, 2], upright[:, 1], -upright[:, 0]], axis=1)  # +90 about y: (x, y, z) -> (z, y, -x)
    np.testing.assert_allclose(scene.positions, 3 * turned + [10, 0, 0], atol=1e-14)


def test_huge_light_grid_refused_before_meshes_are_read(tmp_path):
    """A 1e15-sample grid is refused by its sample count first (the mesh is not even looked for), naming the limit."""
    toml = write(tmp_path, "s.toml", '[[object]]\nmesh = "absent.obj"\n[lights]\ngrid = [100000, 100000, 100000]\n')
    with pytest.raises(SceneError, match=r"s\.toml: lights\.grid: .* asks for 1000000000000000 light samples; at "
                                         r"most 100,000 are allowed"):
        load_scene(toml)


MATERIALS_UV_OBJ = """\
v 0 0 0
v 1 0 0
v 0 0 1
v 1 0 1
vt 0 0
vt 1 0
vt 0 1
vt 1 1
vt 0.5 0.5
vn 0 1 0
usemtl a
f 1/1/1 3/3/1 2/2/1
usemtl b
f 2/5/1 3/3/1 4/4/1
"""


def test_obj_with_materials_and_texture_coordinates_keeps_the_files_vertices(tmp_path):
    """An OBJ with two usemtl groups whose faces carry vt/vn: trimesh gives each group its own vertex copies (7 of
    the file's 4); the file's vertices come back, in order, and the two faces share their edge (1-2)."""
    path = write(tmp_path, "uv.obj", MATERIALS_UV_OBJ)
    pos, faces = load_mesh(path)
    ref = np.array([[float(t) for t in ln.split()[1:4]] for ln in MATERIALS_UV_OBJ.splitlines() if ln.startswith("v ")])
    np.testing.assert_array_equal(pos, ref)
    np.testing.assert_array_equal(faces, [[0, 2, 1], [1, 2, 3]])


def test_obj_with_texture_coordinates_keeps_an_unreferenced_vertex(tmp_path):
    """One group whose faces carry vt/vn, and a vertex no face uses: trimesh drops that vertex even without a
    material split (4 of the file's 5), so the file's 'v' lines are counted for every OBJ, and it comes back."""
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 5 5 5\nvn 0 0 1\nvt 0 0\nvt 1 0\n" \
           "f 1/1/1 2/2/1 3/1/1\nf 2/1/1 4/2/1 3/2/1\n"
    pos, faces = load_mesh(write(tmp_path, "vt.obj", text))
    np.testing.assert_array_equal(pos, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [5, 5, 5]])
    np.testing.assert_array_equal(faces, [[0, 1, 2], [1, 3, 2]])


def test_obj_vertex_index_zero_is_refused_naming_the_line(tmp_path):
    """OBJ counts vertices from 1 (negative: back from the last), so an index 0 names no vertex: trimesh took
    another vertex for it (-0 too: it was read as vertex 0). A 0 elsewhere (a texture index, a coordinate, 10) is no
    vertex index 0."""
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1/0 2/1 3\nf -1 -2 -3\n"
    load_mesh(write(tmp_path, "ok.obj", text))
    for bad, line in (("f 0 2 3\n", 7), ("f 2 4 3 0\n", 7), ("f  2/1 00/1 3\n", 7), ("f 2 -0 3\n", 7)):
        with pytest.raises(SceneError, match=rf"bad\.obj: field 'faces': line {line} uses vertex index 0"):
            load_mesh(write(tmp_path, "bad.obj", text + bad))


def test_the_log_names_the_reader_that_read_the_obj(tmp_path, caplog):
    """A plain OBJ is read by trimesh and the log says so; one whose vertices trimesh copied per material is read
    by pymeshlab, and the log gives trimesh's count beside the file's (every OBJ was logged as read by pymeshlab,
    with pymeshlab's count as trimesh's)."""
    plain = write(tmp_path, "plain.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with caplog.at_level("INFO", logger="lodprt.model.meshio"):
        load_mesh(plain)
    assert "read with trimesh: 3 vertices, 1 triangles" in caplog.text, caplog.text
    caplog.clear()
    with caplog.at_level("INFO", logger="lodprt.model.meshio"):
        load_mesh(write(tmp_path, "uv.obj", MATERIALS_UV_OBJ))
    assert "read with pymeshlab (trimesh made 7 vertices of the file's 4): 4 vertices" in caplog.text, caplog.text


def test_empty_ply_is_called_empty_not_a_point_cloud(tmp_path):
    """A PLY of no vertices and no faces is an empty mesh (it was called a point cloud)."""
    head = "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\n"
    path = write(tmp_path, "empty.ply", head + "element face 0\nproperty list uchar int vertex_indices\nend_header\n")
    with pytest.raises(SceneError, match=r"empty\.ply: field 'faces': no faces: .* the mesh is empty"):
        load_mesh(path)


def test_unreferenced_vertices_size_nothing(tmp_path):
    """A vertex no face uses, 100 units under a unit triangle, moves neither the floor nor the default light box
    nor the default radius: the scene is the one without it."""
    tri = "v 0 0 0\nv 1 0 0\nv 0 0 1\n"
    write(tmp_path, "a.obj", tri + "f 1 3 2\n")
    write(tmp_path, "b.obj", tri + "v 0 -100 0\nf 1 3 2\n")
    scenes = [load_scene(write(tmp_path, f"{m}.toml", f'[[object]]\nmesh = "{m}.obj"\n[floor]\nresolution = 3\n'))
              for m in "ab"]
    assert scenes[0].lights == scenes[1].lights
    np.testing.assert_array_equal(scenes[0].positions[-9:], scenes[1].positions[-9:])  # the floor, at y = 0
    assert scenes[1].positions[-9:, 1].max() == 0.0


def test_assemble_scene_checks_arrays_given_in_memory():
    """Arrays handed to assemble_scene get the checks a file gets: a negative or too large face index, NaN and
    (V, 2) positions, float faces are refused naming the object and the field."""
    from lodprt.model.scene import THESIS_MATERIAL, assemble_scene

    p = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1.0]])
    f = np.array([[0, 2, 1], [1, 2, 3]])
    cases = [(p, np.array([[0, 2, 1], [1, 2, -1]]), r"faces: indices must lie in 0\.\.3, got -1\.\.2"),
             (p, np.array([[0, 2, 1], [1, 2, 7]]), r"faces: indices must lie in 0\.\.3, got 0\.\.7"),
             (np.where(np.arange(12).reshape(4, 3) == 4, np.nan, p), f, r"positions: vertex 1 is \[1\.0, nan"),
             (p[:, :2], f, r"positions: expected \(V, 3\)"), (p, f.astype(float), r"faces: expected \(F, 3\) integer")]
    for pos, faces, msg in cases:
        with pytest.raises(SceneError, match=r"src: object\[0\] \(name 'o'\): " + msg):
            assemble_scene([("o", pos, faces, THESIS_MATERIAL)], None, {}, "lights", "src")
    assemble_scene([("o", p, f, THESIS_MATERIAL)], None, {}, "lights", "src")  # the good one passes


def test_radiance_beyond_float32_refused(tmp_path):
    """Each limit alone holds (intensity 1e12, kd = ks = 1e6, radius 1e-12) but their product, 2e42, would overflow
    float32: refused naming the three fields. A radius of 1e-9 brings it to 2e36 (still refused), 1e-8 to 2e34."""
    write(tmp_path, "t.obj", "v 0 0 0\nv 1 0 0\nv 0 0 1\nf 1 3 2\n")
    body = '[[object]]\nmesh = "t.obj"\nkd = 1e6\nks = 1e6\n[lights]\nintensity = 1e12\nradius = {}\n'
    for r in ("1e-12", "1e-9"):
        with pytest.raises(SceneError, match=r"lights\.intensity 1e\+12 x \(kd \+ ks\) 2e\+06 / lights\.radius\^2"):
            load_scene(write(tmp_path, "s.toml", body.format(r)))
    assert load_scene(write(tmp_path, "s.toml", body.format("1e-8"))).lights.radius == 1e-8


def test_one_number_is_grey_for_colours_only(tmp_path):
    """kd = 0.5 and intensity = 2 stand for three equal values; rotate = 90 or translate = 5 is refused (it used to
    become [90, 90, 90] or [5, 5, 5] without a word)."""
    write(tmp_path, "t.obj", "v 0 0 0\nv 1 0 0\nv 0 0 1\nf 1 3 2\n")
    scene = load_scene(write(tmp_path, "g.toml", '[[object]]\nmesh = "t.obj"\nkd = 0.5\n[lights]\nintensity = 2\n'))
    assert scene.materials[0].kd == (0.5, 0.5, 0.5) and scene.lights.intensity == (2.0, 2.0, 2.0)
    for key, value in (("rotate", 90), ("translate", 5)):
        with pytest.raises(SceneError, match=rf"object\[0\]\.{key}: expected a list of 3 numbers, got {value}"):
            load_scene(write(tmp_path, "v.toml", f'[[object]]\nmesh = "t.obj"\n{key} = {value}\n'))


def test_an_unknown_file_type_is_named(tmp_path):
    """A scene file without .toml or a mesh of a type no reader knows names the suffix and what lodprt reads (it was
    trimesh's NotImplementedError with the absolute path)."""
    for name in ("s.yaml", "m.dat"):
        with pytest.raises(SceneError, match=rf"{name}: not a file type lodprt reads \(\.{name[2:]}\): a scene file "
                                             r"ends in \.toml; a mesh in \.obj"):
            load_scene(write(tmp_path, name, "v 0 0 0\n"))


#: Four vertices and two faces, the content every OBJ layout below writes (an independent oracle for the reader).
TETRA_V = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
TETRA_F = [[0, 1, 2], [0, 2, 3]]


def read_obj_bytes(tmp_path, data: bytes, name="m.obj"):
    path = tmp_path / name
    path.write_bytes(data)
    return load_mesh(path)


@pytest.mark.parametrize("text", [
    "  v 0 0 0\n  v 1 0 0\n\tv 0 1 0\n v 0 0 1\nf 1 2 3\n  f 1 3 4\n",  # trimesh raised IndexError
    "v 0 0 0\n   v 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n",  # one indented line
    "v\t0\t0\t0\nv\t1\t0\t0\nv 0 1\t0\nv 0 0 1\nf\t1\t2\t3\nf 1 3\t4\n",  # tabs
    "\ufeffv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n",  # a UTF-8 byte order mark
    "v 0 0 \\\n   0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n",  # a continued line keeps its blanks
], ids=["indented", "one-indented", "tabs", "bom", "continued-line"])
def test_obj_indented_and_tab_separated_lines_read_as_written(tmp_path, text):
    """Leading blanks and tabs separate nothing in OBJ; trimesh dropped indented 'v' lines (a raw IndexError, or
    another vertex in their place)."""
    pos, faces = read_obj_bytes(tmp_path, text.encode())
    np.testing.assert_array_equal(pos, TETRA_V)
    np.testing.assert_array_equal(faces, TETRA_F)


def test_obj_trailing_comments_are_dropped(tmp_path):
    """'#' starts a comment to the line's end: 'f 1 2 3 # 0' is face 1 2 3 (trimesh raised ValueError; the 0 is no
    vertex index 0), and a '#' in a material name is kept."""
    text = ("# tetra\nmtllib m.mtl\nv 0 0 0 # origin\nv 1 0 0#x\nv 0 1 0\nv 0 0 1\nusemtl red#1\n"
            "f 1 2 3 # 0\nf 1/1 3/1 4/1 # 7\nvt 0 0 # uv\n")
    pos, faces = read_obj_bytes(tmp_path, text.encode())
    np.testing.assert_array_equal(pos, TETRA_V)
    np.testing.assert_array_equal(faces, TETRA_F)
    from lodprt.model.meshio import normalised_obj
    assert b"usemtl red#1\n" in normalised_obj(text.encode())


def test_obj_cr_only_line_ends(tmp_path):
    """Old Mac files end lines with CR alone: trimesh read them as one line (ValueError, or no vertex at all when the
    first line was a comment). Lines are counted as the file shows them in error messages."""
    body = "# old mac\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n"
    for text in (body.replace("\n", "\r"), body.replace("\n", "\r").rstrip("\r"), body.replace("\n", "\r\n")):
        pos, faces = read_obj_bytes(tmp_path, text.encode())
        np.testing.assert_array_equal(pos, TETRA_V)
        np.testing.assert_array_equal(faces, TETRA_F)
    with pytest.raises(SceneError, match=r"bad\.obj: field 'faces': line 8 uses vertex index 0"):
        read_obj_bytes(tmp_path, (body + "f 1 0 2\n").replace("\n", "\r").encode(), "bad.obj")


@pytest.mark.parametrize("face, message", [
    ("f 1 3 9", "line 6: face 2 refers to vertex 9, but the file has only 4 vertices$"),
    ("f 1/1 3/1 5/1", "line 6: face 2 refers to vertex 5, but the file has only 4 vertices$"),
    ("f 1 2 3 5", "line 6: face 2 refers to vertex 5, but the file has only 4 vertices$"),
    ("f -1 -2 -5", "line 6: face 2 refers to vertex -5, but the file has only 4 vertices before that line$"),
], ids=["past-end", "with-vt", "quad", "negative"])
def test_obj_face_index_past_the_last_vertex_names_the_line(tmp_path, face, message):
    """trimesh raised a bare 'IndexError: index 8 is out of bounds for axis 0 with size 4'."""
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\n" + face + "\nvt 0 0\n"
    with pytest.raises(SceneError, match=r"bad\.obj: field 'faces': " + message) as err:
        read_obj_bytes(tmp_path, text.encode(), "bad.obj")
    assert "\n" not in str(err.value)


def test_obj_negative_indices_count_back_from_their_own_line(tmp_path):
    """OBJ's negative indices are relative to the vertices read so far: with a second object's 'v' lines after the
    first's faces, trimesh counted back from the file's end and gave both faces the second triangle, silently."""
    tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n"
    text = tri + tri.replace("v 0", "v 5").replace("v 1", "v 6")
    pos, faces = read_obj_bytes(tmp_path, text.encode())
    np.testing.assert_array_equal(pos, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 0, 0], [6, 0, 0], [5, 1, 0]])
    np.testing.assert_array_equal(faces, [[0, 1, 2], [3, 4, 5]])
    with pytest.raises(SceneError, match=r"line 4: face 1 refers to vertex -4, but the file has only 3 vertices "):
        read_obj_bytes(tmp_path, text.replace("f -3 -2 -1", "f -4 -2 -1", 1).encode(), "bad.obj")
