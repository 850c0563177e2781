'use strict';
// The sampling loop (docs/runtime.md, "The loop"), one sample, its noise supplied by the
// caller: a port cannot reproduce numpy's PCG64 normals, so a replay reads them from the
// vectors and an application draws its own.

const { featureLayout, sixdToMatrix } = require('./codec');
const { Schedule } = require('./schedule');
const { WindowedDenoiser, defaultHop } = require('./windows');

const DEFAULT_STEPS = 50;
const EDGE_MARGIN = 8;

function defaultSteps(metadata) {
  const value = (metadata.sampling_defaults || {}).steps;
  return Number.isInteger(value) && value >= 1 && value <= metadata.alphas_cumprod.length ? value : DEFAULT_STEPS;
}

// Per-feature factors from features to the graph's space: the root's horizontal velocity
// counts in metres per second when metadata.velocity_unit is "second" (float32, as numpy's).
function modelScale(metadata, layout, F) {
  const scale = new Float32Array(F).fill(1);
  const root = layout.find((b) => b.kind === 'root');
  if (metadata.velocity_unit === 'second' && root) {
    scale[root.start] = scale[root.start + 2] = metadata.codec.fps;
  }
  return scale;
}

// A heading-frame model (docs/runtime.md, heading_frame): the trajectory joint's rotation and
// velocity turned back by the heading, integrated in float64 from metadata.heading_frame.start over
// the turn rates (rad/s, the last channel) of frames 1..; a loop's turn first rounded to whole turns.
function fromHeadingFrame(metadata, layout, x, T, margin, frames, loop, scale, round, features) {
  const F = features.length / frames;
  const fps = metadata.codec.fps;
  const joint = metadata.codec.trajectory_joint;
  const rotation = layout.find((b) => b.kind === 'rotation' && b.joint === joint).start;
  const root = layout.find((b) => b.kind === 'root').start;
  const up = metadata.codec.height_axis ?? 1;
  const [h1, h2] = [0, 1, 2].filter((a) => a !== up);
  const u = (up + 1) % 3;
  const v = (up + 2) % 3;
  const rate = new Float64Array(frames);
  for (let i = 0; i < frames; i++) rate[i] = x[F * T + margin + i];
  if (loop) {
    let total = 0;
    for (let i = 0; i < frames; i++) total += rate[i];
    total /= fps;
    const missing = 2 * Math.PI * Math.round(total / (2 * Math.PI)) - total;
    for (let i = 0; i < frames; i++) rate[i] = round(rate[i] + (missing * fps) / frames);
  }
  let turned = 0; // the cumulative sum of rate / fps over frames 1..i, as numpy's cumsum
  const m = new Float64Array(9);
  for (let i = 0; i < frames; i++) {
    if (i > 0) turned += rate[i] / fps;
    const heading = metadata.heading_frame.start + turned;
    const value = (f) => x[f * T + margin + i] / scale[f];
    for (let f = 0; f < F; f++) features[i * F + f] = value(f);
    sixdToMatrix([0, 1, 2, 3, 4, 5].map((k) => x[(rotation + k) * T + margin + i]), m, 0);
    const c = Math.cos(heading);
    const s = Math.sin(heading);
    // axis_matrix(up, heading) @ m: rows u and v mix, row up stays
    const r = Array.from(m);
    for (let col = 0; col < 3; col++) {
      r[u * 3 + col] = c * m[u * 3 + col] - s * m[v * 3 + col];
      r[v * 3 + col] = s * m[u * 3 + col] + c * m[v * 3 + col];
    }
    for (let k = 0; k < 6; k++) features[i * F + rotation + k] = r[k];
    const velocity = [0, 0, 0];
    velocity[h1] = value(root);
    velocity[h2] = value(root + 2);
    const world = [0, 0, 0];
    world[up] = velocity[up];
    world[u] = c * velocity[u] - s * velocity[v];
    world[v] = s * velocity[u] + c * velocity[v];
    features[i * F + root] = world[h1];
    features[i * F + root + 2] = world[h2];
  }
}

// options: { frames, steps?, hop?, margin?, loop?, sampler?, eta?, stateDtype? };
// noise.initial(size) -> x_T values, noise.step(k, size) -> the normals of loop iteration k;
// onStep(k, t, x_t, x0_hat) is called at every iteration (for checks).
async function sampleFeatures(ort, session, metadata, options, noise, onStep) {
  const layout = featureLayout(metadata.codec);
  const F = layout[layout.length - 1].stop;
  const G = F + (metadata.heading_frame ? 1 : 0); // the graph's channels: a heading-frame model adds its turn rate
  const window = metadata.window;
  const loop = Boolean(options.loop);
  const margin = loop ? 0 : options.margin ?? EDGE_MARGIN;
  const frames = options.frames;
  if (loop && frames < window) throw new Error(`a loop must be at least one window (${window} frames) long, got ${frames}`);
  const hop = options.hop ?? defaultHop(metadata, window);
  const round = (options.stateDtype ?? 'float32') === 'float32' ? Math.fround : (v) => v;
  const State = round === Math.fround ? Float32Array : Float64Array;
  const denoiser = new WindowedDenoiser(ort, session, G, window, frames + 2 * margin, hop, loop, round);
  const T = denoiser.frames;
  const schedule = new Schedule(metadata.alphas_cumprod, options.steps ?? defaultSteps(metadata));
  const sampler = options.sampler ?? 'ddpm';
  let x = State.from(noise.initial(G * T));
  const S = schedule.timesteps.length;
  for (let k = 0; k < S; k++) {
    const step = S - 1 - k;
    const t = schedule.timesteps[step];
    const x0 = await denoiser.denoise(x, t);
    if (onStep) onStep(k, t, x, x0);
    const eps = step > 0 ? noise.step(k, G * T) : null; // drawn after denoising, none at the last step
    const next = new State(G * T);
    if (sampler === 'ddpm') schedule.ddpmStep(step, x, x0, eps, round, next);
    else schedule.ddimStep(step, x, x0, options.eta ?? 0, eps, round, next);
    x = next;
  }
  // cut the margins, back from the graph's space (metadata velocity_unit), transpose (F, T) -> (frames, F)
  const scale = modelScale(metadata, layout, F);
  const features = new Float32Array(frames * F);
  if (metadata.heading_frame) {
    fromHeadingFrame(metadata, layout, x, T, margin, frames, loop, scale, round, features);
    return { features, x, schedule, denoiser, margin, hop };
  }
  for (let f = 0; f < F; f++) for (let i = 0; i < frames; i++) features[i * F + f] = x[f * T + margin + i] / scale[f];
  return { features, x, schedule, denoiser, margin, hop };
}

module.exports = { sampleFeatures, modelScale, defaultSteps, DEFAULT_STEPS, EDGE_MARGIN };
