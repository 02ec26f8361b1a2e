"""Speeds that can be compared: every traced scheme and the opaque-only traversal timed in
rounds, side by side (each round traces all of them, one after the other), each keeping its best
round. One timing of each is at the mercy of whatever else the machine does at that moment (a
first run also pays for warming caches); the best of several rounds, taken under the same
conditions, is the figure the code itself sets, and a ratio of two best rounds is the fair one.
Only the timings change: the counting runs' results (tests, hits) stay as they were traced."""

from __future__ import annotations

__all__ = ["TIMING_ROUNDS", "time_side_by_side", "round_seconds"]

TIMING_ROUNDS = 3  # rounds in all, the counting run included


def round_seconds(run) -> float:
    """The seconds a run's rate is computed from: its primary rays, plus its shadow rays."""
    return run.primary.seconds + (run.shadow.seconds if run.shadow is not None else 0.0)


def time_side_by_side(runs: dict, trace_once, rounds: int = TIMING_ROUNDS) -> dict:
    """Time every run of ``runs`` (key -> a traced run, the first round) ``rounds`` times in all:
    each further round calls ``trace_once(key)`` for every key in order. Each run keeps the
    primary and shadow seconds of its best (fastest) round; returns key -> every round's seconds."""
    samples = {k: [round_seconds(r)] for k, r in runs.items()}
    best = {k: (r.primary.seconds, None if r.shadow is None else r.shadow.seconds) for k, r in runs.items()}
    for _ in range(rounds - 1):
        for k in runs:
            again = trace_once(k)
            t = round_seconds(again)
            if t < min(samples[k]):
                best[k] = (again.primary.seconds, None if again.shadow is None else again.shadow.seconds)
            samples[k].append(t)
    for k, r in runs.items():
        r.primary.seconds = best[k][0]
        if r.shadow is not None:
            r.shadow.seconds = best[k][1]
    return samples
