"""The wheel ``pip install .`` builds carries the kernels compiled for this machine
(setup.py's build hook), so that the first render after installing loads them."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from raytrad.core._kernel_signatures import SIGNATURES
from tests.conftest import REPOSITORY

#: Lists the listed kernels numba's cache, as the installed package finds it, lacks.
MISSING = (
    "import json, sys; sys.path.insert(0, sys.argv[1]); import numba; "
    "from raytrad.core import compiled; "
    "from raytrad.core._kernel_signatures import SIGNATURES; "
    "kernels = compiled._dispatchers(numba); "
    "print(json.dumps([n for n in SIGNATURES if not compiled._cached(numba, kernels[n], "
    "SIGNATURES[n])]))"
)


@pytest.mark.slow
def test_the_wheel_carries_every_listed_kernel_compiled(tmp_path: Path) -> None:
    """Built as ``pip install .`` builds it (an isolated build with numba), the wheel holds
    numba's cache of every kernel a render calls, and numba, reading the unpacked wheel
    as an installed package, finds each listed signature there (its source hash, this
    CPU and numba version match): nothing left to compile."""
    source = tmp_path / "source"  # what a build reads, no earlier build's folder or cache
    package = shutil.ignore_patterns("__pycache__")
    shutil.copytree(REPOSITORY / "raytrad", source / "raytrad", ignore=package)
    for name in ("pyproject.toml", "setup.py", "README.md"):
        shutil.copy(REPOSITORY / name, source / name)
    wheels = tmp_path / "wheels"
    build = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "-q",
            "-w",
            str(wheels),
            str(source),
        ],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert build.returncode == 0, build.stderr[-2000:]
    wheel = next(wheels.glob("raytrad-*.whl"))
    unpacked = tmp_path / "site"
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
        archive.extractall(unpacked)
    indexed = {Path(n).name.split("-")[0] for n in names if n.endswith(".nbi")}
    for kernel in SIGNATURES:
        assert any(name.endswith("." + kernel) for name in indexed), kernel
    missing = subprocess.run(
        [sys.executable, "-c", MISSING, str(unpacked)],
        capture_output=True,
        text=True,
        check=True,
        cwd=tmp_path,
    )
    assert json.loads(missing.stdout) == []
