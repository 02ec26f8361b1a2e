import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from omaps import states
from omaps.errors import InputError
from omaps.sampling import address, footprint_grid, wrap_code

import reference as ref


@given(st.integers(-1000, 1000), st.integers(1, 37), st.sampled_from(["wrap", "clamp", "mirror"]))
def test_address_matches_numpy_pad(i, n, wrap):
    row = np.arange(n)
    m = abs(i) + 1
    padded = np.pad(row, m, mode=ref.PAD_MODES[wrap])
    assert address(i, n, wrap_code(wrap)) == padded[i + m]


def test_linear_grid_cells_or_their_taps():
    s = np.array([[states.T, states.O, states.T]], np.uint8)
    g = footprint_grid(s, "linear", "clamp")
    assert g.offset == 0.5 and g.flags.shape == (2, 4)
    # dual cells along x: [t0], [t0 t1], [t1 t2], [t2]
    assert list(g.flags[0]) == [states.FLAG_T, states.FLAG_C, states.FLAG_C, states.FLAG_T]
    g = footprint_grid(s, "linear", "wrap")
    assert list(g.flags[0]) == [states.FLAG_T, states.FLAG_C, states.FLAG_C]  # cell 0 = taps t2, t0


def test_grid_errors():
    with pytest.raises(InputError, match="filter"):
        footprint_grid(np.zeros((2, 2), np.uint8), "cubic")
    with pytest.raises(InputError, match="wrap"):
        footprint_grid(np.zeros((2, 2), np.uint8), "nearest", "repeat")
    with pytest.raises(InputError, match="non-empty"):
        footprint_grid(np.zeros((0, 2), np.uint8))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.lists(st.integers(0, 255), min_size=3, max_size=3), min_size=2, max_size=2),
       st.integers(-12, 20), st.integers(-12, 20), st.sampled_from(["clamp", "wrap", "mirror"]))
def test_linear_fetch_matches_the_exact_reference(rows, qx, qy, wrap):
    """``sampling.sample_texture`` (the shader's fetch, through ``sampling.blend``) against the
    exact bilinear alpha of the reference at quarter-texel points, where float arithmetic on
    8-bit taps is exact; nearest reads the texel the point lies in."""
    from fractions import Fraction

    from omaps.sampling import sample_texture

    values = np.array(rows, dtype=np.uint8)
    x, y = Fraction(qx, 4), Fraction(qy, 4)
    mode = wrap_code(wrap)
    got = sample_texture(values, 1, mode, mode, float(x), float(y))
    assert got == ref.bilinear_at(values, wrap, wrap, x, y)
    got = sample_texture(values, 0, mode, mode, float(x), float(y))
    assert got == values[ref._address(math.floor(y), 2, wrap), ref._address(math.floor(x), 3, wrap)]
