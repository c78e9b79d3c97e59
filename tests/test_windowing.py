"""De-ringing windows (lodprt.model.windowing, W-1..W-3): closed forms, identity, a ringing disc light made
non-negative by ``auto``, the Parseval error against a quadrature, and the CLI options."""

import json
import math

import numpy as np
import pytest

from lodprt.errors import LodprtError
from lodprt.model import environment as E
from lodprt.model import irradiance as I
from lodprt.model import sh
from lodprt.model import windowing as W

DISC_AXIS = np.array([0.3, 0.9, 0.3]) / np.linalg.norm([0.3, 0.9, 0.3])


def disc_environment(ambient=0.0, radius_deg=5.0, bright=200.0, resolution=64):
    """A small bright disc (a sun) over a dim, uniform ambient: the classic ringing case."""
    d = E.texel_directions("latlong", resolution)
    rad = np.full((len(d), 3), float(ambient))
    rad[d @ DISC_AXIS > np.cos(np.radians(radius_deg))] += bright
    return E.Environment("latlong", rad.reshape(resolution, 2 * resolution, 3), "disc")


def random_normals(n=200_000, seed=1):
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


@pytest.mark.parametrize("width", [1.0, 2.0, 2.7, 3.0, 5.5])
def test_hann_and_lanczos_factors_are_their_closed_forms(width):
    """W-1: w_l = (1 + cos(pi l/W))/2 and sin(pi l/W)/(pi l/W) for l < W, 0 from l = W on (math, term by term)."""
    order = 6
    hann = W.band_factors("hann", order, width)
    lanczos = W.band_factors("lanczos", order, width)
    for l in range(order):
        x = math.pi * l / width
        assert hann[l] == pytest.approx((1 + math.cos(x)) / 2 if l < width else 0.0, abs=1e-15)
        assert lanczos[l] == pytest.approx((math.sin(x) / x if l else 1.0) if l < width else 0.0, abs=1e-15)


def test_default_width_is_the_order_as_sh_window():
    """Width defaults to the order: the same factors as lodprt.model.sh.window, the classic choice."""
    for kind in ("hann", "lanczos", "none"):
        assert np.allclose(W.band_factors(kind, 4), sh.window(4, kind), atol=1e-15)


def test_none_is_the_identity():
    """--window none leaves every coefficient as it is, and so does auto when the irradiance is >= 0 already."""
    L = E.procedural("sky", resolution=32).project(4)
    for choice in (W.choose_window(L, "none"), W.choose_window(L, "auto")):
        assert choice.kind == "none" and choice.rel_rmse == 0.0
        assert np.array_equal(W.apply_window(L, choice.factors), L)


def test_auto_removes_the_ringing_of_a_small_bright_disc():
    """A 5-degree disc at order 3 rings below zero; ``auto`` makes the irradiance >= 0 everywhere (checked on
    200,000 random normals with the Ramamoorthi-Hanrahan matrix, independent of the window's own test set) and is
    the widest such window: half a percent of a band wider rings again."""
    L = disc_environment().project(3)
    e = I.irradiance(random_normals(), L, method="matrix")
    assert e.min() < -0.03 * e.max()  # -3.7% of the maximum, as a directional light
    ch = W.choose_window(L, "auto")
    assert ch.kind in ("hann", "lanczos") and ch.minimum_before.max() < 0
    ew = I.irradiance(random_normals(), W.apply_window(L, ch.factors), method="matrix")
    assert ew.min() >= -1e-9 * e.max()
    wider = W.apply_window(L, W.band_factors(ch.kind, 3, ch.width * 1.005))
    assert I.irradiance(random_normals(), wider, method="matrix").min() < 0
    assert 0 < ch.rel_rmse < 1


@pytest.mark.parametrize("ambient, order", [(0.02, 5), (0.05, 3)])
def test_auto_with_some_ambient_narrows_less(ambient, order):
    """With a dim ambient the disc needs a milder window: >= 0 everywhere, and a smaller error than the
    narrowest window (band 0 and half of band 1)."""
    L = disc_environment(ambient).project(order)
    ch = W.choose_window(L, "auto")
    assert ch.minimum_before.min() < 0 <= ch.minimum_after.min()
    assert ch.width > 2.5
    dirs = random_normals(50_000)
    e = sh.basis(dirs, order) @ (W.apply_window(L, ch.factors) * W.irradiance_factors(order)).T
    assert e.min() >= -1e-9 * e.max()


def test_window_error_is_the_rms_over_the_sphere():
    """W-3 (Parseval) equals the rel-RMSE of the windowed against the unwindowed irradiance, integrated by an exact
    Gauss-Legendre x uniform quadrature."""
    order = 4
    L = np.random.default_rng(5).normal(size=(3, order * order))
    f = W.band_factors("hann", order, 2.5)
    dirs, wts = sh.quadrature(3 * order)
    a = W.irradiance_factors(order)
    e0 = sh.basis(dirs, order) @ (L * a).T
    e1 = sh.basis(dirs, order) @ (W.apply_window(L, f) * a).T
    rms = np.sqrt((wts[:, None] * (e1 - e0) ** 2).sum() / (wts[:, None] * e0**2).sum())
    assert W.window_error(L, f) == pytest.approx(rms, rel=1e-10)


def test_irradiance_factors_are_a_hat():
    """A_l of W-3 are I-6's pi, 2pi/3, pi/4 for l <= 2, and -pi/24 at l = 4 (0 at l = 3)."""
    a = W.irradiance_factors(5)
    assert np.allclose(a[[0, 1, 4]], I.A_HAT, rtol=1e-14)
    assert abs(a[9]) < 1e-15 and a[16] == pytest.approx(-np.pi / 24, rel=1e-12)


def test_the_choice_does_not_depend_on_rotation():
    """A band window commutes with rotation (P-4): the rotated lighting gets the same window."""
    L = disc_environment(0.02).project(4)
    R = E.rotation_about_y(70.0) @ np.array([[1, 0, 0], [0, np.cos(0.4), -np.sin(0.4)], [0, np.sin(0.4), np.cos(0.4)]])
    a, b = W.choose_window(L, "auto"), W.choose_window(E.rotate_lighting(L, R), "auto")
    assert a.kind == b.kind and a.width == pytest.approx(b.width, abs=1e-3)


def test_bad_windows_are_refused():
    L = np.ones((3, 9))
    with pytest.raises(LodprtError, match="--window 'kaiser'"):
        W.choose_window(L, "kaiser")
    with pytest.raises(LodprtError, match="--window-width applies"):
        W.choose_window(L, "auto", width=2.0)
    with pytest.raises(LodprtError, match="width"):
        W.band_factors("hann", 3, -1.0)
    with pytest.raises(LodprtError, match="L_00 < 0"):
        W.choose_window(-np.eye(1, 9).repeat(3, 0), "auto")


def test_irradiance_cli_window(capsys, tmp_path):
    """``lodprt irradiance --window auto --json`` reports the window and a non-negative range; none warns."""
    from lodprt.cli.main import main

    path = tmp_path / "disc.npy"
    np.save(path, disc_environment(resolution=32).data)
    assert main(["irradiance", str(path), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert min(doc["irradiance_min"]) < 0 and doc["window"]["kind"] == "none"
    assert main(["irradiance", str(path), "--window", "auto", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    w = doc["window"]
    assert w["requested"] == "auto" and w["kind"] in ("hann", "lanczos") and w["width_bands"] > 1
    assert min(doc["irradiance_min"]) >= -1e-9 and min(w["irradiance_min_unwindowed"]) < 0
    assert 0 < w["rel_rmse_vs_unwindowed"] < 1
    assert main(["irradiance", str(path), "--window", "hann", "--window-width", "2"]) == 0
    captured = capsys.readouterr()
    assert "window: hann window of width 2 bands" in captured.out and "negative" not in captured.err
    assert main(["irradiance", str(path), "--window", "none", "--window-width", "2"]) == 2
    assert "--window-width applies" in capsys.readouterr().err
