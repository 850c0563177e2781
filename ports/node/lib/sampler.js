'use strict';
// The sampling loop (docs/runtime.md, "The loop"), one sample, its noise supplied by the
// caller: a port cannot reproduce numpy's PCG64 normals, so a replay reads them from the
// vectors and an application draws its own.

const { featureLayout } = require('./codec');
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

// options: { frames, steps?, hop?, margin?, loop?, sampler?, eta?, stateDtype? };
// noise.initial(size) -> x_T values, noise.step(k, size) -> the normals of loop iteration k;
// onStep(k, t, x_t, x0_hat) is called at every iteration (for checks).
async function sampleFeatures(ort, session, metadata, options, noise, onStep) {
  const layout = featureLayout(metadata.codec);
  const F = layout[layout.length - 1].stop;
  const window = metadata.window;
  const loop = Boolean(options.loop);
  const margin = loop ? 0 : options.margin ?? EDGE_MARGIN;
  const frames = options.frames;
  if (loop && frames < window) throw new Error(`a loop must be at least one window (${window} frames) long, got ${frames}`);
  const hop = options.hop ?? defaultHop(metadata, window);
  const round = (options.stateDtype ?? 'float32') === 'float32' ? Math.fround : (v) => v;
  const State = round === Math.fround ? Float32Array : Float64Array;
  const denoiser = new WindowedDenoiser(ort, session, F, window, frames + 2 * margin, hop, loop, round);
  const T = denoiser.frames;
  const schedule = new Schedule(metadata.alphas_cumprod, options.steps ?? defaultSteps(metadata));
  const sampler = options.sampler ?? 'ddpm';
  let x = State.from(noise.initial(F * T));
  const S = schedule.timesteps.length;
  for (let k = 0; k < S; k++) {
    const step = S - 1 - k;
    const t = schedule.timesteps[step];
    const x0 = await denoiser.denoise(x, t);
    if (onStep) onStep(k, t, x, x0);
    const eps = step > 0 ? noise.step(k, F * T) : null; // drawn after denoising, none at the last step
    const next = new State(F * T);
    if (sampler === 'ddpm') schedule.ddpmStep(step, x, x0, eps, round, next);
    else schedule.ddimStep(step, x, x0, options.eta ?? 0, eps, round, next);
    x = next;
  }
  // cut the margins, back from the graph's space (metadata velocity_unit), transpose (F, T) -> (frames, F)
  const scale = modelScale(metadata, layout, F);
  const features = new Float32Array(frames * F);
  for (let f = 0; f < F; f++) for (let i = 0; i < frames; i++) features[i * F + f] = x[f * T + margin + i] / scale[f];
  return { features, x, schedule, denoiser, margin, hop };
}

module.exports = { sampleFeatures, modelScale, defaultSteps, DEFAULT_STEPS, EDGE_MARGIN };
