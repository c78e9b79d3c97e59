"""The house rules (docs/ARCHITECTURE.md), checked on the source: imports run one way along the data flow, with no
loop (function-level imports included); no module over 600 lines, no function over 120; no private name of one
module imported by another."""

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: stage of each subpackage, in the order data flows; a module may import its own subpackage and lower stages only
STAGES = {"errors": 0, "allocator": 0, "devices": 0, "launches": 0, "version": 0, "deprecation": 0, "model": 1, "store": 2, "precompute": 3, "runtime": 4, "display": 5, "cli": 6}


def modules() -> dict[str, Path]:
    """Dotted name -> file of every module of the package (kernels/ is installed as lodprt.kernels)."""
    out = {}
    for path in sorted((REPO / "lodprt").rglob("*.py")):
        parts = path.relative_to(REPO).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    for path in sorted((REPO / "kernels").glob("*.py")):
        out["lodprt.kernels" + ("" if path.stem == "__init__" else "." + path.stem)] = path
    return out


def imports(path: Path, name: str) -> list[tuple[str, list[str], int]]:
    """(imported module, names imported from it, line) for every import statement, at any depth."""
    tree = ast.parse(path.read_text())
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, [], node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1] + ([base] if base else []))
            out.append((base, [a.name for a in node.names], node.lineno))
    return out


def resolve(target: str, names: list[str], known: dict) -> list[str]:
    """The package modules an import reaches: ``from pkg import mod`` reaches the module pkg.mod, ``from pkg import
    Name`` (not a module) the package's ``__init__``."""
    if not target.startswith("lodprt"):
        return []
    subs = [f"{target}.{n}" for n in names if f"{target}.{n}" in known]
    rest = [n for n in names if f"{target}.{n}" not in known]
    return subs + ([target] if target in known and (rest or not names) else [])


def stage(name: str) -> int | None:
    parts = name.split(".")
    if len(parts) < 2:
        return None  # lodprt/__init__.py: the public API, above every stage
    return STAGES.get(parts[1])


def graph() -> dict[str, set[str]]:
    known = modules()
    return {name: {m for t, ns, _ in imports(path, name) for m in resolve(t, ns, known) if m != name}
            for name, path in known.items()}


def test_imports_follow_the_data_flow():
    """Every import (module or function level) goes to the same subpackage or an earlier stage; kernels import
    only kernels; nothing imports the cli."""
    known = modules()
    bad = []
    for name, path in known.items():
        for target, names, line in imports(path, name):
            for dst in resolve(target, names, known):
                if name.startswith("lodprt.kernels"):
                    ok = dst.startswith("lodprt.kernels")
                else:
                    a, b = stage(name), stage(dst)
                    same = dst.split(".")[:2] == name.split(".")[:2]
                    ok = a is None or same or (b is not None and b < a) or (b == 0 and a == 0)
                    ok = ok or (dst.startswith("lodprt.kernels") and a is not None and a >= 1)
                if not ok:
                    bad.append(f"{path.relative_to(REPO)}:{line}: {name} imports {dst}")
    assert not bad, "imports against the flow (docs/ARCHITECTURE.md):\n" + "\n".join(bad)


def test_no_import_loop():
    """The module import graph (function-level imports included) has no cycle."""
    g = graph()
    index, low, stack, on, loops = {}, {}, [], set(), []

    def visit(v):  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in g.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                loops.append(sorted(comp))

    for v in g:
        if v not in index:
            visit(v)
    assert not loops, f"import loops: {loops}"


def test_the_flow_rule_catches_a_back_import(tmp_path):
    """The checker itself: an import from the model into the run time is reported (the test can fail)."""
    known = {"lodprt.model.x": tmp_path / "x.py", "lodprt.runtime.y": tmp_path / "y.py"}
    (tmp_path / "x.py").write_text("def f():\n    from lodprt.runtime.y import z\n")
    found = [dst for t, ns, _ in imports(known["lodprt.model.x"], "lodprt.model.x") for dst in resolve(t, ns, known)]
    assert found == ["lodprt.runtime.y"] and stage("lodprt.runtime.y") > stage("lodprt.model.x")


@pytest.mark.parametrize("limit_lines, limit_function", [(600, 120)])
def test_module_and_function_sizes(limit_lines, limit_function):
    """No module over 600 lines and no function over 120 in lodprt/ and kernels/."""
    big, long = [], []
    for name, path in modules().items():
        text = path.read_text()
        if text.count("\n") > limit_lines:
            big.append(f"{path.relative_to(REPO)}: {text.count(chr(10))} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > limit_function:
                    long.append(f"{path.relative_to(REPO)}:{node.lineno}: {node.name} {n} lines")
    assert not big and not long, "\n".join(big + long)


def test_no_private_name_crosses_modules():
    """No module imports a private name (``_x``) of another module of the package."""
    known = modules()
    bad = [f"{path.relative_to(REPO)}:{line}: {n} from {t}"
           for name, path in known.items() for t, names, line in imports(path, name)
           if t.startswith("lodprt") and t != name for n in names if n.startswith("_") and not n.startswith("__")]
    assert not bad, "\n".join(bad)


def test_public_api_resolves_and_open_is_deprecated():
    """Every documented top-level name imports (lazily) from its stage; ``lodprt.open`` still works, with a
    DeprecationWarning, and is ``open_store``; ``lodprt.bake`` is the bake function, not a module."""
    import lodprt

    for name in lodprt.__all__:
        assert getattr(lodprt, name) is not None, name
    with pytest.warns(DeprecationWarning, match="open_store"):
        assert lodprt.open is lodprt.open_store
    assert callable(lodprt.bake) and lodprt.bake.__module__ == "lodprt.precompute.bake"


def test_package_docstring_example_calls_functions():
    """Every ``lodprt.NAME(...)`` call in the package docstring's example names a callable (not a module, as
    ``lodprt.precompute.bake(...)`` once did), and its keyword arguments are parameters of that callable."""
    import inspect
    import re

    import lodprt

    calls = re.findall(r"lodprt\.([\w.]+)\(([^()]*(?:\([^()]*\)[^()]*)*)\)", lodprt.__doc__)
    assert len(calls) >= 10
    for dotted, args in calls:
        obj = lodprt
        for part in dotted.split("."):
            obj = getattr(obj, part)
        assert callable(obj) and not inspect.ismodule(obj), dotted
        params = inspect.signature(obj).parameters
        for kw in re.findall(r"(?<![\w=])(\w+)=", args):
            assert kw in params or any(p.kind is p.VAR_KEYWORD for p in params.values()), (dotted, kw)


def test_cli_choices_are_the_library_lists():
    """The transfer modes and view-cut criteria the CLI offers are the library's (the CLI keeps copies so that
    ``lodprt --help`` imports no bake and no run time)."""
    from lodprt.cli.environment import TRANSFERS
    from lodprt.cli.main import build_parser
    from lodprt.precompute.transfer import MODES
    from lodprt.runtime.criteria import CRITERIA

    assert TRANSFERS == MODES
    choices = set()
    for action in build_parser()._subparsers._group_actions[0].choices.values():
        for a in action._actions:
            if "--criterion" in a.option_strings:
                choices.add(tuple(a.choices))
    assert choices == {tuple(CRITERIA)}


def test_camera_paths_are_one_list():
    """``lodprt frames --path`` and ``lodprt view --path`` offer exactly ``camera_path``'s paths, and ``frames``
    runs ``PATH_FRAMES`` frames by default (a lap of ``view --path``: ``tests/test_viewer.py``); ``camera_path``
    refuses any other name, listing them."""
    from lodprt.cli.main import build_parser
    from lodprt.errors import LodprtError
    from lodprt.runtime.camera import PATH_FRAMES, PATHS, camera_path

    commands = build_parser()._subparsers._group_actions[0].choices
    for command in ("frames", "view"):
        (path,) = [a for a in commands[command]._actions if "--path" in a.option_strings]
        assert tuple(path.choices) == PATHS, command
    (frames,) = [a for a in commands["frames"]._actions if "--frames" in a.option_strings]
    assert frames.default == PATH_FRAMES
    with pytest.raises(LodprtError, match="camera path 'spiral': choose one of orbit, dolly"):
        next(camera_path(None, "spiral", 3))
