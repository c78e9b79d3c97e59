"""The default white of a bake store, recorded at bake time (docs/FORMAT.md "Default white"), so that opening a
store of many light samples reads one attribute instead of every sample's rows.

The rule (the one of ``lodprt.runtime.frames.auto_white``, applied to the whole store):

* DW-1: per stored row ``v`` of light sample ``j``, the view-averaged radiance ``d = max_c |c[v, c, 0]| *
  max(intensity) * y_0`` (float32 coefficients, float64 product);
* DW-2: ``white = percentile_99 { d > 0 over every sample }`` (numpy's linear interpolation between the two
  values at ranks ``floor(0.99 (N - 1))`` and the next one; 1 when no ``d`` is positive).

A bake records per sample (attributes of ``samples/KKKKK``) ``white_count``, its number of rows with ``d > 0``,
and ``white_top``, the largest ``m = max_c |c[v, c, 0]|`` of them (descending; the top ``1 / TOP_DIVISOR`` plus 2:
a few bytes per sample). :func:`store_white` combines them when the store is committed: the white needs the
``N - floor(0.99 (N - 1))`` largest values of the store, and the records hold every one of them when the smallest
of those is no smaller than any partial record's smallest entry (an unrecorded value of a sample is no larger
than its record's smallest). Where that fails, the samples whose records stop too high are read again (one at a
time, only the largest values kept), so the recorded white equals DW-2 on the stored rows exactly, not a
streaming estimate.
"""

from __future__ import annotations

import numpy as np

from lodprt.model import sh
from lodprt.store.bake_store import open_store, sample_group
from lodprt.store.sample_groups import group_attrs

#: the percentile of DW-2 (``lodprt.runtime.frames.auto_white`` uses the same)
PERCENTILE = 99
#: a sample records its largest ``count // TOP_DIVISOR + 2`` view-averaged values
TOP_DIVISOR = 64
#: the root attribute holding the store's default white (absent in stores baked before it: the run time scans)
WHITE = "default_white"
#: the per-sample attributes of the record (not statistics: ``BakeResult.samples`` leaves them out)
RECORD_KEYS = ("white_count", "white_top")


def white_scale(intensity) -> np.float64:
    """``max(intensity) * y_0`` of DW-1 (float64, as the full scan multiplies)."""
    y0 = sh.basis(np.array([0.0, 0.0, 1.0]), 1)[0]
    return float(np.max(intensity)) * y0


def view_average(coeffs) -> np.ndarray:
    """(K,) float32 ``max_c |c[v, c, 0]|`` of DW-1 (before the scale) of the rows ``coeffs`` (K, C, N)."""
    return np.abs(np.asarray(coeffs, np.float32)[:, :, 0]).max(1) if len(coeffs) else np.zeros(0, np.float32)


def sample_record(coeffs) -> dict:
    """The white record of one light sample's stored rows: ``white_count`` and ``white_top`` (module doc)."""
    m = view_average(coeffs)
    m = m[m > 0]
    keep = min(len(m), len(m) // TOP_DIVISOR + 2)
    top = -np.partition(-m, keep - 1)[:keep] if keep else m
    return {"white_count": int(len(m)), "white_top": [float(x) for x in np.sort(top)[::-1]]}


def percentile_of_top(top_desc: np.ndarray, count: int) -> float:
    """DW-2 of ``count`` values of which ``top_desc`` (float64, descending) are the largest, enough of them."""
    if count == 0:
        return 1.0
    index = (count - 1) * (PERCENTILE / 100)  # numpy's virtual index of the linear method
    lo = int(np.floor(index))
    gamma = index - lo
    a = top_desc[count - 1 - lo]
    b = top_desc[count - 2 - lo] if lo + 1 < count else a
    return float(np.quantile(np.array([a, b], np.float64), gamma))  # numpy's own interpolation between the two


def store_white(store) -> float | None:
    """The default white of ``store`` (a ``Store``, or one of a partial folder) from its samples' records (DW-2,
    exact); a sample without a record (baked before it existed) is read. None (record nothing: the run time scans)
    for an intensity whose scale could underflow or overflow a value."""
    scale = white_scale(store.intensity)
    if scale == 0:
        return 1.0  # every d is 0
    if not 1e-250 < scale < 1e250:
        return None
    counts, tops, floors = [], [], []
    for k in range(store.num_samples):
        rec = group_attrs(store.path / sample_group(k)) or {}
        if "white_count" not in rec or "white_top" not in rec:
            _, coeffs = store.sample(k)
            rec = sample_record(coeffs)
        top = np.asarray(rec["white_top"], np.float32)
        counts.append(int(rec["white_count"]))
        tops.append(top)
        floors.append(float(top[-1]) if int(rec["white_count"]) > len(top) else -np.inf)  # partial: its smallest
    total = int(sum(counts))
    if total == 0:
        return 1.0
    need = total - int(np.floor((total - 1) * (PERCENTILE / 100)))  # the largest values DW-2 reads
    union = _largest(np.concatenate(tops), need)
    # a lower bound of the need-th largest value (none when the records hold fewer than need values)
    bound = union[need - 1] if len(union) >= need else -np.inf
    short = {k for k, f in enumerate(floors) if f > bound}  # their unrecorded values may exceed the bound
    if short:  # read those again: the largest values of the others' records and of their rows
        union = _largest(np.concatenate([np.zeros(0, np.float32)] + [t for k, t in enumerate(tops) if k not in short]),
                         need)
        for k in sorted(short):
            m = view_average(store.sample(k)[1])
            union = _largest(np.concatenate([union, m[(m > 0) & (m >= bound)]]), need)
    return percentile_of_top(union.astype(np.float64) * scale, total)  # DW-1, DW-2


def _largest(values: np.ndarray, n: int) -> np.ndarray:
    """The ``n`` largest of ``values`` (all of them when fewer), descending."""
    if len(values) > n:
        values = -np.partition(-values, n - 1)[:n]
    return np.sort(values)[::-1]

def record_white(writer, *, decoded: bool = False) -> float | None:
    """Write the root attribute ``default_white`` of the store ``writer`` (a ``StoreWriter``) is about to commit,
    from its samples' records (:func:`store_white`); ``decoded``: first record every sample afresh from its rows
    as a reader decodes them (a re-encoded store: a lossy codec changes the rows)."""
    store = open_store(writer.partial)
    if decoded:
        for k in range(store.num_samples):
            writer.attrs(sample_group(k), **sample_record(store.sample(k)[1]))
    white = store_white(store)
    if white is not None:
        writer.attrs(**{WHITE: white})
    return white
