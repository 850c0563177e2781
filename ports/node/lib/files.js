'use strict';
// Inputs: the model's metadata document (the sidecar JSON beside the .onnx, else the
// vectors' copy) and a vectors directory (manifest.json and little-endian float32 files).

const fs = require('fs');
const path = require('path');

class InputError extends Error {}

function readJson(file, what) {
  let text;
  try {
    text = fs.readFileSync(file, 'utf8');
  } catch (err) {
    throw new InputError(`cannot read ${what} ${file} (${err.code || err.message})`);
  }
  try {
    return JSON.parse(text);
  } catch (err) {
    throw new InputError(`${what} ${file} is not JSON (${err.message})`);
  }
}

// `m_w64.onnx` -> `m_w64.json` beside it (the metadata document as plain JSON).
function sidecarPath(modelPath) {
  const parsed = path.parse(modelPath);
  return path.join(parsed.dir, `${parsed.name}.json`);
}

function loadMetadata(modelPath, vectorsDir) {
  const sidecar = sidecarPath(modelPath);
  const file = fs.existsSync(sidecar) ? sidecar : path.join(vectorsDir, 'metadata.json');
  const document = readJson(file, 'model metadata');
  if (document.format !== 'sinmdm-denoiser' || document.format_version !== 1) {
    throw new InputError(`${file} is not sinmdm model metadata of format 1 (format ${JSON.stringify(document.format)}, version ${document.format_version})`);
  }
  return { document, file };
}

function loadVectors(dir) {
  const manifest = readJson(path.join(dir, 'manifest.json'), 'vectors manifest');
  if (manifest.format !== 'sinmdm-vectors' || manifest.format_version !== 1) {
    throw new InputError(`${dir}/manifest.json is not a sinmdm-vectors manifest of format 1`);
  }
  const arrays = {};
  for (const [name, entry] of Object.entries(manifest.arrays)) {
    if (entry.dtype !== 'float32' || entry.byte_order !== 'little') throw new InputError(`${name}: expected little-endian float32`);
    const file = path.join(dir, entry.file);
    let bytes;
    try {
      bytes = fs.readFileSync(file);
    } catch (err) {
      throw new InputError(`cannot read ${file} (${err.code || err.message})`);
    }
    const count = entry.shape.reduce((a, b) => a * b, 1);
    if (bytes.length !== count * 4) throw new InputError(`${file} has ${bytes.length} bytes, expected ${count * 4} for shape [${entry.shape}]`);
    const values = new Float32Array(count);
    for (let i = 0; i < count; i++) values[i] = bytes.readFloatLE(i * 4);
    arrays[name] = { values, shape: entry.shape };
  }
  return { manifest, arrays };
}

module.exports = { InputError, loadMetadata, loadVectors, sidecarPath };
