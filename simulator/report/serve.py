"""A loopback-only HTTP server for a report folder (``vimsim report OUTDIR --serve``), with byte ranges for video seeking."""

from __future__ import annotations

import functools
import http.server
import os
import re
import threading
import urllib.parse
from pathlib import Path
from typing import ClassVar

__all__ = ["ReportServer", "start_server"]

LOOPBACK = "127.0.0.1"
#: ``Host`` names answered (with no port or the bound one): loopback only, so a page of
#: another site whose name resolves to 127.0.0.1 (DNS rebinding) is refused (403).
LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "[::1]"})
_RANGE = re.compile(r"bytes=(\d*)-(\d*)$")


class _Handler(http.server.SimpleHTTPRequestHandler):
    """Static files of one folder; ``Range: bytes=a-b`` answered with 206 (browsers seek
    in a video by range requests); no directory listings; nothing logged. Only requests
    whose ``Host`` is a loopback name (with no port or the bound one) are answered (400
    without one, 403 for another); a path that is not UTF-8 or holds a NUL is 400; a file
    whose real path (symlinks resolved) lies outside the folder is 404."""

    extensions_map: ClassVar[dict[str, str]] = {**http.server.SimpleHTTPRequestHandler.extensions_map,
                      ".js": "text/javascript", ".mjs": "text/javascript", ".mp4": "video/mp4",
                      ".bin": "application/octet-stream", ".json": "application/json"}  # fmt: skip

    def log_message(self, format, *args):
        return

    def list_directory(self, path):
        self.send_error(404, "no listing")

    def _refusal(self) -> tuple[int, str] | None:
        """``(status, reason)`` when the request may not be answered, else None."""
        host = (self.headers.get("Host") or "").strip().lower()
        if not host:
            return 400, "Host header missing"
        port = str(self.server.server_address[1])
        name, _, p = host.rpartition(":") if not host.endswith("]") else (host, "", "")
        if not name or not re.fullmatch(r"\d+", p):
            name, p = host, ""
        if name not in LOOPBACK_NAMES or p not in ("", port):
            return 403, "Host not answered: open the report at the printed 127.0.0.1 address"
        raw = self.path.split("?", 1)[0].split("#", 1)[0]
        try:
            text = urllib.parse.unquote(raw, errors="strict")
        except UnicodeDecodeError:
            return 400, "path is not UTF-8"
        if "\x00" in text or not text.startswith("/"):
            return 400, "bad path"
        root = os.path.realpath(self.directory)
        path = self.translate_path(self.path)
        if os.path.isdir(path):
            path = os.path.join(path, "index.html")
        if os.path.lexists(path):
            real = os.path.realpath(path)
            if os.path.commonpath([root, real]) != root:
                return 404, "File not found"
        return None

    def send_head(self):
        refused = self._refusal()
        if refused is not None:
            self.send_error(*refused)
            return None
        rng = self.headers.get("Range")
        path = self.translate_path(self.path)
        if rng is None or not os.path.isfile(path):
            return super().send_head()
        m = _RANGE.match(rng.strip())
        size = os.path.getsize(path)
        if not m or (m.group(1) == "" and m.group(2) == ""):
            return super().send_head()
        if m.group(1) == "":
            start, end = max(0, size - int(m.group(2))), size - 1
        else:
            start = int(m.group(1))
            end = min(size - 1, int(m.group(2))) if m.group(2) else size - 1
        if start >= size or start > end:
            self.send_response(416)
            self.send_header("Content-Range", f"bytes */{size}")
            self.end_headers()
            return None
        f = open(path, "rb")  # noqa: SIM115 - closed by the base class's copyfile caller
        f.seek(start)
        self.send_response(206)
        self.send_header("Content-Type", self.guess_type(path))
        self.send_header("Content-Range", f"bytes {start}-{end}/{size}")
        self.send_header("Content-Length", str(end - start + 1))
        self.send_header("Accept-Ranges", "bytes")
        self.end_headers()
        self._remaining = end - start + 1
        return f

    def copyfile(self, source, outputfile):
        n = getattr(self, "_remaining", None)
        if n is None:
            return super().copyfile(source, outputfile)
        try:
            while n > 0:
                buf = source.read(min(n, 1 << 16))
                if not buf:
                    break
                outputfile.write(buf)
                n -= len(buf)
        except (ConnectionError, TimeoutError):  # the browser dropped a range it no longer needs
            pass
        return None

    def end_headers(self):
        self.send_header("Cache-Control", "no-store")
        super().end_headers()


class _Server(http.server.ThreadingHTTPServer):
    daemon_threads = True

    def handle_error(self, request, client_address):
        """A browser that drops a connection (seeking a video does) is not an error; any
        other failure of one request closes its connection without a traceback."""
        return


class ReportServer:
    """A running loopback server: ``url`` of the folder, :meth:`close` to stop."""

    def __init__(self, folder: str | os.PathLike, port: int = 0):
        handler = functools.partial(_Handler, directory=str(Path(folder)))
        self.httpd = _Server((LOOPBACK, int(port)), handler)
        self.url = f"http://{LOOPBACK}:{self.httpd.server_address[1]}/"
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)

    def start(self) -> ReportServer:
        self.thread.start()
        return self

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()


def start_server(folder: str | os.PathLike, port: int = 0) -> ReportServer:
    """Serve ``folder`` on 127.0.0.1 (``port`` 0: any free one) in a background thread."""
    return ReportServer(folder, port).start()
