"""The study manifest (``STUDY.toml``): videos, viewings and options, read and validated.

Every check runs here, before any work: an unknown key, a missing video id, a glob that
matches nothing, a duplicate viewing id or a bad option value is one
:class:`~simulator.core.errors.InputError` line naming the manifest and the entry, e.g.
``study.toml: [[viewings]] #2 (video 'coaster'): unknown key 'usr'; expected one of ...``.
Paths in the manifest are relative to its folder. The format, with a full example, is in
``docs/study.md`` and ``examples/study.toml``.
"""

from __future__ import annotations

import csv
import glob
import math
import re
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

from simulator.core.choices import MITIGATIONS
from simulator.core.errors import InputError
from simulator.core.fileio import check_input_file
from simulator.mitigation.kinds import APERTURE_MIN_DEG, FEATHER_DEG
from simulator.sphere.headsets import resolve_fov
from simulator.traces.readers import FORMATS, detect_format

__all__ = ["SCRIPTED", "VIEWER_KINDS", "Manifest", "VideoSpec", "ViewingSpec", "load_manifest"]

_LAYOUTS = ("mono", "top-bottom", "side-by-side")
_ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
_GLOB_CHARS = re.compile(r"[*?\[]")

_TOP_KEYS = ("study", "videos", "viewings", "questionnaires", "epof", "render", "grf")
_STUDY_KEYS = ("name", "cache")
_VIDEO_KEYS = (
    "id", "path", "layout", "eye", "method", "grid", "fov", "hfov", "vfov", "headset",
    "window_size", "flow", "cell",
)  # fmt: skip
_VIEWING_KEYS = ("id", "video", "trace", "viewers", "format", "user", "participant", "condition",
                 "render")  # fmt: skip
_VIEWERS_KEYS = ("kind", "n", "seed")
#: Scripted viewers' head paths (``viewers = {kind = ...}``; keyframes needs a file).
VIEWER_KINDS: tuple[str, ...] = ("look-around", "sine", "sweep", "static")
#: ``ViewingSpec.format`` of a scripted viewer: ``synth:<kind>``, its seed in ``user``.
SCRIPTED = "synth:"
_QUEST_KEYS = ("path", "flow_stat", "exclude_below", "conditions")
_EPOF_KEYS = (
    "fov", "hfov", "vfov", "headset", "method", "top_k", "hold_last", "low_pct", "high_pct",
    "opacity_source", "smooth", "ease_in", "ease_out", "opacity_rule", "low_dps", "high_dps",
    "artefacts",
)  # fmt: skip
_RENDER_KEYS = ("eye_size", "fov", "hfov", "vfov", "headset", "grf", "opacity", "hold_last",
                "preset", "crf", "cpus", "mitigation", "aperture_min", "feather",
                "vignette_color")  # fmt: skip
_GRF_KEYS = ("grain_size", "density", "cutout", "seed", "grain_distance")
_PRESETS = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow")


@dataclass(frozen=True)
class VideoSpec:
    """One ``[[videos]]`` entry: the video and how it is preprocessed (degrees)."""

    id: str
    path: Path
    layout: str = "mono"
    eye: str = "left"
    method: str = "paper"
    grid: str = "default"
    hfov_deg: float = 107.0
    vfov_deg: float = 107.0
    window_size: int = 256
    flow: str = "dis"
    cell_deg: float = 4.0
    #: A grid the user already made of this video (checked to match); None: the cache's.
    grid_file: Path | None = None
    #: Detect artefacts while preprocessing (sphere mode; not part of the cache key).
    artefacts: bool = False

    def options(self) -> dict:
        """The preprocessing options (what the grid cache key is made of, besides the video)."""
        return {
            "layout": self.layout,
            "eye": self.eye,
            "method": self.method,
            "grid": self.grid,
            "hfov_deg": self.hfov_deg,
            "vfov_deg": self.vfov_deg,
            "window_size": self.window_size,
            "flow": self.flow,
            "cell_deg": self.cell_deg if self.method == "sphere" else None,
        }


@dataclass(frozen=True)
class ViewingSpec:
    """One viewing: a video watched along one trace (one user of a multi-user file), or
    by a scripted viewer (``format`` ``synth:<kind>``, ``user`` its seed, no ``trace``)."""

    id: str
    video: str
    trace: Path | None
    format: str = "auto"
    user: int | None = None
    participant: str = ""
    condition: str = ""
    render: bool = False


@dataclass(frozen=True)
class Manifest:
    """A validated study manifest (see the module docstring)."""

    path: Path
    name: str
    videos: tuple[VideoSpec, ...]
    viewings: tuple[ViewingSpec, ...]
    epof: dict = field(default_factory=dict)
    render: dict = field(default_factory=dict)
    grf: dict = field(default_factory=dict)
    questionnaires: dict | None = None
    cache: Path | None = None

    def video(self, vid: str) -> VideoSpec:
        return next(v for v in self.videos if v.id == vid)

    def input_files(self) -> list[Path]:
        """Every file the study reads (for the never-overwrite-an-input check)."""
        files = [self.path, *(v.path for v in self.videos)]
        files += [w.trace for w in self.viewings if w.trace is not None]
        if self.questionnaires:
            files.append(self.questionnaires["path"])
        return files


# ------------------------------------------------------------------------- checks
class _Entry:
    """Reads typed values from one table of the manifest; errors name manifest and entry."""

    def __init__(self, manifest: Path, where: str, table: object, allowed: tuple[str, ...]):
        self.m, self.where = manifest, where
        if not isinstance(table, dict):
            self.fail(f"expected a table, got {type(table).__name__}")
        self.t = table
        unknown = [k for k in table if k not in allowed]
        if unknown:
            self.fail(f"unknown key {unknown[0]!r}; expected one of {', '.join(allowed)}")

    def fail(self, msg: str):
        raise InputError(f"{self.m}: {self.where}: {msg}")

    def get(self, key, types, default=None, *, required=False, choices=None):
        if key not in self.t:
            if required:
                self.fail(f"key {key!r} missing")
            return default
        v = self.t[key]
        if isinstance(v, bool) and bool not in types:
            self.fail(f"{key} = {v!r}: expected {'/'.join(t.__name__ for t in types)}")
        if not isinstance(v, types):
            self.fail(f"{key} = {v!r}: expected {'/'.join(t.__name__ for t in types)}")
        if isinstance(v, float) and not math.isfinite(v):
            self.fail(f"{key} = {v!r}: expected a finite number")
        if choices is not None and v not in choices:
            self.fail(f"{key} = {v!r}: expected one of {', '.join(map(str, choices))}")
        return v

    def number(self, key, default=None, *, lo=None, hi=None, integer=False, lo_open=False):
        v = self.get(key, (int,) if integer else (int, float), default)
        if v is None:
            return None
        if (lo is not None and (v < lo or (lo_open and v == lo))) or (hi is not None and v > hi):
            rng = f"{'(' if lo_open else '['}{lo if lo is not None else '-inf'}, {hi if hi is not None else 'inf'}]"
            self.fail(f"{key} = {v!r}: expected a number in {rng}")
        return v if integer else float(v)

    def fov(self, default):
        try:
            return resolve_fov(
                headset=self.get("headset", (str,)),
                fov_deg=self.number("fov"),
                hfov_deg=self.number("hfov"),
                vfov_deg=self.number("vfov"),
                default=default,
            )
        except InputError as e:
            self.fail(str(e))

    def path(self, key, base: Path, *, required=True) -> Path | None:
        v = self.get(key, (str,), required=required)
        if v is None:
            return None
        p = Path(v).expanduser()
        return p if p.is_absolute() else base / p


def _stem_fields(trace: Path, user: int | None, n_users: int) -> dict:
    width = len(str(n_users)) if n_users > 1 else 1
    return {"stem": trace.stem, "user": "" if user is None else f"{user:0{width}d}"}


def _n_users(trace: Path, fmt: str) -> tuple[str, int]:
    """(format, number of users) of a trace file; counts lines only (no parsing)."""
    check_input_file(trace, "head path")
    f = detect_format(trace) if fmt == "auto" else fmt
    if f != "360vidstr":
        return f, 1
    with open(trace, encoding="utf-8", errors="replace") as fh:
        n = sum(1 for ln in fh if ln.strip())
    return f, max(1, (n - 1) // 2)


def _videos(m: Path, base: Path, tables) -> tuple[VideoSpec, ...]:
    if not isinstance(tables, list) or not tables:
        raise InputError(f"{m}: no [[videos]] entries; expected at least one with id and path")
    out: list[VideoSpec] = []
    for i, t in enumerate(tables, start=1):
        label = t.get("id") if isinstance(t, dict) else None
        e = _Entry(m, f"[[videos]] #{i}" + (f" ({label!r})" if label else ""), t, _VIDEO_KEYS)
        vid = e.get("id", (str,), required=True)
        if not _ID_RE.match(vid):
            e.fail(f"id {vid!r}: use letters, digits, '.', '_' and '-' (it names files)")
        if any(v.id == vid for v in out):
            e.fail(f"duplicate video id {vid!r}")
        path = e.path("path", base)
        try:
            check_input_file(path, "video")
        except InputError as err:
            e.fail(str(err))
        h, v = e.fov((107.0, 107.0))
        method = e.get("method", (str,), "paper", choices=("paper", "sphere"))
        cell = e.number("cell", 4.0, lo=0.0, lo_open=True)
        if method == "sphere" and abs(180.0 / cell - round(180.0 / cell)) > 1e-9:
            e.fail(f"cell = {cell}: expected degrees dividing 180, e.g. 4")
        out.append(
            VideoSpec(
                id=vid,
                path=path,
                layout=e.get("layout", (str,), "mono", choices=_LAYOUTS),
                eye=e.get("eye", (str,), "left", choices=("left", "right")),
                method=method,
                grid=e.get("grid", (str,), "default", choices=("default", "paper-198")),
                hfov_deg=float(h),
                vfov_deg=float(v),
                window_size=e.number("window_size", 256, lo=16, hi=2048, integer=True),
                flow=e.get("flow", (str,), "dis"),
                cell_deg=cell,
            )
        )
    return tuple(out)


def _viewings(m: Path, base: Path, tables, videos) -> tuple[ViewingSpec, ...]:
    if not isinstance(tables, list) or not tables:
        raise InputError(
            f"{m}: no [[viewings]] entries; expected at least one with video and trace"
        )
    ids = {v.id for v in videos}
    out: list[ViewingSpec] = []
    seen: dict[str, str] = {}
    for i, t in enumerate(tables, start=1):
        label = t.get("video") if isinstance(t, dict) else None
        where = f"[[viewings]] #{i}" + (f" (video {label!r})" if label else "")
        e = _Entry(m, where, t, _VIEWING_KEYS)
        vid = e.get("video", (str,), required=True)
        if vid not in ids:
            e.fail(f"video {vid!r} is not a [[videos]] id; known: {', '.join(sorted(ids))}")
        if "viewers" in e.t:
            out += _scripted(e, vid, seen, where)
            continue
        pattern = e.get("trace", (str,), required=True)
        fmt = e.get("format", (str,), "auto", choices=("auto", *FORMATS))
        user = e.get("user", (int, str))
        if isinstance(user, str) and user != "all":
            e.fail(f'user = {user!r}: expected a number >= 1 or "all"')
        if isinstance(user, int) and user < 1:
            e.fail(f'user = {user}: expected a number >= 1 or "all"')
        pat = str(Path(pattern).expanduser())
        pat = pat if Path(pat).is_absolute() else str(base / pat)
        if _GLOB_CHARS.search(pattern):
            traces = [Path(p) for p in sorted(glob.glob(pat)) if Path(p).is_file()]
            if not traces:
                e.fail(f"trace glob {pattern!r} matches no file (relative to {base})")
        else:
            traces = [Path(pat)]
        participant_t = e.get("participant", (str,))
        id_t = e.get("id", (str,))
        condition = e.get("condition", (str,), "")
        render = e.get("render", (bool,), False)
        for trace in traces:
            try:
                tfmt, n_users = _n_users(trace, fmt)
            except InputError as err:
                e.fail(str(err))
            if user == "all":
                users: list[int | None] = (
                    list(range(1, n_users + 1)) if n_users > 1 or tfmt == "360vidstr" else [None]
                )
            else:
                if isinstance(user, int) and tfmt == "360vidstr" and user > n_users:
                    e.fail(f"{trace}: no user {user}; the file holds {n_users}")
                users = [user]
            for u in users:
                f = _stem_fields(trace, u, n_users)
                default_p = f["stem"] + (f"_user{f['user']}" if u is not None else "")
                try:
                    participant = participant_t.format(**f) if participant_t else default_p
                    f["participant"] = participant
                    f["video"] = vid
                    f["condition"] = condition
                    default_id = f"{vid}-{participant}" + (f"-{condition}" if condition else "")
                    vw_id = id_t.format(**f) if id_t else default_id
                except (KeyError, IndexError, ValueError) as err:
                    e.fail(
                        f"bad template in id/participant ({err}); fields: stem, user, participant, video, condition"
                    )
                if not _ID_RE.match(vw_id):
                    e.fail(
                        f"viewing id {vw_id!r}: use letters, digits, '.', '_' and '-' (it names files)"
                    )
                if vw_id in seen:
                    e.fail(
                        f"duplicate viewing id {vw_id!r} (also from {seen[vw_id]}); give each "
                        "viewing its own participant, condition or id"
                    )
                seen[vw_id] = where
                out.append(ViewingSpec(vw_id, vid, trace, fmt, u, participant, condition, render))
    return tuple(out)


def _scripted(e: _Entry, vid: str, seen: dict, where: str) -> list[ViewingSpec]:
    """``viewers = {kind = "look-around", n = 30, seed = 0}``: n scripted viewers, viewer k
    with seed ``seed + k - 1``, ids ``<video>-viewer<k>`` (or the ``id`` template with
    ``{video}``, ``{participant}``, ``{user}`` = k)."""
    for k in ("trace", "format", "user"):
        if k in e.t:
            e.fail(f"{k} and viewers are exclusive: scripted viewers have no trace file")
    v = _Entry(e.m, f"{where}: viewers", e.t["viewers"], _VIEWERS_KEYS)
    kind = v.get("kind", (str,), "look-around")
    if kind not in VIEWER_KINDS:
        v.fail(f"unknown viewer kind {kind!r}; expected one of {', '.join(VIEWER_KINDS)}")
    n = v.number("n", 30, lo=1, hi=100_000, integer=True)
    seed = v.number("seed", 0, lo=0, integer=True)
    id_t, cond = e.get("id", (str,)), e.get("condition", (str,), "")
    render = e.get("render", (bool,), False)
    out = []
    width = max(3, len(str(n)))
    for k in range(1, n + 1):
        f = {"video": vid, "participant": f"viewer{k:0{width}d}", "user": f"{k:0{width}d}",
             "stem": f"viewer{k:0{width}d}", "condition": cond}  # fmt: skip
        try:
            vw_id = id_t.format(**f) if id_t else f"{vid}-{f['participant']}"
        except (KeyError, IndexError, ValueError) as err:
            e.fail(f"bad template in id ({err}); fields: video, participant, user, condition")
        if not _ID_RE.match(vw_id) or vw_id in seen:
            e.fail(f"viewing id {vw_id!r}: not a file name or used twice; give an id template")
        seen[vw_id] = where
        out.append(ViewingSpec(vw_id, vid, None, SCRIPTED + kind, seed + k - 1,
                               f["participant"], cond, render))  # fmt: skip
    return out


def _questionnaires(m: Path, base: Path, t) -> dict | None:
    if t is None:
        return None
    e = _Entry(m, "[questionnaires]", t, _QUEST_KEYS)
    path = e.path("path", base)
    try:
        check_input_file(path, "questionnaire CSV")
        with open(path, newline="", encoding="utf-8-sig") as fh:
            rows = [r for r in csv.reader(ln for ln in fh if not ln.lstrip().startswith("#"))]
    except (InputError, UnicodeDecodeError) as err:
        e.fail(str(err) if isinstance(err, InputError) else f"{path}: not UTF-8 text")
    header = [c.strip().lower() for c in (rows[0] if rows else [])]
    if "participant" not in header and "id" not in header:
        e.fail(f"{path}: no 'participant' (or 'id') column to key rows by; found {header}")
    conds = e.get("conditions", (list,))
    if conds is not None and (len(conds) != 2 or not all(isinstance(c, str) and c for c in conds)):
        e.fail(f'conditions = {conds!r}: expected two labels, e.g. ["NR", "GR"]')
    return {
        "path": path,
        "flow_stat": e.get("flow_stat", (str,), "mean", choices=("mean", "median", "sum")),
        "exclude_below": e.number("exclude_below", None, lo=0.0),
        "conditions": tuple(conds) if conds else None,
    }


def _epof(m: Path, t) -> dict:
    e = _Entry(m, "[epof]", t or {}, _EPOF_KEYS)
    h, v = e.fov((None, None))
    low = e.number("low_pct", 10.0, lo=0.0, hi=100.0)
    high = e.number("high_pct", 90.0, lo=0.0, hi=100.0)
    if not low < high:
        e.fail(f"low_pct ({low}) must be below high_pct ({high})")
    return {
        "hfov_deg": h,
        "vfov_deg": v,
        "method": e.get("method", (str,), "auto", choices=("auto", "paper", "sphere")),
        "top_k": e.number("top_k", None, lo=1, integer=True),
        "hold_last": e.get("hold_last", (bool,), False),
        "low_pct": low,
        "high_pct": high,
        "opacity_source": e.get("opacity_source", (str,), "grid", choices=("grid", "viewing")),
        "smooth_s": e.number("smooth", 0.0, lo=0.0),
        # As vimsim epof: the eased comfort rule by default, the paper's one option away.
        "opacity_rule": e.get(
            "opacity_rule", (str,), "comfort", choices=("comfort", "paper", "absolute")
        ),
        "ease_in_s": e.number("ease_in", None, lo=0.0),
        "ease_out_s": e.number("ease_out", None, lo=0.0),
        **_absolute(e),
        # Codec keyframes, cuts, fades, overlays: detected, left out of thresholds, held.
        "artefacts": e.get("artefacts", (bool,), False),
    }


def _absolute(e: _Entry) -> dict:
    """``low_dps``/``high_dps`` of the absolute opacity rule (only with it; defaults 5, 30)."""
    lo, hi = e.number("low_dps", None, lo=0.0), e.number("high_dps", None, lo=0.0)
    if e.t.get("opacity_rule") != "absolute":
        if lo is not None or hi is not None:
            e.fail('low_dps/high_dps need opacity_rule = "absolute"')
        return {}
    lo, hi = (5.0 if lo is None else lo), (30.0 if hi is None else hi)
    if not lo < hi:
        e.fail(f"low_dps ({lo:g}) must be below high_dps ({hi:g}) deg/s")
    return {"low_dps": lo, "high_dps": hi}


def _render(m: Path, t) -> dict:
    e = _Entry(m, "[render]", t or {}, _RENDER_KEYS)
    size = e.get("eye_size", (str, list), "1440x1440")
    try:
        if isinstance(size, str):
            w, h = (int(x) for x in size.lower().split("x"))
        else:
            w, h = (int(x) for x in size)
        if not (0 < w <= 16384 and 0 < h <= 16384) or w % 2 or h % 2:
            raise ValueError
    except (ValueError, TypeError):
        e.fail(f'eye_size = {size!r}: expected even WxH pixels, e.g. "480x480"')
    hf, vf = e.fov((107.0, 107.0))
    opacity = e.get("opacity", (str, int, float), "auto")
    if isinstance(opacity, str) and opacity != "auto":
        e.fail(f'opacity = {opacity!r}: expected "auto" or a number in [0, 1]')
    if not isinstance(opacity, str) and not 0.0 <= opacity <= 1.0:
        e.fail(f'opacity = {opacity!r}: expected "auto" or a number in [0, 1]')
    return {
        "eye_size": [w, h],
        "hfov_deg": float(hf),
        "vfov_deg": float(vf),
        "grf": e.get("grf", (str,), "on", choices=("on", "off")),
        "opacity": opacity if isinstance(opacity, str) else float(opacity),
        "hold_last": e.get("hold_last", (bool,), False),
        "preset": e.get("preset", (str,), "veryfast", choices=_PRESETS),
        "crf": e.number("crf", 18, lo=0, hi=51, integer=True),
        "cpus": e.number("cpus", 1, lo=1, hi=256, integer=True),
        # As vimsim render --mitigation (docs/mitigation.md); checked when the task builds it.
        "mitigation": e.get("mitigation", (str,), "grf", choices=MITIGATIONS),
        "aperture_min_deg": e.number("aperture_min", APERTURE_MIN_DEG, lo=0.0),
        "feather_deg": e.number("feather", FEATHER_DEG, lo=0.0),
        "vignette_color": e.get("vignette_color", (str,), "0,0,0"),
    }


def _grf(m: Path, t) -> dict:
    e = _Entry(m, "[grf]", t or {}, _GRF_KEYS)
    cut = e.get("cutout", (list,), [18.0, 40.0])
    if len(cut) != 2 or not all(
        isinstance(c, (int, float)) and not isinstance(c, bool) for c in cut
    ):
        e.fail(f"cutout = {cut!r}: expected [INNER, OUTER] degrees, e.g. [18, 40]")
    return {
        "grain_deg": e.number("grain_size", 1.5, lo=0.0, lo_open=True),
        "density": e.number("density", 0.5, lo=0.0, hi=1.0),
        "inner_deg": float(cut[0]),
        "outer_deg": float(cut[1]),
        "seed": e.number("seed", 0, lo=0, integer=True),
        "distance_m": e.number("grain_distance", None, lo=0.0, lo_open=True),
    }


def load_manifest(path) -> Manifest:
    """Read and validate ``STUDY.toml``; InputError (one line: manifest, entry, problem)."""
    m = check_input_file(path, "study manifest")
    try:
        data = tomllib.loads(m.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise InputError(f"{m}: not UTF-8 text; expected a TOML study manifest") from None
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{m}: not valid TOML ({e})") from None
    unknown = [k for k in data if k not in _TOP_KEYS]
    if unknown:
        raise InputError(f"{m}: unknown table {unknown[0]!r}; expected {', '.join(_TOP_KEYS)}")
    base = m.resolve().parent
    st = _Entry(m, "[study]", data.get("study", {}), _STUDY_KEYS)
    videos = _videos(m, base, data.get("videos"))
    viewings = _viewings(m, base, data.get("viewings"), videos)
    epof = _epof(m, data.get("epof"))
    if epof["artefacts"]:  # detected in the preprocessing pass (sphere mode) where it runs
        videos = tuple(replace(v, artefacts=True) for v in videos)
    return Manifest(
        path=m.resolve(),
        name=st.get("name", (str,), m.stem),
        videos=videos,
        viewings=viewings,
        epof=epof,
        render=_render(m, data.get("render")),
        grf=_grf(m, data.get("grf")),
        questionnaires=_questionnaires(m, base, data.get("questionnaires")),
        cache=st.path("cache", base, required=False),
    )
