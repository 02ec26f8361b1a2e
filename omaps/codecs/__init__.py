"""Compressed opacity-map codecs. Each codec keeps the physical block (bytes) apart from the
symbolic block (indices, codebook, transforms), the encoder search and the decoders."""
