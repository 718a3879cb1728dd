"""vimsim screen: bad input is one line and exit 2, before any work."""

from __future__ import annotations

import numpy as np
import pytest
from media_helpers import cut_clip
from PIL import Image

from simulator.cli import main


@pytest.fixture
def still(tmp_path):
    p = tmp_path / "still.png"
    Image.fromarray(np.zeros((64, 128, 3), np.uint8)).save(p)
    return p


@pytest.mark.parametrize(
    ("extra", "msg"),
    [
        (["--viewers", "0"], "--viewers"),
        (["--viewer-kind", "zigzag"], "unknown viewer kind"),
        (["--opacity-rule", "absolute", "--low-dps", "30", "--high-dps", "5"], "--low-dps"),
        (["--opacity-rule", "absolute", "--low-dps", "5", "--high-dps", "5"], "--low-dps"),
        (["--opacity-rule", "absolute", "--high-dps", "nan"], "--high-dps"),
        (["--opacity-rule", "absolute", "--low-dps", "inf"], "--low-dps"),
        (["--low-dps", "3"], "--opacity-rule absolute"),
    ],
)
def test_bad_options_exit_2(tmp_path, still, capsys, extra, msg):
    out = tmp_path / "out"
    try:
        rc = main(["screen", str(still), "-o", str(out), "--no-progress", *extra])
    except SystemExit as e:  # an argparse usage error
        rc = e.code
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert msg in err
    assert not out.exists()


def test_still_image_exit_2(tmp_path, still, capsys):
    out = tmp_path / "out"
    assert main(["screen", str(still), "-o", str(out), "--no-progress", "--viewers", "2"]) == 2
    err = capsys.readouterr().err.strip()
    assert "still.png" in err and "still image" in err
    assert len(err.splitlines()) == 1
    assert not out.exists()


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    """A tiny calm clip and the same clip with a hard cut to a faster one at frame 10."""
    from simulator.synth import SynthConfig, synthesize

    d = tmp_path_factory.mktemp("screen")
    synthesize(
        SynthConfig("rotate", seconds=2.0, fps=10, size=(128, 64), omega_dps=3.0), d / "calm.mp4"
    )
    synthesize(SynthConfig("coaster", seconds=2.0, fps=10, size=(128, 64)), d / "ride.mp4")
    cut_clip(d / "calm.mp4", d / "ride.mp4", d / "cut.mp4")
    return d


@pytest.fixture(scope="module")
def screened(clips, tmp_path_factory):
    """The screening of the calm and the cut clip (3 viewers), its output folder."""
    d = tmp_path_factory.mktemp("screened")
    out, cache = d / "o", d / "cache"
    rc = main(["screen", str(clips / "calm.mp4"), str(clips / "cut.mp4"), "-o", str(out),
               "--viewers", "3", "--cache-dir", str(cache), "--workers", "1", "--no-progress",
               "--opacity-rule", "absolute"])  # fmt: skip
    assert rc == 0
    return out


def test_screen_end_to_end(clips, screened, tmp_path, capsys):
    out = screened
    table = [ln for ln in (out / "screen" / "comparison.csv").read_text().splitlines()]
    assert any(ln.startswith("# band provocative: 30 to 60 deg/s") for ln in table)
    rows = [ln.split(",") for ln in table if not ln.startswith("#")]
    head = rows[0]
    by = {r[0]: dict(zip(head, r)) for r in rows[1:]}
    assert set(by) == {"calm", "cut"} and by["calm"]["viewers"] == "3"
    assert by["cut"]["artefact_kinds"] == "cut:1"  # the cut found, left out
    assert float(by["calm"]["opacity_mean"]) == 0.0  # absolute rule: a calm clip, no grains
    assert by["calm"]["opacity_rule"] == "absolute 5-30 deg/s"
    epof = (out / "epof" / "cut-viewer001.csv").read_text().splitlines()
    data = [ln for ln in epof if not ln.startswith("#")]
    assert data[0].endswith(",artefact") and data[11].endswith(",cut")  # row of frame 10
    for f in ("summary.png", "map.png", "map.csv", "epof_distribution.csv", "sphere_flow.csv",
              "moments.csv", "moment_1.png"):  # fmt: skip
        assert (out / "screen" / "cut" / f).is_file()
    import csv
    import json

    # The whole sphere's flow, its translational part and the camera's rotation (sphere
    # mode records them): the rotating calm clip turns at 3 deg/s, mostly rotation.
    with open(out / "screen" / "calm" / "sphere_flow.csv") as fh:
        sf = [r for r in csv.DictReader(ln for ln in fh if not ln.startswith("#"))]
    rot = np.array([float(r["camera_rotation_dps"]) for r in sf[1:]])
    trans = np.array([float(r["sphere_trans_mean_dps"]) for r in sf[1:]])
    whole = np.array([float(r["sphere_mean_dps"]) for r in sf[1:]])
    assert np.all(np.isfinite(rot)) and 1.5 < np.median(rot) < 4.5, rot
    assert np.median(trans) < np.median(whole), (trans, whole)

    rep = json.loads((out / "screen" / "screen.json").read_text())
    assert [e["kind"] for e in rep["videos"]["cut"]["artefacts"]] == ["cut"]
    mo = (out / "screen" / "cut" / "moments.csv").read_text().splitlines()
    assert all(",10," not in ln.split("band")[0] for ln in mo[1:])  # never the cut frame
    # A grid already made is reused (and says so); the same numbers come out.
    from simulator.preprocess.sphere import preprocess_sphere
    from simulator.sphere.windows import grid_preset

    preprocess_sphere(clips / "calm.mp4", tmp_path / "calm.npz", grid=grid_preset("default"))
    capsys.readouterr()
    rc = main(["screen", str(clips / "calm.mp4"), "-o", str(tmp_path / "o2"), "--viewers", "3",
               "--cache-dir", str(tmp_path / "empty"), "--grid", str(tmp_path / "calm.npz"),
               "--workers", "1", "--no-progress", "--opacity-rule", "absolute"])  # fmt: skip
    assert rc == 0
    assert "reused" in capsys.readouterr().err
    assert not list((tmp_path / "empty" / "grids").glob("*.npz"))  # nothing preprocessed


def test_manifest_viewers_option(clips, tmp_path):
    from simulator.study.manifest import load_manifest

    shutil_copy = (clips / "calm.mp4").read_bytes()
    (tmp_path / "calm.mp4").write_bytes(shutil_copy)
    m = tmp_path / "s.toml"
    m.write_text('[[videos]]\nid = "calm"\npath = "calm.mp4"\nmethod = "sphere"\n\n'
                 '[[viewings]]\nvideo = "calm"\nviewers = { kind = "look-around", n = 4, seed = 7 }\n'
                 '\n[epof]\nartefacts = true\nopacity_rule = "absolute"\n')  # fmt: skip
    man = load_manifest(m)
    assert [w.id for w in man.viewings] == [f"calm-viewer{k:03d}" for k in range(1, 5)]
    assert [w.user for w in man.viewings] == [7, 8, 9, 10]
    assert man.epof["low_dps"] == 5.0 and man.videos[0].artefacts
    out = tmp_path / "o"
    from simulator.study.plan import dry_run  # scripted paths pass the dry run's checks

    plan = dry_run(man, out, cache_dir=tmp_path / "c")
    assert plan["problems"] == [] and plan["tasks"] == 1 + 4 and not out.exists()
    assert {v["trace"] for v in plan["viewings"]} == {""}
    assert main(["study", str(m), "-o", str(out), "--cache-dir", str(tmp_path / "c"),
                 "--workers", "1", "--no-progress"]) == 0  # fmt: skip
    assert len(list((out / "epof").glob("calm-viewer*.csv"))) == 4
    for bad, msg in (('viewers = { kind = "zigzag" }', "unknown viewer kind"),
                     ("viewers = { n = 0 }", "n = 0"),
                     ('viewers = { n = 2 }\ntrace = "x.csv"', "exclusive")):  # fmt: skip
        m.write_text(
            f'[[videos]]\nid = "calm"\npath = "calm.mp4"\n\n[[viewings]]\nvideo = "calm"\n{bad}\n'
        )
        with pytest.raises(Exception, match=msg):
            load_manifest(m)
    m.write_text('[[videos]]\nid = "calm"\npath = "calm.mp4"\n\n[[viewings]]\nvideo = "calm"\n'
                 'viewers = { n = 2 }\n\n[epof]\nopacity_rule = "absolute"\nlow_dps = 9\nhigh_dps = 3\n')  # fmt: skip
    with pytest.raises(Exception, match="low_dps"):
        load_manifest(m)


@pytest.mark.gl
def test_preprocess_stores_artefacts_for_render(clips, tmp_path):
    """preprocess --artefacts: found in the decoding pass, stored in the grid's meta, read
    back by what render and frames use."""
    from simulator.media.gridfile import load_grid
    from simulator.preprocess.artefacts import stored_artefacts

    out = tmp_path / "g.npz"
    assert main(["preprocess", str(clips / "cut.mp4"), "-o", str(out), "--method", "sphere",
                 "--artefacts", "--window-size", "64", "--no-progress"]) == 0  # fmt: skip
    g = load_grid(out)
    assert [e["kind"] for e in g.meta["artefacts"]["events"]] == ["cut"]
    art = stored_artefacts(g)
    assert art is not None and art.kind[10] == "cut" and sum(map(bool, art.kind)) == 1
    assert stored_artefacts(load_grid(_plain(clips, tmp_path))) is None
    # render's epof.csv names the artefact frames too (their opacity held)
    hp, r = tmp_path / "hp.csv", tmp_path / "r"
    assert main(["headpath", "synth", "static", "-o", str(hp), "--seconds", "3"]) == 0
    assert main(["render", str(clips / "cut.mp4"), str(hp), "-o", str(r), "--grid", str(out),
                 "--eye-size", "64x64", "--no-audio", "--no-progress"]) == 0  # fmt: skip
    rows = [ln for ln in (r / "epof.csv").read_text().splitlines() if not ln.startswith("#")]
    assert rows[0].endswith(",artefact") and rows[11].endswith(",cut")
    assert sum(ln.endswith(",cut") for ln in rows[1:]) == 1


def _plain(clips, tmp_path):
    out = tmp_path / "plain.npz"
    assert main(["preprocess", str(clips / "calm.mp4"), "-o", str(out), "--method", "sphere",
                 "--window-size", "64", "--no-progress"]) == 0  # fmt: skip
    return out


def test_a_users_grid_that_does_not_match_is_left_alone(tmp_path):
    """A study's ``grid_file`` that cannot serve its video: the cache's entry is used, the
    user's file is never removed (a stale cache entry is)."""
    from simulator.study.manifest import VideoSpec
    from simulator.study.plan import _grid_path

    video = tmp_path / "v.mp4"
    video.write_bytes(b"not a video")
    mine = tmp_path / "mine.npz"
    mine.write_bytes(b"not a grid")
    got = _grid_path(VideoSpec(id="v", path=video, grid_file=mine), tmp_path / "cache")
    assert got != mine and got.parent == tmp_path / "cache" / "grids"
    assert mine.read_bytes() == b"not a grid"


def _page_links(path):
    """Every ``src`` and ``href`` of an HTML file (the standard library's parser)."""
    from html.parser import HTMLParser

    links: list[str] = []

    class P(HTMLParser):
        def handle_starttag(self, tag, attrs):
            links.extend(v for k, v in attrs if k in ("src", "href") and v is not None)

    P().feed(path.read_text(encoding="utf-8"))
    return links


def test_screen_page_is_self_contained(screened):
    """screen/index.html: every link a file inside the screen folder; every video, its
    plots, moments (thumbnails and captions) and artefacts; the bands with their sources."""
    from urllib.parse import unquote, urlsplit

    folder = screened / "screen"
    page = folder / "index.html"
    text = page.read_text(encoding="utf-8")
    links = _page_links(page)
    files = []
    for ln in links:
        u = urlsplit(ln)
        if ln.startswith("#") or (u.scheme == "data"):
            continue
        assert not u.scheme and not u.netloc and not ln.startswith("/"), ln  # no CDN, relative
        f = (folder / unquote(u.path)).resolve()
        assert f.is_relative_to(folder.resolve()) and f.is_file(), ln
        files.append(unquote(u.path))
    for vid in ("calm", "cut"):
        assert f'id="v-{vid}"' in text and f'href="#v-{vid}"' in text
        for name in ("summary.png", "map.png", "moment_1.png", "moments.csv"):
            assert f"{vid}/{name}" in files
    assert "comparison.csv" in files and "screen.json" in files
    assert "vection" in text and "Nesti" in text  # a band and its source
    cut = text[text.index('id="v-cut"'):]
    assert "<td>cut</td><td>10-10</td>" in cut  # the cut listed, frame 10
    assert "#1: " in cut and "deg/s" in cut  # a moment's caption
    assert not list(folder.glob("*.tmp*"))  # nothing half-written; the folder's manifest only
    assert [p.name for p in folder.glob(".*")] == [".vimsim-manifest.json"]


@pytest.mark.browser
def test_screen_page_loads_clean(browser, screened):
    """The page loads from the file system with no console error and no failed image."""
    page = screened / "screen" / "index.html"
    browser.get(page.as_uri())
    console, urls = browser.drain()
    assert not [c for c in console if c["level"] == "SEVERE"], console
    assert not [u for u in urls if u.startswith(("http:", "https:"))], urls  # offline, no CDN
    assert any(u.endswith("/screen/cut/summary.png") for u in urls), urls
    broken = browser.driver.execute_script(
        "return [...document.images].filter(i => !i.complete || i.naturalWidth === 0).length"
    )
    assert broken == 0
    assert browser.driver.execute_script("return document.images.length") >= 4
