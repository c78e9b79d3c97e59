"""Progress bars on stderr for the long commands (bakes, run-time set-up)."""

from __future__ import annotations

import sys


class ProgressBars:
    """tqdm bars on stderr, one per name, each made at its first report (when its total is known).

    ``with ProgressBars() as bars: bake(..., progress=bars.callback("bake", "sample"))``; the bars are closed on leaving.
    """

    def __init__(self):
        self._bars = {}

    def callback(self, name: str, unit: str):
        """A ``progress(done, total)`` callback that advances the bar ``name`` counting ``unit``."""

        def update(done, total):
            if name not in self._bars:
                from tqdm import tqdm

                self._bars[name] = tqdm(total=total, unit=unit, desc=name, file=sys.stderr)
            self._bars[name].update(done - self._bars[name].n)

        return update

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        for bar in self._bars.values():
            bar.close()
        return False


def with_progress(total: int, desc: str, unit: str, work):
    """``work(progress)`` with a transient bar of ``total`` steps on stderr, ``progress(done, total)`` advancing it."""
    from tqdm import tqdm

    bar = tqdm(total=total, unit=unit, desc=desc, file=sys.stderr, leave=False)
    try:
        return work(lambda done, _total: bar.update(done - bar.n))
    finally:
        bar.close()
