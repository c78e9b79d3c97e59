"""The view-cut criteria as objects (``lodprt.runtime.criteria``): the keyword API and the object give the same
frames bit for bit, the registry makes the CLI's options and objects, and bad names or settings are refused
naming them."""

import dataclasses

import numpy as np
import pytest

from lodprt.errors import LodprtError
from lodprt.runtime.camera import Camera
from lodprt.runtime.criteria import (CRITERIA, DEFAULT_ERROR_BOUND, ScreenCriterion, ThesisCriterion,
                                     make_criterion)
from lodprt.runtime.session import Runtime


@pytest.fixture(scope="module")
def ball_store(tmp_path_factory):
    """An icosphere (642 vertices) on a 24 x 24 floor, 3 x 1 x 3 lights, SH order 3, with its hierarchy."""
    import trimesh

    from lodprt.model.scene import THESIS_MATERIAL, assemble_scene
    from lodprt.precompute.bake import bake
    from lodprt.store.bake_store import open_store

    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.3)
    mesh.apply_translation((0.0, 0.3, 0.0))
    scene = assemble_scene([("ball", np.asarray(mesh.vertices), np.asarray(mesh.faces), THESIS_MATERIAL)],
                           (24, 1.0, THESIS_MATERIAL), {}, "lights", "ball")
    path = tmp_path_factory.mktemp("criteria") / "ball.zarr"
    bake(scene, path, sh_order=3, device="cpu", threshold_deg=30.0)
    return open_store(path)


def frames(rt, n=3):
    """``n`` frames of an orbit at 320 x 240 with a light between the samples."""
    c = 0.5 * (rt.bounds[0] + rt.bounds[1])
    ext = float((rt.bounds[1] - rt.bounds[0]).max())
    rt.set_lights(rt.store.light_positions.mean(0)[None, :])  # inside the light box
    out = []
    for k in range(n):
        a = 0.3 * k
        eye = c + ext * np.array([0.5 * np.sin(a), 0.35, 0.5 * np.cos(a)])
        rt.set_camera(Camera(eye=tuple(eye), target=tuple(c), width=320, height=240))
        out.append(rt.update())
    return out


@pytest.mark.parametrize("keywords, criterion", [
    ({}, ScreenCriterion()),
    ({"criterion": "screen", "error_bound": 0.3, "alpha": 0.4}, ScreenCriterion(error_bound=0.3)),
    ({"criterion": "screen", "target_psnr": 38, "error_bound": 0.5}, ScreenCriterion(0.5, target_psnr=38)),
    ({"criterion": "thesis", "error_bound": 0.1, "alpha": 0.3}, ThesisCriterion(0.1, alpha=0.3)),
    ({"criterion": "thesis"}, ThesisCriterion()),
])
def test_keywords_and_object_make_the_same_frames(ball_store, keywords, criterion):
    """``Runtime(store, criterion="thesis", error_bound=..., alpha=...)`` and ``Runtime(store,
    criterion=ThesisCriterion(...))`` hold equal criteria and make the same frames: triangles, the cut's vertex ids
    and the relit colours equal bit for bit (the exact identity), the steered bound too."""
    by_name = Runtime(ball_store, device="cpu", **keywords)
    by_object = Runtime(ball_store, device="cpu", criterion=criterion)
    assert by_name.criterion == criterion and by_object.criterion is criterion
    for a, b in zip(frames(by_name), frames(by_object)):
        assert len(a.triangles) == len(b.triangles) > 0
        assert np.array_equal(a.triangles, b.triangles)
        assert np.array_equal(a.vertex_ids, b.vertex_ids)
        assert np.array_equal(a.radiance, b.radiance) and np.array_equal(a.coefficients, b.coefficients)
        assert a.stats["error_bound"] == b.stats["error_bound"]
    assert by_name.criterion == by_object.criterion  # the steering (target_psnr) replaced both alike


def test_criteria_differ_and_defaults_hold(ball_store):
    """The two criteria read different per-node bounds and give different cuts; the defaults are the registry's."""
    screen, thesis = Runtime(ball_store, device="cpu"), Runtime(ball_store, device="cpu", criterion="thesis")
    assert (screen.criterion.name, screen.error_bound) == ("screen", DEFAULT_ERROR_BOUND["screen"]) == ("screen", 0.8)
    assert (thesis.error_bound, thesis.alpha) == (0.25, 0.6)
    assert "detail" in ball_store_derived(screen) and "boxes" not in ball_store_derived(screen)
    assert "boxes" in ball_store_derived(thesis) and "detail" not in ball_store_derived(thesis)
    thesis.set_error_bound(0.2, alpha=0.5)
    assert thesis.criterion == ThesisCriterion(0.2, alpha=0.5)
    screen.set_error_bound(0.4, alpha=0.5)  # alpha checked, unread by the screen criterion
    assert screen.criterion == ScreenCriterion(0.4, target_psnr=36.0)  # the default target steers on from 0.4


def ball_store_derived(rt) -> set:
    return set(rt.samples.derived)


def test_registry_is_consistent():
    """Each registered criterion names itself, has its own kernel mode, reads known node bounds and lists its
    error bound first with the class default."""
    modes = set()
    for name, cls in CRITERIA.items():
        c = cls()
        assert c.name == name and cls.MODE not in modes
        modes.add(cls.MODE)
        assert set(cls.NODE_BOUNDS) <= {"detail", "box_centre", "box_half"} and cls.NODE_BOUNDS
        assert cls.KNOBS[0].name == "error_bound" and cls.KNOBS[0].default == c.error_bound == DEFAULT_ERROR_BOUND[name]
        assert {k.name for k in cls.KNOBS} <= {f.name for f in dataclasses.fields(cls)}
        assert c.with_bound(0.5) == dataclasses.replace(c, error_bound=0.5) and c.with_bound(0.5) is not c
        assert c.kernel_inputs(320, 240)[0] == cls.MODE
    assert ScreenCriterion().describe() == "screen criterion, error bound 0.8"
    assert ThesisCriterion(0.25, alpha=0.3).describe() == "thesis criterion, error bound 0.25, alpha 0.30"


def test_measured_frames_hold_geometry_at_the_default_rate():
    """S-1's geometric rate: a steered criterion's bound per pixel tolerance in motion (the geometric error held at
    pixel_tolerance pixels whatever the bound), the default bound's on E-5's measured still frame (as a fixed
    bound's); a fixed bound's rate and T-14's inputs do not depend on it."""
    from lodprt.runtime.criteria import PIXEL_TOLERANCE, SCREEN_BOUND

    for bound in (0.05, 0.8, 8.0):
        steered = ScreenCriterion(bound, target_psnr=36.0)
        assert steered.kernel_inputs(400, 300)[1] == pytest.approx(bound / PIXEL_TOLERANCE)
        assert steered.kernel_inputs(400, 300, True)[1] == pytest.approx(SCREEN_BOUND / PIXEL_TOLERANCE)
        fixed = ScreenCriterion(bound)
        assert fixed.kernel_inputs(400, 300, True) == fixed.kernel_inputs(400, 300, False)
        assert fixed.kernel_inputs(400, 300)[1] == pytest.approx(SCREEN_BOUND / PIXEL_TOLERANCE)
        thesis = ThesisCriterion(bound, alpha=0.3)
        assert thesis.kernel_inputs(400, 300, True) == thesis.kernel_inputs(400, 300) == (thesis.MODE, 1.0, 1.0, 0.3)


def parse(*argv):
    from lodprt.cli import args as cli_args
    from lodprt.cli.main import build_parser

    return cli_args.criterion(build_parser().parse_args(["frames", "some.zarr", *argv]))


def test_cli_options_make_the_criterion():
    """``--criterion thesis --alpha 0.3`` makes ThesisCriterion(0.25, 0.3); ``--alpha`` with the screen criterion is
    accepted and unread (as before the objects), though checked; ``--target-psnr`` with 'thesis' is refused naming it."""
    assert parse("--criterion", "thesis", "--alpha", "0.3") == ThesisCriterion(0.25, alpha=0.3)
    assert parse("--criterion", "thesis", "--error-bound", "0.1") == ThesisCriterion(0.1, alpha=0.6)
    assert parse() == ScreenCriterion()
    assert parse("--alpha", "0.3") == ScreenCriterion()
    assert parse("--target-psnr", "38", "--error-bound", "0.5") == ScreenCriterion(0.5, target_psnr=38.0)
    with pytest.raises(LodprtError, match="target_psnr 38.0: .*not with criterion 'thesis'"):
        parse("--criterion", "thesis", "--target-psnr", "38")
    for criterion in ("thesis", "screen"):  # unread by 'screen', yet checked: --alpha 7 was taken
        with pytest.raises(LodprtError, match="alpha 1.5: must lie in"):
            parse("--criterion", criterion, "--alpha", "1.5")
    with pytest.raises(SystemExit):  # argparse refuses a name the registry does not hold
        parse("--criterion", "nope")


def test_bad_names_and_settings_are_refused_naming_them(ball_store):
    """An unknown criterion, an unknown setting, a setting out of range, or an object with keyword settings
    besides: LodprtError naming the argument."""
    with pytest.raises(LodprtError, match="criterion 'nope': choose one of screen, thesis"):
        make_criterion("nope")
    with pytest.raises(LodprtError, match="criterion 'nope'"):
        Runtime(ball_store, device="cpu", criterion="nope")
    with pytest.raises(LodprtError, match="bogus: not a setting"):
        make_criterion("screen", bogus=1)
    with pytest.raises(LodprtError, match="alpha 1.5: must lie in"):
        ThesisCriterion(alpha=1.5)
    with pytest.raises(LodprtError, match="error_bound -1"):
        ScreenCriterion(error_bound=-1)
    with pytest.raises(LodprtError, match="pixel_tolerance 0"):
        make_criterion("screen", pixel_tolerance=0)
    with pytest.raises(LodprtError, match="target_psnr -3"):
        ScreenCriterion(target_psnr=-3)
    with pytest.raises(LodprtError, match="not also alpha"):
        Runtime(ball_store, device="cpu", criterion=ThesisCriterion(), alpha=0.3)
    with pytest.raises(LodprtError, match="not with a triangle_budget"):
        Runtime(ball_store, device="cpu", criterion=ScreenCriterion(target_psnr=38), triangle_budget=1000)


@pytest.mark.parametrize("criterion, knobs, absent", [
    ("screen", {"error_bound", "target_psnr", "pixel_tolerance"}, {"alpha"}),
    ("thesis", {"error_bound", "alpha"}, {"target_psnr", "pixel_tolerance"})])
def test_frame_stats_carry_only_the_active_criterions_knobs(ball_store, criterion, knobs, absent):
    """A frame's stats name the criterion and hold its own settings (the steered bound included), none of
    another criterion's (issue 26: a dead alpha was reported under the screen criterion)."""
    rt = Runtime(ball_store, device="cpu", criterion=criterion, alpha=0.3)
    stats = frames(rt, 1)[0].stats
    assert stats["criterion"] == criterion
    assert knobs <= set(stats) and not absent & set(stats)
    assert stats["error_bound"] == rt.error_bound
    if criterion == "thesis":
        assert stats["alpha"] == 0.3
