"""The report's pages without a browser: the analysis page, the viewings table's columns read by
name (extra columns such as ``warnings`` kept and filterable), and ``--serve`` on loopback."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import urllib.request
from pathlib import Path

import pytest

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


def _clip(path: Path, size: str, codec: list[str], frames: int = 3) -> Path:
    import imageio_ffmpeg

    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-f", "lavfi", "-i",
                    f"testsrc2=size={size}:rate=10", "-frames:v", str(frames), *codec, str(path)],
                   check=True)  # fmt: skip
    return path


def test_browser_copy_kinds(tmp_path):
    """The browser copy: a copy of an H.264 MP4, a stream copy of H.264 in another container,
    a re-encoding otherwise (another codec; one eye of a stereo video; wider than the
    browser width, 2048 by default)."""
    import av

    from simulator.report.build import browser_copy

    def info(p):
        with av.open(str(p)) as c:
            s = c.streams.video[0]
            return s.codec_context.name, s.codec_context.pix_fmt, s.width, s.height, s.frames

    h264 = ["-c:v", "libx264", "-pix_fmt", "yuv420p"]
    cases = [
        (_clip(tmp_path / "a.mp4", "128x64", h264), "mono", "copy of the source", (128, 64)),
        (_clip(tmp_path / "b.mkv", "128x64", h264), "mono", "stream copy", (128, 64)),
        (_clip(tmp_path / "c.avi", "128x64", ["-c:v", "mpeg4"]), "mono", "re-encoded", (128, 64)),
        (_clip(tmp_path / "d.mp4", "128x128", h264), "top-bottom", "re-encoded", (128, 64)),
        # wider than the default browser width (2048): scaled down to it
        (_clip(tmp_path / "e.mp4", "2560x1280", h264, 1), "mono", "re-encoded", (2048, 1024)),
        # ... unless a width is asked for: then the source as it is
        (tmp_path / "e.mp4", "mono", "copy of the source", (2560, 1280), {"width": 2560}),
        (tmp_path / "e.mp4", "mono", "re-encoded", (1024, 512), {"width": 1024}),
    ]
    for src, layout, how, size, *opts in cases:
        dst = tmp_path / f"{src.stem}.{len(opts)}.{size[0]}.web.mp4"
        r = browser_copy(src, dst, layout=layout, **(opts[0] if opts else {}))
        assert how in r["how"] and (r["width"], r["height"]) == size, (src.name, r)
        codec, pix, w, h, _ = info(dst)
        assert (codec, pix, w, h) == ("h264", "yuv420p", *size), (src.name, codec, pix, w, h)


@pytest.mark.parametrize("width", ["0", "-2", "1023", "abc", "8192", "1e3"])
def test_browser_width_refused(width):
    """--browser-width: a positive even number of pixels, at most 4096 (exit 2 in the CLI)."""
    from simulator.core.errors import InputError
    from simulator.report.build import check_browser_width

    with pytest.raises(InputError, match="--browser-width"):
        check_browser_width(width)
    assert check_browser_width("1024") == 1024


def test_browser_width_wider_than_the_source(tmp_path):
    from simulator.core.errors import InputError
    from simulator.report.build import browser_copy

    src = _clip(tmp_path / "a.mp4", "128x64", ["-c:v", "libx264", "-pix_fmt", "yuv420p"])
    with pytest.raises(InputError, match=r"a.mp4: --browser-width 256 is wider than the video"):
        browser_copy(src, tmp_path / "w.mp4", width=256, explicit=True)
    assert not (tmp_path / "w.mp4").exists()


def test_each_viewing_shows_its_preset():
    rows = [{"viewing": "a", "video": "v", "status": "ok"}]
    study = {"settings": {"epof": {"preset": "cao2021-code"}}}
    site = Site(study, rows, {})
    html = site.viewings_page()
    assert "<th>preset</th>" in html and "cao2021-code" in html
    assert "cao2021-code" in site.viewing_page(site.rows[0], None)
    assert "<td>vimsim</td>" in Site({}, rows, {}).viewings_page()  # a study before presets
