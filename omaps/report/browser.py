"""Open a report in headless Chromium and look at it: a small DevTools-protocol client over
``--remote-debugging-pipe`` (no extra package). WebGL runs on the CPU through SwiftShader, so it
works on a machine without a GPU. Used by the tests and by ``docs/scripts`` for screenshots.

Example::

    >>> from omaps.report.browser import find_chromium, open_page                 # doctest: +SKIP
    >>> with open_page(find_chromium(), "report.html") as p:                       # doctest: +SKIP
    ...     p.wait("window.omapsReport && window.omapsReport.ready")
    ...     png = p.screenshot()
    ...     p.console_errors(), p.requests
"""

from __future__ import annotations

import base64
import contextlib
import json
import os
import pathlib
import shutil
import signal
import subprocess
import tempfile
import time

__all__ = ["find_chromium", "open_page", "Page", "CHROMIUM_FLAGS"]

CHROMIUM_FLAGS = ("--headless=new", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--no-sandbox",
                  "--disable-gpu-sandbox", "--no-first-run", "--no-default-browser-check", "--disable-extensions",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--mute-audio", "--hide-scrollbars", "--remote-debugging-pipe")


def find_chromium() -> str | None:
    """The path of a Chromium or Chrome on PATH (``OMAPS_CHROMIUM`` first), or None."""
    env = os.environ.get("OMAPS_CHROMIUM")
    if env:
        return shutil.which(env) or (env if os.path.isfile(env) else None)
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


class Page:
    """One page in a headless browser, driven through the DevTools protocol.

    Attributes
    ----------
    console : list of (str, str)
        Console messages (type, text) and uncaught exceptions ("exception", text).
    log : list of (str, str)
        The browser's log entries (level, text): failed loads, blocked requests.
    requests : list of str
        Every URL the page requested.
    """

    def __init__(self, proc, rfile, wfile, width: int, height: int):
        self.proc, self._r, self._w = proc, rfile, wfile
        self._id = 0
        self._buf = b""
        self.console: list = []
        self.log: list = []
        self.requests: list = []
        self.session = None
        target = self.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        self.session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        for domain in ("Runtime", "Log", "Network", "Page"):
            self.call(f"{domain}.enable")
        self.call("Emulation.setDeviceMetricsOverride",
                  {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False})

    def _send(self, msg: dict) -> None:
        self._w.write(json.dumps(msg).encode() + b"\0")
        self._w.flush()

    def _next(self, timeout: float) -> dict:
        end = time.monotonic() + timeout
        while b"\0" not in self._buf:
            if time.monotonic() > end:
                raise TimeoutError("the browser did not answer")
            chunk = os.read(self._r.fileno(), 1 << 20)
            if not chunk:
                raise RuntimeError("the browser closed its pipe")
            self._buf += chunk
        raw, self._buf = self._buf.split(b"\0", 1)
        msg = json.loads(raw)
        self._event(msg)
        return msg

    def _event(self, msg: dict) -> None:
        m, p = msg.get("method"), msg.get("params", {})
        if m == "Runtime.consoleAPICalled":
            text = " ".join(str(a.get("value", a.get("description", ""))) for a in p.get("args", []))
            self.console.append((p.get("type"), text))
        elif m == "Runtime.exceptionThrown":
            d = p.get("exceptionDetails", {})
            self.console.append(("exception", d.get("exception", {}).get("description") or d.get("text")))
        elif m == "Log.entryAdded":
            e = p.get("entry", {})
            self.log.append((e.get("level"), e.get("text")))
        elif m == "Network.requestWillBeSent":
            self.requests.append(p.get("request", {}).get("url"))

    def call(self, method: str, params: dict | None = None, timeout: float = 60.0) -> dict:
        """Send a command (to the page once attached) and return its result."""
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params or {}}
        if self.session:
            msg["sessionId"] = self.session
        self._send(msg)
        while True:
            r = self._next(timeout)
            if r.get("id") == self._id:
                if "error" in r:
                    raise RuntimeError(f"{method}: {r['error'].get('message')}")
                return r.get("result", {})

    def goto(self, url: str) -> None:
        self.call("Page.navigate", {"url": url})

    def evaluate(self, expression: str, timeout: float = 60.0):
        """A JavaScript expression's value (JSON-able; promises awaited)."""
        r = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True, "awaitPromise": True},
                      timeout)
        if "exceptionDetails" in r:
            raise RuntimeError(f"{expression}: {r['exceptionDetails'].get('text')}")
        return r["result"].get("value")

    def wait(self, expression: str, timeout: float = 120.0) -> None:
        """Poll until ``expression`` is true."""
        end = time.monotonic() + timeout
        while not self.evaluate(f"!!({expression})"):
            if time.monotonic() > end:
                raise TimeoutError(f"waited {timeout:g} s for {expression}")
            time.sleep(0.2)

    def screenshot(self, clip: dict | None = None) -> bytes:
        """A PNG of the viewport (or of ``clip``: x, y, width, height in CSS pixels)."""
        params = {"format": "png"}
        if clip:
            params["clip"] = {**clip, "scale": 1}
        return base64.b64decode(self.call("Page.captureScreenshot", params)["data"])

    def console_errors(self) -> list:
        """Console errors and uncaught exceptions."""
        return [(k, t) for k, t in self.console if k in ("error", "exception", "assert")]


@contextlib.contextmanager
def open_page(chromium: str, path, width: int = 1280, height: int = 1000, flags=()):
    """A ``Page`` with the file ``path`` opened (file:// URL) in headless ``chromium``."""
    url = pathlib.Path(path).resolve().as_uri()
    profile = tempfile.mkdtemp(prefix="omaps-chromium-")
    try:
        to_child_r, to_child_w = os.pipe()
        from_child_r, from_child_w = os.pipe()

        def fds():  # the protocol's pipe: the browser reads fd 3, writes fd 4
            import fcntl

            a = fcntl.fcntl(to_child_r, fcntl.F_DUPFD_CLOEXEC, 10)  # (out of the way of 3 and 4 first)
            b = fcntl.fcntl(from_child_w, fcntl.F_DUPFD_CLOEXEC, 10)
            os.dup2(a, 3)
            os.dup2(b, 4)

        proc = subprocess.Popen([chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                                 f"--window-size={width},{height}", *flags, "about:blank"],
                                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                preexec_fn=fds, close_fds=False,  # (fds 3 and 4 stay open; the rest are close-on-exec)
                                process_group=0)  # the browser's helper processes with it: stopped together
        os.close(to_child_r)
        os.close(from_child_w)
        w = os.fdopen(to_child_w, "wb")
        r = os.fdopen(from_child_r, "rb")
        try:
            page = Page(proc, r, w, width, height)
            page.goto(url)
            yield page
        finally:
            with contextlib.suppress(Exception):
                w.close()
            _signal_group(proc.pid, signal.SIGTERM)
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                pass
            _signal_group(proc.pid, signal.SIGKILL)  # helper processes that outlived the browser
            proc.wait()
            r.close()
    finally:
        remove_tree(profile)


def _signal_group(pgid: int, sig) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pgid, sig)


def remove_tree(path, patience: float = 10.0) -> None:
    """Remove a folder that processes may still be writing into as they stop (a browser's profile:
    its helper processes flush files after the browser exits), trying again for ``patience``
    seconds; what is left after that stays (a temporary folder is not worth failing for)."""
    end = time.monotonic() + patience
    while True:
        try:
            shutil.rmtree(path)
            return
        except FileNotFoundError:
            return
        except OSError:
            if time.monotonic() > end:
                shutil.rmtree(path, ignore_errors=True)
                return
            time.sleep(0.1)
