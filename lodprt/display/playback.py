"""A camera path played in the viewer (``lodprt view --path orbit|dolly``): each frame takes the next camera and light
of ``lodprt.runtime.camera.camera_path``, the path `lodprt frames` and ``benchmarks/runtime.py`` time, looping; what
each frame cost is kept for the summary ``lodprt view`` prints when it closes."""

from __future__ import annotations

import dataclasses
import statistics


class PathPlayer:
    """The ``frames`` (Camera, lights) of ``camera_path(source, path, frames)``, played in order and looped.
    ``fixed_lights``: the lights stay where the user put them (``--light``), only the camera moves, as in
    ``lodprt frames --light``. Paused, the window's controls take over; ``toggle`` resumes where it stopped."""

    def __init__(self, source, path: str, frames: int, *, camera, fixed_lights: bool = False):
        from lodprt.runtime.camera import camera_path

        self.path = path
        self.steps = list(camera_path(source, path, frames, size=(camera.width, camera.height), fov=camera.fov))
        self.fixed_lights = fixed_lights
        self.index = 0
        self.paused = False
        self.played: list[dict] = []  # one record per frame made on the path (``record``)

    def advance(self, state) -> bool:
        """Put the path's next camera (at the window's current size) and lights into the viewer's ``state``;
        False (and nothing changed) while paused."""
        if self.paused:
            return False
        cam, lights = self.steps[self.index % len(self.steps)]
        self.index += 1
        state.camera = dataclasses.replace(cam, width=state.camera.width, height=state.camera.height)
        if not self.fixed_lights:
            state.lights = lights.astype("float64")  # a copy: the state's own
            state.selected = 0
        state.dirty = True
        return True

    def status(self) -> str:
        """The overlay's line: the path, the frame of its lap last played, playing or paused."""
        lap = len(self.steps)
        return (f"path {self.path}, frame {(max(self.index, 1) - 1) % lap + 1} of {lap}"
                + (" (paused: P plays)" if self.paused else " (P pauses)"))

    def toggle(self) -> None:
        self.paused = not self.paused

    def pause(self) -> None:
        """Stop where the path is (the user took the camera or a light); ``toggle`` plays on from there."""
        self.paused = True

    def record(self, ms_lights: float, ms_update: float, ms_draw: float, completed: int) -> None:
        """What the frame just made on the path cost: setting its lights (the light samples they completed,
        ``completed`` of them), the run time's update after it, drawing."""
        self.played.append({"ms_lights": ms_lights, "ms_update": ms_update, "ms_draw": ms_draw,
                            "samples_completed": completed})

    def summary(self) -> dict:
        """The frames played: their count, the median update and draw after the first frame (as ``lodprt frames``
        reports them), the light samples completed and the seconds they took, the longest such wait."""
        rows = self.played
        if not rows:
            return {"path": self.path, "frames": 0}
        later = rows[1:]  # none after a path of one frame: no median (the first frame's was given as one)
        median = (lambda key: float(statistics.median(r[key] for r in later))) if later else (lambda key: None)
        return {"path": self.path, "frames": len(rows), "first_frame_ms": rows[0]["ms_update"],
                "median_ms_update": median("ms_update"), "median_ms_draw": median("ms_draw"), **light_costs(rows)}


def light_costs(rows) -> dict:
    """What setting the lights cost along a path, from its frames' records (each with ``samples_completed`` and
    ``ms_lights``): the light samples completed, their seconds in all and the longest frame's wait in ms (the same
    keys in ``lodprt frames``' summary and ``lodprt view``'s)."""
    return {"samples_completed": int(sum(r["samples_completed"] for r in rows)),
            "lights_seconds": 1e-3 * float(sum(r["ms_lights"] for r in rows)),
            "max_ms_lights": float(max(r["ms_lights"] for r in rows))}


def summary_line(summary: dict) -> str:
    """``summary`` as the line ``lodprt view`` prints when it closes."""
    if not summary["frames"]:
        return f"path {summary['path']}: no frame played"
    times = (f"median update {summary['median_ms_update']:.0f} ms and draw {summary['median_ms_draw']:.0f} ms after "
             f"the first ({summary['first_frame_ms']:.0f} ms)" if summary["median_ms_update"] is not None else
             f"first frame {summary['first_frame_ms']:.0f} ms, no frame after it to time")
    n = summary["frames"]
    return (f"path {summary['path']}: {n} frame{'s' if n != 1 else ''}, {times}; "
            f"setting the lights completed {summary['samples_completed']} light samples in "
            f"{summary['lights_seconds']:.1f} s (longest frame's {summary['max_ms_lights'] / 1e3:.1f} s)")
