import numpy as np
import pytest
from hypothesis import given
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
