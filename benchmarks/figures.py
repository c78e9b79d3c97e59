"""Regenerate every picture in docs/ that a command makes, by running the command the docs show next to it.

    python benchmarks/figures.py                 # every figure
    python benchmarks/figures.py --only display  # one (names: the keys of FIGURES)

``display`` (docs/display.png, shown in README.md and docs/DISPLAY.md): the first ```bash block of docs/DISPLAY.md,
run as it stands with bash in a scratch folder where ``tests`` and ``docs`` point at the repository's, so its
``-o docs/display.png --overwrite`` replaces the committed picture and its store stays in the scratch folder.

``environment`` (docs/environment.png): the scene and the two commands the paragraph under the picture in
docs/ENVIRONMENT.md names (``ENVIRONMENT_STEPS``; each must appear there word for word, so the two cannot drift
apart), in a scratch folder; the three frames it writes (turn_0000.png ... turn_0002.png) side by side are
docs/environment.png.

``lodprt`` is the one beside this Python (the project's virtual environment). Times on the shared 2-core CPU: about
40 s for display (bake 11 s, compare 25 s) and 60 s for environment (its bake 55 s).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
DOCS = REPO / "docs"

ENVIRONMENT_SCENE = '[[object]]\nmesh = "tests/data/stanford-bunny.obj.xz"\n[floor]\nresolution = 80\n'
ENVIRONMENT_STEPS = [
    "lodprt bake-environment bunny.toml -o bunny_floor.zarr --environment spots --rays 256 --bounces 2",
    "lodprt render-environment bunny_floor.zarr --frames 3 --eye 0 0.22 0.42 --target 0 0.09 0 --size 360 270 "
    "--white 7 -o turn.png",
]


def first_bash_block(markdown: Path) -> str:
    """The body of the first ```bash fenced block of ``markdown``."""
    found = re.search(r"^```bash\n(.*?)^```$", markdown.read_text(), re.S | re.M)
    if found is None:
        raise SystemExit(f"{markdown.relative_to(REPO)}: no ```bash block")
    return found.group(1)


def scratch(folder: Path) -> Path:
    """``folder`` with ``tests`` and ``docs`` linked to the repository's (the documented commands' relative paths)."""
    for name in ("tests", "docs"):
        (folder / name).symlink_to(REPO / name, target_is_directory=True)
    return folder


def run_bash(script: str, cwd: Path) -> None:
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    print(script.rstrip(), flush=True)
    subprocess.run(["bash", "-euo", "pipefail", "-c", script], cwd=cwd, env=env, check=True)


def display(folder: Path) -> Path:
    run_bash(first_bash_block(DOCS / "DISPLAY.md"), scratch(folder))
    return DOCS / "display.png"


def environment(folder: Path) -> Path:
    prose = " ".join((DOCS / "ENVIRONMENT.md").read_text().replace("`", "").split())
    for step in [*ENVIRONMENT_STEPS, "resolution = 80"]:
        if step not in prose:
            raise SystemExit(f"docs/ENVIRONMENT.md no longer shows: {step}")
    (scratch(folder) / "bunny.toml").write_text(ENVIRONMENT_SCENE)
    run_bash("\n".join(ENVIRONMENT_STEPS) + "\n", folder)
    from PIL import Image

    frames = [np.asarray(Image.open(folder / f"turn_{k:04d}.png")) for k in range(3)]
    Image.fromarray(np.concatenate(frames, axis=1)).save(DOCS / "environment.png")
    return DOCS / "environment.png"


FIGURES = {"display": display, "environment": environment}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", choices=sorted(FIGURES), action="append", help="regenerate only this figure")
    args = ap.parse_args(argv)
    for name in args.only or list(FIGURES):
        t0 = time.perf_counter()
        with tempfile.TemporaryDirectory(prefix=f"lodprt-figure-{name}-") as tmp:
            out = FIGURES[name](Path(tmp))
        print(f"{name}: wrote {out.relative_to(REPO)} in {time.perf_counter() - t0:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
