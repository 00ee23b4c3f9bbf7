"""Settings validate themselves, take a scene file's output defaults only where left at
None, and list the solver methods from the registry."""

from __future__ import annotations

import pytest

from raytrad.core.solver import SHOOTING_METHODS
from raytrad.settings import (
    ImageSettings,
    LightmapSettings,
    MeshSettings,
    RenderSettings,
    SettingsError,
    SolveSettings,
    method_summaries,
    with_scene_defaults,
)

FILE = {
    "exposure": -1.5,
    "lightmap_resolution": 256,
    "texel_density": 100.0,
    "image_width": 300,
    "image_height": 200,
}


def test_scene_defaults_fill_what_is_left_at_none() -> None:
    settings = RenderSettings(lightmap=LightmapSettings(), image=ImageSettings())
    resolved = with_scene_defaults(settings, FILE)
    assert resolved.exposure == -1.5
    assert resolved.lightmap is not None and resolved.image is not None
    assert resolved.lightmap.resolution == 256 and resolved.lightmap.texel_density == 100.0
    assert (resolved.image.width, resolved.image.height) == (300, 200)


def test_given_settings_win_over_the_scene_file() -> None:
    settings = RenderSettings(
        exposure=0.0,
        lightmap=LightmapSettings(resolution=64, texel_density=7.0),
        image=ImageSettings(width=10, height=20),
    )
    resolved = with_scene_defaults(settings, FILE)
    assert resolved.exposure == 0.0  # an explicit 0 is not "not given"
    assert resolved.lightmap == settings.lightmap and resolved.image == settings.image


def test_without_a_scene_file_the_defaults_apply() -> None:
    resolved = with_scene_defaults(
        RenderSettings(lightmap=LightmapSettings(), image=ImageSettings()), {}
    )
    assert resolved.exposure == 0.0
    assert resolved.lightmap is not None and resolved.lightmap.resolution == 1024
    assert resolved.lightmap.texel_density is None
    assert resolved.image is not None and resolved.image.width is None
    assert resolved.image.height == 480


@pytest.mark.parametrize(
    "make",
    [
        lambda: MeshSettings(receivers=0),
        lambda: MeshSettings(max_edge=-1.0),
        lambda: MeshSettings(patch_size=0.0),
        lambda: MeshSettings(emitter_samples=0),
        lambda: SolveSettings(method="jacobi"),
        lambda: SolveSettings(tolerance=0.0),
        lambda: SolveSettings(omega=2.0),
        lambda: RenderSettings(scale=float("nan")),
        lambda: RenderSettings(cache_mb=-1.0),
        lambda: LightmapSettings(resolution=0),
        lambda: LightmapSettings(resolution=4),
        lambda: ImageSettings(width=0),
        lambda: ImageSettings(height=0),
        lambda: ImageSettings(tonemap="reinhard"),
    ],
)
def test_invalid_settings_are_refused(make: object) -> None:
    with pytest.raises(SettingsError):
        make()  # type: ignore[operator]


def test_method_summaries_come_from_the_registry() -> None:
    summaries = method_summaries()
    assert list(summaries) == list(SHOOTING_METHODS)
    for name, method in SHOOTING_METHODS.items():
        assert summaries[name] and summaries[name] == method.summary
        assert method.amount.__doc__ is not None
        assert method.amount.__doc__.strip().startswith(summaries[name])
    # the methods whose overshoot rests on the ambient estimate are damped when it misleads
    damped = [n for n, m in SHOOTING_METHODS.items() if m.damped]
    assert damped == ["ambient", "enhanced_super_shoot_gather"]
    gathering = [n for n, m in SHOOTING_METHODS.items() if m.patch_factors]
    assert gathering == ["positive", "super_shoot_gather", "enhanced_super_shoot_gather"]


def test_system_settings_are_the_mesh_and_the_scale() -> None:
    settings = RenderSettings(mesh=MeshSettings(receivers=123), scale=0.5)
    system = settings.system_settings()
    assert system == {"mesh": system["mesh"], "scale": 0.5}
    assert system["mesh"]["receivers"] == 123
