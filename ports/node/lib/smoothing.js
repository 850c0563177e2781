'use strict';
// The smoothing of sampled features (docs/runtime.md, "Smoothing"): a normalised Gaussian of
// sigma frames over each feature channel, the ends extended by their own frame or, for a
// loop, wrapped around the circle. Sums in float32, as the Python runtime's.

const DEFAULT_SMOOTH = 1.0;
const MAX_SMOOTH = 10.0;

function defaultSmooth(metadata) {
  const value = (metadata.sampling_defaults || {}).smooth;
  return typeof value === 'number' && value >= 0 && value <= MAX_SMOOTH ? value : DEFAULT_SMOOTH;
}

function gaussianWeights(sigma) {
  const radius = Math.max(1, Math.ceil(4 * sigma));
  const weights = [];
  for (let k = -radius; k <= radius; k++) weights.push(Math.exp(-0.5 * (k / sigma) ** 2));
  const total = weights.reduce((a, b) => a + b, 0);
  return weights.map((w) => w / total);
}

// features: (frames, F) row-major Float32Array; returns a new array (the input when sigma is 0).
function smoothFrames(features, frames, F, sigma, loop) {
  if (!(sigma > 0)) return features;
  const weights = gaussianWeights(sigma).map(Math.fround);
  const radius = (weights.length - 1) / 2;
  const source = (i) => (loop ? ((i % frames) + frames) % frames : Math.min(Math.max(i, 0), frames - 1));
  const out = new Float32Array(frames * F);
  for (let i = 0; i < frames; i++) {
    for (let f = 0; f < F; f++) {
      let sum = 0;
      for (let k = 0; k < weights.length; k++) {
        sum = Math.fround(sum + Math.fround(weights[k] * features[source(i + k - radius) * F + f]));
      }
      out[i * F + f] = sum;
    }
  }
  return out;
}

module.exports = { smoothFrames, gaussianWeights, defaultSmooth, DEFAULT_SMOOTH, MAX_SMOOTH };
