"""Stored square maps. Each codec keeps the physical block (bytes) apart from the symbolic block
(indices, codebook, transforms), the encoder search and the decoders; ``registry`` gives them all
one interface (``get_codec``), the raw ``sqN`` map included."""

__all__ = ["Codec", "get_codec", "codec_names", "ENCODERS", "EFFORTS"]


def __getattr__(name):
    # the registry on first use: the OMM format reads ``codecs.raw`` alone
    if name in __all__:
        from . import registry

        return getattr(registry, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
