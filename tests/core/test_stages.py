"""Tests of :mod:`raytrad.core.stages`: the form-factor pass and the final gathers say how
far they have come, to the sink installed around a render, and to nobody else."""

from __future__ import annotations

import threading
from pathlib import Path

from raytrad import api
from raytrad.core import stages
from raytrad.settings import MeshSettings, RenderSettings
from tests.conftest import SCENES


def test_a_render_reports_every_column_and_every_gathered_patch(tmp_path: Path) -> None:
    seen: list[tuple[str, int, int]] = []
    settings = RenderSettings(mesh=MeshSettings(receivers=600, patches=40))
    with stages.reporting(lambda *event: seen.append(event)):
        outcome = api.render(SCENES / "cornell-box.obj", tmp_path, settings)
    patches = outcome.prepared.mesh.patch_count
    columns = [done for stage, done, total in seen if stage == stages.FORM_FACTORS]
    assert columns == list(range(1, patches + 1))  # each column once, in order, to the end
    assert {total for stage, _, total in seen} == {patches}
    gathered = [done for stage, done, _ in seen if stage == stages.FINAL_GATHER]
    rounds = outcome.refinement.rounds
    assert rounds >= 1 and gathered == list(range(1, patches + 1)) * rounds


def test_reports_go_nowhere_without_a_sink_and_not_to_another_thread() -> None:
    seen: list[tuple[str, int, int]] = []
    stages.report(stages.FORM_FACTORS, 1, 2)  # no sink: nothing, no error
    with stages.reporting(lambda *event: seen.append(event)):
        other = threading.Thread(target=stages.report, args=(stages.FORM_FACTORS, 1, 2))
        other.start()
        other.join()
        stages.report(stages.FINAL_GATHER, 3, 4)
    stages.report(stages.FORM_FACTORS, 2, 2)  # after the context: nothing
    assert seen == [(stages.FINAL_GATHER, 3, 4)]
