"""A batch's summary: totals, ``summary.json`` / ``summary.csv``, the result object and the
per-input warnings printed while it runs."""

from __future__ import annotations

import csv
import dataclasses
import io
import os
import sys
import warnings

from ..text import plural as count  # "1 input", "2 inputs"


def totals(command: str, records: list[dict]) -> dict:
    t = {"inputs": len(records)}
    for s in ("ok", "problems", "skipped", "error", "unfinished"):
        t[s] = sum(r["status"] == s for r in records)
    t["resumed"] = sum(bool(r.get("resumed")) for r in records)
    done = [r["figures"] for r in records if r.get("figures")]
    if command == "eval" and done:
        schemes = list(done[0]["savings"])
        t["mean_savings"] = {s: sum(f["savings"][s] for f in done) / len(done) for s in schemes}
    elif command == "omm":
        for k in ("triangles", "micro_triangles", "micromaps", "data_bytes"):
            t[k] = sum(f.get(k, 0) for f in done)
    elif command == "trace":
        t["passed"] = sum(bool(f.get("passed")) for f in done)
    return t


def _flat(f: dict) -> dict:
    out = {}
    for k, v in (f or {}).items():
        if isinstance(v, dict):
            out.update({f"{k}:{s}": x for s, x in v.items()})
        else:
            out[k] = v
    return out


def summary_csv(records: list[dict], tot: dict) -> str:
    rows = [{"input": r["input"], "output": r.get("output") or "", "status": r["status"],
             "error": r.get("error") or r.get("reason") or "", **_flat(r.get("figures"))} for r in records]
    total = {"input": "(total)", "output": "", "status": f"{tot['ok']} ok, {count(tot['problems'], 'problem')}, "
             f"{tot['skipped']} skipped, {count(tot['error'], 'error')}"
             + (f", {tot['unfinished']} unfinished" if tot.get("unfinished") else ""), "error": ""}
    kept = {("savings" if k == "mean_savings" else k): v for k, v in tot.items()
            if k in ("mean_savings", "triangles", "micro_triangles", "micromaps", "data_bytes", "passed")}
    total.update(_flat(kept))  # the eval row's savings columns hold the means
    cols = []
    for r in rows + [total]:
        cols += [c for c in r if c not in cols]
    buf = io.StringIO()
    w = csv.DictWriter(buf, cols, lineterminator="\n")
    w.writeheader()
    w.writerows(rows + [total])
    return buf.getvalue()


@dataclasses.dataclass
class BatchResult:
    """What ``run_batch`` did: per input its record (status ok / problems / skipped / error /
    unfinished, its figures or error, seconds), the totals, where the summary was written, and
    why the batch stopped before its end (``stopped``) or could not write its summary."""

    command: str
    records: list
    totals: dict
    summary_json: str | None
    summary_csv: str | None
    seconds: float
    stopped: str | None = None  # why the batch stopped before its end (its unfinished inputs: "unfinished")
    summary_error: str | None = None  # why the summary could not be written (then no summary file)

    @property
    def ok(self) -> bool:
        """Every input ran to its end, and none had an error or problems."""
        return not (self.totals["error"] or self.totals["problems"] or self.stopped or self.summary_error)

    @property
    def complete(self) -> bool:
        """The batch ran to its end and wrote its summary (else ``omaps batch`` exits 3: run the
        same command again to finish)."""
        return not (self.stopped or self.summary_error)

    def messages(self) -> list[str]:
        """Each input's error or problems, one line each, as ``omaps batch`` prints them."""
        out = []
        for r in self.records:
            if r["status"] == "error":
                out.append(f"omaps: error: {r['error']}")
            elif r["status"] == "problems":
                out.append(f"omaps: {r['input']}: done with problems: " + "; ".join(r.get("messages", [])))
        return out

    def line(self) -> str:
        """The closing line ``omaps batch`` prints (and the mean savings of an eval batch)."""
        t = self.totals
        where = (f"summary in {self.summary_json} and .csv" if self.summary_json else
                 f"no summary written ({self.summary_error})")
        text = (f"omaps batch {self.command}: {t['ok']} ok, {t['problems']} with problems, {t['skipped']} skipped, "
                f"{count(t['error'], 'error')}" + (f", {t['unfinished']} unfinished" if t.get("unfinished") else "")
                + f" ({t['resumed']} done before" + (f"; {t['retried']} run again" if t.get("retried") else "")
                + f"); {self.seconds:.2f} s; {where}")
        if self.command == "eval" and "mean_savings" in t:
            text += "\nmean savings: " + ", ".join(f"{s} {v:.3f}" for s, v in t["mean_savings"].items())
        return text


class BatchWarning(UserWarning):
    """An input's warnings (its record's messages), one per input as it finishes."""


def warn_input(rec: dict) -> None:
    """An input's warnings as one ``BatchWarning`` (the first, and how many more the summary
    holds): above a progress bar, which is drawn again below it. Its error, or the problems
    it was done with, are said after the run (``BatchResult.messages``)."""
    notes = [m for m in rec.get("messages", []) if not m.startswith("omaps: error:")]
    if not notes:
        return
    first = notes[0].removeprefix("omaps: warning: ").removeprefix("omaps: ")
    for named in (rec["input"], os.path.abspath(rec["input"])):  # (a scene's warnings name its file)
        first = first.removeprefix(f"{named}: ")
    more = f" (and {count(len(notes) - 1, 'more warning')} in the summary)" if len(notes) > 1 else ""
    from tqdm import tqdm

    with tqdm.external_write_mode(file=sys.stderr):
        warnings.warn(f"{rec['input']}: {first}{more}", BatchWarning, stacklevel=3)
