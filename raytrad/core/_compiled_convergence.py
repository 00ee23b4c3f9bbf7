"""The convergence log's per-receiver sums behind :mod:`raytrad.core.compiled`, written for
numba (imported only there). Plain Python as written here;
:func:`raytrad.core.compiled.get` compiles every function in :data:`KERNELS`. Each
computes what its numpy reference computes (:mod:`raytrad.core.convergence`); see there
for shapes and units.
"""

# mypy: ignore-errors

import numpy as np

#: Every function to compile, each after the helpers it calls.
KERNELS = ("radiosity_sums",)


def radiosity_sums(counted, irradiance, emission, reflectance, area):
    """``sum_i a_i B_i^2`` and ``max_i |B_i|`` per channel, with ``B_i = emission[i] +
    reflectance[i] * irradiance[counted[i]]``, in one pass and no temporary array (see
    :func:`raytrad.core.convergence.radiosity_sums`, the reference)."""
    square = np.zeros(3)
    peak = np.zeros(3)
    for i in range(len(counted)):
        k = counted[i]
        a = area[i]
        for c in range(3):
            b = emission[i, c] + reflectance[i, c] * irradiance[k, c]
            square[c] += a * b * b
            v = abs(b)
            if (v > peak[c] or v != v) and peak[c] == peak[c]:  # a NaN stays, as numpy's
                peak[c] = v
    return square, peak
