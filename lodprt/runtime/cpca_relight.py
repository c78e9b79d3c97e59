"""Relighting in the compressed domain of a cpca store (C-5; Sloan et al. 2003, section 4; docs/FORMAT.md
"Compressed bake store"): the light's weights are applied to the cluster tables once per frame, then each stored
row is one weighted sum of its cluster's lit table, without decoding any sample's coefficients first.

A cpca store (``lodprt.store.codecs``, C-3) holds, per light sample j, rows (vertex v, cluster k, integer weights
q_1..q_M) with  c_vj = mu_k + sum_m q_m (s_km / L) b_km.  Under lights whose interpolation weights (T-12, with the
lights' RGB intensities) are W_j (3,) for the active samples (at most 8 per light):

    C-5   T_jk = W_j [ mu_k ; (s_k1 / L) b_k1 ; ... ; (s_kM / L) b_kM ]        once per frame: J x K x (M+1) x C x N
          c_v  = sum_{j: v kept in j} ( T_jk[0] + sum_m q_m T_jk[m] )          per stored row: a weighted sum
          L_v  = sum_i c_v,i y_i((eye - p_v) / |eye - p_v|)                    T-7, once per vertex

This equals relighting the decoded coefficients (``Store.sample``) exactly up to float rounding. It covers what
the store keeps: every referenced vertex of a full-resolution store; in a light-cut store the vertices kept by
every active sample (``covered``), the others needing T-15 completion of decoded samples (``Store.coefficients``).
"""

from __future__ import annotations

import numpy as np

from lodprt.errors import LodprtError
from lodprt.model import sh
from lodprt.runtime.lights import LightInterpolator, check_lights
from lodprt.store import codecs


class CompressedSamples:
    """The compressed rows of every light sample of a cpca store, read once (no sample is decoded), and the
    cluster tables; :meth:`radiance` relights them (C-5)."""

    def __init__(self, store):
        if not store.codec.startswith("cpca"):
            raise LodprtError(f"{store.path}: codec {store.codec}; compressed-domain relighting needs a cpca store")
        self.store = store
        self.model = codecs.cpca_model(store)
        self.channels = int(store.attrs["channels"])
        self.ncoef = store.coefficients_per_vertex
        self.rows = []
        for k in range(store.num_samples):
            arrays, _ = codecs.sample_arrays(store, k)
            ids, _ = codecs.decode_structure({n: arrays[n] for n in ("vertex_gaps", "vertex_gaps_long")}, None)
            self.rows.append((ids.astype(np.int64), arrays["cluster"].astype(np.int64), arrays["weights"]))
        self.positions = np.asarray(store.positions, np.float64)
        self.normals = np.asarray(store.normals, np.float64)
        self.interp = LightInterpolator(store.light_positions, store.root["lights"].attrs["box"])

    def lit_tables(self, W: np.ndarray, samples) -> np.ndarray:
        """C-5 T_jk for the active ``samples`` (J,) with RGB weights W (S, 3): (J, K, M+1, 3, N) float32."""
        mean, basis = self.model["mean"], self.model["basis"]
        k, m, _ = basis.shape
        scaled = basis * (self.model["weight_scale"] / np.float32(self.model["weight_levels"]))[:, :, None]
        table = np.concatenate([mean[:, None, :], scaled], 1).reshape(k, m + 1, self.channels, self.ncoef)
        w = np.asarray(W, np.float32)[np.asarray(samples)]  # (J, 3); a grey store's one channel serves R, G, B
        return table[None, :, :, :, :] * w[:, None, None, :, None]

    def coefficients(self, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(V, 3, N) float32 lit coefficients summed over the samples with non-zero RGB weight in W (S, 3), and
        (V,) bool: kept by every one of those samples."""
        W = np.asarray(W, np.float64)
        if W.shape != (len(self.rows), 3):
            raise LodprtError(f"light weights: expected ({len(self.rows)}, 3), got {W.shape}")
        active = np.flatnonzero(np.abs(W).sum(1) > 0)
        tables = self.lit_tables(W, active)
        V = len(self.positions)
        out = np.zeros((V, 3, self.ncoef), np.float32)
        kept = np.zeros(V, np.int64)
        for t, j in enumerate(active):
            ids, cluster, q = self.rows[j]
            a = np.concatenate([np.ones((len(q), 1), np.float32), q.astype(np.float32)], 1)
            out[ids] += np.einsum("rm,rmcn->rcn", a, tables[t][cluster])
            kept[ids] += 1
        return out, kept == len(active)

    def radiance(self, W: np.ndarray, eye) -> tuple[np.ndarray, np.ndarray]:
        """(V, 3) float32 radiance toward ``eye`` (T-7 of the C-5 coefficients) and (V,) bool ``covered``."""
        eye = np.asarray(eye, np.float64)
        if eye.shape != (3,) or not np.isfinite(eye).all():
            raise LodprtError(f"eye: expected 3 finite numbers, got {eye.tolist()}")
        c, covered = self.coefficients(W)
        d = eye[None, :] - self.positions
        n = np.linalg.norm(d, axis=1, keepdims=True)
        d = np.where(n > 0, d / np.where(n > 0, n, 1.0), self.normals)
        y = sh.basis(d, int(round(np.sqrt(self.ncoef)))).astype(np.float32)
        return np.einsum("vcn,vn->vc", c, y), covered

    def light_weights(self, lights, colors=None) -> np.ndarray:
        """(S, 3) RGB weights of the light samples for point lights at (L, 3) positions (T-12, clamped into the
        sampled region; ``colors`` default the bake's intensity), as the run time computes them."""
        pos, col = check_lights(lights, colors, self.store.intensity)
        pos, _ = self.interp.clamp(pos)
        return self.interp.rgb_weights(pos, col)
