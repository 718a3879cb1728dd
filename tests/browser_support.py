"""Headless Chromium for the ``browser`` tests: Debian's chromium and chromedriver driven by Selenium, a loopback server.

WebGL stays on (SwiftShader through ANGLE, no GPU); nothing is downloaded (the binaries are
given explicitly, so Selenium Manager never runs); a fresh profile per session; the
browser's console and network events are read from its logs.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path

CHROMIUM = "/usr/bin/chromium"

#: The report replay's canvas after a seek to each time (Browser.replay_at).
_REPLAY_AT = """
const [times] = args;
for (let i = 0; i < 600 && !(window.vimsimReplay && window.vimsimReplay.ready); i++)
  await new Promise((r) => setTimeout(r, 50));
const out = [];
for (const t of times) {
  await window.vimsimReplay.seek(t);
  out.push(window.vimsimReplay.canvas.toDataURL('image/png'));
}
return out;
"""


def data_url_image(url: str):
    """``(h, w, 3)`` uint8 RGB of a ``data:image/png;base64,...`` URL (a canvas's
    ``toDataURL``)."""
    import base64
    import io

    import numpy as np
    from PIL import Image

    raw = base64.b64decode(url.split(",", 1)[1])
    return np.asarray(Image.open(io.BytesIO(raw)).convert("RGB"))
CHROMEDRIVER = "/usr/bin/chromedriver"

FLAGS = (
    "--headless=new",
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-dev-shm-usage",
    "--autoplay-policy=no-user-gesture-required",
    "--window-size=1400,1000",
)


def available() -> str | None:
    """None when the browser can run here, else why not (one line)."""
    for p in (CHROMIUM, CHROMEDRIVER):
        if not Path(p).is_file():
            return f"{p} is missing (make test installs Debian's chromium and chromium-driver)"
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium is not installed (pip install -e '.[dev]')"
    return None


class Browser:
    """One headless Chromium session (Selenium), with its console and network logs."""

    def __init__(self):
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service

        self.profile = tempfile.mkdtemp(prefix="vimsim-chromium-")
        opts = webdriver.ChromeOptions()
        opts.binary_location = CHROMIUM
        for f in FLAGS:
            opts.add_argument(f)
        opts.add_argument(f"--user-data-dir={self.profile}")
        opts.set_capability("goog:loggingPrefs", {"browser": "ALL", "performance": "ALL"})
        self.driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
        self.driver.set_script_timeout(120)

    def get(self, url: str) -> None:
        self.drain()
        self.driver.get(url)

    def drain(self) -> tuple[list[dict], list[str]]:
        """Console entries and requested URLs since the last call."""
        console = self.driver.get_log("browser")
        urls = []
        for e in self.driver.get_log("performance"):
            m = json.loads(e["message"])["message"]
            if m.get("method") == "Network.requestWillBeSent":
                urls.append(m["params"]["request"]["url"])
        return console, urls

    def run_async(self, script: str, *args):
        """Run an async function body (``args`` as ``arguments``; return a value) in the page."""
        body = (
            "const done = arguments[arguments.length - 1];"
            "(async (...args) => {" + script + "})(...Array.from(arguments).slice(0, -1))"
            ".then(done, (e) => done({__error: String(e && e.stack || e)}));"
        )
        out = self.driver.execute_async_script(body, *args)
        if isinstance(out, dict) and "__error" in out:
            raise AssertionError(out["__error"])
        return out

    def run_served(self, folder, page: str, script: str, *args):
        """Serve ``folder`` on loopback, open ``page`` from it and :meth:`run_async` ``script``
        there; the server is stopped on every exit."""
        from simulator.report.serve import start_server

        srv = start_server(folder)
        try:
            self.get(srv.url + page)
            return self.run_async(script, *args)
        finally:
            srv.close()

    def replay_at(self, report, page: str, times) -> list:
        """The report's replay (``report`` served on loopback, ``page`` a viewing page) after
        a seek to each of ``times`` (seconds): its canvas as ``(h, w, 3)`` uint8 RGB each."""
        got = self.run_served(report, page, _REPLAY_AT, list(times))
        return [data_url_image(u) for u in got]

    def gl_renderer(self) -> str:
        return self.driver.execute_script(
            "const gl = document.createElement('canvas').getContext('webgl2');"
            "if (!gl) return 'no WebGL2';"
            "const e = gl.getExtension('WEBGL_debug_renderer_info');"
            "return e ? gl.getParameter(e.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);"
        )

    def close(self) -> None:
        try:
            self.driver.quit()
        finally:
            shutil.rmtree(self.profile, ignore_errors=True)
