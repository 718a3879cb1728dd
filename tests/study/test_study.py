"""``vimsim study`` on the local executor: outputs, agreement with the one-viewing commands,
failures that do not stop the study, resume, the grid cache, questionnaires, bad manifests."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from simulator.cli import main
from simulator.study import VIEWING_COLUMNS
from simulator.study.outputs import PART_MEAN_COLUMNS
from simulator.traces.path import save_headpath_csv, synth


def _epof_rows(path) -> np.ndarray:
    """The numbers of an EPOF CSV's fixed columns (its '#' settings lines and header skipped;
    the ``artefact`` column a study writes by default is text)."""
    lines = [ln for ln in Path(path).read_text().splitlines() if ln and not ln.startswith("#")]
    return np.loadtxt(lines[1:], delimiter=",", ndmin=2, usecols=range(7))


EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "study_example.csv"


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A tiny synthetic clip, 4 scripted traces, a 3-user 360VidStr-format file, a short trace."""
    from simulator.synth import SynthConfig, synthesize

    d = tmp_path_factory.mktemp("study")
    synthesize(SynthConfig("rotate", seconds=1.5, fps=10, size=(128, 64)), d / "clip.mp4")
    for i in range(4):
        save_headpath_csv(d / f"P0{i + 1}.csv", synth("look-around", 2.0, rate_hz=30, seed=i))
    save_headpath_csv(d / "short.csv", synth("static", 0.5, rate_hz=30))
    t = np.arange(0, 2.01, 0.1)
    lines = [" ".join(f"{v:.3f}" for v in t)]
    for u in range(3):  # pitch line, yaw line (radians)
        lines.append(" ".join(f"{0.1 * u:.3f}" for _ in t))
        lines.append(" ".join(f"{0.3 * u + 0.2 * k:.3f}" for k in range(len(t))))
    (d / "multi.txt").write_text("\n".join(lines) + "\n")
    return d


def _manifest(d: Path, extra: str = "", method: str = "sphere") -> Path:
    m = d / "study.toml"
    m.write_text(f"""
[study]
name = "t"

[[videos]]
id = "clip"
path = "clip.mp4"
method = "{method}"
window_size = 64

[[viewings]]
video = "clip"
trace = "P0[12].csv"
participant = "{{stem}}"
condition = "GR"

[[viewings]]
video = "clip"
trace = "P0[34].csv"
participant = "{{stem}}"
condition = "NR"

[[viewings]]
video = "clip"
trace = "multi.txt"
user = "all"
condition = "NR"

[[viewings]]
video = "clip"
trace = "short.csv"

[[viewings]]
video = "clip"
trace = "P01.csv"
participant = "P01"
condition = "GR"
id = "render-P01"
render = true

[render]
eye_size = "64x64"
{extra}
""")
    return m


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def ran(base, tmp_path_factory):
    out = tmp_path_factory.mktemp("out") / "o"
    cache = base / "cache"
    rc = main(["study", str(_manifest(base)), "-o", str(out), "--cache-dir", str(cache),
               "--workers", "2", "--no-progress"])  # fmt: skip
    return rc, out, cache


@pytest.mark.gl
@pytest.mark.slow
def test_study_outputs(ran, base, capsys):
    rc, out, _ = ran
    assert rc == 3  # the short trace fails; everything else completes
    rows = _rows(out / "viewings.csv")
    assert list(rows[0]) == [*VIEWING_COLUMNS, *PART_MEAN_COLUMNS]
    ids = [r["viewing"] for r in rows]
    assert ids == ["clip-P01-GR", "clip-P02-GR", "clip-P03-NR", "clip-P04-NR",
                   "clip-multi_user1-NR", "clip-multi_user2-NR", "clip-multi_user3-NR",
                   "clip-short", "render-P01"]  # fmt: skip
    bad = [r for r in rows if r["status"] != "ok"]
    assert [r["viewing"] for r in bad] == ["clip-short"]
    assert "ends at 0.500 s" in bad[0]["status"] and "\n" not in bad[0]["status"]
    assert bad[0]["frames"] == ""
    s = json.loads((out / "study.json").read_text())
    assert s["counts"] == {"viewings": 9, "ok": 8, "with_warnings": 0, "failed": 1, "resumed": 0,
                           "renders": 1}  # fmt: skip
    assert s["failures"][0]["viewing"] == "clip-short"
    for r in rows:
        if r["status"] != "ok":
            continue
        # The row's numbers are those of its EPOF CSV (recomputed here with numpy).
        a = _epof_rows(out / "epof" / f"{r['viewing']}.csv")
        assert int(r["frames"]) == len(a) == 15
        np.testing.assert_allclose(float(r["epof_mean_dps"]), a[:, 5].mean(), rtol=1e-8)
        np.testing.assert_allclose(float(r["epof_p90_dps"]), np.percentile(a[:, 5], 90), rtol=1e-8)
        np.testing.assert_allclose(float(r["share_opacity_ge_0_5"]), np.mean(a[:, 6] >= 0.5))
    assert (out / "render" / "render-P01" / "summary.json").is_file()
    assert (out / "render" / "render-P01" / "left.mp4").stat().st_size > 0
    v = out / "videos" / "clip"
    for name in ("epof_viewers.png", "provocative.png", "moments.csv", "moment_1.png"):
        assert (v / name).stat().st_size > 0
    mom = _rows(v / "moments.csv")
    assert float(mom[0]["pof_dps"]) >= float(mom[-1]["pof_dps"]) > 0
    # A thumbnail (found by seeking) is the viewport of that frame decoded from the start.
    from PIL import Image

    from simulator.media.video import read_frame
    from simulator.sphere.geometry import extract_view

    r = mom[0]
    ref = extract_view(read_frame(base / "clip.mp4", int(r["frame"])), float(r["yaw_deg"]),
                       float(r["pitch_deg"]), hfov_deg=107.0, vfov_deg=107.0, size=(192, 192))  # fmt: skip
    np.testing.assert_array_equal(np.asarray(Image.open(v / r["thumbnail"])), ref)


@pytest.mark.gl
@pytest.mark.slow
def test_study_epof_equals_vimsim_epof(ran, base, tmp_path):
    """Each viewing's EPOF CSV is byte-identical to `vimsim epof` on the cached grid
    (the single-viewing command), also for a user of the multi-user file."""
    _, out, cache = ran
    grid = next((cache / "grids").glob("*.npz"))
    for vid, trace, user in (
        ("clip-P02-GR", "P02.csv", None),
        ("clip-multi_user2-NR", "multi.txt", "2"),
    ):
        ref = tmp_path / f"{vid}.csv"
        argv = ["epof", str(grid), str(base / trace), "-o", str(ref), "--artefacts"]  # a study's default
        assert main(argv + (["--user", user] if user else [])) == 0
        assert (out / "epof" / f"{vid}.csv").read_bytes() == ref.read_bytes()


@pytest.mark.gl
@pytest.mark.slow
def test_resume_and_cache(ran, base, tmp_path):
    _, out, cache = ran
    before = (out / "viewings.csv").read_bytes()
    m = _manifest(base)
    assert main(["study", str(m), "-o", str(out), "--cache-dir", str(cache), "--no-progress"]) == 3
    s = json.loads((out / "study.json").read_text())
    assert s["counts"]["resumed"] == 8 and s["videos"]["clip"]["cache"] == "hit"
    assert (out / "viewings.csv").read_bytes() == before
    # A changed trace is recomputed, the rest skipped.
    save_headpath_csv(base / "P04.csv", synth("look-around", 2.0, rate_hz=30, seed=9))
    assert main(["study", str(m), "-o", str(out), "--cache-dir", str(cache), "--no-progress"]) == 3
    s = json.loads((out / "study.json").read_text())
    assert s["counts"]["resumed"] == 7
    new = {r["viewing"]: r for r in _rows(out / "viewings.csv")}
    old = {r["viewing"]: r for r in csv.DictReader(before.decode().splitlines())}
    assert new["clip-P04-NR"]["epof_mean_dps"] != old["clip-P04-NR"]["epof_mean_dps"]
    assert new["clip-P03-NR"] == old["clip-P03-NR"]
    # An interrupted study (no study.json, one viewing's outputs missing) resumes.
    (out / "study.json").unlink()
    (out / "epof" / "clip-P03-NR.csv").unlink()
    assert main(["study", str(m), "-o", str(out), "--cache-dir", str(cache), "--no-progress"]) == 3
    s = json.loads((out / "study.json").read_text())
    assert s["counts"]["resumed"] == 7 and (out / "epof" / "clip-P03-NR.csv").is_file()
    # Another study (other OUTDIR) on the same video reuses the cached grid.
    out2 = tmp_path / "o2"
    assert main(["study", str(m), "-o", str(out2), "--cache-dir", str(cache), "--no-progress"]) == 3
    assert json.loads((out2 / "study.json").read_text())["videos"]["clip"]["cache"] == "hit"


@pytest.mark.gl
@pytest.mark.slow
def test_questionnaires_analysis(base, tmp_path):
    """[questionnaires]: the analyze report, each participant's flow = mean of their EPOF."""
    rows = list(csv.reader(ln for ln in EXAMPLE.read_text().splitlines() if not ln.startswith("#")))
    header, data = rows[0], rows[1:]
    q = tmp_path / "q.csv"
    with open(q, "w", newline="") as fh:
        w = csv.writer(fh)
        cols = [c for c in header if c not in ("id", "condition", "flow")]
        w.writerow(["participant", *cols])
        pids = ["P02", "P03", "P04", "multi_user1", "multi_user2", "multi_user3"]
        for pid, r in zip(pids, data):
            w.writerow([pid, *(r[header.index(c)] for c in cols)])
    extra = f'\n[questionnaires]\npath = "{q}"\n'
    d = tmp_path / "b"
    shutil.copytree(base, d, ignore=shutil.ignore_patterns("cache"))
    out = tmp_path / "o"
    argv = ["study", str(_manifest(d, extra)), "-o", str(out), "--cache-dir", str(base / "cache")]
    assert main([*argv, "--no-progress"]) == 3
    scores = {r["id"]: r for r in _rows(out / "analysis" / "scores.csv")}
    assert sorted(scores) == sorted(pids)
    for pid in pids:
        vid = f"clip-{pid}-" + ("GR" if pid == "P02" else "NR")
        e = _epof_rows(out / "epof" / f"{vid}.csv")[:, 5]
        np.testing.assert_allclose(float(scores[pid]["flow"]), e.mean(), rtol=1e-8)
        assert scores[pid]["condition"] == vid.rsplit("-", 1)[1]
    assert (out / "analysis" / "table.csv").is_file() and (out / "analysis" / "report.md").is_file()


BAD = {
    "unknown key": ('[[videos]]\nid = "clip"\npath = "clip.mp4"\n[[viewings]]\nvideo = "clip"\ntrace = "P01.csv"\nusr = 3\n',
                    "[[viewings]] #1 (video 'clip'): unknown key 'usr'"),
    "missing video": ('[[videos]]\nid = "clip"\npath = "clip.mp4"\n[[viewings]]\nvideo = "nope"\ntrace = "P01.csv"\n',
                      "video 'nope' is not a [[videos]] id"),
    "glob": ('[[videos]]\nid = "clip"\npath = "clip.mp4"\n[[viewings]]\nvideo = "clip"\ntrace = "zz*.csv"\n',
             "matches no file"),
    "duplicate": (('[[videos]]\nid = "clip"\npath = "clip.mp4"\n[[viewings]]\nvideo = "clip"\ntrace = "P01.csv"\n'
                   '[[viewings]]\nvideo = "clip"\ntrace = "P01.csv"\n'), "duplicate viewing id 'clip-P01'"),
    "video file": ('[[videos]]\nid = "clip"\npath = "none.mp4"\n[[viewings]]\nvideo = "clip"\ntrace = "P01.csv"\n',
                   "[[videos]] #1 ('clip'): "),
    "toml": ("[[videos]\n", "not valid TOML"),
    "projection": (('[[videos]]\nid = "clip"\npath = "clip.mp4"\nprojection = "mercator"\n'
                   '[[viewings]]\nvideo = "clip"\ntrace = "P01.csv"\n'), "projection = 'mercator': expected one of"),
    "lens fov": (('[[videos]]\nid = "clip"\npath = "clip.mp4"\nprojection = "dfisheye"\nlens_fov = 120\n'
                 '[[viewings]]\nvideo = "clip"\ntrace = "P01.csv"\n'), "lens_fov = 120: expected a number in (180.0, 360.0]"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_manifest(case, base, tmp_path, capsys):
    text, want = BAD[case]
    m = base / f"bad_{case.replace(' ', '_')}.toml"
    m.write_text(text)
    out = tmp_path / "o"
    assert main(["study", str(m), "-o", str(out), "--cache-dir", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(m) in err[0] and want in err[0], err
    assert not out.exists()  # nothing started


@pytest.mark.parametrize(("executor", "want"), [("slurm", "unknown executor 'slurm'"),
                                                ("ray:127.0.0.1:1", "unreachable")])  # fmt: skip
def test_bad_executor(executor, want, base, tmp_path, capsys):
    out = tmp_path / "o"
    argv = ["study", str(_manifest(base)), "-o", str(out), "--executor", executor]
    assert main([*argv, "--cache-dir", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and want in err[0], err
    assert not out.exists()


def test_output_is_an_input_refused(base, tmp_path, capsys):
    m = _manifest(base)
    assert main(["study", str(m), "-o", str(base / "P01.csv"), "--cache-dir", str(tmp_path)]) == 2
    assert "existing file" in capsys.readouterr().err


def test_example_manifest_tables():
    """examples/study.toml: its option tables validate (its media paths are placeholders)."""
    import tomllib

    from simulator.study import manifest as mf

    d = tomllib.loads((EXAMPLE.parent / "study.toml").read_text())
    assert set(d) == set(mf._TOP_KEYS)
    ep, rd, gr = (mf._epof(EXAMPLE, d["epof"]), mf._render(EXAMPLE, d["render"]),
                  mf._grf(EXAMPLE, d["grf"]))  # fmt: skip
    assert rd["eye_size"] == [480, 480] and gr["inner_deg"] == 18.0 and ep["low_pct"] == 10.0
    for t in d["videos"]:
        assert set(t) <= set(mf._VIDEO_KEYS)
    for t in d["viewings"]:
        assert set(t) <= set(mf._VIEWING_KEYS)


def test_provocative_moments_separation():
    """Largest entries first; a smaller peak within 2 s and 90 deg of a larger one is
    skipped, one far in time or across the yaw seam (wrap-around) is kept."""
    from simulator.study.outputs import provocative_moments

    yaw = np.arange(-172.5, 180, 15.0)  # 24 columns
    m = np.zeros((100, 24))
    m[50, 0] = 10.0  # yaw -172.5 at 5.0 s
    m[52, 1] = 9.0  # 0.2 s and 15 deg away: suppressed
    m[51, 23] = 8.5  # 172.5 = 15 deg across the seam: suppressed
    m[51, 12] = 8.0  # 7.5 deg: 180 deg away: kept
    m[80, 0] = 7.0  # 3 s later: kept
    got = provocative_moments(m, yaw, fps=10.0, n=3)
    assert [(g["frame"], g["yaw_deg"]) for g in got] == [(50, -172.5), (51, 7.5), (80, -172.5)]
    assert [g["pof_dps"] for g in got] == [10.0, 8.0, 7.0]


@pytest.mark.gl
@pytest.mark.slow
def test_render_mitigation_from_the_manifest(base, tmp_path, capsys):
    """[render] mitigation = "vignette" (and its parameters) reaches the viewing's render."""
    m = _manifest(base, extra='mitigation = "vignette"\naperture_min = 50\nfeather = 5')
    out = tmp_path / "o"
    rc = main(["study", str(m), "-o", str(out), "--cache-dir", str(base / "cache"),
               "--workers", "1", "--no-progress"])  # fmt: skip
    assert rc == 3  # the short trace still fails
    s = json.loads((out / "render" / "render-P01" / "summary.json").read_text())
    assert s["mitigation"]["kind"] == "vignette"
    assert s["mitigation"]["vignette"]["aperture_min_deg"] == 50.0
    assert s["mitigation"]["vignette"]["feather_deg"] == 5.0
    bad = base / "bad_mitigation.toml"
    bad.write_text(_manifest(tmp_path, extra='mitigation = "tunnel"').read_text())
    capsys.readouterr()
    assert main(["study", str(bad), "-o", str(tmp_path / "b"), "--cache-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "mitigation" in err[0] and "bad_mitigation.toml" in err[0], err


def _renders_manifest(m: Path, video: str, traces: str, window: int, eye: str) -> Path:
    """A manifest ``m``: one sphere-mode video (its file ``video`` beside ``m``, id
    ``video``'s stem), every trace of the glob ``traces`` rendered at ``eye`` ("WxH")."""
    vid = Path(video).stem
    m.write_text(f"""
[[videos]]
id = "{vid}"
path = "{video}"
method = "sphere"
window_size = {window}

[[viewings]]
video = "{vid}"
trace = "{traces}"
participant = "{{stem}}"
render = true

[render]
eye_size = "{eye}"
""")
    return m


@pytest.mark.gl
@pytest.mark.slow
@pytest.mark.parametrize("kills", [1, 99], ids=["killed-once", "always-dies"])
def test_worker_process_death(kills, base, tmp_path, monkeypatch, capsys):
    """A worker process that dies (killed, out of memory, a crash in a native library)
    takes the local pool down with the tasks it ran: they are run once more, each alone on
    new workers, so a one-off death costs nothing; a task whose worker dies every time
    fails with one line, every other viewing completes, exit 3, no traceback."""
    import os

    from simulator.study import runner, tasks
    from simulator.study.executors import LocalExecutor

    runs: dict[str, int] = {}

    class Dying(LocalExecutor):
        def submit(self, fn, *args, **kw):
            if fn is tasks.render_task and args[2]["id"] == "clip-P02":
                runs["P02"] = runs.get("P02", 0) + 1
                if runs["P02"] <= kills:
                    return super().submit(os._exit, 9, **kw)  # the worker dies
            return super().submit(fn, *args, **kw)

    monkeypatch.setattr(runner, "make_executor", lambda text, workers: Dying(2))
    # a copy of the base folder without its cache: the grid is made in this run
    d = tmp_path / "in"
    d.mkdir()
    for f in base.glob("P0*.csv"):
        shutil.copy(f, d)
    shutil.copy(base / "clip.mp4", d)
    out = tmp_path / "o"
    m = _renders_manifest(d / "crash.toml", "clip.mp4", "P0*.csv", 64, "32x32")
    rc = main(["study", str(m), "-o", str(out), "--cache-dir",
               str(base / "cache"), "--no-progress"])  # fmt: skip
    err = capsys.readouterr().err
    assert "Traceback" not in err
    rows = {r["viewing"]: r for r in _rows(out / "viewings.csv")}
    assert (out / "study.json").is_file()
    if kills == 1:
        assert rc == 0 and runs["P02"] == 2, err
        assert all(r["status"] == "ok" for r in rows.values())
        assert (out / "render" / "clip-P02" / "left.mp4").is_file()
    else:
        assert rc == 3 and runs["P02"] == runner.TASK_ATTEMPTS
        assert rows["clip-P02"]["status"] == (
            "render: internal error: worker failed: a worker process died (killed, out of "
            "memory or crashed)"
        )
        lines = [ln for ln in err.splitlines() if "clip-P02" in ln]
        assert len(lines) == 1, err
        # the task beside it when it died ran again, alone, as did the dying one
        assert [v for v, r in rows.items() if r["status"] != "ok"] == ["clip-P02"]


@pytest.mark.gl
@pytest.mark.slow
def test_interrupted_study_resumes(base, tmp_path):
    """Ctrl-C (SIGINT) while the study runs: one line, exit 130, no temporary file and
    no study.json left; the viewings finished before it keep their state records, and
    the next run on the same OUTDIR skips them and completes the rest."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from simulator.synth import SynthConfig, synthesize

    d = tmp_path / "in"
    d.mkdir()
    synthesize(SynthConfig("rotate", seconds=12, fps=10, size=(128, 64)), d / "long.mp4")
    for i in range(6):
        save_headpath_csv(d / f"P{i + 1}.csv", synth("look-around", 12.5, rate_hz=30, seed=i))
    m = _renders_manifest(d / "s.toml", "long.mp4", "P*.csv", 32, "160x160")
    out = tmp_path / "o"
    argv = [sys.executable, "-m", "simulator", "study", str(m), "-o", str(out), "--cache-dir",
            str(tmp_path / "cache"), "--workers", "1", "--no-progress"]  # fmt: skip
    p = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         env=dict(os.environ, PYTHONUNBUFFERED="1"))  # fmt: skip
    t0 = time.monotonic()
    state = out / "state"
    while p.poll() is None and time.monotonic() - t0 < 120:
        if state.is_dir() and len(list(state.glob("*.json"))) >= 2:
            break
        time.sleep(0.02)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    err = err.decode()
    done = sorted(q.stem for q in state.glob("*.json"))
    assert p.returncode == 130, err  # (0: it finished first: the renders must be longer)
    assert len(err.strip().splitlines()) == 1 and "SIGINT" in err and "Traceback" not in err
    assert not [q for q in out.rglob("*") if ".tmp-" in q.name]
    assert not (out / "study.json").exists()
    assert 2 <= len(done) < 6, done
    assert main([*argv[3:], "--resume"]) == 0
    s = json.loads((out / "study.json").read_text())
    assert s["counts"]["ok"] == 6 and s["counts"]["resumed"] == len(done), s["counts"]
    for r in _rows(out / "viewings.csv"):
        assert r["status"] == "ok"
        assert (out / "render" / r["viewing"] / "summary.json").is_file()
