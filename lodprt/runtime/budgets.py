"""The frame's budgets (docs/RUNTIME.md, budgets): how the run time's error bound follows a triangle budget
(B-1) and a frame-time budget (B-2), after each frame.

    B-1   triangle budget T: bound x1.25 when the frame had more than T triangles (up to the steering's highest
          bound, 8, as B-2's floor: a budget under the triangles of that bound's cut holds the bound there and is
          missed by that margin; it used to grow without end, to inf), / 1.1 when under 0.8 T, else kept (the
          bound is steered toward the budget; the target_psnr's steering, E-4, is off)
    B-2   frame-time budget F ms (Hoppe 1997's regulation of the frame rate, on the bound): after a frame in motion
          that made no estimate (E-1) and no pins (E-5), m = the mean of its time and the last such frame's; over F,
          the floor becomes 1.25 max(floor, bound), at most the steering's highest bound; under 0.8 F, floor / 1.1
          (0 once under the lowest). The bound is never under the floor: E-4's bound, a fixed bound and B-1's all
          give way to it, so the frames in motion are held near F where a coarser cut can do it, and E-3's estimate
          says what that costs

The time B-2 reads is the frame's own work (cut, triangulation, relighting), measured on the machine that runs it:
a frame that estimates its error (every 4 to 8 frames in motion) costs more, and no bound makes that cost less.
"""

from __future__ import annotations

from lodprt.runtime.settings import check_frame_ms, check_triangle_budget

#: B-1 and B-2's steps: up x1.25 when over the budget, down / 1.1 when under LOW of it
UP, DOWN, LOW = 1.25, 1.1, 0.8


def toward_budget(bound: float, triangles: int, budget: int, lowest: float, highest: float = float("inf")) -> float:
    """B-1: the bound steered toward a triangle budget: x1.25 above it (from ``lowest`` at least, the lowest
    bound: x1.25 of 0 would stay 0; up to ``highest``, and a bound already over it is kept), /1.1 under 80% of it,
    else unchanged."""
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

    def limit(self, bound: float) -> float:
        """The bound a frame uses: ``bound``, or B-2's floor when that is higher."""
        return max(float(bound), self.floor)

    def after_frame(self, bound: float, triangles: int, ms: float, timed: bool) -> float:
        """The bound for the next frame after one at ``bound`` with ``triangles`` that took ``ms`` (``timed``: in
        motion, without an estimate or pins; B-2 reads only those frames' times)."""
        if self.triangles is not None:
            bound = toward_budget(bound, triangles, self.triangles, self.lowest, self.highest)  # B-1
        self.timed = self.frame_ms is not None and bool(timed)
        if self.timed:  # B-2
            m = ms if self._last is None else 0.5 * (ms + self._last)
            self._last, self.smoothed = ms, m
            if m > self.frame_ms:
                self.floor = min(max(self.floor, bound) * UP, self.highest)
            elif m < LOW * self.frame_ms:
                self.floor = self.floor / DOWN if self.floor / DOWN >= self.lowest else 0.0
        return self.limit(bound)

    def settings(self) -> dict:
        """The budgets and B-2's state, for a frame's stats."""
        return {"triangle_budget": self.triangles, "frame_ms_budget": self.frame_ms,
                "bound_floor": self.floor if self.frame_ms is not None else None, "budget_timed": self.timed}
