"""Spherical harmonics: basis against scipy, float32 kernels against float64, quadrature, rotation, lobes."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.special import sph_harm_y

from lodprt import sh
from lodprt.kernels import sh as ksh

HIGH_ORDER = 101  # l up to 100: scipy's sph_harm_y stays accurate there (the old sph_harm gave NaN from l = 86)


def directions(n=300, seed=0):
    """Random unit directions plus the poles, the equator and the axes."""
    d = np.random.default_rng(seed).normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    special = [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0.6, 0.8, 0.0]]
    return np.vstack([d, special])


def scipy_real_basis(d, order):
    """The convention of lodprt.sh from scipy's complex Y (which carries the Condon-Shortley phase (-1)^m)."""
    theta = np.arccos(np.clip(d[:, 2], -1, 1))
    phi = np.arctan2(d[:, 1], d[:, 0])
    out = np.empty((len(d), order * order))
    for l in range(order):
        for m in range(-l, l + 1):
            c = sph_harm_y(l, abs(m), theta, phi)
            if m > 0:
                v = np.sqrt(2) * (-1) ** m * c.real
            elif m < 0:
                v = np.sqrt(2) * (-1) ** m * c.imag
            else:
                v = c.real
            out[:, l * (l + 1) + m] = v
    return out


def test_basis_matches_scipy_to_high_order():
    """float64 basis equals scipy's sph_harm_y converted to this convention to 1e-12, l = 0..100, poles included."""
    d = directions(150)
    np.testing.assert_allclose(sh.basis(d, HIGH_ORDER), scipy_real_basis(d, HIGH_ORDER), rtol=0, atol=1e-12)


def test_low_bands_explicit():
    """y_0 = 1/sqrt(4 pi) and y_1 = sqrt(3/4pi) (y, z, x): no Condon-Shortley phase, band-1 order (y, z, x)."""
    d = directions(50)
    y = sh.basis(d, 2)
    np.testing.assert_allclose(y[:, 0], 1 / np.sqrt(4 * np.pi), atol=1e-15)
    np.testing.assert_allclose(y[:, 1:4], np.sqrt(3 / (4 * np.pi)) * d[:, [1, 2, 0]], atol=1e-15)


@pytest.mark.parametrize("order", [1, 4, 8, ksh.MAX_KERNEL_ORDER])
def test_float32_kernel_matches_float64(device, order):
    """The Warp float32 basis equals the float64 reference to 1e-5 up to the highest kernel order; zero -> +z."""
    d = np.vstack([directions(500), [[0, 0, 0], [1e-20, 0, 1], [0, 1e-20, -1]]])
    y = ksh.eval_basis(d, order, device)
    assert np.isfinite(y).all()
    np.testing.assert_allclose(y, sh.basis(d, order), rtol=0, atol=1e-5)
    np.testing.assert_allclose(y[-3], sh.basis([0, 0, 1], order), atol=1e-6)


def test_kernel_order_bound():
    """Asking the float32 kernel for more bands than offered is a clear ValueError."""
    with pytest.raises(ValueError, match="orders 1"):
        ksh.eval_basis(np.zeros((1, 3)), ksh.MAX_KERNEL_ORDER + 1, "cpu")


@pytest.mark.parametrize("order", [1, 3, 8, 20])
def test_orthonormal_by_exact_quadrature(order):
    """The Gram matrix of the basis under an exact quadrature is the identity to 1e-12."""
    dirs, w = sh.quadrature_for_order(order)
    y = sh.basis(dirs, order)
    assert w.sum() == pytest.approx(4 * np.pi, rel=1e-14)
    np.testing.assert_allclose((y * w[:, None]).T @ y, np.eye(order * order), atol=1e-12)


def test_project_evaluate_round_trip():
    """project(evaluate(c)) == c for a band-limited function."""
    c = np.random.default_rng(1).normal(size=(3, 49))
    dirs, w = sh.quadrature_for_order(7)
    values = sh.evaluate(c[:, None, :], dirs[None])  # (3, Q)
    np.testing.assert_allclose(sh.project(values.T, dirs, w, 7), c, atol=1e-12)


@pytest.mark.parametrize("order", [2, 5, 12])
def test_rotation_matches_rotated_directions(order):
    """rotate(c, R) evaluated at s equals c at R^T s; per-band energy is preserved; composition and identity hold."""
    rng = np.random.default_rng(order)
    c = rng.normal(size=order * order)
    r1, r2 = Rotation.random(2, random_state=order).as_matrix()
    d = directions(80, seed=order)
    cr = sh.rotate(c, r1)
    np.testing.assert_allclose(sh.evaluate(cr, d), sh.evaluate(c, d @ r1), atol=1e-11)
    for l in range(order):
        sl = slice(l * l, (l + 1) ** 2)
        assert np.dot(cr[sl], cr[sl]) == pytest.approx(np.dot(c[sl], c[sl]), rel=1e-11)
    np.testing.assert_allclose(sh.rotate(sh.rotate(c, r2), r1), sh.rotate(c, r1 @ r2), atol=1e-11)
    np.testing.assert_allclose(sh.rotate(c, np.eye(3)), c, atol=1e-14)


def test_rotation_matches_least_squares_fit():
    """Each band matrix equals a least-squares fit of the band on rotated samples (an independent construction)."""
    r = Rotation.from_euler("zyz", [0.3, 1.1, -0.7]).as_matrix()
    d = directions(400, seed=5)
    for l, dl in enumerate(sh.rotation_matrices(r, 9)):
        sl = slice(l * l, (l + 1) ** 2)
        y = sh.basis(d, 9)[:, sl]
        y_rot = sh.basis(d @ r, 9)[:, sl]  # y_l(R^T s)
        fit = np.linalg.lstsq(y, y_rot, rcond=None)[0].T  # g_i(s) = sum_j D_ij y_j(s)
        np.testing.assert_allclose(dl.T, fit, atol=1e-10)


@pytest.mark.parametrize("shininess", [1, 2, 7.5, 50])
def test_lobe_closed_form_equals_quadrature(shininess):
    """Closed-form projection of max(a.s, 0)^n equals a fine quadrature projection (random axes, several orders)."""
    axes = directions(5, seed=9)[:5]
    dirs, w = sh.quadrature(400)
    for order in (1, 4, 8):
        ref = sh.project(np.clip(dirs @ axes.T, 0, None) ** shininess, dirs, w, order)
        np.testing.assert_allclose(sh.cosine_power_lobe(axes, shininess, order), ref, atol=2e-6)


@pytest.mark.parametrize("shininess", [1, 10, 100, 1000, 1e4])
def test_lobe_extreme_shininess_finite(shininess):
    """Shininess up to 1e4: zonal coefficients finite, positive at l = 0, and bounded by the lobe's L2 norm."""
    z = sh.cosine_power_zonal(shininess, 40)
    assert np.isfinite(z).all() and z[0] > 0
    assert np.sum(z * z) <= 2 * np.pi / (2 * shininess + 1) * (1 + 1e-12)


def test_lobe_zeros_of_integer_exponent():
    """For integer n the projection has exact zeros: max(cos, 0)^1 has no band 3, 5, 7 ... content."""
    z = sh.cosine_power_zonal(1, 9)
    assert z[3] == 0 and z[5] == 0 and z[7] == 0 and z[2] != 0


def test_lobe_energy_captured_table():
    """Captured lobe energy per order lies in (0, 1], grows with order, is ~1 for n = 1 at order 8; printed with -s."""
    rows = []
    for n in (1, 2, 10, 100, 1000):
        e = [sh.lobe_energy_captured(n, k) for k in (1, 2, 4, 6, 8, 12)]
        rows.append((n, e))
        assert all(0 < a <= 1 for a in e)
        assert all(b >= a for a, b in zip(e, e[1:]))
    assert rows[0][1][4] > 0.999
    assert rows[-1][1][-1] < 0.2  # a mirror-like lobe is far beyond 12 bands
    print("\ncaptured energy of max(cos,0)^n, orders 1 2 4 6 8 12")
    for n, e in rows:
        print(f"n={n:>5}: " + " ".join(f"{a:.4f}" for a in e))


def test_convolution_with_clamped_cosine_gives_irradiance_constants():
    """P-6 with h = max(cos, 0): sqrt(4 pi/(2l+1)) h_l = A_l = pi, 2 pi/3, pi/4 (Ramamoorthi-Hanrahan)."""
    h = sh.cosine_power_zonal(1, 3)
    a = np.sqrt(4 * np.pi / (2 * np.arange(3) + 1)) * h
    np.testing.assert_allclose(a, [np.pi, 2 * np.pi / 3, np.pi / 4], rtol=1e-14)
    # irradiance of a constant radiance 1 is pi
    const = np.zeros(9)
    const[0] = np.sqrt(4 * np.pi)
    e = sh.convolve_zonal(const, h)
    assert sh.evaluate(e, [0.2, 0.3, 0.9]) == pytest.approx(np.pi, rel=1e-14)


def test_convolution_matches_direct_quadrature():
    """Convolving f with the clamped cosine equals integrating f(s) max(n.s, 0) directly at several normals."""
    order = 5
    c = np.random.default_rng(4).normal(size=order * order)
    dirs, w = sh.quadrature(60)
    f = sh.evaluate(c, dirs)
    normals = directions(6, seed=2)[:6]
    direct = (np.clip(normals @ dirs.T, 0, None) * f * w).sum(1)
    conv = sh.evaluate(sh.convolve_zonal(c, sh.cosine_power_zonal(1, order)), normals)
    np.testing.assert_allclose(conv, direct, atol=2e-4)


def test_windows():
    """Windows start at 1 and fall with the band; 'none' is all ones."""
    for kind in ("hann", "lanczos"):
        w = sh.window(6, kind)
        assert w[0] == 1 and (np.diff(w) < 0).all()
    assert (sh.window(4, "none") == 1).all()


@pytest.mark.parametrize(
    "call",
    [
        lambda: sh.basis(np.zeros((3, 2)), 3),
        lambda: sh.basis(np.zeros((3, 3)), 0),
        lambda: sh.cosine_power_zonal(-1, 3),
        lambda: sh.rotate(np.zeros(5), np.eye(3)),
        lambda: sh.rotation_matrices(np.diag([1, 1, -1.0]), 3),
        lambda: sh.window(3, "gauss"),
        lambda: sh.sh_index(1, 2),
    ],
)
def test_bad_input_raises(call):
    """Wrong shapes, orders, exponents, improper rotations and unknown windows raise ValueError."""
    with pytest.raises(ValueError):
        call()
