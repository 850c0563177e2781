#!/usr/bin/env node
'use strict';
// node check.js MODEL DIR [--json] [--tolerance 1e-4]
// Replays the vectors in DIR (written by `sinmdm-run vectors MODEL --out DIR`) with this port:
// the same schedule and windows, the whole chain from DIR's x_T with DIR's noise, then the
// decoding. Prints the largest differences; exit 0 within the tolerance, 1 above it, 2 on bad input.

const crypto = require('crypto');
const fs = require('fs');
const { decode } = require('./lib/codec');
const { InputError, loadMetadata, loadVectors } = require('./lib/files');
const { sampleFeatures } = require('./lib/sampler');
const { Schedule } = require('./lib/schedule');
const { smoothFrames } = require('./lib/smoothing');

const USAGE = 'usage: node check.js MODEL DIR [--json] [--tolerance 1e-4]';

function parseArgs(argv) {
  const args = { json: false, tolerance: 1e-4, positional: [] };
  for (let i = 0; i < argv.length; i++) {
    if (argv[i] === '--json') args.json = true;
    else if (argv[i] === '--tolerance') args.tolerance = Number(argv[++i]);
    else if (argv[i].startsWith('--')) throw new InputError(`unknown option ${argv[i]}; ${USAGE}`);
    else args.positional.push(argv[i]);
  }
  if (args.positional.length !== 2) throw new InputError(USAGE);
  if (!(args.tolerance > 0)) throw new InputError('--tolerance must be a positive number');
  return args;
}

function maxAbsDiff(a, b, offsetB = 0) {
  let worst = 0;
  for (let i = 0; i < a.length; i++) {
    const d = Math.abs(a[i] - b[offsetB + i]);
    if (!(d <= worst)) worst = d; // NaN wins
  }
  return worst;
}

function requireOrt() {
  try {
    return require('onnxruntime-node');
  } catch (err) {
    throw new InputError('onnxruntime-node is not installed: npm install --prefix ports/node (or set NODE_PATH to a node_modules that has it)');
  }
}

function sha256(file) {
  return crypto.createHash('sha256').update(fs.readFileSync(file)).digest('hex');
}

async function check(modelPath, dir, tolerance) {
  if (!fs.existsSync(modelPath)) throw new InputError(`model file ${modelPath} does not exist`);
  const { manifest, arrays } = loadVectors(dir);
  const { document: metadata, file: metadataFile } = loadMetadata(modelPath, dir);
  if (sha256(modelPath) !== manifest.model.sha256) {
    throw new InputError(`${modelPath} is not the model the vectors in ${dir} were written with (sha256 differs)`);
  }
  if (metadata.model_id !== manifest.model.model_id) throw new InputError(`${metadataFile} describes another model than the vectors`);
  const ort = requireOrt();
  let session;
  try {
    session = await ort.InferenceSession.create(modelPath, { graphOptimizationLevel: 'all', executionMode: 'sequential' });
  } catch (err) {
    throw new InputError(`${modelPath} is not a readable ONNX model (${String(err.message).split('\n')[0]})`);
  }
  if (session.inputNames.join() !== 'x_t,t' || session.outputNames.join() !== 'x0') {
    throw new InputError(`${modelPath} has inputs ${session.inputNames} and outputs ${session.outputNames}, expected x_t,t and x0`);
  }

  const opts = manifest.options;
  const problems = [];
  // The schedule and windows this port derives must be the recorded ones.
  const schedule = new Schedule(metadata.alphas_cumprod, opts.steps);
  if (schedule.timesteps.join() !== manifest.schedule.timesteps.join()) problems.push('schedule timesteps differ');
  let coefficients = 0;
  for (const [mine, theirs] of [[schedule.c1, 'c1'], [schedule.c2, 'c2'], [schedule.logVariance, 'log_variance']]) {
    coefficients = Math.max(coefficients, maxAbsDiff(mine, manifest.schedule[theirs]));
  }
  if (!(coefficients <= 1e-12)) problems.push(`schedule coefficients differ by ${coefficients}`);

  const F = manifest.features;
  const T = manifest.length;
  const size = (manifest.graph_width ?? F) * T; // the chain's channels
  let worstX0 = 0;
  let worstXt = 0;
  const result = await sampleFeatures(ort, session, metadata, {
    frames: opts.frames, steps: opts.steps, hop: opts.hop, margin: opts.margin, loop: opts.loop,
    sampler: opts.sampler, eta: opts.eta, stateDtype: manifest.state_dtype,
  }, {
    initial: () => arrays.x_T.values,
    step: (k) => arrays.noise.values.subarray(k * size, (k + 1) * size),
  }, (k, t, xT, x0) => {
    if (t !== manifest.denoiser_timesteps[k]) problems.push(`step ${k}: timestep ${t}, recorded ${manifest.denoiser_timesteps[k]}`);
    worstXt = Math.max(worstXt, maxAbsDiff(xT, arrays.x_t.values, k * size));
    worstX0 = Math.max(worstX0, maxAbsDiff(x0, arrays.x0_hat.values, k * size));
  });
  if (result.denoiser.starts.join() !== manifest.window_starts.join()) problems.push('window starts differ');
  if (result.denoiser.frames !== T) problems.push(`sampled length ${result.denoiser.frames}, recorded ${T}`);

  // Vectors written before the smoothing have no `smoothed`: their positions decode `features`.
  const smoothed = smoothFrames(result.features, opts.frames, F, opts.smooth ?? 0, opts.loop);
  const recordedSmoothed = arrays.smoothed ? arrays.smoothed.values : arrays.features.values;
  const decoded = decode(metadata.codec, smoothed, opts.frames, metadata.start_position || [0, 0]);
  const features = maxAbsDiff(result.features, arrays.features.values);
  const smoothedDiff = maxAbsDiff(smoothed, recordedSmoothed);
  const positions = maxAbsDiff(decoded.positions, arrays.positions.values);
  const rotations = maxAbsDiff(decoded.rotations, arrays.local_rotations.values);
  // Decoding alone, from the recorded features: separates the codec from the chain.
  const alone = decode(metadata.codec, recordedSmoothed, opts.frames, metadata.start_position || [0, 0]);
  const decodeOnly = maxAbsDiff(alone.positions, arrays.positions.values) / manifest.figure_size;
  const report = {
    model: modelPath,
    metadata: metadataFile,
    frames: opts.frames,
    steps: schedule.timesteps.length,
    windows: result.denoiser.starts.length,
    schedule_coefficients: coefficients,
    x_t: worstXt,
    x0_hat: worstX0,
    features,
    smooth: opts.smooth ?? 0,
    smoothed: smoothedDiff,
    positions,
    positions_of_size: positions / manifest.figure_size,
    decode_only_positions_of_size: decodeOnly,
    local_rotations: rotations,
    tolerance,
    problems,
  };
  const within = problems.length === 0 && features <= tolerance && smoothedDiff <= tolerance && report.positions_of_size <= tolerance && decodeOnly <= tolerance;
  report.ok = within;
  return report;
}

function print(report) {
  const e = (v) => v.toExponential(2);
  console.log(`model ${report.model}, metadata ${report.metadata}`);
  console.log(`${report.frames} frames, ${report.steps} steps, ${report.windows} windows; schedule coefficients differ by ${e(report.schedule_coefficients)}`);
  console.log(`chain: max |x_t| diff ${e(report.x_t)}, max |x0_hat| diff ${e(report.x0_hat)}`);
  console.log(`features: max abs diff ${e(report.features)}; smoothed (sigma ${report.smooth} frames): ${e(report.smoothed)}`);
  console.log(`positions: max abs diff ${e(report.positions)} file units = ${e(report.positions_of_size)} of the figure's size (decoding alone: ${e(report.decode_only_positions_of_size)})`);
  console.log(`local rotations: max abs diff ${e(report.local_rotations)}`);
  for (const problem of report.problems) console.log(`problem: ${problem}`);
  console.log(report.ok ? `ok (tolerance ${report.tolerance})` : `FAILED (tolerance ${report.tolerance})`);
}

async function main() {
  let args;
  try {
    args = parseArgs(process.argv.slice(2));
    const report = await check(args.positional[0], args.positional[1], args.tolerance);
    if (args.json) console.log(JSON.stringify(report));
    else print(report);
    process.exitCode = report.ok ? 0 : 1;
  } catch (err) {
    if (!(err instanceof InputError)) throw err;
    process.stderr.write(`error: ${err.message}\n`);
    process.exitCode = 2;
  }
}

main();
