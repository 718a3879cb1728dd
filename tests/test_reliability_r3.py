"""Reliability corpus, round 3: the cases of ``test_reliability.CASES`` plus
the commands and faults found since: folder outputs that replaced a user's files,
options that size work without bounds, non-video inputs, EPOF CSVs of another video,
unbounded echoes of user text, a bare ``vimsim``.

Each row is run as the earlier table's are (``{d}`` = a fresh copy of the base corpus)
and checked the same way, and stricter: no new folder either (options are checked before
any folder is created), and a fragment starting with ``!`` must NOT be in the message.
``bench/reliability_corpus.py`` runs both tables against any checkout (the figure of the
issue: cases correct per contract, by class, before and after).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_reliability import EPOF, HPC, RENDER, _copy, _mkdir, _text, base, run_case  # noqa: F401

from simulator.cli import main

FRAMES = ["frames", "{d}/v.mp4", "{d}/P.csv", "--eye-size", "32x32", "--no-progress"]
STUDY_HEAD = '[study]\nname = "t"\n\n'


def _snapshot(d: Path) -> dict[str, str]:
    """Files by content, folders as ``<dir>``: a new empty folder counts as written."""
    import hashlib

    out = {}
    for p in sorted(d.rglob("*")):
        name = str(p.relative_to(d))
        if p.is_symlink():
            continue
        out[name] = "<dir>" if p.is_dir() else hashlib.sha256(p.read_bytes()).hexdigest()
    return out


# ---------------------------------------------------------------- setup builders
def _multi(d: Path) -> None:
    """M.txt: a 360VidStr aggregated file of 3 users (time line, then pitch and yaw lines)."""
    t = np.arange(0, 2.01, 0.1)
    lines = [" ".join(f"{v:.3f}" for v in t)]
    for u in range(3):
        lines.append(" ".join(f"{0.1 * u:.3f}" for _ in t))
        lines.append(" ".join(f"{0.3 * u + 0.2 * k:.3f}" for k in range(len(t))))
    (d / "M.txt").write_text("\n".join(lines) + "\n")


def _png(path: Path, level: int, size=(16, 16)) -> None:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.full((*size[::-1], 3), level, np.uint8)).save(path)


def _frames_pair(d: Path) -> None:
    """n/ (new frames) and g/ (goldens) whose one frame differs: a failing comparison."""
    _png(d / "n" / "t0000.100_both.png", 100)
    _png(d / "g" / "t0000.100_both.png", 0)


def _golden_copy(d: Path) -> None:
    """o/: goldens copied from elsewhere (frames.json listing a PNG; no manifest)."""
    _png(d / "o" / "t0000.100_both.png", 7)
    (d / "o" / "frames.json").write_text('{"frames": [{"file": "t0000.100_both.png"}]}\n')


def _other_video_epof(d: Path) -> None:
    """w.mp4 (another clip, same frame count as v.mp4) and e.csv, v.mp4's EPOF CSV."""
    assert main(["synth", str(d / "w.mp4"), "--scene", "coaster", "--seconds", "0.5",
                 "--fps", "10", "--size", "128x64"]) == 0  # fmt: skip
    (d / "w.truth.npz").unlink()
    assert main(["epof", str(d / "G.npz"), str(d / "P.csv"), "-o", str(d / "e.csv")]) == 0


def _bad_deflate(d: Path) -> None:
    """B.npz: G.npz re-zipped with deflate, a few bytes inside pof_dps.npy's compressed
    stream changed (found by the fuzzer: zlib.error escaped as an internal error)."""
    import zipfile

    with zipfile.ZipFile(d / "G.npz") as src:
        members = {i.filename: src.read(i.filename) for i in src.infolist()}
    with zipfile.ZipFile(d / "B.npz", "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    with zipfile.ZipFile(d / "B.npz") as zf:
        info = zf.getinfo("pof_dps.npy")
    raw = bytearray((d / "B.npz").read_bytes())
    start = info.header_offset + 30 + len(info.filename) + len(info.extra)
    mid = start + 1  # the stream header: the first read (the .npy header check) fails
    raw[mid : mid + 8] = b"\xff\x00\xff\x00\xff\x00\xff\x00"
    (d / "B.npz").write_bytes(bytes(raw))


def _both(*makers):
    def make(d: Path) -> None:
        for m in makers:
            m(d)

    return make


def _study(videos: str, viewings: str = '[[viewings]]\nvideo = "a"\ntrace = "P.csv"\n'):
    return _text("S.toml", STUDY_HEAD + videos + "\n" + viewings)


_VIDEO_A = '[[videos]]\nid = "a"\npath = "{path}"\nwindow_size = 32\n'
LONG = "C" * 100_000  # a 100,000-character name: quoted only as a bounded excerpt
CAMERA = "time_s,x_m,y_m,z_m,yaw_deg,pitch_deg,roll_deg\n"

# (id, setup, argv, status, message fragment ('!...' = must not appear), outputs a success leaves)
CASES: list[tuple] = [
    # --- folder outputs: the one manifest rule (frames, headpath --user all, compare's report)
    ("frames-foreign-png", _copy("p.png", "o/t0000.100_both.png"), [*FRAMES, "-o", "{d}/o", "--at", "0.1"], 2, "not written by vimsim frames", ()),
    ("frames-foreign-json", _copy("P.csv", "o/frames.json"), [*FRAMES, "-o", "{d}/o", "--at", "0.1"], 2, "not written by vimsim frames", ()),
    ("frames-golden-copy", _golden_copy, [*FRAMES, "-o", "{d}/o", "--at", "0.2"], 2, "not written by vimsim frames", ()),
    ("frames-video-in-outdir", _copy("v.mp4", "o/t0000.100_both.png"), ["frames", "{d}/o/t0000.100_both.png", "{d}/P.csv", "-o", "{d}/o", "--at", "0.1"], 2, "o/t0000.100_both.png", ()),
    ("hp-all-foreign", _both(_multi, _copy("P.csv", "o/M_user2.csv")), [*HPC, "{d}/M.txt", "--format", "360vidstr", "--user", "all", "-o", "{d}/o"], 2, "not written by vimsim headpath convert", ()),
    ("hp-all-ok", _multi, [*HPC, "{d}/M.txt", "--format", "360vidstr", "--user", "all", "-o", "{d}/o"], 0, "wrote 3",
     ("o", "o/M_user1.csv", "o/M_user2.csv", "o/M_user3.csv", "o/.vimsim-manifest.json")),
    ("hp-all-outdir-file", _multi, [*HPC, "{d}/M.txt", "--format", "360vidstr", "--user", "all", "-o", "{d}/P.csv"], 2, "existing file", ()),
    ("compare-update-failing", _frames_pair, ["compare", "{d}/n", "{d}/g", "--update", "--report", "{d}/r"], 1, "NOT updated",
     ("r", "r/t0000.100_both.diff.png", "r/t0000.100_both.side.png", "r/compare.json", "r/.vimsim-manifest.json")),
    ("compare-report-foreign", _both(_frames_pair, _copy("P.csv", "r/compare.json")), ["compare", "{d}/n", "{d}/g", "--report", "{d}/r"], 2, "not written by vimsim compare", ()),
    ("compare-report-foreign-diff", _both(_frames_pair, _copy("p.png", "r/t0000.100_both.diff.png")), ["compare", "{d}/n", "{d}/g", "--report", "{d}/r"], 2, "not written by vimsim compare", ()),
    ("compare-force-alone", _frames_pair, ["compare", "{d}/n", "{d}/g", "--force"], 2, "--force goes with --update", ()),
    ("compare-bad-golden-json", _both(_frames_pair, _text("g/frames.json", "{oops")), ["compare", "{d}/n", "{d}/g", "--update", "--force", "--report", "{d}/r"], 2, "frames.json", ("r", "r/t0000.100_both.diff.png", "r/t0000.100_both.side.png", "r/compare.json", "r/.vimsim-manifest.json")),
    ("study-foreign-viewings", _both(_copy("P.csv", "o/viewings.csv"), _study(_VIDEO_A.format(path="v.mp4"))), ["study", "{d}/S.toml", "-o", "{d}/o", "--cache-dir", "{d}/c", "--no-progress"], 2, "not written by vimsim study", ()),
    ("export-foreign", _copy("P.csv", "o/VimsimEpof.cs"), ["export", "{d}/G.npz", "-o", "{d}/o"], 2, "not written by vimsim export", ()),
    # --- options that size work: bounded, checked before any folder is created
    ("frames-every-tiny", None, [*FRAMES, "-o", "{d}/o", "--every", "1e-9"], 2, "--every", ()),
    ("frames-every-zero", None, [*FRAMES, "-o", "{d}/o", "--every", "0"], 2, "--every", ()),
    ("frames-every-many", None, [*FRAMES, "-o", "{d}/o", "--every", "0.00001"], 2, "--every", ()),
    ("frames-at-many", None, [*FRAMES, "-o", "{d}/o", "--at", ",".join(["0.1"] * 10_001)], 2, "at most 10,000", ()),
    ("frames-at-nan", None, [*FRAMES, "-o", "{d}/o", "--at", "nan"], 2, "outside the video", ()),
    ("demo-seconds-huge", None, ["demo", "-o", "{d}/o", "--seconds", "1e9", "--no-progress"], 2, "at most 100,000", ()),
    ("demo-seconds-inf", None, ["demo", "-o", "{d}/o", "--seconds", "inf", "--no-progress"], 2, "--seconds", ()),
    ("synth-seconds-huge", None, ["synth", "{d}/s.mp4", "--scene", "rotate", "--seconds", "1e9"], 2, "at most 100,000", ()),
    ("synth-fps-huge", None, ["synth", "{d}/s.mp4", "--scene", "rotate", "--fps", "1e9"], 2, "fps", ()),
    ("synth-size-huge", None, ["synth", "{d}/s.mp4", "--scene", "rotate", "--size", "99999x99999"], 2, "--size", ()),
    ("synth-size-memory", None, ["synth", "{d}/s.mp4", "--scene", "rotate", "--seconds", "0.1", "--size", "16384x8192"], 2, "--size 16384x8192", ()),
    ("synth-truth-cell-tiny", None, ["synth", "{d}/s.mp4", "--scene", "rotate", "--truth-cell", "0.01"], 2, "--truth-cell", ()),
    ("hp-synth-seconds-huge", None, ["headpath", "synth", "look-around", "-o", "{d}/h.csv", "--seconds", "1e12"], 2, "at most", ()),
    ("hp-synth-rate-huge", None, ["headpath", "synth", "look-around", "-o", "{d}/h.csv", "--seconds", "10", "--rate", "1e9"], 2, "at most", ()),
    ("render-eye-huge", None, [*RENDER[:-3], "-o", "{d}/o", "--eye-size", "99999x99999"], 2, "--eye-size", ()),
    ("view-size-huge-2", None, ["viewport", "{d}/p.png", "--yaw", "0", "--pitch", "0", "--size", "99999x2", "-o", "{d}/o.png"], 2, "size", ()),
    ("render-start-past-end", None, [*RENDER, "-o", "{d}/o", "--start", "5"], 2, "!--end", ()),
    ("render-end-before-start", None, [*RENDER, "-o", "{d}/o", "--start", "0.3", "--end", "0.1"], 2, "--end", ()),
    # --- non-video inputs: one line naming the file, exit 2, never an internal error
    ("render-not-video", _text("B.mp4", "not a video"), ["render", "{d}/B.mp4", "{d}/P.csv", "-o", "{d}/o"], 2, "B.mp4", ()),
    ("frames-not-video", _text("B.mp4", "not a video"), ["frames", "{d}/B.mp4", "{d}/P.csv", "-o", "{d}/o", "--at", "0.1"], 2, "B.mp4", ()),
    ("render-right-not-video", _text("B.mp4", "not a video"), [*RENDER, "-o", "{d}/o", "--right", "{d}/B.mp4"], 2, "B.mp4", ()),
    ("render-grid-is-video", None, [*RENDER, "-o", "{d}/o", "--grid", "{d}/v.mp4"], 2, "not a vimsim grid", ()),
    ("export-not-grid", _text("B.npz", "xx"), ["export", "{d}/B.npz", "-o", "{d}/o"], 2, "B.npz", ()),
    ("study-not-video", _both(_text("B.mp4", "not a video"), _study(_VIDEO_A.format(path="B.mp4"))), ["study", "{d}/S.toml", "-o", "{d}/o", "--cache-dir", "{d}/c", "--no-progress"], 2, "B.mp4", ()),
    ("study-video-missing", _study(_VIDEO_A.format(path="nope.mp4")), ["study", "{d}/S.toml", "-o", "{d}/o", "--cache-dir", "{d}/c", "--no-progress"], 2, "nope.mp4", ()),
    ("study-video-is-dir", _both(_mkdir("vd.mp4"), _study(_VIDEO_A.format(path="vd.mp4"))), ["study", "{d}/S.toml", "-o", "{d}/o", "--cache-dir", "{d}/c", "--no-progress"], 2, "vd.mp4", ()),
    ("study-toml-garbage", _text("S.toml", "[[[ not toml"), ["study", "{d}/S.toml", "-o", "{d}/o", "--no-progress"], 2, "S.toml", ()),
    ("study-toml-binary", _text("S.toml", "\x00\xff\xfe", "latin-1"), ["study", "{d}/S.toml", "-o", "{d}/o", "--no-progress"], 2, "S.toml", ()),
    ("study-no-viewings", _study(_VIDEO_A.format(path="v.mp4"), ""), ["study", "{d}/S.toml", "-o", "{d}/o", "--no-progress"], 2, "S.toml", ()),
    # --- EPOF CSVs: of another video, or not EPOF CSVs
    ("render-opacity-other-video", _other_video_epof, ["render", "{d}/w.mp4", "{d}/P.csv", "-o", "{d}/o", "--opacity", "{d}/e.csv", "--eye-size", "32x32"], 2, "another video", ()),
    ("render-opacity-garbage", _text("B.csv", "frame,x\n1,2\n"), [*RENDER, "-o", "{d}/o", "--opacity", "{d}/B.csv"], 2, "B.csv", ()),
    ("render-opacity-empty", _text("B.csv", ""), [*RENDER, "-o", "{d}/o", "--opacity", "{d}/B.csv"], 2, "B.csv", ()),
    ("an-epof-csv-garbage", _text("B.csv", "id,condition,epof_csv\nP1,GR,x.csv\n"), ["analyze", "{d}/B.csv", "-o", "{d}/o"], 2, "", ()),
    # --- found by the fuzzer (tests/test_fuzz.py), kept as cases
    ("grid-bad-deflate", _bad_deflate, ["epof", "{d}/B.npz", "{d}/P.csv", "-o", "{d}/e.csv"], 2, "B.npz", ()),
    ("an-unbalanced-quote", _text("B.csv", '"id,condition,flow\nP1,GR,2\nP2,NR,3\n'), ["analyze", "{d}/B.csv", "-o", "{d}/o"], 2, "B.csv", ()),
    # --- camera CSVs (synth --scene trajectory)
    ("camera-garbage", _text("C.csv", "hello\x00world"), ["synth", "{d}/s.mp4", "--scene", "trajectory", "--camera", "{d}/C.csv"], 2, "C.csv", ()),
    ("camera-time-order", _text("C.csv", CAMERA + "1,0,0,0,0,0,0\n0,0,0,1,0,0,0\n"), ["synth", "{d}/s.mp4", "--scene", "trajectory", "--camera", "{d}/C.csv"], 2, "C.csv", ()),
    ("camera-nan", _text("C.csv", CAMERA + "0,nan,0,0,0,0,0\n1,0,0,1,0,0,0\n"), ["synth", "{d}/s.mp4", "--scene", "trajectory", "--camera", "{d}/C.csv"], 2, "C.csv", ()),
    ("camera-header-only", _text("C.csv", CAMERA), ["synth", "{d}/s.mp4", "--scene", "trajectory", "--camera", "{d}/C.csv"], 2, "C.csv", ()),
    # --- messages quote a bounded excerpt of user text; a bare vimsim is short
    ("hp-columns-long", _text("B.csv", "t,yaw\n0,1\n1,2\n"), [*HPC, "{d}/B.csv", "-o", "{d}/o.csv", "--columns", f"time=t,yaw={LONG}"], 2, "!" + "C" * 1000, ()),
    ("hp-header-long", _text("B.csv", f"{LONG},yaw\n0,1\n1,2\n"), [*HPC, "{d}/B.csv", "-o", "{d}/o.csv", "--format", "canonical"], 2, "!" + "C" * 1000, ()),
    ("an-column-long", _text("B.csv", f"id,condition,{LONG}\nP1,GR,1\n"), ["analyze", "{d}/B.csv", "-o", "{d}/o"], 2, "!" + "C" * 1000, ()),
    ("study-key-long", _study(_VIDEO_A.format(path="v.mp4") + f"{LONG} = 1\n"), ["study", "{d}/S.toml", "-o", "{d}/o", "--no-progress"], 2, "!" + "C" * 1000, ()),
    ("epof-output-long", None, [*EPOF, "-o", "{d}/" + "n" * 300 + "/e.csv"], 1, "!" + "n" * 300, ()),
    ("bare-vimsim", None, [], 2, "--help", ()),
]  # fmt: skip

#: The class of each case (for the measure): by id prefix.
CLASSES = {
    "folder": ("frames-foreign", "frames-golden", "frames-video", "hp-all", "compare-", "export-foreign",
               "study-foreign"),
    "bounds": ("frames-every", "frames-at", "demo-seconds", "synth-seconds", "synth-fps", "synth-size",
               "synth-truth", "hp-synth", "render-eye", "view-size", "render-start", "render-end"),
    "non-video": ("render-not-video", "frames-not-video", "render-right", "render-grid-is", "export-not",
                  "study-"),
    "epof-csv": ("render-opacity", "an-epof"),
    "fuzz-found": ("grid-bad-deflate", "an-unbalanced-quote"),
    "camera-csv": ("camera-",),
    "messages": ("hp-columns-long", "hp-header-long", "an-column-long", "epof-output-long", "bare-"),
}  # fmt: skip


def case_class(cid: str) -> str:
    if cid.endswith("-long") or cid.startswith("bare-"):
        return "messages"
    for name, prefixes in CLASSES.items():
        if cid.startswith(prefixes):
            return name
    return "other"


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_corpus_r3(case, base, tmp_path, capsys, monkeypatch):  # noqa: F811
    check_case(case, base, tmp_path, capsys, monkeypatch)


def check_case(case, base, tmp_path, capsys, monkeypatch) -> None:  # noqa: F811
    """Run one table case (rounds 3 and 4) and check what it must do: its exit status, its
    message fragment (``!`` = must not appear), one bounded error line for bad input, no
    input changed, nothing left but its outputs, no temporary."""
    status, fragment, outputs = case[3:]
    rc, cap, before, d = run_case(case, base, tmp_path, capsys, monkeypatch, _snapshot)
    err = cap.err
    assert rc == status, err[:2000]
    if fragment.startswith("!"):
        assert fragment[1:] not in err + cap.out, err[:2000]
    else:
        assert fragment in err + cap.out, err[:2000] + cap.out[:2000]
    assert "Traceback" not in err and "internal error" not in err, err[:2000]
    if status == 2:
        assert len([ln for ln in err.splitlines() if "error" in ln]) == 1, err[:2000]
        assert max(len(ln) for ln in err.splitlines()) <= 1000, "an unbounded message"
    after = _snapshot(d)
    for name, h in before.items():  # no input changed (nor any other file that was there)
        if name not in outputs:
            assert after.get(name) == h, f"{name} changed or vanished"
    new = set(after) - set(before)
    assert new <= set(outputs), f"left behind: {sorted(new - set(outputs))[:5]}"
    assert not [n for n in after if ".tmp-" in n]


def test_corpus_r3_size():
    """With the earlier table: at least 120 cases of bad input and faults."""
    from test_reliability import CASES as EARLIER

    ids = [c[0] for c in CASES]
    assert len(ids) == len(set(ids)) and not set(ids) & {c[0] for c in EARLIER}
    assert len(CASES) + len(EARLIER) >= 120
    assert "other" not in {case_class(c) for c in ids}


def test_bare_vimsim_is_short(capsys):
    assert main([]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") <= 2 and "vimsim --help" in err, err
