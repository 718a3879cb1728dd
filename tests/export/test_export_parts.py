"""The Unity export carries the EPOF's rotational part (vimsim_epof_rot.bin) for a sphere-mode grid with the per-frame camera rotation."""

from __future__ import annotations

import numpy as np

from simulator.epof import viewport_epof
from simulator.epof.parts import viewport_parts
from simulator.export import DATA_FILE, export_unity, read_export
from simulator.export.unity import ROT_FILE
from simulator.media.gridfile import load_grid, save_grid
from simulator.preprocess import SphereConfig, field_meta
from simulator.sphere.cells import CellGrid, window_pof
from simulator.sphere.geometry import lonlat_to_dir
from simulator.sphere.windows import grid_preset

CELL, T = 6.0, 4


def _grid(path, parts=True):
    rng = np.random.default_rng(2)
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
            "video": {"path": "x.mp4", "width": 512, "height": 256, "content_hash": "sha256:0"}}  # fmt: skip
    kw = {"field_trans_dps": st.astype(np.float32),
          "extras": {"ego_omega_dps": om.astype(np.float32),
                     "ego_confidence": np.ones(T, np.float32)}} if parts else {}  # fmt: skip
    save_grid(path, dps, px, grid, meta, field_dps=f, **kw)
    return path


def test_export_writes_the_rotational_part(tmp_path):
    g = load_grid(_grid(tmp_path / "g.npz"))
    res = export_unity(g, tmp_path / "out", dtype="float32")
    assert tmp_path / "out" / ROT_FILE in res.files
    head, data = read_export(tmp_path / "out" / DATA_FILE)
    rhead, rot = read_export(tmp_path / "out" / ROT_FILE)
    assert rot.shape == data.shape and rhead["mode"] == "sphere" and "rot" in rhead["part"]
    yaw, pitch = np.array([0.0, 40, -120, 170]), np.array([0.0, 20, -30, 60])
    want, _ = viewport_parts(g, yaw, pitch, 0.0)
    got = viewport_epof(rot, CELL, yaw, pitch, 0.0, hfov_deg=head["viewport"]["hfov_deg"],
                        vfov_deg=head["viewport"]["vfov_deg"])  # fmt: skip
    assert np.allclose(got, want, rtol=1e-5)
    # a grid without the parts: no rot file
    res = export_unity(load_grid(_grid(tmp_path / "o.npz", parts=False)), tmp_path / "o")
    assert not (tmp_path / "o" / ROT_FILE).exists()
    assert ROT_FILE not in [f.name for f in res.files]
