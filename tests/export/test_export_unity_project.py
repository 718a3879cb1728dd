"""Two Unity exports of two videos go into one project without a clash: one runtime package
(same name, same files, same GUIDs in every export), one data asset per video (GUIDs from
the video's content hash), every file with its ``.meta``."""

from __future__ import annotations

import json
import re
import shutil

import numpy as np

from simulator.export import DATA_FILE, export_unity
from simulator.export.unity import ASSET_FILES, ROT_FILE
from simulator.media.gridfile import save_grid
from simulator.preprocess import SphereConfig, field_meta
from simulator.sphere.cells import CellGrid, window_pof
from simulator.sphere.geometry import lonlat_to_dir
from simulator.sphere.windows import grid_preset

CELL, T = 6.0, 4
_GUID = re.compile(rb"^guid: ([0-9a-f]{32})$", re.MULTILINE)


def _grid(path, content_hash: str, seed: int):
    """A sphere-mode grid with the camera's rotation (so the export has ROT_FILE too)."""
    rng = np.random.default_rng(seed)
    cells = CellGrid(CELL)
    d = lonlat_to_dir(*np.meshgrid(*cells.centres_lonlat()))
    om = rng.normal(0, 30, (T, 3))
    sr = np.linalg.norm(np.cross(om[:, None, None], d[None]), axis=-1)
    st = 10 + 10 * rng.random((T, *cells.shape))
    f = (sr + st).astype(np.float32)
    grid = grid_preset("default")
    dps, px = window_pof(f, CELL, grid, 30.0)
    meta = {"fps": 30.0, "n_frames": T, "flow": {"method": "test"}, "layout": "mono",
            "eye": "left", "field": field_meta(SphereConfig(cell_deg=CELL)),
            "video": {"path": f"{seed}.mp4", "width": 512, "height": 256,
                      "content_hash": content_hash}}  # fmt: skip
    save_grid(path, dps, px, grid, meta, field_dps=f, field_trans_dps=st.astype(np.float32),
              extras={"ego_omega_dps": om.astype(np.float32),
                      "ego_confidence": np.ones(T, np.float32)})  # fmt: skip
    return path


def _files(folder) -> dict[str, bytes]:
    return {
        p.relative_to(folder).as_posix(): p.read_bytes() for p in folder.rglob("*") if p.is_file()
    }


def test_two_exports_import_into_one_project(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    export_unity(_grid(tmp_path / "a.npz", "sha256:aaaa", 1), a)
    export_unity(_grid(tmp_path / "b.npz", "sha256:bbbb", 2), b)
    fa, fb = _files(a), _files(b)
    for files in (fa, fb):
        assert ROT_FILE in files and f"{ROT_FILE}.meta" in files
        # every file and folder has its .meta, and no .meta is an orphan
        things = set(files) | {p.rsplit("/", 1)[0] for p in files if "/" in p}
        for rel in things - {r for r in things if r.endswith(".meta")}:
            assert f"{rel}.meta" in files, rel
        for m in (r for r in files if r.endswith(".meta")):
            assert m[:-5] in things, m
    # The runtime package: the same name, files, bytes and GUIDs in both exports.
    runtime = [*ASSET_FILES, *(f"{r}.meta" for r in ASSET_FILES), "Editor.meta"]
    assert all(fa[r] == fb[r] for r in runtime)
    assert json.loads(fa["package.json"])["name"] == json.loads(fb["package.json"])["name"]
    # The data: GUIDs from each video's content hash, different across videos.
    data_guids = {}
    for name, files in (("a", fa), ("b", fb)):
        for r in (DATA_FILE, ROT_FILE):
            data_guids[(name, r)] = _GUID.search(files[f"{r}.meta"]).group(1)
    assert len(set(data_guids.values())) == 4
    # One project: the runtime package from export a (with its data), b's data in Assets/.
    proj = tmp_path / "project"
    shutil.copytree(a, proj / "Packages" / "com.vimsim.epof")
    (proj / "Assets" / "VideoB").mkdir(parents=True)
    for r in (DATA_FILE, ROT_FILE):
        for name in (r, f"{r}.meta"):
            shutil.copyfile(b / name, proj / "Assets" / "VideoB" / name)
    owners: dict[bytes, str] = {}
    for m in proj.rglob("*.meta"):
        g = _GUID.search(m.read_bytes()).group(1)
        assert g not in owners, (m, owners.get(g))
        owners[g] = str(m)
    # A re-export of the same video keeps its data GUIDs (scene references survive).
    export_unity(_grid(tmp_path / "a2.npz", "sha256:aaaa", 3), tmp_path / "a2")
    assert (tmp_path / "a2" / f"{DATA_FILE}.meta").read_bytes() == fa[f"{DATA_FILE}.meta"]
    # Export again into a (its own files, data meta with another GUID): replaced, not refused.
    export_unity(_grid(tmp_path / "c.npz", "sha256:cccc", 4), a)
    assert _GUID.search((a / f"{DATA_FILE}.meta").read_bytes()).group(1) not in data_guids.values()
