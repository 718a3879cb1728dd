"""The report server answers only loopback ``Host`` names, only files really inside its
folder (symlinks resolved), and malformed requests with 400, never a traceback."""

from __future__ import annotations

import http.client
import os

import pytest

from simulator.report.serve import start_server


@pytest.fixture
def served(tmp_path):
    root = tmp_path / "report"
    root.mkdir()
    (root / "index.html").write_text("<p>report</p>")
    (tmp_path / "secret.txt").write_text("participants")
    os.symlink(tmp_path / "secret.txt", root / "link.txt")
    (root / "sub").mkdir()
    os.symlink(tmp_path, root / "up")
    srv = start_server(root)
    try:
        yield srv.httpd.server_address[1]
    finally:
        srv.close()


def _get(port: int, path: str, host: str | None = "default") -> tuple[int, bytes]:
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
    c.putrequest("GET", path, skip_host=True)
    if host == "default":
        host = f"127.0.0.1:{port}"
    if host is not None:
        c.putheader("Host", host)
    c.endheaders()
    r = c.getresponse()
    body = r.read()
    c.close()
    return r.status, body


def test_loopback_hosts_are_answered(served):
    port = served
    for host in (f"127.0.0.1:{port}", f"localhost:{port}", "localhost", f"[::1]:{port}"):
        status, body = _get(port, "/", host)
        assert status == 200 and b"report" in body, host


@pytest.mark.parametrize("host", ["evil.example", "evil.example:{port}", "localhost:1",
                                  "127.0.0.2:{port}", None])  # fmt: skip
def test_other_hosts_are_refused(served, host):
    status, body = _get(served, "/index.html", host if host is None else host.format(port=served))
    assert status in (400, 403) and b"<p>report</p>" not in body


@pytest.mark.parametrize("path", ["/link.txt", "/up/secret.txt", "/up/"])
def test_symlinks_out_of_the_folder_are_404(served, path):
    status, body = _get(served, path)
    assert status == 404 and b"participants" not in body


@pytest.mark.parametrize("path", ["/%00", "/index.html%00.png", "/%ff%fe", "/sub/%c3%28"])
def test_malformed_paths_are_400_without_traceback(served, path, capfd):
    status, _ = _get(served, path)
    assert status == 400
    assert "Traceback" not in capfd.readouterr().err
