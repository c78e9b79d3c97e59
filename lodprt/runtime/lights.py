"""Light interpolation at run time (SPEC 5; thesis 3.4.1, eq. 12): a point light anywhere in the sampled region takes
its coefficients from the light samples nearest to it.

For a light at ``x``, the ``k = 8`` nearest samples (all of them when there are fewer) at distances ``d_j``, with
``r`` the largest of those distances, get

    T-12        w_j = (1 - d_j / r)^4                                  (Silverman's kernel; ``weighting="t12"``)
    exact       w_j = ((1 - d_j / r) / (d_j / r))^4 = T-12 / (d_j/r)^4 (``weighting="exact"``, the default)

normalised to sum 1. Both are continuous as the light moves: the farthest of the k samples has weight 0, so the
sample that enters or leaves the k nearest does so with weight 0. T-12 as printed does not reproduce a sample when
the light sits on it (at the centre sample of a 3 x 3 grid it keeps only 97% of its own coefficients and takes 0.7%
from each edge neighbour); the exact form divides by ``(d_j/r)^4`` (Franke and Little's modification of Shepard's
weights), so that ``w -> 1`` smoothly as the light approaches a sample and the sample is reproduced exactly on it.
When every distance equals ``r`` (all samples equidistant) the weights are equal.

Outside the region (the light box of the bake), ``outside="clamp"`` (default) moves the light to the nearest point
of the box and logs a warning naming where it was moved, once per ``LightInterpolator`` (a light turning in and out
of the box every frame is warned about once; ``clamped`` counts the lights moved); ``outside="error"`` raises
``LodprtError`` naming the box. Several lights: their
coefficients add (thesis 3.4.1), each scaled by its own RGB intensity (``Runtime``).
"""

from __future__ import annotations

import logging

import numpy as np

from lodprt.errors import LodprtError
from lodprt.model.scene import INTENSITY_LIMIT

log = logging.getLogger(__name__)

NEAREST = 8
WEIGHTINGS = ("exact", "t12")


class LightInterpolator:
    """Weights of the light samples for arbitrary light positions.

    samples (S, 3) sample positions; box (xmin, ymin, zmin, xmax, ymax, zmax) the sampled region.
    """

    def __init__(self, samples, box, *, weighting: str = "exact", outside: str = "clamp", nearest: int = NEAREST):
        self.samples = np.asarray(samples, np.float64).reshape(-1, 3)
        if not len(self.samples):
            raise LodprtError("light interpolation: the store has no light samples")
        b = np.asarray(box, np.float64).reshape(-1)
        if b.shape != (6,) or not (b[3:] >= b[:3]).all():
            raise LodprtError(f"light interpolation: box {box!r} is not xmin ymin zmin xmax ymax zmax")
        self.lo, self.hi = b[:3], b[3:]
        if weighting not in WEIGHTINGS:
            raise LodprtError(f"light interpolation: weighting {weighting!r}; choose one of {', '.join(WEIGHTINGS)}")
        if outside not in ("clamp", "error"):
            raise LodprtError(f"light interpolation: outside {outside!r}; choose 'clamp' or 'error'")
        self.weighting, self.outside = weighting, outside
        #: lights moved into the box so far (the warning is logged for the first only)
        self.clamped = 0
        self.k = min(int(nearest), len(self.samples))
        extent = float(np.linalg.norm(self.hi - self.lo)) or float(np.abs(self.samples).max()) or 1.0
        self.tol = 1e-9 * extent  # "on the boundary" counts as inside

    def box_text(self) -> str:
        """The box as ``[xmin, ymin, zmin] - [xmax, ymax, zmax]``."""
        return f"[{', '.join(f'{v:.4g}' for v in self.lo)}] - [{', '.join(f'{v:.4g}' for v in self.hi)}]"

    def clamp(self, lights) -> tuple[np.ndarray, np.ndarray]:
        """(L, 3) positions moved into the box (or LodprtError with ``outside="error"``) and (L,) bool: moved. The
        first light moved is warned about (where it was and where it went); later ones are counted in ``clamped``
        and logged at debug level only."""
        x = np.asarray(lights, np.float64).reshape(-1, 3)
        if not np.isfinite(x).all():
            raise LodprtError(f"light position: expected finite numbers, got {x.tolist()}")
        out = (x < self.lo - self.tol).any(1) | (x > self.hi + self.tol).any(1)
        moved = np.clip(x, self.lo, self.hi)
        if out.any():
            where = ", ".join(_xyz(p) for p in x[out])
            if self.outside == "error":
                raise LodprtError(f"light {where} lies outside the sampled region (light box) {self.box_text()}")
            to = ", ".join(_xyz(p) for p in moved[out])
            if not self.clamped:
                log.warning("light %s lies outside the sampled region (light box) %s: clamped to %s (further lights "
                            "outside it are clamped without another warning)", where, self.box_text(), to)
            else:
                log.debug("light %s clamped to %s", where, to)
            self.clamped += int(out.sum())
        return moved, out

    def weights(self, lights) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For (L, 3) lights: sample indices (L, k) int64, weights (L, k) float64 summing to 1 (T-12), and (L,) bool
        whether each light was clamped into the region."""
        x, moved = self.clamp(lights)
        d = np.linalg.norm(x[:, None, :] - self.samples[None, :, :], axis=2)
        idx = np.argsort(d, axis=1, kind="stable")[:, : self.k]
        dj = np.take_along_axis(d, idx, axis=1)
        r = dj.max(1, keepdims=True)
        rs = np.where(r > 0, r, 1.0)
        t = np.clip(1.0 - dj / rs, 0.0, 1.0)  # T-12 base
        w = t**4
        if self.weighting == "exact":
            q = dj / rs
            on = q <= 1e-12  # the light sits on a sample: exactly that sample
            with np.errstate(divide="ignore"):
                w = np.where(on.any(1, keepdims=True), on.astype(np.float64), w / np.where(on, 1.0, q) ** 4)
        total = w.sum(1, keepdims=True)
        w = np.where(total > 0, w / np.where(total > 0, total, 1.0), 1.0 / self.k)  # all equidistant: equal
        return idx, w, moved

    def rgb_weights(self, lights, colors) -> np.ndarray:
        """(S, 3) factor of every light sample for (L, 3) lights inside the region with (L, 3) RGB intensities:
        ``W[j, c] = sum_l colors[l, c] w_lj`` (several lights add, thesis 3.4.1)."""
        idx, w, _ = self.weights(lights)
        W = np.zeros((len(self.samples), 3))
        np.add.at(W, idx.ravel(), (w[:, :, None] * np.asarray(colors, np.float64)[:, None, :]).reshape(-1, 3))
        return W


def _xyz(p) -> str:
    return "(" + ", ".join(f"{v:.4g}" for v in p) + ")"


def check_lights(positions, colors, intensity) -> tuple[np.ndarray, np.ndarray]:
    """Point lights as given by a caller: (L, 3) positions (one (3,) is one light) and their RGB intensities
    ``colors`` ((L, 3), one (3,) for all, or None: ``intensity``, the bake's). Returns float64 (L, 3) positions
    and colours; LodprtError naming the field for a wrong shape, a non-finite number or a negative intensity."""
    pos = np.asarray(positions, np.float64)
    if pos.ndim == 1:
        pos = pos[None, :]
    if pos.ndim != 2 or pos.shape[1] != 3 or len(pos) < 1 or not np.isfinite(pos).all():
        raise LodprtError(f"lights: expected (L, 3) finite positions with L >= 1, got {np.asarray(positions).tolist()}")
    col = np.asarray(intensity if colors is None else colors, np.float64)
    if col.shape == (3,):
        col = np.repeat(col[None, :], len(pos), axis=0)
    if col.shape != pos.shape or not np.isfinite(col).all() or (col < 0).any():
        raise LodprtError(f"light colors: expected ({len(pos)}, 3) finite RGB intensities >= 0, got {col.tolist()}")
    if (col > INTENSITY_LIMIT).any():  # the bake's own limit: radiance = coefficients x intensity stays in float32
        raise LodprtError(f"light colors: each RGB intensity at most {INTENSITY_LIMIT:g} (the bake's limit, which keeps "
                          f"float32 radiance finite), got {col.max():g}")
    return pos, col

