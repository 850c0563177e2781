"""The foot-contact loss (train/foot_loss.py): forward kinematics in torch that agrees with
the runtime's, on real clips of every layout, and a loss that sees sliding feet."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from sinmdm.runtime.animation import global_positions  # noqa: E402
from sinmdm.runtime.bvh import read_bvh  # noqa: E402
from sinmdm.runtime.errors import SinMDMError  # noqa: E402
from sinmdm.runtime.features import build_codec, model_scale  # noqa: E402
from sinmdm.runtime.graph_space import GraphSpace  # noqa: E402
from sinmdm.runtime.heading import clip_heading_frame  # noqa: E402
from sinmdm.train.foot_loss import FootContactLoss  # noqa: E402

from .conftest import real_clip  # noqa: E402
from .layouts import LAYOUTS  # noqa: E402


def _batch(features: np.ndarray, scale: np.ndarray | None = None) -> "torch.Tensor":
    values = features.T if scale is None else features.T * scale[:, None]
    return torch.from_numpy(np.ascontiguousarray(values[None], dtype=np.float32))


@pytest.mark.parametrize("name,layout,unit", [
    ("Crabnew_Crab-dance-long.bvh", None, "frame"),
    ("Joe_Walk-In-Circle.bvh", "static-root-z-up", "frame"),
    ("Joe_Walk-In-Circle.bvh", None, "second"),
])
def test_contact_velocities_are_the_runtimes(name, layout, unit):
    bvh = read_bvh(real_clip(name))
    bvh = LAYOUTS[layout](bvh) if layout else bvh
    codec = build_codec(bvh)
    features = codec.encode(bvh)
    scale = model_scale(codec, unit)
    velocity = FootContactLoss(codec, scale).velocities(_batch(features, scale))[0].numpy()
    feet = global_positions(codec.decode(features))[:, list(codec.contact_joints)] * codec.scale
    np.testing.assert_allclose(np.linalg.norm(velocity, axis=-1),
                               np.linalg.norm(np.diff(feet, axis=0), axis=-1), atol=1e-5)


def test_contact_velocities_in_the_heading_frame_are_the_worlds():
    """A clip that walks a circle, seen from its heading (the frame the walk trains in): the
    loss's speeds are the world's, though each frame's rotation and velocity are turned."""
    bvh = read_bvh(real_clip("Joe_Walk-In-Circle.bvh"))
    codec = build_codec(bvh)
    features = codec.encode(bvh)
    space = GraphSpace(codec.width, model_scale(codec, "frame"), clip_heading_frame(codec, features))
    graph = space.to_graph(features)
    velocity = FootContactLoss(codec, space.scale, heading=True).velocities(
        torch.from_numpy(np.ascontiguousarray(graph.T[None], dtype=np.float32)))[0].numpy()
    feet = global_positions(codec.decode(features))[:, list(codec.contact_joints)] * codec.scale
    np.testing.assert_allclose(np.linalg.norm(velocity, axis=-1),
                               np.linalg.norm(np.diff(feet, axis=0), axis=-1), atol=1e-5)
    # seen as world features instead, the turn is missed and the speeds are off
    unturned = FootContactLoss(codec, space.scale).velocities(
        torch.from_numpy(np.ascontiguousarray(graph.T[None], dtype=np.float32)))[0].numpy()
    assert np.abs(np.linalg.norm(unturned, axis=-1) - np.linalg.norm(np.diff(feet, axis=0), axis=-1)).max() > 1e-3


def test_the_loss_sees_sliding_feet():
    """The clip against its own labels costs little (its planted feet are slower than the
    contact speed); the same poses on a root that glides 15 cm/s cost far more."""
    bvh = read_bvh(real_clip("Crabnew_Crab-dance-long.bvh"))
    codec = build_codec(bvh)
    features = codec.encode(bvh)
    loss = FootContactLoss(codec)
    clip = float(loss(_batch(features), _batch(features)))
    gliding = features.copy()
    gliding[:, codec.layout.indices(("root",))[0]] += 0.15 / codec.fps
    assert clip < 0.05
    assert float(loss(_batch(gliding), _batch(features))) > 5 * clip + 0.1


def test_a_clip_without_contacts_is_refused():
    bvh = read_bvh(real_clip("Joe_Walk-In-Circle.bvh"))
    with pytest.raises(SinMDMError, match="contact"):
        FootContactLoss(build_codec(bvh, contacts=[]))


def test_the_matched_form_costs_only_what_differs_from_the_clip_and_fades_with_noise():
    """Against the clip's own contact velocities (`signal` given): the clip costs nothing, a root
    that glides costs on every frame, and an example counts by its share of clean signal."""
    bvh = read_bvh(real_clip("Joe_Baseball-Milling-Idle.bvh"))
    codec = build_codec(bvh)
    features = codec.encode(bvh)[:120]
    loss = FootContactLoss(codec)
    clip = _batch(features)
    gliding = features.copy()
    gliding[:, codec.layout.indices(("root",))[0]] += 0.15 / codec.fps
    glide = _batch(gliding)
    assert float(loss(clip, clip, torch.ones(1))) < 1e-8
    full = float(loss(glide, clip, torch.ones(1)))
    expected = (0.15 / codec.fps / loss.speed_unit) ** 2  # the same extra velocity on every contact joint and frame
    assert full == pytest.approx(expected, rel=1e-3)
    assert float(loss(glide, clip, torch.full((1,), 0.25))) == pytest.approx(0.25 * full, rel=1e-5)
    assert float(loss(glide, clip, torch.zeros(1))) == 0.0
