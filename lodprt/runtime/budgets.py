"""The frame's budgets (docs/RUNTIME.md, budgets): how the run time's error bound follows a triangle budget
(B-1) and a frame-time budget (B-2), after each frame.

    B-1   triangle budget T: bound x1.25 when the frame had more than T triangles, / 1.1 when under 0.8 T, else
          kept (the bound is steered toward the budget; the target_psnr's steering, E-4, is off). Past the
          steering's highest bound (8, B-2's cap) the bound rises on settled frames only (the cut made no move),
          x1.25 after a raise that took triangles off, by a squared step after one that took none, up to CEILING;
          when nothing past the last useful bound took triangles off, it goes back to that bound (this view's
          coarsest cut) and stays while the frames are over the budget. It used to grow without end, to inf
    B-2   frame-time budget F ms (Hoppe 1997's regulation of the frame rate, on the bound): after a frame in motion
          that made no estimate (E-1) and no pins (E-5), m = the mean of its time and the last such frame's; over F,
          the floor becomes 1.25 max(floor, bound), at most the steering's highest bound; under 0.8 F, floor / 1.1
          (0 once under the lowest). The bound is never under the floor: E-4's bound, a fixed bound (one set by
          ``set_error_bound`` too) and B-1's all give way to it, so the frames in motion are held near F where a
          coarser cut can do it, and E-3's estimate says what that costs

The time B-2 reads is the frame's own work (cut, triangulation, relighting), measured on the machine that runs it:
a frame that estimates its error (every 4 to 8 frames in motion) costs more, and no bound makes that cost less.
"""

from __future__ import annotations

from lodprt.runtime.settings import check_frame_ms, check_triangle_budget

#: B-1 and B-2's steps: up x1.25 when over the budget, down / 1.1 when under LOW of it
UP, DOWN, LOW = 1.25, 1.1, 0.8
#: B-1's bound never passes this (in units of white, far beyond any node's error: float32 stays finite)
CEILING = 1e30


def toward_budget(bound: float, triangles: int, budget: int, lowest: float, highest: float = float("inf")) -> float:
    """B-1 under the steering's top: the bound steered toward a triangle budget: x1.25 above it (from ``lowest`` at
    least, the lowest bound: x1.25 of 0 would stay 0; up to ``highest``, and a bound already over it is kept),
    /1.1 under 80% of it, else unchanged (``FrameBudgets`` searches past the top)."""
    if triangles > budget:
        return max(min(max(bound, lowest) * UP, highest), bound)
    if triangles < LOW * budget:
        return bound / DOWN
    return bound


class FrameBudgets:
    """B-1 and B-2 for one ``Runtime``: ``triangles`` (or None) and ``frame_ms`` (or None), checked; ``floor`` the
    bound B-2 keeps the frame at or over (0: none), ``smoothed`` B-2's last m (ms; None before the first timed
    frame). ``lowest`` and ``highest``: the range of bounds (the steering's, ``frame_error.BOUND_RANGE``)."""

    def __init__(self, triangles=None, frame_ms=None, *, lowest: float, highest: float):
        self.triangles = check_triangle_budget(triangles)
        self.frame_ms = check_frame_ms(frame_ms)
        self.lowest, self.highest = float(lowest), float(highest)
        self.floor = 0.0
        self.smoothed: float | None = None
        self.timed = False  # whether B-2 read the last frame's time
        self._last: float | None = None
        self._raised_at: int | None = None  # B-1: the triangles of the frame that last raised the bound
        self._useful: float | None = None  # B-1 past the top: the last bound whose raise took triangles off
        self._step = UP  # B-1 past the top: the next raise's factor
        self._stalled = False  # B-1: past the top, nothing took triangles off; held until the bound comes down

    def limit(self, bound: float) -> float:
        """The bound a frame uses: ``bound``, or B-2's floor when that is higher."""
        return max(float(bound), self.floor)

    def after_frame(self, bound: float, triangles: int, ms: float, timed: bool, settled: bool = True) -> float:
        """The bound for the next frame after one at ``bound`` with ``triangles`` that took ``ms`` (``timed``: in
        motion, without an estimate or pins; B-2 reads only those frames' times; ``settled``: the frame's cut
        made no move, so its triangles are the bound's, which B-1 past the top reads)."""
        if self.triangles is not None:
            bound = self._toward_triangles(bound, triangles, settled)
        self.timed = self.frame_ms is not None and bool(timed)
        if self.timed:  # B-2
            m = ms if self._last is None else 0.5 * (ms + self._last)
            self._last, self.smoothed = ms, m
            if m > self.frame_ms:
                self.floor = min(max(self.floor, bound) * UP, self.highest)
            elif m < LOW * self.frame_ms:
                self.floor = self.floor / DOWN if self.floor / DOWN >= self.lowest else 0.0
        return self.limit(bound)

    def _toward_triangles(self, bound: float, triangles: int, settled: bool) -> float:
        """B-1 after a frame of ``triangles`` at ``bound``. Under the steering's top: ``toward_budget``. Over the
        budget at or past the top, on a settled frame (the cut made no move: its triangles are the bound's), a
        search past the top: x1.25 after a raise that took triangles off, a step squared after one that took
        none (a gap between node errors), up to CEILING; when even CEILING took none off, the bound goes back to
        the last one that did (the same cut: this view's coarsest) and is held there until the bound comes down.
        A cut still moving toward the last raise would read as one that raising helps, so motion holds it."""
        new = toward_budget(bound, triangles, self.triangles, self.lowest, self.highest)
        if new < bound:
            self._raised_at, self._stalled, self._step, self._useful = None, False, UP, None
            return new
        if triangles <= self.triangles or new < self.highest or not settled or self._stalled:
            if new > bound:
                self._raised_at = triangles
            return new
        if self._raised_at is None or triangles < self._raised_at or self._useful is None:
            self._useful, self._step = bound, UP  # the last raise took triangles off (or none was made yet)
        else:
            self._step *= self._step
        if bound >= CEILING:
            self._stalled = True
            return self._useful
        self._raised_at = triangles
        return min(bound * self._step, CEILING)

    def settings(self) -> dict:
        """The budgets and B-2's state, for a frame's stats."""
        return {"triangle_budget": self.triangles, "frame_ms_budget": self.frame_ms,
                "bound_floor": self.floor if self.frame_ms is not None else None, "budget_timed": self.timed}
