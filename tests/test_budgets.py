"""The frame's budgets (``lodprt.runtime.budgets``): B-1's triangle budget and B-2's frame-time budget, as laws on
given numbers and on a Runtime along a camera path."""

import json

import numpy as np
import pytest

from lodprt.errors import LodprtError
from lodprt.runtime.budgets import CEILING, DOWN, UP, FrameBudgets, toward_budget
from lodprt.runtime.settings import check_frame_ms
from lodprt.runtime.camera import camera_path
from lodprt.runtime.frame_error import BOUND_RANGE
from lodprt.runtime.session import Runtime
from lodprt.store.bake_store import open_store


@pytest.fixture(scope="module")
def store(bunny_bake):
    return open_store(bunny_bake)


def test_triangle_budget_law():
    """B-1: x1.25 over the budget, / 1.1 under 80% of it, kept between (and a bound of 0 can still rise)."""
    low = BOUND_RANGE[0]
    assert toward_budget(0.5, 1001, 1000, low) == pytest.approx(0.5 * UP)
    assert toward_budget(0.0, 1001, 1000, low) == pytest.approx(low * UP)
    assert toward_budget(0.5, 799, 1000, low) == pytest.approx(0.5 / DOWN)
    assert toward_budget(0.5, 800, 1000, low) == 0.5 and toward_budget(0.5, 1000, 1000, low) == 0.5


def test_triangle_budget_under_the_coarsest_cut_holds_the_bound_at_the_top():
    """B-1 over a budget no cut meets rises to the steering's highest bound and stays there (it grew x1.25 a frame
    without end: inf after about 3,200 frames, and then an error); a bound already over the top is kept."""
    low, high = BOUND_RANGE
    b = 0.5
    for _ in range(400):
        b = toward_budget(b, 10**6, 1, low, high)
    assert b == high
    assert toward_budget(20.0, 10**6, 1, low, high) == 20.0


def test_past_the_top_only_on_settled_frames_while_raises_remove_triangles():
    """B-1 past the steering's highest bound, step by step against the law: on settled frames only, x1.25 after a
    raise that took triangles off, a squared step after one that took none, up to CEILING; then back to the last
    bound that took triangles off, held there over the budget; a frame under 0.8 of it brings the bound down."""
    low, high = BOUND_RANGE
    b = FrameBudgets(triangles=3000, lowest=low, highest=high)
    after = lambda bound, tri, settled=True: b.after_frame(bound, tri, 1.0, timed=False, settled=settled)
    assert after(high, 5000, settled=False) == high  # the cut still moves: held at the top
    assert after(high, 5000) == pytest.approx(high * UP)  # settled, no raise yet: a first try past it
    assert after(high * UP, 4000) == pytest.approx(high * UP**2)  # the try took 1,000 off: on, x1.25
    assert after(high * UP**2, 4000) == pytest.approx(high * UP**4)  # took none off: the step squared
    assert after(high * UP**4, 3900) == pytest.approx(high * UP**5)  # took some off: x1.25 again
    bound = high * UP**5
    while bound < CEILING:  # the coarsest cut: every raise up to CEILING takes none off
        nxt = after(bound, 3900)
        assert bound < nxt <= CEILING
        bound = nxt
    assert after(bound, 3900) == pytest.approx(high * UP**4)  # back to the last bound that took some off
    assert after(high * UP**4, 3900) == pytest.approx(high * UP**4)  # and held there
    assert after(high * UP**4, 2000) == pytest.approx(high * UP**4 / DOWN)  # under 0.8 x 3,000: down
    assert after(high * UP**4 / DOWN, 3500) == pytest.approx(high * UP**5 / DOWN)  # the search may start again


def _settled_triangles(store, bound: float) -> int:
    """The triangles of the cut at a fixed ``bound`` (no target) once it made no move, at the tests' still view."""
    rt = Runtime(store, device="cpu", error_bound=bound, target_psnr=None)
    rt.set_camera(eye=(0.3, 1.0, 1.8), width=64, height=48)
    for _ in range(400):
        f = rt.update()
        if f.stats["refined"] == f.stats["coarsened"] == 0:
            return f.stats["triangles"]
    raise AssertionError(f"the cut at bound {bound} did not settle")


def test_unreachable_triangle_budget_on_a_runtime(store):
    """A Runtime with triangle_budget=1 (every cut has more) on a still camera: the bound ends finite (it grew
    x1.25 a frame without end) and the cut is this view's coarsest: that of a bound no node's error reaches."""
    rt = Runtime(store, device="cpu", triangle_budget=1)
    rt.set_camera(eye=(0.3, 1.0, 1.8), width=64, height=48)
    for _ in range(400):
        frame = rt.update()
    assert BOUND_RANGE[1] < rt.error_bound < CEILING
    assert frame.stats["triangles"] == _settled_triangles(store, CEILING)


def test_a_budget_under_the_top_bounds_cut_is_met(store):
    """A budget between the coarsest cut and the cut of the steering's highest bound (8; it was missed by that
    margin, held at 8): B-1 searches past 8 and the count settles at or under the budget."""
    top, least = _settled_triangles(store, BOUND_RANGE[1]), _settled_triangles(store, CEILING)
    assert least < top
    budget = (top + least) // 2
    rt = Runtime(store, device="cpu", error_bound=0.01, triangle_budget=budget)
    rt.set_camera(eye=(0.3, 1.0, 1.8), width=64, height=48)
    counts = [rt.update().stats["triangles"] for _ in range(400)]
    assert counts[0] > budget and counts[-1] <= budget and rt.error_bound > BOUND_RANGE[1]


def test_frame_time_floor_law():
    """B-2 step by step against the law written out: m the mean of this timed frame and the last, the floor
    1.25 max(floor, bound) over the budget (capped at the highest bound), / 1.1 under 80% of it, 0 once under
    the lowest; untimed frames change nothing; the bound is never under the floor."""
    b = FrameBudgets(frame_ms=10.0, lowest=0.01, highest=2.0)
    assert b.after_frame(0.5, 100, 30.0, timed=False) == 0.5 and b.floor == 0.0 and b.smoothed is None
    assert b.after_frame(0.5, 100, 30.0, timed=True) == pytest.approx(0.625)  # m = 30 > 10
    assert b.floor == pytest.approx(0.625) and b.smoothed == 30.0
    assert b.after_frame(0.3, 100, 12.0, timed=True) == pytest.approx(0.625 * UP)  # m = 21; the floor, not 0.3
    assert b.after_frame(1.0, 100, 9.0, timed=True) == pytest.approx(1.25)  # m = 10.5 > 10: 1.25 max(0.78, 1)
    assert b.floor == pytest.approx(1.25)
    for _ in range(5):
        b.after_frame(1.9, 100, 50.0, timed=True)
    assert b.floor == 2.0  # capped at the highest bound
    assert b.after_frame(0.1, 100, 500.0, timed=False) == 2.0 and b.floor == 2.0  # untimed: unchanged
    b.after_frame(0.1, 100, 7.0, timed=True)  # m = (50 + 7) / 2 = 28.5: over, stays at the cap
    assert b.floor == 2.0
    b.after_frame(0.1, 100, 7.0, timed=True)  # m = 7 < 8: down
    assert b.floor == pytest.approx(2.0 / DOWN) and b.limit(0.1) == pytest.approx(2.0 / DOWN)
    assert b.limit(3.0) == 3.0
    floors = []
    for _ in range(80):
        b.after_frame(0.1, 100, 1.0, timed=True)
        floors.append(b.floor)
    assert all(a >= c for a, c in zip(floors, floors[1:])) and floors[-1] == 0.0  # falls, then none
    assert min(f for f in floors if f > 0) >= 0.01


@pytest.mark.parametrize("bad", [0, -1, float("nan"), float("inf"), "fast", 2e6])
def test_bad_frame_budget_names_the_field(store, bad):
    with pytest.raises(LodprtError, match="frame_ms"):
        check_frame_ms(bad)
    with pytest.raises(LodprtError, match="frame_ms"):
        Runtime(store, device="cpu", frame_ms=bad)


def test_bad_triangle_budget_names_the_field(store):
    with pytest.raises(LodprtError, match="triangle_budget"):
        Runtime(store, device="cpu", triangle_budget=0)
    with pytest.raises(LodprtError, match="triangle_budget"):
        FrameBudgets(triangles="many", lowest=BOUND_RANGE[0], highest=BOUND_RANGE[1])


def _orbit(rt, frames: int) -> list:
    out = []
    for cam, lights in camera_path(rt, "orbit", frames, size=(320, 240)):
        rt.set_camera(cam)
        rt.set_lights(lights)
        out.append(rt.update())
    return out


def test_a_budget_never_exceeded_changes_no_frame(store):
    """A budget no frame comes near leaves B-2's floor at 0: the frames are those of a Runtime without one,
    triangle for triangle and value for value."""
    plain = _orbit(Runtime(store, device="cpu"), 14)
    rt = Runtime(store, device="cpu", frame_ms=1e6)
    budgeted = _orbit(rt, 14)
    for a, b in zip(plain, budgeted):
        assert b.stats["bound_floor"] == 0.0 and b.stats["frame_ms_budget"] == 1e6
        assert a.stats["error_bound"] == b.stats["error_bound"]
        np.testing.assert_array_equal(a.triangles, b.triangles)
        np.testing.assert_array_equal(a.radiance, b.radiance)


def test_a_budget_always_missed_coarsens_to_the_highest_bound(store):
    """A budget every frame misses raises the floor x1.25 a timed frame up to the steering's highest bound; the
    bound follows it whatever E-4 steers toward, the cut ends coarser than without the budget, and the frames
    still report E-3's estimate of what that costs."""
    plain = _orbit(Runtime(store, device="cpu"), 40)
    rt = Runtime(store, device="cpu", frame_ms=1e-3)
    frames = _orbit(rt, 40)
    floors = [f.stats["bound_floor"] for f in frames]
    assert floors[0] == 0.0  # the first frame converges from the base, untimed
    assert all(a <= c for a, c in zip(floors, floors[1:]))
    rising = [c / a for a, c in zip(floors, floors[1:]) if a > 0 and c < BOUND_RANGE[1]]
    assert all(r >= UP * (1 - 1e-9) or r == 1.0 for r in rising)
    assert floors[-1] == BOUND_RANGE[1] and rt.error_bound == BOUND_RANGE[1]
    assert all(f.stats["error_bound"] >= f.stats["bound_floor"] for f in frames[1:])
    assert frames[-1].stats["triangles"] < plain[-1].stats["triangles"]
    assert rt.estimated_psnr is not None and np.isfinite(rt.estimated_psnr)


def test_a_bound_set_under_the_floor_gives_way_to_it(store):
    """B-2: a bound set by set_error_bound under the floor is the floor, as every bound is: the bound the frame's
    cut converges to is the one its stats report (it used to draw the set bound and report the floor)."""
    rt = Runtime(store, device="cpu", error_bound=0.05, frame_ms=1e-3)  # every timed frame misses the budget
    _orbit(rt, 5)
    floor = rt.budgets.floor
    assert floor > 0.05
    rt.set_error_bound(floor / 100)
    assert rt.error_bound == floor
    used, converge = [], rt.refinement.converge
    rt.refinement.converge = lambda errors, evaluate, bound, *a, **kw: used.append(bound) or converge(
        errors, evaluate, bound, *a, **kw)
    frame = rt.update()
    assert used and set(used) == {floor}
    assert frame.stats["error_bound"] == max(floor, frame.stats["bound_floor"])
    plain = Runtime(store, device="cpu", error_bound=0.05)  # no budget: no floor, the set bound kept
    plain.set_error_bound(0.001)
    assert plain.error_bound == 0.001


def test_cli_frames_takes_a_frame_budget(bunny_bake, capsys):
    """`lodprt frames --frame-ms` reports the budget and the floor per frame; a bad budget is a one-line error."""
    from lodprt.cli.main import main

    assert main(["frames", str(bunny_bake), "--frames", "12", "--frame-ms", "0.001", "--size", "160", "120",
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["summary"]["frame_ms_budget"] == 0.001
    assert doc["frames"][0]["bound_floor"] == 0.0 and doc["frames"][-1]["bound_floor"] > 0
    assert main(["frames", str(bunny_bake), "--frames", "2", "--frame-ms", "-1"]) == 2
    assert "error: --frame-ms -1.0: must be a frame time in milliseconds" in capsys.readouterr().err
