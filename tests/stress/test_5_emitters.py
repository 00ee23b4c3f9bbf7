"""Group 5: awkward emitters.

Independent expectations: the exact power balance of closed scenes of uniform reflectance
(sum_j a_j B_j = emitted power / (1 - rho)), with the emitted power known from the
geometry; the continuity of irradiance across the coplanar rim of a lamp (which reflects
like its neighbour: B_lamp - E = B_ceiling there); the mirror symmetry of a double-sided
panel in the middle of a cube.
"""

from __future__ import annotations

import numpy as np
import pytest

from .cases import (
    BULB_EXITANCE,
    BULB_SIDE,
    LED_AREA,
    LED_COUNT,
    LED_EXITANCE,
    PANEL_EXITANCE,
    PANEL_SIDE,
    REFLECTING_LAMP,
    assert_finished,
    assert_within,
    case,
    lamp_continuity_error,
    panel_sides_error,
    run_case,
)


def test_tiny_bright_bulb_in_a_huge_hall() -> None:
    # 1e-6 m2 at 1e9 W m-2 in a 10 m hall of rho = 0.9: sum a B = 1000 W / 0.1.
    # Physical limit: the bulb's back (black, single-sided) faces the ceiling 1 mm away and
    # swallows a little light; it is 1e-6 m2 of 600 m2, far below the 1% tolerance.
    run = run_case(case("tiny-bulb"))
    assert_finished(run)
    np.testing.assert_allclose(run.result.emitted_power, BULB_SIDE**2 * BULB_EXITANCE, rtol=1e-9)
    assert_within(run)
    # the floor right under the bulb is lit directly: B >= rho E A / (pi h^2)
    mesh = run.mesh
    floor = (mesh.receiver_position[:, 1] == 0.0) & (mesh.receiver_normal[:, 1] > 0.99)
    below = floor & (np.linalg.norm(mesh.receiver_position[:, [0, 2]] - 5.0, axis=1) < 0.5)
    direct = 0.9 * BULB_EXITANCE * BULB_SIDE**2 / (np.pi * 10.0**2)
    assert below.any()
    assert (run.result.radiosity[below] > 0.9 * direct).all()


@pytest.mark.slow
def test_a_thousand_small_emitters() -> None:
    # 1000 double-sided triangles of 2e-4 m2 at 100 W m-2: 40 W, sum a B = 400 W.
    run = run_case(case("1000-emitters"))
    assert_finished(run)
    emitted = 2 * LED_COUNT**3 * LED_AREA * LED_EXITANCE
    np.testing.assert_allclose(run.result.emitted_power, emitted, rtol=1e-9)
    assert run.mesh.patch_count >= 2 * LED_COUNT**3  # every side of every light shoots
    assert_within(run)


def test_emitter_that_also_reflects() -> None:
    # A 0.2 m ceiling cell (E = 10, rho = 0.9 like the rest): 0.4 W, sum a B = 4 W; on the
    # lamp's rim it reflects the same irradiance as the ceiling next to it.
    run = run_case(case("reflecting-lamp"))
    assert_finished(run)
    assert_within(run)
    assert lamp_continuity_error(run) < 0.01
    lamp = run.mesh.receiver_emitted_exitance[:, 0] > 0
    assert (run.result.radiosity[lamp] > 1.01 * REFLECTING_LAMP).all()


def test_emission_on_both_sides_of_a_double_sided_quad() -> None:
    # 0.16 m2 at 5 W m-2 per side: 1.6 W; sum a B = 16 W; both sides alike by symmetry.
    run = run_case(case("double-sided-emitter"))
    assert_finished(run)
    emitted = 2 * PANEL_SIDE**2 * PANEL_EXITANCE
    np.testing.assert_allclose(run.result.emitted_power, emitted, rtol=1e-9)
    assert_within(run)
    assert panel_sides_error(run) < 0.01
