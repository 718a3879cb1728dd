"""The screening report: per video the flow across viewers, the time x yaw map, moments, a summary page.

Per video (``OUTDIR/screen/<video>/``): ``epof_distribution.csv`` (per frame: viewers,
mean, 10th / 50th / 90th percentile of EPOF across viewers, artefact), ``map.csv`` (the
window flow of the grid, one row per frame and pitch, one column per yaw, deg/s),
``map.png`` (time x yaw on the horizon row, bands on the colour bar, artefact frames
greyed), ``sphere_flow.csv`` (the whole sphere's mean flow per frame), ``moments.csv`` and
``moment_<k>.png`` (the most provocative instants, artefacts left out, peaks at one
instant merged, each thumbnail captioned), ``summary.png`` (one page). Across videos:
``OUTDIR/screen/comparison.csv`` (:data:`SCREEN_COLUMNS`, the bands and their sources in
``#`` lines) and ``OUTDIR/screen/index.html`` (the one-page browser summary,
:mod:`simulator.screen.page`). Units: deg/s, seconds, degrees.
"""

from __future__ import annotations

import io
import math
import warnings
from pathlib import Path

import numpy as np

from simulator.core.fileio import OutputFolder, atomic_output, write_csv
from simulator.discomfort.predict import MODEL_COLUMNS, model_note, model_summary, predict_columns
from simulator.epof.viewing import read_epof_csv
from simulator.media.coverage import coverage_masks
from simulator.media.gridfile import load_grid
from simulator.media.lazyfield import field_chunks
from simulator.media.source import Source
from simulator.mitigation.bands import BANDS, band_of, draw_bands, rule_text, share_above
from simulator.preprocess.artefacts import KEPT_KINDS
from simulator.screen.page import write_screen_page
from simulator.sphere.geometry import extract_view

__all__ = ["SCREEN_COLUMNS", "write_screen_outputs"]

SCREEN_COLUMNS: tuple[str, ...] = (
    "video", "frames", "seconds", "viewers", "artefact_frames", "artefact_kinds",
    "epof_mean_dps", "epof_p90_dps", "band_p90",
    *(f"share_ge_{b.name}" for b in BANDS[1:]), "opacity_mean", "opacity_rule",
)  # fmt: skip
N_MOMENTS = 5
MOMENT_SEP_S = 2.0
#: The files of ``OUTDIR/screen/`` and of each ``OUTDIR/screen/<video>/``: each folder keeps
#: its manifest (:class:`~simulator.core.fileio.OutputFolder`), so a rerun replaces only
#: the files a screening wrote there.
SCREEN_FILES = ("comparison.csv", "index.html", "screen.json")
VIDEO_FILES = ("epof_distribution.csv", "map.csv", "sphere_flow.csv", "moments.csv", "map.png",
               "summary.png", *(f"moment_{k}.png" for k in range(1, N_MOMENTS + 1)))  # fmt: skip


def screen_folders(out: Path, video_ids) -> list[OutputFolder]:
    """``OUTDIR/screen/`` and its per-video folders as folder outputs (the first is the top);
    call ``check()`` on each before any work."""
    top = Path(out) / "screen"
    return [OutputFolder(top, SCREEN_FILES, "screen"),
            *(OutputFolder(top / vid, VIDEO_FILES, "screen") for vid in video_ids)]  # fmt: skip


def _fmt(v) -> str:
    if isinstance(v, (float, np.floating)):
        return f"{float(v) + 0.0:.10g}" if math.isfinite(v) else ""
    return str(v)


def _write_csv(path: Path, header, rows, comments=()) -> None:
    write_csv(path, header, rows, comments=comments, fmt=_fmt)  # the one guarded CSV writer


def _write_map(path: Path, frames, t, pitch, yaw, kinds, pof) -> None:
    """``map.csv``: one row per frame and pitch, one column per yaw (deg/s, 6 digits)."""
    buf = io.StringIO()
    buf.write(",".join(("frame", "time_s", "pitch_deg", "artefact", *(f"yaw_{y:g}" for y in yaw))))
    buf.write("\n")
    row = ",".join(["%.6g"] * len(yaw))
    for i in range(len(frames)):
        head = f"{int(frames[i])},{float(t[i]):.10g},"
        for j, pv in enumerate(pitch):
            buf.write(f"{head}{float(pv):g},{kinds[i]}," + row % tuple(pof[i, j]) + "\n")
    with atomic_output(path) as tmp:
        Path(tmp).write_text(buf.getvalue())


def _sphere_mean(f, covered=None) -> np.ndarray:
    """Per frame, the solid-angle-weighted mean of a lon/lat field ``(T, n_lat, n_lon)``
    (deg/s) over the cells ``covered`` (bool ``(n_lat, n_lon)``, None: all; a VR180
    source's back half has no flow measured), read chunk by chunk (a lazy grid field:
    memory flat in the video's length)."""
    lat = (np.arange(f.shape[1]) + 0.5) / f.shape[1] * np.pi - np.pi / 2
    w = np.cos(lat)[:, None] * np.ones(f.shape[2])
    if covered is not None and covered.shape == w.shape and covered.any():
        w = w * covered
    out = [(np.asarray(b, np.float64) * w).sum(axis=(1, 2)) / w.sum() for _, b in field_chunks(f)]
    return np.concatenate(out)


def _grid_arrays(path: Path) -> dict:
    """Window matrix, axes, fps and per frame the sphere's mean flow (the field's, else the
    windows'), its translational part and the camera's rotation speed (NaN where the grid
    does not record them)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g = load_grid(path)
    meta = g.meta
    d = {"pof": np.asarray(g.pof_dps, np.float64), "yaw": g.yaw_deg, "pitch": g.pitch_deg,
         "fps": float(g.fps), "start": int(meta.get("start_frame", 0)),
         "hfov": float(meta["grid"]["hfov_deg"]), "vfov": float(meta["grid"]["vfov_deg"])}  # fmt: skip
    wins, cells = coverage_masks(meta)  # a projection covering part of the sphere: that part
    if g.field_dps is not None:
        d["sphere"] = _sphere_mean(g.field_dps, cells)
    else:  # no field: the windows' mean
        pof = d["pof"] if wins is None or not wins.any() else d["pof"][:, wins]
        d["sphere"] = pof.reshape(pof.shape[0], -1).mean(axis=1)
    nan = np.full(len(d["sphere"]), np.nan)
    # the camera's rotation and the flow without it (grids that record them)
    trans = getattr(g, "field_trans_dps", None)
    d["trans"] = nan if trans is None else _sphere_mean(trans, cells)
    om = (g.extras or {}).get("ego_omega_dps")
    d["rot"] = nan if om is None else np.linalg.norm(np.asarray(om, np.float64), axis=1)
    return d


def _moments(m: np.ndarray, yaw, fps: float, bad: np.ndarray) -> list[dict]:
    """The most provocative instants of a (T, Y) map, artefact frames left out; peaks
    within MOMENT_SEP_S of a larger one are merged into it (whatever their yaw)."""
    mm = np.where(bad[:, None], -np.inf, m)
    per_t = mm.max(axis=1)
    order = np.argsort(per_t)[::-1]
    picked: list[int] = []
    for t in order:
        if not np.isfinite(per_t[t]):
            break
        if all(abs(int(t) - p) / fps >= MOMENT_SEP_S for p in picked):
            picked.append(int(t))
            if len(picked) == N_MOMENTS:
                break
    out = []
    for k, t in enumerate(picked):
        y = int(np.argmax(mm[t]))
        hot = yaw[m[t] >= 0.8 * m[t, y]]
        out.append({"rank": k + 1, "frame": t, "time_s": t / fps, "yaw_deg": float(yaw[y]),
                    "pof_dps": float(m[t, y]), "band": band_of(float(m[t, y])),
                    "directions": int(hot.size)})  # fmt: skip
    return out


def _thumbnails(v, g: dict, moments: list[dict], folder: Path, pitch0: float) -> None:
    """``moment_<rank>.png``: each moment's viewport with a caption under it."""
    from PIL import Image, ImageDraw, ImageFont

    try:
        font = ImageFont.load_default(size=13)
    except TypeError:  # Pillow < 10.1: the fixed bitmap font
        font = ImageFont.load_default()

    want = {}
    for mo in moments:
        want.setdefault(mo["frame"] + g["start"], []).append(mo)
    src = Source.open(v.path, layout=v.layout, eye=v.eye, projection=v.projection,
                      lens_fov_deg=v.lens_fov_deg)  # fmt: skip
    for f, mine in want.items():  # the frame's own time (a variable-rate video: not frame / fps)
        for mo in mine:
            mo["time_s"] = float(src.info.times_s([f])[0])
    for f, frame in src.frames_at(sorted(want)):
        for mo in want[f]:
            view = extract_view(frame, mo["yaw_deg"], pitch0, 0.0, hfov_deg=g["hfov"],
                                vfov_deg=g["vfov"], size=(240, 240))  # fmt: skip
            img = Image.new("RGB", (240, 276), "white")
            img.paste(Image.fromarray(view), (0, 0))
            cap = (f"#{mo['rank']} {mo['time_s']:.1f} s, yaw {mo['yaw_deg']:+.0f}: "
                   f"{mo['pof_dps']:.0f} deg/s {mo['band']}")  # fmt: skip
            ImageDraw.Draw(img).text((4, 248), cap, fill="black", font=font)
            name = f"moment_{mo['rank']}.png"
            with atomic_output(folder / name) as tmp:
                img.save(tmp, format="PNG")
            mo["thumbnail"] = name


def _video_report(v, grid_path: Path, epofs: list, out: OutputFolder, artefacts: bool) -> dict:
    """Every per-video file; returns the video's row of the comparison table."""
    folder = out.prepare()
    g = _grid_arrays(grid_path)
    T = g["pof"].shape[0]
    n = min([T, *(len(r.frame) for r in epofs)])
    kinds = list(epofs[0].artefact[:n]) if epofs and epofs[0].artefact is not None else [""] * n
    # left out of the statistics; every kind (camera-fixed too) out of the moments
    bad = np.array([k not in ("", *KEPT_KINDS) for k in kinds], bool)
    e = np.stack([np.asarray(r.epof_dps[:n]) for r in epofs])  # (viewers, n)
    op = np.stack([np.asarray(r.opacity[:n]) for r in epofs])
    t = np.asarray(epofs[0].time_s[:n])
    frames = np.asarray(epofs[0].frame[:n])
    p10, p50, p90 = np.percentile(e, [10, 50, 90], axis=0)
    _write_csv(folder / "epof_distribution.csv",
               ("frame", "time_s", "viewers", "mean_dps", "p10_dps", "p50_dps", "p90_dps", "artefact"),
               zip(frames, t, [e.shape[0]] * n, e.mean(axis=0), p10, p50, p90, kinds))  # fmt: skip
    yaw, pitch = g["yaw"], g["pitch"]
    _write_map(folder / "map.csv", frames, t, pitch, yaw, kinds, g["pof"][:n])
    _write_csv(folder / "sphere_flow.csv", ("frame", "time_s", "sphere_mean_dps",
               "sphere_trans_mean_dps", "camera_rotation_dps", "artefact"),
               zip(frames, t, g["sphere"][:n], g["trans"][:n], g["rot"][:n], kinds))  # fmt: skip
    p0 = int(np.argmin(np.abs(pitch)))
    m = g["pof"][:n, p0, :]
    moments = _moments(m, yaw, g["fps"], np.array([k != "" for k in kinds], bool))
    _thumbnails(v, g, moments, folder, float(pitch[p0]))
    _write_csv(folder / "moments.csv", ("rank", "time_s", "frame", "yaw_deg", "pitch_deg",
               "pof_dps", "band", "directions", "thumbnail"),
               [[mo["rank"], mo["time_s"], mo["frame"], mo["yaw_deg"], float(pitch[p0]),
                 mo["pof_dps"], mo["band"], mo["directions"], mo.get("thumbnail", "")]
                for mo in moments])  # fmt: skip
    keep = np.broadcast_to(~bad, e.shape)
    clean = e[keep] if keep.any() else e.ravel()
    events = _events(kinds, t)
    row = {"video": v.id, "frames": n, "seconds": n / g["fps"], "viewers": e.shape[0],
           "artefact_frames": int(bad.sum()),
           "artefact_kinds": " ".join(f"{k}:{c}" for k, c in _count(kinds).items()),
           "epof_mean_dps": float(clean.mean()), "epof_p90_dps": float(np.percentile(clean, 90)),
           **share_above(e.ravel(), keep=keep.ravel()),
           "opacity_mean": float(op.mean()), "opacity_rule": _rule_name(epofs[0])}  # fmt: skip
    row["band_p90"] = band_of(row["epof_p90_dps"])
    _map_png(folder / "map.png", v.id, m, yaw, g["fps"], bad, moments, float(pitch[p0]))
    _summary_png(folder / "summary.png", v.id, t, e, bad, m, yaw, g, moments, row, events, folder)
    out.complete([*VIDEO_FILES[:6], *(mo["thumbnail"] for mo in moments if mo.get("thumbnail"))])
    return {"row": row, "moments": moments, "artefacts": events, "artefacts_on": artefacts}


def _count(kinds) -> dict[str, int]:
    out: dict[str, int] = {}
    for k in kinds:
        if k:
            out[k] = out.get(k, 0) + 1
    return out


def _events(kinds, t) -> list[dict]:
    ev: list[dict] = []
    for i, k in enumerate(kinds):
        if k and ev and ev[-1]["kind"] == k and ev[-1]["last"] == i - 1:
            ev[-1]["last"] = i
            ev[-1]["end_s"] = float(t[i])
        elif k:
            ev.append(
                {"kind": k, "first": i, "last": i, "start_s": float(t[i]), "end_s": float(t[i])}
            )
    return ev


def _rule_name(r) -> str:
    return rule_text((r.meta.get("settings") or {}).get("opacity_rule"))


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _draw_map(ax, fig, m, yaw, fps, bad, moments, pitch0: float) -> None:
    step = float(np.diff(yaw).mean()) if len(yaw) > 1 else 360.0
    vmax = max(float(np.percentile(m[~bad] if (~bad).any() else m, 99.5)), 1e-6)
    im = ax.imshow(m.T, origin="lower", aspect="auto", cmap="magma", vmin=0, vmax=vmax,
                   extent=(0, m.shape[0] / fps, yaw[0] - step / 2, yaw[-1] + step / 2),
                   interpolation="nearest")  # fmt: skip
    cb = fig.colorbar(im, ax=ax, label=f"flow at pitch {pitch0:g} deg (deg/s)", extend="max")
    for b in BANDS[1:]:
        if b.lo_dps <= vmax:
            cb.ax.axhline(b.lo_dps, color="cyan", lw=1)
            cb.ax.text(
                1.6,
                b.lo_dps,
                b.name,
                fontsize=6,
                va="center",
                transform=cb.ax.get_yaxis_transform(),
            )
    for i in np.flatnonzero(bad):
        ax.axvspan(i / fps, (i + 1) / fps, color="0.6", alpha=0.8, lw=0)
    for mo in moments:
        ax.annotate(str(mo["rank"]), (mo["time_s"], mo["yaw_deg"]), color="white", fontsize=8,
                    ha="center", va="center", weight="bold",
                    bbox={"boxstyle": "circle", "fc": "none", "ec": "white"})  # fmt: skip
    ax.set_xlabel("time (s)")
    ax.set_ylabel("yaw (deg, + right)")


def _map_png(path, vid, m, yaw, fps, bad, moments, pitch0) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(10, 4.2), dpi=110)
    _draw_map(ax, fig, m, yaw, fps, bad, moments, pitch0)
    ax.set_title(f"{vid}: where the video is provocative (artefact frames grey, left out)")
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def _summary_png(path, vid, t, e, bad, m, yaw, g, moments, row, events, folder) -> None:
    """One page a producer can read: verdict, flow across viewers with the bands, the
    map, the top moments' thumbnails, the artefacts."""
    from PIL import Image

    plt = _plt()
    fig = plt.figure(figsize=(11, 8.5), dpi=100)
    gs = fig.add_gridspec(3, 3, height_ratios=(1.3, 1.2, 1.1), hspace=0.45)
    shares = ", ".join(f"{b.name} {100 * row[f'share_ge_{b.name}']:.0f}%" for b in BANDS[1:])
    fig.suptitle(f"{vid}: {row['viewers']} scripted viewers, {row['seconds']:.0f} s -- "
                 f"90% of viewing time below {row['epof_p90_dps']:.1f} deg/s ({row['band_p90']})\n"
                 f"time at or above: {shares}; mean {row['epof_mean_dps']:.1f} deg/s; "
                 f"mean grain opacity {row['opacity_mean']:.2f} ({row['opacity_rule']})",
                 fontsize=10)  # fmt: skip
    ax = fig.add_subplot(gs[0, :])
    lo, med, hi = np.percentile(e, [10, 50, 90], axis=0)
    ax.fill_between(t, lo, hi, color="tab:blue", alpha=0.3, lw=0, label="10-90% of viewers")
    ax.plot(t, med, color="tab:blue", lw=1.2, label="median viewer")
    ax.plot(t, g["sphere"][: len(t)], color="0.25", lw=0.8, ls="--", label="whole sphere")
    ax.set_ylim(0, max(float(hi.max()) * 1.05, 6.0))
    draw_bands(ax)
    for i in np.flatnonzero(bad):
        ax.axvspan(t[i] - 0.5 / g["fps"], t[i] + 0.5 / g["fps"], color="0.4", alpha=0.5, lw=0)
    ax.set_ylabel("EPOF (deg/s)")
    ax.legend(loc="upper left", fontsize=7)
    ax2 = fig.add_subplot(gs[1, :])
    _draw_map(
        ax2,
        fig,
        m,
        yaw,
        g["fps"],
        bad,
        moments,
        float(g["pitch"][int(np.argmin(np.abs(g["pitch"])))]),
    )
    for k, mo in enumerate(moments[:3]):
        a = fig.add_subplot(gs[2, k])
        a.axis("off")
        if mo.get("thumbnail"):
            a.imshow(np.asarray(Image.open(folder / mo["thumbnail"])))
    if events:
        text = (
            "artefacts left out: "
            + "; ".join(
                f"{ev['kind']} {ev['start_s']:.1f}"
                + (f"-{ev['end_s']:.1f}" if ev["last"] > ev["first"] else "")
                + " s"
                for ev in events[:12]
            )
            + (" ..." if len(events) > 12 else "")
        )
    else:
        text = "no artefacts found (keyframes, cuts, fades, overlays)"
    fig.text(0.01, 0.01, text, fontsize=7, wrap=True)
    with atomic_output(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def write_screen_outputs(
    manifest, out: Path, summary: dict, *, artefacts: bool, model=None
) -> dict:
    """Every screening file under ``out/screen/``; returns what was written per video
    (or its one-line error) and the comparison rows. ``model``: a
    :class:`simulator.discomfort.model.Model` whose predictions join each row
    (:data:`simulator.discomfort.predict.MODEL_COLUMNS`)."""
    top, *per_video = screen_folders(out, [v.id for v in manifest.videos])
    folder = top.prepare()  # completed by the caller once screen.json is written
    report: dict = {"videos": {}, "rows": []}
    for v in manifest.videos:
        ids = [w.id for w in manifest.viewings if w.video == v.id]
        paths = [out / "epof" / f"{i}.csv" for i in ids]
        epofs = [read_epof_csv(p) for p in paths if p.is_file()]
        if not epofs:
            report["videos"][v.id] = {"error": f"video {v.id}: no viewer's EPOF (see viewings.csv)"}
            continue
        grid = Path(summary["videos"][v.id]["grid"])
        r = _video_report(v, grid, epofs, per_video[manifest.videos.index(v)], artefacts)
        if model is not None:
            r["row"].update(predict_columns(model, grid))
        report["videos"][v.id] = r
        report["rows"].append(r["row"])
    comments = [f"band {b.name}: {b.lo_dps:g} to {b.hi_dps:g} deg/s -- {b.source}" for b in BANDS]
    comments.append("EPOF statistics over all viewers and frames, artefact frames left out")
    cols = SCREEN_COLUMNS + (MODEL_COLUMNS if model is not None else ())
    if model is not None:
        comments.append(model_note(model))
        report["model"] = {**model_summary(model), "note": model_note(model)}
    _write_csv(folder / "comparison.csv", cols,
               [[r[c] for c in cols] for r in report["rows"]], comments)  # fmt: skip
    write_screen_page(folder, report, cols)  # index.html, last
    return report
