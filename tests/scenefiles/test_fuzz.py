"""Seeded mutation fuzzing of every scene format: a malformed file loads into a valid scene
or is refused with one ``SceneError`` line, never a traceback, a hang or a non-finite scene.

Each case mutates a valid file (byte flips, cut short, a line dropped or repeated, a
number replaced by an extreme: nan, inf, 1e39, 1e300, -1, 0, a huge count) and loads it,
then meshes what loaded at 300 receivers, each under a 20 s alarm. The default run tries
``RAYTRAD_FUZZ_CASES`` (default 40) mutations per format; set it higher for a long run
(``RAYTRAD_FUZZ_CASES=2000 pytest tests/scenefiles/test_fuzz.py``). A failing case's
file is kept under pytest's ``tmp_path`` and named in the message.
"""

from __future__ import annotations

import os
import random
import re
import shutil
import signal
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from raytrad.core.mesh import MeshSettings, build_mesh
from raytrad.core.repair import repair_scene
from raytrad.errors import RaytradError
from raytrad.scenefiles import load_scene
from tests.conftest import SCENES

CASES = int(os.environ.get("RAYTRAD_FUZZ_CASES", "40"))
SECONDS = 20
EXTREMES = [b"nan", b"inf", b"-inf", b"1e39", b"-1e39", b"1e300", b"-1", b"0", b"4294967295"]
NUMBER = re.compile(rb"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")

#: The seed files: (name, bundled files copied beside it).
SEEDS = {
    "cornell-box.obj": ["cornell-box.mtl"],
    "cornell-box-uv.glb": [],
    "shadow.glb": [],
    "colour-room.toml": ["cornell-box.obj", "cornell-box.mtl"],
}


def _ply_seed(directory: Path, binary: bool) -> Path:
    """A Cornell box PLY with face materials, ASCII or binary, written by hand."""
    from tests.scenefiles.test_ply_conformance import _files

    path = directory / ("seed-binary.ply" if binary else "seed-ascii.ply")
    path.write_bytes(_files()["binary little endian" if binary else "ascii"])
    return path


def _mutate(data: bytes, rng: random.Random) -> bytes:
    """One random mutation of a file's bytes."""
    kind = rng.randrange(6)
    if kind == 0 and data:  # flip 1-4 bytes
        out = bytearray(data)
        for _ in range(rng.randint(1, 4)):
            out[rng.randrange(len(out))] = rng.randrange(256)
        return bytes(out)
    if kind == 1:  # cut short
        return data[: rng.randrange(len(data) + 1)]
    lines = data.split(b"\n")
    if kind == 2 and len(lines) > 1:  # drop a line
        del lines[rng.randrange(len(lines))]
        return b"\n".join(lines)
    if kind == 3 and lines:  # repeat a line
        k = rng.randrange(len(lines))
        lines.insert(k, lines[k])
        return b"\n".join(lines)
    numbers = list(NUMBER.finditer(data))
    if numbers:  # a number becomes an extreme
        match = rng.choice(numbers)
        return data[: match.start()] + rng.choice(EXTREMES) + data[match.end() :]
    return data[::-1]


@contextmanager
def _alarm(seconds: int) -> Iterator[None]:
    def hang(signum: int, frame: object) -> None:
        raise TimeoutError(f"no answer within {seconds} s")

    previous = signal.signal(signal.SIGALRM, hang)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def _check_one(path: Path) -> str:
    """Load (and mesh) one file: ``"loaded"`` or ``"refused"``; anything else raises, and
    so does a Python warning (it would print lines beside the one-line error)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        outcome = _load_and_mesh(path)
    assert not caught, f"{path}: warnings {[str(w.message) for w in caught]}"
    return outcome


def _load_and_mesh(path: Path) -> str:
    with _alarm(SECONDS):
        try:
            scene = load_scene(path)
        except RaytradError as exc:
            message = str(exc)
            assert "\n" not in message and message.strip(), f"{path}: bad message {message!r}"
            return "refused"
        assert np.isfinite(scene.positions[np.unique(scene.triangles)]).all()
        assert np.isfinite(scene.material_emitted_exitance).all()
        try:
            build_mesh(repair_scene(scene), MeshSettings(receivers=300, patches=40))
        except RaytradError as exc:
            assert "\n" not in str(exc)
            return "refused"
    return "loaded"


@pytest.mark.skipif(not hasattr(signal, "SIGALRM"), reason="needs SIGALRM to catch hangs")
@pytest.mark.parametrize("seed", [*SEEDS, "seed-ascii.ply", "seed-binary.ply", "seed.gltf"])
def test_mutated_files_load_or_are_refused_in_one_line(tmp_path: Path, seed: str) -> None:
    if seed.endswith(".ply"):
        original = _ply_seed(tmp_path, binary="binary" in seed)
    elif seed == "seed.gltf":  # JSON text with a data URI buffer
        from tests.scenefiles.test_gltf_conformance import _floor_and_lamp

        original = _floor_and_lamp().write_gltf(tmp_path / seed)
    else:
        original = tmp_path / seed
        shutil.copy(SCENES / seed, original)
        for extra in SEEDS[seed]:
            shutil.copy(SCENES / extra, tmp_path / extra)
    data = original.read_bytes()
    rng = random.Random(f"{seed}-{CASES}")
    outcomes = {"loaded": 0, "refused": 0}
    for case in range(CASES):
        path = original.with_name(f"case{case:04d}{original.suffix}")
        path.write_bytes(_mutate(data, rng))
        try:
            outcomes[_check_one(path)] += 1
        except Exception as exc:
            raise AssertionError(f"{path} (mutation {case} of {seed}): {exc!r}") from exc
        path.unlink()
    assert sum(outcomes.values()) == CASES
