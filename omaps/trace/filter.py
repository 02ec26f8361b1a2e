"""The Embree filter function of a scheme: T ignores the hit, O accepts it, C runs the shader.

One numba ``cfunc`` per state function (``lookups``). Per candidate hit on an alpha-tested
triangle it looks the hit's region state up in the scheme's stored data and counts: candidates
per *distinct* (instance, triangle) of a ray -- Embree may report one hit twice (spatial splits)
and a repeated report is one candidate and at most one alpha test -- and alpha tests. In record
mode (deferred shadow rays) C candidates are recorded untested instead.

These filters compile the state functions of ``lookups`` and the codecs' ``block_state`` (every
registered codec's lookup, its format code a constant) into themselves; their cached kernels are
keyed on every module they import, the registry and each codec's modules included
(``omaps.kernel_cache``), so a new or changed codec recompiles them in the next process.
"""

from __future__ import annotations

import numpy as np
from numba import cfunc, njit, types

from .. import states
from .embree import f32_ptr, f64_ptr, i32_ptr, i64_ptr, u8_ptr, u32_ptr
from . import lookups
from .lookups import clamp_bary, shader_alpha_test
from .tables import (C_CALLS, C_CAND, C_MODE, C_REC_BARY, C_REC_CAP, C_REC_N, C_REC_TRI, C_SET_FULL, C_SET_KEYS,
                     C_SET_STAMPS, C_STAMP, C_TABLE, C_TESTS, MODE_RECORD, SET_SIZE, T_ALPHA_BASE, T_PROTO_OF_INST,
                     T_REC_BARY, T_REC_COUNT, T_REC_START, T_REC_STATE, T_REC_TRI)

__all__ = ["make_filter", "make_recording_filter", "record_lookup"]


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
def _no_hook(ctx, table, tri, b1, b2, state):
    """The hook of the traced filters: nothing (compiled away)."""


@njit(cache=True, inline="always")
def record_lookup(ctx, table, tri, b1, b2, state):
    """The hook of ``trace --memory``'s recording filters: the lookup (triangle, barycentrics,
    state) into its pixel's slots (``tables.T_REC_*``; the pixel is the ray's stamp, ``y * w + x``
    in the primary pass). A pixel's lookups past its slots are counted, not stored."""
    pix = ctx[C_STAMP]
    count = i64_ptr(table[T_REC_COUNT])
    k = i64_ptr(table[T_REC_START])[pix] + count[pix]
    if k < i64_ptr(table[T_REC_START])[pix + 1]:
        i64_ptr(table[T_REC_TRI])[k] = tri
        f64_ptr(table[T_REC_BARY])[2 * k] = b1
        f64_ptr(table[T_REC_BARY])[2 * k + 1] = b2
        u8_ptr(table[T_REC_STATE])[k] = state
    count[pix] += 1


@njit(cache=True, inline="always")
def _filter(args, state_fn):
    """The body of every traced filter: ``args`` is Embree's RTCFilterFunctionNArguments (int64 words)."""
    _filter_hooked(args, state_fn, _no_hook)


@njit(cache=True, inline="always")
def _filter_hooked(args, state_fn, hook):
    """The filter's body with ``hook(ctx, table, tri, b1, b2, state)`` called after every lookup."""
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
        hook(ctx, table, tri, b1, b2, state)
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


# ``trace --memory``: the same filters recording every lookup, module-level so numba caches them
def _record_none(args):
    _filter_hooked(args, lookups.no_map_state, record_lookup)


def _record_micromap(args):
    _filter_hooked(args, lookups.micro_map_state, record_lookup)


def _record_succinct(args):
    _filter_hooked(args, lookups.succinct_map_state, record_lookup)


def _record_csm(args):
    _filter_hooked(args, lookups.csm_map_state, record_lookup)


def _record_pair_map(args):
    _filter_hooked(args, lookups.pair_map_state, record_lookup)


_CACHED_RECORDING = {lookups.no_map_state: _record_none, lookups.micro_map_state: _record_micromap,
                     lookups.succinct_map_state: _record_succinct,
                     lookups.csm_map_state: _record_csm, lookups.pair_map_state: _record_pair_map}
_RECORDING: dict = {}


def make_recording_filter(state_fn):
    """``make_filter``'s filter that also records every lookup (``record_lookup``) for
    ``trace --memory``: the same lookups, states and counts (the traced filters stay free of the
    hook)."""
    if state_fn not in _RECORDING:
        if state_fn in _CACHED_RECORDING:
            filt = cfunc(_SIG, cache=True)(_CACHED_RECORDING[state_fn])
        else:
            @cfunc(_SIG)
            def filt(args):
                _filter_hooked(args, state_fn, record_lookup)
        _RECORDING[state_fn] = filt
    return _RECORDING[state_fn]
