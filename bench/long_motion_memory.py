"""Peak RSS per phase of one long motion: load, sample, decode (with contact cleanup), write.

    python bench/long_motion_memory.py MODEL.onnx SECONDS [--steps 2] [--no-contacts]

RSS is polled every 3 ms in a thread. The contact channels of the sampled features are
set to a 20-frame on/off pattern (what a trained walk gives) unless --no-contacts, so
the cleanup runs on any model, also an untrained one (memory does not depend on the
weights). Prints each phase's RSS at its start and its peak, the times, and the BVH's
sha256 (the same bytes before and after a memory change, where it should be).
"""

from __future__ import annotations

import argparse
import hashlib
import os
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

PAGE = os.sysconf("SC_PAGE_SIZE")


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * PAGE / 2**20


class PhaseWatch:
    def __init__(self) -> None:
        self.phase, self.peaks, self.at_start = "import", {}, {}
        threading.Thread(target=self._poll, daemon=True).start()

    def _poll(self) -> None:
        while True:
            self.peaks[self.phase] = max(self.peaks.get(self.phase, 0.0), rss_mb())
            time.sleep(0.003)

    def enter(self, phase: str) -> None:
        time.sleep(0.02)
        self.at_start[phase] = round(rss_mb())
        self.phase = phase


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model")
    parser.add_argument("seconds", type=float)
    parser.add_argument("--steps", type=int, default=2)
    parser.add_argument("--no-contacts", action="store_true")
    args = parser.parse_args()
    watch = PhaseWatch()
    from sinmdm.runtime import SamplingOptions, load_model
    from sinmdm.runtime.bvh import write_bvh
    from sinmdm.runtime.generate import decode_clip
    from sinmdm.runtime.sampler import sample_features

    watch.enter("load")
    model = load_model(args.model, threads=2)
    frames = int(args.seconds * model.codec.fps)
    watch.enter("sample")
    began = time.perf_counter()
    features = sample_features(model, frames, SamplingOptions(steps=args.steps).resolve(model, frames))
    times = {"sample": time.perf_counter() - began}
    if not args.no_contacts:
        t = np.arange(frames)
        for k, channel in enumerate(model.codec.layout.indices(("contact",))):
            features[:, :, channel] = ((t + 7 * k) // 20) % 2
    watch.enter("decode")
    began = time.perf_counter()
    clip = decode_clip(model, features[0], model.start_position, True)
    times["decode"] = time.perf_counter() - began
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "long.bvh"
        watch.enter("write")
        began = time.perf_counter()
        write_bvh(path, clip)
        times["write"] = time.perf_counter() - began
        watch.enter("end")
        digest = hashlib.sha256(path.read_bytes()).hexdigest()[:12]
    time.sleep(0.05)
    print("RSS at start (MB):", watch.at_start)
    print("peak RSS (MB):", {k: round(v) for k, v in watch.peaks.items()})
    print("seconds:", {k: round(v, 1) for k, v in times.items()}, "bvh sha256:", digest)


if __name__ == "__main__":
    main()
