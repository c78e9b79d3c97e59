"""Shared fixtures: every available Warp device, and the shared test meshes."""

from pathlib import Path

import pytest

from lodprt.devices import available_devices

REPO = Path(__file__).resolve().parents[1]
MODELS = REPO.parent / "shared" / "models"


@pytest.fixture(params=available_devices())
def device(request):
    """Each available Warp device in turn ("cpu", then every "cuda:N")."""
    return request.param


@pytest.fixture(scope="session")
def bunny_path():
    """The shared Stanford bunny (34,834 referenced vertices); tests that need it skip when shared/ is absent."""
    p = MODELS / "stanford-bunny.obj"
    if not p.is_file():
        pytest.skip("../shared/models/stanford-bunny.obj is not present")
    return p
