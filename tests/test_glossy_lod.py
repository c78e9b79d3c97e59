"""LOD of the glossy transfer matrices (``--lod-threshold``): only the cut's glossy vertices get a matrix, the
others are completed with T-15 on reading, exactly like the diffuse vectors."""

import numpy as np
import pytest

from lodprt.model import environment as E
from lodprt.model.hierarchy_build import build_hierarchy
from lodprt.model.scene import Material, assemble_scene
from lodprt.precompute import transfer as T
from lodprt.runtime import environment_relight as relight
from lodprt.store.transfer_store import complete_glossy

from test_transfer import icosphere

EYE = (0.4, 1.2, 1.6)


@pytest.fixture(scope="module")
def scene_and_tree():
    """A shiny ball (642 vertices) on a matte 24 x 24 floor: glossy and non-glossy vertices in one cut."""
    pos, faces = icosphere(3, 0.5, (0, 0.5, 0))
    shiny = Material(kd=(0.5, 0.4, 0.3), ks=0.4, shininess=8.0)
    matte = Material(kd=(0.6, 0.6, 0.6), ks=0.0, shininess=1.0)
    scene = assemble_scene([("ball", pos, faces, shiny)], (24, 1.0, matte), {}, "lights", "ball")
    return scene, build_hierarchy(scene.positions, scene.faces, scene.normals)


@pytest.fixture(scope="module")
def full_bake(scene_and_tree, tmp_path_factory):
    scene, _ = scene_and_tree
    out = tmp_path_factory.mktemp("glossy-lod") / "full.zarr"
    T.bake_transfer(scene, out, sh_order=3, mode="shadowed", rays=256, device="cpu", jobs=1)
    return relight.open_transfer(out)


def glossy_only(store, lighting):
    ids, m = store.glossy()
    mid = store.read("scene/material_id")[ids]
    return relight.glossy_radiance(m, store.read("scene/positions")[ids].astype(np.float64),
                                   store.read("scene/normals").astype(np.float64)[ids], store.read("materials/ks")[mid],
                                   store.read("materials/shininess")[mid], lighting, EYE)


@pytest.mark.warp_debug
def test_cut_store_keeps_exact_matrices_and_relights_close(scene_and_tree, full_bake, tmp_path):
    """At the kept vertices the completed matrices are the full bake's bit for bit; elsewhere T-15 fills them and
    the glossy radiance under the sky is within 4% rel-RMSE (measured 2.3%, half the ball's matrices kept) of the
    full-resolution bake."""
    scene, tree = scene_and_tree
    out = tmp_path / "lod.zarr"
    res = T.bake_transfer(scene, out, sh_order=3, mode="shadowed", rays=256, device="cpu", jobs=1, lod_threshold=0.2,
                          tree=tree)
    lod = relight.open_transfer(out)
    ids_full, m_full = full_bake.glossy()
    ids, m = lod.glossy()
    assert np.array_equal(ids, ids_full) and m.shape == m_full.shape
    kept = lod.read("transfer/glossy_kept_ids")
    assert 0 < len(kept) < len(ids) and lod.read("transfer/glossy").shape == (len(kept), 9, 9)
    assert lod.attrs["glossy_kept"] == len(kept) and np.array_equal(kept, res.glossy_kept_ids)
    assert set(kept) <= set(tree.vertex[res.cut_nodes]) and set(kept) <= set(ids)
    at = np.searchsorted(ids, kept)
    assert np.array_equal(m[at], m_full[at])  # exact at kept vertices
    L = E.procedural("sky", resolution=16).project(3)
    g_full, g_lod = glossy_only(full_bake, L), glossy_only(lod, L)
    err = np.linalg.norm(g_lod - g_full) / np.linalg.norm(g_full)
    assert 0 < err < 0.04, err
    total = np.linalg.norm(relight.relit_radiance(lod, L, EYE) - relight.relit_radiance(full_bake, L, EYE))
    assert total / np.linalg.norm(relight.relit_radiance(full_bake, L, EYE)) < 0.04


def test_threshold_zero_equals_the_full_bake(scene_and_tree, full_bake, tmp_path):
    """At threshold 0 only identical diffuse vectors collapse (here: none on the ball): every glossy matrix is kept
    and the glossy radiance is the full bake's exactly. (Identical floor vectors do collapse; T-15 then completes
    them from ring neighbours, so the diffuse part matches only where those agree.)"""
    scene, tree = scene_and_tree
    out = tmp_path / "lod0.zarr"
    T.bake_transfer(scene, out, sh_order=3, mode="shadowed", rays=256, device="cpu", jobs=1, lod_threshold=0.0, tree=tree)
    lod = relight.open_transfer(out)
    L = E.procedural("spots", resolution=16).project(3)
    assert np.array_equal(lod.read("transfer/glossy_kept_ids"), full_bake.glossy()[0])
    assert np.array_equal(lod.glossy()[1], full_bake.glossy()[1])
    assert np.array_equal(glossy_only(lod, L), glossy_only(full_bake, L))


def test_complete_glossy_is_linear_completion(scene_and_tree):
    """complete_glossy = T-15 of each matrix entry: a field linear in position completes exactly (linear precision
    on the flat floor is not needed: constant matrices over a connected glossy object stay constant)."""
    scene, tree = scene_and_tree
    ball = np.flatnonzero(scene.object_id == 0)
    cut = T.transfer_cut(tree, np.ones((scene.num_vertices, 1)), 0.0)  # everything collapses to the roots
    cut_v = tree.vertex[cut]
    kept = np.sort(np.intersect1d(cut_v, ball))
    m = np.tile(np.arange(81, dtype=np.float64).reshape(1, 9, 9), (len(kept), 1, 1))
    done = complete_glossy(tree, scene.positions, scene.normals, cut, kept, m, ball)
    assert np.allclose(done, np.arange(81).reshape(9, 9)[None], atol=1e-9)
