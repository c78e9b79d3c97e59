"""Lossy codecs of a light sample's SH coefficients (format version 2, docs/FORMAT.md "Compressed bake store"; tags
C-1..C-4).

A sample's coefficients are a (K, C, N) float32 array: K kept vertices, C channels, N = n*n coefficients (or 1).
Each codec turns it into a few small arrays and decodes them with numpy alone:

    none         the version-1 arrays, unchanged (lossless)
    f16          C-1  float16 after a power-of-two scale 2^e of the sample (e chosen so max|c| / 2^e < 2^15):
                      |c^ - c| <= 2^-11 |c| + 2^(e-25) per element (round to nearest; 2^(e-25) covers subnormals)
    q8 q10 q12   C-2  integers per vertex and SH band l: scale s_l = max |c| over the band's 2l+1 coefficients and
                      the channels (stored float16, rounded up), b_l = max(B - l, 4) bits for band l (fewer bits for
                      higher bands, whose scale is already small), q = round(c / S_l * L_l), L_l = 2^(b_l - 1) - 1:
                      |c^ - c| <= S_l / (2 L_l) per element (half a step) plus float32 rounding, S_l >= s_l the
                      stored scale (times the sample's 2^e), within 2^-10 of s_l when s_l >= 2^(e-14) (float16
                      normal: band maxima within 2^29 of the sample's largest)
    cpca:K:M[:W] C-3  clustered PCA (Sloan et al. 2003), jointly over vertices x light samples: every (vertex,
                      sample) row of the store, a vector of D = C*N numbers, is one point. K clusters (k-means,
                      then CPCA reassignment by reconstruction error), per cluster a mean and M orthonormal basis
                      vectors; per row its cluster and M weights, quantised to W = 8 (default) or 16 bits with a
                      per-(cluster, vector) scale, or W = 32 (float32, unquantised):
                      |c^ - c|_2 <= r + sqrt(sum_m (s_km / (2 L))^2) per row, r its distance to the cluster's
                      affine subspace (0 when M = D), s_km the weight scale, L = 2^(W-1) - 1 (no term for W = 32)

Structure arrays are stored losslessly and compactly in every version-2 store (C-4): vertex ids as gaps
(``ids = cumsum(gaps)``; ids ascend; uint8 gaps, 255 escaping to a uint32 list), the light cut's nodes as the
number of parent steps from the leaf at the vertex (the nodes standing at one vertex are a chain of child-0
ancestors of its leaf), dark flags as bits.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np

from lodprt.errors import LodprtError, StoreError

#: the codec names ``--compress`` / ``--codec`` accept (cpca takes its numbers: cpca:CLUSTERS:VECTORS[:BITS])
CODECS = ("none", "f16", "q8", "q10", "q12", "cpca:CLUSTERS:VECTORS[:BITS]")
#: fewest bits any SH band gets in the q codecs
MIN_BAND_BITS = 4
#: k-means (Lloyd) iterations and CPCA reassignment rounds of the cpca fit
LLOYD_ITERATIONS = 12
CPCA_ROUNDS = 3
#: a vertex-id gap of this or more is stored as this byte plus its value in ``vertex_gaps_long`` (C-4)
GAP_ESCAPE = 255
#: rows per block of the cpca distance computations (bounds memory to a few tens of MB)
BLOCK_ROWS = 1 << 14
#: what each codec kind writes in every sample group: (arrays, attributes) of its coefficients (C-1..C-3)
CODEC_PARTS = {"none": (("coefficients",), ()), "f16": (("coefficients_f16",), ("scale_exponent",)),
               "q": (("coefficients_q", "band_scales"), ("scale_exponent", "band_bits")),
               "cpca": (("cluster", "weights"), ())}
#: a sample's structure arrays (C-4) in every version-2 store, and those added in a light-cut store
STRUCTURE_ARRAYS = ("vertex_gaps", "vertex_gaps_long")
CUT_STRUCTURE_ARRAYS = ("cut_levels", "dark_bits")
#: the store-level cpca arrays under ``codec/`` (their group's attribute: ``weight_levels``)
MODEL_ARRAYS = ("mean", "basis", "weight_scale")


@dataclasses.dataclass(frozen=True)
class Codec:
    """A parsed codec: ``kind`` none | f16 | q | cpca; ``bits`` (q: B, cpca: weight bits W); ``clusters``,
    ``vectors`` (cpca)."""

    kind: str
    bits: int = 0
    clusters: int = 0
    vectors: int = 0

    @property
    def name(self) -> str:
        if self.kind == "q":
            return f"q{self.bits}"
        if self.kind == "cpca":
            return f"cpca:{self.clusters}:{self.vectors}" + ("" if self.bits == 8 else f":{self.bits}")
        return self.kind

    @property
    def lossless(self) -> bool:
        return self.kind == "none"

    @property
    def weight_levels(self) -> int:
        """cpca: L of the weights' quantisation (1 for float32 weights)."""
        return 1 if self.bits == 32 else 2 ** (self.bits - 1) - 1


def parse_codec(text: str, option: str = "--codec") -> Codec:
    """The codec named by ``text``; LodprtError naming ``option`` when it is not one of CODECS."""
    s = str(text).strip().lower()
    if s in ("none", "f16"):
        return Codec(s)
    m = re.fullmatch(r"q(8|10|12)", s)
    if m:
        return Codec("q", bits=int(m.group(1)))
    m = re.fullmatch(r"cpca:(\d+):(\d+)(?::(\d+))?", s)
    if m:
        clusters, vectors, bits = int(m.group(1)), int(m.group(2)), int(m.group(3) or 8)
        if clusters < 1 or clusters > 65535 or vectors < 1 or bits not in (8, 16, 32):
            raise LodprtError(f"{option} {text}: cpca needs 1 <= CLUSTERS <= 65535, VECTORS >= 1 and BITS 8, 16 "
                              "or 32")
        return Codec("cpca", bits=bits, clusters=clusters, vectors=vectors)
    raise LodprtError(f"{option} {text!r}: not a codec; choose one of {', '.join(CODECS)}")


def check_layout(codec: Codec, channels: int, ncoef: int, option: str = "--codec") -> None:
    """Refuse a cpca codec with more basis vectors than a row has numbers (C * N)."""
    if codec.kind == "cpca" and codec.vectors > channels * ncoef:
        raise LodprtError(f"{option} {codec.name}: VECTORS {codec.vectors} exceeds the {channels * ncoef} "
                          f"coefficients of a vertex in this store ({channels} channel(s) x {ncoef})")


def sample_parts(codec: str, *, cut: bool) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(arrays, attributes) every sample group of a store of ``codec`` holds ("none": version 1's arrays): its
    vertex ids or structure arrays, those of the light cut when ``cut``, and the codec's own."""
    kind = parse_codec(codec, "codec").kind
    arrays, attrs = CODEC_PARTS[kind]
    if kind == "none":
        return ("vertex_ids", *arrays, *(("cut_nodes", "dark") if cut else ())), attrs
    return (*STRUCTURE_ARRAYS, *(CUT_STRUCTURE_ARRAYS if cut else ()), *arrays), attrs


# -- helpers: float16 with a power-of-two scale, bands --------------------------------------------------------


def power_of_two_exponent(max_abs: float) -> int:
    """e such that max_abs / 2^e < 2^15 (inside float16's range with room for rounding); 0 for 0."""
    if not max_abs > 0:
        return 0
    return int(np.ceil(np.log2(max_abs))) - 14


def float16_up(x: np.ndarray) -> np.ndarray:
    """float16 values >= x (x >= 0, below 65504): round to nearest, then one step up where that fell short."""
    h = np.asarray(x, np.float32).astype(np.float16)
    short = h.astype(np.float32) < x
    h[short] = np.nextafter(h[short], np.float16(np.inf))
    return h


def band_slices(ncoef: int) -> list[slice]:
    """The coefficient ranges of SH bands l = 0.. (l*l .. (l+1)^2) of a vector of ncoef = n*n (or 1) entries."""
    n = int(round(np.sqrt(ncoef)))
    if n * n != ncoef:
        raise StoreError(f"coefficients_per_vertex {ncoef}: not a square number")
    return [slice(l * l, (l + 1) * (l + 1)) for l in range(n)]


def band_bits(bits: int, bands: int) -> list[int]:
    """C-2 bits of each band: max(B - l, MIN_BAND_BITS)."""
    return [max(bits - l, MIN_BAND_BITS) for l in range(bands)]


def smallest_uint(max_value: int) -> np.dtype:
    for t in (np.uint8, np.uint16, np.uint32):
        if max_value <= np.iinfo(t).max:
            return np.dtype(t)
    return np.dtype(np.uint64)


# -- C-4: structure arrays ---------------------------------------------------------------------------------------


def encode_structure(ids: np.ndarray, cut_nodes: np.ndarray | None, dark: np.ndarray | None,
                     parent: np.ndarray | None, vertex: np.ndarray | None) -> dict[str, np.ndarray]:
    """Vertex ids, cut nodes and dark flags of a sample as version-2 arrays (lossless, C-4). Ids must ascend
    (every bake writes them so); cut nodes need the hierarchy's ``parent`` and ``vertex``."""
    ids = np.asarray(ids, np.int64)
    out: dict[str, np.ndarray] = {}
    if len(ids) and (ids[0] < 0 or (np.diff(ids) <= 0).any()):
        raise StoreError("vertex_ids: not strictly ascending; version 2 stores them as gaps")
    gaps = np.diff(ids, prepend=0)
    long = gaps >= GAP_ESCAPE
    out["vertex_gaps"] = np.where(long, GAP_ESCAPE, gaps).astype(np.uint8)
    out["vertex_gaps_long"] = gaps[long].astype(np.uint32)
    if cut_nodes is not None:
        out["cut_levels"] = cut_levels(ids, np.asarray(cut_nodes, np.int64), parent, vertex)
        out["dark_bits"] = np.packbits(np.asarray(dark, np.uint8) != 0)
    return out


def cut_levels(ids: np.ndarray, nodes: np.ndarray, parent: np.ndarray, vertex: np.ndarray) -> np.ndarray:
    """Parent steps from leaf ``ids[j]`` up to ``nodes[j]`` (C-4); StoreError when a node is not on that chain."""
    if parent is None or vertex is None:
        raise StoreError("cut_nodes without hierarchy/parent: cannot store them as levels")
    levels = np.zeros(len(ids), np.int64)
    node = ids.copy()
    todo = node != nodes
    while todo.any():
        node[todo] = parent[node[todo]]
        levels[todo] += 1
        bad = todo & ((node < 0) | (vertex[np.maximum(node, 0)] != ids))
        if bad.any():
            raise StoreError(f"cut_nodes: node {int(nodes[bad][0])} does not stand at vertex {int(ids[bad][0])}")
        todo = node != nodes
    return levels.astype(smallest_uint(int(levels.max()) if len(levels) else 0))


def decode_structure(arrays: dict, parent: np.ndarray | None) -> tuple[np.ndarray, dict]:
    """(vertex ids (K,) int32, {"cut_nodes", "dark"} or {}) from version-2 arrays (C-4)."""
    gaps = np.asarray(arrays["vertex_gaps"], np.int64)
    gaps[gaps == GAP_ESCAPE] = arrays["vertex_gaps_long"]
    ids = np.cumsum(gaps)
    cut: dict[str, np.ndarray] = {}
    if "cut_levels" in arrays:
        levels = np.asarray(arrays["cut_levels"], np.int64)
        node = ids.copy()
        for step in range(int(levels.max()) if len(levels) else 0):
            up = levels > step
            node[up] = parent[node[up]]
        cut = {"cut_nodes": node.astype(np.int32),
               "dark": np.unpackbits(arrays["dark_bits"], count=len(ids)).astype(np.uint8)}
    return ids.astype(np.int32), cut


# -- C-1, C-2: per-sample codecs ------------------------------------------------------------------------------------


def encode_f16(c: np.ndarray) -> tuple[dict, dict]:
    """C-1: (arrays, attributes) of a sample's coefficients as float16 times 2^e."""
    e = power_of_two_exponent(float(np.abs(c).max()) if c.size else 0.0)
    return {"coefficients_f16": (c.astype(np.float64) / 2.0**e).astype(np.float16)}, {"scale_exponent": e}


def encode_q(c: np.ndarray, bits: int) -> tuple[dict, dict]:
    """C-2: (arrays, attributes) of a sample's coefficients as integers per vertex and band."""
    slices = band_slices(c.shape[2])
    bb = band_bits(bits, len(slices))
    scale = np.stack([np.abs(c[:, :, s]).max(axis=(1, 2)) for s in slices], 1) if c.size else \
        np.zeros((len(c), len(slices)), np.float32)
    e = power_of_two_exponent(float(scale.max()) if scale.size else 0.0)
    stored = float16_up(scale.astype(np.float64) / 2.0**e)
    step = stored.astype(np.float64) * 2.0**e
    q = np.zeros(c.shape, np.int8 if bits <= 8 else np.int16)
    for l, s in enumerate(slices):
        L = 2 ** (bb[l] - 1) - 1
        sl = np.where(step[:, l] > 0, step[:, l], 1.0)[:, None, None]
        q[:, :, s] = np.clip(np.rint(c[:, :, s] / sl * L), -L, L)
    return {"coefficients_q": q, "band_scales": stored}, {"scale_exponent": e, "band_bits": bb}


def decode_q(q: np.ndarray, scales: np.ndarray, exponent: int, bits: list[int]) -> np.ndarray:
    """C-2 decode: c = q * s_l 2^e / L_l, (K, C, N) float32."""
    out = np.empty(q.shape, np.float32)
    for l, s in enumerate(band_slices(q.shape[2])):
        L = 2 ** (bits[l] - 1) - 1
        out[:, :, s] = q[:, :, s] * (scales[:, l].astype(np.float32) * np.float32(2.0**exponent / L))[:, None, None]
    return out


def decode_sample(codec: str, arrays: dict, attrs: dict, model: dict | None = None, shape=None) -> np.ndarray:
    """The (K, C, N) float32 coefficients of one sample of a version-2 store from its arrays and attributes;
    ``model`` holds the store-level cpca arrays (mean, basis, weight_scale), ``shape`` (C, N)."""
    kind = parse_codec(codec, "codec").kind
    if kind == "f16":
        return (arrays["coefficients_f16"].astype(np.float32) * np.float32(2.0 ** attrs["scale_exponent"]))
    if kind == "q":
        return decode_q(arrays["coefficients_q"], arrays["band_scales"], attrs["scale_exponent"], attrs["band_bits"])
    if kind == "cpca":
        rows = cpca_decode(model, arrays["cluster"], arrays["weights"])
        return rows.reshape((len(rows),) + tuple(shape))
    return arrays["coefficients"]


def encode_sample(codec: Codec, c: np.ndarray) -> tuple[dict, dict]:
    """(arrays, attributes) of one sample under a per-sample codec (none, f16, q)."""
    if codec.kind == "f16":
        return encode_f16(c)
    if codec.kind == "q":
        return encode_q(c, codec.bits)
    if codec.kind == "none":
        return {"coefficients": np.asarray(c, np.float32)}, {}
    raise StoreError(f"codec {codec.name}: fitted over the whole store, not per sample (use CPCA.fit)")


# -- C-3: clustered PCA --------------------------------------------------------------------------------------------


def nearest_centres(X: np.ndarray, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(index of the nearest centre, squared distance to it) for every row of X, in blocks of rows."""
    c2 = (centres * centres).sum(1)
    lab = np.empty(len(X), np.int64)
    dist = np.empty(len(X))
    for a in range(0, len(X), BLOCK_ROWS):
        x = X[a:a + BLOCK_ROWS]
        d = (x * x).sum(1)[:, None] - 2.0 * x @ centres.T + c2[None, :]
        lab[a:a + len(x)] = d.argmin(1)
        dist[a:a + len(x)] = np.maximum(d[np.arange(len(x)), lab[a:a + len(x)]], 0.0)
    return lab, dist


def kmeans(X: np.ndarray, k: int, rng: np.random.Generator, iterations: int = LLOYD_ITERATIONS) -> np.ndarray:
    """Lloyd's k-means of the rows of X (float64): the label of each row. Seeds by k-means++ (Arthur and
    Vassilvitskii 2007: each next seed drawn with probability proportional to the squared distance to the nearest
    seed so far); a cluster left empty is re-seeded with the row farthest from its centre."""
    centres = np.empty((k, X.shape[1]))
    centres[0] = X[rng.integers(len(X))]
    d2 = ((X - centres[0]) ** 2).sum(1)
    for j in range(1, k):
        total = d2.sum()
        pick = rng.choice(len(X), p=d2 / total) if total > 0 else rng.integers(len(X))
        centres[j] = X[pick]
        d2 = np.minimum(d2, ((X - centres[j]) ** 2).sum(1))
    for _ in range(iterations):
        lab, dist = nearest_centres(X, centres)
        count = np.bincount(lab, minlength=k)
        sums = np.zeros_like(centres)
        np.add.at(sums, lab, X)
        filled = count > 0
        centres[filled] = sums[filled] / count[filled, None]
        empty = np.flatnonzero(~filled)
        if len(empty):
            centres[empty] = X[np.argsort(dist)[::-1][: len(empty)]]
    return nearest_centres(X, centres)[0]


def cluster_pca(X: np.ndarray, lab: np.ndarray, k: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Per cluster the mean (k, D) and the m leading principal directions (k, m, D), orthonormal rows (0 rows
    where a cluster is empty); the eigenvectors of the cluster's scatter matrix, largest eigenvalue first."""
    D = X.shape[1]
    mean = np.zeros((k, D))
    basis = np.zeros((k, m, D))
    order = np.argsort(lab, kind="stable")
    bounds = np.searchsorted(lab[order], np.arange(k + 1))
    for j in range(k):
        rows = X[order[bounds[j]:bounds[j + 1]]]
        if not len(rows):
            continue
        mean[j] = rows.mean(0)
        y = rows - mean[j]
        _, vec = np.linalg.eigh(y.T @ y)
        basis[j] = vec[:, ::-1][:, :m].T
    return mean, basis


def subspace_errors(X: np.ndarray, mean: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """|x - mu_k|^2 - |B_k (x - mu_k)|^2 for every row and cluster, (R, k): the squared distance of each row to
    each cluster's affine subspace (CPCA's reassignment criterion)."""
    k, m, D = basis.shape
    flat = basis.reshape(k * m, D)
    mb = np.einsum("kd,kmd->km", mean, basis)
    out = np.empty((len(X), k))
    for a in range(0, len(X), BLOCK_ROWS):
        x = X[a:a + BLOCK_ROWS]
        d2 = (x * x).sum(1)[:, None] - 2.0 * x @ mean.T + (mean * mean).sum(1)[None, :]
        proj = (x @ flat.T).reshape(len(x), k, m) - mb[None]
        out[a:a + len(x)] = d2 - (proj * proj).sum(2)
    return out


def cpca_fit(X: np.ndarray, codec: Codec, *, seed: int = 0, rounds: int = CPCA_ROUNDS) -> dict:
    """C-3: fit clustered PCA to the rows of X (R, D) and encode them. Returns the store-level model
    {"mean" (k, D) f32, "basis" (k, M, D) f32, "weight_scale" (k, M) f32} and per-row "cluster" (R,) and
    "weights" (R, M) (int8 / int16 / float32). k = min(CLUSTERS, R)."""
    X = np.asarray(X, np.float64)
    R, D = X.shape
    m = codec.vectors
    k = max(1, min(codec.clusters, R))
    rng = np.random.default_rng(seed)
    lab = kmeans(X, k, rng) if R else np.zeros(0, np.int64)
    mean, basis = cluster_pca(X, lab, k, m)
    for _ in range(rounds if R else 0):  # Sloan et al.: reassign each row to the subspace that fits it best
        new = subspace_errors(X, mean, basis).argmin(1)
        if np.array_equal(new, lab):
            break
        lab = new
        mean, basis = cluster_pca(X, lab, k, m)
    mean, basis = mean.astype(np.float32), basis.astype(np.float32)
    w = np.zeros((R, m))
    for a in range(0, R, BLOCK_ROWS):  # weights = B_k (x - mu_k), in blocks (basis[lab] is R x M x D)
        b = lab[a:a + BLOCK_ROWS]
        w[a:a + len(b)] = np.einsum("rd,rmd->rm", X[a:a + len(b)] - mean[b], basis[b].astype(np.float64))
    scale = np.zeros((k, m))
    np.maximum.at(scale, lab, np.abs(w))
    scale = np.where(scale > 0, scale, 1.0).astype(np.float32)
    L = codec.weight_levels
    if codec.bits == 32:
        weights = w.astype(np.float32)
        scale[:] = 1.0
    else:
        weights = np.clip(np.rint(w / scale[lab] * L), -L, L).astype(np.int8 if codec.bits == 8 else np.int16)
    cluster = lab.astype(np.uint8 if k <= 256 else np.uint16)
    return {"mean": mean, "basis": basis, "weight_scale": scale, "weight_levels": L,
            "cluster": cluster, "weights": weights}


def cpca_decode(model: dict, cluster: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """C-3 decode: c = mean[k] + sum_m (weights_m * weight_scale[k, m] / L) basis[k, m], rows (R, D) float32."""
    k = np.asarray(cluster, np.int64)
    w = weights.astype(np.float32) * (model["weight_scale"][k] / np.float32(model["weight_levels"]))
    return model["mean"][k] + np.einsum("rm,rmd->rd", w, model["basis"][k])


# -- reading a version-2 store (duck-typed: ``store.read(name)``, ``store.root``, ``store.attrs``) --------------------


def cpca_model(store) -> dict:
    """The store-level cpca arrays ``codec/mean``, ``codec/basis``, ``codec/weight_scale`` and L."""
    return {"mean": store.read("codec/mean"), "basis": store.read("codec/basis"),
            "weight_scale": store.read("codec/weight_scale"),
            "weight_levels": int(store.root["codec"].attrs["weight_levels"])}


def sample_arrays(store, k: int) -> tuple[dict, dict]:
    """(arrays by name, attributes) of the group ``samples/KKKKK`` as stored."""
    g = f"samples/{k:05d}"
    group = store.root[g]
    return {name: store.read(f"{g}/{name}", cache=False) for name in group.array_keys()}, dict(group.attrs)


def read_sample(store, k: int) -> tuple[np.ndarray, np.ndarray, dict]:
    """(vertex ids (K,) int32, coefficients (K, C, N) float32, {"cut_nodes", "dark"} or {}) of sample ``k`` of a
    version-2 store, decoded (C-1..C-4)."""
    arrays, attrs = sample_arrays(store, k)
    codec = str(store.attrs.get("codec", "none"))
    try:
        parent = store.read("hierarchy/parent") if "cut_levels" in arrays else None
        ids, cut = decode_structure(arrays, parent)
        model = cpca_model(store) if codec.startswith("cpca") else None
        shape = (int(store.attrs["channels"]), int(store.attrs["coefficients_per_vertex"]))
        coeffs = decode_sample(codec, arrays, attrs, model, shape)
    except StoreError:  # a damaged array it read (the hierarchy's, the codec's): already one line naming it
        raise
    except (KeyError, IndexError, ValueError) as exc:
        raise StoreError(f"{store.path}: samples/{k:05d} (codec {codec}): cannot decode: {exc!r}") from exc
    return ids, coeffs, cut


def read_cut(store, k: int) -> dict:
    """{"cut_nodes", "dark"} of sample ``k`` of a version-2 light-cut store ({} in full mode), C-4."""
    arrays = sample_arrays(store, k)[0]
    return decode_structure(arrays, store.read("hierarchy/parent") if "cut_levels" in arrays else None)[1]


def codec_summary(store) -> dict:
    """What ``lodprt info`` adds for the codec: its name, the bytes of the store-level codec arrays, the
    version-1 payload of the samples (``bytes_raw``; their own ``bytes`` in version 1)."""
    raw = 0
    for k in range(store.num_samples):
        a = store.sample_info(k)
        raw += int(a.get("bytes_raw", a["bytes"]))
    return {"codec": store.codec, "codec_bytes": int(store.attrs.get("codec_bytes", 0)), "bytes_raw_total": raw}
