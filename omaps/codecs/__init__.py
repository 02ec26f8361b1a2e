"""Stored square maps. Each codec keeps the physical block (bytes) apart from the symbolic block
(indices, codebook, transforms), the encoder search and the decoders; ``registry`` gives them all
one interface (``get_codec``), the raw ``sqN`` map included, and is the one list of codecs
(``ENTRIES``). Outside this package, omaps uses only the names below: the registry, the raw
2-bit layout, ``block_state`` (the tracer's read of any codec's block by its format code) and
the hierarchical micromaps (``succinct_*``: one triangle's pruned tree with rank support;
``csm_*``: a set's micromaps with common subtrees merged)."""

from ..lazy import exports

_REGISTRY = ["Codec", "CodecEntry", "CompileFamily", "PairMicromaps", "ENTRIES", "PLUGIN_GROUP", "get_codec", "codec_names",
             "codec_list", "entry", "budget_options", "format_names", "family_codecs", "square_codec", "COMPILE_FAMILIES",
             "ENCODERS", "EFFORTS"]
_RAW = ["pack_states", "unpack_states", "row_bytes", "read_state"]  # the one 2-bit layout of every raw map
# hierarchical micromaps (schemes succinctL, csmL): one triangle's pruned tree with rank support,
# and a set's merged subtrees
_SUCCINCT = ["succinct_encode", "succinct_encode_many", "succinct_encode_dag", "succinct_decode", "succinct_lookup", "succinct_bits",
             "succinct_check"]
_CSM = ["csm_build", "csm_treelets", "csm_pack", "csm_encode", "csm_decode", "csm_unpack", "csm_lookup", "csm_bits", "csm_check",
        "CsmBuilder"]
_BITS = ["get_bits", "bit_length"]  # the bit-field rule of every block (docs/FORMAT.md)
__all__ = _REGISTRY + _RAW + _SUCCINCT + _CSM + _BITS + ["block_state", "pair_block_state", "MAX_BLOCK_BYTES"]

# each name from its module on first use: the OMM format reads the raw layout alone
__getattr__, __dir__ = exports(__name__, {**dict.fromkeys(_REGISTRY, "registry"), **dict.fromkeys(_RAW, "raw"),
                                          "block_state": "dispatch", "pair_block_state": "dispatch", "MAX_BLOCK_BYTES": "dispatch",
                                          **dict.fromkeys(_SUCCINCT, "succinct"), **dict.fromkeys(_CSM, "csm"),
                                          **dict.fromkeys(_BITS, "bits")})
