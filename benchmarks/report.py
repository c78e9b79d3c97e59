"""Regenerate, or check, every table in README.md and docs/*.md that quotes a benchmark's results file.

    python benchmarks/report.py                         # rewrite the tables between the markers
    python benchmarks/report.py --check                 # tables match the JSON, and the JSON matches the code
    python benchmarks/report.py --check --tables-only   # only: each table is what its results file renders
    python benchmarks/report.py --check --stale-only    # only: each quoted results file measured the current code

A generated table stands between ``<!-- report:NAME -->`` and ``<!-- /report:NAME -->``; NAME is a key of
``report_tables.TABLES``, which names the results file (``benchmarks/results/<file>.json``, the full run, never the
``-quick`` one) and the function that renders it. Everything between the markers is replaced.

``--check`` exits 1 and names each table that differs from what its results file renders, and each results file
whose ``code_fingerprint`` (written by ``common.write``; ``fingerprint.py``) differs from the current code's, with
the files that changed and the command that re-measures it. The tests run ``--check --tables-only`` (the
fingerprints change with every code change during development); the full ``--check`` is the release check, after
``python benchmarks/run_all.py`` has re-measured everything on the final code.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

from fingerprint import REPO, code_fingerprint
from report_tables import TABLES

#: A marker stands alone on its line (a marker quoted in prose, in backticks, is not one).
BLOCK = re.compile(r"^<!-- report:(?P<name>[\w-]+) -->\n(?P<body>.*?)\n?^<!-- /report:(?P=name) -->$", re.S | re.M)
OPEN = re.compile(r"^<!-- report:([\w-]+) -->$", re.M)


def markdown_files(root: Path = REPO) -> list[Path]:
    return [root / "README.md", *sorted((root / "docs").glob("*.md"))]


def blocks(text: str) -> list[tuple[str, str]]:
    """(name, body) of every generated block in ``text``; raises ValueError on an opening marker without its close."""
    found = [(m["name"], m["body"]) for m in BLOCK.finditer(text)]
    opened = OPEN.findall(text)
    if sorted(opened) != sorted(name for name, _ in found):
        unclosed = sorted(set(opened) - {name for name, _ in found}) or opened
        raise ValueError(f"marker <!-- report:{unclosed[0]} --> has no matching <!-- /report:{unclosed[0]} -->")
    return found


def replace_blocks(text: str, render) -> str:
    """``text`` with the body of every block NAME replaced by ``render(NAME)`` (the markers stay)."""
    blocks(text)
    return BLOCK.sub(lambda m: f"<!-- report:{m['name']} -->\n{render(m['name']).rstrip()}\n<!-- /report:{m['name']} -->",
                     text)


def results_path(stem: str, results: Path) -> Path:
    return results / f"{stem}.json"


def load_results(stem: str, results: Path) -> dict:
    path = results_path(stem, results)
    if not path.is_file():
        raise FileNotFoundError(f"results file {path.name} is missing: run python benchmarks/{stem}.py")
    return json.loads(path.read_text())


def render_table(name: str, results: Path) -> str:
    if name not in TABLES:
        raise KeyError(f"unknown table {name!r} (a marker names a key of report_tables.TABLES)")
    stem, fn = TABLES[name]
    return fn(load_results(stem, results))


def table_problems(files: list[Path], results: Path) -> list[str]:
    """One line per table that differs from what its results file renders (or cannot be rendered)."""
    out = []
    for md in files:
        text = md.read_text()
        try:
            found = blocks(text)
        except ValueError as e:
            out.append(f"{md.name}: {e}")
            continue
        for name, body in found:
            try:
                want = render_table(name, results)
            except (KeyError, FileNotFoundError) as e:
                out.append(f"{md.name}: table {name}: {e.args[0]}")
                continue
            if body.strip() != want.strip():
                out.append(f"{md.name}: table {name} differs from what {TABLES[name][0]}.json renders: "
                           f"run python benchmarks/report.py")
    return out


def stale_problems(files: list[Path], results: Path, root: Path = REPO) -> list[str]:
    """One line per results file a table quotes whose code fingerprint is not the current code's."""
    stems = sorted({TABLES[name][0] for md in files for name, _ in blocks(md.read_text()) if name in TABLES})
    out = []
    for stem in stems:
        try:
            r = load_results(stem, results)
        except FileNotFoundError as e:
            out.append(str(e))
            continue
        script = root / "benchmarks" / f"{r.get('benchmark', stem)}.py"
        rerun = f"run python benchmarks/{script.name}"
        if "code_fingerprint" not in r:
            out.append(f"results file {stem}.json records no code fingerprint (measured before they were kept): {rerun}")
            continue
        now, hashes = code_fingerprint(script, root)
        if now != r["code_fingerprint"]:
            old = r.get("code_files", {})
            changed = sorted(k for k in set(old) | set(hashes) if old.get(k) != hashes.get(k))
            shown = ", ".join(changed[:6]) + (f" and {len(changed) - 6} more" if len(changed) > 6 else "")
            out.append(f"results file {stem}.json is older than the code it measures ({shown}): {rerun}")
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--check", action="store_true", help="change nothing; exit 1 when a table or results file is stale")
    p.add_argument("--tables-only", action="store_true", help="with --check: only compare the tables with the JSON")
    p.add_argument("--stale-only", action="store_true", help="with --check: only compare the JSON with the code")
    p.add_argument("--results", type=Path, default=REPO / "benchmarks" / "results", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    files = markdown_files()
    if not args.check:
        changed = []
        for md in files:
            text = md.read_text()
            new = replace_blocks(text, lambda name: render_table(name, args.results))
            if new != text:
                md.write_text(new)
                changed.append(md.relative_to(REPO).as_posix())
        print("rewrote " + ", ".join(changed) if changed else "every table already matches its results file")
        return 0
    problems = []
    if not args.stale_only:
        tables = table_problems(files, args.results)
        print(f"tables: {len(tables)} differ from their results files" if tables else "tables: all match the JSON")
        problems += tables
    if not args.tables_only:
        stale = stale_problems(files, args.results)
        print(f"results: {len(stale)} older than the code" if stale else "results: all measured the current code")
        problems += stale
    for line in problems:
        print("  " + line)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
