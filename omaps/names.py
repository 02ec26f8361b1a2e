"""The names the command line offers, defined once and without numpy or numba, so that parsing a
command line (and ``omaps omm --help``) loads no kernels. The modules that give the names their
meaning import them from here: ``sampling`` (filters, wrap modes), ``alpha_test`` (corpus and
BLEND rules), ``promotion``, ``codecs.options`` (encoders, efforts), ``omm_format`` (OMM formats).

Example::

    >>> from omaps.names import FILTERS, PROMOTIONS
    >>> FILTERS, PROMOTIONS[0]
    (('nearest', 'linear'), 'nearest')
"""

__all__ = ["WRAP_MODES", "FILTERS", "MODES", "BLEND_RULES", "PROMOTIONS", "ENCODERS", "EFFORTS", "OMM_FORMATS",
           "BUDGET_WEIGHTS"]

WRAP_MODES = ("wrap", "clamp", "mirror")  # texture addressing (``sampling``)
FILTERS = ("nearest", "linear")  # texture filters (``sampling``)
MODES = ("levels", "cutoff")  # the corpus rules of ``omaps eval`` (``alpha_test.StateRule``)
BLEND_RULES = ("levels", "cutoff", "skip")  # glTF BLEND materials (``alpha_test.MaterialRules.blend``)
PROMOTIONS = ("nearest", "opaque", "transparent", "hashed")  # what a C region becomes (``promotion``)
ENCODERS = ("paper", "best")  # the deck's compressor, and our search (``codecs.options``)
EFFORTS = {"fast": 0, "medium": 1, "thorough": 2}  # our encoder's search effort (``codecs.options``)
OMM_FORMATS = {"2state": 1, "4state": 2}  # standard OMM formats and their codes (``omm_format``)
BUDGET_WEIGHTS = ("area", "view")  # a byte budget's weights: world area x instances, or ``view``
