"""The code fingerprint of a benchmark: a hash of the source files it measures.

A benchmark script measures the lodprt (and ``lodprt.kernels``) modules it imports, directly or through other
modules, and its own helper scripts in ``benchmarks/`` (``common.py``, ``table1.py``, ...). The files are found by
reading the imports (every ``import`` statement, function-level ones included, the code of string constants a
script runs in a child process, e.g. ``python -c BAKE_CHILD``, and the modules it runs as programs, e.g.
``[sys.executable, "-m", "lodprt", "frames", ...]``: ``lodprt.__main__``, so the whole command line), not by
running anything, so the fingerprint is a
function of the source tree alone: a docs edit (docstrings and comments included), a test or a module the benchmark
never imports does not change it.
The package's ``__init__`` modules on the way to an imported module count (they run on import). This file and the
report scripts do not count: they measure nothing.
"""

from __future__ import annotations

import ast
import hashlib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: Python package -> source folder (pyproject.toml's package-dir: lodprt.kernels lives in kernels/).
PACKAGES = {"lodprt.kernels": "kernels", "lodprt": "lodprt"}
#: Benchmark files that measure nothing (left out of every fingerprint).
NOT_MEASURED = {"fingerprint.py", "report.py", "report_tables.py", "run_all.py"}


def module_file(name: str, root: Path = REPO) -> Path | None:
    """The source file of module ``name`` of lodprt in the tree at ``root`` (None when it is not one)."""
    for pkg, folder in PACKAGES.items():
        if name == pkg or name.startswith(pkg + "."):
            rel = name[len(pkg):].lstrip(".").split(".") if name != pkg else []
            base = root.joinpath(folder, *rel)
            for f in (base.with_suffix(".py") if rel else None, base / "__init__.py"):
                if f is not None and f.is_file():
                    return f
            return None
    return None


def _imports(tree: ast.AST, here: str | None, is_package: bool, code_strings: bool) -> set[str]:
    """Module names imported anywhere in ``tree`` (relative imports resolved against module ``here``)."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level and here:
                parts = here.split(".")
                parts = parts[: len(parts) - node.level + (1 if is_package else 0)]
                base = ".".join(parts + ([node.module] if node.module else []))
            names.add(base)
            names.update(f"{base}.{a.name}" for a in node.names)
        elif code_strings and isinstance(node, (ast.List, ast.Tuple)):
            names.update(_run_as_main(node))
        elif code_strings and isinstance(node, ast.Constant) and isinstance(node.value, str) and "import" in node.value:
            try:
                names |= _imports(ast.parse(node.value), None, False, False)
            except SyntaxError:
                pass
    return names


def _run_as_main(node: ast.List | ast.Tuple) -> set[str]:
    """The modules a command line written as a list or tuple literal runs with ``-m`` (``"-m", "lodprt"`` ->
    ``lodprt`` and ``lodprt.__main__``): a child process a benchmark starts runs that code as surely as an import."""
    items = [e.value if isinstance(e, ast.Constant) and isinstance(e.value, str) else None for e in node.elts]
    return {f"{m}{tail}" for k, m in zip(items, items[1:]) if k == "-m" and m for tail in ("", ".__main__")}


def _parents(name: str) -> list[str]:
    parts = name.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def code_files(script: Path, root: Path = REPO) -> list[Path]:
    """The source files benchmark ``script`` measures: itself, its helper scripts and the lodprt modules they import,
    transitively (sorted)."""
    bench = Path(script).resolve().parent
    todo, seen, files = [(Path(script).resolve(), None)], set(), set()
    while todo:
        f, name = todo.pop()
        if f in seen:
            continue
        seen.add(f)
        files.add(f)
        is_bench = name is None
        for imp in _imports(ast.parse(f.read_text()), name, f.name == "__init__.py", is_bench):
            for mod in (*_parents(imp), imp):
                target = module_file(mod, root)
                if target is not None:
                    todo.append((target, mod))
                elif is_bench and "." not in mod and (bench / f"{mod}.py").is_file() \
                        and f"{mod}.py" not in NOT_MEASURED:
                    todo.append(((bench / f"{mod}.py").resolve(), None))
    return sorted(files)


def code_text(source: str) -> str:
    """What of a Python source the fingerprint hashes: its syntax tree without docstrings (comments are not in
    the tree), so that editing documentation in a module does not make results stale, while any code does."""
    tree = ast.parse(source)
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and body \
                and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
                and isinstance(body[0].value.value, str):
            node.body = body[1:] or [ast.Pass()]
    return ast.dump(tree)


def file_hashes(files: list[Path], root: Path = REPO) -> dict[str, str]:
    """{path relative to root (posix): sha256 of its code (``code_text``), first 16 hex digits}."""
    out = {}
    for f in files:
        rel = Path(f).resolve().relative_to(root.resolve()).as_posix()
        out[rel] = hashlib.sha256(code_text(Path(f).read_text()).encode()).hexdigest()[:16]
    return dict(sorted(out.items()))


def fingerprint(hashes: dict[str, str]) -> str:
    """One hash of the files' names and contents (what the results JSON records as ``code_fingerprint``)."""
    h = hashlib.sha256()
    for rel, digest in sorted(hashes.items()):
        h.update(f"{rel}\0{digest}\n".encode())
    return h.hexdigest()[:16]


def code_fingerprint(script: Path, root: Path = REPO) -> tuple[str, dict[str, str]]:
    """(fingerprint, per-file hashes) of the code benchmark ``script`` measures in the tree at ``root``."""
    hashes = file_hashes(code_files(script, root), root)
    return fingerprint(hashes), hashes
