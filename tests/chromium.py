"""Headless Chromium for tests: find it (or install Debian's package), drive it over CDP.

``find_chromium()`` returns the browser's path, installing Debian's ``chromium`` with apt-get
when it is missing and the tests run as root (CI does); None where it cannot be had.
``Browser`` starts it headless — WebGL through SwiftShader, no network of its own, a fresh
profile — and speaks the DevTools protocol over ``--remote-debugging-pipe`` (NUL-separated JSON
on file descriptors 3 and 4), so no websocket library is needed. ``Browser.canvas_png(url)``
opens a page, waits for ``window.bakerViewReady`` and returns the canvas as PNG bytes;
``Browser.page_png`` the whole window (docs/make_images.py).
"""

from __future__ import annotations

import base64
import fcntl
import json
import os
import shutil
import subprocess
import tempfile
import time

from machine_lock import machine_lock

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--remote-debugging-pipe")
_PACKAGE = "chromium"


def find_chromium() -> str | None:
    """The path of a Chromium, installing Debian's package when missing and possible.

    The suite's workers (``pytest -n``) may all want it at once: one installs while the others
    wait on a lock file, then find it installed; apt-get itself waits up to 10 minutes for
    dpkg's lock, which any other apt run may hold."""
    if path := _installed():
        return path
    if os.geteuid() != 0 or shutil.which("apt-get") is None:
        return None
    with machine_lock("chromium"):
        if path := _installed():  # another worker installed it while this one waited
            return path
        env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
        apt = ["apt-get", "-o", "DPkg::Lock::Timeout=600"]
        install = [*apt, "install", "-y", "--no-install-recommends", _PACKAGE]
        if subprocess.run(install, env=env, capture_output=True).returncode != 0:
            subprocess.run([*apt, "update"], env=env, capture_output=True)
            subprocess.run(install, env=env, capture_output=True)
        return _installed()


def _installed() -> str | None:
    """The path of the Chromium on PATH, None when there is none."""
    return next(filter(None, map(shutil.which, ("chromium", "chromium-browser"))), None)


class Browser:
    """One headless Chromium, driven over the DevTools pipe. Use as a context manager."""

    def __init__(self, executable: str):
        self.profile = tempfile.mkdtemp(prefix="baker-chromium-")
        commands, self._to_browser = os.pipe()
        self._from_browser, replies = os.pipe()

        def wire() -> None:  # in the child: the pipe ends Chromium expects on fds 3 and 4
            # (copied above 10 first: a pipe end may itself be fd 3 or 4, and dup2 onto itself
            # would keep it close-on-exec)
            ends = [fcntl.fcntl(end, fcntl.F_DUPFD, 10) for end in (commands, replies)]
            os.dup2(ends[0], 3)
            os.dup2(ends[1], 4)

        self.process = subprocess.Popen(
            [executable, *FLAGS, f"--user-data-dir={self.profile}", "about:blank"],
            preexec_fn=wire, close_fds=False, stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(commands)
        os.close(replies)
        self._buffer = b""
        self._id = 0

    def __enter__(self) -> "Browser":
        return self

    def __exit__(self, *exc) -> None:
        self.process.kill()
        self.process.wait()
        os.close(self._to_browser)
        os.close(self._from_browser)
        shutil.rmtree(self.profile, ignore_errors=True)

    def send(self, method: str, params: dict | None = None, session: str | None = None) -> dict:
        """Send one CDP command and return its result (events in between are dropped)."""
        self._id += 1
        message = {"id": self._id, "method": method, "params": params or {}}
        if session:
            message["sessionId"] = session
        os.write(self._to_browser, json.dumps(message).encode() + b"\0")
        while True:
            while b"\0" not in self._buffer:
                chunk = os.read(self._from_browser, 1 << 20)
                if not chunk:
                    raise RuntimeError("Chromium closed the DevTools pipe")
                self._buffer += chunk
            line, self._buffer = self._buffer.split(b"\0", 1)
            reply = json.loads(line)
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply["result"]

    def evaluate(self, session: str, expression: str):
        result = self.send("Runtime.evaluate", {"expression": expression, "returnByValue": True},
                           session)
        return result["result"].get("value")

    def canvas_png(self, url: str, script: str = "", timeout: float = 30.0) -> bytes:
        """Open ``url``, wait until the page sets ``window.bakerViewReady``, run ``script``
        (then wait for two animation frames, which redraw), and return its ``#view`` canvas as
        PNG bytes; RuntimeError with the page's error if it reports one."""
        target, session = self._open(url, timeout)
        try:
            if script:
                self.send("Runtime.evaluate", {
                    "expression": f"{script}; new Promise(done => requestAnimationFrame(() => "
                                  "requestAnimationFrame(done)))", "awaitPromise": True},
                    session)
            data = self.evaluate(session, "document.getElementById('view').toDataURL('image/png')")
            return base64.b64decode(data.split(",", 1)[1])
        finally:
            self.send("Target.closeTarget", {"targetId": target})

    def page_png(self, url: str, width: int, height: int, timeout: float = 30.0) -> bytes:
        """The whole page at ``url`` (toolbar and all) in a ``width`` × ``height`` window, once
        ready, as PNG bytes."""
        target, session = self._open("about:blank", timeout, wait=False)
        try:
            self.send("Emulation.setDeviceMetricsOverride", {
                "width": width, "height": height, "deviceScaleFactor": 1, "mobile": False},
                session)
            self.send("Page.navigate", {"url": url}, session)
            self._wait_ready(session, timeout)
            data = self.send("Page.captureScreenshot", {"format": "png"}, session)["data"]
            return base64.b64decode(data)
        finally:
            self.send("Target.closeTarget", {"targetId": target})

    def _open(self, url: str, timeout: float, wait: bool = True) -> tuple[str, str]:
        """A new tab at ``url`` and its session, once the page is ready (``wait``)."""
        target = self.send("Target.createTarget", {"url": url})["targetId"]
        session = self.send("Target.attachToTarget", {"targetId": target,
                                                      "flatten": True})["sessionId"]
        if wait:
            try:
                self._wait_ready(session, timeout)
            except Exception:
                self.send("Target.closeTarget", {"targetId": target})
                raise
        return target, session

    def _wait_ready(self, session: str, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while True:
            state = self.evaluate(session, "window.bakerViewReady === true ? 'ready' : "
                                           "(window.bakerViewError || '')")
            if state == "ready":
                return
            if state or time.monotonic() > deadline:
                raise RuntimeError(f"the page did not render: {state or 'timed out'}")
            time.sleep(0.05)
