"""The compiled kernels (numba) against their numpy references in raytrad.core.kernels.

Random pairs and the adversarial ones where a form-factor kernel goes wrong first: a
receiver in the triangle's plane (grazing), a receiver whose horizon contains the
triangle (coplanar), corners exactly on or a rounding error off the horizon (straddling),
a receiver on a corner or a hair off an edge, degenerate triangles.

A receiver exactly *on* an edge, or inside a triangle in its plane, is not among them:
there Lambert's formula is singular (the edge's plane through the receiver is undefined,
and the factor's limit depends on the side approached from), so both implementations
return a rounding-dependent value in [0, 1]. Receivers never sit there: their evaluation
points move into their own triangles (:func:`raytrad.core.pairs.receiver_points`).
"""

from __future__ import annotations

import os
from types import SimpleNamespace

import numpy as np
import pytest

from raytrad.core import compiled, kernels

pytestmark = pytest.mark.skipif(compiled.get() is None, reason="numba is not installed")

#: Agreement asked of compiled and numpy kernels (same formula, same order).
AGREE = 1e-12


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def adversarial_pairs(rng: np.random.Generator, count: int = 4000):
    """(triangles (N, 3, 3), points (N, 3), normals (N, 3)): random and hard pairs."""
    tri = rng.normal(size=(count, 3, 3))
    x = rng.normal(size=(count, 3)) * 0.5
    n = _unit(rng.normal(size=(count, 3)))
    k = count // 8
    # grazing: the receiver lies in the triangle's plane, beside it
    a, b = tri[:k, 1] - tri[:k, 0], tri[:k, 2] - tri[:k, 0]
    x[:k] = tri[:k, 0] - 0.7 * a - 0.4 * b
    # coplanar: the triangle lies in the receiver's tangent plane, the receiver beside it
    # (inside it the limit is singular, as on an edge)
    s = slice(k, 2 * k)
    n[s] = _unit(np.cross(tri[s, 1] - tri[s, 0], tri[s, 2] - tri[s, 0]))
    n[s] *= rng.choice([-1.0, 1.0], size=(k, 1))
    x[s] = tri[s, 0] - 0.6 * (tri[s, 1] - tri[s, 0]) - 0.3 * (tri[s, 2] - tri[s, 0])
    # straddling: one corner exactly on the horizon, one a rounding error below
    s = slice(2 * k, 3 * k)
    h = np.einsum("ikj,ij->ik", tri[s] - x[s, None, :], n[s])
    tri[s, 0] -= h[:, 0, None] * n[s]
    tri[s, 1] -= (h[:, 1, None] + 1e-17) * n[s]
    # the receiver on a corner, and a thousandth of the edge's length off its midpoint
    s = slice(3 * k, 4 * k)
    x[s] = tri[s, 2]
    s = slice(4 * k, 5 * k)
    edge = np.linalg.norm(tri[s, 1] - tri[s, 0], axis=1)[:, None]
    x[s] = 0.5 * (tri[s, 0] + tri[s, 1]) + 1e-3 * edge * _unit(rng.normal(size=(k, 3)))
    # degenerate: two corners equal, or all three on a line
    s = slice(5 * k, 6 * k)
    tri[s, 1] = tri[s, 0]
    s = slice(6 * k, 7 * k)
    tri[s, 2] = 2.0 * tri[s, 1] - tri[s, 0]
    return tri, x, n


def test_polygon_form_factor_agrees_with_numpy():
    tri, x, n = adversarial_pairs(np.random.default_rng(1))
    got = kernels.polygon_form_factor(tri, x, n)
    want = kernels.numpy_polygon_form_factor(tri, x, n)
    assert np.isfinite(got).all()
    np.testing.assert_allclose(got, want, rtol=0, atol=AGREE)
    assert (want > 0).sum() > len(tri) // 3  # the cases are not all trivially zero


@pytest.mark.parametrize("levels", [2, 3])
def test_linear_corner_shares_agree_with_numpy(levels):
    tri, x, n = adversarial_pairs(np.random.default_rng(3), 1600)
    got = kernels.linear_corner_shares(tri, x, n, levels)
    want = kernels.numpy_linear_corner_shares(tri, x, n, levels)
    np.testing.assert_allclose(got.sum(axis=1), 1.0, atol=AGREE)
    assert ((got >= 0) & (got <= 1)).all()
    # shares are ratios of factor sums: where the receiver sees next to nothing of the
    # triangle (a factor of 1e-17, rounding noise at grazing) they are ratios of noise, and
    # weigh nothing; compare them where the ratio is well conditioned
    seen = kernels.numpy_polygon_form_factor(tri, x, n) > 1e-3
    assert seen.sum() > len(tri) // 4
    np.testing.assert_allclose(got[seen], want[seen], rtol=0, atol=AGREE)


def test_sample_weights_agree_with_numpy():
    rng = np.random.default_rng(5)
    x = rng.normal(size=(300, 3))
    n = _unit(rng.normal(size=(300, 3)))
    y = rng.normal(size=(50, 3))
    y[:5] = x[:5]  # a sample exactly at a receiver
    ny = _unit(rng.normal(size=(50, 3)))
    reach = rng.uniform(0.0, 0.8, 50)
    area = rng.uniform(1e-4, 0.1, 50)
    x[10], n[10] = [100.0, 0.0, 0.0], [1.0, 0.0, 0.0]  # faces away from every sample
    sees = rng.random(300) < 0.7
    sees[10] = True
    got = kernels.sample_weights(x, n, sees, y, ny, reach, area)
    want = kernels.numpy_sample_weights(x, n, sees, y, ny, reach, area)
    np.testing.assert_allclose(got[0], want[0], rtol=0, atol=AGREE)
    np.testing.assert_array_equal(got[1], want[1])
    np.testing.assert_array_equal(got[2], want[2])
    assert got[1].any() and got[2].any()
    assert got[2][10].all()  # near every sample: handled triangle by triangle
    assert not (got[1][~sees].any() or got[2][~sees].any() or got[0][~sees].any())


def test_visibility_rays_agree_with_numpy():
    rng = np.random.default_rng(6)
    origins = rng.normal(size=(40, 3)) * 1e3
    far = rng.random((40, 12)) < 0.5
    targets = origins[:12] + rng.normal(size=(12, 3))
    targets[0] = origins[0]  # a zero-length ray
    near_c = rng.integers(0, 40, 25)
    near_targets = origins[near_c] + rng.normal(size=(25, 3))
    shift = np.array([1e3, -2e3, 5.0])
    got = kernels.visibility_rays(origins, far, targets, near_c, near_targets, shift, 1e-4)
    want = kernels.numpy_visibility_rays(origins, far, targets, near_c, near_targets, shift, 1e-4)
    for g, w in zip(got, want, strict=True):
        assert g.dtype == w.dtype
        np.testing.assert_array_equal(g, w)
    assert len(got[0]) == far.sum() + 25


def test_numpy_kernels_on_request(monkeypatch):
    monkeypatch.setenv("RAYTRAD_KERNELS", "numpy")
    assert compiled.get() is None
    tri, x, n = adversarial_pairs(np.random.default_rng(7), 80)
    np.testing.assert_array_equal(
        kernels.polygon_form_factor(tri, x, n), kernels.numpy_polygon_form_factor(tri, x, n)
    )


@pytest.mark.parametrize("n", [0, 1, 2, 3, 4, 13, 14, 40, 41, 500])
def test_the_gather_sort_agrees_with_numpy(n):
    # the means and spreads sort each pair's sources with its own loop instead of np.sort (whose
    # compilation took seconds of a first run): the same order, duplicates and a tail
    # beyond n left alone
    rng = np.random.default_rng(n)
    values = rng.integers(0, max(n, 1) * 3 + 1, size=n + 7).astype(np.int64)
    got = values.copy()
    compiled.get()._sort_ascending(got, n)
    np.testing.assert_array_equal(got[:n], np.sort(values[:n]))
    np.testing.assert_array_equal(got[n:], values[n:])


# -- compiling ahead, on every core, the first time ------------------------------------


#: A render recording the signatures of every kernel call from Python (the path of a call
#: from Python, whether numba then compiles or loads): tools/kernel_signatures.py's.
def _recorded_calls(tmp_path) -> dict[str, list[list[str]]]:
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    sys.path.insert(0, str(root / "tools"))
    try:
        from kernel_signatures import RECORD
    finally:
        sys.path.remove(str(root / "tools"))
    scene = str(root / "scenes" / "cornell-box.obj")
    command = [sys.executable, "-c", RECORD, "render", scene, "--receivers", "500", "-q"]
    # compiling nothing ahead: a kernel compiled ahead in this process (a cold cache, as
    # on a fresh install) is never called through the recorded path
    env = {**os.environ, "RAYTRAD_COMPILERS": "1"}
    done = subprocess.run(
        command, capture_output=True, text=True, cwd=tmp_path, env=env, check=True
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_render_calls_only_listed_signatures(tmp_path) -> None:
    from raytrad.core._kernel_signatures import SIGNATURES

    called = _recorded_calls(tmp_path)
    # the pass and the solve ran (its shot one after another, or on several threads)
    assert "near_triangles" in called and ("shoot" in called or "shoot_parallel" in called)
    for name, signatures in called.items():
        listed = {tuple(arguments) for arguments in SIGNATURES.get(name, [])}
        missing = {tuple(arguments) for arguments in signatures} - listed
        assert not missing, f"{name} {missing}: rerun python tools/kernel_signatures.py"


#: Run in a fresh process with an empty cache: compile every listed kernel, and print the
#: helpers numba compiled for a literal argument type.
_LITERAL_COMPILES = """
import numba
from numba.core import event
from raytrad.core import compiled
from raytrad.core._kernel_signatures import SIGNATURES
kernels = compiled._dispatchers(numba)
with event.install_recorder("numba:compile") as recorder:
    for name, signatures in SIGNATURES.items():
        compiled._compile(numba, kernels[name], signatures)
for _, e in recorder.buffer:
    if e.is_start and "Literal" in str(e.data["args"]):
        print(e.data["dispatcher"].py_func.__name__, e.data["args"])
"""


@pytest.mark.slow
def test_no_helper_compiles_twice_for_a_literal(tmp_path) -> None:
    """A helper called with a counter that starts as the literal 0 compiles once for
    ``Literal[int](0)`` and again for ``int64`` (about a second of a first run's compiling
    for the near field's triangle step): counters start as ``np.int64(0)``."""
    import os
    import subprocess
    import sys

    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path), "RAYTRAD_COMPILERS": "1"}
    done = subprocess.run(
        [sys.executable, "-c", _LITERAL_COMPILES],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    )
    assert done.stdout.strip() == ""


def test_listed_signatures_are_numba_signatures() -> None:
    import numba

    from raytrad.core._kernel_signatures import SECONDS, SIGNATURES

    kernels = compiled._dispatchers(numba)
    assert set(SECONDS) == set(SIGNATURES) and set(SIGNATURES) <= set(kernels)
    for signatures in SIGNATURES.values():
        for arguments in signatures:
            parsed = compiled.signature(numba, arguments)
            assert all(isinstance(t, numba.core.types.Type) for t in parsed)
            assert [repr(t) for t in parsed] == arguments


def test_borrowing_helpers_allocate_nothing_and_count_no_references() -> None:
    # a helper compiled without reference counting must not allocate (numba would leak
    # or refuse it) nor hand an array back; the others keep numba's counting
    import inspect

    import numba

    from raytrad.core import _compiled_gather, _compiled_kernels, _compiled_near

    kernels = compiled._dispatchers(numba)
    for module in (_compiled_kernels, _compiled_near, _compiled_gather):
        assert set(module.BORROWING) <= set(module.KERNELS)
        for name in module.BORROWING:
            source = inspect.getsource(kernels[name].py_func)
            for allocation in ("np.empty", "np.zeros", "np.ones", "np.full", ".copy(", "_buffers("):
                assert allocation not in source, (name, allocation)
            assert kernels[name].targetoptions.get("_nrt") is False, name
    assert "_nrt" not in kernels["near_triangles"].targetoptions  # it allocates its output


def test_a_borrowing_helper_gives_what_the_counting_one_gives() -> None:
    import numba

    from raytrad.core import _compiled_kernels

    tri, x, n = adversarial_pairs(np.random.default_rng(11), 400)
    counting = numba.njit(nogil=True)(_compiled_kernels.clipped_factor.py_func)
    work = np.empty((4, 3))
    for i in range(len(tri)):
        assert _compiled_kernels.clipped_factor(tri[i], x[i], n[i], work) == counting(
            tri[i], x[i], n[i], work
        )


def test_share_out_balances_and_keeps_every_name() -> None:
    seconds = {"a": 5.0, "b": 3.0, "c": 2.0, "d": 1.0, "e": 1.0}
    groups = compiled.share_out(list(seconds), 2, seconds)
    assert sorted(n for g in groups for n in g) == sorted(seconds)
    totals = sorted(sum(seconds[n] for n in g) for g in groups)
    assert totals == [6.0, 6.0]
    assert all(compiled.share_out(["x", "y", "z"], 3, {}))  # each group gets one


def test_a_helper_compiles_into_the_cache_and_the_check_sees_it(tmp_path) -> None:
    import os
    import subprocess
    import sys

    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "RAYTRAD_COMPILERS": "1"}
    # run where another raytrad lies (a source checkout beside an installed copy): the
    # helper must still import this process's raytrad, or it fills another cache
    decoy = tmp_path / "decoy"
    (decoy / "raytrad").mkdir(parents=True)
    (decoy / "raytrad" / "__init__.py").write_text("raise ImportError('the decoy')\n")
    helper = compiled.helper_command(["column_sweep", "column_final"])
    subprocess.run(helper, env=env, check=True, capture_output=True, cwd=decoy)
    check = (
        "import numba\n"
        "from raytrad.core import compiled\n"
        "from raytrad.core._kernel_signatures import SIGNATURES as S\n"
        "k = compiled._dispatchers(numba)\n"
        "print([compiled._cached(numba, k[n], S[n]) for n in "
        "('column_sweep', 'column_final', 'patch_average')])\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", check], env=env, check=True, capture_output=True, text=True
    )
    assert done.stdout.strip() == "[True, True, False]"


def test_compilers_reads_the_environment(monkeypatch) -> None:
    monkeypatch.setenv("RAYTRAD_COMPILERS", "3")
    assert compiled.compilers() == 3
    monkeypatch.setenv("RAYTRAD_COMPILERS", "0")
    assert compiled.compilers() == 1
    monkeypatch.setenv("RAYTRAD_COMPILERS", "many")
    assert compiled.compilers() == 1
    monkeypatch.delenv("RAYTRAD_COMPILERS")
    assert 1 <= compiled.compilers() <= compiled.MAX_COMPILERS


def _solver_threads_in_child() -> int:
    return compiled.solver_threads(2)


def test_the_solver_loops_run_one_after_another_in_a_forked_child() -> None:
    """numba's threading layer (GNU OpenMP) does not survive a fork: a child forked after
    this process started it gets the loops one after another, and does not hang."""
    import multiprocessing

    compiled.solver_threads(2)  # starts the layer here
    with multiprocessing.get_context("fork").Pool(1) as pool:
        assert pool.apply_async(_solver_threads_in_child).get(timeout=120) == 1


def test_a_parallel_copy_is_compiled_and_cached_apart() -> None:
    """Each solver loop's ``parallel=True`` copy is a dispatcher of its own, named apart
    (numba keys its cache by name: the copy must not load the original's code)."""
    fast = compiled.get()
    for name in ("shoot",):
        serial, parallel = getattr(fast, name), getattr(fast, f"{name}_parallel")
        assert parallel.targetoptions.get("parallel") and not serial.targetoptions.get("parallel")
        assert parallel.py_func.__qualname__ == f"{name}_parallel"
        assert parallel.py_func.__code__.co_code == serial.py_func.__code__.co_code


def test_the_solver_loops_run_one_after_another_without_a_cheap_threading_layer(
    monkeypatch,
) -> None:
    """Where numba's threading layer would be its workqueue (a launch costs more than a
    shot's loops), or one thread is wanted, the serial loops run."""
    monkeypatch.setitem(compiled._STATE, "threading", (os.getpid(), False))
    assert compiled.solver_threads(2) == 1
    monkeypatch.setitem(compiled._STATE, "threading", (os.getpid(), True))
    assert compiled.solver_threads(1) == 1
    fast = compiled.get()
    assert compiled.solver_loops(fast, 1).shoot is fast.shoot


def test_the_solver_loops_go_serial_while_other_processes_keep_the_cores_busy(
    monkeypatch,
) -> None:
    """Before each shot the solver reads other processes' load on its CPUs: above
    ``BUSY_CORES`` it takes the serial loops, at or below it (or unknown) the parallel
    ones again."""
    fast = compiled.get()
    if compiled.solver_threads(2) < 2:
        pytest.skip("one thread here: the serial loops always")
    loops = compiled.solver_loops(fast, 2)
    assert loops.parallel and loops.shoot is fast.shoot_parallel
    for load, parallel in ((1.0, False), (compiled.BUSY_CORES, True), (0.9, False), (None, True)):
        # a load of this solve's own (patching the shared one would leave a bound
        # method on it when undone, shadowing later patches of the class)
        monkeypatch.setattr(loops, "_load", SimpleNamespace(cores=lambda load=load: load))
        loops.tick()
        assert loops.parallel == parallel
        suffix = "_parallel" if parallel else ""
        for name in compiled.SOLVER_LOOPS:
            assert getattr(loops, name) is getattr(fast, name + suffix)


#: Run in a fresh process: prepare a small Cornell box, then print the kernels the solve
#: still had to load or compile (a new overload on its dispatcher).
_SOLVE_LOADS = """
import json, sys
from raytrad import api
from raytrad.core import compiled, pipeline, solver
from raytrad.core.mesh import MeshSettings
prepared = pipeline.prepare(api.load(sys.argv[1]).scene, MeshSettings(receivers=500))
fast = compiled.get()
before = {name: len(getattr(fast, name).overloads) for name in vars(fast)}
solver.solve(prepared.mesh, prepared.engine)
print(json.dumps([name for name in before if len(getattr(fast, name).overloads) != before[name]]))
"""


def test_the_solve_loads_no_kernel_the_pipeline_did_not(tmp_path) -> None:
    """The pipeline's kernels stage loads the solver's loops and helpers
    (:func:`compiled.load_solver`): the first solve in a process, on one thread or
    several, does not pay numba's loading of them (about 30 ms at the default size)."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    scene = str(Path(__file__).resolve().parents[2] / "scenes" / "cornell-box.obj")
    for threads in ("1", "2"):
        env = {**os.environ, "RAYTRAD_THREADS": threads}
        done = subprocess.run(
            [sys.executable, "-c", _SOLVE_LOADS, scene],
            capture_output=True,
            text=True,
            cwd=tmp_path,
            env=env,
            check=True,
        )
        assert json.loads(done.stdout.strip().splitlines()[-1]) == [], threads
