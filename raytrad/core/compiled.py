"""Compiled form-factor kernels: the numba adapter.

The form-factor pass evaluates Lambert's formula for millions of small (receiver,
polygon) pairs: a patch's outline (whole or clipped to a receiver's horizon), near
triangles of a sub-area, the parts of a triangle split for
:func:`~raytrad.core.kernels.linear_corner_shares`. In numpy each of those is a chain of
small temporaries; here each pair is one loop, compiled once (``cache=True``, so later
processes load it from disk) and run without the GIL (``nogil=True``), so the
form-factor engine's threads run on every core.

:mod:`raytrad.core.kernels`, :mod:`raytrad.core.contour`, :mod:`raytrad.core.gather`,
:mod:`raytrad.core.spread`, :mod:`raytrad.core.clusters`, :mod:`raytrad.core.pairs` and
:mod:`raytrad.core.segment_search` keep the numpy implementations as the reference: every
function here computes the same
formula in the same order, and the tests compare the two to 1e-12 on random and
adversarial pairs (grazing, coplanar, straddling the horizon).
numba is imported only when a kernel is first asked for (:func:`get`), and
``RAYTRAD_KERNELS=numpy`` in the environment keeps the numpy path. The first time (numba's
cache lacks them) the kernels a render calls compile on every core at once
(:func:`_compile_ahead`; ``RAYTRAD_COMPILERS`` processes).
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys
import threading
import time
import types
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from raytrad.core.cores import OtherLoad

log = logging.getLogger(__name__)

_LOCK = threading.Lock()
_STATE: dict[str, Any] = {}
_THREAD = threading.local()
#: The most processes that compile the kernels at once the first time (:func:`compilers`).
MAX_COMPILERS = 8
#: Seconds to wait for a helper compiling kernels before leaving them to numba [s].
HELPER_TIMEOUT = 300.0


def wanted() -> bool:
    """Whether compiled kernels are asked for: ``RAYTRAD_KERNELS`` is not ``numpy``."""
    return os.environ.get("RAYTRAD_KERNELS", "compiled").strip().lower() != "numpy"


def get() -> SimpleNamespace | None:
    """The compiled kernels, or None (numba missing, or ``RAYTRAD_KERNELS=numpy``).

    Compiles (or loads from numba's cache) on the first call; thread-safe.
    """
    if not wanted():
        return None
    return _once("kernels", _build)


def _once(key: str, make: Any) -> Any:
    """``_STATE[key]``, made by ``make()`` on the first call of any thread (the others
    wait for it)."""
    if key not in _STATE:
        with _LOCK:
            if key not in _STATE:
                _STATE[key] = make()
    return _STATE[key]


def _build() -> SimpleNamespace | None:
    start = time.perf_counter()
    try:
        import numba
    except ImportError:  # pragma: no cover - numba is a dependency
        log.warning("numba is not installed: form factors use the slower numpy kernels")
        return None
    kernels = _dispatchers(numba)
    _compile_ahead(numba, kernels)
    log.debug("compiled kernels ready in %.2f s", time.perf_counter() - start)
    return SimpleNamespace(**kernels)


def _dispatchers(numba: Any) -> dict[str, Any]:
    """Every loop of the ``_compiled_*`` modules wrapped by :func:`_jit` (once; rebound in
    its module, helpers first, so that the kernels call each other compiled), by name.
    numba compiles each on its first call, or loads it from its cache."""
    from raytrad.core import (
        _compiled_convergence,
        _compiled_gather,
        _compiled_kernels,
        _compiled_near,
        _compiled_rays,
        _compiled_segments,
        _compiled_shafts,
        _compiled_solver,
        _compiled_spread,
    )

    modules = (
        _compiled_kernels,
        _compiled_near,
        _compiled_gather,
        _compiled_shafts,
        _compiled_spread,
        _compiled_solver,
        _compiled_segments,
        _compiled_rays,
        _compiled_convergence,
    )
    link_embree(numba)
    kernels = {}
    for loops in modules:
        kernels.update(_bind(numba, loops, loops.KERNELS))
    return kernels


def link_embree(numba: Any) -> None:
    """Give :mod:`raytrad.core._compiled_rays` Embree's packet functions as numba
    external functions, before its loops are compiled: the library embreex ships
    (:func:`raytrad.core.embree.library_path`) loaded into LLVM's symbol table, where
    numba's linker finds ``rtcOccluded8`` and ``rtcIntersect8`` by name (also for loops
    loaded from its cache). Nothing when the library is not usable (the module then has
    no loops)."""
    from raytrad.core import _compiled_rays, embree

    if not _compiled_rays.KERNELS or _compiled_rays._occluded8 is not None:
        return
    import llvmlite.binding

    llvmlite.binding.load_library_permanently(embree.library_path())
    pointer = numba.types.uintp
    signature = numba.types.void(pointer, pointer, pointer, pointer)
    _compiled_rays._intersect8 = numba.types.ExternalFunction("rtcIntersect8", signature)
    _compiled_rays._occluded8 = numba.types.ExternalFunction("rtcOccluded8", signature)


def _bind(numba: Any, loops: Any, names: tuple[str, ...]) -> dict[str, Any]:
    """The loops ``names`` of module ``loops`` wrapped by :func:`_jit` where not yet (and
    rebound in the module, so that later loops call them compiled), by name; those of its
    ``PARALLEL`` also as ``<name>_parallel``, compiled with ``parallel=True`` (its
    ``prange`` is numba's)."""
    borrowing = getattr(loops, "BORROWING", ())
    if hasattr(loops, "prange"):
        loops.prange = numba.prange
    bound = {}
    for name in names:
        if not hasattr(getattr(loops, name), "py_func"):  # not compiled yet
            setattr(loops, name, _jit(numba, getattr(loops, name), name in borrowing))
        bound[name] = getattr(loops, name)
    for name in getattr(loops, "PARALLEL", ()):
        twin = f"{name}_parallel"
        if not hasattr(loops, twin):
            setattr(loops, twin, _jit(numba, _renamed(bound[name].py_func, twin), parallel=True))
        bound[twin] = getattr(loops, twin)
    return bound


def _renamed(function: Any, name: str) -> Any:
    """A copy of ``function`` named ``name``: numba caches a function by its module,
    qualified name and line, so a copy compiled with other options gets a cache of its
    own instead of loading the original's."""
    code = function.__code__.replace(co_name=name, co_qualname=name)
    copy = types.FunctionType(
        code, function.__globals__, name, function.__defaults__, function.__closure__
    )
    copy.__qualname__ = name
    copy.__doc__ = function.__doc__
    return copy


#: The solver's loops compiled twice (:func:`solver_loops`): the shot, the choice of the
#: next shooter, and the spreads summed again before the solve stops or is read.
SOLVER_LOOPS = ("shoot", "ambient_choice", "refresh_stale")
#: Other processes' load [cores] on this process's CPUs above which the solver takes its
#: serial loops (:class:`SolverLoops`).
BUSY_CORES = 0.5


class SolverLoops:
    """The solver's loops (:data:`SOLVER_LOOPS`, as attributes): their ``parallel=True``
    copies while the cores are free, else the loops themselves.

    Each parallel loop waits for all of numba's threads, and a core kept busy by another
    process makes the thread meant for it wait for the scheduler: with a busy loop on
    the other core the default solve took 4.1 s, against 0.64 s on one thread
    (2026-12-05). So :meth:`tick`, called once a shot, reads other processes' load on
    this process's CPUs (:class:`raytrad.core.cores.OtherLoad`, every 0.1 s, one for the
    process, so that a refinement's next solve starts knowing it) and takes the serial
    loops while it is above :data:`BUSY_CORES`. Both give the same results
    to the bit, so a switch in the middle of a solve changes its time alone.
    """

    def __init__(self, serial: SimpleNamespace, parallel: SimpleNamespace | None = None) -> None:
        self._serial, self._parallel = serial, parallel
        self._load = _once("other load", OtherLoad) if parallel is not None else None
        self._use(parallel or serial)

    def _use(self, loops: SimpleNamespace) -> None:
        for name in SOLVER_LOOPS:
            setattr(self, name, getattr(loops, name))
        self.parallel = loops is self._parallel

    def tick(self) -> None:
        """Before a shot: the parallel loops while other processes' load is at most
        :data:`BUSY_CORES` (or unknown), else the serial ones."""
        if self._load is None:
            return
        load = self._load.cores()
        free = load is None or load <= BUSY_CORES
        if free != self.parallel:
            log.debug("solver loops: %s", "parallel" if free else f"serial, other load {load:.2f}")
            self._use(self._parallel if free else self._serial)  # type: ignore[arg-type]


def solver_loops(fast: SimpleNamespace, wanted: int) -> SolverLoops:
    """The solver's loops of the compiled kernels ``fast`` (:data:`SOLVER_LOOPS`) to call
    from this thread, for one solve: their ``parallel=True`` copies where
    :func:`solver_threads` of ``wanted`` threads is above 1 (numba's threads set to that
    in this thread) and no other process keeps the cores busy (:class:`SolverLoops`),
    else the loops
    themselves. Both give the same results to the bit (their blocks and rows are summed
    apart and added in order)."""
    threads = solver_threads(wanted)
    serial = SimpleNamespace(**{name: getattr(fast, name) for name in SOLVER_LOOPS})
    if threads <= 1 or not hasattr(fast, "shoot_parallel"):
        return SolverLoops(serial)
    if getattr(_THREAD, "threads", 0) != threads:
        import numba

        numba.set_num_threads(threads)  # numba's setting is per calling thread
        _THREAD.threads = threads
    parallel = {name: getattr(fast, name + "_parallel") for name in SOLVER_LOOPS}
    return SolverLoops(serial, SimpleNamespace(**parallel))


#: Kernels the solve calls from Python besides its loops, loaded ahead with them
#: (:func:`load_solver`).
SOLVE_HELPERS = ("patch_average", "patch_spread_rows", "unshot_totals")


def load_solver(wanted: int) -> None:
    """Load the loops a solve with ``wanted`` threads starts with (:func:`solver_loops`:
    the parallel copies, or the loops themselves on one thread) and
    :data:`SOLVE_HELPERS` from numba's cache now, compiling any it lacks. numba does
    this at a kernel's first call otherwise: about 30 ms for these (2026-12-06), which
    the first solve in a process paid. The pipeline calls it in its kernels stage.
    Nothing where numba is not used."""
    fast = get()
    if fast is None:
        return
    import numba

    from raytrad.core._kernel_signatures import SIGNATURES

    parallel = solver_threads(wanted) > 1 and hasattr(fast, "shoot_parallel")
    names = [name + ("_parallel" if parallel else "") for name in SOLVER_LOOPS]
    for name in (*names, *SOLVE_HELPERS):
        if hasattr(fast, name) and name in SIGNATURES:
            _compile(numba, getattr(fast, name), SIGNATURES[name])


def solver_threads(wanted: int) -> int:
    """Threads the solver's parallel loops run on in this process: ``wanted`` (the
    form-factor pass's, :func:`raytrad.core.visibility.worker_count`), at most numba's. 1
    (the loops one after another) where numba's threading layer is its workqueue (neither
    OpenMP nor TBB loads: a launch would cost about 120 µs, more than a shot's loops), in
    a process forked from one that had started the layer (GNU OpenMP's threads do not
    survive a fork). The layer is started on the first call that wants several threads."""
    if wanted <= 1:
        return 1
    started = _once("threading", lambda: (os.getpid(), _start_threading()))
    if started[0] != os.getpid() or not started[1]:
        return 1
    import numba

    return max(1, min(wanted, int(getattr(numba.config, "NUMBA_NUM_THREADS", 1))))


def _start_threading() -> bool:
    """Start numba's threading layer; whether it is one whose launches are cheap (OpenMP,
    TBB)."""
    try:
        import numba
        from numba.np.ufunc import parallel

        parallel._launch_threads()
        return numba.threading_layer() in ("omp", "tbb")
    except Exception as error:  # numba internals moved, no layer: the serial loops
        log.debug("numba's threading layer did not start: %s", error)
        return False


def rays() -> SimpleNamespace | None:
    """The packet loops of :mod:`raytrad.core._compiled_rays` alone (and the helper they
    share with the pass's rays), loaded from numba's cache or compiled on first use
    without the other kernels: an :class:`~raytrad.core.visibility.Occluder` traces rays
    while the mesh is built, before :func:`get` compiles the rest (a scene that cannot be
    solved fails first). None where :func:`wanted` is False. Thread-safe."""
    if not wanted():
        return None
    return _once("rays", _build_rays)


def _build_rays() -> SimpleNamespace:
    """:func:`rays`' loops, bound."""
    import numba

    from raytrad.core import _compiled_kernels, _compiled_rays

    link_embree(numba)
    _bind(numba, _compiled_kernels, ("_segment",))
    return SimpleNamespace(**_bind(numba, _compiled_rays, _compiled_rays.KERNELS))


def compilers() -> int:
    """Processes that compile the kernels at once the first time (:func:`_compile_ahead`):
    ``RAYTRAD_COMPILERS`` in the environment, else this process's cores, at most
    :data:`MAX_COMPILERS`; 1 compiles each kernel lazily in this process only."""
    text = os.environ.get("RAYTRAD_COMPILERS", "").strip()
    if text:
        try:
            return max(1, int(text))
        except ValueError:
            log.warning("RAYTRAD_COMPILERS=%r is not a whole number: using 1", text)
            return 1
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        cores = os.cpu_count() or 1
    return min(cores, MAX_COMPILERS)


def _compile_ahead(numba: Any, kernels: dict[str, Any]) -> None:
    """Compile the kernels a render calls on every core at once, the first time.

    numba compiles a kernel on its first call, one after another, in numba's own front
    end (Python: about 18 s for a default render's kernels, 0.2-1.5 s each). When its
    cache lacks some of the kernels and signatures a render calls
    (:data:`raytrad.core._kernel_signatures.SIGNATURES`), they are shared out by their
    measured compile times among :func:`compilers` processes: this one compiles its share,
    the others (:func:`helper_command`) theirs into numba's cache,
    from which this process then loads them. Anything that goes wrong (no cache, a helper
    that fails or takes over :data:`HELPER_TIMEOUT`) leaves numba compiling lazily, as
    without this.
    """
    from raytrad.core._kernel_signatures import SECONDS, SIGNATURES

    workers = compilers()
    if workers < 2:
        return
    listed = [name for name in SIGNATURES if name in kernels]
    cold = [name for name in listed if not _cached(numba, kernels[name], SIGNATURES[name])]
    workers = min(workers, len(cold))
    if workers < 2:
        return
    start = time.perf_counter()
    groups = share_out(cold, workers, SECONDS)
    helpers = [_spawn(group) for group in groups[1:]]
    try:
        for name in groups[0]:
            _compile(numba, kernels[name], SIGNATURES[name])
    except BaseException:  # interrupted: the helpers' work is no longer wanted
        for helper in helpers:
            helper.kill()
            helper.communicate()
        raise
    for helper in helpers:
        _wait(helper)
    log.debug(
        "compiled %d kernels in %d processes in %.1f s",
        len(cold),
        workers,
        time.perf_counter() - start,
    )


def share_out(names: list[str], groups: int, seconds: dict[str, float]) -> list[list[str]]:
    """``names`` in ``groups`` lists of about equal total ``seconds`` (the longest first,
    each into the lightest list so far; 1 s for a name without a time). Every list is
    non-empty when there are at least ``groups`` names."""
    shares: list[list[str]] = [[] for _ in range(groups)]
    totals = [0.0] * groups
    for name in sorted(names, key=lambda n: -seconds.get(n, 1.0)):
        lightest = totals.index(min(totals))
        shares[lightest].append(name)
        totals[lightest] += seconds.get(name, 1.0)
    return shares


def signature(numba: Any, arguments: list[str]) -> tuple:
    """A kernel signature (a tuple of numba types, as ``dispatcher.signatures`` lists them)
    from its arguments' type ``repr``, e.g. ``["Array(float64, 2, 'C', False,
    aligned=True)", "float64"]``."""
    namespace = vars(numba.core.types)
    # the texts are raytrad's own (_kernel_signatures.py), never user input
    return tuple(eval(text, {"__builtins__": {}}, namespace) for text in arguments)


def _cached(numba: Any, dispatcher: Any, signatures: list[list[str]]) -> bool:
    """Whether numba's cache holds ``dispatcher`` for every one of ``signatures`` (read
    from its index as numba reads it before compiling); True where it cannot tell."""
    try:
        cache = dispatcher._cache
        index = cache._cache_file._load_index()
        codegen = dispatcher.targetctx.codegen()
        return all(cache._index_key(signature(numba, t), codegen) in index for t in signatures)
    except Exception as error:  # numba internals moved, no cache: leave it to numba
        log.debug("cannot read numba's cache for %s: %s", dispatcher, error)
        return True


def _compile(numba: Any, dispatcher: Any, signatures: list[list[str]]) -> None:
    """Compile ``dispatcher`` for each of ``signatures`` (numba saves it to its cache); a
    signature numba refuses is left to compile lazily."""
    for arguments in signatures:
        try:
            dispatcher.compile(signature(numba, arguments))
        except Exception as error:
            log.debug("compiling %s%s ahead failed: %s", dispatcher, arguments, error)


#: A helper's program: its first argument is where this process imported raytrad from.
HELPER = (
    "import sys; sys.path.insert(0, sys.argv[1]); "
    "from raytrad.core.compiled import _compile_named; sys.exit(_compile_named(sys.argv[2:]))"
)


def helper_command(names: list[str]) -> list[str]:
    """The command of a helper process compiling the kernels ``names`` into numba's cache.

    It imports raytrad from where this process did, whatever its working directory
    holds: ``python -m raytrad...`` run from a source checkout beside an installed copy
    imported the checkout's, compiled into the checkout's cache (another key), and the
    render compiled everything again."""
    root = str(Path(__file__).resolve().parents[2])
    return [sys.executable, "-c", HELPER, root, *names]


def _spawn(names: list[str]) -> subprocess.Popen:
    """A helper process compiling the kernels ``names`` (:func:`helper_command`)."""
    return subprocess.Popen(
        helper_command(names),
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )


def _wait(helper: subprocess.Popen) -> None:
    """Wait for a helper at most :data:`HELPER_TIMEOUT`; kill it past that (or when this
    process is interrupted meanwhile) and log why it failed."""
    try:
        _, errors = helper.communicate(timeout=HELPER_TIMEOUT)
    except BaseException:
        helper.kill()
        helper.communicate()
        raise
    if helper.returncode:
        log.debug("kernel compiler %s failed: %s", helper.args, errors.decode(errors="replace"))


def _compile_named(names: list[str]) -> int:
    """Entry of a helper process: compile the kernels ``names`` for their signatures in
    :data:`raytrad.core._kernel_signatures.SIGNATURES` into numba's cache."""
    import numba

    from raytrad.core._kernel_signatures import SIGNATURES

    kernels = _dispatchers(numba)
    for name in names:
        _compile(numba, kernels[name], SIGNATURES[name])
    return 0


def compile_listed() -> None:
    """Compile every kernel a render calls (:data:`~raytrad.core._kernel_signatures.SIGNATURES`)
    into numba's cache now: on every core, as a first render would
    (:func:`_compile_ahead`), then in this process whatever is still not cached (one core,
    or a helper that failed). ``setup.py``'s build hook runs it on the package being
    built, so that the installed package carries the cache."""
    import numba

    from raytrad.core._kernel_signatures import SIGNATURES

    kernels = _dispatchers(numba)
    _compile_ahead(numba, kernels)
    for name, signatures in SIGNATURES.items():
        # a kernel this process lacks (the packet loops without Embree's library) is left
        if name in kernels and not _cached(numba, kernels[name], signatures):
            _compile(numba, kernels[name], signatures)


def _jit(numba: Any, function: Any, borrowing: bool = False, parallel: bool = False) -> Any:
    """``numba.njit(cache=True, nogil=True)``, without the disk cache where numba finds no
    writable place for it (a read-only install and no home directory): compiled anew in
    each process then, never an error.

    A ``borrowing`` helper (a module's ``BORROWING``: it allocates nothing and returns no
    array, so it only borrows its arguments) is compiled without numba's reference
    counting (``_nrt=False``). numba otherwise counts a reference to every array it is
    handed, tuples' members included, on each call, and the near field calls its
    helpers once a triangle. Where numba refuses the option, the helper counts as before.
    ``parallel``: compiled with ``parallel=True`` (its ``prange`` loops on numba's
    threads).
    """
    options: dict[str, Any] = {"nogil": True}
    if parallel:
        options["parallel"] = True
    if borrowing and hasattr(numba.core.cpu.CPUTargetOptions, "_nrt"):
        options["_nrt"] = False
    try:
        return numba.njit(cache=True, **options)(function)
    except RuntimeError as error:  # numba: "cannot cache function ...: no locator"
        log.debug("numba cannot cache %s (%s): compiling without a cache", function, error)
        return numba.njit(**options)(function)
