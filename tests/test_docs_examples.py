"""The fenced examples of README.md and docs/*.md, and the one in lodprt's docstring, run (docs/TESTING.md).

Every ```python / ```bash (sh, shell, console) block runs, each in a fresh temporary folder, unless the line just
before its fence is a marker ``<!-- example: not run: REASON -->``; a ```toml block is parsed; any other block
(a plain ``` block, say) needs the marker. Shell blocks run in bash with ``set -e`` and ``lodprt``/``python`` meaning
this interpreter's ``python -m lodprt`` / ``python``; every ``-o FILE`` they name must exist afterwards.

To stay small (the whole file in a few minutes on two cores) a block may get the fixture files it reads (``NEEDS``:
small stores baked once per module) and explicit text substitutions (``SUBS``: smaller floors, fewer frames, rays,
grid cells); a substitution that no longer matches its block fails, so the table cannot go stale silently.
"""

import os
import re
import shutil
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
DOCS = ["README.md", *sorted(p.relative_to(REPO).as_posix() for p in (REPO / "docs").glob("*.md"))]
MARKER = re.compile(r"^\s*<!--\s*example:\s*not run:(.*?)-->\s*$")
FENCE = re.compile(r"^(\s*)```(\S*)\s*$")
PYTHON = {"python", "py"}
SHELL = {"bash", "sh", "shell", "console"}
#: Commands and names that draw with OpenGL: their blocks need the ``gl`` fixture.
GL_USE = re.compile(r"\blodprt (render|compare|diff|turntable|view|render-environment|render-volume)\b|Renderer\(")


def parse_blocks(name, text):
    """The fenced blocks of one markdown text: (name, line of the fence, language, code, marker reason or None)."""
    blocks, lines, i = [], text.splitlines(), 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        j = i + 1
        while j < len(lines) and not lines[j].strip().startswith("```"):
            j += 1
        before = next((ln for ln in reversed(lines[:i]) if ln.strip()), "")
        mark = MARKER.match(before)
        code = textwrap.dedent("\n".join(lines[i + 1 : j])) + "\n"
        blocks.append((name, i + 1, m.group(2).lower(), code, mark.group(1).strip() if mark else None))
        i = j + 1
    return blocks


def collect_blocks():
    """Every fenced block of README.md and docs/*.md."""
    return [b for name in DOCS for b in parse_blocks(name, (REPO / name).read_text())]


def problems(blocks):
    """file:line of each block neither run nor marked, and of each marker without a reason."""
    bad = []
    for name, line, lang, _, reason in blocks:
        if reason is not None and not reason:
            bad.append(f"{name}:{line}: marker with an empty reason")
        elif reason is None and lang not in PYTHON | SHELL | {"toml"}:
            bad.append(f"{name}:{line}: ```{lang} block is neither run nor marked <!-- example: not run: REASON -->")
    return bad


BLOCKS = collect_blocks()
RUN = [b for b in BLOCKS if b[4] is None and b[2] in PYTHON | SHELL]


def block_id(block):
    return f"{block[0]}:{block[1]}"


def first_line(code):
    return code.strip().splitlines()[0]


# Per block, keyed by (file, its first line of code): the fixture files copied into its folder first.
NEEDS = {
    ("README.md", "lodprt diff demo.zarr --sample 4 --eye 0.3 0.7 1.4 -o diff.png"): ["demo.zarr"],
    ("docs/FORMAT.md", "import numpy as np, zarr"): ["demo.zarr", "bunny_q8.zarr", "bunny_env.zarr"],
    ("docs/EXPORT.md", "lodprt export bunny.zarr --sample 4 --eye 0.02 0.26 0.5 -o bunny.glb"
     "                  # light sample 4, view cut"): ["bunny.zarr"],
    ("docs/EXPORT.md", 'lodprt.export_glb("bunny.zarr", "bunny.glb", sample=4, eye=(0.02, 0.26, 0.5))'
     "   # returns the numbers written"): ["bunny.zarr"],
    ("docs/RUNTIME.md", "import lodprt"): ["bunny.zarr"],
    ("docs/RUNTIME.md", "lodprt radiance bunny.zarr --light 0.05 0.28 0.02 [--light ...] [--color R G B ...] "
     "[--interpolation direct|direct-agree|direct-blend|thesis] --eye 0 0.3 0.6 -o rad.npy"): ["bunny.zarr"],
    ("docs/GI.md", "lodprt bake scene.toml -o gi.zarr --bounces 2 --gi-rays 128 --threshold-deg 0.5 "
     "--indirect-threshold-deg 20"): ["scene.toml", "ball.obj"],
    ("docs/GI.md", "from lodprt.precompute.bake import bake"): ["scene.toml", "ball.obj"],
    ("docs/DISTRIBUTED.md", "lodprt bake scene.toml -o scene.zarr            # [lights] grid = [3, 1, 3]"):
        ["scene.toml", "finer.toml", "ball.obj"],
    ("docs/ENVIRONMENT.md", "lodprt irradiance sky                        # 9 RGB coefficients, A_l, c1..c5, M "
     "per channel, registers cAr..cC"): ["env.hdr", "sun.hdr"],
    ("docs/VOLUMES.md", "lodprt bake-volume cloud:24 -o cloud.zarr --rays 64 --bounces 2 --environment sky"):
        ["smoke.npy", "scene.toml", "ball.obj", "plane.obj"],
}
# Per block: (old, new) text substitutions that keep it small; "SYNOPSIS" drops [optional ...] usage brackets.
FLOOR = ("resolution = 380", "resolution = 40")  # the bunny on a 40 x 40 floor, not the thesis' 380 x 380
SUBS = {
    ("README.md", "lodprt diff demo.zarr --sample 4 --eye 0.3 0.7 1.4 -o diff.png"): [
        ("--frames 120 --error-every 20", "--frames 4 --error-every 2")],
    ("README.md", "cat > bunny.toml <<'EOF'"): [FLOOR, ("--frames 72", "--frames 3")],
    ("docs/RUNTIME.md", "import lodprt"): [("colors=...)", "colors=[(1.0, 0.9, 0.8)])")],
    ("docs/RUNTIME.md", "lodprt radiance bunny.zarr --light 0.05 0.28 0.02 [--light ...] [--color R G B ...] "
     "[--interpolation direct|direct-agree|direct-blend|thesis] --eye 0 0.3 0.6 -o rad.npy"): [
        "SYNOPSIS", ("--frames 240", "--frames 3"), ("--frames 240", "--frames 3"), ("--frames 240", "--frames 3"),
        ("--frames 240", "--frames 3"), ("--error-every 10", "--error-every 2")],
    ("docs/GI.md", "lodprt bake scene.toml -o gi.zarr --bounces 2 --gi-rays 128 --threshold-deg 0.5 "
     "--indirect-threshold-deg 20"): [("--gi-rays 128", "--gi-rays 8"), ("--full ", "--full --gi-rays 8 ")],
    ("docs/GI.md", "from lodprt.precompute.bake import bake"): [("gi_rays=128", "gi_rays=8")],
    ("docs/ENVIRONMENT.md", "lodprt irradiance sky                        # 9 RGB coefficients, A_l, c1..c5, M "
     "per channel, registers cAr..cC"): [("--rays 256", "--rays 8"), ("--rays 1024", "--rays 8"),
                                         ("--frames 12", "--frames 2")],
    ("docs/VOLUMES.md", "lodprt bake-volume cloud:24 -o cloud.zarr --rays 64 --bounces 2 --environment sky"): [
        "SYNOPSIS", ("cloud:24", "cloud:10"), ("--rays 64", "--rays 8"), ("--albedo 0.8", "--albedo 0.8 --rays 8"),
        ("--grid 16 16 16", "--grid 4 4 4 --rays 8")],
}
# Per python block: code run after it in the same process, checking what the doc states.
CHECKS = {
    ("README.md", "import lodprt"): "assert rgb.shape == (store.positions.shape[0], 3) and rgb.dtype == 'float32'\n"
    "assert frame.triangles.shape[1] == 3 and frame.radiance.shape == (len(frame.positions), 3)\n",
    ("docs/RUNTIME.md", "import lodprt"): "assert frame.radiance.shape == (len(frame.positions), 3)\n"
    "assert frame.coefficients.shape[:2] == (len(frame.positions), 3)\nassert rgb.shape[1] == 3\n",
}
# Per python block: code run before it (names the doc's prose defines).
PRELUDE = {
    ("docs/EXPORT.md", 'lodprt.export_glb("bunny.zarr", "bunny.glb", sample=4, eye=(0.02, 0.26, 0.5))'
     "   # returns the numbers written"): "import lodprt\n",
    ("docs/RUNTIME.md", "import lodprt"): "eye = (0.0, 0.3, 0.6)\nlights = [(0.05, 0.28, 0.02)]\n",
    ("docs/GI.md", "from lodprt.precompute.bake import bake"):
        "import lodprt\nscene = lodprt.load_scene('scene.toml')\n",
}
# The FORMAT.md readers, each as one block: what "zarr and numpy alone" must reproduce of lodprt's own reading.
FORMAT_CHECKS = {
    'root = zarr.open_group("demo.zarr", mode="r")':
        "import lodprt\nref = lodprt.open_store('demo.zarr').radiance(sample=4, eye=tuple(eye))[ids]\n"
        "assert np.allclose(rgb, ref, rtol=1e-4, atol=1e-5), abs(rgb - ref).max()\n",
    'root = zarr.open_group("bunny_q8.zarr", mode="r")':
        "import lodprt\nref = lodprt.open_store('bunny_q8.zarr').coefficients(4)[ids]\n"
        "assert c.shape == ref.shape and np.allclose(c, ref, rtol=1e-5, atol=1e-6), abs(c - ref).max()\n",
    'root = zarr.open_group("bunny_env.zarr", mode="r")':
        "import lodprt\nassert rgb.shape == (root['transfer/diffuse'].shape[0], 3) and np.isfinite(rgb).all()\n",
}


def _write_obj(path, pos, faces):
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in pos)
                    + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces))


@pytest.fixture(scope="module")
def fixtures(tmp_path_factory):
    """The small files the examples read, made once: stores (baked by lodprt's CLI), meshes, scenes, HDR images."""
    import trimesh

    from lodprt.cli.main import main
    from lodprt.model.environment import write_rgbe

    d = tmp_path_factory.mktemp("doc-fixtures")
    (d / "tests").symlink_to(REPO / "tests")
    (d / "bunny.toml").write_text('[[object]]\nmesh = "tests/data/stanford-bunny.obj.xz"\n[floor]\nresolution = 40\n'
                                  "[lights]\ngrid = [3, 1, 3]\n")
    # the README's install line ends with these two commands
    assert main(["bake", "demo", "-o", str(d / "demo.zarr"), "--overwrite"]) == 0
    assert main(["info", str(d / "demo.zarr")]) == 0
    assert main(["bake", str(d / "bunny.toml"), "-o", str(d / "bunny.zarr"), "--sh-order", "4"]) == 0
    assert main(["compress", str(d / "bunny.zarr"), "-o", str(d / "bunny_q8.zarr"), "--codec", "q8"]) == 0
    assert main(["bake-environment", str(REPO / "tests/data/spot.obj.xz"), "-o", str(d / "bunny_env.zarr"),
                 "--environment", "sky", "--rays", "8"]) == 0
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    _write_obj(d / "ball.obj", ball.vertices, ball.faces)
    plane = trimesh.creation.box(extents=(1.0, 0.02, 1.0))
    _write_obj(d / "plane.obj", plane.vertices, plane.faces)
    scene = '[[object]]\nmesh = "ball.obj"\nname = "ball"\ntranslate = [0, 0.15, 0]\n[floor]\nresolution = 12\n'
    (d / "scene.toml").write_text(scene + "[lights]\ngrid = [3, 1, 3]\n")
    (d / "finer.toml").write_text(scene + "[lights]\ngrid = [9, 1, 3]\n")  # the docs' [9, 3, 9], smaller
    np.save(d / "smoke.npy", np.random.default_rng(0).random((8, 8, 8)).astype(np.float32))
    sky = np.full((16, 32, 3), 0.2, np.float32)
    sky[:8] += np.linspace(0.2, 1.0, 8, dtype=np.float32)[:, None, None]
    write_rgbe(d / "env.hdr", sky)
    sun = np.full((16, 32, 3), 0.05, np.float32)
    sun[3, 10] = 500.0
    write_rgbe(d / "sun.hdr", sun)
    return d


def apply_subs(key, code):
    for sub in SUBS.get(key, []):
        if sub == "SYNOPSIS":
            new = re.sub(r" \[[^\]]*\]", "", code)
        else:
            new = code.replace(sub[0], sub[1], 1)
        assert new != code, f"{key}: the substitution {sub!r} no longer matches its block; update SUBS"
        code = new
    return code


def workspace(tmp_path, fixtures, key):
    (tmp_path / "tests").symlink_to(REPO / "tests")
    (tmp_path / "docs").mkdir()  # a block that writes docs/... writes here, never into the repository
    for name in NEEDS.get(key, []):
        src = fixtures / name
        (shutil.copytree if src.is_dir() else shutil.copy)(src, tmp_path / name)


def run_python(code, cwd):
    (cwd / "example.py").write_text(code)
    proc = subprocess.run([sys.executable, "example.py"], cwd=cwd, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"exit {proc.returncode}\n{code}\n--- stdout\n{proc.stdout}\n--- stderr\n{proc.stderr}"
    return proc


def run_shell(code, cwd):
    prefix = ('lodprt() { "$LODPRT_PY" -m lodprt "$@"; }\npython() { "$LODPRT_PY" "$@"; }\n'
              "set -euxo pipefail\n")
    (cwd / "example.sh").write_text(prefix + code)
    env = {**os.environ, "LODPRT_PY": sys.executable}
    proc = subprocess.run(["bash", "example.sh"], cwd=cwd, capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, f"exit {proc.returncode}\n{code}\n--- stdout\n{proc.stdout}\n--- stderr\n{proc.stderr}"
    for out in re.findall(r"(?:^|\s)-o\s+(\S+)", code):
        stem = out.rsplit(".", 1)
        frames = list(cwd.glob(f"{stem[0]}_*.{stem[1]}")) if len(stem) == 2 else []
        assert (cwd / out).exists() or frames, f"the example names -o {out}, which it did not write\n{code}"
    return proc


def test_every_block_runs_or_is_marked():
    """A block this test does not run needs the marker, with a reason; a python or shell block is run."""
    assert len(BLOCKS) >= 25, "the fence parser found too few blocks"
    bad = problems(BLOCKS)
    keys = {(b[0], first_line(b[3])) for b in BLOCKS}
    for table in (NEEDS, SUBS, CHECKS, PRELUDE):
        bad += [f"{k}: table entry matches no block" for k in table if k not in keys]
    assert not bad, "\n".join(bad)


def test_unmarked_or_unexplained_blocks_are_reported():
    """The check above names the file and line of a plain block without a marker and of a marker without a reason."""
    text = "# T\n\n```\nsome listing\n```\n\n<!-- example: not run:  -->\n```bash\nlodprt info x.zarr\n```\n"
    text += "\n<!-- example: not run: needs a GPU -->\n```\nlisting\n```\n\n```python\nprint(1)\n```\n"
    assert problems(parse_blocks("docs/T.md", text)) == [
        "docs/T.md:3: ``` block is neither run nor marked <!-- example: not run: REASON -->",
        "docs/T.md:8: marker with an empty reason"]


def test_toml_blocks_parse():
    for name, line, lang, code, reason in BLOCKS:
        if lang == "toml" and reason is None:
            try:
                tomllib.loads(code)
            except tomllib.TOMLDecodeError as exc:
                pytest.fail(f"{name}:{line}: {exc}")


@pytest.mark.parametrize("block", RUN, ids=block_id)
def test_block_runs(block, fixtures, tmp_path, request):
    name, line, lang, code, _ = block
    if GL_USE.search(code):
        request.getfixturevalue("gl")  # skips, saying so, only where no offscreen OpenGL context can be made
    key = (name, first_line(code))
    workspace(tmp_path, fixtures, key)
    code = apply_subs(key, code)
    if lang in SHELL:
        run_shell(code, tmp_path)
        return
    if name == "docs/FORMAT.md":
        extra = [v for k, v in FORMAT_CHECKS.items() if k in code]
        assert len(extra) == 1, f"{name}:{line}: no FORMAT_CHECKS entry for this reader"
        code += extra[0]
    run_python(PRELUDE.get(key, "") + code + CHECKS.get(key, ""), tmp_path)


def test_package_docstring_example(tmp_path, gl):
    """``help(lodprt)``'s "Public API" example runs (smaller: fewer rays, a coarser volume)."""
    import lodprt

    doc = lodprt.__doc__.split("::\n", 1)[1].split("\nNames are", 1)[0]
    code = textwrap.dedent(doc)
    for old, new in [("environment=env)", "environment=env, rays=8, bounces=1)"),
                     ("rays=128, bounces=2", "rays=8, bounces=2"), ("grid=(16, 16, 16)", "grid=(4, 4, 4), rays=8")]:
        assert old in code, f"lodprt/__init__.py docstring changed: {old!r}; update this test"
        code = code.replace(old, new)
    run_python("import lodprt\n" + code + "assert png.ndim == 3 and png.dtype == 'uint8'\n", tmp_path)
