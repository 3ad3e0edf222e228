"""Python lists handed to pybullet's shape constructors, refilled in place so resets do not leak them.

Owns `bullet_list`. pybullet 3.2.7 keeps two references to every list, and to every row list, passed as
vertices / indices / uvs / normals / heightfieldData (measured with sys.getrefcount), so a fresh list per reset
leaks ~190 B per vertex (~16 MB per desert reset). Refilling one pooled list per (argument, shape) bounds that
to one leaked list per shape ever used. Not thread-safe: build worlds from one thread at a time.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

_POOL: dict[tuple[str, tuple[int, ...]], list] = {}


def bullet_list(argument: str, values: npt.ArrayLike) -> list:
    """`values` (N,) or (N, K) as a Python list for pybullet argument `argument` ("vertices", "uvs", ...).

    The returned list is the pooled one for (argument, shape), refilled in place (outer and row objects kept),
    so pass it straight to pybullet and do not hold on to it: the next call with that key overwrites it.
    """
    arr = np.asarray(values)
    if arr.ndim not in (1, 2):
        raise ValueError(f"bullet_list needs a 1-D or 2-D array for {argument!r}, got shape {arr.shape}")
    fresh = arr.tolist()
    pooled = _POOL.setdefault((argument, arr.shape), fresh)
    if pooled is fresh:
        return fresh
    if arr.ndim == 1:
        pooled[:] = fresh
    else:
        for row, values_row in zip(pooled, fresh):
            row[:] = values_row
    return pooled
