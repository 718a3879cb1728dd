"""``vimsim report`` and the report ``vimsim study`` writes: pages in headless Chromium (no console
error, no request outside the folder), the replay against ``vimsim frames``, bad input."""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from browser_support import data_url_image
from PIL import Image

from simulator.cli import main
from simulator.report.serve import start_server
from simulator.testing.reference import psnr
from simulator.traces.path import save_headpath_csv, synth

EYE = (160, 120)


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    """A tiny study (one video, two viewings; [render] settings for the replay, no render)."""
    from simulator.synth import SynthConfig, synthesize

    d = tmp_path_factory.mktemp("rep")
    synthesize(SynthConfig("coaster", seconds=1.5, fps=10, size=(256, 128)), d / "full.mp4")
    # Anamorphic, as many 360 videos (1920x1080 shown 2:1): stored 192x128, SAR 4:3 (the
    # browser's videoWidth is the display width, 256).
    import imageio_ffmpeg

    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-i", str(d / "full.mp4"),
                    "-vf", "scale=192:128,setsar=4/3", "-c:v", "libx264", "-pix_fmt", "yuv420p",
                    str(d / "clip.mp4")], check=True)  # fmt: skip
    for i in range(2):
        save_headpath_csv(d / f"P0{i + 1}.csv", synth("look-around", 2.0, rate_hz=30, seed=i))
    (d / "study.toml").write_text(f"""
[study]
name = "t"
[[videos]]
id = "clip"
path = "clip.mp4"
method = "sphere"
window_size = 64
[[viewings]]
video = "clip"
trace = "P0[12].csv"
participant = "{{stem}}"
condition = "GR"
[render]
eye_size = "{EYE[0]}x{EYE[1]}"
hfov = 100
vfov = 80
""")
    assert main(["study", str(d / "study.toml"), "-o", str(d / "out"), "--cache-dir",
                 str(d / "cache"), "--no-progress"]) == 0  # fmt: skip
    return d / "out"


def _pages(report: Path) -> list[str]:
    return sorted(p.name for p in report.glob("*.html"))


@pytest.mark.browser
def test_pages_load_clean_served_and_from_files(browser, study):
    report = study / "report"
    pages = _pages(report)
    assert {"index.html", "viewings.html", "analysis.html", "video-clip.html"} <= set(pages)
    assert sum(p.startswith("viewing-") for p in pages) == 2
    srv = start_server(report)
    try:
        for name in pages:
            browser.get(srv.url + name)
            if name.startswith("viewing-"):
                browser.driver.set_script_timeout(60)
                ok = browser.run_async("""
                    for (let i = 0; i < 600; i++) {
                      if (window.vimsimReplay && window.vimsimReplay.ready) return true;
                      const n = document.getElementById('replay-note');
                      if (n && n.textContent) return n.textContent;
                      await new Promise((r) => setTimeout(r, 50));
                    }
                    return 'timeout';""")
                assert ok is True, ok
            console, urls = browser.drain()
            assert not [c for c in console if c["level"] in ("SEVERE", "WARNING")], (name, console)
            outside = [u for u in urls if not u.startswith(srv.url) and not u.startswith("data:")]
            assert not outside, (name, outside)
        # The viewings table sorts and filters.
        browser.get(srv.url + "viewings.html")
        n = browser.driver.execute_script("""
            const s = document.querySelector('[data-filter=status]');
            s.value = 'ok'; s.dispatchEvent(new Event('change'));
            document.querySelector('table.sortable th').click();
            return Array.from(document.querySelectorAll('tbody tr')).filter((r) => !r.hidden).length;""")
        assert n == 2
    finally:
        srv.close()
    # From the file system: the pages load without errors; the replay page says why it cannot play.
    for name in ("index.html", next(p for p in pages if p.startswith("viewing-"))):
        browser.get((report / name).as_uri())
        console, _ = browser.drain()
        assert not [c for c in console if c["level"] == "SEVERE"], (name, console)
    note = browser.driver.find_element("id", "replay-note").text
    assert "--serve" in note


@pytest.mark.browser
def test_replay_matches_vimsim_frames(browser, study, tmp_path):
    """Replay paused after a seek vs vimsim frames of the same viewing, same browser copy."""
    report = study / "report"
    viewing = "clip-P01-GR"
    times = [0.3, 0.75, 1.2]
    frames_dir = tmp_path / "frames"
    src = study.parent / "P01.csv"
    assert main(["frames", str(report / "media" / "clip.mp4"), str(src), "-o", str(frames_dir),
                 "--at", ",".join(map(str, times)), "--eye-size", f"{EYE[0]}x{EYE[1]}",
                 "--hfov", "100", "--vfov", "80", "--opacity", str(study / "epof" / f"{viewing}.csv"),
                 "--grf", "on", "--no-progress"]) == 0  # fmt: skip
    meta = json.loads((frames_dir / "frames.json").read_text())
    srv = start_server(report)
    try:
        browser.get(srv.url + f"viewing-{viewing}.html")
        got = browser.run_async(
            """
            const [times] = args;
            for (let i = 0; i < 600 && !(window.vimsimReplay && window.vimsimReplay.ready); i++)
              await new Promise((r) => setTimeout(r, 50));
            const out = [];
            for (const t of times) {
              const s = await window.vimsimReplay.seek(t);
              out.push({png: window.vimsimReplay.canvas.toDataURL('image/png'), opacity: s.opacity});
            }
            // Free look at the last time: the live EPOF at the recorded pose, then after a drag.
            const st = window.vimsimReplay.state, rec = st.epof, pose = [st.yaw, st.pitch];
            document.getElementById('freelook').click();
            const live = st.epof;
            const cv = window.vimsimReplay.canvas, r = cv.getBoundingClientRect();
            const ev = (type, x) => new PointerEvent(type, {clientX: r.left + x, clientY: r.top + 10, bubbles: true});
            cv.dispatchEvent(ev('pointerdown', 10));
            window.dispatchEvent(ev('pointermove', 60));
            window.dispatchEvent(ev('pointerup', 60));
            return {frames: out, rec, live, pose, moved: [st.yaw, st.pitch], after: st.epof,
                    label: document.getElementById('mode').textContent};""",
            times,
        )
        renderer = browser.gl_renderer()
    finally:
        srv.close()
    free = got
    got = got["frames"]
    # Free look: the runtime's live EPOF at the recorded pose is the recorded EPOF (vimsim epof).
    assert abs(free["live"] - free["rec"]) <= 1e-5 * abs(free["rec"]), free
    assert free["moved"][0] != free["pose"][0] and free["after"] != free["live"]
    assert "live" in free["label"]
    files = sorted(frames_dir.glob("*.png"))
    assert len(files) == len(times) == len(got), (files, meta)
    scores = []
    for f, g in zip(files, got):
        ref = np.asarray(Image.open(f).convert("RGB"))
        js = data_url_image(g["png"])
        assert js.shape == ref.shape
        scores.append(psnr(js, ref))
    print(f"\nreplay vs vimsim frames PSNR {', '.join(f'{s:.1f}' for s in scores)} dB ({renderer})")
    assert min(scores) >= 30.0, scores


def test_report_bad_input(study, tmp_path, capsys):
    # Not a study; an incomplete study (no study.json).
    assert main(["report", str(tmp_path / "none")]) == 2
    part = tmp_path / "part"
    shutil.copytree(study, part, ignore=shutil.ignore_patterns("report", "study.json"))
    assert main(["report", str(part)]) == 2
    assert not (part / "report").exists()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "not a complete vimsim study" in err[-1]
    # A report folder holding a file vimsim did not write: refused, nothing changed.
    full = tmp_path / "full"
    shutil.copytree(study, full)
    (full / "report" / "media" / "notes.txt").write_text("mine")
    before = {p: p.stat().st_mtime_ns for p in (full / "report").rglob("*")}
    assert main(["report", str(full)]) == 2
    assert {p: p.stat().st_mtime_ns for p in (full / "report").rglob("*")} == before
    assert "was not written by vimsim report" in capsys.readouterr().err
    # Our own report is rebuilt (the browser copy reused).
    (full / "report" / "media" / "notes.txt").unlink()
    assert main(["report", str(full)]) == 0
    assert (full / "report" / "index.html").is_file()


def test_report_without_grid_or_source(study, tmp_path):
    """A study copied elsewhere (its grid cache and source video gone): the pages are made,
    the replay says why it cannot play, and a failed viewing has a page saying so."""
    moved = tmp_path / "moved"
    shutil.copytree(study, moved, ignore=shutil.ignore_patterns("report"))
    s = json.loads((moved / "study.json").read_text())
    s["videos"]["clip"].update(grid=str(tmp_path / "gone.npz"), path=str(tmp_path / "gone.mp4"))
    s["failures"] = [{"viewing": "clip-P02-GR", "status": "bad trace"}]
    (moved / "study.json").write_text(json.dumps(s))
    with open(moved / "viewings.csv", newline="") as f:  # status by name (warnings follow it)
        rows = list(csv.DictReader(f))
    rows[-1]["status"] = "bad trace"
    with open(moved / "viewings.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    assert main(["report", str(moved)]) == 0
    rep = moved / "report"
    assert not (rep / "data").exists() and not (rep / "media" / "clip.mp4").exists()
    page = (rep / "viewing-clip-P01-GR.html").read_text()
    assert '"media":null' in page and '"export":null' in page
    assert "No EPOF for this viewing" in (rep / "viewing-clip-P02-GR.html").read_text()
    assert "bad trace" in (rep / "index.html").read_text()
