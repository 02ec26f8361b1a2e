"""omaps.rows: the hashed search for equal rows gives exactly np.unique(axis=0)'s answer, also
when every hash collides."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import omaps.rows
from omaps.rows import row_hashes, unique_rows


def _rows(data, dtype):
    n = data.draw(st.integers(0, 60))
    shape = tuple(data.draw(st.lists(st.integers(1, 9), min_size=1, max_size=2)))
    base = np.array(data.draw(st.lists(st.integers(0, 3), min_size=int(np.prod(shape)) * 4,
                                       max_size=int(np.prod(shape)) * 4)), dtype=dtype).reshape((4,) + shape)
    pick = np.array(data.draw(st.lists(st.integers(0, 3), min_size=n, max_size=n)), dtype=np.int64)
    return base[pick]


@settings(max_examples=150, deadline=None)
@given(st.data(), st.sampled_from([np.uint8, np.int32, np.int64, np.bool_]))
def test_unique_rows_is_numpy_unique(data, dtype):
    a = _rows(data, dtype)
    uniq, inverse = unique_rows(a)
    flat = a.reshape(len(a), int(np.prod(a.shape[1:])))
    if len(a):
        u2, i2 = np.unique(flat, axis=0, return_inverse=True)
        np.testing.assert_array_equal(uniq.reshape(len(uniq), -1), u2)
        np.testing.assert_array_equal(inverse, i2.ravel())
    assert uniq.shape[1:] == a.shape[1:]
    np.testing.assert_array_equal(uniq[inverse], a)


@settings(max_examples=50, deadline=None)
@given(st.data())
def test_collisions_are_caught(data):
    a = _rows(data, np.uint8)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(omaps.rows, "row_hashes", lambda f: np.zeros(len(f), np.uint64))  # every row one hash
        uniq, inverse = omaps.rows.unique_rows(a)
    np.testing.assert_array_equal(uniq[inverse], a)
    assert len(uniq) == len({r.tobytes() for r in a})


def test_hashes_of_equal_rows_agree_and_differ_otherwise():
    rng = np.random.default_rng(5)
    a = rng.integers(0, 3, (500, 13), dtype=np.uint8)  # 13 bytes: a padded last word
    a[250:] = a[:250]
    h = row_hashes(a)
    np.testing.assert_array_equal(h[:250], h[250:])
    assert len(np.unique(h[:250])) == len({r.tobytes() for r in a[:250]})
    b = a[:1].copy()
    b[0, 12] ^= 1  # one bit in the padded word
    assert row_hashes(b)[0] != h[0]


@settings(max_examples=100, deadline=None)
@given(st.integers(2, 16), st.data())
def test_structured_differences_do_not_collide(n_words, data):
    """Rows that differ in a few bits, chosen by position (the high bits of two words cancelled in
    the old weighted-sum hash: 4 of the oak leaf's micromaps collided), hash apart."""
    base = np.frombuffer(data.draw(st.binary(min_size=8 * n_words, max_size=8 * n_words)), np.uint8)
    bits = data.draw(st.lists(st.integers(0, 64 * n_words - 1), min_size=1, max_size=4, unique=True))
    other = base.copy()
    for b in bits:
        other[b >> 3] ^= np.uint8(1 << (b & 7))
    h = row_hashes(np.stack([base, other]))
    assert h[0] != h[1]


def test_top_bits_of_two_words():
    a = np.zeros((2, 16), np.uint8)
    a[1, 7] = a[1, 15] = 0x80  # bit 63 of both words
    assert row_hashes(a)[0] != row_hashes(a)[1]


@settings(max_examples=100, deadline=None)
@given(st.data(), st.booleans())
def test_first_occurrences(data, collide):
    a = _rows(data, np.uint8)
    with pytest.MonkeyPatch.context() as mp:
        if collide:
            mp.setattr(omaps.rows, "row_hashes", lambda f: np.zeros(len(f), np.uint64))
        first, inverse = omaps.rows.first_occurrences(a)
    np.testing.assert_array_equal(a[first][inverse], a)
    seen = {}
    for i, r in enumerate(a):
        seen.setdefault(r.tobytes(), i)
    assert first.tolist() == list(seen.values())  # each distinct row's first index, in order of first use


def test_only_integer_rows():
    with pytest.raises(TypeError, match="integer or bool rows"):
        unique_rows(np.zeros((3, 2)))


@settings(max_examples=150, deadline=None)
@given(st.data(), st.sampled_from(["hash", "collide", "few"]), st.booleans())
def test_row_index_ids_across_calls(data, hashes, external):
    """``RowIndex``: over several ``add`` calls (the table grows and rehashes), one id per
    distinct row, counted up in the order of first use -- checked against a dict of the rows'
    bytes -- also when every hash collides or only a few values occur; with its own copy of the
    rows, or ``external``: comparing with the caller's bytes (the new rows stored after some
    junk, at an offset the caller chooses, as the pack stage keeps its data)."""
    width = data.draw(st.integers(1, 20))
    pool = data.draw(st.lists(st.binary(min_size=width, max_size=width), min_size=1, max_size=12))
    calls = data.draw(st.lists(st.lists(st.integers(0, len(pool) - 1), max_size=40), min_size=1, max_size=5))
    fake = {"collide": lambda f: np.zeros(len(f), np.uint64),
            "few": lambda f: np.frombuffer(b"".join(bytes(r[:1]) * 8 for r in f), np.uint64) & np.uint64(3)}
    index = omaps.rows.RowIndex(width, external=external)
    ref: dict[bytes, int] = {}
    store = bytearray()
    with pytest.MonkeyPatch.context() as mp:
        if hashes in fake:
            mp.setattr(omaps.rows, "row_hashes", fake[hashes])
        for picks in calls:
            rows = np.array([np.frombuffer(pool[p], np.uint8) for p in picks], np.uint8).reshape(len(picks), width)
            if external:
                store += bytes(data.draw(st.binary(max_size=5)))  # bytes no row uses, between the rows
                before = index.n
                ids = index.add(rows, np.frombuffer(store, np.uint8), len(store))
                store += rows[omaps.rows.first_uses(ids, before)].tobytes()
            else:
                ids = index.add(rows)
            want = [ref.setdefault(pool[p], len(ref)) for p in picks]
            assert ids.tolist() == want
    assert index.n == len(ref)


def test_row_index_rejects_another_width():
    index = omaps.rows.RowIndex(4)
    with pytest.raises(ValueError, match="5 bytes"):
        index.add(np.zeros((2, 5), np.uint8))
    external = omaps.rows.RowIndex(4, external=True)
    with pytest.raises(ValueError, match="pass it"):
        external.add(np.zeros((2, 4), np.uint8))
    external.add(np.zeros((2, 4), np.uint8), np.zeros(0, np.uint8), 0)
    with pytest.raises(ValueError, match="does not hold"):  # the caller did not store the new row
        external.add(np.ones((1, 4), np.uint8), np.zeros(2, np.uint8), 2)


def test_external_index_refuses_data_that_lacks_a_row_it_has_seen():
    from omaps.rows import RowIndex, first_uses

    index, data = RowIndex(3, external=True), bytearray()
    for rows in (np.array([[1, 2, 3], [4, 5, 6]], np.uint8), np.array([[4, 5, 6], [7, 8, 9]], np.uint8)):
        before = index.n
        ids = index.add(rows, np.frombuffer(bytes(data), np.uint8), len(data))
        data += rows[first_uses(ids, before)].tobytes()  # the caller stores the new rows, in id order
    assert len(data) == 9 and index.n == 3
    assert index.add(np.array([[7, 8, 9]], np.uint8), np.frombuffer(bytes(data), np.uint8), len(data)).tolist() == [2]
    with pytest.raises(ValueError, match="every row"):  # the last row stored lies past the data given
        index.add(np.array([[1, 2, 3]], np.uint8), np.frombuffer(bytes(data[:8]), np.uint8), 8)
