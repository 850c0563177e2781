"""BVH -> glTF 2.0 binary (GLB) as a skinned skeleton animation, and back.

Layout of a written file:
- one node per BVH joint (node name = joint name, BVH hierarchy, rest
  translation = OFFSET in metres, rest rotation identity), then one leaf node
  per End Site named "<parent>_end" (extras {"bvh_end_site": true}); a
  skeleton with several ROOTs gets one node "skeleton" above them, and so does
  a Z-up clip (runtime/rig.py detects it, or `up` says so): there that node
  turns it -90 degrees about X (extras {"sinmdm_up_axis": "z"}), so it stands
  in glTF's Y-up world while the joints and the animation stay the file's own;
- a skin listing all of those nodes, with the inverse bind matrices of the rest
  pose, so engines import an armature;
- a skinned mesh of one octahedral "bone" per segment, weighted fully to the
  segment's parent joint, so the skeleton is visible without an armature view
  (none from the static reference joints above the one that carries the
  character, such as a `joint_Root` at the floor: they stay joints, unseen);
- one animation: a rotation channel (x, y, z, w) for every joint and a
  translation channel for every joint with position channels, LINEAR, at the
  times k / fps.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from ..runtime.animation import Animation, animation_from_bvh, nominal_fps, rest_positions
from ..runtime.atomic import write_bytes_atomic
from ..runtime.bvh import BVH, Skeleton
from ..runtime.errors import SinMDMError
from ..runtime.features import unit_scale
from ..runtime.kinematics import forward_kinematics
from ..runtime.rig import AXIS_NAMES, analyse_rig
from ..runtime.rotations import matrix_to_quat, quat_fix_sign, quat_normalize, quat_to_matrix
from . import CLIP_COLOURS, UP_TO_Y, import_extra

END_SITE_MARK = "bvh_end_site"
UP_AXIS_MARK = "sinmdm_up_axis"
FLOAT, UNSIGNED_BYTE, UNSIGNED_SHORT, UNSIGNED_INT = 5126, 5121, 5123, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
BONE_WIDTH = 0.08  # octahedron radius as a fraction of the bone's length
_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
_DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_NORMALIZED_MAX = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}


# --------------------------------------------------------------------------- writing


def write_glb(
    bvh: BVH,
    path: str | os.PathLike,
    units: str | float = "auto",
    fps: float | None = None,
    root: str | None = None,
    up: str | None = None,
) -> Path:
    """Write `bvh` as a GLB file (atomically). `fps` overrides the clip's frame rate;
    `root` and `up` override what runtime/rig.py detects."""
    path = Path(path)
    write_bytes_atomic(path, bvh_to_glb(bvh, units=units, fps=fps, root=root, up=up))
    return path


def bvh_to_glb(
    bvh: BVH,
    units: str | float = "auto",
    fps: float | None = None,
    root: str | None = None,
    up: str | None = None,
) -> bytes:
    """The GLB bytes of a clip: skeleton, skin, bone mesh and animation, in metres, Y up."""
    gltf_module = import_extra("pygltflib")
    if bvh.frames == 0:
        raise SinMDMError(f"{bvh.path or 'the clip'} has no frames to export")
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise SinMDMError(f"frame rate must be a number > 0, got {fps}")
    skeleton = bvh.skeleton
    scale = unit_scale(skeleton, units)
    rate = float(fps) if fps is not None else nominal_fps(bvh.frame_time)
    animation = animation_from_bvh(bvh)
    rig = analyse_rig(Animation(skeleton, animation.rotations, animation.translations, rate), scale, root, up)
    builder = _GLBBuilder(gltf_module)

    names = _node_names(skeleton)
    joint_count = skeleton.num_joints
    end_parents = [p for p, _ in skeleton.end_sites]
    end_offsets = np.array([np.zeros(3) if o is None else o for _, o in skeleton.end_sites]).reshape(-1, 3)
    point_parents = np.concatenate([skeleton.parents, end_parents]).astype(np.int64)
    local_rest = np.concatenate([skeleton.offsets, end_offsets]) * scale
    rest_world = np.concatenate([rest_positions(skeleton), rest_positions(skeleton)[end_parents] + end_offsets]) * scale

    nodes = []
    for k, name in enumerate(names):
        node = gltf_module.Node(name=name, translation=[float(v) for v in local_rest[k]])
        node.children = [int(c) for c in np.flatnonzero(point_parents == k)]
        if k >= joint_count:
            node.extras = {END_SITE_MARK: True}
        nodes.append(node)

    # Rest rotations are identity, so each inverse bind matrix is a translation
    # by minus the rest position (column-major, as glTF stores MAT4).
    inverse_bind = np.tile(np.eye(4), (len(names), 1, 1))
    inverse_bind[:, :3, 3] = -rest_world
    skin = gltf_module.Skin(
        name="skeleton",
        joints=list(range(len(names))),
        inverseBindMatrices=builder.accessor(np.transpose(inverse_bind, (0, 2, 1)), "MAT4"),
    )
    roots = skeleton.roots
    if len(roots) > 1 or rig.up_axis != 1:
        # glTF wants all joints of a skin under one node; BVH allows several ROOTs.
        # A Z-up clip is stood up by this node, the joints keep the file's frame.
        top = gltf_module.Node(name="skeleton", children=list(roots))
        if rig.up_axis != 1:
            top.rotation = [float(v) for v in _up_rotation_xyzw(rig.up_axis)]
            top.extras = {UP_AXIS_MARK: AXIS_NAMES[rig.up_axis]}
        nodes.append(top)
        roots = [len(nodes) - 1]
    skin.skeleton = roots[0]

    mesh_node = len(nodes)
    nodes.append(gltf_module.Node(name="bones", mesh=0, skin=0))
    # The skinned mesh is in the joints' own (file) frame: the skin's joints carry
    # the top node's turn, so the bones stand up with them.
    shown = ~np.isin(np.arange(len(names)), rig.fixed_joints)
    bone_parents = np.where(shown[np.maximum(point_parents, 0)], point_parents, -1)
    mesh = _bone_mesh(gltf_module, builder, rest_world, bone_parents)

    times = np.arange(animation.frames, dtype=np.float64) / rate
    time_accessor = builder.accessor(times.astype(np.float32), "SCALAR", with_bounds=True)
    samplers, channels = [], []

    def add_channel(node: int, path: str, values: np.ndarray, kind: str) -> None:
        output = builder.accessor(values, kind)
        samplers.append(gltf_module.AnimationSampler(input=time_accessor, output=output, interpolation="LINEAR"))
        target = gltf_module.AnimationChannelTarget(node=node, path=path)
        channels.append(gltf_module.AnimationChannel(sampler=len(samplers) - 1, target=target))

    # Consecutive keys on the same hemisphere, so interpolation takes the short way.
    rotations = quat_fix_sign(quat_normalize(matrix_to_quat(animation.rotations)), axis=0)
    for j in range(joint_count):
        add_channel(j, "rotation", rotations[:, j][:, [1, 2, 3, 0]], "VEC4")
        if skeleton.position_channels(j):
            add_channel(j, "translation", animation.translations[:, j] * scale, "VEC3")

    gltf = gltf_module.GLTF2(
        asset=gltf_module.Asset(version="2.0", generator="sinmdm"),
        scene=0,
        scenes=[gltf_module.Scene(name=Path(bvh.path).stem if bvh.path else "motion", nodes=[*roots, mesh_node])],
        nodes=nodes,
        skins=[skin],
        meshes=[mesh],
        materials=[gltf_module.Material(
            name="bone",
            pbrMetallicRoughness=gltf_module.PbrMetallicRoughness(
                baseColorFactor=[*_linear_rgb(CLIP_COLOURS[0]), 1.0], metallicFactor=0.0, roughnessFactor=0.7),
        )],
        animations=[gltf_module.Animation(
            name=Path(bvh.path).stem if bvh.path else "motion",
            samplers=samplers,
            channels=channels,
            extras={"fps": rate, "frames": animation.frames, "metres_per_unit": scale},
        )],
    )
    return builder.finish(gltf)


class _GLBBuilder:
    """Collects arrays into one binary buffer, one buffer view and accessor each."""

    def __init__(self, gltf_module: Any):
        self.gltf = gltf_module
        self.chunks: list[bytes] = []
        self.size = 0
        self.views: list[Any] = []
        self.accessors: list[Any] = []

    def accessor(self, values: np.ndarray, kind: str, target: int | None = None, with_bounds: bool = False) -> int:
        values = np.ascontiguousarray(values)
        if values.dtype == np.float64:
            values = values.astype(np.float32)
        component = {np.dtype(np.float32): FLOAT, np.dtype(np.uint8): UNSIGNED_BYTE,
                     np.dtype(np.uint16): UNSIGNED_SHORT, np.dtype(np.uint32): UNSIGNED_INT}[values.dtype]
        data = values.tobytes()
        self.views.append(self.gltf.BufferView(buffer=0, byteOffset=self.size, byteLength=len(data), target=target))
        self.chunks.append(data + b"\0" * (-len(data) % 4))
        self.size += len(self.chunks[-1])
        width = _COMPONENTS[kind]
        flat = values.reshape(-1, width)
        accessor = self.gltf.Accessor(bufferView=len(self.views) - 1, componentType=component, count=len(flat), type=kind)
        if with_bounds:
            accessor.min = flat.min(axis=0).tolist()
            accessor.max = flat.max(axis=0).tolist()
        self.accessors.append(accessor)
        return len(self.accessors) - 1

    def finish(self, gltf: Any) -> bytes:
        blob = b"".join(self.chunks)
        gltf.accessors = self.accessors
        gltf.bufferViews = self.views
        gltf.buffers = [self.gltf.Buffer(byteLength=len(blob))]
        gltf.set_binary_blob(blob)
        return b"".join(gltf.save_to_bytes())


def _up_rotation_xyzw(up_axis: int) -> np.ndarray:
    """The glTF quaternion (x, y, z, w) that turns world `up_axis` to +Y."""
    w, x, y, z = matrix_to_quat(UP_TO_Y[up_axis])
    return np.array([x, y, z, w])


def _node_names(skeleton: Skeleton) -> list[str]:
    """Joint names, then a unique "<parent>_end" for each End Site."""
    names = list(skeleton.names)
    taken = set(names)
    for parent, _ in skeleton.end_sites:
        base = f"{skeleton.names[parent]}_end"
        name, k = base, 2
        while name in taken:
            name, k = f"{base}{k}", k + 1
        taken.add(name)
        names.append(name)
    return names


def _linear_rgb(colour: str) -> list[float]:
    srgb = np.array([int(colour[k:k + 2], 16) / 255 for k in (1, 3, 5)])
    return np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4).round(4).tolist()


def _bone_mesh(gltf_module: Any, builder: _GLBBuilder, rest_world: np.ndarray, parents: np.ndarray) -> Any:
    """An octahedron from each point's parent to the point, in the rest pose."""
    positions, joints, indices = [], [], []
    pairs = [(int(parents[k]), k) for k in range(len(parents)) if parents[k] >= 0]
    pairs = [(h, t) for h, t in pairs if np.linalg.norm(rest_world[t] - rest_world[h]) > 1e-6]
    if not pairs:  # a skeleton without bones still gets a small marker at its root
        size = 0.05
        heads = [rest_world[0]]
        tails = [rest_world[0] + np.array([0.0, size, 0.0])]
        owners = [0]
    else:
        heads = [rest_world[h] for h, _ in pairs]
        tails = [rest_world[t] for _, t in pairs]
        owners = [h for h, _ in pairs]
    for head, tail, owner in zip(heads, tails, owners):
        axis = tail - head
        length = float(np.linalg.norm(axis))
        d = axis / length
        u = np.cross(d, [0.0, 1.0, 0.0] if abs(d[1]) < 0.9 else [1.0, 0.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(d, u)  # (u, v, d) is right-handed, so the winding below faces outwards
        middle = head + d * length * 0.15
        radius = length * BONE_WIDTH
        ring = [middle + radius * e for e in (u, v, -u, -v)]
        base = len(positions)
        positions += [head, *ring, tail]
        joints += [owner] * 6
        for k in range(4):
            a, b = base + 1 + k, base + 1 + (k + 1) % 4
            indices += [base, b, a, base + 5, a, b]
    positions_array = np.array(positions, dtype=np.float32)
    joint_type = np.uint8 if len(rest_world) <= 256 else np.uint16
    joints_array = np.zeros((len(joints), 4), dtype=joint_type)
    joints_array[:, 0] = joints
    weights_array = np.zeros((len(joints), 4), dtype=np.float32)
    weights_array[:, 0] = 1.0
    index_type = np.uint16 if len(positions) < 65536 else np.uint32
    attributes = gltf_module.Attributes(
        POSITION=builder.accessor(positions_array, "VEC3", ARRAY_BUFFER, with_bounds=True),
        JOINTS_0=builder.accessor(joints_array, "VEC4", ARRAY_BUFFER),
        WEIGHTS_0=builder.accessor(weights_array, "VEC4", ARRAY_BUFFER),
    )
    primitive = gltf_module.Primitive(
        attributes=attributes,
        indices=builder.accessor(np.array(indices, dtype=index_type), "SCALAR", ELEMENT_ARRAY_BUFFER),
        material=0,
    )
    return gltf_module.Mesh(name="bones", primitives=[primitive])


# --------------------------------------------------------------------------- reading


def read_glb(path: str | os.PathLike) -> dict:
    """The skeleton animation of a GLB file with a skin.

    Returns names, parents (-1 for roots; parents precede children), offsets
    (J, 3), end_sites [(parent index, offset)], frames, fps, times (T,),
    rotations (T, J, 4; w, x, y, z, the package's order), translations
    (T, J, 3) and positions (T, J, 3), all in the file's units (metres for
    sinmdm's and Blender's). Joints are the skin's joints except its End Sites:
    the nodes this module marks as such, or, in a file without those marks (a
    DCC tool such as Blender drops glTF extras unless told to keep them), the
    leaf joints named "<parent>_end" or "<parent>_end<k>", as written here.
    The rest pose is the glTF rest pose with every joint's frame aligned with the
    skeleton's (as in a BVH file): rest rotations a tool gave its bones (Blender
    points them at their children) are folded into the offsets and the
    animation, so a skeleton sinmdm wrote comes back with its own offsets and
    rotations. Channels a joint lacks hold its rest transform; scales are
    ignored. Positions follow from those rotations and translations alone (the
    skeleton's own frame: a BVH written from them has these positions);
    world_positions (T, J, 3) are where a glTF viewer shows the joints, with the
    rest transforms of the nodes above them applied (such as the node that
    stands a Z-up clip up, or the armature node a tool adds). up_axis is the
    skeleton's own up axis: as this module marked it, else "z" when the nodes
    above the skeleton turn its +Z to glTF's +Y, else "y"."""
    gltf_module = import_extra("pygltflib")
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(4)
    except OSError as exc:
        raise SinMDMError(f"cannot read {path}: {exc.strerror or exc}") from None
    if head != b"glTF":
        raise SinMDMError(f"{path} is not a GLB file")
    try:
        gltf = gltf_module.GLTF2().load_binary(str(path))
    except Exception as exc:  # pygltflib raises assorted errors for damaged files
        raise SinMDMError(f"{path}: damaged GLB file ({exc})") from None
    if gltf is None or not gltf.skins:
        raise SinMDMError(f"{path} has no skin (no skeleton to read)")
    blob = gltf.binary_blob() or b""

    def accessor(index: int) -> np.ndarray:
        return _read_accessor(gltf, blob, index, path)

    skin_nodes = set(gltf.skins[0].joints)
    parent_of = {child: k for k, node in enumerate(gltf.nodes) for child in node.children or []}
    order = [k for k in _depth_first(gltf, parent_of) if k in skin_nodes]
    end_nodes = _end_site_nodes(gltf, order, parent_of)
    joint_nodes = [k for k in order if k not in end_nodes]
    index_of = {node: j for j, node in enumerate(joint_nodes)}

    def joint_parent(node: int) -> int:
        parent = parent_of.get(node)
        while parent is not None and parent not in index_of:
            parent = parent_of.get(parent)
        return -1 if parent is None else index_of[parent]

    names = [gltf.nodes[k].name or f"joint{j}" for j, k in enumerate(joint_nodes)]
    parents = np.array([joint_parent(k) for k in joint_nodes], dtype=np.int64)
    rest_rotation = np.array([_node_rotation(gltf.nodes[k], path) for k in joint_nodes]).reshape(-1, 4)
    rest_translation = np.array([_node_translation(gltf.nodes[k]) for k in joint_nodes]).reshape(-1, 3)
    ends = sorted(end_nodes, key=order.index)
    end_parents = [joint_parent(k) for k in ends]
    end_offsets = np.array([_node_translation(gltf.nodes[k]) for k in ends]).reshape(-1, 3)

    channels = []
    animation = gltf.animations[0] if gltf.animations else None
    if animation is not None:
        for channel in animation.channels:
            node, target = channel.target.node, channel.target.path
            if node in index_of and target in ("rotation", "translation"):
                sampler = animation.samplers[channel.sampler]
                channels.append((index_of[node], target, accessor(sampler.input).reshape(-1).astype(np.float64),
                                 accessor(sampler.output).astype(np.float64), sampler.interpolation or "LINEAR"))
    times = max((c[2] for c in channels), key=len, default=np.zeros(1))
    frames = len(times)
    fps = _extras(animation).get("fps") if animation is not None else None
    if fps is None:
        fps = nominal_fps(float(np.median(np.diff(times)))) if frames > 1 else 30.0

    rotations = np.broadcast_to(rest_rotation, (frames, len(joint_nodes), 4)).copy()
    translations = np.broadcast_to(rest_translation, (frames, len(joint_nodes), 3)).copy()
    for joint, target, keys, values, interpolation in channels:
        sampled = _sample(times, keys, values, interpolation)
        if target == "rotation":
            rotations[:, joint] = quat_normalize(sampled[:, [3, 0, 1, 2]])
        else:
            translations[:, joint] = sampled
    offsets = rest_translation
    if not np.array_equal(rest_rotation, np.tile([1.0, 0.0, 0.0, 0.0], (len(joint_nodes), 1))):
        rest_world = _rest_world_rotations(quat_to_matrix(quat_normalize(rest_rotation)), parents)
        above = np.concatenate([np.eye(3)[None], rest_world])[parents + 1]  # each joint's parent, or the skeleton
        rotations = quat_fix_sign(matrix_to_quat(above @ quat_to_matrix(rotations) @ np.swapaxes(rest_world, -1, -2)))
        translations = np.einsum("jab,tjb->tja", above, translations)
        offsets = np.einsum("jab,jb->ja", above, rest_translation)
        end_offsets = np.einsum("jab,jb->ja", rest_world[end_parents], end_offsets)
    _, positions = forward_kinematics(quat_to_matrix(rotations), translations, parents)
    world_positions, up_axis = _placed(gltf, joint_nodes, parents, parent_of, positions)
    return {
        "names": names,
        "parents": parents,
        "offsets": offsets,
        "end_sites": list(zip(end_parents, end_offsets)),
        "frames": frames,
        "fps": float(fps),
        "times": times,
        "rotations": rotations,
        "translations": translations,
        "positions": positions,
        "world_positions": world_positions,
        "up_axis": up_axis,
    }


def _end_site_nodes(gltf: Any, order: list[int], parent_of: dict[int, int]) -> set[int]:
    """The skin's End Site nodes: those marked so, or in a file without marks, the
    leaf joints named after their parent joint as `_node_names` names them."""
    marked = {k for k in order if _extras(gltf.nodes[k]).get(END_SITE_MARK)}
    if marked:
        return marked
    joints = set(order)
    ends = set()
    for k in order:
        node, parent = gltf.nodes[k], parent_of.get(k)
        if parent not in joints or any(c in joints for c in node.children or []):
            continue
        if node.name and re.fullmatch(re.escape(gltf.nodes[parent].name or "") + r"_end(\d+)?", node.name):
            ends.add(k)
    return ends


def _extras(item: Any) -> dict:
    """A glTF object's extras when they are a JSON object (glTF allows any value there)."""
    return item.extras if isinstance(item.extras, dict) else {}


def _rest_world_rotations(rest: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """(J, 3, 3) each joint's rest rotation in the skeleton's frame."""
    world = rest.copy()
    for j, p in enumerate(parents):
        if p >= 0:
            world[j] = world[p] @ rest[j]
    return world


def _placed(gltf: Any, joint_nodes: list[int], parents: np.ndarray, parent_of: dict[int, int],
            positions: np.ndarray) -> tuple[np.ndarray, str]:
    """The joints' positions in the glTF world (the rest transforms of the nodes
    above each root applied) and the skeleton's own up axis."""
    world_positions = positions.copy()
    marked, turned = None, False
    for j, node in enumerate(joint_nodes):
        if parents[j] >= 0:
            continue
        subtree = np.flatnonzero(_root_of(parents) == j)
        above = np.eye(4)
        ancestor = parent_of.get(node)
        while ancestor is not None:
            above = _node_matrix(gltf.nodes[ancestor]) @ above
            marked = _extras(gltf.nodes[ancestor]).get(UP_AXIS_MARK, marked)
            ancestor = parent_of.get(ancestor)
        world_positions[:, subtree] = positions[:, subtree] @ above[:3, :3].T + above[:3, 3]
        up = above[:3, 2] / max(float(np.linalg.norm(above[:3, 2])), 1e-12)
        turned = turned or up[1] > 1 - 1e-4  # a Z-up skeleton stood up, whether or not its mark survived
    return world_positions, marked or ("z" if turned else "y")


def _root_of(parents: np.ndarray) -> np.ndarray:
    """(J,) the root joint above each joint (parents precede children)."""
    roots = np.arange(len(parents))
    for j, p in enumerate(parents):
        if p >= 0:
            roots[j] = roots[p]
    return roots


def _node_matrix(node: Any) -> np.ndarray:
    """A node's rest transform as a 4x4 matrix (column vectors)."""
    if node.matrix is not None:
        return np.array(node.matrix, dtype=np.float64).reshape(4, 4).T  # glTF stores column-major
    w, x, y, z = _node_rotation(node, Path())
    matrix = np.eye(4)
    matrix[:3, :3] = quat_to_matrix(quat_normalize(np.array([w, x, y, z], dtype=np.float64))) * np.array(
        node.scale or [1.0, 1.0, 1.0], dtype=np.float64)
    matrix[:3, 3] = _node_translation(node)
    return matrix


def _depth_first(gltf: Any, parent_of: dict[int, int]) -> list[int]:
    """Node indices with every parent before its children."""
    scene_roots = [k for k in range(len(gltf.nodes)) if k not in parent_of]
    order, stack = [], list(reversed(scene_roots))
    while stack:
        node = stack.pop()
        order.append(node)
        stack.extend(reversed(gltf.nodes[node].children or []))
    return order


def _node_rotation(node: Any, path: Path) -> list[float]:
    if node.matrix is not None:
        raise SinMDMError(f"{path}: joint {node.name!r} uses a matrix transform; only TRS nodes are supported")
    x, y, z, w = node.rotation or [0.0, 0.0, 0.0, 1.0]
    return [w, x, y, z]


def _node_translation(node: Any) -> np.ndarray:
    return np.array(node.translation or [0.0, 0.0, 0.0], dtype=np.float64)


def _read_accessor(gltf: Any, blob: bytes, index: int, path: Path) -> np.ndarray:
    accessor = gltf.accessors[index]
    if accessor.sparse is not None or accessor.bufferView is None:
        raise SinMDMError(f"{path}: sparse or empty accessors are not supported")
    view = gltf.bufferViews[accessor.bufferView]
    if view.buffer != 0 or gltf.buffers[0].uri is not None:
        raise SinMDMError(f"{path}: external buffers are not supported")
    dtype = np.dtype(_DTYPES[accessor.componentType])
    width = _COMPONENTS[accessor.type]
    element = dtype.itemsize * width
    stride = view.byteStride or element
    start = (view.byteOffset or 0) + (accessor.byteOffset or 0)
    end = start + stride * (accessor.count - 1) + element
    if accessor.count and end > (view.byteOffset or 0) + view.byteLength or end > len(blob):
        raise SinMDMError(f"{path}: accessor {index} reaches past its buffer")
    rows = np.ndarray((accessor.count, width), dtype=dtype.newbyteorder("<"), buffer=blob, offset=start,
                      strides=(stride, dtype.itemsize))
    values = rows.astype(np.float64)
    if accessor.normalized and accessor.componentType in _NORMALIZED_MAX:
        values = np.maximum(values / _NORMALIZED_MAX[accessor.componentType], -1.0)
    return values


def _sample(times: np.ndarray, keys: np.ndarray, values: np.ndarray, interpolation: str) -> np.ndarray:
    """A channel's values at `times` (rotations come back unnormalised)."""
    if interpolation == "CUBICSPLINE":
        values = values.reshape(len(keys), 3, -1)[:, 1]  # (in-tangent, value, out-tangent): keep the values
    if len(keys) == len(times) and np.array_equal(keys, times):
        return values
    if interpolation == "STEP":
        return values[np.clip(np.searchsorted(keys, times, side="right") - 1, 0, len(keys) - 1)]
    return np.stack([np.interp(times, keys, values[:, k]) for k in range(values.shape[1])], axis=1)
