"""The chained decoder of paper §5: Enc (RGB -> p), Dec_R (p -> R(lambda)), Dec_T ((p, R) -> K-media mixture)."""

from training.model.chain import DECODER_OUTPUTS, INVERSION_OUTPUTS, DecoderGraph, InversionGraph, SkinChain
from training.model.config import ModelConfig

__all__ = ["DECODER_OUTPUTS", "INVERSION_OUTPUTS", "DecoderGraph", "InversionGraph", "ModelConfig", "SkinChain"]
