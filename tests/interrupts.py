"""Ctrl-C checks for tests that interrupt an ``omaps batch`` process at a moment the test
chooses (an event, never a time): the batch's test-only gate (``omaps.batch.task.TEST_GATE``), its
child processes, and what an interrupted batch must leave behind (one line, exit 130, no summary,
no process)."""

import os
import signal
import time

from omaps.batch.task import TEST_GATE

LIMIT = 900  # seconds: a hang guard only (a wait that never ends fails instead of hanging)


def children(pid):
    """Every live descendant process of ``pid`` (none once it has ended)."""
    import psutil

    try:
        return psutil.Process(pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return []


def gate_env(env, folder):
    """``env`` with the batch's test-only gate on ``folder`` (created): every input task (not
    split) and every piece task waits at its start for ``release`` or ``release-…`` there
    (``release``), saying so with a file ``held-input-NAME`` / ``held-piece-…`` (``held``)."""
    os.makedirs(folder, exist_ok=True)
    return dict(env, **{TEST_GATE: os.fspath(folder)})


def held(folder, kind=""):
    """The names (``input-NAME``, ``piece-…``) of the tasks that the gate holds or held, ``kind``
    their prefix."""
    return sorted(f[len("held-"):] for f in os.listdir(folder) if f.startswith("held-" + kind))


def release(folder, what=""):
    """Let the gated task ``what`` go on (all of them: ``what`` empty)."""
    with open(os.path.join(folder, "release-" + what if what else "release"), "w"):
        pass


def went_on_unreleased(folder):
    """The gated tasks that went past the gate (``passed-…``) though the test never released
    them: none, while the gate holds."""
    return sorted(f[len("passed-"):] for f in os.listdir(folder) if f.startswith("passed-") and not
                  os.path.exists(os.path.join(folder, "release-" + f[len("passed-"):])))


def wait_for(cond, what, p, limit=LIMIT):
    """Wait until ``cond()`` holds, while the process ``p`` runs: the batch ending first (it
    cannot, gated) or the hang guard failing are errors naming ``what``."""
    deadline = time.monotonic() + limit
    while not cond():
        assert p.poll() is None, f"the batch ended before {what}"
        assert time.monotonic() < deadline, f"no {what} in {limit} s (hang guard)"
        time.sleep(0.01)


def _session(pid):
    """Live processes (zombies aside) of the session ``pid`` leads (``start_new_session``)."""
    import psutil

    found = []
    for proc in psutil.process_iter(["status"]):
        try:
            if proc.pid != pid and os.getsid(proc.pid) == pid and proc.info["status"] != psutil.STATUS_ZOMBIE:
                found.append(proc)
        except (OSError, psutil.Error):
            pass
    return found


def check_interrupted(p, out, wait, group=True, gate=None):
    """Call ``wait()`` (it returns at the moment the test chose), then send SIGINT to the batch
    process ``p`` (a ``subprocess.Popen`` with stderr piped): to its process group (``group``, as
    a terminal's Ctrl-C; ``p`` started with ``start_new_session``) or to it alone. The batch prints
    ``omaps: interrupted`` alone, exits 130, writes no summary into ``out`` and leaves no process
    behind: every process it had when the signal went, and (``group``) every process of its
    session, ends (within the hang guard: the exit handlers of a process take a moment). ``gate``:
    the gate's folder: no task the test held went on (the signal came while they were held), and
    they are all released once the check is over, whatever its outcome."""
    import psutil

    kids = []
    try:
        wait()
        kids = children(p.pid)
        if group:
            os.killpg(p.pid, signal.SIGINT)
        else:
            p.send_signal(signal.SIGINT)
        err = p.communicate(timeout=LIMIT)[1].decode(errors="replace")
        assert p.returncode == 130, err
        assert err == "omaps: interrupted\n", err
        assert not os.path.exists(os.path.join(out, "summary.json"))
        if gate is not None:
            assert not went_on_unreleased(gate), went_on_unreleased(gate)
        _, alive = psutil.wait_procs(kids, timeout=LIMIT)
        assert not alive, alive
        if group:
            deadline = time.monotonic() + LIMIT
            while _session(p.pid):
                assert time.monotonic() < deadline, _session(p.pid)
                time.sleep(0.05)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
        if group:
            for proc in _session(p.pid):
                proc.kill()
        for proc in kids:
            try:
                proc.kill()
            except psutil.Error:
                pass
        if gate is not None:
            release(gate)
