"""benchmarks/procedural.py: the procedural and decimated scenes the view-cut benchmark measures besides the three
shared models -- closed and wound outward where the shape is closed, the triangle counts, the same arrays from the
same seed, scene files lodprt loads, and fins that really are thin."""

import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

import procedural  # noqa: E402

#: object triangles per scene, from the construction (``procedural.grid_box``: 4 (nx ny + ny nz + nx nz))
EXPECTED = {
    "comb": 4 * (32 * 2 + 2 * 16 + 32 * 16) + procedural.COMB_FINS * 4 * (1 * 24 + 24 * 24 + 1 * 24),
    "relief": 20 * 4 ** 5,
    "crowd": 8 * 20 * 4 ** 3 + 8 * 4 * 3 * 36 + 8 * 2 * 48 * 16,
    "terrain": 4 * (100 * 1 + 1 * 100 + 100 * 100),
    "speck": 2 * 160 * 32,
    "rough": 59_000,
}


@pytest.fixture(scope="module")
def scenes():
    return {name: procedural.scene_meshes(name, seed=0) for name in procedural.SCENES}


def edges_manifold(faces: np.ndarray) -> bool:
    """Every undirected edge in exactly two faces, and every directed edge in one (consistent winding)."""
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    undirected = np.sort(directed, axis=1)
    _, counts = np.unique(undirected, axis=0, return_counts=True)
    _, dcounts = np.unique(directed, axis=0, return_counts=True)
    return bool((counts == 2).all() and (dcounts == 1).all())


def signed_volume(pos: np.ndarray, faces: np.ndarray) -> float:
    a, b, c = pos[faces[:, 0]], pos[faces[:, 1]], pos[faces[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6)


@pytest.mark.parametrize("name", procedural.CLOSED)
def test_closed_scenes_are_watertight_and_wound_outward(scenes, name):
    import trimesh

    for obj, pos, faces in scenes[name]["objects"]:
        assert edges_manifold(faces), obj
        assert trimesh.Trimesh(pos, faces, process=False).is_watertight, obj
        # closed and outward: the signed volume is positive (each part of the comb on its own, too)
        assert signed_volume(pos, faces) > 0, obj
        # the ground contact: every object stands on y = 0
        assert pos[:, 1].min() == pytest.approx(0.0, abs=1e-12), obj


def test_comb_parts_are_each_closed_and_outward(scenes):
    import trimesh

    _, pos, faces = scenes["comb"]["objects"][0]
    parts = trimesh.Trimesh(pos, faces, process=False).split(only_watertight=False)
    assert len(parts) == procedural.COMB_FINS + 1
    assert all(p.is_watertight and p.volume > 0 for p in parts)


@pytest.mark.parametrize("name", list(EXPECTED))
def test_triangle_counts(scenes, name):
    assert sum(len(f) for _, _, f in scenes[name]["objects"]) == EXPECTED[name]


def test_every_scene_is_small_enough_to_bake_in_seconds(scenes):
    for name, spec in scenes.items():
        tris = sum(len(f) for _, _, f in spec["objects"])
        assert 5_000 < tris <= procedural.MAX_TRIANGLES, name
    assert sum(len(f) for _, _, f in scenes["comb"]["objects"]) >= 20_000  # "tens of thousands"
    assert len(scenes["crowd"]["objects"]) == procedural.CROWD_OBJECTS


def test_bunny_coarse_is_a_quarter_of_the_bunny_and_outward(scenes):
    from lodprt.model.scene import load_mesh

    _, faces = load_mesh(REPO / "tests" / "data" / "stanford-bunny.obj.xz")
    _, pos, coarse = scenes["bunny-coarse"]["objects"][0]
    assert abs(len(coarse) - len(faces) // 4) <= 0.01 * len(faces)
    assert signed_volume(pos, coarse) > 0  # open (holes in its base) but wound outward


def test_rough_is_the_decimated_bunny_moved_along_its_normals(scenes):
    """``rough``: the bunny decimated to ROUGH_FACES, just under MAX_TRIANGLES (pymeshlab, the same faces), each
    vertex moved along its normal (nothing tangential) by white noise whose spread is ROUGH_NOISE median edges; wound
    outward."""
    import trimesh

    _, pos, faces = scenes["rough"]["objects"][0]
    base_pos, base_faces = procedural.decimated_bunny(procedural.ROUGH_FACES)
    np.testing.assert_array_equal(faces, base_faces)
    base = trimesh.Trimesh(base_pos, base_faces, process=False)
    move = pos - base_pos
    along = np.einsum("ij,ij->i", move, base.vertex_normals)
    np.testing.assert_allclose(move, along[:, None] * base.vertex_normals, atol=1e-12)
    step = procedural.ROUGH_NOISE * np.median(base.edges_unique_length)
    assert abs(along.std() / step - 1) < 0.03 and abs(along.mean()) < 0.03 * step
    assert signed_volume(pos, faces) > 0


def test_fins_are_thin(scenes):
    """Every fin is a box exactly FIN_WIDTH thick along x, under 4% of its height (0.7 to 1 FIN_HEIGHT) and 40 times
    thinner than deep."""
    _, pos, faces = scenes["comb"]["objects"][0]
    base_top = procedural.COMB_BASE[1]
    fin = pos[:, 1] > base_top + 1e-9  # vertices above the base belong to fins only
    bx = procedural.COMB_BASE[0]
    pitch = bx / (procedural.COMB_FINS + 1)
    slot = np.rint((pos[fin, 0] + bx / 2) / pitch).astype(int)
    assert sorted(set(slot.tolist())) == list(range(1, procedural.COMB_FINS + 1))
    for k in range(1, procedural.COMB_FINS + 1):
        x = pos[fin][slot == k]
        width = x[:, 0].max() - x[:, 0].min()
        height = x[:, 1].max() - (base_top - 0.01)
        assert width == pytest.approx(procedural.FIN_WIDTH, rel=1e-9)
        assert width < 0.04 * height
        assert width * 40 <= x[:, 2].max() - x[:, 2].min()
    assert procedural.FIN_WIDTH / procedural.FIN_HEIGHT == pytest.approx(0.025)


def test_sizes_spread_in_the_crowd_and_the_speck_is_small(scenes):
    extents = [np.ptp(pos, axis=0).max() for _, pos, _ in scenes["crowd"]["objects"]]
    assert max(extents) / min(extents) > 10
    _, pos, _ = scenes["speck"]["objects"][0]
    assert np.ptp(pos, axis=0).max() < 0.06
    assert scenes["speck"]["floor"][1] >= 10  # the floor reaches many object sizes beyond it


def test_same_seed_same_arrays_other_seed_other_arrays():
    for name in ("comb", "relief", "crowd", "terrain", "speck"):
        a, b = procedural.scene_meshes(name, seed=3), procedural.scene_meshes(name, seed=3)
        for (na, pa, fa), (nb, pb, fb) in zip(a["objects"], b["objects"], strict=True):
            assert na == nb
            np.testing.assert_array_equal(pa, pb)
            np.testing.assert_array_equal(fa, fb)
        c = procedural.scene_meshes(name, seed=4)
        assert any(not np.array_equal(pa, pc) for (_, pa, _), (_, pc, _) in zip(a["objects"], c["objects"]))


@pytest.mark.parametrize("name", ["comb", "crowd", "speck"])
def test_scene_files_load(tmp_path, name):
    from lodprt.model.scene import load_scene

    spec = procedural.scene_meshes(name)
    scene = load_scene(procedural.write_scene(name, tmp_path, seed=0))
    tris = sum(len(f) for _, _, f in spec["objects"])
    resolution = spec["floor"][0]
    assert len(scene.faces) == tris + 2 * (resolution - 1) ** 2
    verts = sum(len(p) for _, p, _ in spec["objects"])
    np.testing.assert_allclose(np.asarray(scene.positions)[:verts], np.concatenate(
        [p for _, p, _ in spec["objects"]]), atol=1e-6 * 4)


def test_view_cut_scene_selection():
    from argparse import Namespace

    import view_cut

    def names(**kw):
        return view_cut.scene_names(Namespace(**{"quick": False, "scenes": None, "only": None, **kw}))

    assert names() == (list(view_cut.MODELS_USED), list(procedural.SCENES))
    assert names(quick=True) == (["stanford-bunny"], [])
    assert names(scenes="procedural") == ([], list(procedural.SCENES))
    assert names(scenes="shared") == (list(view_cut.MODELS_USED), [])
    assert names(only=["comb", "spot"]) == (["spot"], ["comb"])
    with pytest.raises(SystemExit):
        names(only=["nonesuch"])


def static_row(scene, family, view, setting, psnr, fewer):
    """A row of view_cut.py's static views under one of its STATIC_SETTINGS."""
    criterion = {"default": "screen (target 36 dB)", "screen": "screen (bound 0.8)", "thesis": "thesis"}[setting]
    return {"scene": scene, "family": family, "view": view, "setting": setting, "criterion": criterion,
            "triangles": round(1000 / fewer), "full": 1000, "fewer": fewer, "psnr_db": psnr,
            "estimated_psnr_db": psnr - 2.0 if setting == "default" else float("nan"),
            "grid_psnr_db": psnr - 3.0 if setting == "default" else float("nan")}


def test_static_summary_and_its_tables():
    import report_tables
    import view_cut

    rows = [static_row("spot", "shared", "front", "default", 39.0, 5.0),
            static_row("spot", "shared", "front", "screen", 41.0, 6.0),
            static_row("spot", "shared", "front", "thesis", 25.0, 60.0),
            static_row("comb", "procedural", "front", "screen", 33.5, 9.0),
            static_row("comb", "procedural", "default eye", "screen", 39.0, 3.5),
            static_row("comb", "procedural", "front", "thesis", 20.0, 50.0),
            static_row("comb", "procedural", "default eye", "thesis", 22.0, 40.0)]
    summary = view_cut.static_summary(rows)
    assert [s["criterion"] for s in summary] == ["default", "screen", "thesis"]
    assert (summary[0]["rows"], summary[0]["worst_psnr_db"], summary[0]["least_fewer"]) == (1, 39.0, 5.0)
    screen = summary[1]
    assert (screen["rows"], screen["worst_psnr_db"], screen["least_fewer"]) == (3, 33.5, 3.5)
    assert summary[2]["worst_psnr_db"] == 20.0 and summary[2]["least_fewer"] == 40.0
    assert screen["worst_psnr_at"] == "comb, front" and screen["least_fewer_at"] == "comb, default eye"
    r = {"floor": 200, "static_views": rows, "static_summary": summary}
    shared = report_tables.view_cut_static(r)
    assert "spot + 200" in shared and "comb" not in shared
    assert "| 200 / 1,000 | 5.0 | 39.0 dB | 37.0 dB | 36.0 dB | 6.0 | 41.0 dB | 60 | 25.0 dB |" in shared  # the default beside the fixed bound
    made = report_tables.view_cut_procedural(r)
    assert "| comb | front |" in made and "spot" not in made
    assert "33.5 dB | comb, front" in report_tables.view_cut_summary(r)
    old = {"floor": 200, "static_views": rows[:3]}  # results from before the procedural scenes
    assert report_tables.view_cut_procedural(old) == report_tables.NOT_MEASURED
    assert report_tables.view_cut_summary(old) == report_tables.NOT_MEASURED


def test_the_script_writes_the_scene_files(tmp_path, capsys):
    procedural.main([str(tmp_path), "--only", "speck", "relief"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["relief.obj", "relief.toml", "speck.obj", "speck.toml"]
    assert "10,240 object triangles" in capsys.readouterr().out
