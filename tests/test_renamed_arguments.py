"""One name per concept across the bakes' Python API: ``sh_order`` and ``bounce_threshold`` everywhere (as the CLI's
``--sh-order`` / ``--bounce-threshold`` and the stores' attributes), the old keyword names still accepted with a
DeprecationWarning, and never both."""

from __future__ import annotations

import inspect
import warnings

import numpy as np
import pytest

from lodprt.deprecation import renamed_arguments
from lodprt.errors import LodprtError
from lodprt.precompute.bake import bake
from lodprt.precompute.neighbourhood import bake_neighbourhood
from lodprt.precompute.transfer import bake_transfer
from lodprt.precompute.volume import bake_volume


@pytest.mark.parametrize("fn", [bake, bake_transfer, bake_volume, bake_neighbourhood])
def test_every_bake_names_the_sh_bands_sh_order(fn):
    params = inspect.signature(fn).parameters
    assert "sh_order" in params and "order" not in params
    assert "threshold" not in params  # the pass-energy stop is bounce_threshold wherever a bake has one
    if fn is not bake_neighbourhood:
        assert "bounce_threshold" in params


def test_old_name_warns_and_maps_to_the_new_one():
    @renamed_arguments(order="sh_order")
    def f(*, sh_order=3):
        return sh_order

    assert f(sh_order=5) == 5
    with pytest.warns(DeprecationWarning, match=r"f\(order=...\) is now sh_order="):
        assert f(order=2) == 2
    with pytest.raises(LodprtError, match="not both sh_order and its old name order"):
        f(order=2, sh_order=3)


def test_volume_bake_same_result_under_the_old_names(tmp_path):
    from lodprt.model.volume import procedural_volume

    vol = procedural_volume("cloud:6")
    new = bake_volume(vol, None, sh_order=2, rays=8, bounces=1, bounce_threshold=0.5, device="cpu")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        old = bake_volume(vol, None, order=2, rays=8, bounces=1, threshold=0.5, device="cpu")
    np.testing.assert_array_equal(new.transfer.transfer, old.transfer.transfer)
    assert new.transfer.threshold == old.transfer.threshold == 0.5
