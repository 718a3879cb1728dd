"""The report's pages without a browser: the analysis page, the viewings table's columns read by
name (extra columns such as ``warnings`` kept and filterable), and ``--serve`` on loopback."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import urllib.request
from pathlib import Path

from simulator.report.pages import Site


def test_analysis_page(tmp_path):
    a = tmp_path / "analysis"
    a.mkdir()
    (a / "table.csv").write_text("measure,GR,NR,p\nssq_total,10.2,20.5,0.03\n")
    (a / "normality.csv").write_text("measure,W,p\nflow,0.95,0.4\n")
    (a / "boxplots.png").write_bytes(b"\x89PNG")
    (a / "report.md").write_text("K_OF = sum(flow) / <script>\n")
    site = Site({"outputs": {"analysis": {"error": None}}}, [], {})
    html = site.analysis_page(a)
    assert "<td>ssq_total</td><td>10.2</td>" in html and "<td>0.95</td>" in html
    assert 'src="media/analysis/boxplots.png"' in html
    assert "K_OF = sum(flow) / &lt;script&gt;" in html  # escaped
    assert "no [questionnaires]" in Site({"outputs": {}}, [], {}).analysis_page(a)
    err = Site({"outputs": {"analysis": {"error": "too few <rows>"}}}, [], {}).analysis_page(a)
    assert "too few &lt;rows&gt;" in err


def test_viewings_table_reads_columns_by_name():
    rows = [
        {"viewing": "a", "video": "v", "status": "ok", "condition": "GR", "warnings": "radians?"},
        {"viewing": "b", "video": "v", "status": "failed: x", "condition": "NR", "warnings": ""},
    ]
    html = Site({}, rows, {}).viewings_page()
    assert "<th>warnings</th>" in html and "radians?" in html
    assert 'data-filter="condition"' in html and 'data-filter="status"' in html
    assert 'data-filter-text="warnings"' in html
    assert 'href="viewing-a.html"' in html and 'href="video-v.html"' in html


def test_serve_prints_a_loopback_address_and_stops_on_sigint(tmp_path):
    out = tmp_path / "study"
    (out / "report").mkdir(parents=True)
    (out / "epof").mkdir()
    (out / "viewings.csv").write_text("viewing,video,status\n")
    (out / "study.json").write_text('{"format": "vimsim-study"}')
    (out / "report" / "index.html").write_text("<!DOCTYPE html><title>x</title>hello")
    exe = Path(sys.executable).with_name("vimsim")
    p = subprocess.Popen([str(exe), "report", str(out), "--serve", "--no-build"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        line = p.stdout.readline()
        assert "serving" in line and "http://127.0.0.1:" in line, line
        url = line.split(" at ", 1)[1].split()[0]
        with urllib.request.urlopen(url + "index.html", timeout=10) as r:
            assert b"hello" in r.read()
        req = urllib.request.Request(url + "index.html", headers={"Range": "bytes=22-26"})
        with urllib.request.urlopen(req, timeout=10) as r:
            assert r.status == 206 and r.read() == b"x</ti"
    finally:
        p.send_signal(signal.SIGINT)
        rc = p.wait(timeout=20)
    assert rc == 130, (rc, p.stderr.read())
    assert os.path.isfile(out / "report" / "index.html")


def test_stale_build_folders_of_dead_processes_are_removed(tmp_path):
    from simulator.report.build import _remove_stale

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp_path / f".report-tmp-{dead.pid}").mkdir()
    (tmp_path / f".report-old-{os.getpid()}").mkdir()  # a live process's: kept
    _remove_stale(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == [f".report-old-{os.getpid()}"]
