"""Comparison figures (figures 14-17 style): LOD frame, full-resolution frame and their difference."""

import numpy as np
import pytest

pytest.importorskip("moderngl")


@pytest.fixture(scope="module")
def cut_store(bunny_floor, bunny_hierarchy, tmp_path_factory):
    """The bunny on a 40 x 40 floor, light cut at 5 degrees, with the hierarchy."""
    from lodprt.precompute.bake import bake

    path = tmp_path_factory.mktemp("compare") / "cut.zarr"
    bake(bunny_floor, path, sh_order=4, device="cpu", tree=bunny_hierarchy, threshold_deg=5.0)
    return path


def test_compare_figure_numbers_and_error_bound(cut_store, tmp_path):
    """The figure is written; the LOD frame has fewer triangles than the full one, and a tighter error bound gives
    more triangles and a smaller difference."""
    from lodprt.display.compare import compare_figure
    from lodprt.runtime.camera import Camera
    from lodprt.store.bake_store import open_store

    store = open_store(cut_store)
    cam = Camera(eye=(0.05, 0.3, 0.45), target=(0.0, 0.1, 0.0), width=160, height=120)
    loose = compare_figure(store, tmp_path / "a.png", lights=[(0.05, 0.3, 0.1)], camera=cam, error_bound=0.5)
    tight = compare_figure(store, tmp_path / "b.png", lights=[(0.05, 0.3, 0.1)], camera=cam, error_bound=0.01)
    assert (tmp_path / "a.png").stat().st_size > 10_000
    assert loose["triangles_lod"] < tight["triangles_lod"] <= tight["triangles_full"]
    assert tight["mean_difference"] < loose["mean_difference"]
    assert np.isfinite(loose["psnr_db"]) and tight["psnr_db"] > loose["psnr_db"]


def test_cli_compare(cut_store, tmp_path, capsys):
    """`lodprt compare` prints triangle counts and PSNR and never replaces an existing figure without --overwrite."""
    from lodprt.cli.main import main

    out = tmp_path / "fig.png"
    args = ["compare", str(cut_store), "--light", "0.05", "0.3", "0.1", "--eye", "0.05", "0.3", "0.45", "--size", "120",
            "90", "--wireframe", "-o", str(out)]
    assert main(args) == 0
    assert "PSNR" in capsys.readouterr().out and out.is_file()
    assert main(args) == 2
    assert "already exists" in capsys.readouterr().err
