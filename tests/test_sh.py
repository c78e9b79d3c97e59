"""Spherical harmonics: basis against scipy, float32 kernels against float64, quadrature, rotation, lobes, convolution."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.special import sph_harm_y

from lodprt.model import sh
from lodprt.kernels import sh as ksh

# Bands 0..100.  scipy's sph_harm_y (recurrence-based since scipy 1.15) has not broken down there: the two
# independent evaluations agree to ~3e-13 (values up to 4), and to ~1e-12 even at l = 200.
SCIPY_ORDER = 101


def directions(n=300, seed=0):
    """Random unit directions plus the poles, points next to the poles, the equator and the axes."""
    d = np.random.default_rng(seed).normal(size=(n, 3))
    special = [
        [0, 0, 1], [0, 0, -1], [1e-9, 0, 1], [0, -1e-7, -1], [1e-4, 2e-4, 1],  # poles and next to them
        [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0.6, 0.8, 0.0], [-0.28, 0.96, 0.0],  # equator
    ]
    d = np.vstack([d, special])
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def scipy_real_basis(d, order):
    """This module's real convention from scipy's complex Y_l^m, which carries the Condon-Shortley phase (-1)^m.

    Y_l^m = (-1)^m K_l^m P_l^m e^{i m phi} (P without the phase), so for m > 0 y_l^m = sqrt(2) (-1)^m Re Y_l^m and
    for m < 0 y_l^m = sqrt(2) K sin(|m| phi) P_l^|m| = sqrt(2) (-1)^m Im Y_l^|m|  (sin(-m phi) = sin(|m| phi);
    e.g. y_1^-1 = sqrt(3/4pi) sin(theta) sin(phi) = sqrt(3/4pi) y).
    """
    theta = np.arctan2(np.hypot(d[:, 0], d[:, 1]), d[:, 2])  # accurate at the poles, unlike arccos(z)
    phi = np.arctan2(d[:, 1], d[:, 0])
    ls = np.repeat(np.arange(order), 2 * np.arange(order) + 1)
    ms = np.arange(order * order) - ls * (ls + 1)
    c = sph_harm_y(ls[:, None], np.abs(ms)[:, None], theta[None], phi[None])  # (order^2, N)
    sign = np.where(ms % 2 == 0, 1.0, -1.0)[:, None]
    out = np.where(ms[:, None] > 0, np.sqrt(2) * sign * c.real, np.sqrt(2) * sign * c.imag)
    out = np.where(ms[:, None] == 0, c.real, out)
    return out.T


def hemisphere_quadrature(axis, n_t, n_phi):
    """Gauss-Legendre in t = axis.s on [0, 1] x uniform phi about ``axis``: exact for t^k times any SH of band < n_phi.

    The integrand max(axis.s, 0)^n f(s) vanishes on the other hemisphere, so this integrates it without the kink.
    """
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    helper = np.array([1.0, 0, 0]) if abs(a[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(helper, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    x, w = np.polynomial.legendre.leggauss(n_t)
    t, wt = 0.5 * (x + 1), 0.5 * w
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    tt, pp = np.meshgrid(t, phi, indexing="ij")
    s = np.sqrt(1 - tt**2)
    dirs = (s * np.cos(pp))[..., None] * e1 + (s * np.sin(pp))[..., None] * e2 + tt[..., None] * a
    return dirs.reshape(-1, 3), np.repeat(wt, n_phi) * 2 * np.pi / n_phi


# -- basis ------------------------------------------------------------------------------------------------------


def test_basis_matches_scipy_to_high_order():
    """float64 basis equals scipy's sph_harm_y in this real convention to 1e-12 absolute for every l <= 100."""
    d = directions(150)
    ours, ref = sh.basis(d, SCIPY_ORDER), scipy_real_basis(d, SCIPY_ORDER)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-12)
    assert np.abs(ref).max() > 3  # the l = 100 zonal band reaches sqrt(201/4pi) at the poles: not a trivial check


def test_low_bands_explicit():
    """y_0 = 1/sqrt(4 pi) and (y_1^-1, y_1^0, y_1^1) = sqrt(3/4pi) (y, z, x): no Condon-Shortley phase."""
    d = directions(50)
    y = sh.basis(d, 2)
    np.testing.assert_allclose(y[:, 0], 1 / np.sqrt(4 * np.pi), rtol=0, atol=1e-15)
    np.testing.assert_allclose(y[:, 1:4], np.sqrt(3 / (4 * np.pi)) * d[:, [1, 2, 0]], rtol=0, atol=1e-15)
    assert sh.sh_index(1, -1) == 1 and sh.sh_index(1, 1) == 3 and sh.sh_index(3, 0) == 12
    assert sh.num_coefficients(5) == 25


def test_basis_shapes_and_normalisation():
    """basis keeps leading dims, normalises its input (scale-free) and reads a zero vector as +z."""
    d = directions(12)[:12].reshape(2, 2, 3, 3)
    assert sh.basis(d, 4).shape == (2, 2, 3, 16)
    assert sh.basis([0, 0, 1], 3).shape == (9,)
    np.testing.assert_allclose(sh.basis(d * 7.5, 6), sh.basis(d, 6), rtol=0, atol=1e-14)
    np.testing.assert_allclose(sh.basis(d * 1e-200, 6), sh.basis(d, 6), rtol=0, atol=1e-14)
    np.testing.assert_array_equal(sh.basis([0, 0, 0], 5), sh.basis([0, 0, 1], 5))


# -- float32 Warp kernel ----------------------------------------------------------------------------------------


@pytest.mark.warp_debug
@pytest.mark.parametrize("order", sorted({1, 2, 4, 8, 16, ksh.MAX_KERNEL_ORDER}))
def test_float32_kernel_matches_float64(device, order):
    """The Warp float32 basis equals the float64 reference to 1e-5 absolute; a zero vector gives +z, never NaN."""
    extra = [[0, 0, 0], [1e-30, 0, 0], [0, 1e-20, -1e-20], [3e5, -4e5, 1e5]]  # zero, tiny and long vectors
    d = np.vstack([directions(400), extra])
    y = ksh.eval_basis(d, order, device)
    assert y.shape == (len(d), order * order) and y.dtype == np.float32
    assert np.isfinite(y).all()
    np.testing.assert_allclose(y, sh.basis(d, order), rtol=0, atol=1e-5)
    np.testing.assert_allclose(y[-4], sh.basis([0, 0, 1], order), rtol=0, atol=1e-5)


@pytest.mark.warp_debug
@pytest.mark.parametrize("order", [1, 2, 3, 4, 5, 8])
def test_closed_form_kernel_basis_matches_float64(device, order):
    """sh_basis_fast (closed-form polynomials for l <= 3, the recurrence above) equals the float64 reference."""
    extra = [[0, 0, 0], [1e-30, 0, 0], [0, 1e-20, -1e-20], [3e5, -4e5, 1e5], [0, 0, -1], [1, 0, 0]]
    d = np.vstack([directions(400), extra])
    y = ksh.eval_basis(d, order, device, fast=True)
    assert np.isfinite(y).all()
    np.testing.assert_allclose(y, sh.basis(d, order), rtol=0, atol=2e-6)


def test_kernel_rejects_bad_order_and_shape():
    """eval_basis refuses orders outside 1..MAX_KERNEL_ORDER and directions that are not (N, 3)."""
    for order in (0, ksh.MAX_KERNEL_ORDER + 1):
        with pytest.raises(ValueError, match="orders 1"):
            ksh.eval_basis(np.zeros((1, 3)), order, "cpu")
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        ksh.eval_basis(np.zeros((4, 2)), 2, "cpu")


# -- quadrature, projection, reconstruction (T-6, T-7, T-8) -----------------------------------------------------


def test_orthonormal_by_exact_quadrature():
    """The Gram matrix of the basis under quadrature_for_order is the identity to 1e-12 for orders 1..20."""
    for order in range(1, 21):
        dirs, w = sh.quadrature_for_order(order)
        y = sh.basis(dirs, order)
        assert w.sum() == pytest.approx(4 * np.pi, rel=1e-14)
        np.testing.assert_allclose((y * w[:, None]).T @ y, np.eye(order * order), rtol=0, atol=1e-12, err_msg=f"order {order}")


def test_project_evaluate_round_trip():
    """project(evaluate(c)) == c for band-limited functions, with extra value dims as in the docstrings."""
    c = np.random.default_rng(1).normal(size=(3, 49))
    dirs, w = sh.quadrature_for_order(7)
    values = sh.evaluate(c[:, None, :], dirs)  # (3, 1, 49) with (Q, 3) -> (3, Q)
    assert values.shape == (3, len(dirs))
    np.testing.assert_allclose(sh.project(values.T, dirs, w, 7), c, rtol=0, atol=1e-12)
    np.testing.assert_allclose(sh.project(values[0], dirs, w, 7), c[0], rtol=0, atol=1e-12)
    assert sh.evaluate(c, dirs[:3]).shape == (3,)  # one direction per function
    # product integral (T-8): the quadrature of f g equals the dot product of the coefficients
    assert (values[0] * values[1] * w).sum() == pytest.approx(c[0] @ c[1], rel=1e-12)


# -- rotation (P-4) ---------------------------------------------------------------------------------------------


def test_rotation_matches_rotated_directions():
    """rotate(c, R)(s) == c(R^T s) for random R, orders 1..12; band energy kept; identity and composition hold."""
    rng = np.random.default_rng(3)
    d = directions(60, seed=3)
    for order in range(1, 13):
        c = rng.normal(size=(2, order * order))  # a batch of two
        r1, r2 = Rotation.random(2, random_state=order).as_matrix()
        cr = sh.rotate(c, r1)
        np.testing.assert_allclose(sh.evaluate(cr[:, None], d), sh.evaluate(c[:, None], d @ r1), rtol=0, atol=1e-11)
        for l in range(order):
            sl = slice(l * l, (l + 1) ** 2)
            np.testing.assert_allclose((cr[:, sl] ** 2).sum(1), (c[:, sl] ** 2).sum(1), rtol=1e-11, atol=1e-14)
        np.testing.assert_allclose(sh.rotate(sh.rotate(c, r2), r1), sh.rotate(c, r1 @ r2), rtol=0, atol=1e-11)
        np.testing.assert_allclose(sh.rotate(c, np.eye(3)), c, rtol=0, atol=1e-14)


def test_rotation_matches_least_squares_fit():
    """Each band matrix equals a least-squares fit of the band's rotated samples (independent construction)."""
    r = Rotation.from_euler("zyz", [0.3, 1.1, -0.7]).as_matrix()
    d = directions(400, seed=5)
    y, y_rot = sh.basis(d, 10), sh.basis(d @ r, 10)  # y(s), y(R^T s)
    for l, dl in enumerate(sh.rotation_matrices(r, 10)):
        sl = slice(l * l, (l + 1) ** 2)
        fit = np.linalg.lstsq(y[:, sl], y_rot[:, sl], rcond=None)[0]  # y_j(R^T s) = sum_i fit_ij y_i(s)
        np.testing.assert_allclose(dl, fit, rtol=0, atol=1e-10)
        np.testing.assert_allclose(dl @ dl.T, np.eye(2 * l + 1), rtol=0, atol=1e-12)


def test_rotation_moves_a_lobe_to_the_rotated_axis():
    """Rotating the lobe about a gives the lobe about R a; a float32 rotation matrix is accepted."""
    a = np.array([0.2, -0.5, 0.8])
    r = Rotation.from_rotvec([0.4, 1.3, -0.2]).as_matrix()
    lobe = sh.cosine_power_lobe(a, 5.0, 9)
    np.testing.assert_allclose(sh.rotate(lobe, r), sh.cosine_power_lobe(r @ a, 5.0, 9), rtol=0, atol=1e-13)
    np.testing.assert_allclose(sh.rotate(lobe, r.astype(np.float32)), sh.rotate(lobe, r), rtol=0, atol=1e-6)


# -- clamped cosine-power lobes ---------------------------------------------------------------------------------


@pytest.mark.parametrize("shininess", [1, 2, 7.5, 50])
def test_lobe_closed_form_equals_quadrature(shininess):
    """Closed-form projection of max(a.s, 0)^n equals its quadrature projection (random axes, orders 1..10)."""
    for axis in directions(4, seed=9)[:4]:
        dirs, w = hemisphere_quadrature(axis, 80, 24)  # exact (or, for n = 7.5, to ~1e-16) up to order 10
        values = np.clip(dirs @ axis, 0, None) ** shininess
        for order in (1, 3, 6, 10):
            ref = sh.project(values, dirs, w, order)
            np.testing.assert_allclose(sh.cosine_power_lobe(axis, shininess, order), ref, rtol=0, atol=1e-13)


def test_lobe_on_a_generic_grid():
    """The closed form also matches a plain quadrature(n_theta) grid not aligned with the axis (smooth lobe n = 50)."""
    axes = directions(3, seed=11)[:3]
    dirs, w = sh.quadrature(150)
    ref = sh.project(np.clip(dirs @ axes.T, 0, None) ** 50, dirs, w, 8)  # (3, 64)
    np.testing.assert_allclose(sh.cosine_power_lobe(axes, 50, 8), ref, rtol=0, atol=1e-9)


@pytest.mark.parametrize("shininess", [1, 10, 100, 1000, 1e4])
def test_lobe_extreme_shininess_finite(shininess):
    """Shininess up to 1e4: coefficients finite, z_0 > 0 and sum z_l^2 never above the lobe's 2 pi/(2n+1)."""
    z = sh.cosine_power_zonal(shininess, 200)
    assert np.isfinite(z).all() and z[0] > 0
    assert np.sum(z * z) <= 2 * np.pi / (2 * shininess + 1) * (1 + 1e-12)
    assert np.isfinite(sh.cosine_power_lobe(directions(5), shininess, 32)).all()


def test_lobe_zeros_of_integer_exponent():
    """For integer n the bands l = n+2, n+4, ... vanish exactly (max(cos, 0) has no band 3, 5, 7 content)."""
    z = sh.cosine_power_zonal(1, 9)
    assert z[3] == 0 and z[5] == 0 and z[7] == 0 and z[2] != 0 and z[4] != 0
    assert (sh.cosine_power_zonal(4, 20)[6::2] == 0).all()


def test_lobe_energy_captured_table():
    """Captured lobe energy per order lies in (0, 1], never falls with order, is ~1 for n = 1 at order 8 (-s prints)."""
    orders = (1, 2, 3, 4, 6, 8, 12, 16, 24, 32)
    print("\ncaptured energy of max(cos, 0)^n (fraction of 2 pi/(2n+1)) per order")
    print("   order:" + " ".join(f"{k:>6}" for k in orders))
    table = {}
    for n in (1, 2, 10, 100, 1000):
        e = np.array([sh.lobe_energy_captured(n, k) for k in orders])
        table[n] = e
        print(f"n = {n:>4}: " + " ".join(f"{a:6.4f}" for a in e))
        assert ((e > 0) & (e <= 1)).all()
        assert (np.diff(e) >= 0).all()
    assert table[1][orders.index(8)] > 0.999
    assert table[1000][orders.index(12)] < 0.2  # a mirror-like lobe needs far more bands
    assert sh.lobe_energy_captured(0, 1) == pytest.approx(0.5)  # the hemisphere indicator: half in band 0


# -- zonal convolution (P-6) ------------------------------------------------------------------------------------


def test_convolution_with_clamped_cosine_gives_irradiance_constants():
    """P-6 with h = max(cos, 0): sqrt(4 pi/(2l+1)) h_l = A_l = pi, 2 pi/3, pi/4; a constant 1 has irradiance pi."""
    h = sh.cosine_power_zonal(1, 3)
    a = np.sqrt(4 * np.pi / (2 * np.arange(3) + 1)) * h
    np.testing.assert_allclose(a, [np.pi, 2 * np.pi / 3, np.pi / 4], rtol=1e-14)
    const = np.zeros(9)
    const[0] = np.sqrt(4 * np.pi)  # f = 1
    e = sh.convolve_zonal(const, h)
    np.testing.assert_allclose(sh.evaluate(e, directions(5)), np.pi, rtol=1e-14)


def test_convolution_with_delta_kernel_is_identity():
    """The delta at +z has h_l = y_l^0(+z) = sqrt((2l+1)/4pi), and convolving with it changes nothing."""
    h = sh.basis([0, 0, 1], 6)[[l * (l + 1) for l in range(6)]]
    np.testing.assert_allclose(h, np.sqrt((2 * np.arange(6) + 1) / (4 * np.pi)), rtol=1e-14)
    c = np.random.default_rng(7).normal(size=(4, 36))
    np.testing.assert_allclose(sh.convolve_zonal(c, h), c, rtol=1e-14)


@pytest.mark.parametrize("shininess", [1, 3.5])
def test_convolution_matches_direct_quadrature(shininess):
    """(h * f)(n) from P-6 equals integral max(n.u, 0)^k f(u) du by exact quadrature about each normal n."""
    order = 6
    c = np.random.default_rng(4).normal(size=order * order)
    conv = sh.convolve_zonal(c, sh.cosine_power_zonal(shininess, order))
    for normal in directions(5, seed=2)[:5]:
        dirs, w = hemisphere_quadrature(normal, 40, 16)
        direct = (np.clip(dirs @ normal, 0, None) ** shininess * sh.evaluate(c, dirs) * w).sum()
        assert sh.evaluate(conv, normal) == pytest.approx(direct, abs=1e-12)


def test_windows():
    """Windows follow their documented formulae: start at 1 and fall with the band; 'none' is all ones."""
    l = np.arange(6)
    np.testing.assert_allclose(sh.window(6, "hann"), 0.5 * (1 + np.cos(np.pi * l / 6)), rtol=1e-15)
    np.testing.assert_allclose(sh.window(6, "lanczos")[1:], np.sin(np.pi * l[1:] / 6) / (np.pi * l[1:] / 6), rtol=1e-15)
    for kind in ("hann", "lanczos"):
        w = sh.window(6, kind)
        assert w[0] == 1 and (np.diff(w) < 0).all()
    assert (sh.window(4, "none") == 1).all()


# -- bad input --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "call",
    [
        lambda: sh.basis(np.zeros((3, 2)), 3),
        lambda: sh.basis(np.zeros((3, 3)), 0),
        lambda: sh.basis(np.zeros((3, 3)), 2.5),
        lambda: sh.basis([np.nan, 0, 1], 3),
        lambda: sh.quadrature(0),
        lambda: sh.project(np.ones(5), np.zeros((4, 3)), np.ones(4), 2),
        lambda: sh.evaluate(np.zeros(5), [0, 0, 1]),
        lambda: sh.cosine_power_zonal(-1, 3),
        lambda: sh.cosine_power_zonal(np.inf, 3),
        lambda: sh.rotate(np.zeros(5), np.eye(3)),
        lambda: sh.rotation_matrices(np.diag([1, 1, -1.0]), 3),
        lambda: sh.rotation_matrices(np.eye(3) * 1.1, 3),
        lambda: sh.rotation_matrices(np.eye(2), 3),
        lambda: sh.convolve_zonal(np.zeros(9), np.ones(2)),
        lambda: sh.window(3, "gauss"),
        lambda: sh.sh_index(1, 2),
    ],
)
def test_bad_input_raises(call):
    """Wrong shapes, orders, non-finite directions, exponents, improper rotations and unknown windows raise ValueError."""
    with pytest.raises(ValueError):
        call()
