"""Build hook: compile raytrad's numba kernels into the package being built.

``pip install .`` builds a wheel on the machine it installs on. After the package's
files are copied to the build folder, its kernels are compiled there, on every core,
into numba's cache beside them (``raytrad/core/__pycache__``), and the wheel carries the
cache. numba keys a cached kernel by its source file's content, the numba version and
this CPU, so the installed copy loads them instead of compiling them (11-13 s on 2
cores) on the first render. Anything that goes wrong here leaves the kernels to compile
on first use, as without this hook; ``RAYTRAD_BUILD_KERNELS=0`` skips it. Editable
installs skip it too (their kernels are cached in the checkout on first use).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

#: The most seconds the compiling may take (it takes 11-13 s on 2 cores).
TIMEOUT = 600


class build_py_with_kernels(build_py):  # setuptools names commands in snake case
    def run(self) -> None:
        super().run()
        cache = Path(self.build_lib) / "raytrad" / "core" / "__pycache__"
        for stale in [*cache.glob("*.nbi"), *cache.glob("*.nbc")]:  # an earlier build's
            stale.unlink()
        if getattr(self, "editable_mode", False) or os.environ.get("RAYTRAD_BUILD_KERNELS") == "0":
            return
        try:
            compile_kernels(Path(self.build_lib))
        except Exception as error:  # never fail the install: they compile on first use
            print(f"raytrad: kernels not compiled at install ({error})", file=sys.stderr)


def compile_kernels(build_lib: Path) -> None:
    """Compile every listed kernel of the built package in ``build_lib`` into its
    in-tree numba cache (:func:`raytrad.core.compiled.compile_listed`, in a process of
    the build's Python importing the built package)."""
    start = time.perf_counter()
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}  # in-tree cache
    program = (
        "import sys; sys.path.insert(0, sys.argv[1]); "
        "from raytrad.core.compiled import compile_listed; compile_listed()"
    )
    subprocess.run(
        [sys.executable, "-c", program, str(build_lib)], env=env, check=True, timeout=TIMEOUT
    )
    seconds = time.perf_counter() - start
    count = len(list((build_lib / "raytrad" / "core" / "__pycache__").glob("*.nbi")))
    print(f"raytrad: {count} compiled functions cached for this machine in {seconds:.1f} s")


setup(cmdclass={"build_py": build_py_with_kernels})
