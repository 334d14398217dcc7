"""Array helpers of the message classes: every array a message holds is a read-only copy.

Private to :mod:`fabric.interfaces`; a frozen dataclass whose arrays could be written in place would
not be a value.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def frozen(a: Any, dtype: Any = np.float64) -> np.ndarray:
    """A read-only copy of ``a`` as ``dtype``."""
    arr = np.array(a, dtype=dtype, copy=True)
    arr.setflags(write=False)
    return arr


def vector(v: Any) -> np.ndarray:
    """A read-only 1-D float64 copy of ``v``; None is the empty vector (an optional array that is absent)."""
    a = np.array(() if v is None else v, dtype=np.float64, copy=True).reshape(-1)
    a.setflags(write=False)
    return a
