"""Model load time: `load_model()` of the bundled demo, warm, median of 7 calls.

    python bench/load_time.py LABEL      # PYTHONPATH=<checkout> to compare two versions
"""

from __future__ import annotations

import statistics
import sys
import time

from sinmdm.runtime import load_model


def main() -> None:
    load_model()  # warm-up: imports, page cache
    times = []
    for _ in range(7):
        began = time.perf_counter()
        load_model()
        times.append(time.perf_counter() - began)
    label = sys.argv[1] if len(sys.argv) > 1 else ""
    print(f"{label} load_model() demo: median {statistics.median(times):.3f} s, "
          f"min {min(times):.3f}, max {max(times):.3f} (7 runs)")


if __name__ == "__main__":
    main()
