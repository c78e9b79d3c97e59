"""Light interpolation (T-12): weights, exact reproduction on a sample, continuity, outside the region."""

import logging

import numpy as np
import pytest

from lodprt.errors import LodprtError
from lodprt.runtime.lights import LightInterpolator


def grid(nx=4, ny=2, nz=3):
    """Samples at cell centres of the unit box, as the bake places them."""
    ax = [(np.arange(n) + 0.5) / n for n in (nx, ny, nz)]
    g = np.stack(np.meshgrid(*ax, indexing="ij"), -1).reshape(-1, 3)
    return g, (0.0, 0.0, 0.0, 1.0, 1.0, 1.0)


@pytest.mark.parametrize("weighting", ["exact", "t12"])
def test_weights_sum_to_one_and_are_nonnegative(weighting):
    """For lights anywhere in the box the 8 weights are >= 0 and sum to 1."""
    s, box = grid()
    li = LightInterpolator(s, box, weighting=weighting)
    x = np.random.default_rng(0).random((500, 3))
    idx, w, moved = li.weights(x)
    assert idx.shape == (500, 8) and not moved.any()
    assert (w >= 0).all()
    np.testing.assert_allclose(w.sum(1), 1.0, rtol=0, atol=1e-12)


def test_t12_matches_formula_by_hand():
    """T-12: w_j = (1 - d_j/r)^4 over the 8 nearest, r the largest of them, normalised (computed independently)."""
    s, box = grid()
    li = LightInterpolator(s, box, weighting="t12")
    x = np.array([0.31, 0.47, 0.52])
    d = np.linalg.norm(s - x, axis=1)
    near = np.argsort(d)[:8]
    w = (1 - d[near] / d[near].max()) ** 4
    w /= w.sum()
    idx, got, _ = li.weights(x)
    assert set(idx[0]) == set(near)
    np.testing.assert_allclose(got[0][np.argsort(idx[0])], w[np.argsort(near)], atol=1e-14)


def test_exact_reproduces_a_sample_and_t12_does_not():
    """On a sample the exact weighting puts all weight on it; T-12 as printed leaks to the neighbours."""
    s, box = grid(3, 1, 3)
    centre = s[4]
    idx, w, _ = LightInterpolator(s, box).weights(centre)
    assert w[0][idx[0] == 4][0] == 1.0 and w.sum() == 1.0
    idx, w, _ = LightInterpolator(s, box, weighting="t12").weights(centre)
    own = w[0][idx[0] == 4][0]
    assert 0.9 < own < 1.0


@pytest.mark.parametrize("weighting", ["exact", "t12"])
def test_continuous_across_cell_boundaries(weighting):
    """Moving a light in tiny steps through cell boundaries changes the per-sample weights by tiny amounts."""
    s, box = grid()
    li = LightInterpolator(s, box, weighting=weighting)
    t = np.linspace(0, 1, 4001)
    path = np.c_[0.02 + 0.96 * t, 0.3 + 0.4 * t, 0.9 - 0.8 * t]
    dense = np.zeros((len(t), len(s)))
    idx, w, _ = li.weights(path)
    np.put_along_axis(dense, idx, w, axis=1)
    step = np.abs(np.diff(dense, axis=0)).max()
    assert step < 0.02, step  # a jump at a set change would be of the order of the weights themselves


def test_light_near_a_sample_converges_to_it():
    """The exact weighting tends to the sample smoothly (no jump at the sample itself)."""
    s, box = grid()
    li = LightInterpolator(s, box)
    for eps in (1e-2, 1e-4, 1e-8):
        idx, w, _ = li.weights(s[5] + eps)
        assert w[0][idx[0] == 5][0] >= 1 - 10 * (eps / 0.25) ** 4


def test_outside_is_clamped_with_warning_or_refused(caplog):
    """A light outside the box is clamped to it (warned), or refused with outside='error'; on the boundary is in."""
    s, box = grid()
    li = LightInterpolator(s, box)
    with caplog.at_level(logging.WARNING, logger="lodprt.runtime.lights"):
        idx, w, moved = li.weights([[2.0, 0.5, 0.5], [1.0, 0.0, 0.5]])
    assert moved.tolist() == [True, False]
    assert "outside the sampled region" in caplog.text and "clamped to (1, 0.5, 0.5)" in caplog.text
    clamped = li.clamp([[2.0, 0.5, 0.5]])[0]
    np.testing.assert_array_equal(clamped, [[1.0, 0.5, 0.5]])
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="lodprt.runtime.lights"):
        for k in range(5):  # a light circling outside the box: one interpolator warns once, counts every move
            li.clamp([[2.0 + k, 0.5, 0.5]])
    assert caplog.text == "" and li.clamped == 7
    with pytest.raises(LodprtError, match=r"outside the sampled region \(light box\) \[0, 0, 0\] - \[1, 1, 1\]"):
        LightInterpolator(s, box, outside="error").weights([[2.0, 0.5, 0.5]])


def test_single_sample_and_bad_input():
    """One sample gets weight 1; NaN positions, bad boxes and unknown options are refused clearly."""
    li = LightInterpolator([[0.5, 0.5, 0.5]], (0, 0, 0, 1, 1, 1))
    idx, w, _ = li.weights([0.1, 0.2, 0.3])
    assert idx.tolist() == [[0]] and w.tolist() == [[1.0]]
    with pytest.raises(LodprtError, match="finite"):
        li.weights([np.nan, 0, 0])
    with pytest.raises(LodprtError, match="box"):
        LightInterpolator([[0, 0, 0]], (1, 0, 0, 0, 1, 1))
    with pytest.raises(LodprtError, match="weighting"):
        LightInterpolator([[0, 0, 0]], (0, 0, 0, 1, 1, 1), weighting="linear")
