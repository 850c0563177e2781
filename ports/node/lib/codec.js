'use strict';
// Feature decoding (docs/runtime.md, "Decoding"): (frames, F) features -> local rotations,
// local translations (file units) and world joint positions by forward kinematics. float64.

const AXIS_NAMES = 'xyz';

function rotationOrder(channels) {
  return channels.filter((c) => c.endsWith('rotation')).map((c) => c[0]).join('');
}

// The layout blocks: stored in the metadata's codec, else derived by the same rule.
function featureLayout(codec) {
  const sk = codec.skeleton;
  const index = new Map(sk.names.map((n, i) => [n, i]));
  const fixed = new Set((codec.fixed_joints || []).map((n) => index.get(n)));
  const blocks = [];
  let start = 0;
  const add = (kind, joint, components) => {
    blocks.push({ kind, joint, start, stop: start + components.length, components });
    start += components.length;
  };
  sk.names.forEach((name, j) => {
    if (rotationOrder(sk.channels[j]) && !fixed.has(j)) add('rotation', name, ['r00', 'r01', 'r02', 'r10', 'r11', 'r12']);
  });
  for (const name of codec.translation_joints) add('translation', name, ['x', 'y', 'z']);
  for (const name of codec.contact_joints) add('contact', name, ['contact']);
  if (codec.trajectory_joint != null) {
    const height = codec.height_axis ?? 1;
    const [h1, h2] = [0, 1, 2].filter((a) => a !== height);
    add('root', codec.trajectory_joint, [`d${AXIS_NAMES[h1]}`, AXIS_NAMES[height], `d${AXIS_NAMES[h2]}`]);
  }
  if (codec.layout && JSON.stringify(codec.layout) !== JSON.stringify(blocks)) {
    throw new Error("the metadata's feature layout differs from the one its skeleton derives");
  }
  return codec.layout || blocks;
}

// (w, x, y, z) -> row-major 3x3, normalised first.
function quatToMatrix(q) {
  const n = Math.max(Math.hypot(q[0], q[1], q[2], q[3]), 1e-12);
  const [w, x, y, z] = q.map((v) => v / n);
  return [
    1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
    2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
    2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
  ];
}

// 6D (the first two rows) -> row-major 3x3 by Gram-Schmidt; third row = row0 x row1.
function sixdToMatrix(d, out, at) {
  const na = Math.max(Math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), 1e-12);
  const r0 = [d[0] / na, d[1] / na, d[2] / na];
  const dot = r0[0] * d[3] + r0[1] * d[4] + r0[2] * d[5];
  const b = [d[3] - dot * r0[0], d[4] - dot * r0[1], d[5] - dot * r0[2]];
  const nb = Math.max(Math.sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]), 1e-12);
  const r1 = [b[0] / nb, b[1] / nb, b[2] / nb];
  const r2 = [r0[1] * r1[2] - r0[2] * r1[1], r0[2] * r1[0] - r0[0] * r1[2], r0[0] * r1[1] - r0[1] * r1[0]];
  out.set([...r0, ...r1, ...r2], at);
}

// features: Float32Array (frames * F, row-major); start: [h1, h2] metres.
function decode(codec, features, frames, start) {
  const sk = codec.skeleton;
  const J = sk.names.length;
  const index = new Map(sk.names.map((n, i) => [n, i]));
  const layout = featureLayout(codec);
  const F = layout[layout.length - 1].stop;
  const rotations = new Float64Array(frames * J * 9);
  const translations = new Float64Array(frames * J * 3);
  const rest = codec.rest_rotations ? codec.rest_rotations.map(quatToMatrix) : null;
  const identity = [1, 0, 0, 0, 1, 0, 0, 0, 1];
  for (let t = 0; t < frames; t++) {
    for (let j = 0; j < J; j++) {
      rotations.set(rest ? rest[j] : identity, (t * J + j) * 9);
      translations.set(codec.rest_translations[j], (t * J + j) * 3);
    }
  }
  const root = { x: 0.0, z: 0.0 };
  const origin = start || [0.0, 0.0];
  for (let t = 0; t < frames; t++) {
    const row = features.subarray(t * F, (t + 1) * F);
    for (const block of layout) {
      const j = index.get(block.joint);
      const v = Array.from(row.subarray(block.start, block.stop));
      if (block.kind === 'rotation') sixdToMatrix(v, rotations, (t * J + j) * 9);
      else if (block.kind === 'translation') translations.set(v.map((m) => m / codec.scale), (t * J + j) * 3);
      else if (block.kind === 'root') {
        // velocities integrate from frame 1 on: frame 0's velocity is not applied
        if (t > 0) { root.x += v[0]; root.z += v[2]; }
        const height = codec.height_axis ?? 1;
        const [h1, h2] = [0, 1, 2].filter((a) => a !== height);
        const path = [0, 0, 0];
        path[h1] = origin[0] + root.x;
        path[height] = v[1];
        path[h2] = origin[1] + root.z;
        translations.set(path.map((m) => m / codec.scale), (t * J + j) * 3);
      }
    }
  }
  return { rotations, translations, positions: forwardKinematics(sk.parents, rotations, translations, frames) };
}

// Roots: global = local; a child: G_j = G_p L_j, P_j = P_p + G_p t_j (row-major 3x3).
function forwardKinematics(parents, rotations, translations, frames) {
  const J = parents.length;
  const G = new Float64Array(J * 9);
  const positions = new Float64Array(frames * J * 3);
  for (let t = 0; t < frames; t++) {
    for (let j = 0; j < J; j++) {
      const L = rotations.subarray((t * J + j) * 9, (t * J + j + 1) * 9);
      const tr = translations.subarray((t * J + j) * 3, (t * J + j + 1) * 3);
      const P = positions.subarray((t * J + j) * 3, (t * J + j + 1) * 3);
      const p = parents[j];
      if (p < 0) {
        G.set(L, j * 9);
        P.set(tr);
        continue;
      }
      const Gp = G.subarray(p * 9, p * 9 + 9);
      const Pp = positions.subarray((t * J + p) * 3, (t * J + p + 1) * 3);
      for (let r = 0; r < 3; r++) {
        for (let c = 0; c < 3; c++) {
          G[j * 9 + r * 3 + c] = Gp[r * 3] * L[c] + Gp[r * 3 + 1] * L[3 + c] + Gp[r * 3 + 2] * L[6 + c];
        }
        P[r] = Pp[r] + Gp[r * 3] * tr[0] + Gp[r * 3 + 1] * tr[1] + Gp[r * 3 + 2] * tr[2];
      }
    }
  }
  return positions;
}

module.exports = { decode, featureLayout, forwardKinematics, sixdToMatrix, quatToMatrix };
