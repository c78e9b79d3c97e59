"""The run time's numeric settings (``lodprt.runtime.settings``): every checker takes the numbers of its range,
edges included or not as documented, and refuses anything else -- no number, nan, infinities, out of range -- with a
LodprtError that names the setting and the value, where the user hands it over (Runtime, criteria)."""

import math
import re

import numpy as np
import pytest

from lodprt.errors import LodprtError, is_number, is_whole, shown
from lodprt.runtime import settings
from lodprt.runtime.criteria import make_criterion

#: checker, field, values it keeps (given -> returned), values it refuses
CASES = [
    (settings.check_bound, "error_bound", [(0, 0.0), (0.8, 0.8), (np.float32(2), 2.0), (np.array(0.5), 0.5), (1e9, 1e9)],
     [-1e-12, -1, math.nan, math.inf, "loose", None, "2", True, np.array([0.5, 0.5])]),
    (settings.check_alpha, "alpha", [(0, 0.0), (1, 1.0), (0.6, 0.6)], [-0.01, 1.01, math.nan, "a"]),
    (settings.check_target, "target_psnr", [(200, 200.0), (36, 36.0), ("off", None), (" OFF ", None), (None, None)],
     [0, -3, 200.5, math.nan, math.inf, "high"]),
    (settings.check_frame_ms, "frame_ms", [(1e6, 1e6), (0.5, 0.5), (None, None)],
     [0, -1, 2e6, math.nan, math.inf, "fast"]),
    (settings.check_triangle_budget, "triangle_budget", [(1, 1), (4000.0, 4000), (np.int64(12), 12), (None, None)],
     [0, 0.5, 2.5, -4, math.inf, math.nan, "many", "12", True]),
]


@pytest.mark.parametrize("check, field, good, bad", CASES, ids=[c[1] for c in CASES])
def test_each_setting_keeps_its_range_and_names_itself_outside_it(check, field, good, bad):
    for given, kept in good:
        got = check(given)
        assert got == kept and type(got) is type(kept)
    for value in bad:  # named in one line: a string by its repr, an array by its shape, never numpy's repr
        with pytest.raises(LodprtError, match=rf"^{field} {re.escape(shown(value))}: must ") as e:
            check(value)
        assert "\n" not in str(e.value)


def test_a_number_is_one_notion_across_the_settings():
    """``is_number`` (the float settings, the camera) and ``is_whole`` (the whole-number ones) agree on what a
    number is: numpy scalars and a 0-d array are, a bool, a string or an array of several are not; ``shown``
    gives a bad value in one short line."""
    for value in (2, 2.0, np.float32(2), np.int8(2), np.array(2.0), np.array(2)):
        assert is_number(value) and is_whole(value, 1, 3)
    for value in (True, np.bool_(True), "2", b"2", None, [2], np.array([2.0]), np.array(True)):
        assert not is_number(value) and not is_whole(value, 1, 3)
    assert shown(np.zeros((50, 3))) == "an array of shape (50, 3) (float64)"
    assert shown("x" * 200).endswith("...") and len(shown("x" * 200)) == 60
    assert "\n" not in shown(np.zeros((50, 3)).tolist()) and shown(0.5) == "0.5"


def test_criteria_refuse_bad_settings_by_name():
    """What the criteria hand over goes through the same checks: a bound or an alpha that is no number is a
    LodprtError naming it (it was a bare ValueError), and so is a pixel tolerance of 0."""
    for kwargs, field in (({"error_bound": "x"}, "error_bound"), ({"alpha": "x"}, "alpha"),
                          ({"pixel_tolerance": 0}, "pixel_tolerance"), ({"target_psnr": 0}, "target_psnr")):
        name = "thesis" if "alpha" in kwargs else "screen"
        with pytest.raises(LodprtError, match=field):
            make_criterion(name, **kwargs)


def test_is_whole_against_the_written_out_rule():
    """``lodprt.errors.is_whole``, which the whole-number settings share (SH orders, rays, bounces, mip levels,
    jobs, camera sizes): an int or a float equal to one in the range, never a bool, a string, NaN or inf; with
    ``integer_type`` no float either. Python's unbounded ints and numpy's types included."""
    import numpy as np

    from lodprt.errors import is_whole

    for value in (3, 3.0, np.int64(3), np.float32(3), np.uint8(3)):
        assert is_whole(value, 1, 8)
    for value in (3.5, True, np.bool_(True), "3", None, math.nan, math.inf, 0, 9, [3]):
        assert not is_whole(value, 1, 8)
    assert is_whole(10**400) and not is_whole(10**400, high=1e300) and not is_whole(-(10**400), 0)
    assert is_whole(3, integer_type=True) and is_whole(np.int32(3), integer_type=True)
    assert not is_whole(3.0, integer_type=True) and not is_whole(False, integer_type=True)


@pytest.mark.parametrize("call", ["mip", "gi", "transfer"])
def test_a_whole_number_setting_given_a_word_is_named(call):
    """A word where a whole number belongs is the setting's own LodprtError (``int("x")`` raised ValueError)."""
    from lodprt.model.environment import load_environment
    from lodprt.precompute.gi import GISettings

    with pytest.raises(LodprtError, match={"mip": "mip level 'x'", "gi": "bounces 'x'", "transfer": "glossy order"}[call]):
        if call == "mip":
            load_environment("constant").mip("x")
        elif call == "gi":
            GISettings("x", 0.01, 64, None)
        else:
            from lodprt.precompute.transfer import check_glossy_order

            check_glossy_order("x")
