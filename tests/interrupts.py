"""Ctrl-C checks for tests that interrupt an ``omaps batch`` process: its child processes, and
what an interrupted batch must leave behind (one line, exit 130, no summary, no process)."""

import os
import time


def children(pid):
    """Every live descendant process of ``pid`` (none once it has ended)."""
    import psutil

    try:
        return psutil.Process(pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return []


def check_interrupted(p, out, interrupt):
    """Call ``interrupt()`` (it waits for its moment, then sends SIGINT) on the batch process ``p``
    (a ``subprocess.Popen`` with stderr piped): the batch prints ``omaps: interrupted`` alone,
    exits 130, writes no summary into ``out`` and leaves no process behind."""
    try:
        interrupt()
        err = p.communicate(timeout=60)[1].decode(errors="replace")
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130, err
    assert err == "omaps: interrupted\n", err
    assert not os.path.exists(os.path.join(out, "summary.json"))
    time.sleep(0.5)
    assert not children(p.pid)
