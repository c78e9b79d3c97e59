"""Progress bars on stderr for the long commands (bakes, run-time set-up)."""

from __future__ import annotations

import signal
import sys
import threading


def new_bar(**options):
    """A tqdm bar on stderr made with Ctrl-C held back until it exists: a SIGINT inside tqdm's constructor left a
    half-made bar whose finaliser printed a traceback at exit (the interrupted command must print one line only).
    In the main thread a SIGINT meanwhile is recorded, then handed to the previous handler once the bar is made."""
    from tqdm import tqdm

    if threading.current_thread() is not threading.main_thread():
        return tqdm(file=sys.stderr, **options)
    pending = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: pending.append(frame))
    try:
        bar = tqdm(file=sys.stderr, **options)
    finally:
        signal.signal(signal.SIGINT, previous)
    if pending:  # the Ctrl-C that came meanwhile, now that the bar is whole
        if callable(previous):
            previous(signal.SIGINT, pending[0])
        elif previous == signal.SIG_DFL:
            raise KeyboardInterrupt
    return bar


class ProgressBars:
    """tqdm bars on stderr, one per name, each made at its first report (when its total is known).

    ``with ProgressBars() as bars: bake(..., progress=bars.callback("bake", "sample"))``; the bars are closed on leaving.
    ``options`` go to every bar (``leave=False``: transient bars, gone once closed).
    """

    def __init__(self, **options):
        self._bars = {}
        self._options = options

    def callback(self, name: str, unit: str):
        """A ``progress(done, total)`` callback that advances the bar ``name`` counting ``unit``."""

        def update(done, total):
            if name not in self._bars:
                self._bars[name] = new_bar(total=total, unit=unit, desc=name, **self._options)
            self._bars[name].update(done - self._bars[name].n)

        return update

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def close(self) -> None:
        """Close every bar (a transient one leaves no line behind)."""
        for bar in self._bars.values():
            bar.close()


def with_progress(total: int, desc: str, unit: str, work):
    """``work(progress)`` with a transient bar of ``total`` steps on stderr, ``progress(done, total)`` advancing it."""
    bar = new_bar(total=total, unit=unit, desc=desc, leave=False)
    try:
        return work(lambda done, _total: bar.update(done - bar.n))
    finally:
        bar.close()


def transient_bar(desc: str, unit: str):
    """A ``progress(done, total)`` callback drawing a transient bar on stderr, made at its first report and closed
    once ``done`` reaches ``total`` (for work reported from inside a constructor, the viewer's opening)."""
    bars = ProgressBars(leave=False)
    advance = bars.callback(desc, unit)

    def update(done, total):
        advance(done, total)
        if done >= total:
            bars.close()

    return update


def set_lights_with_progress(source, lights, colors=None, *, desc: str = "completing light samples") -> None:
    """``source.set_lights(lights, colors)`` with a transient bar on stderr while it completes light samples
    (seconds each at millions of vertices, docs/SCALE.md), shown as the first one starts (the source's sample
    cache reports each, ``SampleCache.reporting``; a source without one sets its lights as it is)."""
    from lodprt.runtime.sources import reporting

    with ProgressBars(leave=False) as bars, reporting(source, bars.callback(desc, "sample")):
        source.set_lights(lights, colors)
