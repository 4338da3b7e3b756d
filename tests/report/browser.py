"""A headless Chromium driven over the DevTools protocol (``--remote-debugging-pipe``), for the page tests.

No client library: the protocol's JSON messages, each ended by a NUL byte, go to the browser on file
descriptor 3 and come back on 4. The viewport is set with ``Emulation.setDeviceMetricsOverride`` (the
window of headless Chromium is at least 500 px wide, so ``--window-size=400,...`` does not give 400 px).
"""
from __future__ import annotations

import base64
import json
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

CHROMIUM = ("/usr/bin/chromium", "chromium", "chromium-browser")


def find_chromium() -> str | None:
    """The Chromium executable, or None."""
    for name in CHROMIUM:
        path = shutil.which(name)
        if path:
            return path
    return None


class Browser:
    """One headless Chromium; ``page(url, width)`` loads a page at that viewport width."""

    def __init__(self, executable: str, timeout: float = 60.0) -> None:
        self.timeout = timeout
        self._profile = tempfile.TemporaryDirectory()
        to_browser_r, self._to_browser = os.pipe()
        self._from_browser, from_browser_w = os.pipe()
        # the child reads commands on fd 3 and writes answers on fd 4
        self.proc = subprocess.Popen(
            [executable, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
             "--remote-debugging-pipe", f"--user-data-dir={self._profile.name}", "about:blank"],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            pass_fds=(3, 4, to_browser_r, from_browser_w),  # 3, 4: kept open after preexec_fn's dup2
            preexec_fn=lambda: (os.dup2(to_browser_r, 3), os.dup2(from_browser_w, 4)))
        os.close(to_browser_r)
        os.close(from_browser_w)
        self._buffer = b""
        self._id = 0

    def send(self, method: str, params: dict | None = None, session: str | None = None) -> dict:
        """Send one command and return its result (events received meanwhile are dropped)."""
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self._to_browser, json.dumps(msg).encode() + b"\0")
        return self._wait(lambda m: m.get("id") == self._id)

    def _wait(self, match) -> dict:  # noqa: ANN001
        deadline = time.monotonic() + self.timeout
        while True:
            while b"\0" in self._buffer:
                raw, self._buffer = self._buffer.split(b"\0", 1)
                msg = json.loads(raw)
                if match(msg):
                    if "error" in msg:
                        raise RuntimeError(f"chromium: {msg['error']}")
                    return msg.get("result", msg.get("params", {}))
            if time.monotonic() > deadline:
                raise TimeoutError("chromium did not answer")
            chunk = os.read(self._from_browser, 1 << 20)
            if not chunk:
                raise RuntimeError("chromium closed the pipe")
            self._buffer += chunk

    def page(self, path: Path, width: int, height: int = 900, full: bool = True) -> dict:
        """Load ``path`` at a viewport of ``width`` x ``height`` CSS px.

        Returns ``{"scroll_width", "inner_width", "png", "eval"}``: the document's scroll width and the viewport
        width [CSS px], a screenshot (PNG bytes: the whole page with ``full``, else the viewport; a report
        page's whole length is ~0.25 s of Chromium's CPU to paint and encode, ~40 % of its load) and a
        function evaluating JavaScript in the page.
        """
        target = self.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = self.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        self.send("Emulation.setDeviceMetricsOverride",
                  {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False}, session)
        self.send("Page.enable", {}, session)
        self.send("Page.navigate", {"url": Path(path).resolve().as_uri()}, session)
        self._wait(lambda m: m.get("method") == "Page.loadEventFired" and m.get("sessionId") == session)

        def evaluate(expression: str):  # noqa: ANN202
            return self.send("Runtime.evaluate", {"expression": expression, "returnByValue": True},
                             session)["result"].get("value")

        scroll, inner = evaluate("[document.documentElement.scrollWidth, window.innerWidth]")
        if full:
            tall = evaluate("document.documentElement.scrollHeight")
            shot = self.send("Page.captureScreenshot", {"format": "png", "captureBeyondViewport": True,
                                                        "clip": {"x": 0, "y": 0, "width": width, "height": tall,
                                                                 "scale": 1}}, session)
        else:
            shot = self.send("Page.captureScreenshot", {"format": "png"}, session)
        return {"scroll_width": scroll, "inner_width": inner, "png": base64.b64decode(shot["data"]),
                "eval": evaluate}

    def close(self) -> None:
        try:
            self.send("Browser.close")
        except (RuntimeError, TimeoutError, OSError):
            pass
        try:
            self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        os.close(self._to_browser)
        os.close(self._from_browser)
        self._profile.cleanup()
