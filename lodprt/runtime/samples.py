"""Completed light samples on demand for the run time (SPEC 5; thesis 3.4.3, T-15): ``SampleCache`` completes a
light sample the first time the lights give it a non-zero weight and keeps it in one of a bounded number of slots,
so that opening a store and a frame cost memory for the samples in use, not for every sample of the store
(docs/RUNTIME.md, docs/SCALE.md). Per-sample quantities derived from the completed coefficients (the view cut's
per-node bounds) live in the same slots and are made with them.
"""

from __future__ import annotations

import contextlib
import logging
import typing

import numpy as np

from lodprt.errors import LodprtError, StoreError
from lodprt.store.white import WHITE, view_average, white_scale

log = logging.getLogger(__name__)

#: default cache size: completed samples (and their per-node bounds) up to this many bytes, never fewer slots than
#: the samples one frame uses
DEFAULT_CACHE_BYTES = 1 << 30


class SampleCache:
    """Slots of completed light samples, vertex-major ``coeffs`` (V, slots, C, ncoef) float32 so that a vertex's
    samples sit together for the per-frame gathers; ``slot_sample[s]`` is the sample in slot ``s`` (-1: empty).

    ``ensure(samples)`` returns the slot of each sample, completing the missing ones (T-15, ``store.complete``)
    into empty slots, then (once the slots reach ``cache_bytes``) into the least recently used ones not asked for
    now; slots are allocated as they are needed (doubling), and never fewer than one frame asks for. ``derive(name, make, shape, dtype)`` adds a per-slot array ``(rows, slots) + shape`` filled
    by ``make(coefficients)`` for every sample loaded, now and later. ``version`` changes whenever a slot's
    content does (the device copies are refreshed from it).
    """

    def __init__(self, store, *, cache_bytes: int | None = None, progress=None, split=None, field=None):
        self.store = store
        self.V = store.num_vertices
        self.C = int(store.root.attrs.get("channels", 1))
        self.n = store.coefficients_per_vertex
        self.S = store.num_samples
        if cache_bytes is not None and (not isinstance(cache_bytes, (int, np.integer)) or cache_bytes < 0):
            raise LodprtError(f"cache_bytes {cache_bytes!r}: must be a whole number of bytes >= 0")
        self.cache_bytes = DEFAULT_CACHE_BYTES if cache_bytes is None else int(cache_bytes)
        self.progress = progress
        # M-2: split(sample, completed) -> (visibility (V,) uint8, residual (V, C, ncoef)); the slots then hold the
        # residual and ``visibility`` (V, slots) the sample's visibility states (lodprt.runtime.direct_light)
        self.split = split
        # the derived per-node bounds are made from the field the run time draws with the light on each sample: S_j
        # itself (T-12, and M-1 on a GI store, which gives back S_j on a sample), or, with ``field``, D_j V_j.
        # field(sample) -> (visibility (V,) uint8, drawn field (V, C, ncoef)): when the lighting never reads the
        # samples' coefficients (M-1 on a direct-only store), the slots keep no coefficients (``coeffs`` has no
        # rows) and a sample is not completed: its derived bounds come from this field (D_j V_j), its visibility
        # (with ``split``) from the same shadow rays (docs/SCALE.md: run-time memory)
        self.field = field
        self.visibility = np.zeros((self.V, 0), np.uint8)
        self.derived: dict[str, tuple[np.ndarray, typing.Callable]] = {}
        self.slot_sample = np.zeros(0, np.int64)
        self.last_used = np.zeros(0, np.int64)
        self.coeffs = np.zeros((0 if field is not None else self.V, 0, self.C, self.n), np.float32)
        self.clock = 0
        self.version = 0
        self.completed = 0  # samples completed so far (misses)

    # -- size ------------------------------------------------------------------------------------------------
    def bytes_per_slot(self) -> int:
        """Bytes one slot holds: the coefficients and every derived array's row."""
        per = len(self.coeffs) * self.C * self.n * 4 + (self.V if self.split is not None else 0)
        for arr, _ in self.derived.values():
            per += arr[:, :1].nbytes
        return per

    @property
    def slots(self) -> int:
        return len(self.slot_sample)

    @property
    def nbytes(self) -> int:
        return self.coeffs.nbytes + self.visibility.nbytes + sum(a.nbytes for a, _ in self.derived.values())

    def _capacity(self, need: int) -> int:
        """Slots to hold: at least ``need`` (one frame's samples), as many more as ``cache_bytes`` allows, at most S."""
        return int(min(self.S, max(need, self.cache_bytes // max(self.bytes_per_slot(), 1))))

    def _grow(self, slots: int) -> None:
        old = self.slots
        if slots <= old:
            return

        def widen(a: np.ndarray) -> np.ndarray:
            out = np.zeros((a.shape[0], slots) + a.shape[2:], a.dtype)
            out[:, :old] = a
            return out

        self.coeffs = widen(self.coeffs)
        if self.split is not None:
            self.visibility = widen(self.visibility)
        self.derived = {k: (widen(a), make) for k, (a, make) in self.derived.items()}
        self.slot_sample = np.concatenate([self.slot_sample, np.full(slots - old, -1, np.int64)])
        self.last_used = np.concatenate([self.last_used, np.full(slots - old, -1, np.int64)])
        self.version += 1

    # -- use -------------------------------------------------------------------------------------------------
    def ensure(self, samples) -> np.ndarray:
        """(K,) int32 the slot holding each of ``samples``, completing those not held (least recently used slots
        first; never a slot asked for in the same call)."""
        samples = np.asarray(samples, np.int64).ravel()
        if len(samples) and (samples.min() < 0 or samples.max() >= self.S):
            raise LodprtError(f"light sample {int(samples.max())} does not exist (the store has {self.S})")
        self.clock += 1
        want = np.unique(samples)
        where = {int(k): int(s) for s, k in enumerate(self.slot_sample) if k >= 0}
        keep = np.array([where[k] for k in want.tolist() if k in where], np.int64)
        self.last_used[keep] = self.clock
        missing = [k for k in want.tolist() if k not in where]
        empty = int((self.slot_sample < 0).sum())
        cap = self._capacity(len(want))  # >= len(want): one frame's samples always fit
        if len(missing) > empty and self.slots < cap:  # grow (doubling) before replacing anything, up to the cap
            self._grow(min(cap, max(self.slots + len(missing) - empty, 2 * self.slots)))
        if missing and self.progress:  # before the first: a bar or a notice shows while it completes
            self.progress(0, len(missing))
        for i, k in enumerate(missing):
            free = np.flatnonzero(self.last_used != self.clock)
            s = int(free[np.argmin(self.last_used[free])])  # empty slots read -1: taken first
            self._load(s, k)
            where[k] = s
            self.last_used[s] = self.clock
            if self.progress:
                self.progress(i + 1, len(missing))
        return np.array([where[int(k)] for k in samples], np.int32)

    @contextlib.contextmanager
    def reporting(self, callback):
        """Within the block, ``callback(done, total)`` hears of the samples ``ensure`` completes too (after the
        cache's own ``progress``): (0, n) before the first of n, (i, n) after the i-th; the cache's ``progress`` is
        as it was afterwards."""
        held = self.progress

        def both(done, total):
            if held:
                held(done, total)
            callback(done, total)

        self.progress = both
        try:
            yield self
        finally:
            self.progress = held

    def _load(self, slot: int, sample: int) -> None:
        if self.slot_sample[slot] >= 0:
            log.debug("sample cache: slot %d: sample %d replaces %d", slot, sample, self.slot_sample[slot])
        if self.field is not None:  # no coefficients kept: the drawn field and visibility from one set of rays
            vis, f = self.field(sample)
        else:
            vis, f = None, self.store.complete(sample, dtype=np.float32)  # T-15, in float32 throughout
        for arr, make in self.derived.values():  # per-node bounds from the field drawn with the light on the sample
            arr[:, slot] = make(f)
        if self.field is None:
            if self.split is not None:
                vis, f = self.split(sample, f)  # M-2: the slot holds R_j
            self.coeffs[:, slot] = f
        if self.split is not None:
            self.visibility[:, slot] = vis
        self.slot_sample[slot] = sample
        self.completed += 1
        self.version += 1

    def derive(self, name: str, make, rows: int, shape: tuple, dtype) -> np.ndarray:
        """The per-slot array ``name`` (rows, slots) + shape, made by ``make(coefficients (V, C, ncoef))`` for each
        sample held now and for every sample loaded later."""
        if name not in self.derived:
            arr = np.zeros((rows, self.slots) + tuple(shape), dtype)
            for s in np.flatnonzero(self.slot_sample >= 0):  # from S_j: completed afresh when slots hold R_j
                k = int(self.slot_sample[s])
                if self.field is not None:
                    arr[:, s] = make(self.field(k)[1])
                    continue
                c = self.coeffs[:, s] if self.split is None else self.store.complete(k, dtype=np.float32)
                arr[:, s] = make(c)
            self.derived[name] = (arr, make)
            self.version += 1
        return self.derived[name][0]


def default_white(store) -> float:
    """The radiance shown as white by default: the 99th percentile over every sample's baked vertices of the
    view-averaged radiance (y_0 term, brightest channel, the bake's intensity; DW-1, DW-2 of
    :mod:`lodprt.store.white`). The store's recorded ``default_white`` (written at bake time) when it has one: one
    attribute, no sample read. Otherwise (stores baked before the record) read one sample at a time from the store
    (the stored rows only: no completion, memory for one sample) and given to
    :func:`lodprt.runtime.frames.auto_white`, the same rule applied to one frame: the Runtime's fixed white, so
    that frames do not change brightness as the light moves."""
    from lodprt.runtime.frames import auto_white

    recorded = store.attrs.get(WHITE)
    if recorded is not None:
        if isinstance(recorded, bool) or not isinstance(recorded, (int, float)) or not 0 < recorded < float("inf"):
            raise StoreError(f"{store.path}: root attribute {WHITE} is {recorded!r}; expected a positive number "
                             "(bake the store again, or pass white=)")
        return float(recorded)
    scale = white_scale(store.intensity)
    parts = []
    for k in range(store.num_samples):
        _, c = store.sample(k)
        dc = view_average(c) * scale  # DW-1
        parts.append(dc[dc > 0])
    return auto_white(np.concatenate(parts) if parts else np.zeros(0))
