"""Reliability corpus, round 4 (part A): ``--log`` as an output, folder manifests of every
folder a command writes, the report server, CSV cells, bad input named, sv3d cubemap tags.

The table runs as ``test_reliability_r3``'s does (``{d}`` = a fresh copy of the base
corpus; no input changed, no new file or folder beyond the outputs named, one error
line); the cases that need more than a command line are functions below it.
"""

from __future__ import annotations

import contextlib
import subprocess
from pathlib import Path

import pytest
from test_reliability import HPC, _both, _copy, _mkdir, _text, base, run_case  # noqa: F401
from test_reliability_r3 import _frames_pair, _multi, _study, check_case

from simulator.cli import main

FRAMES = ["frames", "{d}/v.mp4", "{d}/P.csv", "--eye-size", "32x32", "--no-progress", "--at", "0.1"]
RENDER = [
    "render",
    "{d}/v.mp4",
    "{d}/P.csv",
    "--eye-size",
    "32x32",
    "--no-progress",
    "--opacity",
    "0.5",
]
STUDY = [
    "study",
    "{d}/S.toml",
    "-o",
    "{d}/o",
    "--cache-dir",
    "{d}/c",
    "--no-progress",
    "--workers",
    "1",
]
_VIDEO_A = '[[videos]]\nid = "a"\npath = "v.mp4"\nwindow_size = 32\nmethod = "sphere"\ncell = 10\n'
CONVERT = [*HPC, "{d}/P.csv", "-o", "{d}/h.csv"]


def _file(name: str, text: str):
    def make(d: Path) -> None:
        (d / name).parent.mkdir(parents=True, exist_ok=True)
        (d / name).write_text(text)

    return make


def _manifest_folder(d: Path) -> None:
    """m/: a folder an earlier vimsim run wrote (a manifest, a viewings.csv, a summary.json)."""
    (d / "m").mkdir()
    (d / "m" / ".vimsim-manifest.json").write_text(
        '{"command": "study", "state": "complete", "files": []}\n'
    )
    (d / "m" / "viewings.csv").write_text("viewing,video\n1,a\n")
    (d / "m" / "sub").mkdir()
    (d / "m" / "sub" / "summary.json").write_text("{}\n")


# (id, setup, argv, status, message fragment ('!...' = must not appear), outputs a success leaves)
CASES: list[tuple] = [
    # --- --log is an output: never an input, never among the outputs, never in a vimsim folder
    ("log-study-trace", _study(_VIDEO_A), [*STUDY, "--log", "{d}/P.csv"], 2, "--log", ()),
    ("log-study-video", _study(_VIDEO_A), [*STUDY, "--log", "{d}/v.mp4"], 2, "--log", ()),
    ("log-study-trace-dry", _study(_VIDEO_A), [*STUDY, "--dry-run", "--log", "{d}/P.csv"], 2, "--log", ()),
    ("log-viewings-csv", _manifest_folder, [*CONVERT, "--log", "{d}/m/viewings.csv"], 2, "manifest", ()),
    ("log-summary-json", _manifest_folder, [*CONVERT, "--log", "{d}/m/sub/summary.json"], 2, "manifest", ()),
    ("log-render-left", None, [*RENDER, "-o", "{d}/o", "--log", "{d}/o/left.mp4"], 2, "inside the output folder", ()),
    ("log-frames-json", None, [*FRAMES, "-o", "{d}/o", "--log", "{d}/o/frames.json"], 2, "inside the output folder", ()),
    ("log-export-js", None, ["export", "{d}/G.npz", "-o", "{d}/o", "--format", "web", "--log", "{d}/o/vimsim.js"], 2, "inside the output folder", ()),
    ("log-report-index", _mkdir("o"), ["report", "{d}/o", "--log", "{d}/o/report/index.html"], 2, "inside the output folder", ()),
    ("log-compare-golden", _frames_pair, ["compare", "{d}/n", "{d}/g", "--log", "{d}/g/run.log"], 2, "inside the output folder", ()),
    ("log-is-output", None, [*CONVERT, "--log", "{d}/h.csv"], 2, "--log", ()),
    ("log-is-plot", None, ["epof", "{d}/G.npz", "{d}/P.csv", "-o", "{d}/e.csv", "--plot", "{d}/e.png", "--log", "{d}/e.png"], 2, "--log", ()),
    ("log-refusal-no-log", None, [*HPC, "{d}/nope.csv", "-o", "{d}/h.csv", "--log", "{d}/run.log"], 2, "nope.csv", ()),
    ("log-ok", None, [*CONVERT, "--log", "{d}/run.log"], 0, "wrote", ("h.csv", "run.log")),
]  # fmt: skip


def test_log_gets_the_run_once_checks_pass(base, tmp_path, capsys):  # noqa: F811
    """A run that passes its checks appends a header, its notes and its result line; an
    existing log is appended to, never replaced."""
    log = tmp_path / "run.log"
    log.write_text("earlier\n")
    out = tmp_path / "h.csv"
    assert main([*HPC, str(base / "P.csv"), "-o", str(out), "--log", str(log)]) == 0
    text = log.read_text()
    assert text.startswith("earlier\n# ") and "wrote" in text.splitlines()[-1], text


def _fill(path: Path) -> None:
    with contextlib.suppress(OSError), open(path / "fill", "wb") as f:
        while True:
            f.write(b"x" * 1024)
            f.flush()


@contextlib.contextmanager
def _full_tmpfs(path: Path, size: str = "8k", fill: bool = True):
    """A tmpfs at ``path`` (filled up unless ``fill`` is False); skipped without root."""
    path.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                       check=False, capture_output=True, text=True)  # fmt: skip
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs ({r.stderr.strip()[:80]}): needs root/CAP_SYS_ADMIN")
    try:
        if fill:
            _fill(path)
        yield path
    finally:
        subprocess.run(["umount", str(path)], check=False)


def test_log_on_a_full_disk_is_one_line_naming_it(base, tmp_path, capsys):  # noqa: F811
    with _full_tmpfs(tmp_path / "full") as m:
        rc = main([*HPC, str(base / "P.csv"), "-o", str(tmp_path / "h.csv"),
                   "--log", str(m / "run.log")])  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 1, err
    lines = [ln for ln in err.splitlines() if "error" in ln]
    assert len(lines) == 1 and "No space left on device" in lines[0], err
    assert str(m / "run.log") in lines[0] and "Traceback" not in err, err


# ----------------------------------------------------------------- screen's folders
SCREEN = ["screen", "{d}/v.mp4", "-o", "{d}/o", "--viewers", "2", "--cache-dir", "{d}/c",
          "--workers", "1", "--no-progress"]  # fmt: skip
CASES += [
    ("screen-foreign-index", _file("o/screen/index.html", "<p>mine</p>"), SCREEN, 2, "not written by vimsim screen", ()),
    ("screen-foreign-video-file", _file("o/screen/v/map.csv", "mine"), SCREEN, 2, "not written by vimsim screen", ()),
    ("screen-video-folder-is-file", _file("o/screen/v", "mine"), SCREEN, 2, "existing file", ()),
]  # fmt: skip


@pytest.mark.slow
def test_screen_folders_keep_manifests_and_rerun(base, tmp_path, capsys):  # noqa: F811
    import json

    argv = [a.replace("{d}", str(base)).replace(f"{base}/o", str(tmp_path / "o"))
            .replace(f"{base}/c", str(tmp_path / "c")) for a in SCREEN]  # fmt: skip
    assert main(argv) == 0, capsys.readouterr().err
    for sub in ("screen", "screen/v"):
        m = json.loads((tmp_path / "o" / sub / ".vimsim-manifest.json").read_text())
        assert m["command"] == "screen" and m["state"] == "complete", m
    assert {"index.html", "comparison.csv", "screen.json"} <= set(
        json.loads((tmp_path / "o" / "screen" / ".vimsim-manifest.json").read_text())["files"]
    )
    assert main(argv) == 0, capsys.readouterr().err  # a rerun replaces its own files


# ----------------------------------------------------------------- bad input named
def _bomb_png(d: Path) -> None:
    """B.png: a PNG whose header claims 30000x15000 px (a decompression bomb), a few bytes."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data) & 0xFFFFFFFF
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)

    ihdr = struct.pack(">IIBBBBB", 30000, 15000, 8, 2, 0, 0, 0)
    (d / "B.png").write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr)
                              + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b""))  # fmt: skip


def _deep_settings(d: Path) -> None:
    """B.csv: an EPOF CSV whose settings line holds JSON nested 200,000 deep."""
    assert main(["epof", str(d / "G.npz"), str(d / "P.csv"), "-o", str(d / "e.csv")]) == 0
    text = (d / "e.csv").read_text()
    (d / "e.csv").unlink()
    (d / "B.csv").write_text("# method: " + "[" * 200_000 + "]" * 200_000 + "\n" + text)


def _pickled_member(d: Path) -> None:
    """B.npz: S.npz (v.mp4's sphere grid) plus a pickled object member."""
    import numpy as np

    with np.load(d / "S.npz", allow_pickle=False) as z:
        a = {k: z[k] for k in z.files}
    a["extra"] = np.array([{"x": 1}], dtype=object)
    with open(d / "B.npz", "wb") as fh:
        np.savez(fh, **a)  # pickles the object member; a reader must refuse, never unpickle


_STILL_A = '[[videos]]\nid = "a"\npath = "p.png"\nwindow_size = 32\n'
_EAC_A = '[[videos]]\nid = "a"\npath = "v.mp4"\nwindow_size = 32\nprojection = "eac"\n'
DRY = ["study", "{d}/S.toml", "-o", "{d}/o", "--cache-dir", "{d}/c", "--dry-run"]
CASES += [
    ("bomb-viewport", _bomb_png, ["viewport", "{d}/B.png", "--yaw", "0", "--pitch", "0", "--size", "32x32", "-o", "{d}/o.png"], 2, "B.png", ()),
    ("bomb-render", _bomb_png, ["render", "{d}/B.png", "{d}/P.csv", "-o", "{d}/o", "--eye-size", "32x32", "--opacity", "0.5"], 2, "B.png", ()),
    ("bomb-texture", _bomb_png, ["synth", "{d}/s.mp4", "--scene", "rotate", "--texture", "{d}/B.png"], 2, "B.png", ()),
    ("deep-epof-settings", _deep_settings, [*RENDER[:-2], "-o", "{d}/o", "--opacity", "{d}/B.csv"], 2, "B.csv", ()),
    ("screen-grid-pickled", _pickled_member, [*SCREEN, "--grid", "{d}/B.npz"], 2, "B.npz", ()),
    ("still-seconds-huge", None, ["render", "{d}/p.png", "{d}/P.csv", "-o", "{d}/o", "--eye-size", "32x32", "--opacity", "0.5", "--seconds", "1e9"], 2, "at most 100,000", ()),
    ("still-fps-huge", None, ["frames", "{d}/p.png", "{d}/P.csv", "-o", "{d}/o", "--eye-size", "32x32", "--at", "0.1", "--fps", "1e6"], 2, "--fps", ()),
    ("dry-run-still", _study(_STILL_A), DRY, 2, "still image", ()),
    ("dry-run-eac-2to1", _study(_EAC_A), DRY, 2, "eac", ()),
]  # fmt: skip


_HUGE = '"' + "[" * 200_000 + '"'  # one CSV field over the csv module's 128 KiB limit
CASES += [
    ("deep-study-toml", _text("S.toml", "a = " + "[" * 200_000 + "]" * 200_000 + "\n"), DRY, 2, "S.toml", ()),
    ("csv-field-analyze", _text("B.csv", f"id,condition\n{_HUGE},GR\n"), ["analyze", "{d}/B.csv", "-o", "{d}/o"], 2, "B.csv", ()),
    ("csv-field-headpath", _text("B.csv", f"time_s,yaw_deg,pitch_deg\n0,1,2\n{_HUGE},1,2\n"), [*HPC, "{d}/B.csv", "-o", "{d}/o.csv"], 2, "B.csv", ()),
    ("csv-field-camera", _text("C.csv", f"time_s,x_m,y_m,z_m,yaw_deg,pitch_deg,roll_deg\n{_HUGE},0,0,0,0,0,0\n"), ["synth", "{d}/s.mp4", "--scene", "trajectory", "--camera", "{d}/C.csv"], 2, "C.csv", ()),
]  # fmt: skip


# ----------------------------------------------------------------- --columns with --user
_COLS = ["--columns", "time=t,yaw=y,pitch=p"]
CASES += [
    ("hp-all-columns", _multi, [*HPC, "{d}/M.txt", "--user", "all", *_COLS, "-o", "{d}/o"], 2, "--columns with --user all", ()),
    ("hp-user-columns", _multi, [*HPC, "{d}/M.txt", "--user", "2", *_COLS, "-o", "{d}/o.csv"], 2, "--columns with --user 2", ()),
    ("epof-user-columns", None, ["epof", "{d}/G.npz", "{d}/P.csv", "--user", "2", *_COLS, "-o", "{d}/e.csv"], 2, "--columns with --user", ()),
]  # fmt: skip


# ----------------------------------------------------------------- the table, run
@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_corpus_r4a(case, base, tmp_path, capsys, monkeypatch):  # noqa: F811
    check_case(case, base, tmp_path, capsys, monkeypatch)


# ----------------------------------------------------------------- CSV cells
def test_write_csv_guards_text_cells_only(tmp_path):
    from simulator.core.fileio import csv_uncell, write_csv

    p = write_csv(tmp_path / "t.csv", ["id", "x", "y"],
                  [["=HYPERLINK(1)", -3.5, "-3.5"], ["-cmd", float("nan"), "@SUM(A1)"],
                   ["+x", None, "P01"]])  # fmt: skip
    rows = [ln.split(",") for ln in p.read_text().splitlines()]
    assert rows[1] == ["'=HYPERLINK(1)", "-3.5", "-3.5"]  # numbers stay numbers
    assert rows[2] == ["'-cmd", "", "'@SUM(A1)"] and rows[3] == ["'+x", "", "P01"]
    assert csv_uncell("'=HYPERLINK(1)") == "=HYPERLINK(1)" and csv_uncell("'P01") == "'P01"


@pytest.mark.slow
def test_study_csvs_guard_participant_and_condition(base, tmp_path, capsys):  # noqa: F811
    """viewings.csv and analysis/DATA.csv of a study whose participants and conditions
    start with = - + @: text cells guarded, numeric cells untouched."""
    import csv
    import shutil

    from test_reliability import EXAMPLE

    d = tmp_path / "d"
    shutil.copytree(base, d)
    rows = list(csv.reader(ln for ln in EXAMPLE.read_text().splitlines() if ln[:1] != "#"))
    head, data = rows[0], rows[1:]
    pids = ["=HYPERLINK(1)", "-cmd", "@x", "+y"]
    with open(d / "q.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["participant", *(c for c in head if c not in ("id", "condition", "flow"))])
        for pid, r in zip(pids, data):
            w.writerow([pid, *(v for c, v in zip(head, r) if c not in ("id", "condition", "flow"))])
    views = "".join(
        f'[[viewings]]\nid = "v{k}"\nvideo = "a"\ntrace = "P.csv"\nparticipant = "{pid}"\n'
        f'condition = "{"=GR" if k % 2 else "-NR"}"\n'
        for k, pid in enumerate(pids)
    )
    (d / "S.toml").write_text('[study]\nname = "t"\n\n' + _VIDEO_A + "\n" + views
                              + '\n[questionnaires]\npath = "q.csv"\n')  # fmt: skip
    out = tmp_path / "o"
    rc = main(["study", str(d / "S.toml"), "-o", str(out), "--cache-dir", str(tmp_path / "c"),
               "--no-progress", "--workers", "1"])  # fmt: skip
    assert rc in (0, 3), capsys.readouterr().err
    with open(out / "viewings.csv", newline="") as fh:
        vrows = list(csv.DictReader(fh))
    assert [r["participant"] for r in vrows] == ["'" + p for p in pids]
    assert {r["condition"] for r in vrows} == {"'=GR", "'-NR"}
    assert all(float(r["epof_mean_dps"]) >= 0 for r in vrows)  # numbers stay numbers
    with open(out / "analysis" / "DATA.csv", newline="") as fh:
        drows = [r for r in csv.DictReader(ln for ln in fh if ln[:1] != "#")]
    assert sorted(r["id"] for r in drows) == sorted("'" + p for p in pids)
    assert all(not r["condition"] or r["condition"][0] == "'" for r in drows)


def test_web_export_full_temporary_disk_names_the_output(base, tmp_path, capsys, monkeypatch):  # noqa: F811
    """The web export's data file is made under a temporary name first: a full disk there
    is one line naming the output file, exit 1, nothing left."""
    import tempfile

    with _full_tmpfs(tmp_path / "full") as m:
        monkeypatch.setattr(tempfile, "tempdir", str(m))
        rc = main(["export", str(base / "S.npz"), "-o", str(tmp_path / "o"), "--format", "web"])
        left = sorted(p.name for p in m.iterdir())
    err = capsys.readouterr().err
    assert rc == 1, err
    lines = [ln for ln in err.splitlines() if "error" in ln]
    assert len(lines) == 1 and "No space left on device" in lines[0], err
    assert str(tmp_path / "o" / "vimsim_epof.bin") in lines[0] and str(m) not in lines[0], err
    assert left == ["fill"] and not (tmp_path / "o" / "vimsim_epof.bin").exists()


@pytest.mark.slow
def test_report_full_disk_names_the_report_file(base, tmp_path, capsys):  # noqa: F811
    """report builds into a temporary folder: a full disk is one line naming the report's
    file (not the temporary one), exit 1, no temporary left."""
    import shutil

    d = tmp_path / "d"
    shutil.copytree(base, d)
    (d / "S.toml").write_text('[study]\nname = "t"\n\n' + _VIDEO_A + '\n[[viewings]]\nvideo = "a"\n'
                              'trace = "P.csv"\n')  # fmt: skip
    study = tmp_path / "o"
    assert main(["study", str(d / "S.toml"), "-o", str(study), "--cache-dir", str(tmp_path / "c"),
                 "--no-progress", "--workers", "1", "--no-report"]) == 0  # fmt: skip
    capsys.readouterr()
    with _full_tmpfs(tmp_path / "full", size="4m", fill=False) as m:
        shutil.copytree(study, m / "o")
        _fill(m)
        rc = main(["report", str(m / "o")])
        left = sorted(p.name for p in (m / "o").iterdir())
    err = capsys.readouterr().err
    assert rc == 1, err
    lines = [ln for ln in err.splitlines() if "error" in ln]
    assert len(lines) == 1 and "No space left on device" in lines[0], err
    assert str(m / "o" / "report") in lines[0] and ".report-tmp" not in lines[0], err
    assert not [n for n in left if "tmp" in n], left
