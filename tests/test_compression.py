"""Lossy coefficient codecs (format version 2, lodprt.store.codecs, C-1..C-5): each codec within its stated bound on
random and baked data, exact identities (cpca with every vector and float32 weights; lossless structure arrays;
compressed-domain relighting equal to relighting the decoded coefficients), version 1 stores still open, the CLI."""

import json

import numpy as np
import pytest
import trimesh

from lodprt.cli.main import main
from lodprt.errors import LodprtError, StoreError
from lodprt.model.scene import Material, assemble_scene
from lodprt.precompute.bake import bake
from lodprt.store import codecs
from lodprt.store.bake_store import open_store
from lodprt.store.compress import compress_store

CODECS = ["f16", "q8", "q10", "q12", "cpca:16:4", "cpca:8:27:32"]


@pytest.fixture(scope="module")
def scene():
    """An icosphere (642 vertices) on a 12 x 12 floor, coloured Phong (3 channels, order 3: 9 coefficients)."""
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    pos = np.asarray(ball.vertices) + [0.0, 0.1, 0.0]
    mat = Material(kd=(0.8, 0.5, 0.3), ks=0.3, shininess=6.0)
    return assemble_scene([("ball", pos, np.asarray(ball.faces), mat)], (12, 0.5, mat), {"grid": [2, 1, 2]},
                          "lights", "ball")


@pytest.fixture(scope="module")
def stores(scene, tmp_path_factory):
    """A light-cut bake (20 degrees) and a full-resolution bake of ``scene``, format version 1."""
    folder = tmp_path_factory.mktemp("compression")
    cut, full = folder / "cut.zarr", folder / "full.zarr"
    bake(scene, cut, sh_order=3, device="cpu", threshold_deg=20.0)
    bake(scene, full, sh_order=3, device="cpu", hierarchy=False)
    return {"cut": cut, "full": full, "folder": folder}


def rng_coefficients(seed, k=400, c=3, n=16):
    """Random coefficients over 12 orders of magnitude, signs mixed, some exact zeros (wide-range stress)."""
    rng = np.random.default_rng(seed)
    mag = 10.0 ** rng.uniform(-9, 3, size=(k, c, n))
    out = (mag * rng.choice([-1.0, 1.0], size=mag.shape)).astype(np.float32)
    out[rng.random(out.shape) < 0.05] = 0.0
    return out


# -- codec strings ---------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("text,name", [("none", "none"), ("F16", "f16"), ("q8", "q8"), ("q12", "q12"),
                                       ("cpca:256:3", "cpca:256:3"), ("cpca:4:2:32", "cpca:4:2:32"),
                                       ("cpca:4:2:8", "cpca:4:2")])
def test_codec_names(text, name):
    assert codecs.parse_codec(text).name == name


@pytest.mark.parametrize("text", ["q9", "q16", "zstd", "cpca", "cpca:0:3", "cpca:4:0", "cpca:4:2:12", "cpca:4", ""])
def test_bad_codec_names_the_option(text):
    with pytest.raises(LodprtError, match="--compress") as info:
        codecs.parse_codec(text, "--compress")
    assert "\n" not in str(info.value)


# -- bounds on random data -------------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1])
def test_f16_bound(seed):
    """C-1: |c^ - c| <= 2^-11 |c| + 2^(e-25) per element; values above float16's range survive the scale."""
    c = rng_coefficients(seed) * np.float32(1e3)  # up to 1e6: beyond float16's 65504 without the scale
    arrays, attrs = codecs.encode_f16(c)
    got = codecs.decode_sample("f16", arrays, attrs)
    bound = 2.0**-11 * np.abs(c.astype(np.float64)) + 2.0 ** (attrs["scale_exponent"] - 25)
    assert (np.abs(got.astype(np.float64) - c) <= bound).all()
    assert np.isfinite(got).all()


@pytest.mark.parametrize("bits", [8, 10, 12])
@pytest.mark.parametrize("seed", [0, 1])
def test_q_bound(bits, seed):
    """C-2: half a quantisation step of the stored band scale, which is >= the band's maximum and within 2^-10 of
    it where float16 is normal; fewer bits for higher bands; the integers use the declared range."""
    c = rng_coefficients(seed)
    arrays, attrs = codecs.encode_q(c, bits)
    got = codecs.decode_sample(f"q{bits}", arrays, attrs).astype(np.float64)
    assert attrs["band_bits"] == [max(bits - l, 4) for l in range(4)]
    for l, s in enumerate(codecs.band_slices(16)):
        L = 2 ** (attrs["band_bits"][l] - 1) - 1
        err = np.abs(got[:, :, s] - c[:, :, s]).max(axis=(1, 2))
        stored = arrays["band_scales"][:, l].astype(np.float64) * 2.0 ** attrs["scale_exponent"]
        assert (err <= stored / (2 * L) * (1 + 1e-6)).all(), l
        true_max = np.abs(c[:, :, s].astype(np.float64)).max(axis=(1, 2))
        assert (stored >= true_max).all()
        normal = true_max >= 2.0 ** (attrs["scale_exponent"] - 14)  # float16 scale in its normal range
        assert (err[normal] <= true_max[normal] * (1 + 2.0**-10) / (2 * L) * (1 + 1e-6)).all(), l
        assert np.abs(arrays["coefficients_q"][:, :, s]).max() <= L
    assert arrays["coefficients_q"].dtype == (np.int8 if bits == 8 else np.int16)


def test_cpca_bound_against_a_float64_projection():
    """C-3: each row within its distance to the cluster's affine subspace (computed here in float64 from the
    stored mean and basis) plus the weights' quantisation term; the basis is orthonormal."""
    X = rng_coefficients(2, k=600, c=1, n=16).reshape(600, 16) / np.float32(1e3)
    codec = codecs.parse_codec("cpca:6:3")
    fit = codecs.cpca_fit(X, codec)
    got = codecs.cpca_decode(fit, fit["cluster"], fit["weights"]).astype(np.float64)
    k = fit["cluster"].astype(int)
    B = fit["basis"].astype(np.float64)
    np.testing.assert_allclose(np.einsum("kmd,knd->kmn", B, B), np.broadcast_to(np.eye(3), (6, 3, 3)), atol=1e-5)
    y = X - fit["mean"][k]
    resid = np.linalg.norm(y - np.einsum("rm,rmd->rd", np.einsum("rd,rmd->rm", y, B[k]), B[k]), axis=1)
    quant = np.sqrt(((fit["weight_scale"][k] / (2 * 127.0)) ** 2).sum(1))
    err = np.linalg.norm(got - X, axis=1)
    assert (err <= resid + quant + 1e-5 * np.linalg.norm(X, axis=1) + 1e-12).all()
    assert fit["weights"].dtype == np.int8 and fit["cluster"].dtype == np.uint8


def test_cpca_every_vector_with_float32_weights_is_lossless():
    """C-3 with VECTORS = D and float32 weights: the cluster bases span everything, the error is float rounding."""
    X = rng_coefficients(3, k=300, c=1, n=9).reshape(300, 9)
    fit = codecs.cpca_fit(X, codecs.parse_codec("cpca:5:9:32"))
    got = codecs.cpca_decode(fit, fit["cluster"], fit["weights"])
    np.testing.assert_allclose(got, X, rtol=0, atol=1e-5 * np.abs(X).max())


def test_cpca_finds_points_on_affine_subspaces():
    """Points lying exactly on 3 far-apart 2-d affine subspaces: 3 clusters and 2 vectors reconstruct them to
    float rounding (k-means and the reassignment must find the three groups)."""
    rng = np.random.default_rng(4)
    rows = []
    for j in range(3):
        origin = rng.normal(size=12) * 100.0
        plane = np.linalg.qr(rng.normal(size=(12, 2)))[0].T
        rows.append(origin + rng.normal(size=(150, 2)) @ plane)
    X = np.concatenate(rows).astype(np.float32)
    fit = codecs.cpca_fit(X, codecs.parse_codec("cpca:3:2:32"))
    got = codecs.cpca_decode(fit, fit["cluster"], fit["weights"])
    np.testing.assert_allclose(got, X, atol=1e-5 * np.abs(X).max())


def test_structure_round_trip_with_long_gaps():
    """C-4: ids with gaps of 1, 254, 255 and 70,000 come back exactly."""
    ids = np.cumsum([3, 1, 254, 255, 256, 70_000, 1, 1]).astype(np.int32)
    arrays = codecs.encode_structure(ids, None, None, None, None)
    assert arrays["vertex_gaps"].dtype == np.uint8 and len(arrays["vertex_gaps_long"]) == 3
    got, cut = codecs.decode_structure(arrays, None)
    np.testing.assert_array_equal(got, ids)
    assert cut == {}
    with pytest.raises(LodprtError, match="ascending"):
        codecs.encode_structure(ids[::-1], None, None, None, None)


# -- baked stores ----------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def compressed(stores):
    """Every codec applied to the light-cut store: {codec: path}."""
    return {c: compress_store(stores["cut"], stores["folder"] / f"cut-{c.replace(':', '_')}.zarr", c)["path"]
            for c in CODECS}


def test_version_1_store_still_opens(stores):
    store = open_store(stores["cut"])
    assert store.attrs["format_version"] == 1 and store.codec == "none"
    assert store.info()["codec"] == "none"


@pytest.mark.parametrize("codec", CODECS)
def test_baked_samples_within_bound(stores, compressed, codec):
    """Every sample decodes within the codec's bound of the version-1 sample; the structure arrays exactly; the
    recorded max_abs_error is the measured one; the store is version 2 and says its codec."""
    v1, v2 = open_store(stores["cut"]), open_store(compressed[codec])
    assert v2.attrs["format_version"] == 2 and v2.codec == codecs.parse_codec(codec).name
    for k in range(v1.num_samples):
        ids1, c1 = v1.sample(k)
        ids2, c2 = v2.sample(k)
        np.testing.assert_array_equal(ids1, ids2)
        for name, a in v1.cut_arrays(k).items():
            np.testing.assert_array_equal(a, v2.cut_arrays(k)[name])
        err = np.abs(c2.astype(np.float64) - c1)
        info = v2.sample_info(k)
        assert info["max_abs_error"] == pytest.approx(float(err.max()), rel=1e-6, abs=1e-30)
        scale = np.abs(c1).max()
        if codec == "f16":
            assert (err <= 2.0**-11 * np.abs(c1) + 2.0 ** (info["scale_exponent"] - 25)).all()
        elif codec.startswith("q"):
            assert err.max() <= scale / (2 * (2 ** (int(codec[1:]) - 1) - 1)) * 1.001
        elif codec == "cpca:8:27:32":  # every vector: lossless up to float rounding
            assert err.max() <= 1e-5 * scale
        assert info["bytes"] < info["bytes_raw"]


def radiance_bound(store_v2, k, n):
    """Per-vertex radiance bound of a full-resolution sample from its largest coefficient error: |dL| <= |I|
    |dc|_2 |y|_2 with |y|_2 = n / sqrt(4 pi) (Unsold) and |dc|_2 <= sqrt(C N) max|dc| per channel."""
    info = store_v2.sample_info(k)
    return float(np.abs(store_v2.intensity).max() * np.sqrt(n * n) * info["max_abs_error"] * n / np.sqrt(4 * np.pi))


@pytest.mark.parametrize("codec", ["f16", "q8", "cpca:16:4"])
def test_compressed_full_store_frames_within_bound(stores, codec):
    """full_frame of a compressed full-resolution store equals the original's within the radiance bound that
    follows from the recorded coefficient error; the Runtime-free paths (radiance --light) run unchanged."""
    from lodprt.runtime.camera import Camera
    from lodprt.runtime.frames import full_frame, light_radiance

    out = stores["folder"] / f"full-{codec.replace(':', '_')}.zarr"
    compress_store(stores["full"], out, codec)
    v1, v2 = open_store(stores["full"]), open_store(out)
    cam = Camera(eye=(0.3, 0.35, 0.4), target=(0.0, 0.1, 0.0), fov=40, width=64, height=48)
    for k in range(v1.num_samples):
        a, b = full_frame(v1, cam, sample=k), full_frame(v2, cam, sample=k)
        assert np.abs(a.radiance - b.radiance).max() <= radiance_bound(v2, k, 3) + 1e-6
    light = v1.light_positions.mean(0)
    ra, rb = light_radiance(v1, [light], cam.eye), light_radiance(v2, [light], cam.eye)
    assert np.sqrt(((ra - rb) ** 2).mean() / (ra**2).mean()) < (0.05 if codec.startswith("cpca") else 0.005)


def test_compressed_cut_store_runs_the_runtime(stores, compressed):
    """The Runtime (view cut, T-15 completion) on a q12 store: the frame matches the version-1 store's frame."""
    from lodprt.runtime.camera import Camera
    from lodprt.runtime.session import Runtime

    cam = Camera(eye=(0.3, 0.35, 0.4), target=(0.0, 0.1, 0.0), fov=40, width=64, height=48)
    frames = []
    for path in (stores["cut"], compressed["q12"]):
        rt = Runtime(open_store(path), lod=False, device="cpu")
        rt.set_camera(cam)
        frames.append(rt.update())
    a, b = frames
    np.testing.assert_array_equal(a.vertex_ids, b.vertex_ids)
    assert np.sqrt(((a.radiance - b.radiance) ** 2).mean() / (a.radiance**2).mean()) < 1e-3


def test_cpca_relight_equals_decoded_relight(stores, compressed):
    """C-5: relighting the compressed rows equals relighting the decoded coefficients: every vertex of a full
    store, the vertices kept by every active sample of a cut store."""
    from lodprt.runtime.cpca_relight import CompressedSamples
    from lodprt.runtime.frames import light_radiance
    from lodprt.store.bake_store import radiance_toward

    eye = np.array([0.25, 0.3, 0.35])
    full = stores["folder"] / "full-relight.zarr"
    compress_store(stores["full"], full, "cpca:16:4")
    store = open_store(full)
    cs = CompressedSamples(store)
    lights = [store.light_positions.mean(0), store.light_positions[0] * 0.9]
    W = cs.light_weights(lights, colors=[(1.0, 0.5, 0.25), (0.2, 0.4, 1.0)])
    rad, covered = cs.radiance(W, eye)
    # cpca_relight relights in the compressed domain by T-12: the thesis interpolation of the decoded samples
    want = light_radiance(store, lights, eye, colors=[(1.0, 0.5, 0.25), (0.2, 0.4, 1.0)], interpolation="thesis")
    ref = np.unique(store.faces)
    assert covered[ref].all()
    np.testing.assert_allclose(rad[ref], want[ref], rtol=0, atol=1e-5 * np.abs(want).max())

    cut = open_store(compressed["cpca:16:4"])
    cs = CompressedSamples(cut)
    W = cs.light_weights([cut.light_positions.mean(0)])
    rad, covered = cs.radiance(W, eye)
    c = np.zeros((cut.num_vertices, 3, cut.coefficients_per_vertex))
    for j in np.flatnonzero(np.abs(W).sum(1) > 0):
        ids, cj = cut.sample(int(j))
        c[ids] += cj * W[j][None, :, None]
    want = radiance_toward(cut.positions, cut.normals, c, eye, np.ones(3))
    assert covered.sum() > 50
    np.testing.assert_allclose(rad[covered], want[covered], rtol=0, atol=1e-5 * np.abs(want).max())


def test_codec_none_decompresses_to_version_1(stores, compressed):
    """compress --codec none of a version-2 store: a version-1 store holding the decoded coefficients."""
    out = stores["folder"] / "back.zarr"
    compress_store(compressed["q8"], out, "none")
    back, v2 = open_store(out), open_store(compressed["q8"])
    assert back.attrs["format_version"] == 1 and "codec" not in back.attrs
    for k in range(back.num_samples):
        np.testing.assert_array_equal(back.sample(k)[1], v2.sample(k)[1])
        np.testing.assert_array_equal(back.cut_arrays(k)["cut_nodes"], v2.cut_arrays(k)["cut_nodes"])


def test_zarr_and_numpy_decode_of_docs(stores, compressed):
    """The decode steps docs/FORMAT.md shows (zarr + numpy only) give Store.sample's arrays."""
    import zarr

    for codec in ("q8", "cpca:16:4"):
        root = zarr.open_group(str(compressed[codec]), mode="r")
        s = root["samples/00001"]
        g = s["vertex_gaps"][...].astype(np.int64)
        g[g == 255] = s["vertex_gaps_long"][...]
        ids = np.cumsum(g)
        if codec == "q8":
            q, scales, a = s["coefficients_q"][...], s["band_scales"][...], s.attrs
            c = np.empty(q.shape, np.float32)
            for l, b in enumerate(a["band_bits"]):
                step = scales[:, l].astype(np.float32) * np.float32(2.0 ** a["scale_exponent"] / (2 ** (b - 1) - 1))
                c[:, :, l * l:(l + 1) ** 2] = q[:, :, l * l:(l + 1) ** 2] * step[:, None, None]
        else:
            k = s["cluster"][...].astype(np.int64)
            w = s["weights"][...] * (root["codec/weight_scale"][...][k] / root["codec"].attrs["weight_levels"])
            c = root["codec/mean"][...][k] + np.einsum("rm,rmd->rd", w, root["codec/basis"][...][k])
            c = c.reshape(len(k), root.attrs["channels"], root.attrs["coefficients_per_vertex"])
        ids2, c2 = open_store(compressed[codec]).sample(1)
        np.testing.assert_array_equal(ids, ids2)
        np.testing.assert_allclose(c, c2, rtol=1e-6, atol=1e-7 * np.abs(c2).max())


# -- command line ----------------------------------------------------------------------------------------------------


def test_cli_compress_and_info(stores, capsys):
    out = stores["folder"] / "cli-q8.zarr"
    assert main(["compress", str(stores["cut"]), "-o", str(out), "--codec", "q8"]) == 0
    assert "codec q8" in capsys.readouterr().err
    assert main(["compress", str(stores["cut"]), "-o", str(out), "--codec", "q8"]) == 2  # no --overwrite
    assert "--overwrite" in capsys.readouterr().err
    assert main(["compress", str(stores["cut"]), "-o", str(out), "--codec", "q8x", "--overwrite"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--codec" in err and err.count("\n") == 0
    assert main(["compress", str(stores["cut"]), "-o", str(out), "--codec", "cpca:4:28"]) == 2
    assert "VECTORS 28" in capsys.readouterr().err
    assert main(["info", str(out)]) == 0
    assert "codec q8" in capsys.readouterr().out
    assert main(["info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["codec"] == "q8" and info["format_version"] == 2 and info["bytes_total"] < info["bytes_raw_total"]


def test_cli_bake_compress(tmp_path, capsys):
    """bake --compress q10 writes a version-2 store whose samples equal compressing the plain bake; a bad codec
    fails before any work with one line naming --compress."""
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    mesh = tmp_path / "ball.obj"
    ball.export(mesh)
    common = [str(mesh), "--device", "cpu", "--sh-order", "2", "--no-hierarchy"]
    assert main(["bake", *common, "-o", str(tmp_path / "plain.zarr")]) == 0
    assert main(["bake", *common, "-o", str(tmp_path / "q.zarr"), "--compress", "q10"]) == 0
    compress_store(tmp_path / "plain.zarr", tmp_path / "ref.zarr", "q10")
    got, want = open_store(tmp_path / "q.zarr"), open_store(tmp_path / "ref.zarr")
    assert got.codec == "q10"
    for k in range(got.num_samples):
        np.testing.assert_array_equal(got.sample(k)[1], want.sample(k)[1])
    capsys.readouterr()
    assert main(["bake", *common, "-o", str(tmp_path / "bad.zarr"), "--compress", "q7"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--compress" in err and err.count("\n") == 0
    assert not (tmp_path / "bad.zarr").exists()


def test_a_damaged_codec_array_is_one_line_naming_it(stores, compressed, tmp_path):
    """A chunk file of the store-level CPCA basis garbled: decoding a sample says which array is damaged in one
    line, as every damaged read does (it was wrapped as 'cannot decode: StoreError("...")')."""
    import shutil

    cpca = next(path for codec, path in compressed.items() if codec.startswith("cpca"))
    copy = tmp_path / "c.zarr"
    shutil.copytree(cpca, copy)
    chunk = next(p for p in sorted((copy / "codec" / "basis").rglob("*")) if p.is_file() and p.name != "zarr.json")
    chunk.write_bytes(b"garbled garbled")
    with pytest.raises(StoreError) as err:
        open_store(copy).sample(0)
    text = str(err.value)
    assert text.startswith(f"{copy}: array 'codec/basis' is damaged, a chunk cannot be read (") and "\n" not in text
    assert "cannot decode" not in text and "StoreError(" not in text, text
