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
    # compare draws the full-resolution frame beside the cut anyway: --full is no option of it (it was taken and
    # ignored)
    with pytest.raises(SystemExit) as stop:
        main([*args[:-2], "--full", "-o", str(tmp_path / "other.png")])
    assert stop.value.code == 2 and "unrecognized arguments: --full" in capsys.readouterr().err
    assert not (tmp_path / "other.png").exists()


LIGHTS = [(0.05, 0.3, 0.1)]


def _camera(w=160, h=120):
    from lodprt.runtime.camera import Camera

    return Camera(eye=(0.05, 0.3, 0.45), target=(0.0, 0.1, 0.0), width=w, height=h)


def test_compare_error_is_difference_over_runtime_white(cut_store, tmp_path):
    """compare's numbers are |LOD - full| / white of the two linear renders (`render_to_file` to .npy, LOD on and
    off), computed here in numpy, with white the Runtime's fixed white of the store; the figure is laid out pixel
    for pixel: its size is the layout's, and its middle panel is the full-resolution PNG of `render_to_file`."""
    from PIL import Image

    from lodprt.display.compare import compare_figure
    from lodprt.display.error_figure import TITLE, layout
    from lodprt.display.pictures import render_to_file
    from lodprt.runtime.samples import default_white
    from lodprt.store.bake_store import open_store

    store, cam = open_store(cut_store), _camera()
    got = compare_figure(store, tmp_path / "c.png", lights=LIGHTS, camera=cam, error_bound=0.5)
    for name, lod in (("lod", True), ("full", False)):
        render_to_file(store, tmp_path / f"{name}.npy", lights=LIGHTS, camera=cam, error_bound=0.5, lod=lod)
        render_to_file(store, tmp_path / f"{name}.png", lights=LIGHTS, camera=cam, error_bound=0.5, lod=lod)
    a, b = (np.load(tmp_path / f"{n}.npy").astype(np.float64) for n in ("lod", "full"))
    white = default_white(store)
    assert got["white"] == pytest.approx(white, rel=1e-12)
    covered = (a.max(2) > 0) | (b.max(2) > 0)
    rel = (np.abs(a - b).sum(2) / 3 / white)[covered]
    assert rel.max() > 0
    assert got["max_difference"] == pytest.approx(rel.max(), rel=1e-6)
    assert got["mean_difference"] == pytest.approx(rel.mean(), rel=1e-6)
    assert got["p99_difference"] == pytest.approx(np.percentile(rel, 99), rel=1e-6)
    mse = np.mean((np.clip(a, None, white) - np.clip(b, None, white))[covered] ** 2) / white**2
    assert got["psnr_db"] == pytest.approx(-10 * np.log10(mse), abs=1e-6)
    fig = np.asarray(Image.open(tmp_path / "c.png").convert("RGB"))
    assert (fig.shape[1], fig.shape[0]) == layout(160, 120)["size"]
    x = layout(160, 120)["panels"][1][0]
    full_png = np.asarray(Image.open(tmp_path / "full.png").convert("RGB"))
    assert np.array_equal(fig[TITLE + 30:, x:x + 160], full_png[30:])  # below the panel's own title


def test_panels_fill_the_figure():
    """The three panels cover most of the figure (the rest: a two-line title and the colour bar)."""
    from lodprt.display.error_figure import layout

    for (w, h), least in (((320, 240), 0.8), ((640, 480), 0.88)):
        fw, fh = layout(w, h)["size"]
        assert 3 * w * h / (fw * fh) > least


class _Linear:
    """A stand-in renderer whose linear image of a frame is the frame (an array) itself, as one row of pixels."""

    def image(self, frame, *, linear, per_vertex=False):
        assert linear
        return np.asarray(frame, np.float32)[None]


def test_diff_error_is_difference_over_white_as_compare(cut_store, tmp_path):
    """diff's per-vertex error is |cut - full| / white of the completed light cut and the full re-bake, computed
    here in numpy, white the Runtime's fixed white; compare's `frame_error` gives the same numbers on the same
    pair; the colour scale tops at the 99th percentile, and --scale below zero is refused."""
    from lodprt.display.compare import frame_error
    from lodprt.display.diff import diff_figure, full_resolution_radiance
    from lodprt.errors import LodprtError
    from lodprt.runtime.samples import default_white
    from lodprt.store.bake_store import open_store

    store, eye = open_store(cut_store), np.array([0.05, 0.3, 0.45])
    got = diff_figure(store, 0, eye, tmp_path / "d.png", size=(120, 90))
    cut = store.radiance(0, eye).astype(np.float32)
    full = full_resolution_radiance(store, 0, eye, "cpu").astype(np.float32)
    white = default_white(store)
    rel = np.abs(cut.astype(np.float64) - full).mean(1) / white
    assert got["white"] == pytest.approx(white, rel=1e-12)
    np.testing.assert_allclose(got["error"], rel, rtol=1e-5, atol=1e-9)
    assert got["max_difference"] == pytest.approx(rel.max(), rel=1e-5) and rel.max() > 0
    same, _, _ = frame_error(_Linear(), cut, full, white)
    for key in ("psnr_db", "relative_rmse", "mean_difference", "max_difference", "p99_difference"):
        assert same[key] == pytest.approx(got[key], rel=1e-5), key
    with pytest.raises(LodprtError, match="--scale"):
        diff_figure(store, 0, eye, tmp_path / "e.png", size=(120, 90), scale=-1.0)


def test_error_against_full_uses_the_run_times_interpolation(cut_store):
    """With LOD off, a frame of the thesis interpolation is the full mesh under it: measured against the full frame
    of the same interpolation it is the same picture (PSNR over 100 dB: float rounding); against the default's
    (what `frames --error-every` used to compare with) it reads the interpolations' difference instead."""
    from lodprt.display.compare import error_against_full
    from lodprt.display.render import Renderer
    from lodprt.runtime.camera import Camera
    from lodprt.runtime.session import Runtime
    from lodprt.store.bake_store import open_store

    store = open_store(cut_store)
    rt = Runtime(store, device="cpu", lod=False, interpolation="thesis")
    rt.set_lights([(0.05, 0.3, 0.1)])
    rt.set_camera(Camera(eye=(0.05, 0.3, 0.45), target=(0.0, 0.1, 0.0), width=160, height=120))
    frame = rt.update()
    with Renderer() as r:
        same = error_against_full(r, store, frame, rt.white, rt.interpolation)
        other = error_against_full(r, store, frame, rt.white)
    assert same["psnr_db"] > 100 and np.isfinite(other["psnr_db"]) and other["psnr_db"] < 60


def test_the_pictures_white_is_the_cuts_white(cut_store, tmp_path):
    """--white is the unit of the run time's errors too: a light 100x dimmer drawn with a white 100x lower is the
    same picture, and the view cut is the same cut (it kept the store's white and coarsened to 19 dB)."""
    from lodprt.display.compare import compare_figure
    from lodprt.runtime.camera import Camera
    from lodprt.runtime.sources import frame_source
    from lodprt.store.bake_store import open_store

    store = open_store(cut_store)
    assert frame_source(store, white=0.25).white == 0.25
    white = frame_source(store).white
    cam = Camera(eye=(0.05, 0.3, 0.45), target=(0.0, 0.1, 0.0), width=160, height=120)
    a = compare_figure(store, tmp_path / "a.png", lights=[(0.05, 0.3, 0.1)], camera=cam)
    b = compare_figure(store, tmp_path / "b.png", lights=[(0.05, 0.3, 0.1)], camera=cam,
                       colors=[store.intensity * 0.01], white=white * 0.01)
    assert a["triangles_lod"] == b["triangles_lod"]
    assert b["psnr_db"] == pytest.approx(a["psnr_db"], abs=0.05)


def test_a_figure_of_panels_a_few_pixels_tall(cut_store, tmp_path):
    """Panels under 14 pixels tall (64 x 8, 1 x 1) get a colour bar as tall as they are: the figure is written (its
    bar's height was negative, a matplotlib error)."""
    from lodprt.display.compare import compare_figure
    from lodprt.display.error_figure import layout
    from lodprt.runtime.camera import Camera
    from lodprt.store.bake_store import open_store

    assert layout(64, 8)["bar"][1:] == (0, layout(64, 8)["bar"][2], 8) and layout(1, 1)["bar"][3] == 1
    assert layout(160, 120)["bar"][1] == 6 and layout(160, 120)["bar"][3] == 108
    store = open_store(cut_store)
    for w, h in ((64, 8), (1, 1)):
        cam = Camera(eye=(0.05, 0.3, 0.45), target=(0.0, 0.1, 0.0), width=w, height=h)
        compare_figure(store, tmp_path / f"{w}x{h}.png", lights=[(0.05, 0.3, 0.1)], camera=cam)
        assert (tmp_path / f"{w}x{h}.png").stat().st_size > 0


def test_readme_compare_row_is_true_to_its_parser():
    """README's table said `lodprt compare OUT.zarr (as render, without --full)`, but compare requires --light and
    --eye and has no --sample: every option of the row's synopsis is one of compare's, and the required ones stand
    outside brackets."""
    import re
    from pathlib import Path

    from lodprt.cli.main import build_parser

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    (row,) = [line for line in readme.splitlines() if line.startswith("| `lodprt compare ")]
    synopsis = row.split("`")[1]
    compare = build_parser()._subparsers._group_actions[0].choices["compare"]
    options = {s for a in compare._actions for s in a.option_strings}
    assert set(re.findall(r"--[a-z-]+", synopsis)) <= options, synopsis
    required = {a.option_strings[-1] for a in compare._actions if a.required and a.option_strings}
    outside = re.sub(r"\[[^\]]*\]", "", synopsis)
    assert {"--light", "--eye", "--out"} == required and {"--light", "--eye", "-o"} <= set(outside.split()), synopsis
