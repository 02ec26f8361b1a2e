"""Stored square maps. Each codec keeps the physical block (bytes) apart from the symbolic block
(indices, codebook, transforms), the encoder search and the decoders; ``registry`` gives them all
one interface (``get_codec``), the raw ``sqN`` map included."""

from .registry import EFFORTS, ENCODERS, Codec, codec_names, get_codec

__all__ = ["Codec", "get_codec", "codec_names", "ENCODERS", "EFFORTS"]
