"""Torch-free runtime: BVH, motion features, ONNX model loading and sampling.

    from sinmdm.runtime import load_model, generate, SamplingOptions, write_bvh
"""

from .bvh import BVH, Skeleton, read_bvh, write_bvh
from .errors import BVHError, ModelError, SinMDMError
from .features import FeatureLayout, MotionCodec, build_codec
from .generate import GenerationResult, generate
from .outputs import write_outputs
from .model import MotionModel, load_model
from .options import SamplingOptions
from .sampler import Guide, sample_features

__all__ = [
    "BVH", "Skeleton", "read_bvh", "write_bvh", "BVHError", "ModelError", "SinMDMError",
    "FeatureLayout", "MotionCodec", "build_codec", "SamplingOptions", "GenerationResult",
    "generate", "write_outputs", "MotionModel", "load_model", "Guide", "sample_features",
]
