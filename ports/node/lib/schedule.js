'use strict';
// The diffusion schedule (docs/runtime.md, "Schedule"): respacing, the posterior
// coefficients and the DDPM / DDIM updates. Coefficients are float64; the state
// arithmetic follows the state dtype (float32: every operation rounded to float32).

// numpy's np.round: halves go to the even neighbour (Math.round sends them up).
function roundHalfEven(value) {
  const floor = Math.floor(value);
  const rest = value - floor;
  if (rest < 0.5) return floor;
  if (rest > 0.5) return floor + 1;
  return floor % 2 === 0 ? floor : floor + 1;
}

// The chain's original timesteps for `steps` denoising steps (null: all of them).
function respacedTimesteps(total, steps) {
  if (steps == null || steps >= total) return Array.from({ length: total }, (_, i) => i);
  if (!(steps >= 1)) throw new Error(`steps must be >= 1, got ${steps}`);
  if (steps === 1) return [total - 1];
  const frac = (total - 1) / Math.max(steps - 1, 1);
  const use = new Set();
  for (let k = 0; k < steps; k++) use.add(roundHalfEven(k * frac));
  return [...use].sort((a, b) => a - b);
}

class Schedule {
  constructor(alphasCumprodAll, steps) {
    this.timesteps = respacedTimesteps(alphasCumprodAll.length, steps);
    const abar = this.timesteps.map((t) => alphasCumprodAll[t]);
    const n = abar.length;
    this.alphasCumprod = abar;
    this.c1 = new Array(n);
    this.c2 = new Array(n);
    this.logVariance = new Array(n);
    const variance = new Array(n);
    for (let i = 0; i < n; i++) {
      const prev = i === 0 ? 1.0 : abar[i - 1];
      const beta = 1.0 - abar[i] / prev;
      this.c1[i] = (beta * Math.sqrt(prev)) / (1.0 - abar[i]);
      this.c2[i] = ((1.0 - prev) * Math.sqrt(1.0 - beta)) / (1.0 - abar[i]);
      variance[i] = (beta * (1.0 - prev)) / (1.0 - abar[i]);
    }
    for (let i = 0; i < n; i++) {
      // the first step's variance is 0: its log is taken from the second step
      this.logVariance[i] = n > 1 ? Math.log(variance[i === 0 ? 1 : i]) : Math.log(Math.max(variance[i], 1e-20));
    }
  }

  // x at chain step `step` - 1 from x at `step`, x0_hat and noise (null at step 0); in place into `out`.
  ddpmStep(step, x, x0, noise, round, out) {
    const c1 = round(this.c1[step]);
    const c2 = round(this.c2[step]);
    const sigma = round(Math.exp(0.5 * this.logVariance[step]));
    for (let i = 0; i < x.length; i++) {
      let mean = round(c1 * x0[i]);
      mean = round(mean + round(c2 * x[i]));
      if (step > 0) mean = round(mean + round(sigma * noise[i]));
      out[i] = mean;
    }
    return out;
  }

  // DDIM (Song et al. eq. 12): eta 0 deterministic.
  ddimStep(step, x, x0, eta, noise, round, out) {
    const abar = this.alphasCumprod[step];
    const abarPrev = step > 0 ? this.alphasCumprod[step - 1] : 1.0;
    const sigma = eta * Math.sqrt(((1 - abarPrev) / (1 - abar)) * (1 - abar / abarPrev));
    const a = round(Math.sqrt(abar));
    const b = round(Math.sqrt(1.0 - abar));
    const c = round(Math.sqrt(abarPrev));
    const d = round(Math.sqrt(Math.max(1 - abarPrev - sigma * sigma, 0.0)));
    const s = round(sigma);
    for (let i = 0; i < x.length; i++) {
      const eps = round(round(x[i] - round(a * x0[i])) / b);
      let value = round(round(c * x0[i]) + round(d * eps));
      if (step > 0 && sigma > 0) value = round(value + round(s * noise[i]));
      out[i] = value;
    }
    return out;
  }
}

module.exports = { Schedule, respacedTimesteps, roundHalfEven };
