"""Stored square maps. Each codec keeps the physical block (bytes) apart from the symbolic block
(indices, codebook, transforms), the encoder search and the decoders; ``registry`` gives them all
one interface (``get_codec``), the raw ``sqN`` map included."""

from ..lazy import exports

__all__ = ["Codec", "get_codec", "codec_names", "ENCODERS", "EFFORTS"]

# the registry on first use: the OMM format reads ``codecs.raw`` alone
__getattr__, __dir__ = exports(__name__, dict.fromkeys(__all__, "registry"))
