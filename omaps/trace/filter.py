"""The Embree filter function of a scheme: T ignores the hit, O accepts it, C runs the shader.

One numba ``cfunc`` per state function (``lookups``). Per candidate hit on an alpha-tested
triangle it looks the hit's region state up in the scheme's stored data and counts: candidates
per *distinct* (instance, triangle) of a ray -- Embree may report one hit twice (spatial splits)
and a repeated report is one candidate and at most one alpha test -- and alpha tests. In record
mode (deferred shadow rays) C candidates are recorded untested instead.

numba's on-disk cache keys a kernel on its own file only: these filters compile the state
functions of ``lookups`` and the codecs' ``block_state`` (format codes from the codec registry)
into themselves, so a change there needs this file touched too (a change to the format codes
did, and the hierarchical micromaps' state functions).
"""

from __future__ import annotations

import numpy as np
from numba import cfunc, njit, types

from .. import states
from .embree import f32_ptr, f64_ptr, i32_ptr, i64_ptr, u32_ptr
from . import lookups
from .lookups import clamp_bary, shader_alpha_test
from .tables import (C_CALLS, C_CAND, C_MODE, C_REC_BARY, C_REC_CAP, C_REC_N, C_REC_TRI, C_SET_FULL, C_SET_KEYS,
                     C_SET_STAMPS, C_STAMP, C_TABLE, C_TESTS, MODE_RECORD, SET_SIZE, T_ALPHA_BASE, T_PROTO_OF_INST)

__all__ = ["make_filter"]


@njit(cache=True, inline="always")
def _seen_before(ctx, key):
    """Insert ``key`` into the ray's candidate set; True if it was there already."""
    keys = i64_ptr(ctx[C_SET_KEYS])
    stamps = i64_ptr(ctx[C_SET_STAMPS])
    stamp = ctx[C_STAMP]
    h = (key * 0x9E3779B97F4A7C15) >> 20
    for probe in range(SET_SIZE):
        slot = (h + probe) & (SET_SIZE - 1)
        if stamps[slot] != stamp:
            stamps[slot] = stamp
            keys[slot] = key
            return False
        if keys[slot] == key:
            return True
    ctx[C_SET_FULL] += 1
    return False


@njit(cache=True, inline="always")
def _filter(args, state_fn):
    """The body of every filter: ``args`` is Embree's RTCFilterFunctionNArguments (int64 words)."""
    valid = i32_ptr(args[0])
    ctx = i64_ptr(args[2])
    hitf = f32_ptr(args[4])
    hitu = u32_ptr(args[4])
    n = args[5] & 0xFFFFFFFF
    table = i64_ptr(ctx[C_TABLE])
    proto_of = i32_ptr(table[T_PROTO_OF_INST])
    base = i64_ptr(table[T_ALPHA_BASE])
    for r in range(n):
        if valid[r] == 0:
            continue
        inst = np.int64(hitu[7 * n + r])
        prim = np.int64(hitu[5 * n + r])
        tri = base[proto_of[inst]] + prim
        b1, b2 = clamp_bary(hitf[3 * n + r], hitf[4 * n + r])
        ctx[C_CALLS] += 1
        repeat = _seen_before(ctx, (inst << 32) | prim)
        if not repeat:
            ctx[C_CAND] += 1
        state = state_fn(table, tri, b1, b2)
        if state == states.C:
            if ctx[C_MODE] == MODE_RECORD:
                if not repeat:
                    k = ctx[C_REC_N]
                    if k < ctx[C_REC_CAP]:
                        i64_ptr(ctx[C_REC_TRI])[k] = tri
                        f64_ptr(ctx[C_REC_BARY])[2 * k] = b1
                        f64_ptr(ctx[C_REC_BARY])[2 * k + 1] = b2
                    ctx[C_REC_N] = k + 1
                valid[r] = 0
                continue
            if not repeat:
                ctx[C_TESTS] += 1
            if not shader_alpha_test(table, tri, b1, b2):
                valid[r] = 0
        elif state == states.T:
            valid[r] = 0


# One module-level filter per module-level state function: numba caches them on disk (a filter
# made in a closure would be compiled again in every process, ~0.5 s each).
def _filter_none(args):
    _filter(args, lookups.no_map_state)


def _filter_micromap(args):
    _filter(args, lookups.micro_map_state)


def _filter_stored_micromap(args):
    _filter(args, lookups.stored_micromap_state)


def _filter_succinct(args):
    _filter(args, lookups.succinct_map_state)


def _filter_csm(args):
    _filter(args, lookups.csm_map_state)


def _filter_counting(args):
    _filter(args, lookups.counting_state)


def _filter_mixed(args):
    _filter(args, lookups.mixed_map_state)


def _filter_pair_map(args):
    _filter(args, lookups.pair_map_state)


_CACHED = {lookups.no_map_state: _filter_none, lookups.micro_map_state: _filter_micromap,
           lookups.stored_micromap_state: _filter_stored_micromap, lookups.counting_state: _filter_counting,
           lookups.succinct_map_state: _filter_succinct, lookups.csm_map_state: _filter_csm,
           lookups.mixed_map_state: _filter_mixed, lookups.pair_map_state: _filter_pair_map}
_FILTERS: dict = {}
_SIG = types.void(types.CPointer(types.int64))


def make_filter(state_fn):
    """The Embree filter (RTCFilterFunctionN) of a scheme, as a numba cfunc (cached on disk for the
    state functions of ``lookups``; compiled per process for a codec's closure)."""
    if state_fn in _FILTERS:
        return _FILTERS[state_fn]
    if state_fn in _CACHED:
        filt = cfunc(_SIG, cache=True)(_CACHED[state_fn])
    else:
        @cfunc(_SIG)
        def filt(args):
            _filter(args, state_fn)
    _FILTERS[state_fn] = filt
    return filt
