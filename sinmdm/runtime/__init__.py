"""Torch-free runtime: BVH, motion features, ONNX model loading and sampling."""
