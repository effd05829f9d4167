"""Headless Chromium driven over the DevTools protocol (websocket-client), for the HTML report tests.

Chromium is Debian's package (``tests/run``, the README's test command, installs it and sets
``CAMPAIGN_TESTS_BROWSER=required``: a browser test then fails without it, never skips); the browser gets a new
empty profile, no network features, and is killed by its own process id when the page is done.
"""
from __future__ import annotations

import base64
import json
import os
import shutil
import subprocess
import time
import urllib.request
from dataclasses import dataclass
from pathlib import Path

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync")


def chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


def skip_without_browser() -> bool:
    """Skip a browser test: Chromium is missing and the run does not require it (``tests/run`` does)."""
    return chromium() is None and os.environ.get("CAMPAIGN_TESTS_BROWSER") != "required"


@dataclass
class PageResult:
    errors: list          # console errors, uncaught exceptions, failed loads
    images: list          # [{alt, complete, width, height}]
    numbers: list         # [{doc, key, value, text, fmt, scale}]
    text: str             # document.body.innerText
    figures: int          # <figure> elements


class Chromium:
    """One headless browser with a fresh profile; ``load(url)`` -> PageResult, ``screenshot(path)``."""

    def __init__(self, profile_dir: Path, timeout_s: float = 60.0):
        import websocket  # websocket-client

        exe = chromium()
        if exe is None:
            raise RuntimeError("chromium is not installed (apt-get install chromium)")
        profile_dir.mkdir(parents=True, exist_ok=True)
        self.proc = subprocess.Popen([exe, *FLAGS, f"--user-data-dir={profile_dir}", "--remote-debugging-port=0",
                                      "--window-size=1300,1000", "about:blank"],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        port_file = profile_dir / "DevToolsActivePort"
        deadline = time.monotonic() + timeout_s
        while not port_file.exists() or not port_file.read_text().strip():
            if time.monotonic() > deadline or self.proc.poll() is not None:
                self.close()
                raise RuntimeError("chromium did not open its DevTools port")
            time.sleep(0.1)
        port = int(port_file.read_text().split()[0])
        pages = []
        while not pages:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as r:
                pages = [p for p in json.load(r) if p.get("type") == "page"]
            if time.monotonic() > deadline:
                self.close()
                raise RuntimeError("chromium shows no page target")
        self.ws = websocket.create_connection(pages[0]["webSocketDebuggerUrl"], timeout=timeout_s,
                                              suppress_origin=True)
        self.next_id = 0
        self.events: list[dict] = []
        for domain in ("Page", "Runtime", "Log"):
            self.call(f"{domain}.enable")

    def call(self, method: str, **params) -> dict:
        self.next_id += 1
        my = self.next_id
        self.ws.send(json.dumps({"id": my, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == my:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})
            self.events.append(msg)

    def _wait_event(self, name: str, timeout_s: float = 60.0) -> None:
        deadline = time.monotonic() + timeout_s
        while not any(e.get("method") == name for e in self.events):
            if time.monotonic() > deadline:
                raise RuntimeError(f"no {name} within {timeout_s} s")
            self.events.append(json.loads(self.ws.recv()))

    def evaluate(self, expression: str):
        r = self.call("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        if "exceptionDetails" in r:
            raise RuntimeError(f"page script failed: {r['exceptionDetails']}")
        return r["result"].get("value")

    def load(self, url: str) -> PageResult:
        self.events.clear()
        self.call("Page.navigate", url=url)
        self._wait_event("Page.loadEventFired")
        # every <img> decoded (decode() rejects on a broken image)
        images = self.evaluate("""Promise.all([...document.images].map(i => i.decode().then(
              () => ({alt: i.alt, complete: i.complete, width: i.naturalWidth, height: i.naturalHeight}),
              e => ({alt: i.alt, complete: false, width: 0, height: 0, error: String(e)}))))""")
        numbers = self.evaluate("""[...document.querySelectorAll('[data-key]')].map(e => ({doc: e.dataset.doc,
              key: e.dataset.key, value: e.dataset.value, text: e.textContent, fmt: e.dataset.fmt || null,
              scale: e.dataset.scale || null}))""")
        text = self.evaluate("document.body.innerText")
        figures = self.evaluate("document.querySelectorAll('figure').length")
        errors = []
        for e in self.events:
            m, p = e.get("method"), e.get("params", {})
            if m == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
                errors.append(("console", p))
            elif m == "Runtime.exceptionThrown":
                errors.append(("exception", p))
            elif m == "Log.entryAdded" and p.get("entry", {}).get("level") == "error":
                errors.append(("log", p["entry"]))
        return PageResult(errors, images, numbers, text, figures)

    def screenshot(self, path: Path) -> tuple[int, int]:
        """Full-page PNG; returns its (width, height) in CSS pixels."""
        w, h = self.evaluate("[document.documentElement.scrollWidth, document.documentElement.scrollHeight]")
        self.call("Emulation.setDeviceMetricsOverride", width=int(w), height=int(h), deviceScaleFactor=1, mobile=False)
        data = self.call("Page.captureScreenshot", format="png", captureBeyondViewport=True)["data"]
        path.write_bytes(base64.b64decode(data))
        return int(w), int(h)

    def close(self) -> None:
        try:
            if getattr(self, "ws", None) is not None:
                self.ws.close()
        finally:
            if self.proc.poll() is None:
                self.proc.terminate()
                try:
                    self.proc.wait(10)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait(10)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
