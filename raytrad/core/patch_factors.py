"""Patch-to-patch form factors and the overshooting methods that need them.

Feda's paper (``../shared/papers/feda-overshooting.txt``) has three estimates of the
unshot radiosity that gather over patch-to-patch factors F_ij (patch i receiving from
patch j): positive overshooting (formula 6), super-shoot-gather (8) and enhanced
super-shoot-gather with ambient light (9). Vertex-to-patch ray casting gives F_kj for
every receiver k; the area-weighted mean over patch i's receivers (``W``, the patch
average of :mod:`raytrad.core.system`) is the area-to-patch factor, so the matrix comes
from the columns the form-factor pass already traced, with their visibility. Receivers
have their own reflectance, so what is kept is the reflected factor

    K_ijc = sum_k W_ik rho_kc F_kj      (rho_i F_ij of the paper, per channel c),

P x P x 3 float64: its size is stated before it is built and refused above
:data:`MAX_PATCH_FACTOR_MB` (:func:`check_patch_factor_memory`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from raytrad.errors import SettingsError

if TYPE_CHECKING:
    from raytrad.core.formfactor import FormFactorEngine
    from raytrad.core.system import DiscreteSystem

log = logging.getLogger(__name__)

MAX_PATCH_FACTOR_MB = 2048.0
"""The most memory the patch-to-patch factors may take [MiB] (about 9000 patches)."""


def patch_factor_mb(patch_count: int) -> float:
    """Memory of the P x P x 3 float64 reflected factors [MiB]."""
    return patch_count * patch_count * 3 * 8 / 2**20


def check_patch_factor_memory(patch_count: int, method: str) -> None:
    """Refuse, before any work, a method whose patch-to-patch factors would not fit.

    Raises
    ------
    SettingsError
        Naming the method, the patch count, the memory and the way out.
    """
    need = patch_factor_mb(patch_count)
    if need > MAX_PATCH_FACTOR_MB:
        raise SettingsError(
            f"method {method!r} needs patch-to-patch form factors: {patch_count} patches "
            f"take {need:.0f} MiB, above the {MAX_PATCH_FACTOR_MB:.0f} MiB limit; use fewer "
            "--patches, or a method without them (ambient, overrelaxation, progressive)"
        )


@dataclass(frozen=True)
class PatchFactors:
    """The reflected patch-to-patch factors ``K`` (see the module docstring).

    Attributes
    ----------
    reflected : (3, P, P) float64
        ``reflected[c, i, j] = K_ijc`` [1], one matrix per channel (so gathering is one
        BLAS product per channel).
    return_share : (P, 3) float64
        ``sum_j K_ij K_ji``: the share of a patch's shot that one bounce brings back to
        it (formula 7), computed once.
    """

    reflected: np.ndarray
    return_share: np.ndarray

    @classmethod
    def from_matrix(cls, reflected: np.ndarray) -> PatchFactors:
        """From (3, P, P) reflected factors."""
        reflected = np.ascontiguousarray(reflected, dtype=np.float64)
        returned = np.einsum("cij,cji->ic", reflected, reflected)
        return cls(reflected, returned)

    @classmethod
    def from_columns(
        cls, problem: DiscreteSystem, engine: FormFactorEngine, receiver_reflectance: np.ndarray
    ) -> PatchFactors:
        """K from every patch's (balanced) vertex-to-patch column."""
        count = len(problem.patch_area)
        log.info(
            "patch-to-patch form factors: %d x %d, %.1f MiB", count, count, patch_factor_mb(count)
        )
        reflected = np.empty((3, count, count))
        for j in range(count):
            column = engine.column(j)
            values = receiver_reflectance[column.receivers] * column.factors[:, None]
            reflected[:, :, j] = problem.average(column.receivers, values).T
        return cls.from_matrix(reflected)

    def gathered(self, unshot: np.ndarray) -> np.ndarray:
        """(P, 3) ``sum_j K_ij dB_j``: what each patch will reflect of ``unshot`` [W m-2]."""
        return np.stack([self.reflected[c] @ unshot[:, c] for c in range(3)], axis=1)

    def returned(self) -> np.ndarray:
        """(P, 3) ``sum_j K_ij K_ji`` (formula 7; :attr:`return_share`)."""
        return self.return_share


def _only_positive(amount: np.ndarray, unshot: np.ndarray) -> np.ndarray:
    """The estimate for patches with positive unshot radiosity; a patch with none shoots
    what it has (negative) instead of an estimate.

    The paper lets such patches wait until others' shots make them positive, which
    exact factors guarantee. The factors here are the patch means of vertex-to-patch
    factors, and near receivers gather what a patch shoots as it varies across it, so
    a small overshoot can stay negative for ever: shooting it when it is the largest
    unshot power keeps the solve converging (super-shoot-gather stalled at a 3e-6
    residual on the Cornell box otherwise)."""
    waiting = np.asarray(~(unshot > 0).any(axis=1))
    return np.where(waiting[:, None], unshot, amount)


def positive_overshoot(unshot: np.ndarray, factors: PatchFactors) -> np.ndarray:
    """(P, 3) what each patch shoots by positive overshooting (formula 6) [W m-2].

    ``dB_i + sum_j K_ij max(dB_j, 0)``: the unshot radiosity plus what the patch will
    surely receive from the others' positive unshot radiosity; patches with none wait.
    """
    amount = unshot + factors.gathered(np.maximum(unshot, 0.0))
    return _only_positive(amount, unshot)


def super_shoot_gather(unshot: np.ndarray, factors: PatchFactors) -> np.ndarray:
    """(P, 3) super-shoot-gather (formula 8, the simplified form without the N x N
    matrix) [W m-2]: formula 6 divided by ``1 - sum_j K_ij K_ji``, the geometric series of
    what the environment reflects back to the shooter."""
    gathered = unshot + factors.gathered(np.maximum(unshot, 0.0))
    amount = gathered / np.maximum(1.0 - factors.returned(), 1e-12)
    return _only_positive(amount, unshot)


def enhanced_super_shoot_gather(
    unshot: np.ndarray, raised: np.ndarray, patch_area: np.ndarray, factors: PatchFactors
) -> np.ndarray:
    """(P, 3) enhanced super-shoot-gather with ambient light (formula 9) [W m-2].

    Parameters
    ----------
    unshot : (P, 3) float
        dB [W m-2].
    raised : (P, 3) float
        ``dB_j + rho_j Ambient``: the others' unshot radiosity raised by the ambient light.
    patch_area : (P,) float [m2]
    factors : PatchFactors

    Notes
    -----
    The amount is capped at the total unshot power over the patch's area, the cap the
    paper says its source [Xu 94] omitted: no patch shoots more than the total unshot
    power, so the ambient term never turns negative (as formula 5 does for ambient
    overshooting).
    """
    amount = (unshot + factors.gathered(raised)) / np.maximum(1.0 - factors.returned(), 1e-12)
    cap = np.maximum(patch_area @ unshot, 0.0)[None, :] / patch_area[:, None]
    return np.minimum(amount, cap)
