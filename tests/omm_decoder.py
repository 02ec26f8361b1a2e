"""An independent reader of an ``omaps omm`` folder, written from docs/FORMAT.md ("Standard
opacity micromaps") with struct and plain Python only: it shares no code with omaps."""

import json
import os
import struct

SPECIAL = {-1: 0, -2: 1, -3: 2, -4: 3}  # special index -> the state of every micro-triangle


def read_folder(folder):
    def raw(name):
        with open(os.path.join(folder, name), "rb") as f:
            return f.read()

    data = raw("omm_data.bin")
    trib = raw("omm_triangles.bin")
    idxb = raw("omm_index.bin")
    records = [struct.unpack_from("<IHH", trib, 8 * i) for i in range(len(trib) // 8)]
    index = list(struct.unpack(f"<{len(idxb) // 4}i", idxb))
    with open(os.path.join(folder, "omm.json")) as f:
        summary = json.load(f)
    with open(os.path.join(folder, "omm_usage.json")) as f:
        usage = json.load(f)
    return data, records, index, summary, usage


def micromap_states(data, record):
    offset, level, fmt = record
    n = 4 ** level
    out = []
    for i in range(n):
        if fmt == 2:  # 4-state: bits 2*(i mod 4) of byte i div 4
            out.append((data[offset + i // 4] >> (2 * (i % 4))) & 3)
        elif fmt == 1:  # 2-state: bit i mod 8 of byte i div 8
            out.append((data[offset + i // 8] >> (i % 8)) & 1)
        else:
            raise ValueError(f"bad format {fmt}")
    return out


def triangle_states(folder):
    """Per input triangle: (level or None for a special index, list of states)."""
    data, records, index, _, _ = read_folder(folder)
    out = []
    for i in index:
        if i < 0:
            out.append((None, [SPECIAL[i]]))
        else:
            out.append((records[i][1], micromap_states(data, records[i])))
    return out


def usage_counts(folder):
    """The two histograms recomputed from records and index: {(level, format): count}."""
    _, records, index, _, _ = read_folder(folder)
    arr, geo = {}, {}
    for _, level, fmt in records:
        arr[(level, fmt)] = arr.get((level, fmt), 0) + 1
    for i in index:
        if i >= 0:
            _, level, fmt = records[i]
            geo[(level, fmt)] = geo.get((level, fmt), 0) + 1
    return arr, geo
