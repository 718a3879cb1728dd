"""The study's summary outputs: viewings.csv, per-video plots and provocative moments, the analysis.

Per video (``OUTDIR/videos/<video>/``): ``epof_viewers.png`` (EPOF over time of every
viewer, faint, with the median and the 10-90 % band across viewers), ``provocative.png``
(the time x yaw map of the flow of the windows on the horizon row -- pitch nearest 0 --
of the grid, deg/s, with the viewers' yaw as dots and the most provocative moments
numbered), ``moments.csv`` (rank, time, frame, yaw, pitch, POF) and ``moment_<k>.png`` (the
viewport of each moment, the grid's window FOV). Frames the viewings' EPOF CSVs mark as
artefacts (their ``artefact`` column) are left out of the ranking and greyed on the map. With ``[questionnaires]``:
``OUTDIR/analysis/`` holds the ``vimsim analyze`` report of the study, each participant's
session flow taken from their EPOF (``DATA.csv`` there is what was analysed).
"""

from __future__ import annotations

import concurrent.futures
import csv
import dataclasses
import json
import math
import platform
from pathlib import Path

import av
import cv2
import numpy as np
import scipy

from simulator import __version__
from simulator.analyze.data import read_study
from simulator.analyze.report import analyze_study, write_report
from simulator.analyze.stats import StatsOptions
from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output, write_csv
from simulator.discomfort.model import load_model
from simulator.discomfort.predict import predict_columns
from simulator.epof.viewing import EPOF_COLUMNS, read_epof_csv
from simulator.media.source import Source
from simulator.mitigation.bands import draw_bands
from simulator.sphere.geometry import extract_view
from simulator.study.tasks import PART_MEAN_COLUMNS
from simulator.traces.path import HeadPath

__all__ = [
    "add_predictions",
    "artefact_frames",
    "confound_notes",
    "provocative_moments",
    "versions",
    "write_study_outputs",
    "write_viewings_csv",
]

#: Moments listed per video, and how far apart (seconds, or degrees of yaw) they must be.
N_MOMENTS = 5
MOMENT_SEP_S = 2.0
MOMENT_SEP_DEG = 90.0
THUMB_SIZE = (192, 192)


def _cell(v) -> str:
    if isinstance(v, float):
        return f"{round(v, 9) + 0.0:.10g}" if math.isfinite(v) else ""
    return str(v)




def _part_means(epof_csv: Path) -> dict:
    """Means of ``epof_rot_dps`` / ``epof_trans_dps`` of a viewing's EPOF CSV, if any."""
    try:
        r = read_epof_csv(epof_csv)
    except (InputError, OSError):
        return {}
    if r.epof_rot_dps is None or r.epof_trans_dps is None:
        return {}
    means = (float(np.mean(r.epof_rot_dps)), float(np.mean(r.epof_trans_dps)))
    return dict(zip(PART_MEAN_COLUMNS, means))


def write_viewings_csv(path, rows: list[dict], columns) -> None:
    """One row per viewing, in manifest order; floats as the EPOF CSV writes them; then
    the means of the EPOF's rotational and translational parts (:data:`PART_MEAN_COLUMNS`)
    as the row has them (the EPOF task's), else read from the viewing's
    ``epof/<viewing>.csv`` beside ``path``."""
    columns = (*columns, *PART_MEAN_COLUMNS)
    table = []
    for r in rows:
        have = all(c in r for c in PART_MEAN_COLUMNS)  # the task's (or the resumed row's)
        if r.get("viewing") and r.get("status") == "ok" and not have:
            r = {**r, **_part_means(Path(path).parent / "epof" / f"{r['viewing']}.csv")}
        table.append([r.get(c, "") for c in columns])
    write_csv(path, columns, table, fmt=_cell)  # text cells guarded (csv_cell)


def add_predictions(model_path: Path, out: Path, grids: dict, table: list[dict]) -> dict:
    """``[model]``: each finished viewing's row of ``table`` gets the model's
    :data:`~simulator.discomfort.predict.MODEL_COLUMNS` (a per-viewing model: from the head
    pose of each frame in ``epof/<viewing>.csv``; else the video's prediction). Returns
    ``{viewing: reason}`` of those whose prediction could not be made (left empty)."""
    model = load_model(model_path)
    per_video: dict[str, dict] = {}
    failed: dict[str, str] = {}
    for r in table:
        if r.get("status") != "ok":
            continue
        try:
            if model.data["ratings"].get("per_viewing"):
                e = read_epof_csv(out / "epof" / f"{r['viewing']}.csv")
                hp = HeadPath.from_angles_deg(e.time_s, e.yaw_deg, e.pitch_deg, e.roll_deg)
                r.update(predict_columns(model, grids[r["video"]], hp))
            else:
                if r["video"] not in per_video:
                    per_video[r["video"]] = predict_columns(model, grids[r["video"]])
                r.update(per_video[r["video"]])
        except (InputError, OSError) as err:
            failed[r["viewing"]] = f"no predicted discomfort: {err}"
    return failed


def _load_epof(path: Path) -> np.ndarray:
    """(T, 7) array of an EPOF CSV (frame, time_s, yaw, pitch, roll, epof_dps, opacity),
    read by :func:`simulator.epof.read_epof_csv`."""
    return _read_epof(path)[0]


def _read_epof(path: Path) -> tuple[np.ndarray, tuple[str, ...] | None]:
    """:func:`_load_epof`'s array and the artefact kind of each row (None: no column)."""
    r = read_epof_csv(path)
    return np.column_stack([getattr(r, c) for c in EPOF_COLUMNS]).astype(np.float64), r.artefact


def artefact_frames(epofs: dict[str, tuple[np.ndarray, tuple[str, ...] | None]]) -> dict[int, str]:
    """``{frame: kind}`` of the frames any viewing's EPOF CSV marks as an artefact (its
    ``artefact`` column; the frame from its ``frame`` column)."""
    out: dict[int, str] = {}
    for a, kinds in epofs.values():
        for f, k in zip(a[:, 0], kinds or ()):
            if k:
                out.setdefault(int(f), k)
    return out


def provocative_moments(pof_ty, yaw_deg, fps: float, *, n: int = N_MOMENTS,
                        sep_s: float = MOMENT_SEP_S, sep_deg: float = MOMENT_SEP_DEG,
                        exclude=None) -> list[dict]:  # fmt: skip
    """The ``n`` largest entries of a (T, Y) time x yaw flow map (deg/s), each at least
    ``sep_s`` seconds or ``sep_deg`` degrees of yaw (wrapped) from every larger one;
    the rows ``exclude`` (a length-T bool array: artefact frames) never ranked."""
    m = np.asarray(pof_ty, np.float64)
    if exclude is not None:
        m = np.where(np.asarray(exclude, bool)[:, None], -np.inf, m)
    order = np.argsort(m, axis=None)[::-1]
    picked: list[tuple[int, int]] = []
    for flat in order:
        t, y = divmod(int(flat), m.shape[1])
        if not np.isfinite(m[t, y]):
            break
        ok = True
        for t2, y2 in picked:
            dyaw = abs((yaw_deg[y] - yaw_deg[y2] + 180.0) % 360.0 - 180.0)
            if abs(t - t2) / fps < sep_s and dyaw < sep_deg:
                ok = False
                break
        if ok:
            picked.append((t, y))
            if len(picked) == n:
                break
    return [
        {"rank": k + 1, "frame": t, "time_s": t / fps, "yaw_deg": float(yaw_deg[y]),
         "pof_dps": float(m[t, y])}
        for k, (t, y) in enumerate(picked)
    ]  # fmt: skip


def _thumbnails(source, moments: list[dict], hfov: float, vfov: float,
                folder: Path) -> None:  # fmt: skip
    """``moment_<rank>.png``: the viewport of each moment (one decoding pass)."""
    from PIL import Image

    want: dict[int, list[dict]] = {}
    for mo in moments:
        want.setdefault(mo["frame"], []).append(mo)
    for i, frame in source.frames_at(sorted(want)):
        for mo in want[i]:
            view = extract_view(frame, mo["yaw_deg"], mo["pitch_deg"], 0.0,
                                hfov_deg=hfov, vfov_deg=vfov, size=THUMB_SIZE)  # fmt: skip
            name = f"moment_{mo['rank']}.png"
            with atomic_output(folder / name) as tmp:
                Image.fromarray(view).save(tmp, format="PNG")
            mo["thumbnail"] = name


@dataclasses.dataclass(frozen=True)
class _GridMap:
    """What the plots need of a grid file (its window matrix, not its sphere field)."""

    pof_dps: np.ndarray
    yaw_deg: np.ndarray
    pitch_deg: np.ndarray
    fps: float
    hfov_deg: float
    vfov_deg: float


def _grid_map(path: Path) -> _GridMap:
    """The window matrix of a cached grid (written by this study's preprocess and loaded by
    its workers with :func:`simulator.media.gridfile.load_grid`); the field is not decompressed."""
    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(str(z["meta"]))
        return _GridMap(z["pof_dps"], z["yaw_deg"], z["pitch_deg"], float(meta["fps"]),
                        float(meta["grid"]["hfov_deg"]), float(meta["grid"]["vfov_deg"]))  # fmt: skip


def _video_outputs(v, grid_path: Path, epofs: dict[str, np.ndarray], folder: Path,
                   artefacts: dict[int, str] | None = None) -> dict:  # fmt: skip
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import patheffects

    folder.mkdir(parents=True, exist_ok=True)
    grid = _grid_map(grid_path)
    fps = grid.fps
    written: list[str] = []

    # EPOF across viewers.
    fig, ax = plt.subplots(figsize=(10, 3.8), dpi=110)
    if epofs:
        n = min(len(a) for a in epofs.values())
        stack = np.stack([a[:n, 5] for a in epofs.values()])
        t = next(iter(epofs.values()))[:n, 1]
        for row in stack:
            ax.plot(t, row, color="0.3", lw=0.5, alpha=0.15)
        lo, med, hi = np.percentile(stack, [10, 50, 90], axis=0)
        ax.fill_between(t, lo, hi, color="tab:blue", alpha=0.3, lw=0, label="10-90% of viewers")
        ax.plot(t, med, color="tab:blue", lw=1.4, label="median")
        ax.legend(loc="upper right", fontsize=8)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("EPOF (deg/s)")
    ax.set_ylim(bottom=0)
    draw_bands(ax)  # the named flow bands (docs/screen.md)
    ax.set_title(f"{v.id}: EPOF across {len(epofs)} viewers")
    fig.tight_layout()
    with atomic_output(folder / "epof_viewers.png") as tmp:
        fig.savefig(tmp)
    plt.close(fig)
    written.append("epof_viewers.png")

    # Time x yaw map on the horizon row, moments, thumbnails.
    p0 = int(np.argmin(np.abs(grid.pitch_deg)))
    pitch0 = float(grid.pitch_deg[p0])
    m = np.asarray(grid.pof_dps[:, p0, :], np.float64)
    art = {f: k for f, k in (artefacts or {}).items() if 0 <= f < m.shape[0]}
    bad = np.zeros(m.shape[0], bool)
    bad[list(art)] = True
    moments = provocative_moments(m, grid.yaw_deg, fps, exclude=bad)
    for mo in moments:
        mo["pitch_deg"] = pitch0
    src = Source.open(v.path, layout=v.layout, eye=v.eye, projection=v.projection,
                      lens_fov_deg=v.lens_fov_deg)  # fmt: skip
    for mo in moments:  # the frame's own time (a variable-rate video: not frame / fps)
        mo["time_s"] = float(src.info.times_s([mo["frame"]])[0])
    # the thumbnails decode (FFmpeg, outside the GIL) while the map is drawn
    pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="thumbnails")
    thumbs = pool.submit(_thumbnails, src, moments, grid.hfov_deg, grid.vfov_deg, folder)
    pool.shutdown(wait=False)
    fig, ax = plt.subplots(figsize=(10, 4.2), dpi=110)
    step = float(np.diff(grid.yaw_deg).mean()) if len(grid.yaw_deg) > 1 else 360.0
    T = m.shape[0]
    lo_yaw, hi_yaw = grid.yaw_deg[0] - step / 2, grid.yaw_deg[-1] + step / 2
    # Colour scale to the 99.5th percentile: a scene cut's single frame would flatten the rest.
    # (artefact frames left out of it too).
    vmax = max(float(np.percentile(m[~bad] if (~bad).any() else m, 99.5)), 1e-6)
    im = ax.imshow(m.T, origin="lower", aspect="auto", cmap="magma", vmin=0, vmax=vmax,
                   extent=(0, T / fps, lo_yaw, hi_yaw), interpolation="nearest")  # fmt: skip
    fig.colorbar(im, ax=ax, label=f"POF at pitch {pitch0:g} deg (deg/s)", extend="max")
    for a in epofs.values():
        k = max(1, len(a) // 300)
        y = (a[::k, 2] - lo_yaw) % 360.0 + lo_yaw  # the map's yaw range (wraps at the seam)
        ax.plot(a[::k, 1], y, ".", color="cyan", ms=1, alpha=0.3)
    ax.set_ylim(lo_yaw, hi_yaw)
    # Markers readable on any colour of the map: white with a black outline (and a black
    # disc behind the number), from black through magma's bright yellow.
    halo = [patheffects.withStroke(linewidth=3, foreground="black")]
    for mo in moments:
        ax.plot(mo["time_s"], mo["yaw_deg"], "o", mfc="black", mec="white", ms=14, mew=1.5,
                alpha=0.9, path_effects=halo)  # fmt: skip
        ax.annotate(str(mo["rank"]), (mo["time_s"], mo["yaw_deg"]), color="white", fontsize=8,
                    ha="center", va="center", weight="bold", path_effects=halo)  # fmt: skip
    ax.set_xlabel("time (s)")
    ax.set_ylabel("yaw (deg, + right)")
    for f in art:  # artefact frames greyed: left out of the ranking
        ax.axvspan(f / fps, (f + 1) / fps, color="0.6", lw=0)
    left = f"; {len(art)} artefact frames (grey) left out" if art else ""
    ax.set_title(f"{v.id}: where the video is provocative (viewers' yaw as dots{left})")
    fig.tight_layout()
    with atomic_output(folder / "provocative.png") as tmp:
        fig.savefig(tmp)
    plt.close(fig)
    written.append("provocative.png")
    thumbs.result()  # its error, if any, is this video's
    cols = ("rank", "time_s", "frame", "yaw_deg", "pitch_deg", "pof_dps", "thumbnail")
    write_csv(folder / "moments.csv", cols, [[mo.get(c, "") for c in cols] for mo in moments],
              fmt=_cell)  # fmt: skip
    written += ["moments.csv", *(mo["thumbnail"] for mo in moments if "thumbnail" in mo)]
    kinds: dict[str, int] = {}
    for k in art.values():
        kinds[k] = kinds.get(k, 0) + 1
    return {"files": written, "moments": moments, "artefact_frames_left_out": len(art),
            "artefact_kinds": kinds}  # fmt: skip


def _analysis(manifest, out: Path, table: list[dict]) -> dict:
    """The ``vimsim analyze`` report of the study into ``OUTDIR/analysis/``."""
    q = manifest.questionnaires
    folder = out / "analysis"
    folder.mkdir(exist_ok=True)
    text = Path(q["path"]).read_text(encoding="utf-8-sig")
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    reader = csv.reader(lines)
    header = [c.strip().lower() for c in next(reader)]
    key = "participant" if "participant" in header else "id"
    skip = {key, "id", "participant", "condition", "flow", "epof_csv"}
    extra = [c for c in header if c not in skip]
    ok: dict[str, list[dict]] = {}
    for r in table:
        if r["status"] == "ok":
            ok.setdefault(r["participant"], []).append(r)
    rows, seen = [], set()
    for cells in reader:
        rec = dict(zip(header, (c.strip() for c in cells)))
        pid = rec.get(key, "")
        seen.add(pid)
        vs = ok.get(pid, [])
        cond = rec.get("condition") or (
            vs[0]["condition"] if len({x["condition"] for x in vs}) == 1 else ""
        )
        flow = epof_csv = ""
        if len(vs) == 1:
            epof_csv = f"../epof/{vs[0]['viewing']}.csv"
        elif vs:  # several viewings: session flow over all their frames
            e = np.concatenate([_load_epof(out / "epof" / f"{x['viewing']}.csv")[:, 5] for x in vs])
            flow = _cell(
                float({"mean": np.mean, "median": np.median, "sum": np.sum}[q["flow_stat"]](e))
            )
        video = [] if "video" in header else [vs[0]["video"] if len({x["video"] for x in vs}) == 1 else ""]
        rows.append([pid, cond, *(rec.get(c, "") for c in extra), flow, epof_csv, *video])
    data = folder / "DATA.csv"
    # the video column lets the analysis give per-video tables and warn on pooled flows
    vcol = [] if "video" in header else ["video"]
    write_csv(data, ["id", "condition", *extra, "flow", "epof_csv", *vcol], rows, fmt=_cell)
    info = {"dir": str(folder), "data": str(data),
            "no_questionnaire": sorted(p for p in ok if p not in seen)}  # fmt: skip
    try:
        study = read_study(data, flow_stat=q["flow_stat"])
        kw = {"exclude_below": q["exclude_below"], "conditions": q["conditions"],
              "k_of_formula": q.get("k_of", "invariant")}  # fmt: skip
        try:  # the design's statistics (tests.csv, model.csv, analysis.md) where the data allow
            an = analyze_study(study, notes=confound_notes(table), stats=StatsOptions(), **kw)
        except InputError as e:  # too few for them: the paper's analysis alone, and why
            an = analyze_study(study, notes=[*confound_notes(table), f"no design statistics: {e}"],
                               **kw)  # fmt: skip
        info["files"] = [p.name for p in write_report(an, folder)]
        info["problems"] = list(study.problems)
        info["excluded"] = [f"{pid}: {why}" for pid, why in an.excluded]
        info["comparisons"] = an.comparisons
        info["notes"] = an.messages()
        info["error"] = None
    except InputError as e:
        info["error"] = str(e)
    return info


def confound_notes(table: list[dict]) -> list[str]:
    """A warning line when condition and video are confounded: no video was watched under
    two conditions, so a difference between conditions may be one between videos."""
    by_cond: dict[str, set[str]] = {}
    for r in table:
        if r["status"] == "ok" and r["condition"]:
            by_cond.setdefault(r["condition"], set()).add(r["video"])
    if len(by_cond) < 2:
        return []
    sets = list(by_cond.values())
    if any(sets[i] & sets[j] for i in range(len(sets)) for j in range(i + 1, len(sets))):
        return []
    per = "; ".join(f"{c} on {', '.join(sorted(v))}" for c, v in by_cond.items())
    line = f"WARNING: condition is confounded with video ({per}): a difference between "
    return [line + "conditions may be one between videos"]


def write_study_outputs(manifest, out: Path, grids: dict[str, Path], table: list[dict]) -> dict:
    """Per-video plots, moments and thumbnails; the analysis. Returns what was written
    (and the one-line error of any part that could not be made)."""
    report: dict = {"videos": {}}
    for v in manifest.videos:
        mine = [r for r in table if r["video"] == v.id and r["status"] == "ok"]
        read = {r["viewing"]: _read_epof(out / "epof" / f"{r['viewing']}.csv") for r in mine}
        epofs = {k: a for k, (a, _) in read.items()}
        try:
            if not grids[v.id].is_file():
                raise InputError("no grid (its preprocessing failed)")  # the CLI names the video
            report["videos"][v.id] = _video_outputs(v, grids[v.id], epofs, out / "videos" / v.id,
                                                    artefact_frames(read))  # fmt: skip
        except InputError as e:
            report["videos"][v.id] = {"error": str(e)}
    if manifest.questionnaires:
        report["analysis"] = _analysis(manifest, out, table)
    return report


def versions(ex_info: dict) -> dict:
    """Versions of what computed the study."""
    v = {"vimsim": __version__, "python": platform.python_version(), "numpy": np.__version__,
         "scipy": scipy.__version__, "opencv": cv2.__version__, "av": av.__version__}  # fmt: skip
    if "ray_version" in ex_info:
        v["ray"] = ex_info["ray_version"]
    return v
