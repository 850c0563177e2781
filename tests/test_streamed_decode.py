"""Long motions in bounded memory: decoding to BVH a chunk of frames at a time, the contact
cleanup solved on the legs' sub-skeleton only, the DDPM update in place. Each must give
the bytes of the whole-array path it replaces."""

from __future__ import annotations

import numpy as np
import pytest

from sinmdm.runtime.animation import animation_to_bvh, chunks_to_bvh
from sinmdm.runtime.bvh import read_bvh
from sinmdm.runtime.cleanup import cleaned_legs, cleanup_contacts
from sinmdm.runtime.features import build_codec
from sinmdm.runtime.rotations import unwrap_euler
from sinmdm.runtime.schedule import Schedule, cosine_alphas_cumprod

from .conftest import real_clip

LENGTH = 5000  # more than two of the decoder's 2,048-frame chunks


def long_features(name: str, seed: int = 0):
    """A real clip's features tiled past LENGTH frames, its root velocity and rotations
    disturbed so that the planted feet slide (work for the cleanup) and Euler curves wrap."""
    bvh = read_bvh(real_clip(name))
    codec = build_codec(bvh)
    features = np.tile(codec.encode(bvh), (LENGTH // 100, 1))[:LENGTH].copy()
    rng = np.random.default_rng(seed)
    rotations = codec.layout.indices(("rotation",))
    features[:, rotations] += 0.05 * rng.standard_normal((LENGTH, len(rotations))).astype(np.float32)
    dx, _, dz = codec.layout.indices(("root",))
    features[:, [dx, dz]] += 0.01 * rng.standard_normal((LENGTH, 2)).astype(np.float32)
    return codec, features


@pytest.mark.parametrize("name", ["Joe_Walk-In-Circle.bvh", "Crabnew_Crab-dance-long.bvh"])
def test_streamed_decode_and_cleanup_give_the_whole_array_bytes(name):
    codec, features = long_features(name)
    start = np.array([0.3, -1.2])
    whole = codec.decode(features, start)
    np.testing.assert_array_equal(codec.decode_bvh(features, start).values, animation_to_bvh(whole).values)
    cleaned = cleanup_contacts(whole, codec, features, in_place=True)
    legs = cleaned_legs(codec, features, start)
    assert legs.skeleton.num_joints < codec.skeleton.num_joints
    np.testing.assert_array_equal(codec.decode_bvh(features, start, replaced=legs).values,
                                  animation_to_bvh(cleaned).values)


def test_the_legs_sub_skeleton_keeps_the_contacts_and_their_ancestors_only():
    codec, features = long_features("Joe_Walk-In-Circle.bvh")
    legs, channels = codec.restricted([0, 1, 2])
    assert legs.skeleton.names == codec.skeleton.names[:3]
    assert len(channels) == legs.width and legs.layout.blocks[0].joint == codec.skeleton.names[0]
    np.testing.assert_array_equal(legs.decode(features[:50, channels]).rotations,
                                  codec.decode(features[:50]).rotations[:, :3])
    sub = cleaned_legs(codec, features[:300])
    names = set(sub.skeleton.names)
    assert {codec.skeleton.names[j] for j in codec.contact_joints} <= names
    assert not any("Hand" in n or "Head" in n for n in names)


def test_chunks_to_bvh_unwraps_across_chunks():
    codec, features = long_features("Joe_Walk-In-Circle.bvh", seed=3)
    animation = codec.decode(features[:700])
    whole = animation_to_bvh(animation).values
    for chunk in (1, 64, 333):
        streamed = chunks_to_bvh(animation.skeleton, animation.fps, animation.frames,
                                 lambda a, b: (animation.rotations[a:b], animation.translations[a:b]), chunk=chunk)
        np.testing.assert_array_equal(streamed.values, whole)


def test_unwrap_euler_continues_from_the_previous_frame():
    rng = np.random.default_rng(1)
    angles = np.cumsum(rng.normal(0, 0.7, (400, 5, 3)), axis=0)
    angles = (angles + np.pi) % (2 * np.pi) - np.pi  # wrapped, to be unwrapped again
    whole = unwrap_euler(angles, "ZXY")
    first = unwrap_euler(angles[:150], "ZXY")
    second = unwrap_euler(angles[150:], "ZXY", previous=first[-1])
    np.testing.assert_array_equal(np.concatenate([first, second]), whole)


def test_the_ddpm_update_in_place_gives_the_same_values():
    schedule = Schedule.from_alphas_cumprod(cosine_alphas_cumprod(), 20)
    rng = np.random.default_rng(2)
    x, x0, noise = (rng.standard_normal((2, 7, 9000)).astype(np.float32) for _ in range(3))
    for step in (0, 5, 19):
        expected = schedule.ddpm_step(step, x, x0, noise)
        state = x.copy()
        assert schedule.ddpm_step(step, state, x0, noise, out=state) is state
        np.testing.assert_array_equal(state, expected)
        mean = float(schedule.posterior()[0][step]) * x0
        mean += float(schedule.posterior()[1][step]) * x
        if step:
            mean += np.exp(0.5 * schedule.posterior()[2][step]) * noise
        np.testing.assert_allclose(expected, mean, rtol=1e-6, atol=1e-6)


def test_free_heap_is_returned_after_a_long_motion_only(monkeypatch):
    from sinmdm.runtime import heap

    calls = []
    monkeypatch.setattr(heap, "_malloc_trim", lambda: calls.append)
    heap.release_free_heap(heap.LONG_MOTION_VALUES - 1)
    assert calls == []
    heap.release_free_heap(heap.LONG_MOTION_VALUES)
    assert calls == [0]


def test_free_heap_release_runs_on_this_platform():
    from sinmdm.runtime.heap import LONG_MOTION_VALUES, release_free_heap

    release_free_heap(LONG_MOTION_VALUES)  # glibc: malloc_trim; elsewhere nothing, never an error
