"""Re-measure every benchmark, then regenerate the tables of README.md and docs/*.md from the results.

    python benchmarks/run_all.py [--quick] [--device cpu|cuda] [--only NAME ...]

Runs each benchmark script in turn (in a fresh process, from the benchmarks folder), stops at the first one that
fails with its name, exit status and the command that reproduces it, prints the time each took, then runs
``report.py`` (and, after a full run, ``report.py --check``). ``--quick`` writes the ``-quick`` results, which no
table quotes, so the tables stay as they are; the full run (no ``--quick``) is what a release needs (the full
benchmarks take well over an hour on a 2-core CPU).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: Every benchmark, in the order they run (cheap ones first, so a broken script fails early).
BENCHMARKS = ["visibility", "bake", "table1", "light_spacing", "hierarchy", "environment", "volume", "neighbourhood",
              "view_cut", "runtime", "render", "compression", "moving_lights", "gi", "scale",
              "bake_memory", "ten_million"]
#: Arguments of the full runs the docs quote (not passed with --quick). gi.py --mitsuba needs Mitsuba 3
#: (pip install '.[reference]'): the gi_mitsuba table quotes that part of gi.json.
FULL_ARGS = {"view_cut": ["--frames", "48"], "gi": ["--mitsuba"], "moving_lights": ["--mitsuba"]}


def command(script: str, extra: list[str], quick: bool) -> list[str]:
    return [sys.executable, str(HERE / f"{script}.py"), *extra, *([] if quick else FULL_ARGS.get(script, []))]


def run(cmd: list[str]) -> tuple[int, float]:
    t = time.perf_counter()
    rc = subprocess.run(cmd, cwd=HERE).returncode
    return rc, time.perf_counter() - t


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="the small versions (seconds each; CI smoke test)")
    p.add_argument("--device", default=None, help="Warp device passed to every benchmark")
    p.add_argument("--only", nargs="+", metavar="NAME", choices=BENCHMARKS, help="run only these benchmarks")
    args = p.parse_args(argv)
    extra = (["--quick"] if args.quick else []) + (["--device", args.device] if args.device else [])
    times = []
    for name in args.only or BENCHMARKS:
        cmd = command(name, extra, args.quick)
        shown = " ".join([f"python benchmarks/{name}.py", *cmd[2:]])
        print(f"=== {shown}", flush=True)
        rc, seconds = run(cmd)
        times.append((name, seconds))
        if rc != 0:
            print(f"run_all: {name}.py failed (exit status {rc}) after {seconds:.0f} s; reproduce with: {shown}",
                  file=sys.stderr)
            summary(times)
            return rc
    summary(times)
    rc = subprocess.run([sys.executable, str(HERE / "report.py")], cwd=HERE).returncode
    if rc == 0 and not args.quick and not args.only:
        rc = subprocess.run([sys.executable, str(HERE / "report.py"), "--check"], cwd=HERE).returncode
    return rc


def summary(times: list[tuple[str, float]]) -> None:
    print("\nbenchmark        seconds")
    for name, seconds in times:
        print(f"{name:<16} {seconds:7.1f}")
    print(f"{'total':<16} {sum(s for _, s in times):7.1f}", flush=True)


if __name__ == "__main__":
    sys.exit(main())
