'use strict';
const { roundHalfEven } = require('./schedule');

// Windowed denoising (docs/runtime.md, "Windows"): x0_hat for a whole sequence from a
// fixed-window graph, overlapping windows blended with tent weights.

function windowStarts(frames, window, hop) {
  if (frames <= window) return [0];
  const starts = [];
  for (let s = 0; s <= frames - window; s += hop) starts.push(s);
  if (starts[starts.length - 1] !== frames - window) starts.push(frames - window);
  return starts;
}

// A circle of `frames` (>= window) frames: ceil(frames / hop) starts spread evenly.
function circularWindowStarts(frames, window, hop) {
  if (frames < window) throw new Error(`a loop must be at least one window (${window} frames) long, got ${frames}`);
  const count = Math.ceil(frames / hop);
  return Array.from({ length: count }, (_, k) => Math.floor((k * frames) / count));
}

function blendWeights(window) {
  return Array.from({ length: window }, (_, i) => Math.min(i + 0.5, window - i - 0.5));
}

// The hop for a request: the option, else the model's measured one scaled to the window, else half a window.
function defaultHop(metadata, window) {
  const defaults = metadata.sampling_defaults || {};
  const trained = metadata.trained_window ?? metadata.window;
  const value = defaults.hop;
  if (Number.isInteger(value) && value >= 1 && value <= trained) {
    // Python's round(): halves to even
    return Math.max(1, Math.min(window, roundHalfEven((value * window) / trained)));
  }
  return Math.max(Math.floor(window / 2), 1);
}

class WindowedDenoiser {
  // session: an onnxruntime-node InferenceSession of a graph with window `window`;
  // length: the sampled frames (margins included); round: the state dtype's rounding.
  constructor(ort, session, features, window, length, hop, loop, round) {
    if (!(hop >= 1 && hop <= window)) throw new Error(`hop must be between 1 and the window (${window}), got ${hop}`);
    this.ort = ort;
    this.session = session;
    this.features = features;
    this.window = window;
    this.loop = loop;
    this.frames = loop ? length : Math.max(length, window);
    this.hop = hop;
    this.round = round;
    this.starts = loop ? circularWindowStarts(this.frames, window, hop) : windowStarts(this.frames, window, hop);
    this.weights = blendWeights(window);
    const coverage = new Float64Array(this.frames);
    for (const s of this.starts) for (let i = 0; i < window; i++) coverage[(s + i) % this.frames] += this.weights[i];
    this.normaliser = Array.from(coverage, (c) => 1.0 / c);
  }

  // x: Float32Array / Float64Array (features * frames, row-major (F, T)); t: the original timestep.
  async denoise(x, t) {
    const { features: F, window: W, frames: T, starts } = this;
    const K = starts.length;
    const batch = new Float32Array(K * F * W);
    for (let k = 0; k < K; k++) {
      for (let f = 0; f < F; f++) {
        const row = (k * F + f) * W;
        for (let i = 0; i < W; i++) batch[row + i] = x[f * T + ((starts[k] + i) % T)];
      }
    }
    const feeds = {
      x_t: new this.ort.Tensor('float32', batch, [K, F, W]),
      t: new this.ort.Tensor('float32', new Float32Array(K).fill(t), [K]),
    };
    const out = (await this.session.run(feeds)).x0.data;
    const blended = new x.constructor(F * T);
    for (let k = 0; k < K; k++) {
      for (let f = 0; f < F; f++) {
        const row = (k * F + f) * W;
        for (let i = 0; i < W; i++) {
          const at = f * T + ((starts[k] + i) % T);
          blended[at] = this.round(blended[at] + out[row + i] * this.weights[i]);
        }
      }
    }
    for (let f = 0; f < F; f++) {
      for (let i = 0; i < T; i++) blended[f * T + i] = this.round(blended[f * T + i] * this.normaliser[i]);
    }
    return blended;
  }
}

module.exports = { WindowedDenoiser, windowStarts, circularWindowStarts, blendWeights, defaultHop };
