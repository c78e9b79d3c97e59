"""Export (docs/EXPORT.md): ``lodprt export`` .glb files, ``lodprt irradiance --format`` and ``turntable -o .mp4``.

The GLB is read back twice, by trimesh and by pygltflib plus a numpy decoder written here from the glTF 2.0 spec
(with the structural rules the Khronos validator applies), and compared with ``Store.radiance`` /
``lodprt radiance`` and the stored, completed coefficients. Each irradiance format is evaluated the way its
consumer does (Babylon.js's basis constants, Unity's ShadeSH9 registers, Filament's shader polynomial) and compared
with the Ramamoorthi-Hanrahan formula and with the closed form for one directional light.
"""

import json
import re
import struct
import sys
from pathlib import Path

import numpy as np
import pytest

from lodprt.cli.main import main
from lodprt.model.scene import Material, assemble_scene

GREY, RGB = (0.7, 0.7, 0.7), (0.9, 0.5, 0.2)
#: name -> (kd, ks, hierarchy)
KINDS = {"grey": (GREY, 0.19, True), "rgb": (RGB, 0.3, True), "rgb-diffuse": (RGB, 0.0, True),
         "grey-nohier": (GREY, 0.19, False)}
EYE = (0.35, 0.9, 1.1)
INTENSITY = (2.0, 1.0, 0.5)


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    """name -> store path: a ball (642 vertices) on an 8 x 8 floor, 3 x 1 x 3 lights, SH order 3 (tenths of a s)."""
    import trimesh

    from lodprt.model.hierarchy_build import build_hierarchy
    from lodprt.precompute.bake import bake

    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.3)
    root = tmp_path_factory.mktemp("export")
    tree, out = None, {}
    for name, (kd, ks, hier) in KINDS.items():
        m = Material(kd, ks, 8.0)
        scene = assemble_scene([("ball", ball.vertices + [0, 0.3, 0], ball.faces, m)], (8, 1.0, m),
                               {"intensity": list(INTENSITY)}, "lights", "ball")
        if hier and tree is None:
            tree = build_hierarchy(scene.positions, scene.faces, scene.normals)
        out[name] = root / f"{name}.zarr"
        bake(scene, out[name], sh_order=3, device="cpu", threshold_deg=30.0 if hier else None, hierarchy=hier,
             tree=tree if hier else None)
    return out


def run(argv, capsys):
    """``lodprt ARGV`` in process: (exit code, stdout, stderr)."""
    rc = main([str(a) for a in argv])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


# -- reading a GLB independently ------------------------------------------------------------------------------------
COMPONENTS = {5126: np.float32, 5125: np.uint32, 5123: np.uint16, 5121: np.uint8}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def read_glb(path):
    """(json document, {semantic: array}, triangles (M, 3)) decoded with numpy from the chunks pygltflib parses,
    after the structural checks a glTF validator makes."""
    import pygltflib

    raw = path.read_bytes()
    magic, version, length = struct.unpack_from("<4sII", raw)
    assert (magic, version, length) == (b"glTF", 2, len(raw))
    g = pygltflib.GLTF2().load(str(path))  # a structural load of the whole file
    doc = json.loads(g.to_json())
    blob = g.binary_blob()
    assert len(raw) % 4 == 0 and doc["asset"]["version"] == "2.0" and doc["buffers"][0]["byteLength"] <= len(blob)
    arrays = {}

    def accessor(i):
        a = doc["accessors"][i]
        v = doc["bufferViews"][a["bufferView"]]
        dt, k = np.dtype(COMPONENTS[a["componentType"]]), WIDTH[a["type"]]
        start = v.get("byteOffset", 0) + a.get("byteOffset", 0)
        assert start % dt.itemsize == 0 and start % 4 == 0
        assert a["count"] * k * dt.itemsize <= v["byteLength"] and v["byteOffset"] + v["byteLength"] <= len(blob)
        return np.frombuffer(blob, dt, a["count"] * k, start).reshape(a["count"], k)

    (prim,) = doc["meshes"][0]["primitives"]
    for name, i in prim["attributes"].items():
        assert name in ("POSITION", "NORMAL", "COLOR_0") or name.startswith("_"), name
        assert doc["bufferViews"][doc["accessors"][i]["bufferView"]]["target"] == 34962
        arrays[name] = accessor(i)
    pos_acc = doc["accessors"][prim["attributes"]["POSITION"]]
    assert np.allclose(pos_acc["min"], arrays["POSITION"].min(0)) and np.allclose(pos_acc["max"], arrays["POSITION"].max(0))
    assert len({len(a) for a in arrays.values()}) == 1
    assert np.all((arrays["COLOR_0"] >= 0) & (arrays["COLOR_0"] <= 1))  # the validator's ACCESSOR_NON_CLAMPED
    assert np.allclose(np.linalg.norm(arrays["NORMAL"], axis=1), 1, atol=1e-5)  # ACCESSOR_NON_UNIT
    tri = accessor(prim["indices"]).reshape(-1, 3)
    assert prim.get("mode", 4) == 4 and tri.max() < len(arrays["POSITION"])
    assert "KHR_materials_unlit" in doc["extensionsUsed"]
    return doc, arrays, tri


def sh_stack(arrays):
    """(A, 3, n) float64 from the _SH_i attributes."""
    n = len([k for k in arrays if re.fullmatch(r"_SH_\d+", k)])
    return np.stack([arrays[f"_SH_{i}"] for i in range(n)], -1).astype(np.float64)


def check_glb(path, expected_radiance, expected_coefficients, *, full: bool, store):
    """The file loads in trimesh with its vertices and custom attributes, and its numbers are the expected ones
    at the vertices it names (``_VERTEX_ID``): radiance, linear COLOR_0 times its scale, SH coefficients, and the
    radiance re-evaluated from its own SH coefficients toward the eye (T-7)."""
    import trimesh

    from lodprt.model import sh

    doc, arrays, tri = read_glb(path)
    mesh = trimesh.load(path, force="mesh", process=False)
    assert len(mesh.vertices) == len(arrays["POSITION"]) and len(mesh.faces) == len(tri)
    n = expected_coefficients.shape[-1]
    assert {f"_SH_{i}" for i in range(n)} | {"_RADIANCE", "_VERTEX_ID"} <= set(mesh.vertex_attributes)
    assert f"_SH_{n}" not in arrays
    ids = arrays["_VERTEX_ID"][:, 0].astype(np.int64)
    assert np.array_equal(ids, arrays["_VERTEX_ID"][:, 0]) and len(np.unique(ids)) == len(ids)
    referenced = np.unique(store.faces)
    if full:
        assert set(referenced) <= set(ids.tolist())
    else:
        assert len(ids) < len(referenced)
    np.testing.assert_array_equal(arrays["POSITION"], store.positions[ids].astype(np.float32))
    ref = expected_radiance[ids].astype(np.float64)
    tol = 1e-5 * float(np.abs(expected_radiance).max())
    np.testing.assert_allclose(arrays["_RADIANCE"], ref, rtol=1e-4, atol=tol)
    meta = doc["asset"]["extras"]["lodprt"]
    assert meta["vertex_colors"] == "linear"
    np.testing.assert_allclose(arrays["COLOR_0"] / meta["color_scale"], np.clip(ref, 0, None), rtol=1e-4, atol=tol)
    coeffs = sh_stack(arrays)
    c_tol = 1e-5 * float(np.abs(expected_coefficients).max())
    np.testing.assert_allclose(coeffs, expected_coefficients[ids], rtol=1e-4, atol=c_tol)
    d = np.asarray(EYE) - arrays["POSITION"].astype(np.float64)
    own = np.einsum("vci,vi->vc", coeffs, sh.basis(d / np.linalg.norm(d, axis=1, keepdims=True), 3 if n == 9 else 1))
    np.testing.assert_allclose(own, ref, rtol=1e-3, atol=10 * tol)
    return doc, arrays


@pytest.mark.parametrize("name", list(KINDS))
@pytest.mark.parametrize("full", [False, True], ids=["cut", "full"])
def test_export_sample_equals_radiance(stores, tmp_path, capsys, name, full):
    """``export --sample K``: a GLB trimesh loads with its vertex count and _SH_i attributes, whose linear COLOR_0
    and _RADIANCE equal Store.radiance(K, eye) and whose _SH_i equal the completed coefficients times the
    intensity, for 1- and 3-channel, 1- and 9-coefficient stores, view cut and full mesh."""
    from lodprt.store.bake_store import open_store

    store = open_store(stores[name])
    out = tmp_path / "k.glb"
    rc, text, err = run(["export", stores[name], "--sample", 4, "--eye", *EYE, "--vertex-colors", "linear",
                         "--size", 320, 240, *(["--full"] if full else []), "-o", out], capsys)
    assert rc == 0, err
    assert "wrote" in text and ("full resolution" if full or name.endswith("nohier") else "view cut") in text
    coeffs = store.coefficients(4) * np.asarray(INTENSITY)[None, :, None]  # a grey store broadcasts to RGB
    check_glb(out, store.radiance(4, EYE), coeffs, full=full or name.endswith("nohier"), store=store)


def rotate(q, v):
    """Vector ``v`` turned by the unit quaternion q = (x, y, z, w) (Hamilton, as glTF): v + 2 w (u x v) +
    2 u x (u x v), u = (x, y, z)."""
    u, w = np.asarray(q[:3], np.float64), float(q[3])
    v = np.asarray(v, np.float64)
    return v + 2 * w * np.cross(u, v) + 2 * np.cross(u, np.cross(u, v))


def test_export_camera_and_point_lights(stores, tmp_path, capsys):
    """The .glb has a perspective camera node at the eye whose -z looks at the target with +y up on screen, and a
    KHR_lights_punctual point light node per light, at its position with its RGB intensity (read with pygltflib)."""
    import pygltflib

    target, lights = (0.0, 0.2, 0.0), [(0.1, 0.9, 0.1), (-0.2, 0.95, 0.0)]  # inside the light box
    colors = [(1.0, 0.5, 0.25), (0.2, 0.4, 0.8)]
    out = tmp_path / "cam.glb"
    argv = ["export", stores["rgb"], "--eye", *EYE, "--target", *target, "--size", 320, 240, "--fov", 50,
            "--outside", "error"]
    for light, color in zip(lights, colors):
        argv += ["--light", *light, "--color", *color]
    rc, _, err = run([*argv, "-o", out], capsys)
    assert rc == 0, err
    doc, _, _ = read_glb(out)
    g = pygltflib.GLTF2().load(str(out))
    assert sorted(g.scenes[0].nodes) == list(range(len(g.nodes))) == [0, 1, 2, 3]
    (cam_node,) = [n for n in g.nodes if n.camera is not None]
    cam = g.cameras[cam_node.camera]
    assert cam.type == "perspective"
    assert cam.perspective.yfov == pytest.approx(np.radians(50)) and cam.perspective.aspectRatio == pytest.approx(4 / 3)
    assert cam.perspective.znear > 0
    np.testing.assert_allclose(cam_node.translation, EYE)
    q = cam_node.rotation
    assert np.linalg.norm(q) == pytest.approx(1)
    forward = np.subtract(target, EYE) / np.linalg.norm(np.subtract(target, EYE))
    np.testing.assert_allclose(rotate(q, (0, 0, -1)), forward, atol=1e-6)
    screen_up = rotate(q, (0, 1, 0))
    assert abs(screen_up @ forward) < 1e-6 and screen_up[1] > 0 and abs(rotate(q, (1, 0, 0))[1]) < 1e-6
    assert "KHR_lights_punctual" in doc["extensionsUsed"]
    punctual = doc["extensions"]["KHR_lights_punctual"]["lights"]
    nodes = [n for n in doc["nodes"] if "KHR_lights_punctual" in n.get("extensions", {})]
    assert len(punctual) == len(nodes) == 2
    for node, light, color in zip(nodes, lights, colors):
        spec = punctual[node["extensions"]["KHR_lights_punctual"]["light"]]
        assert spec["type"] == "point"
        np.testing.assert_allclose(node["translation"], light)
        np.testing.assert_allclose(np.multiply(spec["color"], spec["intensity"]), color)
        assert max(spec["color"]) == pytest.approx(1.0)


def test_look_at_quaternion_in_every_direction():
    """``look_at_quaternion`` turns -z onto the view direction and +y into the up half-plane for random views and
    for the half turn (looking along +z, the singular case of the trace formula)."""
    from lodprt.display.export import look_at_quaternion

    rng = np.random.default_rng(3)
    views = [((0, 0, 0), (0, 0, 1)), ((0, 0, 0), (0, 0, -1)), ((1, 2, 3), (1.0, 2.0, 4.0))]
    views += [(tuple(rng.normal(size=3)), tuple(rng.normal(size=3))) for _ in range(50)]
    for eye, target in views:
        q = look_at_quaternion(eye, target, (0.0, 1.0, 0.0))
        f = np.subtract(target, eye) / np.linalg.norm(np.subtract(target, eye))
        np.testing.assert_allclose(rotate(q, (0, 0, -1)), f, atol=1e-9)
        up = rotate(q, (0, 1, 0))
        assert abs(up @ f) < 1e-9 and up[1] > 0
    for target in ((0.0, -3.0, 0.0), (0.0, 3.0, 0.0)):  # straight along up: the viewers' fallback (it was NaN)
        q = look_at_quaternion((0.0, 0.0, 0.0), target, (0.0, 1.0, 0.0))
        assert np.isfinite(q).all() and abs(np.linalg.norm(q) - 1) < 1e-12
        np.testing.assert_allclose(rotate(q, (0, 0, -1)), np.sign(target[1]) * np.array([0, 1.0, 0]), atol=1e-9)


@pytest.mark.parametrize("name", ["grey", "rgb"])
@pytest.mark.parametrize("full", [False, True], ids=["cut", "full"])
def test_export_lights_equals_radiance_command(stores, tmp_path, capsys, name, full):
    """``export --light ... --color ...``: _RADIANCE and linear COLOR_0 equal what ``lodprt radiance --light``
    writes for the same lights, colours and eye; _SH_i equal light_coefficients (T-12 + T-15)."""
    from lodprt.runtime.frames import light_coefficients
    from lodprt.store.bake_store import open_store

    lights = ["--light", 0.2, 0.95, 0.1, "--light", -0.3, 0.9, -0.2, "--color", 1.0, 0.5, 0.25, "--color", 0.2, 0.4, 1.5]
    rc, _, err = run(["radiance", stores[name], *lights, "--eye", *EYE, "-o", tmp_path / "rad.npy"], capsys)
    assert rc == 0, err
    out = tmp_path / "l.glb"
    rc, _, err = run(["export", stores[name], *lights, "--eye", *EYE, "--vertex-colors", "linear",
                      *(["--full"] if full else []), "-o", out], capsys)
    assert rc == 0, err
    store = open_store(stores[name])
    _, _, coeffs = light_coefficients(store, [(0.2, 0.95, 0.1), (-0.3, 0.9, -0.2)],
                                      colors=[(1.0, 0.5, 0.25), (0.2, 0.4, 1.5)])
    check_glb(out, np.load(tmp_path / "rad.npy"), coeffs, full=full, store=store)


def test_display_colors_are_the_render_tone_mapping(stores, tmp_path, capsys):
    """Default COLOR_0 is clip(2^exposure L / white, 0, 1) with the white recorded in the file (the run time's),
    and --white sets it; an export without --eye uses the default eye and the middle light sample."""
    from lodprt.runtime.camera import default_eye
    from lodprt.store.bake_store import open_store

    store = open_store(stores["rgb"])
    for extra, white in (([], None), (["--white", 0.5, "--exposure", 1.0], 0.5)):
        out = tmp_path / f"d{len(extra)}.glb"
        rc, _, err = run(["export", stores["rgb"], "-o", out, *extra], capsys)
        assert rc == 0, err
        doc, arrays, _ = read_glb(out)
        meta = doc["asset"]["extras"]["lodprt"]
        assert meta["vertex_colors"] == "display" and meta["sample"] == store.num_samples // 2
        np.testing.assert_allclose(meta["eye"], default_eye(store))
        if white is not None:
            assert meta["white"] == white and meta["exposure"] == 1.0
        ids = arrays["_VERTEX_ID"][:, 0].astype(int)
        L = store.radiance(store.num_samples // 2, default_eye(store))[ids].astype(np.float64)
        expected = np.clip(L * 2.0 ** meta["exposure"] / meta["white"], 0, 1)
        np.testing.assert_allclose(arrays["COLOR_0"], expected, atol=2e-5)
        assert 0 < expected.mean() < 1


def test_export_glb_api_and_overwrite(stores, tmp_path):
    """``lodprt.export_glb`` takes a path, refuses an existing file without overwrite (leaving it as it was) and
    replaces it whole with overwrite."""
    import lodprt
    from lodprt.errors import LodprtError

    out = tmp_path / "api.glb"
    out.write_bytes(b"keep me")
    with pytest.raises(LodprtError, match="already exists"):
        lodprt.export_glb(stores["grey"], out, sample=0)
    assert out.read_bytes() == b"keep me"
    stats = lodprt.export_glb(stores["grey"], out, sample=0, lod=False, overwrite=True)
    assert stats["bytes"] == out.stat().st_size and stats["vertices"] == len(read_glb(out)[1]["POSITION"])
    assert not list(tmp_path.glob(".*partial*"))


@pytest.mark.parametrize("argv, message", [
    (["export", "{missing}", "-o", "{out}"], "no such store"),
    (["export", "{store}", "--sample", 99, "-o", "{out}"], "sample 99 out of range"),
    (["export", "{store}", "--sample", -1, "-o", "{out}"], "sample -1 out of range"),
    (["export", "{store}", "-o", "{existing}"], "already exists; pass --overwrite"),
    (["export", "{store}", "-o", "{wrong}"], "must be a .glb file"),
    (["export", "{store}", "--sample", 1, "--color", 1, 1, 1, "-o", "{out}"], "--color goes with --light, not with --sample"),
    (["export", "{store}", "--color", 1, 1, 1, "-o", "{out}"], "without --light the middle stored sample is drawn"),
    (["export", "{store}", "--light", 0, 1, 0, "--color", 1, 1, 1, "--color", 1, 1, 1, "-o", "{out}"], "--color: 2 given"),
    (["export", "{store}", "--white", 0, "-o", "{out}"], "--white 0"),
])
def test_bad_input_is_one_line(stores, tmp_path, capsys, argv, message):
    """Bad input (missing store, bad --sample, an existing output without --overwrite, a wrong suffix, bad
    colours or white) exits 2 with one line naming the problem, and writes nothing."""
    (tmp_path / "existing.glb").write_bytes(b"x")
    paths = {"missing": tmp_path / "missing.zarr", "store": stores["grey"], "out": tmp_path / "o.glb",
             "existing": tmp_path / "existing.glb", "wrong": tmp_path / "o.gltf"}
    rc, _, err = run([str(a).format(**paths) for a in argv], capsys)
    assert rc == 2 and message in err and err.count("\n") == 1 and err.startswith("lodprt export: error:")
    assert not (tmp_path / "o.glb").exists() and (tmp_path / "existing.glb").read_bytes() == b"x"


# -- irradiance formats (IF-1..IF-3) --------------------------------------------------------------------------------
def unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def babylon_eval(c, n):
    """E(n) as Babylon.js evaluates ``irradianceCoefficients`` (its SH3ylmBasisConstants, Condon-Shortley signs)."""
    x, y, z = n.T
    k = np.array([np.sqrt(1 / (4 * np.pi)), -np.sqrt(3 / (4 * np.pi)), np.sqrt(3 / (4 * np.pi)),
                  -np.sqrt(3 / (4 * np.pi)), np.sqrt(15 / (4 * np.pi)), -np.sqrt(15 / (4 * np.pi)),
                  np.sqrt(5 / (16 * np.pi)), -np.sqrt(15 / (4 * np.pi)), np.sqrt(15 / (16 * np.pi))])
    t = np.stack([np.ones_like(x), y, z, x, x * y, y * z, 3 * z * z - 1, x * z, x * x - y * y], 1)
    return (t * k) @ np.asarray(c)


def unity_shade_sh9(regs, n_lodprt):
    """Unity's ShadeSH9 (UnityCG.cginc: SHEvalLinearL0L1 + SHEvalLinearL2) on the 7 registers, at the normal as
    Unity sees it (left-handed: x mirrored); returns E/pi."""
    n = n_lodprt * [-1, 1, 1]
    a = np.concatenate([n, np.ones((len(n), 1))], 1)
    b = n[:, [0, 1, 2, 2]] * n[:, [1, 2, 2, 0]]
    c = n[:, 0] ** 2 - n[:, 1] ** 2
    out = [a @ regs[f"unity_SHA{ch}"] + b @ regs[f"unity_SHB{ch}"] + regs["unity_SHC"][i] * c
           for i, ch in enumerate("rgb")]
    return np.stack(out, 1)


def filament_eval(f, n):
    """Filament's shader (Irradiance_SphericalHarmonics) on pre-scaled coefficients: E/pi, clamped at 0."""
    x, y, z = n.T
    t = np.stack([np.ones_like(x), y, z, x, y * x, y * z, 3 * z * z - 1, z * x, x * x - y * y], 1)
    return np.maximum(t @ np.asarray(f), 0.0)


def consumers(coeffs):
    """format -> E(n) function evaluating that format's document the way its consumer does."""
    from lodprt.model.irradiance_formats import export_document

    g = export_document("gltf", coeffs)["KHR_lights_environment"]["lights"][0]["irradianceCoefficients"]
    u = export_document("unity", coeffs)
    f = export_document("filament", coeffs)
    regs = {k: np.asarray(v) for k, v in u["shader_constants"].items()}
    return {"gltf": lambda n: babylon_eval(g, n), "unity": lambda n: np.pi * unity_shade_sh9(regs, n),
            "filament": lambda n: np.pi * filament_eval(f["irradiance"], n)}


def test_formats_match_ramamoorthi_hanrahan():
    """For a sky and random lighting, each exported format evaluated the way its consumer does equals R-H's
    E(n) = n^T M n (eq. 12) at 200 normals (Filament's clamp at 0 applied to the reference)."""
    from lodprt.model.environment import load_environment
    from lodprt.model.irradiance import irradiance, lighting_coefficients

    rng = np.random.default_rng(3)
    n = unit(rng.normal(size=(200, 3)))
    for L in (lighting_coefficients(load_environment("sky:64")), rng.normal(size=(3, 9))):
        e = irradiance(n, L, method="matrix")
        for fmt, evaluate in consumers(L).items():
            ref = np.maximum(e, 0) if fmt == "filament" else e
            np.testing.assert_allclose(evaluate(n), ref, rtol=1e-9, atol=1e-12, err_msg=fmt)


def test_formats_match_directional_light_closed_form():
    """One directional light of unit radiance from d (L_lm = y_lm(d)): every format gives the 3-band clamped
    cosine 1/4 + cos/2 + 5/32 (3 cos^2 - 1) of n.d (Legendre addition theorem), whatever its basis signs and axes."""
    from lodprt.model import sh

    rng = np.random.default_rng(7)
    for d in unit(rng.normal(size=(4, 3))):
        L = np.repeat(sh.basis(d[None], 3), 3, axis=0)
        n = unit(rng.normal(size=(50, 3)))
        t = n @ d
        closed = 0.25 + 0.5 * t + 5 / 32 * (3 * t * t - 1)
        for fmt, evaluate in consumers(L).items():
            ref = np.maximum(closed, 0) if fmt == "filament" else closed
            np.testing.assert_allclose(evaluate(n), np.repeat(ref[:, None], 3, 1), atol=1e-12, err_msg=fmt)


def test_unity_and_filament_layouts():
    """Unity: a constant environment of radiance c puts c in sh[ch, 0] and 0 elsewhere (AddAmbientLight's
    layout), the registers pack SphericalHarmonicsL2 as Unity does; lodprt's y_i = k_i P_i; Filament's sh.txt
    lines parse back to its coefficients."""
    from lodprt.model import irradiance_formats as F
    from lodprt.model import sh
    from lodprt.model.environment import load_environment
    from lodprt.model.irradiance import lighting_coefficients

    L = lighting_coefficients(load_environment("constant:32")) * np.array([[0.5], [1.0], [2.0]])
    u = np.asarray(F.export_document("unity", L)["SphericalHarmonicsL2"])
    np.testing.assert_allclose(u[:, 0], [0.5, 1.0, 2.0], rtol=1e-6)
    np.testing.assert_allclose(u[:, 1:], 0, atol=1e-3)  # the 32 x 64 map's quadrature error, not the layout
    rng = np.random.default_rng(1)
    sh9 = rng.normal(size=(3, 9))
    regs = F.unity_shader_registers(sh9)
    assert regs["unity_SHAg"] == pytest.approx([sh9[1, 3], sh9[1, 1], sh9[1, 2], sh9[1, 0] - sh9[1, 6]])
    assert regs["unity_SHBb"] == pytest.approx([sh9[2, 4], sh9[2, 5], 3 * sh9[2, 6], sh9[2, 7]])
    assert regs["unity_SHC"] == pytest.approx([sh9[0, 8], sh9[1, 8], sh9[2, 8], 1.0])
    n = unit(rng.normal(size=(20, 3)))
    x, y, z = n.T
    p = np.stack([np.ones_like(x), y, z, x, x * y, y * z, 3 * z * z - 1, x * z, x * x - y * y], 1)
    np.testing.assert_allclose(sh.basis(n, 3), p * F.BASIS_CONSTANTS, atol=1e-14)
    doc = F.export_document("filament", rng.normal(size=(3, 9)))
    rows = [[float(v) for v in re.findall(r"-?\d+\.\d+", line)] for line in doc["sh_txt"].splitlines()]
    np.testing.assert_allclose(rows, doc["irradiance"], atol=1e-12)
    assert doc["sh_txt"].splitlines()[1].endswith("// L1-1, irradiance, pre-scaled base")


def test_irradiance_format_command(capsys):
    """``lodprt irradiance ENV --format F`` prints exactly the document of the projected coefficients; --json with
    --format is refused in one line; a bad format is refused by the parser."""
    from lodprt.model.environment import load_environment
    from lodprt.model.irradiance import lighting_coefficients
    from lodprt.model.irradiance_formats import export_document

    L = lighting_coefficients(load_environment("sky:32"))
    for fmt in ("gltf", "unity", "filament"):
        rc, text, _ = run(["irradiance", "sky:32", "--format", fmt], capsys)
        assert rc == 0
        assert json.loads(text) == json.loads(json.dumps(export_document(fmt, L, source=load_environment("sky:32").source)))
    rc, _, err = run(["irradiance", "sky:32", "--format", "unity", "--json"], capsys)
    assert rc == 2 and err.count("\n") == 1 and "--format" in err
    with pytest.raises(SystemExit):
        main(["irradiance", "sky:32", "--format", "unreal"])


# -- turntable video ------------------------------------------------------------------------------------------------
@pytest.mark.usefixtures("gl")
def test_turntable_mp4(stores, tmp_path, capsys):
    """``turntable -o x.mp4`` writes H.264 that decodes to --frames frames of --size (odd sizes padded to even),
    whose first frame is the PNG turntable's first frame (within the codec's loss); no partial file stays."""
    import imageio_ffmpeg
    from PIL import Image

    view = ["--frames", 4, "--eye", *EYE, "--light", 0.1, 0.95, 0.1]
    for w, h in ((96, 64), (97, 63)):
        out = tmp_path / f"t{w}.mp4"
        rc, _, err = run(["turntable", stores["rgb"], *view, "--size", w, h, "-o", out], capsys)
        assert rc == 0, err
        reader = imageio_ffmpeg.read_frames(str(out))
        meta = next(reader)
        frames = [np.frombuffer(f, np.uint8).reshape(meta["size"][1], meta["size"][0], 3) for f in reader]
        assert meta["codec"] == "h264" and meta["size"] == (w + w % 2, h + h % 2) and len(frames) == 4
    rc, _, err = run(["turntable", stores["rgb"], *view, "--size", 96, 64, "-o", tmp_path / "png"], capsys)
    assert rc == 0, err
    png = np.asarray(Image.open(tmp_path / "png" / "frame_0000.png"), np.float64)
    first = tmp_path / "t96.mp4"
    reader = imageio_ffmpeg.read_frames(str(first))
    next(reader)
    decoded = np.frombuffer(next(reader), np.uint8).reshape(64, 96, 3).astype(np.float64)
    assert png.std() > 10 and np.abs(decoded - png).mean() < 6
    rc, _, err = run(["turntable", stores["rgb"], *view, "--size", 96, 64, "-o", first], capsys)
    assert rc == 2 and "already exists" in err
    assert not list(tmp_path.glob(".*partial*"))


def test_turntable_mp4_without_the_extra(stores, tmp_path, capsys, monkeypatch):
    """Without imageio-ffmpeg, ``turntable -o x.mp4`` fails in one line naming pip install 'lodprt[video]' and
    writes nothing."""
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # import imageio_ffmpeg now raises ImportError
    out = tmp_path / "v.mp4"
    rc, _, err = run(["turntable", stores["rgb"], "--frames", 2, "-o", out], capsys)
    assert rc == 2 and "pip install 'lodprt[video]'" in err and err.count("\n") == 1
    assert not out.exists() and not list(tmp_path.iterdir())


#: where .ci/run installs the Khronos glTF validator (``npm install --prefix .ci/node gltf-validator``)
VALIDATOR = Path(__file__).resolve().parents[1] / ".ci" / "node" / "node_modules" / "gltf-validator"
VALIDATE_JS = """
const fs = require('fs'), v = require(process.argv[1]);
v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])), {maxIssues: 100})
  .then((r) => console.log(JSON.stringify(r.issues)))
  .catch((e) => { console.error(String(e)); process.exit(2); });
"""


@pytest.mark.parametrize("name, full", [("rgb", False), ("grey-nohier", True)])
def test_khronos_validator_reports_nothing(stores, tmp_path, capsys, name, full):
    """The Khronos glTF validator (the npm package, installed by .ci/run) reports 0 errors, warnings, infos and
    hints on an exported .glb with a camera, two KHR_lights_punctual lights and the SH extras."""
    import shutil
    import subprocess

    node = shutil.which("node")
    if node is None or not VALIDATOR.is_dir():
        pytest.skip("the Khronos glTF validator is not installed (.ci/run: npm install --prefix .ci/node "
                    "gltf-validator)")
    out = tmp_path / "v.glb"
    argv = ["export", stores[name], "--eye", *EYE, "--light", 0.1, 0.9, 0.1, "--light", -0.2, 0.95, 0.0,
            "--outside", "error", "-o", out] + (["--full"] if full else [])
    rc, _, err = run(argv, capsys)
    assert rc == 0, err
    res = subprocess.run([node, "-e", VALIDATE_JS, str(VALIDATOR), str(out)], capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr
    issues = json.loads(res.stdout)
    counts = {k: issues[k] for k in ("numErrors", "numWarnings", "numInfos", "numHints")}
    assert counts == {"numErrors": 0, "numWarnings": 0, "numInfos": 0, "numHints": 0}, issues["messages"]


def test_export_docs_say_radiance_is_the_sh_reconstruction():
    """docs/EXPORT.md described _RADIANCE as "L itself", yet export writes negative values there (SH ringing): the
    row says it is the SH reconstruction, which can ring below 0, while COLOR_0 is clipped."""
    docs = (Path(__file__).resolve().parents[1] / "docs" / "EXPORT.md").read_text()
    (row,) = [line for line in docs.splitlines() if line.startswith("| `_RADIANCE`")]
    assert "SH reconstruction" in row and "below 0" in row and "`COLOR_0` is clipped" in row, row
