"""Environment maps: exact texel solid angles, SH projection, rotation, mip levels, files and their errors."""

import numpy as np
import pytest

from lodprt.model import environment as E
from lodprt.model import sh
from lodprt.errors import LodprtError


@pytest.mark.parametrize("kind", ["latlong", "cube"])
@pytest.mark.parametrize("n", [1, 3, 16, 64])
def test_solid_angles_sum_to_4pi(kind, n):
    """The exact per-texel solid angles of lat-long and cube maps sum to 4 pi at any resolution."""
    om = E.texel_solid_angles(kind, n)
    assert (om > 0).all()
    assert abs(om.sum() - 4 * np.pi) < 1e-12


def test_cube_texel_solid_angle_matches_numerical_integration():
    """A corner cube texel's closed-form solid angle equals a fine midpoint integration of (1 + u^2 + v^2)^-3/2."""
    n = 4
    exact = E.texel_solid_angles("cube", n)[0]  # face +x, row 0, column 0: u, v in [-1, -0.5]
    m = 2000
    c = -1 + (np.arange(m) + 0.5) * 0.5 / m
    u, v = np.meshgrid(c, c)
    numeric = ((1 + u * u + v * v) ** -1.5).sum() * (0.5 / m) ** 2
    assert abs(exact - numeric) < 1e-7 * numeric


@pytest.mark.parametrize("kind", ["latlong", "cube"])
def test_texel_directions_round_trip_through_lookup(kind):
    """Looking up each texel centre's direction returns that texel (directions and lookup agree)."""
    env = E.procedural("spots", resolution=8, kind=kind)
    assert np.array_equal(env.lookup(env.directions()), env.radiance())
    assert np.allclose(np.linalg.norm(env.directions(), axis=1), 1)


@pytest.mark.parametrize("kind", ["latlong", "cube"])
def test_constant_environment_projects_to_y0(kind):
    """A constant map projects to exactly sqrt(4 pi) in y_0; higher bands vanish up to the O(1/H^2) midpoint error."""
    errs = []
    for n in (16, 32):
        c = E.procedural("constant", resolution=n, kind=kind).project(4)
        assert np.allclose(c[:, 0], np.sqrt(4 * np.pi), rtol=1e-12)
        errs.append(np.abs(c[:, 1:]).max())
    if kind == "cube":
        assert max(errs) < 1e-12  # the cube's texels are symmetric under the octahedral group: exact to band 3
    else:
        assert errs[0] < 0.01 and 3.5 < errs[0] / errs[1] < 4.5  # texel-centre basis values: second order in 1/H


def test_latlong_and_cube_projections_agree():
    """The sky projected from a 256x512 lat-long map and from a 6x128x128 cube map agrees to 0.1% (order 4)."""
    a = E.procedural("sky", resolution=256).project(4)
    b = E.procedural("sky", resolution=128, kind="cube").project(4)
    assert np.linalg.norm(a - b) < 1e-3 * np.linalg.norm(a)


def test_projection_matches_quadrature_of_the_function():
    """Texel projection of the sky equals a Gauss-Legendre projection of the same function (order 5, 0.2%)."""
    dirs, w = sh.quadrature(200, 400)
    ref = sh.project(E.sky_radiance(dirs), dirs, w, 5)
    got = E.procedural("sky", resolution=256).project(5)
    assert np.linalg.norm(got - ref) < 2e-3 * np.linalg.norm(ref)


def test_rotate_then_project_equals_project_then_rotate_exact_azimuth():
    """Rotating a lat-long map by whole texels about +y then projecting equals rotating its coefficients (1e-12)."""
    env = E.procedural("spots", resolution=32)
    k = 5
    angle = 360.0 * k / (2 * env.resolution)
    rotated = env.rotated_azimuth(k).project(5)
    coeffs = E.rotate_lighting(env.project(5), E.rotation_about_y(angle))
    assert np.abs(rotated - coeffs).max() < 1e-12 * np.abs(coeffs).max() * 100


def test_rotate_then_project_equals_project_then_rotate_any_axis():
    """For a rotation about a tilted axis, projecting the rotated sky equals rotating the sky's coefficients (0.2%)."""
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    a = 1.1
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K
    d = E.texel_directions("latlong", 256)
    om = E.texel_solid_angles("latlong", 256)
    rotated = E.project_texels(E.sky_radiance(d @ R), d, om, 4)  # L'(s) = L(R^T s): row-vector s R = (R^T s)^T
    coeffs = E.rotate_lighting(E.procedural("sky", resolution=256).project(4), R)
    assert np.linalg.norm(rotated - coeffs) < 2e-3 * np.linalg.norm(coeffs)


def test_rotation_about_y_turns_z_toward_x():
    """rotation_about_y(90) maps +z to +x (right-handed about +y), matching the lat-long azimuth direction."""
    assert np.allclose(E.rotation_about_y(90) @ [0, 0, 1], [1, 0, 0])
    env = E.procedural("spots", resolution=16)
    d = env.directions().reshape(16, 32, 3)
    assert np.allclose(E.rotation_about_y(360 / 32) @ d[3, 4], d[3, 5])


@pytest.mark.parametrize("kind", ["latlong", "cube"])
def test_mip_levels_keep_power_and_report_growing_error(kind):
    """Solid-angle box filtering keeps the y_0 coefficient exactly; coarser levels report larger errors."""
    env = E.procedural("sky", resolution=64, kind=kind)
    levels = E.mip_projections(env, 3)
    assert levels[0]["relative_error"] == 0 and levels[0]["shape"][-1] == (64 if kind == "cube" else 128)
    assert [lv["level"] for lv in levels] == list(range(len(levels)))
    c0 = levels[0]["coefficients"][:, 0]
    for lv in levels:
        assert np.allclose(lv["coefficients"][:, 0], c0, rtol=1e-12)
    errs = [lv["relative_error"] for lv in levels]
    assert all(b >= a for a, b in zip(errs[1:], errs[2:]))
    assert errs[2] < 4e-3  # level 2: the paper's 64 x 64 of 256 x 256 is the same ratio (measured 0.30% / 0.09%)


def test_mip_past_the_last_level_names_the_level_once():
    """A mip level past 1 x 1 is one message naming the map, the level and how far it halves (it repeated
    "(mip)" once per level done)."""
    env = E.procedural("sky", resolution=16)
    assert env.mip(4).resolution == 1
    with pytest.raises(LodprtError, match=r"\(latlong 16\): mip level 9: resolution 16 halves only 4 time\(s\), "
                                          r"to 1$") as err:
        env.mip(9)
    assert "(mip)" not in str(err.value)


def test_hdr_round_trip(tmp_path):
    """A lat-long map written as Radiance .hdr reads back within the 8-bit mantissa precision (0.8%)."""
    env = E.procedural("sky", resolution=16)
    p = tmp_path / "sky.hdr"
    E.write_rgbe(p, env.data)
    back = E.load_environment(p)
    assert back.kind == "latlong" and back.data.shape == (16, 32, 3)
    big = env.data.max(axis=2, keepdims=True)
    assert np.abs(back.data - env.data).max() <= 0.008 * big.max()
    assert (np.abs(back.data - env.data) <= 0.008 * big).all()


def _rle_scanline(values: np.ndarray) -> bytes:
    """New-style RLE of one channel: a run for repeated bytes, literal chunks otherwise (test encoder)."""
    out = bytearray()
    i = 0
    while i < len(values):
        j = i
        while j < len(values) and values[j] == values[i] and j - i < 127:
            j += 1
        if j - i >= 3:
            out += bytes([128 + j - i, values[i]])
            i = j
        else:
            k = min(i + 2, len(values))
            out += bytes([k - i]) + bytes(values[i:k])
            i = k
    return bytes(out)


def test_hdr_run_length_scanlines(tmp_path):
    """Run-length encoded RGBE scanlines decode to the same pixels as flat ones."""
    rng = np.random.default_rng(1)
    h, w = 4, 16
    rgbe = rng.integers(100, 120, size=(h, w, 4), dtype=np.uint8)
    rgbe[:, :8] = rgbe[:, :1]  # a run
    body = bytearray()
    for row in rgbe:
        body += bytes([2, 2, w >> 8, w & 255])
        for ch in range(4):
            body += _rle_scanline(row[:, ch])
    head = f"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {h} +X {w}\n".encode()
    (tmp_path / "rle.hdr").write_bytes(head + bytes(body))
    (tmp_path / "flat.hdr").write_bytes(head + rgbe.tobytes())
    assert np.array_equal(E.read_rgbe(tmp_path / "rle.hdr"), E.read_rgbe(tmp_path / "flat.hdr"))


def test_cube_folder_of_faces(tmp_path):
    """A folder of six .npy faces px..nz loads as a cube map equal to the array it was cut from."""
    env = E.procedural("spots", resolution=8, kind="cube")
    for name, face in zip(E.CUBE_FACE_NAMES, env.data):
        np.save(tmp_path / f"{name}.npy", face)
    back = E.load_environment(tmp_path)
    assert back.kind == "cube" and np.array_equal(back.data, env.data)


def test_cube_faces_of_different_sizes_are_refused(tmp_path):
    """Faces of unequal size give a LodprtError that lists each face file and its size."""
    for i, name in enumerate(E.CUBE_FACE_NAMES):
        n = 8 if i != 4 else 4
        np.save(tmp_path / f"{name}.npy", np.ones((n, n, 3)))
    with pytest.raises(LodprtError, match=r"differ in size.*pz.npy 4x4"):
        E.load_environment(tmp_path)


def test_missing_cube_face_is_named(tmp_path):
    """A cube folder without nz names the missing face."""
    for name in E.CUBE_FACE_NAMES[:5]:
        np.save(tmp_path / f"{name}.npy", np.ones((4, 4, 3)))
    with pytest.raises(LodprtError, match="'nz' missing"):
        E.load_environment(tmp_path)


def test_nan_texel_is_refused_with_its_index(tmp_path):
    """A NaN texel gives an error naming the file, the count and the first index; no silent repair."""
    a = np.ones((8, 16, 3))
    a[2, 5, 1] = np.nan
    p = tmp_path / "nan.npy"
    np.save(p, a)
    with pytest.raises(LodprtError, match=r"nan.npy: 1 texel value\(s\) are NaN or infinite \(first at index \(2, 5, 1\)\)"):
        E.load_environment(p)


def test_negative_radiance_is_refused(tmp_path):
    """Negative radiance is an error naming the file, not clamped."""
    a = np.ones((6, 4, 4, 3))
    a[1, 0, 0, 0] = -0.5
    np.save(tmp_path / "neg.npy", a)
    with pytest.raises(LodprtError, match="neg.npy: 1 texel value.*negative"):
        E.load_environment(tmp_path / "neg.npy")


def test_radiance_that_float32_relighting_would_overflow_is_refused(tmp_path):
    """A finite texel above RADIANCE_LIMIT (1e36; float32 ends at 3.4e38) is refused naming the file and the
    texel: a constant map of 1e38 rendered the volume black. At the limit, the map's projection stays finite."""
    from lodprt.model.scene import RADIANCE_LIMIT

    a = np.ones((8, 16, 3))
    a[3, 4, 2] = 1e38
    np.save(tmp_path / "big.npy", a)
    with pytest.raises(LodprtError, match=r"big\.npy: 1 texel value\(s\) are above 1e\+36 \(first at index \(3, 4, 2\)"):
        E.load_environment(tmp_path / "big.npy")
    np.save(tmp_path / "edge.npy", np.full((8, 16, 3), RADIANCE_LIMIT))
    coeffs = E.load_environment(tmp_path / "edge.npy").project(3)
    assert np.isfinite(coeffs.astype(np.float32)).all()


@pytest.mark.parametrize("shape", [(8, 8, 3), (8, 16, 2), (6, 4, 5, 3), (5, 4, 4, 3)])
def test_wrong_shapes_are_refused(tmp_path, shape):
    """Arrays that are neither (H, 2H, 3) lat-long nor (6, N, N, 3) cube maps give an error stating the expected shape."""
    np.save(tmp_path / "bad.npy", np.ones(shape))
    with pytest.raises(LodprtError, match=r"bad.npy: a (lat-long|cube) map must"):
        E.load_environment(tmp_path / "bad.npy")


def test_bad_files_are_refused(tmp_path):
    """Garbage .hdr, truncated .hdr, an 8-bit image, and a missing path each give a LodprtError naming the file."""
    (tmp_path / "junk.hdr").write_bytes(b"not an hdr")
    with pytest.raises(LodprtError, match="junk.hdr: not a Radiance"):
        E.load_environment(tmp_path / "junk.hdr")
    (tmp_path / "short.hdr").write_bytes(b"#?RADIANCE\n\n-Y 4 +X 8\n" + bytes(10))
    with pytest.raises(LodprtError, match="short.hdr: truncated"):
        E.load_environment(tmp_path / "short.hdr")
    (tmp_path / "photo.png").write_bytes(b"\x89PNG")
    with pytest.raises(LodprtError, match="photo.png: unsupported.*sRGB"):
        E.load_environment(tmp_path / "photo.png")
    with pytest.raises(LodprtError, match="nothing.hdr: no such environment"):
        E.load_environment(tmp_path / "nothing.hdr")
    with pytest.raises(LodprtError, match="known names"):
        E.procedural("fog")


def test_procedural_names_with_resolution():
    """'sky:32' is the procedural sky at 32 x 64 texels."""
    env = E.load_environment("sky:32")
    assert env.kind == "latlong" and env.data.shape == (32, 64, 3)


def test_exr_without_backend_or_corrupt_is_named(tmp_path):
    """A .exr imageio cannot decode gives a LodprtError naming the file and how to get an EXR backend."""
    (tmp_path / "broken.exr").write_bytes(b"not an exr")
    with pytest.raises(LodprtError, match=r"broken.exr: (imageio cannot read this .exr|unreadable)"):
        E.load_environment(tmp_path / "broken.exr")


def test_public_api_names():
    """lodprt exposes load_environment, Environment, bake_transfer, open_transfer and relit_radiance lazily."""
    import lodprt

    assert lodprt.load_environment is E.load_environment and lodprt.Environment is E.Environment
    for name in ("bake_transfer", "open_transfer", "relit_radiance"):
        assert callable(getattr(lodprt, name)) and name in lodprt.__all__


def test_order6_on_a_16x16_cube_beats_the_patent_figure():
    """Order-6 signals on a 6x16x16 cube project back far under the patent's 0.2% / 0.5% mean / worst squared error."""
    rng = np.random.default_rng(0)
    d = E.texel_directions("cube", 16)
    errs = []
    for _ in range(10):
        c = rng.normal(size=36)
        env = E.Environment("cube", np.repeat(sh.evaluate(c, d)[:, None], 3, 1).reshape(6, 16, 16, 3), "signal")
        got = env.radiance().T @ E.projection_weights("cube", 16, 6)
        errs.append(np.sum((got[0] - c) ** 2) / np.sum(c**2))
    assert np.mean(errs) < 2e-4 and np.max(errs) < 5e-4


def test_glossy_order_zero_is_refused_not_replaced():
    """--glossy-order 0 was read as 'not given' (the SH order) and baked; it is refused before any work, glossy
    vertices or not, as --sh-order 0 is."""
    from lodprt.errors import LodprtError
    from lodprt.model.scene import demo_scene
    from lodprt.precompute.transfer import bake_transfer

    with pytest.raises(LodprtError, match="glossy order 0: the transfer kernels offer orders 1..8"):
        bake_transfer(demo_scene(floor_resolution=2), None, glossy_order=0)
