"""Returning freed memory to the operating system after a long motion.

A 10-minute motion frees arrays of tens of MB between its phases (sampling, decoding,
writing). glibc keeps such blocks in its heap once its mmap threshold has grown past
them, so they stay resident: 90 MB after sampling a 10-minute walk (BENCHMARKS.md).
`malloc_trim(0)` hands them back. Elsewhere (macOS, Windows, musl) this does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
from functools import lru_cache

LONG_MOTION_VALUES = 1 << 22  # samples x frames x features above which a trim is worth its milliseconds


@lru_cache(maxsize=1)
def _malloc_trim():
    name = ctypes.util.find_library("c")
    try:
        return ctypes.CDLL(name).malloc_trim if name else None
    except (OSError, AttributeError):
        return None


def release_free_heap(values: int) -> None:
    """After work on `values` numbers: give glibc's free heap pages back, for long motions only."""
    trim = _malloc_trim()
    if trim is not None and values >= LONG_MOTION_VALUES:
        trim(0)
