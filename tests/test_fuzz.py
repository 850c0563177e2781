"""Property-based fuzzing of the whole clip path: read -> build_codec -> encode -> decode
-> write. Mutated real clips and generated skeletons may be refused, but only with the
project's own error type, and whatever is written reads back finite. Seeded and bounded
(derandomized hypothesis, a fixed number of examples), so it runs the same in CI."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sinmdm.runtime.bvh import BVH, CHANNEL_NAMES, Skeleton, format_bvh, parse_bvh, read_bvh, write_bvh
from sinmdm.runtime.errors import SinMDMError
from sinmdm.runtime.features import build_codec

from .conftest import DEMO_CLIP, SHARED_MOTIONS

FUZZ = settings(derandomize=True, deadline=None, max_examples=200, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
BASE_FRAMES = 40  # real clips are cut to this many frames: the mutations matter, not the length
NUMBER = re.compile(rb"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")
REPLACEMENTS = [b"1e308", b"-1e308", b"3.5e38", b"1e39", b"nan", b"NaN", b"inf", b"-inf", b"-1", b"-0", b"0",
                b"", b"1e-320", b"99999999999999999999", b"100", b"1e30", b"-12345.678"]


def _cut(path: Path, frames: int) -> bytes:
    """The clip with only its first `frames` frames (its 'Frames:' line rewritten)."""
    clip = read_bvh(path)
    return format_bvh(BVH(clip.skeleton, clip.frame_time, clip.values[:frames])).encode()


def _base_clips() -> list[bytes]:
    clips = [_cut(DEMO_CLIP, BASE_FRAMES)]
    real = SHARED_MOTIONS / "Elephant_idle1.bvh"
    if real.exists():
        clips.append(_cut(real, BASE_FRAMES))
    return clips


BASES = _base_clips()


def through_the_pipeline(data: bytes, out: Path) -> None:
    """Read, encode, decode and write; a refusal must be a SinMDMError, and a written file
    must read back with finite values only."""
    try:
        clip = parse_bvh(data, "fuzz.bvh")
        codec = build_codec(clip)
        features = codec.encode(clip)
        assert np.isfinite(features).all()
        write_bvh(out, codec.decode_bvh(features, codec.start_position(clip)))
    except SinMDMError as error:
        assert "\n" not in str(error) and str(error)
        return
    written = read_bvh(out)
    assert np.isfinite(written.values).all() and np.isfinite(written.skeleton.offsets).all()


# ------------------------------------------------------------------ mutated real clips


@st.composite
def mutated_clips(draw) -> bytes:
    # Positions come from a Random that hypothesis seeds (derandomized): uniform over the
    # file, where hypothesis' own integers favour the first bytes (the HIERARCHY keyword).
    rng = draw(st.randoms(use_true_random=True))
    data = bytearray(draw(st.sampled_from(BASES)))
    for _ in range(rng.randint(1, 3)):
        if not data:
            break
        kind = rng.choice(["flip", "delete line", "number", "number", "truncate"])
        if kind == "flip":
            data[rng.randrange(len(data))] = rng.choice(b"{}0123456789.-+eE \n\t:xNa")
        elif kind == "delete line":
            lines = bytes(data).split(b"\n")
            del lines[rng.randrange(len(lines))]
            data = bytearray(b"\n".join(lines))
        elif kind == "number":
            matches = list(NUMBER.finditer(bytes(data)))
            if matches:
                match = rng.choice(matches)
                data[match.start():match.end()] = rng.choice(REPLACEMENTS)
        else:
            del data[rng.randrange(len(data)):]
    return bytes(data)


@FUZZ
@given(data=mutated_clips())
def test_mutated_real_clips(data, tmp_path):
    through_the_pipeline(data, tmp_path / "out.bvh")


# ------------------------------------------------------------------ generated skeletons


@st.composite
def depth_first_parents(draw) -> list[int]:
    """A forest in file (depth-first) order: each joint's parent is the previous joint or
    one of its ancestors, or none (a new ROOT)."""
    parents, chain = [-1], [0]
    for j in range(1, draw(st.integers(1, 12))):
        new_root = draw(st.integers(0, 9)) == 0  # mostly one tree, sometimes several roots
        del chain[0 if new_root else draw(st.integers(1, len(chain))):]
        parents.append(chain[-1] if chain else -1)
        chain.append(j)
    return parents


channel_sets = st.lists(st.sampled_from(CHANNEL_NAMES), unique=True, max_size=6).flatmap(st.permutations)
coordinates = st.floats(-200, 200, allow_nan=False, width=32)


@st.composite
def generated_clips(draw) -> bytes:
    parents = draw(depth_first_parents())
    joints = len(parents)
    skeleton = Skeleton(
        names=tuple(f"j{j}" for j in range(joints)),
        parents=np.array(parents),
        offsets=np.array(draw(st.lists(st.tuples(coordinates, coordinates, coordinates), min_size=joints, max_size=joints))),
        channels=tuple(draw(st.lists(channel_sets, min_size=joints, max_size=joints))),
        end_sites=tuple((j, np.array([0.0, 1.0, 0.0])) for j in range(joints) if j not in parents),
    )
    rng = draw(st.randoms(use_true_random=True))
    frames = rng.choice([0, 1, 2] + [rng.randint(3, 30)] * 5)
    width = skeleton.num_channels
    if rng.random() < 0.5:  # a moving clip
        flat = rng.uniform(-180, 180) + np.linspace(0, 30, frames)[:, None] * np.sin(np.arange(width) + rng.random())
    else:  # noise
        flat = np.array([rng.uniform(-720, 720) for _ in range(frames * width)]).reshape(frames, width)
    if flat.size and rng.random() < 0.2:
        flat.flat[rng.randrange(flat.size)] = rng.choice([1e6, -1e30, 3e38, 1e-30])
    frame_time = draw(st.sampled_from([1 / 30, 1 / 60, 1 / 24, 1 / 120, 0.5, 1.0]))
    return format_bvh(BVH(skeleton, frame_time, flat.reshape(frames, width))).encode()


@FUZZ
@given(data=generated_clips())
def test_generated_skeletons(data, tmp_path):
    through_the_pipeline(data, tmp_path / "out.bvh")


@pytest.mark.parametrize("index", range(len(BASES)))
def test_unmutated_bases_go_through(index, tmp_path):
    out = tmp_path / "out.bvh"
    through_the_pipeline(BASES[index], out)
    assert read_bvh(out).frames > 0
