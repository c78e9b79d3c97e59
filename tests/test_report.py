"""benchmarks/report.py: the generated tables of README.md and docs/*.md match the results JSON, the marker
replacement, and the code fingerprint the results record (benchmarks/fingerprint.py).

Only ``--check --tables-only`` runs here: every code change moves the fingerprints, so the full ``--check`` (tables
and fingerprints) is the release check after ``benchmarks/run_all.py`` (docs/BENCHMARKS.md)."""

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BENCH = REPO / "benchmarks"
sys.path.insert(0, str(BENCH))

import fingerprint  # noqa: E402
import report  # noqa: E402
from report_tables import TABLES  # noqa: E402


def test_markdown_tables_match_the_results():
    done = subprocess.run([sys.executable, str(BENCH / "report.py"), "--check", "--tables-only"], cwd=REPO,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr


def test_every_table_has_a_marker_and_every_marker_a_table():
    used = {name for md in report.markdown_files() for name, _ in report.blocks(md.read_text())}
    assert used == set(TABLES)


def test_replacement_keeps_markers_and_text_around_them():
    text = ("intro\n<!-- report:a -->\n| old |\n|---|\n<!-- /report:a -->\nmiddle `<!-- report:b -->` prose\n"
            "<!-- report:b -->\n<!-- /report:b -->\nend\n")
    out = report.replace_blocks(text, lambda name: f"| {name} |\n|---|\n| 1 |")
    assert out == ("intro\n<!-- report:a -->\n| a |\n|---|\n| 1 |\n<!-- /report:a -->\nmiddle `<!-- report:b -->` prose\n"
                   "<!-- report:b -->\n| b |\n|---|\n| 1 |\n<!-- /report:b -->\nend\n")
    assert report.replace_blocks(out, lambda name: f"| {name} |\n|---|\n| 1 |") == out  # idempotent
    with pytest.raises(ValueError, match="report:c"):
        report.blocks("<!-- report:c -->\n| x |\n")


def test_check_names_a_table_that_differs(tmp_path):
    results = tmp_path / "results"
    results.mkdir()
    r = json.loads((BENCH / "results" / "runtime.json").read_text())
    md = tmp_path / "X.md"
    md.write_text(f"<!-- report:runtime_sweep -->\n{TABLES['runtime_sweep'][1](r)}\n<!-- /report:runtime_sweep -->\n")
    r["sweep"][0]["median_triangles"] += 1000
    (results / "runtime.json").write_text(json.dumps(r))
    problems = report.table_problems([md], results)
    assert len(problems) == 1 and "runtime_sweep" in problems[0]
    assert report.table_problems([md], BENCH / "results") == []


def make_tree(root: Path) -> Path:
    """A tiny checkout: a benchmark importing lodprt.a (which imports lodprt.kernels.k) and a helper, plus docs."""
    for rel, text in {"lodprt/__init__.py": "", "lodprt/a.py": "from lodprt.kernels import k\n",
                      "lodprt/unused.py": "x = 1\n", "kernels/__init__.py": "", "kernels/k.py": "y = 2\n",
                      "benchmarks/helper.py": "z = 3\n",
                      "benchmarks/bench.py": "def main():\n    import helper\n    from lodprt.a import *\n"
                                             "CHILD = 'from lodprt.unused import x'\n",
                      "docs/X.md": "# docs\n", "README.md": "readme\n"}.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)
    return root / "benchmarks" / "bench.py"


def test_fingerprint_covers_what_the_benchmark_imports(tmp_path):
    script = make_tree(tmp_path)
    files = {p.relative_to(tmp_path).as_posix() for p in fingerprint.code_files(script, tmp_path)}
    assert files == {"benchmarks/bench.py", "benchmarks/helper.py", "lodprt/__init__.py", "lodprt/a.py",
                     "lodprt/unused.py", "kernels/__init__.py", "kernels/k.py"}
    fp, hashes = fingerprint.code_fingerprint(script, tmp_path)
    tree = "Module(body=[Assign(targets=[Name(id='y', ctx=Store())], value=Constant(value=2))], type_ignores=[])"
    assert hashes["kernels/k.py"] == hashlib.sha256(tree.encode()).hexdigest()[:16]
    assert len(fp) == 16


def test_fingerprint_covers_a_module_run_as_a_program(tmp_path):
    """A benchmark that runs ``[sys.executable, "-m", "lodprt", ...]`` in a child measures ``lodprt.__main__`` and
    what it imports (the command line), though it never imports them itself; an edit there moves its fingerprint."""
    make_tree(tmp_path)
    (tmp_path / "lodprt" / "__main__.py").write_text("from lodprt.cli import main\n")
    (tmp_path / "lodprt" / "cli.py").write_text("def main():\n    from lodprt.unused import x\n")
    script = tmp_path / "benchmarks" / "cmd.py"
    script.write_text("import subprocess, sys\nCMD = [sys.executable, '-m', 'lodprt', 'frames']\n")
    files = {p.relative_to(tmp_path).as_posix() for p in fingerprint.code_files(script, tmp_path)}
    assert files == {"benchmarks/cmd.py", "lodprt/__init__.py", "lodprt/__main__.py", "lodprt/cli.py",
                     "lodprt/unused.py"}
    before, _ = fingerprint.code_fingerprint(script, tmp_path)
    (tmp_path / "lodprt" / "unused.py").write_text("x = 2\n")
    assert fingerprint.code_fingerprint(script, tmp_path)[0] != before
    (tmp_path / "benchmarks" / "plain.py").write_text("ARGS = ['-m', 'x']\nimport lodprt.a\n")  # not lodprt: no file
    assert "lodprt/__main__.py" not in {p.name for p in fingerprint.code_files(tmp_path / "benchmarks" / "plain.py",
                                                                              tmp_path)}


@pytest.mark.parametrize("rel, edit, changes", [
    ("kernels/k.py", "w = 0\n", True), ("lodprt/a.py", "w = 0\n", True), ("benchmarks/helper.py", "w = 0\n", True),
    ("kernels/k.py", "# a comment\n", False), ("docs/X.md", "more\n", False), ("README.md", "more\n", False)])
def test_fingerprint_changes_with_code_not_docs(tmp_path, rel, edit, changes):
    script = make_tree(tmp_path)
    before, _ = fingerprint.code_fingerprint(script, tmp_path)
    (tmp_path / rel).write_text((tmp_path / rel).read_text() + edit)
    after, _ = fingerprint.code_fingerprint(script, tmp_path)
    assert (after != before) == changes


def test_fingerprint_ignores_docstrings_but_not_string_code():
    code = 'def f(x):\n    return x + 1\n'
    documented = '"""Module doc."""\n\n\ndef f(x):\n    """What f does."""\n    return x + 1  # T-7\n'
    assert fingerprint.code_text(code) == fingerprint.code_text(documented)
    assert fingerprint.code_text(code) != fingerprint.code_text(code.replace("+ 1", "+ 2"))
    assert fingerprint.code_text('X = "a"\n') != fingerprint.code_text('X = "b"\n')  # a constant, not a docstring


def test_stale_results_are_named_with_the_changed_files(tmp_path):
    script = make_tree(tmp_path)
    fp, hashes = fingerprint.code_fingerprint(script, tmp_path)
    results = tmp_path / "results"
    results.mkdir()
    (results / "view_cut.json").write_text(json.dumps({"benchmark": "bench", "code_fingerprint": fp,
                                                       "code_files": hashes}))
    md = tmp_path / "docs" / "X.md"
    md.write_text("<!-- report:view_cut -->\n<!-- /report:view_cut -->\n")
    assert report.stale_problems([md], results, tmp_path) == []
    (tmp_path / "kernels" / "k.py").write_text("y = 3\n")
    problems = report.stale_problems([md], results, tmp_path)
    assert len(problems) == 1 and "view_cut.json is older than the code" in problems[0]
    assert "kernels/k.py" in problems[0] and "python benchmarks/bench.py" in problems[0]
