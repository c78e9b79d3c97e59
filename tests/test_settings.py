"""The run time's numeric settings (``lodprt.runtime.settings``): every checker takes the numbers of its range,
edges included or not as documented, and refuses anything else -- no number, nan, infinities, out of range -- with a
LodprtError that names the setting and the value, where the user hands it over (Runtime, criteria)."""

import math

import pytest

from lodprt.errors import LodprtError
from lodprt.runtime import settings
from lodprt.runtime.criteria import make_criterion

#: checker, field, values it keeps (given -> returned), values it refuses
CASES = [
    (settings.check_bound, "error_bound", [(0, 0.0), (0.8, 0.8), ("2", 2.0), (1e9, 1e9)],
     [-1e-12, -1, math.nan, math.inf, "loose", None]),
    (settings.check_alpha, "alpha", [(0, 0.0), (1, 1.0), (0.6, 0.6)], [-0.01, 1.01, math.nan, "a"]),
    (settings.check_target, "target_psnr", [(200, 200.0), (36, 36.0), ("off", None), (" OFF ", None), (None, None)],
     [0, -3, 200.5, math.nan, math.inf, "high"]),
    (settings.check_frame_ms, "frame_ms", [(1e6, 1e6), (0.5, 0.5), (None, None)],
     [0, -1, 2e6, math.nan, math.inf, "fast"]),
    (settings.check_triangle_budget, "triangle_budget", [(1, 1), (4000.0, 4000), ("12", 12), (None, None)],
     [0, 0.5, 2.5, -4, math.inf, math.nan, "many"]),
]


@pytest.mark.parametrize("check, field, good, bad", CASES, ids=[c[1] for c in CASES])
def test_each_setting_keeps_its_range_and_names_itself_outside_it(check, field, good, bad):
    for given, kept in good:
        got = check(given)
        assert got == kept and type(got) is type(kept)
    for value in bad:
        with pytest.raises(LodprtError, match=rf"^{field} {value}: must "):
            check(value)


def test_criteria_refuse_bad_settings_by_name():
    """What the criteria hand over goes through the same checks: a bound or an alpha that is no number is a
    LodprtError naming it (it was a bare ValueError), and so is a pixel tolerance of 0."""
    for kwargs, field in (({"error_bound": "x"}, "error_bound"), ({"alpha": "x"}, "alpha"),
                          ({"pixel_tolerance": 0}, "pixel_tolerance"), ({"target_psnr": 0}, "target_psnr")):
        name = "thesis" if "alpha" in kwargs else "screen"
        with pytest.raises(LodprtError, match=field):
            make_criterion(name, **kwargs)
