"""Ramamoorthi-Hanrahan irradiance environment maps: constants, quadratic form, accuracy, GLSL, CLI."""

import json

import numpy as np
import pytest

from lodprt.display.irradiance_render import irradiance_gl, render_irradiance
from lodprt.model import environment as E
from lodprt.model import irradiance as I
from lodprt.model import sh
from lodprt.errors import LodprtError


def unit_normals(n=400, seed=0):
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_constants_match_table1():
    """c1..c5 derived from A_l and the SH normalisations match Ramamoorthi-Hanrahan table 1 to its 6 digits."""
    for k, v in I.RH_TABLE1.items():
        assert abs(I.RH_CONSTANTS[k] - v) < 1.5e-6, k
    assert I.A_HAT == (np.pi, 2 * np.pi / 3, np.pi / 4)


def test_a_hat_is_the_clamped_cosine_convolution():
    """A_l equals the P-6 factor sqrt(4 pi/(2l+1)) h_l of the clamped cosine max(cos, 0)."""
    h = sh.cosine_power_zonal(1.0, 3)
    assert np.allclose(np.sqrt(4 * np.pi / (2 * np.arange(3) + 1)) * h, I.A_HAT, rtol=1e-14)


def test_quadratic_form_equals_sh_evaluation():
    """n^T M n, the seed's 7 registers and sum A_l L_lm y_lm(n) are the same polynomial (1e-13)."""
    L = np.random.default_rng(3).normal(size=(3, 9))
    n = unit_normals()
    ref = I.irradiance(n, L, method="sh")
    assert np.abs(I.irradiance(n, L, method="matrix") - ref).max() < 1e-13
    assert np.abs(I.irradiance(n, L, method="registers") - ref).max() < 1e-13
    m = I.quadratic_matrices(L)
    assert np.allclose(m, np.transpose(m, (0, 2, 1)))


@pytest.mark.parametrize("name", ["sky", "spots"])
def test_nine_coefficients_match_brute_force_integration(name):
    """9-coefficient irradiance is within 1% mean and 5% worst of a brute-force integral over every texel."""
    env = E.procedural(name, resolution=64)
    n = unit_normals(300)
    approx = I.irradiance(n, I.lighting_coefficients(env))
    exact = I.brute_force_irradiance(env, n)
    rel = np.abs(approx - exact) / exact
    assert rel.mean() < 0.01, rel.mean()
    assert rel.max() < 0.05, rel.max()


def test_irradiance_from_a_mip_level_is_close():
    """Irradiance from mip level 2 (32x64) of a 128x256 sky stays within 0.5% of the full map's (the paper's trade)."""
    env = E.procedural("sky", resolution=128)
    n = unit_normals(200)
    full = I.irradiance(n, I.lighting_coefficients(env))
    coarse = I.irradiance(n, I.lighting_coefficients(env.mip(2)))
    assert (np.abs(coarse - full) / full).max() < 5e-3


def test_constant_environment_gives_pi():
    """A unit constant environment gives E = pi for every normal (the cosine's integral)."""
    L = E.procedural("constant", resolution=8, kind="cube").project(3)
    assert np.allclose(I.irradiance(unit_normals(50), L), np.pi, rtol=1e-12)


def test_bad_coefficients_are_refused():
    """Coefficient arrays with fewer than 9 entries or non-finite values raise LodprtError."""
    with pytest.raises(LodprtError, match=">= 9"):
        I.quadratic_matrices(np.ones((3, 4)))
    with pytest.raises(LodprtError, match="finite"):
        I.irradiance([[0, 0, 0], [0, 0, 1]], np.full((3, 9), np.nan))


def _gl(fn, *a, **kw):
    from conftest import gl_unavailable

    if gl_unavailable():  # pragma: no cover - machines without EGL
        pytest.skip(f"no offscreen OpenGL context on this machine: {gl_unavailable()}")
    return fn(*a, **kw)


def test_glsl_shader_matches_cpu():
    """The GLSL 7-register shader (moderngl, EGL) gives the CPU quadratic form to float32 precision."""
    pytest.importorskip("moderngl")
    env = E.procedural("spots", resolution=32)
    L = I.lighting_coefficients(env)
    n = unit_normals(3000)
    gpu = _gl(irradiance_gl, n, L)
    cpu = I.irradiance(n, L)
    assert gpu.shape == (3000, 3)
    assert np.abs(gpu - cpu).max() < 2e-5 * np.abs(cpu).max()


def test_render_irradiance_centre_pixel():
    """A sphere rendered with the shader shows at its centre kd E(n_eye) / pi, sRGB-encoded (within 3/255)."""
    pytest.importorskip("moderngl")
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=4)
    env = E.procedural("sky", resolution=32)
    L = I.lighting_coefficients(env)
    img = _gl(render_irradiance, m.vertices, m.faces, m.vertex_normals, L, albedo=(0.5, 0.5, 0.5), eye=(0, 0, 4),
              target=(0, 0, 0), size=(64, 64), exposure=0.5)
    x = np.clip(0.5 * 0.5 * I.irradiance([0, 0, 1], L) / np.pi, 0, 1)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055) * 255
    assert np.abs(img[32, 32].astype(float) - srgb).max() <= 3
    assert (img[0, 0] == 0).all()  # background


def test_irradiance_cli_json(capsys):
    """`lodprt irradiance sky:16 --json` prints the 9 RGB coefficients, A_l, c1..c5, the matrices and the registers."""
    from lodprt.cli.main import main

    assert main(["irradiance", "sky:16", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert len(doc["coefficients"]["r"]) == 9 and set(doc["constants"]) == {"c1", "c2", "c3", "c4", "c5"}
    assert np.array(doc["matrices"]["g"]).shape == (4, 4) and list(doc["registers"]) == list(I.REGISTERS)
    L = np.array([doc["coefficients"][c] for c in "rgb"])
    assert np.allclose(L, E.load_environment("sky:16").project(3))


def test_irradiance_cli_text_and_error(capsys, tmp_path):
    """The text form prints the table; a bad file gives exit code 2 and one line naming it."""
    from lodprt.cli.main import main

    assert main(["irradiance", "spots:8"]) == 0
    out = capsys.readouterr().out
    assert "c1 = 0.429043" in out and "cAr" in out
    np.save(tmp_path / "bad.npy", np.ones((4, 4, 3)))
    assert main(["irradiance", str(tmp_path / "bad.npy")]) == 2
    assert "bad.npy: a lat-long map must" in capsys.readouterr().err


def test_ringing_of_a_directional_light_is_reported(capsys, tmp_path):
    """A directional light's 9-coefficient irradiance dips to -3.7% of its maximum; the range and the CLI report it."""
    from lodprt.cli.main import main

    d = E.texel_directions("latlong", 64)
    spot = np.exp((d @ [0.0, 1.0, 0.0] - 1) / 0.0005)
    np.save(tmp_path / "spot.npy", np.repeat(spot[:, None], 3, 1).reshape(64, 128, 3))
    L = I.lighting_coefficients(E.load_environment(tmp_path / "spot.npy"))
    lo, hi = I.irradiance_range(L)
    dip = (0.25 - 8 / 30 + 5 / 32 * (3 * 64 / 225 - 1)) / 1.0625  # f(c) = 1/4 + c/2 + 5/32 (3c^2 - 1) at -8/15
    assert np.allclose(lo / hi, dip, rtol=0.05)
    assert main(["irradiance", str(tmp_path / "spot.npy")]) == 0
    assert "negative irradiance" in capsys.readouterr().err


def test_bad_cube_maps_hdr_headers_and_mip_levels_are_named(tmp_path):
    """A cube map of N = 0 (a ZeroDivisionError), a cube face of 2 channels (a numpy stack error), an .hdr whose
    resolution line claims more pixels than the file holds (it allocated terabytes) and a negative mip level (read
    as level 0) are refused naming the file or the level."""
    np.save(tmp_path / "cube0.npy", np.zeros((6, 0, 0, 3)))
    with pytest.raises(E.EnvironmentMapError, match=r"cube0\.npy: a cube map must have shape \(6, N, N, 3\) with N"):
        E.load_environment(tmp_path / "cube0.npy")
    faces = tmp_path / "faces"
    faces.mkdir()
    for name in E.CUBE_FACE_NAMES:
        np.save(faces / f"{name}.npy", np.ones((4, 4, 2 if name == E.CUBE_FACE_NAMES[0] else 3)))
    with pytest.raises(E.EnvironmentMapError, match=r"\.npy: a cube face must be square, \(N, N, 1\|3\|4\)"):
        E.load_environment(faces)
    E.write_rgbe(tmp_path / "ok.hdr", np.full((4, 8, 3), 2.0))
    raw = (tmp_path / "ok.hdr").read_bytes()
    (tmp_path / "big.hdr").write_bytes(raw.replace(b"-Y 4 +X 8", b"-Y 4000000 +X 8000000"))
    with pytest.raises(E.EnvironmentMapError, match=r"big\.hdr: truncated or wrong resolution line: 4000000 x 8000000"):
        E.read_rgbe(tmp_path / "big.hdr")
    np.testing.assert_allclose(E.read_rgbe(tmp_path / "ok.hdr"), 2.0, rtol=1e-2)  # the good one still reads
    env = E.procedural("sky", resolution=8)
    with pytest.raises(E.EnvironmentMapError, match=r"mip level -2: a whole number >= 0"):
        env.mip(-2)
    assert env.mip(0) is env
