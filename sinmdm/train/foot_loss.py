"""Foot-contact loss (an option, `TrainConfig.foot_loss`; the paper has no geometric loss):
where the clip's contact label is set, the contact joint's velocity in the predicted x0,
by forward kinematics of its rotations and root path, is driven to zero (MDM's foot-contact
loss, Tevet et al. 2023). Why: a sampled crab moves its poses like the clip (86-93 %
coverage on the rotation columns) while its labelled feet slide 15 cm/s, because the 6D
rotations of a five-joint leg and the root's velocity are learned apart and nothing in
the paper's loss ties them (BENCHMARKS.md).

The "clip" form (`TrainConfig.foot_loss_target`) instead matches every contact joint's velocity
to the clip's on every frame, each example weighted by its share of clean signal abar(t): it
cannot be met by standing still (the "still" form froze the walk), and the noisiest predictions,
which cannot know where a foot is, barely count (BENCHMARKS.md, "Feet the model does not stop").

Velocities are taken in the trajectory joint's parent frame (a constant rotation away
from the world's, so their lengths are the world's; in the heading frame, in the next frame's
heading) and counted in units of the codec's contact speed per frame. Even so one weight does
not fit every clip: measured, 0.001 taught Xia normal to step and slowed the idle and the crab
far more than 0.0003 did (BENCHMARKS.md).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from ..runtime.errors import SinMDMError
from ..runtime.features import MotionCodec
from ..runtime.rig import ancestors

FOOT_LOSS_TARGETS = ("still", "clip")


def sixd_to_matrix(d6: Tensor) -> Tensor:
    """(..., 6) -> (..., 3, 3), rows by Gram-Schmidt: runtime.rotations.sixd_to_matrix in torch."""
    a, b = d6[..., :3], d6[..., 3:]
    row0 = a / a.norm(dim=-1, keepdim=True).clamp_min(1e-8)
    b = b - (row0 * b).sum(dim=-1, keepdim=True) * row0
    row1 = b / b.norm(dim=-1, keepdim=True).clamp_min(1e-8)
    return torch.stack([row0, row1, torch.cross(row0, row1, dim=-1)], dim=-2)


def turn_about(points: Tensor, angle: Tensor, axis: int) -> Tensor:
    """(B, T, C, 3) points turned by `angle` (B, T) about coordinate axis `axis`, as
    runtime.rotations.axis_matrix turns."""
    c, s = torch.cos(angle)[..., None], torch.sin(angle)[..., None]
    u, v = (axis + 1) % 3, (axis + 2) % 3
    out = points.clone()
    out[..., u] = c * points[..., u] - s * points[..., v]
    out[..., v] = s * points[..., u] + c * points[..., v]
    return out


class FootContactLoss:
    """Callable (prediction, x0[, signal]) -> scalar on (B, F, T) batches in the model's space."""

    def __init__(self, codec: MotionCodec, scale: np.ndarray | None = None, heading: bool = False) -> None:
        if codec.trajectory_joint is None or not codec.contact_joints:
            raise SinMDMError("--foot-loss needs a clip with a trajectory joint and contact joints")
        skeleton, root = codec.skeleton, codec.trajectory_joint
        # The joints between the trajectory joint and each contact joint, parents first.
        joints = sorted({j for c in codec.contact_joints for j in (c, *ancestors(skeleton, c))
                         if j == root or root in ancestors(skeleton, j)})
        self.joints = joints
        self.parents = [joints.index(skeleton.parents[j]) if j != root else -1 for j in joints]
        self.contacts = [joints.index(c) for c in codec.contact_joints]
        rotation_joints = codec.rotation_joints
        rot = codec.layout.indices(("rotation",)).reshape(-1, 6)
        self.rotation_channels = {i: rot[rotation_joints.index(j)] for i, j in enumerate(joints) if j in rotation_joints}
        rest = np.eye(3) if codec.rest_rotations is None else np.asarray(codec.rest_rotations)
        self.rest_rotations = torch.as_tensor(np.broadcast_to(rest, (skeleton.num_joints, 3, 3))[joints], dtype=torch.float32)
        self.offsets = torch.as_tensor(np.asarray(codec.rest_translations)[joints] * codec.scale, dtype=torch.float32)
        translation = codec.layout.indices(("translation",)).reshape(-1, 3) if codec.translation_joints else None
        self.translation_channels = {i: translation[codec.translation_joints.index(j)]
                                     for i, j in enumerate(joints) if j in codec.translation_joints and j != root}
        self.contact_channels = codec.layout.indices(("contact",))
        dx, y, dz = codec.layout.indices(("root",))
        self.root_channels = (dx, y, dz)
        h1, h2 = codec.horizontal_axes
        self.axes = (h1, codec.height_axis, h2)
        unscale = np.ones(codec.width) if scale is None else 1.0 / np.asarray(scale, dtype=np.float64)
        self.unscale = torch.as_tensor(unscale, dtype=torch.float32)
        self.speed_unit = codec.contact_speed / codec.fps  # metres per frame
        # In the heading frame (runtime.heading) the root's rotation and velocity are seen from the
        # heading and one last channel holds its turn rate (rad/s): a frame's positions are turned
        # into the next frame's heading before differencing, so the speeds are the world's.
        self.turn_fps = float(codec.fps) if heading else None
        self.up = codec.height_axis

    def velocities(self, x: Tensor) -> Tensor:
        """(B, T-1, C, 3) contact joints' velocity per frame, metres, in the root's parent frame."""
        rate = x[:, -1].float() if self.turn_fps is not None else None  # (B, T) rad/s
        x = x[:, : len(self.unscale)]
        x = (x.float() * self.unscale.to(x.device)[:, None]).transpose(1, 2)  # (B, T, F) metres per frame
        batch, frames = x.shape[:2]
        globals_, positions = [], []
        for i, parent in enumerate(self.parents):
            if i in self.rotation_channels:
                local = sixd_to_matrix(x[..., self.rotation_channels[i]])
            else:
                local = self.rest_rotations[i].to(x.device).expand(batch, frames, 3, 3)
            if parent < 0:  # the trajectory joint, at the origin: its path is added below
                globals_.append(local)
                positions.append(x.new_zeros(batch, frames, 3))
                continue
            offset = x[..., self.translation_channels[i]] if i in self.translation_channels else self.offsets[i].to(x.device)
            positions.append(positions[parent] + (globals_[parent] @ offset.expand(batch, frames, 3)[..., None])[..., 0])
            globals_.append(globals_[parent] @ local)
        feet = torch.stack([positions[c] for c in self.contacts], dim=2)  # (B, T, C, 3)
        dx, y, dz = (x[..., k] for k in self.root_channels)
        step = x.new_zeros(batch, frames - 1, 3)
        h1, up, h2 = self.axes
        step[..., h1], step[..., up], step[..., h2] = dx[:, 1:], y[:, 1:] - y[:, :-1], dz[:, 1:]
        before = feet[:, :-1]
        if rate is not None:
            before = turn_about(before, -rate[:, 1:] / self.turn_fps, self.up)
        return feet[:, 1:] - before + step[:, :, None]

    def __call__(self, prediction: Tensor, x0: Tensor, signal: Tensor | None = None) -> Tensor:
        """`signal` (B,): each example's share of clean signal, abar(t). With it, the loss is the
        contact joints' velocity against the clip's on every frame, weighted by `signal`
        (`TrainConfig.foot_loss_target` "clip"); without it, the planted joints' speed (MDM's, "still")."""
        # float32 even under bf16 autocast: a foot's millimetres per frame over a metre-long chain
        with torch.autocast(device_type=prediction.device.type, enabled=False):
            predicted = self.velocities(prediction)
            if signal is not None:
                with torch.no_grad():
                    target = self.velocities(x0)
                error = ((predicted - target) / self.speed_unit).pow(2).sum(dim=-1).mean(dim=(1, 2))  # (B,)
                return (signal.float() * error).mean()
            speed = predicted.norm(dim=-1) / self.speed_unit
        planted = x0[:, self.contact_channels].float().transpose(1, 2) > 0.5  # (B, T, C), the clip's labels
        planted = (planted[:, 1:] & planted[:, :-1]).float()
        return (planted * speed**2).sum() / planted.sum().clamp_min(1.0)
