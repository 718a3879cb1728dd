"""Property-based fuzzing of every reader: random bytes and mutated valid files
fed to the head-path formats, grid files, EPOF CSVs, study manifests, camera CSVs,
``frames.json`` and study data. Each must read the file or raise ``InputError`` (which
the CLI prints as one line, exit 2): never any other exception (a traceback).

Short by default (``VIMSIM_FUZZ_EXAMPLES``, default 15 examples per reader); a long run:
``VIMSIM_FUZZ_EXAMPLES=2000 pytest tests/test_fuzz.py --hypothesis-show-statistics``
(``bench/fuzz_readers.py`` runs it and counts).
"""

from __future__ import annotations

import io
import json
import os
import shutil
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis", reason="hypothesis is a dev dependency")
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from simulator.core.errors import InputError

EXAMPLES = int(os.environ.get("VIMSIM_FUZZ_EXAMPLES", "15"))
FUZZ = settings(
    max_examples=EXAMPLES,
    deadline=None,
    derandomize=EXAMPLES <= 50,  # the short CI run is the same every time
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    database=None,
)
REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "headtraces"
#: Inputs tried per reader in this run; written to ``$VIMSIM_FUZZ_COUNTS`` (JSON) at the end.
COUNTS: dict[str, int] = {}


def _count(reader: str) -> None:
    COUNTS[reader] = COUNTS.get(reader, 0) + 1


@pytest.fixture(scope="module", autouse=True)
def _write_counts():
    yield
    if os.environ.get("VIMSIM_FUZZ_COUNTS"):
        Path(os.environ["VIMSIM_FUZZ_COUNTS"]).write_text(json.dumps(COUNTS, indent=1))


EXAMPLE_DATA = Path(__file__).resolve().parents[1] / "examples" / "study_example.csv"


# ------------------------------------------------------------------- mutations
@st.composite
def mutated(draw, seed: bytes) -> bytes:
    """``seed`` with a few random edits: byte flips, cuts, insertions, duplicated or
    dropped lines, a cell replaced by an extreme number or text."""
    data = bytearray(seed)
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["flip", "cut", "insert", "dup", "drop", "cell"]))
        n = len(data)
        i = draw(st.integers(0, max(0, n - 1)))
        if op == "flip" and n:
            data[i] = draw(st.integers(0, 255))
        elif op == "cut":
            data = data[:i]
        elif op == "insert":
            data[i:i] = draw(st.binary(min_size=1, max_size=20))
        elif op in ("dup", "drop"):
            lines = bytes(data).split(b"\n")
            k = draw(st.integers(0, max(0, len(lines) - 1)))
            if op == "dup":
                lines.insert(k, lines[k])
            else:
                del lines[k]
            data = bytearray(b"\n".join(lines))
        elif op == "cell":
            cell = draw(st.sampled_from([b"nan", b"inf", b"-1e308", b"1e308", b"", b"x",
                                         b"\"", b"0" * 400, b"-0", b"1e-320", b"\xff"]))  # fmt: skip
            seps = [j for j, c in enumerate(data) if c in b", \t\n"] or [0]
            j = draw(st.sampled_from(seps))
            data[j + 1 : j + 1] = cell
    return bytes(data)


def inputs(seeds: list[bytes]):
    """Random bytes, random text, or a mutated seed."""
    choices = [st.binary(max_size=600), st.text(max_size=300).map(lambda t: t.encode("utf-8"))]
    choices += [mutated(s) for s in seeds]
    return st.one_of(*choices)


def _reads(fn, data: bytes, name: str) -> None:
    """``fn(path)`` on ``data`` written as ``name``: it returns or raises InputError."""
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / name
        p.write_bytes(data)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                fn(p)
            except InputError as e:
                assert str(e).strip(), "an empty message"


# ------------------------------------------------------------------- seeds
def _canonical() -> bytes:
    return b"time_s,yaw_deg,pitch_deg,roll_deg\n" + b"".join(
        f"{k / 10},{k * 3 - 20},{k - 5},{k % 3}\n".encode() for k in range(12)
    )


def _real(rel: str, lines: int = 40) -> bytes | None:
    p = REAL / rel
    if not p.is_file():
        return None
    with open(p, "rb") as fh:
        return b"".join(fh.readline() for _ in range(lines))


def _vidstr() -> bytes:
    t = np.arange(0, 2.01, 0.1)
    rows = [" ".join(f"{v:.3f}" for v in t)]
    for u in range(2):
        rows.append(" ".join(f"{0.1 * u:.3f}" for _ in t))
        rows.append(" ".join(f"{0.3 * u + 0.2 * k:.3f}" for k in range(len(t))))
    return ("\n".join(rows) + "\n").encode()


HEADPATH_SEEDS = {
    "canonical": [_canonical()],
    "keyframes-json": [
        json.dumps(
            [
                {"time_s": 0, "yaw_deg": 1, "pitch_deg": 2},
                {"time_s": 1, "yaw_deg": 30, "pitch_deg": -5},
            ]
        ).encode()
    ],
    "360vidstr": [_vidstr()],
    "corbillon": [_real("corbillon_mmsys18_multiviewpoint/user1_quaternion.txt")],
    "corbillon-euler": [_real("corbillon_mmsys18_multiviewpoint/user1_euler.txt")],
    "salient360-dyn": [_real("salient360_toolbox_raw/rawDataDyn1.csv")],
    "salient360-static": [_real("salient360_toolbox_raw/rawDataStatic1.csv")],
    "quat": [b"time_s,qx,qy,qz,qw\n0,0,0,0,1\n0.5,0,0.1,0,0.995\n1,0,0.2,0,0.98\n"],
    "avtrack360": [],
}


@pytest.mark.parametrize("fmt", ["auto", *HEADPATH_SEEDS])
def test_fuzz_headpath_readers(fmt):
    from simulator.traces.readers import load_all_users, load_headpath

    seeds = [s for s in HEADPATH_SEEDS.get(fmt, []) if s] or [_canonical()]
    if fmt == "auto":
        seeds = [s for v in HEADPATH_SEEDS.values() for s in v if s]

    @FUZZ
    @given(inputs(seeds), st.booleans())
    def run(data, every_user):
        _count(f"headpath {fmt}")
        read = load_all_users if every_user else load_headpath
        _reads(lambda p: read(p, fmt), data, "trace.json" if "json" in fmt else "trace.csv")

    run()


# ------------------------------------------------------------------- grid files
@pytest.fixture(scope="module")
def grids(tmp_path_factory) -> dict[str, bytes]:
    """A paper and a sphere grid file of a tiny synthetic clip (bytes)."""
    from simulator.cli import main

    d = tmp_path_factory.mktemp("fuzz")
    assert main(["synth", str(d / "v.mp4"), "--scene", "rotate", "--seconds", "0.3",
                 "--fps", "10", "--size", "64x32"]) == 0  # fmt: skip
    pre = ["preprocess", str(d / "v.mp4"), "--window-size", "16", "--no-progress"]
    assert main([*pre, "-o", str(d / "G.npz")]) == 0
    assert main([*pre, "-o", str(d / "S.npz"), "--method", "sphere", "--cell", "30"]) == 0
    assert main(["epof", str(d / "G.npz"), str(d / "P.csv"), "-o", str(d / "e.csv")]) in (0, 2)
    return {n: (d / n).read_bytes() for n in ("G.npz", "S.npz")}


def _load_grid_fully(p: Path) -> None:
    from simulator.media.gridfile import load_grid

    g = load_grid(p)
    if g.field_dps is not None:
        np.asarray(g.field_dps[: len(g.field_dps)])  # every row of a lazy field


def test_fuzz_grid_bytes(grids):
    @FUZZ
    @given(inputs(list(grids.values())))
    def run(data):
        _count("grid file (bytes)")
        _reads(_load_grid_fully, data, "g.npz")

    run()


_ARRAYS = st.one_of(
    st.builds(np.array, st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=8)),
    st.builds(np.array, st.lists(st.integers(-(2**40), 2**40), max_size=8)),
    st.builds(lambda s: np.array(s), st.text(max_size=40)),
    st.builds(lambda n, m: np.zeros((n, m), np.float32), st.integers(0, 4), st.integers(0, 4)),
    st.builds(lambda n: np.zeros((n, 11, 24), np.float16), st.integers(0, 3)),
    st.just(np.array(True)),
)


def test_fuzz_grid_arrays(grids):
    """Valid zip files whose arrays are replaced, dropped or given random meta: the
    checks behind the zip layer (dtypes, shapes, meta fields)."""

    @FUZZ
    @given(st.sampled_from(sorted(grids)), st.data())
    def run(name, data):
        _count("grid file (arrays, meta)")
        with np.load(io.BytesIO(grids[name]), allow_pickle=False) as z:
            arrs = {k: z[k] for k in z.files}
        key = data.draw(st.sampled_from(sorted(arrs)))
        how = data.draw(st.sampled_from(["replace", "drop", "meta"]))
        if how == "replace":
            arrs[key] = data.draw(_ARRAYS)
        elif how == "drop":
            del arrs[key]
        else:
            meta = json.loads(str(arrs["meta"]))
            k = data.draw(st.sampled_from(sorted(meta)))
            meta[k] = data.draw(st.one_of(st.none(), st.integers(), st.floats(), st.text(max_size=9),
                                          st.lists(st.integers(), max_size=3)))  # fmt: skip
            arrs["meta"] = np.array(json.dumps(meta))
        buf = io.BytesIO()
        np.savez(buf, **arrs)
        _reads(_load_grid_fully, buf.getvalue(), "g.npz")

    run()


# ------------------------------------------------------------------- text readers
EPOF_SEED = (
    b'# epof_method: "paper"\n# opacity_thresholds_dps: [1.0, 2.0]\n'
    b"frame,time_s,yaw_deg,pitch_deg,roll_deg,epof_dps,opacity\n"
    + b"".join(f"{k},{k / 10},{k},{k / 2},0,{k * 1.5},{min(1, k / 5)}\n".encode() for k in range(8))
)
MANIFEST_SEED = b"""[study]
name = "t"

[[videos]]
id = "a"
path = "v.mp4"
window_size = 32

[[viewings]]
video = "a"
trace = "P.csv"
participant = "{stem}"

[render]
eye_size = "64x64"
"""
CAMERA_SEED = b"time_s,x_m,y_m,z_m,yaw_deg,pitch_deg,roll_deg\n" + b"".join(
    f"{k / 4},{k * 0.1},1.6,{k * 0.5},{k * 2},0,0\n".encode() for k in range(10)
)


def test_fuzz_epof_csv():
    from simulator.epof.viewing import read_epof_csv

    @FUZZ
    @given(inputs([EPOF_SEED]))
    def run(data):
        _count("EPOF CSV")
        _reads(read_epof_csv, data, "e.csv")

    run()


def test_fuzz_study_manifest(tmp_path_factory):
    from simulator.study.manifest import load_manifest

    d = tmp_path_factory.mktemp("manifest")  # the files a valid manifest names
    (d / "v.mp4").write_bytes(b"\0" * 64)
    (d / "P.csv").write_bytes(_canonical())

    @FUZZ
    @given(inputs([MANIFEST_SEED]))
    def run(data):
        _count("study manifest")
        m = d / "s.toml"
        m.write_bytes(data)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                load_manifest(m)
        except InputError as e:
            assert str(e).strip()

    run()


def test_fuzz_camera_csv():
    from simulator.synth.camera_path import load_camera_csv

    @FUZZ
    @given(inputs([CAMERA_SEED]))
    def run(data):
        _count("camera CSV")
        _reads(load_camera_csv, data, "camera.csv")

    run()


def test_fuzz_study_data():
    from simulator.analyze.data import read_study

    @FUZZ
    @given(inputs([EXAMPLE_DATA.read_bytes()]))
    def run(data):
        _count("study data (analyze)")
        _reads(read_study, data, "DATA.csv")

    run()


def test_fuzz_frames_json(tmp_path_factory):
    """``compare --update`` reads the goldens' frames.json (which frames it may remove)."""
    from PIL import Image

    from simulator.testing.compare import update_goldens

    d = tmp_path_factory.mktemp("frames")
    Image.new("RGB", (8, 8)).save(d / "t0000.100_both.png")
    seed = json.dumps({"frames": [{"file": "t0000.100_both.png"}, {"file": "t0000.200_both.png"}]})

    @FUZZ
    @given(inputs([seed.encode()]))
    def run(data):
        _count("frames.json")
        with tempfile.TemporaryDirectory() as t:
            new, gold = Path(t) / "new", Path(t) / "gold"
            new.mkdir()
            shutil.copy(d / "t0000.100_both.png", new)
            gold.mkdir()
            Image.new("RGB", (8, 8), "red").save(gold / "t0000.200_both.png")
            (gold / "frames.json").write_bytes(data)
            try:
                update_goldens(new, gold)
            except InputError as e:
                assert str(e).strip()

    run()
