"""The floor plan, read from the code: layers that import downward only, no import cycle
(lazy imports included), one adapter module per heavy dependency, small modules, a thin API
and a CLI that talks to the API and the settings only (``docs/architecture.md``)."""

from __future__ import annotations

import ast
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.conftest import REPOSITORY

PACKAGE = REPOSITORY / "raytrad"

#: Layers from the bottom up; a module may import only from its own layer or below.
LAYERS = (
    ("raytrad", "raytrad.errors", "raytrad.constants", "raytrad.arrays"),
    ("raytrad.formats",),
    ("raytrad.scene",),
    ("raytrad.scenefiles",),
    ("raytrad.core",),
    ("raytrad.products",),
    ("raytrad.settings",),
    ("raytrad.outputs",),
    ("raytrad.api",),
    ("raytrad.batch",),
    ("raytrad.cli", "raytrad.__main__"),
)

#: Each heavy dependency and the one module allowed to import it (inside a function).
ADAPTERS = {
    "embreex": "raytrad.core.visibility",
    "numba": "raytrad.core.compiled",
    "trimesh": "raytrad.scenefiles.trimesh_adapter",
    "OpenImageIO": "raytrad.formats.images",
    "colour": "raytrad.scene.colorimetry",
    "xatlas": "raytrad.products.atlas",
    "matplotlib": "raytrad.outputs.plot",
    "tqdm": "raytrad.cli",
    "distributed": "raytrad.batch.dask",
}

#: Longest module [lines], and longest API module.
MODULE_LIMIT = 650
API_LIMIT = 400


def _modules() -> dict[str, Path]:
    names = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(REPOSITORY).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        names[".".join(parts)] = path
    return names


MODULES = _modules()


def _imports(path: Path) -> Iterator[tuple[str, bool]]:
    """(imported module, at module level) for every import statement of a file; a name
    imported from a package is the submodule when one has that name."""
    tree = ast.parse(path.read_text())
    top = {id(node) for node in tree.body}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, id(node) in top
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            for alias in node.names:
                candidate = f"{node.module}.{alias.name}"
                yield (candidate if candidate in MODULES else node.module), id(node) in top


def _graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for name, path in MODULES.items():
        graph[name] = {
            target
            for target, _ in _imports(path)
            if target in MODULES and target != name and not name.startswith(target + ".")
        }
    return graph


def _layer(module: str) -> int:
    for level, prefixes in enumerate(LAYERS):
        if any(module == p or (p != "raytrad" and module.startswith(p + ".")) for p in prefixes):
            return level
    raise AssertionError(f"{module} is in no layer of the floor plan")


def test_every_module_is_in_a_layer() -> None:
    for module in MODULES:
        _layer(module)


def test_imports_point_downward() -> None:
    upward = [
        f"{module} (layer {_layer(module)}) imports {target} (layer {_layer(target)})"
        for module, targets in _graph().items()
        for target in targets
        if _layer(target) > _layer(module)
    ]
    assert upward == []


def test_no_import_cycle() -> None:
    graph = _graph()
    state: dict[str, int] = {}
    cycles: list[list[str]] = []

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for target in sorted(graph[node]):
            if state.get(target) == 1:
                cycles.append([*path[path.index(target) :], target])
            elif target not in state:
                visit(target, [*path, target])
        state[node] = 2

    for module in sorted(graph):
        if module not in state:
            visit(module, [module])
    assert cycles == []


def test_the_core_reads_and_writes_no_file_format() -> None:
    touching = {
        f"{module} -> {target}"
        for module, targets in _graph().items()
        if module.startswith("raytrad.core")
        for target in targets
        if target.startswith(("raytrad.formats", "raytrad.scenefiles", "raytrad.outputs"))
    }
    assert touching == set()


def test_products_write_nothing() -> None:
    writers = {
        f"{module} -> {target}"
        for module, targets in _graph().items()
        if module.startswith("raytrad.products")
        for target in targets
        if target in ("raytrad.formats.atomic", "raytrad.formats.ply", "raytrad.formats.glb")
    }
    assert writers == set()


def test_the_cli_imports_only_the_api_the_batch_and_the_settings() -> None:
    # raytrad.cli and its own modules (the parser) import nothing else of the package
    cli = {name for name in MODULES if name == "raytrad.cli" or name.startswith("raytrad.cli.")}
    allowed = {"raytrad", "raytrad.api", "raytrad.batch", "raytrad.settings"} | cli
    for name in cli:
        assert _graph()[name] <= allowed, name


@pytest.mark.parametrize(("dependency", "adapter"), sorted(ADAPTERS.items()))
def test_each_heavy_dependency_has_one_lazy_adapter(dependency: str, adapter: str) -> None:
    users = {}
    for module, path in MODULES.items():
        found = [top for target, top in _imports(path) if target.split(".")[0] == dependency]
        if found:
            users[module] = found
    assert set(users) == {adapter}
    assert not any(users[adapter]), f"{adapter} imports {dependency} at module level"


def test_importing_the_api_loads_no_heavy_dependency() -> None:
    code = (
        "import sys, raytrad.api, raytrad.cli\n"
        f"heavy = {sorted(ADAPTERS)!r}\n"
        "print(','.join(h for h in heavy if h in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == ""


def test_modules_stay_small() -> None:
    lengths = {name: len(path.read_text().splitlines()) for name, path in MODULES.items()}
    assert {name: n for name, n in lengths.items() if n > MODULE_LIMIT} == {}
    assert lengths["raytrad.api"] <= API_LIMIT


def test_importing_the_package_loads_nothing_until_a_name_is_used() -> None:
    code = (
        "import sys, raytrad\n"
        "print(','.join(sorted(m for m in sys.modules if m.startswith('raytrad.'))))\n"
        "raytrad.RenderSettings\n"
        "print('raytrad.settings' in sys.modules, 'raytrad.api' in sys.modules)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.split("\n")[:2] == ["", "True False"]
