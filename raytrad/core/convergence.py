"""How wrong is the solve now: an error log with an estimate, a guaranteed bound and, when a
reference is known, the true error. The derivation of the bound is in ``docs/error.md``.

Notation (see :mod:`raytrad.core.solver`): patch unshot radiosity dB_p, patch area A_p, receiver
area a_j, reflectance rho_j, form factors F_jp, capture fraction g_p = sum_j a_j F_jp / A_p.

Every relative error is taken over the receivers that do not emit
(:func:`counted_receivers`): a lamp's radiosity is mostly its own emission, known exactly,
and one bright lamp would otherwise dominate the norm and make every error look small.
Where every surface emits (a furnace), all receivers count.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from raytrad.arrays import column_max
from raytrad.constants import sign_with_band, tol
from raytrad.core import compiled
from raytrad.core.formfactor import FormFactorEngine
from raytrad.core.mesh import RadiosityMesh
from raytrad.core.solver import SolverState, filled_capture

#: Log points are spaced by this factor in shot count (plus every point while shots < 20).
LOG_SPACING = 1.05


@dataclass(frozen=True)
class Reference:
    """A solution to measure the true error against.

    Attributes
    ----------
    radiosity : (R, 3) float64
        Reference radiosity per receiver [W m-2].
    kind : str
        ``dense`` (direct solve of the same system), ``analytic``, ``file`` or ``converged``.
    description : str
        Where it came from, in words.
    """

    radiosity: np.ndarray
    kind: str
    description: str


def counted_receivers(mesh: RadiosityMesh) -> np.ndarray:
    """(R,) bool: the receivers relative errors are measured over.

    Those that do not emit, or every receiver when all of them emit.
    """
    counted = ~(mesh.receiver_emitted_exitance > 0).any(axis=1)
    if not (counted & (mesh.receiver_area > 0)).any():
        counted = np.ones(mesh.receiver_count, dtype=bool)
    return np.asarray(counted, dtype=bool)


def true_error(
    radiosity: np.ndarray, reference: np.ndarray, area: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Area-weighted relative RMS and relative maximum error per channel.

    Parameters
    ----------
    radiosity, reference : (R, 3) float64 [W m-2]
    area : (R,) float64 [m2]

    Returns
    -------
    rms : (3,) float64, sqrt(sum a (B - B*)^2 / sum a B*^2) [1]
    maximum : (3,) float64, max |B - B*| / max B* [1]
    """
    difference = radiosity - reference
    norm = np.sqrt(area @ reference**2)
    rms = np.sqrt(area @ difference**2) / np.where(norm > 0, norm, 1.0)
    peak = column_max(np.abs(reference))
    maximum = column_max(np.abs(difference)) / np.where(peak > 0, peak, 1.0)
    return rms, maximum


@dataclass(frozen=True)
class ReceiverNorms:
    """What the bound and the estimate need of the receivers the error is taken over.

    Attributes
    ----------
    area : float
        Their total area, ``sum_j a_j`` [m2].
    square : (3,) float64
        ``sum_j a_j B_j^2`` [W2 m-2].
    peak : (3,) float64
        ``max_j |B_j|`` [W m-2].
    reflectance_square : (3,) float64
        ``sum_j a_j rho_j^2`` [m2].
    """

    area: float
    square: np.ndarray
    peak: np.ndarray
    reflectance_square: np.ndarray


def radiosity_sums(
    counted: np.ndarray,
    irradiance: np.ndarray,
    emission: np.ndarray,
    reflectance: np.ndarray,
    area: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``sum_i a_i B_i^2`` [W2 m-2] and ``max_i |B_i|`` [W m-2], (3,) each, of the
    radiosity ``B_i = emission[i] + reflectance[i] * irradiance[counted[i]]`` of the
    receivers ``counted`` ((N,) int64 into ``irradiance`` (R, 3) [W m-2]; ``emission``
    (N, 3) [W m-2], ``reflectance`` (N, 3) [1] and ``area`` (N,) [m2] are theirs). The
    reference of the compiled loop the convergence monitor sums a row with
    (:mod:`raytrad.core._compiled_convergence`: one pass and no temporary array, a sixth
    of these numpy steps' time at 106 049 receivers)."""
    radiosity = emission + reflectance * np.take(irradiance, counted, axis=0)
    return area @ radiosity**2, column_max(np.abs(radiosity))


def receiver_norms(
    receiver_area: np.ndarray, radiosity: np.ndarray, receiver_reflectance: np.ndarray
) -> ReceiverNorms:
    """:class:`ReceiverNorms` of receivers of ``receiver_area`` ((R,) [m2]), ``radiosity``
    ((R, 3) [W m-2]) and ``receiver_reflectance`` ((R, 3) [1]). The convergence monitor
    sums the area and the reflectance once a solve, and the radiosity once a row."""
    return ReceiverNorms(
        float(receiver_area.sum()),
        receiver_area @ radiosity**2,
        column_max(np.abs(radiosity)),
        receiver_area @ receiver_reflectance**2,
    )


def error_bound(
    unshot: np.ndarray,
    patch_area: np.ndarray,
    norms: ReceiverNorms,
    max_reflectance: np.ndarray,
    max_row_sum: float,
    max_capture: float,
    unshot_peak: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Guaranteed bounds on the relative RMS and maximum error of the current radiosity.

    With u = (I - K)^-1 dB the radiosity still to be shot (K = W diag(rho) F),
    ``|B*_j - B_j| <= rho_j sum_p F_jp |u_p|``, hence with rho_m the largest reflectance,
    r_m >= every row sum of F and g_m >= every capture fraction::

        max_j |e_j|        <= rho_m r_m max_p |dB_p| / (1 - rho_m r_m)
        sum_j a_j |e_j|    <= rho_m g_m sum_p A_p |dB_p| / (1 - rho_m g_m)
        RMS_a(e)           <= sqrt(max |e| * mean_a |e|)

    and relative to the unknown solution, ||B*|| >= ||B|| - ||e||.

    Parameters
    ----------
    unshot : (P, 3) float64 [W m-2]
    patch_area : (P,) float64 [m2]
    norms : ReceiverNorms
        Of the current solution at the receivers the error is taken over (any subset: the
        bounds on the maximum and on the area-weighted sum hold over every subset,
        :func:`counted_receivers`).
    max_reflectance : (3,) float64 [1]
    max_row_sum, max_capture : float [1]
    unshot_peak : (P, 3) float64 or None [W m-2]
        The largest unshot radiosity of each patch's receivers (a near receiver sees them
        one by one, :attr:`~raytrad.core.solver.SolverState.unshot_peak`); None: ``|unshot|``.

    Returns
    -------
    rms, maximum : (3,) float64, relative bounds [1]; inf where no bound exists yet
        (rho_m r_m >= 1, or the error could still be as large as the solution).
    """
    total_area = norms.area
    q_max = max_reflectance * max_row_sum
    q_sum = max_reflectance * max_capture
    with np.errstate(divide="ignore", invalid="ignore"):
        peak = np.abs(unshot) if unshot_peak is None else np.maximum(np.abs(unshot), unshot_peak)
        e_max = np.where(q_max < 1.0, q_max * peak.max(axis=0) / (1.0 - q_max), np.inf)
        e_mean = np.where(
            q_sum < 1.0,
            q_sum * (patch_area @ np.abs(unshot)) / (1.0 - q_sum) / total_area,
            np.inf,
        )
        e_rms = np.sqrt(e_max * e_mean)
        b_rms = np.sqrt(norms.square / total_area)
        b_max = norms.peak
        rms = np.where(b_rms > e_rms, e_rms / (b_rms - e_rms), np.inf)
        maximum = np.where(b_max > e_max, e_max / (b_max - e_max), np.inf)
    zero = (e_max == 0) & (e_mean == 0)
    return np.where(zero, 0.0, rms), np.where(zero, 0.0, maximum)


def error_estimate(
    unshot: np.ndarray,
    patch_area: np.ndarray,
    patch_reflectance: np.ndarray,
    captured: np.ndarray,
    norms: ReceiverNorms,
    spread: np.ndarray | float = 0.0,
) -> np.ndarray:
    """Predicted relative RMS change still to come, from the ambient term (Feda formula 3).

    The unshot power, amplified by the scene's measured interreflection
    ``1 / (1 - rho g)``, spread over all surfaces and reflected once: ``rho_j * Ambient``,
    relative to the current solution at the receivers of ``norms``
    (:func:`receiver_norms`; ``sum_j a_j (rho_j Ambient)^2 = Ambient^2 sum_j a_j
    rho_j^2`` per channel). ``spread`` ((P, 3) or 0) is the unshot radiosity's spread
    within each patch (:attr:`~raytrad.core.solver.SolverState.spread`), counted in the
    unsigned sum.

    Returns
    -------
    (3,) float64 [1]
    """
    capture = filled_capture(captured, patch_area)
    lost = np.maximum(patch_area @ (1.0 - patch_reflectance * capture[:, None]), 1e-300)
    # The signed unshot power is Feda's ambient; after overshooting, positive and negative
    # unshot radiosity partly cancel, and the signed sum can be near zero while the
    # remaining corrections are not. The unsigned sum assumes no cancellation at all. The
    # remaining change lies between the two; their geometric mean tracks it (docs/error.md).
    caught = patch_area * capture  # only the caught part of a shot lands on surfaces
    signed = np.abs(caught @ unshot) / lost
    unsigned = (caught @ (np.abs(unshot) + spread)) / lost
    ambient = np.sqrt(signed * unsigned)
    change = ambient * np.sqrt(norms.reflectance_square)
    norm = np.sqrt(norms.square)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(norm > 0, change / norm, np.where(change > 0, np.inf, 0.0))


@dataclass
class ErrorLog:
    """Convergence history of one solve, one row per log point."""

    seconds: list[float] = field(default_factory=list)
    shots: list[int] = field(default_factory=list)
    rays: list[int] = field(default_factory=list)
    residual: list[float] = field(default_factory=list)
    estimate: list[list[float]] = field(default_factory=list)
    bound_rms: list[list[float]] = field(default_factory=list)
    bound_max: list[list[float]] = field(default_factory=list)
    true_rms: list[list[float]] = field(default_factory=list)
    true_max: list[list[float]] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready columns (inf becomes null)."""
        return {name: _jsonable(getattr(self, name)) for name in self.__dataclass_fields__}

    @classmethod
    def from_dict(cls, columns: dict[str, Any]) -> ErrorLog:
        """The log :meth:`as_dict` gave (null back to inf).

        Raises
        ------
        ValueError
            ``columns`` are not a log's: a column missing, or of another length (the
            true-error columns may be empty).
        """
        names = list(cls.__dataclass_fields__)
        if not isinstance(columns, dict) or sorted(columns) != sorted(names):
            raise ValueError("not an error log")
        rows = len(columns["shots"])
        for name in names:
            if len(columns[name]) != rows and not (name.startswith("true_") and not columns[name]):
                raise ValueError(
                    f"error log column {name} has {len(columns[name])} rows, not {rows}"
                )
        return cls(**{name: _restored(columns[name]) for name in names})

    def first_below(self, threshold: float, column: str = "true_rms") -> tuple[float, int] | None:
        """(seconds, shots) at the first log point whose worst channel is below threshold."""
        for seconds, shots, values in zip(
            self.seconds, self.shots, getattr(self, column), strict=True
        ):
            if max(values) < threshold:
                return seconds, shots
        return None


def _restored(values: list[Any]) -> list[Any]:
    """:func:`_jsonable`'s values back: null to inf."""
    return [_restored(v) if isinstance(v, list) else math.inf if v is None else v for v in values]


def _jsonable(values: list[Any]) -> list[Any]:
    def clean(v: Any) -> Any:
        if isinstance(v, list):
            return [clean(x) for x in v]
        if isinstance(v, float) and not math.isfinite(v):
            return None
        return v

    return [clean(v) for v in values]


class ConvergenceMonitor:
    """Keeps an :class:`ErrorLog` during a solve; pass it as the solver's progress hook.

    Rows are taken at geometrically spaced shot counts (every shot up to 20, then each
    time the count has grown by :data:`LOG_SPACING`), and by :meth:`finish`, so the cost
    stays a small fraction of the solve whatever its length.

    Parameters
    ----------
    mesh : RadiosityMesh
    engine : FormFactorEngine
        Supplies the largest form-factor row sum seen so far.
    reference : Reference or None
    history : ErrorLog or None
        The log of the solve this one resumes (saved with its checkpoint): the new rows
        follow it, so the log covers the whole solve. Passed over when it has true-error
        columns and there is no reference, or the other way round.
    """

    def __init__(
        self,
        mesh: RadiosityMesh,
        engine: FormFactorEngine,
        reference: Reference | None = None,
        history: ErrorLog | None = None,
    ) -> None:
        self.mesh = mesh
        self.engine = engine
        self.reference = reference
        self.log = ErrorLog()
        self._next = 0
        if history is not None and history.shots:
            if bool(history.true_rms) == (reference is not None):
                self.log = history
                self._next = _next_row(history.shots[-1])
        self._max_reflectance = mesh.receiver_reflectance.max(axis=0)
        #: the receivers the error is taken over, and their area, reflectance and emission
        self._counted = np.flatnonzero(counted_receivers(mesh))
        self._area = mesh.receiver_area[self._counted]
        self._reflectance = mesh.receiver_reflectance[self._counted]
        self._emission = mesh.receiver_emitted_exitance[self._counted]
        self._area_total = float(self._area.sum())
        self._reflectance_square = self._area @ self._reflectance**2
        self._emitted = float((mesh.receiver_area @ mesh.receiver_emitted_exitance).sum())
        self.latest_estimate = math.inf
        self.latest_bound = math.inf

    def __call__(self, state: SolverState, residual: float = math.nan) -> None:
        if state.shots >= self._next:
            self.record(state)
            self._next = _next_row(state.shots)

    def record(self, state: SolverState) -> None:
        """Add one row for the current state."""
        state.settled()  # its spreads summed again where a shot left them to drift
        m = self.mesh
        unshot_power = float((m.patch_area @ state.unshot_magnitude).sum())
        residual = unshot_power / self._emitted if self._emitted > 0 else 0.0
        # the counted receivers' radiosity (the others' is never read), summed
        area = self._area
        fast = compiled.get()
        sums = radiosity_sums if fast is None else fast.radiosity_sums
        square, peak = sums(
            self._counted, state.irradiance, self._emission, self._reflectance, area
        )
        norms = ReceiverNorms(self._area_total, square, peak, self._reflectance_square)
        captured = state.captured[np.isfinite(state.captured)]
        max_capture = max(1.0, float(captured.max()) if len(captured) else 1.0)
        bound_rms, bound_max = error_bound(
            state.unshot_magnitude,
            m.patch_area,
            norms,
            self._max_reflectance,
            max(1.0, self.engine.max_row_sum),
            max_capture,
            state.unshot_peak,
        )
        estimate = error_estimate(
            state.unshot,
            m.patch_area,
            m.patch_reflectance,
            state.captured,
            norms,
            state.spread if state.spread.shape == state.shot.shape else 0.0,
        )
        log = self.log
        log.seconds.append(state.seconds)
        log.shots.append(state.shots)
        log.rays.append(state.rays)
        log.residual.append(residual)
        log.estimate.append(estimate.tolist())
        log.bound_rms.append(bound_rms.tolist())
        log.bound_max.append(bound_max.tolist())
        if self.reference is not None:
            irradiance = np.take(state.irradiance, self._counted, axis=0)
            radiosity = self._emission + self._reflectance * irradiance
            truth = self.reference.radiosity[self._counted]
            rms, maximum = true_error(radiosity, truth, area)
            log.true_rms.append(rms.tolist())
            log.true_max.append(maximum.tolist())
        self.latest_estimate = float(estimate.max())
        self.latest_bound = float(bound_rms.max())

    def finish(self, state: SolverState) -> ErrorLog:
        """Record the final state (unless it is the last row already) and return the log."""
        if not self.log.shots or self.log.shots[-1] != state.shots:
            self.record(state)
        return self.log


def _next_row(shots: int) -> int:
    """The shot count of the log row after one at ``shots`` (every shot up to 20, then
    :data:`LOG_SPACING` apart)."""
    return shots + 1 if shots < 20 else int(shots * LOG_SPACING) + 1


def eta_seconds(seconds: list[float], residuals: list[float], target: float) -> float:
    """Time until ``target`` residual, extrapolating the decay of the recent history.

    Fits log(residual) against time over the last third of the history (at least 5 points);
    returns inf when the residual is not decreasing, 0 when the target is reached. A fitted
    decrease over the fitted span within ``tol.fit`` of the largest fitted log-residual is
    rounding noise of the fit (a constant history fits a slope of about -1e-17), not a
    decay.

    Parameters
    ----------
    seconds, residuals : lists of float
        History of (elapsed time [s], residual [1]).
    target : float
        Residual to reach [1].
    """
    if residuals and residuals[-1] <= target:
        return 0.0
    n = len(seconds)
    if n < 5:
        return math.inf
    start = min(n - 5, 2 * n // 3)
    t = np.asarray(seconds[start:])
    r = np.log(np.maximum(np.asarray(residuals[start:]), 1e-300))
    if np.ptp(t) <= 0:
        return math.inf
    slope = float(np.polyfit(t, r, 1)[0])
    band = tol.fit * max(1.0, float(np.abs(r).max()))
    if sign_with_band(slope * np.ptp(t), band) >= 0:
        return math.inf
    return float((math.log(target) - r[-1]) / slope)


class ResidualTrend:
    """The residual history of a running solve, sampled for :func:`eta_seconds`.

    A sample is kept at most every ``interval`` seconds of solve time, so the fit stays
    cheap however many shots there are.

    Parameters
    ----------
    target : float
        The residual to reach [1].
    interval : float
        Shortest solve time between samples [s].
    """

    def __init__(self, target: float, interval: float = 0.25) -> None:
        self.target = target
        self.interval = interval
        self._seconds: list[float] = []
        self._residuals: list[float] = []
        self.eta = math.inf

    def add(self, seconds: float, residual: float) -> float:
        """Record (solve time [s], residual [1]); the current estimate of the time left [s]."""
        if residual <= self.target:
            self.eta = 0.0
        elif not self._seconds or seconds - self._seconds[-1] >= self.interval:
            self._seconds.append(seconds)
            self._residuals.append(residual)
            self.eta = eta_seconds(self._seconds, self._residuals, self.target)
        return self.eta
