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
import re
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

from simulator.core.choices import (
    MITIGATIONS,
    OPACITY_RULE_DEFAULT,
    OPACITY_RULES,
    PROJECTIONS,
    SYSTEM_PRESETS,
)
from simulator.core.choices import X264_PRESETS as _PRESETS
from simulator.core.errors import InputError
from simulator.core.fileio import check_input_file
from simulator.core.traceopts import TraceOptions
from simulator.discomfort.predict import study_model
from simulator.mitigation.bands import ABSOLUTE_HIGH_DPS, ABSOLUTE_LOW_DPS
from simulator.mitigation.kinds import APERTURE_MIN_DEG, FEATHER_DEG
from simulator.study.entry import Entry, render_users, stem_fields, user_numbers
from simulator.study.traces import VIEWING_TRACE_KEYS, trace_defaults, viewing_trace_options
from simulator.study.viewers import SCRIPTED, VIEWER_KINDS, expand_traces, scripted_viewers
from simulator.traces.readers import n_users
from simulator.viewing.spec import ViewSpec

__all__ = ["SCRIPTED", "VIEWER_KINDS", "Manifest", "VideoSpec", "ViewingSpec", "load_manifest"]

_LAYOUTS = ("mono", "top-bottom", "side-by-side")
_ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")

_TOP_KEYS = ("study", "videos", "viewings", "questionnaires", "epof", "render", "grf", "traces", "model")  # fmt: skip
_STUDY_KEYS = ("name", "cache")
_VIDEO_KEYS = (
    "id", "path", "layout", "eye", "method", "grid", "fov", "hfov", "vfov", "headset",
    "window_size", "flow", "cell", "projection", "lens_fov",
)  # fmt: skip
_GRF_KEYS = ("grain_size", "density", "cutout", "seed", "grain_distance")
_RENDER_KEYS = ("eye_size", "fov", "hfov", "vfov", "headset", "grf", "opacity", "hold_last",
                "x264_preset", "crf", "cpus", "mitigation", "aperture_min", "feather",
                "vignette_color", "start", "end", "review", "eyes", "audio")  # fmt: skip
#: Render options a viewing may set for itself (over [render] and [grf]); cpus is the
#: study's; a viewing's hold_last is a trace key (it reaches the EPOF and the render).
_VIEWING_RENDER_KEYS = (*(k for k in _RENDER_KEYS if k not in ("cpus", "hold_last")), *_GRF_KEYS)
_VIEWING_KEYS = ("id", "video", "trace", "viewers", "participant", "condition", "render",
                 "plot", *_VIEWING_RENDER_KEYS, *VIEWING_TRACE_KEYS)  # fmt: skip
_QUEST_KEYS = ("path", "flow_stat", "exclude_below", "conditions", "k_of")
_EPOF_KEYS = (
    "fov", "hfov", "vfov", "headset", "method", "top_k", "hold_last", "low_pct", "high_pct",
    "opacity_source", "smooth", "ease_in", "ease_out", "opacity_rule", "low_dps", "high_dps",
    "artefacts", "preset",
)  # fmt: skip


@dataclass(frozen=True)
class VideoSpec:
    """One ``[[videos]]`` entry: the video and how it is preprocessed (degrees)."""

    id: str
    path: Path
    layout: str = "mono"
    eye: str = "left"
    method: str = "sphere"
    grid: str = "default"
    hfov_deg: float = 107.0
    vfov_deg: float = 107.0
    window_size: int = 256
    flow: str = "dis"
    cell_deg: float = 4.0
    projection: str = "equirect"
    lens_fov_deg: float | None = None
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
            **({} if self.projection == "equirect" else
               {"projection": self.projection, "lens_fov_deg": self.lens_fov_deg}),
        }  # fmt: skip


@dataclass(frozen=True)
class ViewingSpec:
    """One viewing: a video along a trace (one user of a file) or a scripted viewer's path."""

    id: str
    video: str
    trace: Path | None
    format: str = "auto"
    user: int | None = None
    participant: str = ""
    condition: str = ""
    render: bool = False
    #: Its render options ([render] with its own keys over it); None when not rendered.
    render_opts: dict | None = None
    #: Also plot this viewing's EPOF (``epof/<id>.png``).
    plot: bool = False
    #: How its trace is read and placed on the video's clock ([traces] and its own keys).
    trace_opts: TraceOptions = field(default_factory=lambda: TraceOptions(origin="manifest"))
    own_render: dict | None = None  # its render options, rendered or not (mitigation, replay)


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
    model: Path | None = None  # [model] path: simulator.discomfort.predict.study_model

    def video(self, vid: str) -> VideoSpec:
        return next(v for v in self.videos if v.id == vid)

    def input_files(self) -> list[Path]:
        """Every file the study reads (for the never-overwrite-an-input check)."""
        files = [self.path, *(v.path for v in self.videos)]
        files += [w.trace for w in self.viewings if w.trace is not None]
        if self.questionnaires:
            files.append(self.questionnaires["path"])
        return files + ([self.model] if self.model is not None else [])


def _videos(m: Path, base: Path, tables) -> tuple[VideoSpec, ...]:
    if not isinstance(tables, list) or not tables:
        raise InputError(f"{m}: no [[videos]] entries; expected at least one with id and path")
    out: list[VideoSpec] = []
    for i, t in enumerate(tables, start=1):
        label = t.get("id") if isinstance(t, dict) else None
        e = Entry(m, f"[[videos]] #{i}" + (f" ({label!r})" if label else ""), t, _VIDEO_KEYS)
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
        # sphere by default, as vimsim preprocess; "paper" is the paper's method
        method = e.get("method", (str,), "sphere", choices=("paper", "sphere"))
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
                projection=e.get("projection", (str,), "equirect", choices=PROJECTIONS),
                lens_fov_deg=e.number("lens_fov", None, lo=180.0, lo_open=True, hi=360.0),
            )
        )
    return tuple(out)


def _users_of(e: Entry, trace: Path, fmt: str, user, opts) -> tuple[list[int | None], int]:
    """The users of ``trace`` a viewing entry takes (None: the file's one trace), and the
    number of users the file holds; ``opts``' AVTrack360 video choice refused elsewhere."""
    try:
        tfmt, n = n_users(check_input_file(trace, "head path"), fmt)  # counts lines only
    except InputError as err:
        e.fail(opts.fix(str(err)))
    if "trace_video" in e.t and tfmt != "avtrack360":  # (a [traces] default: other files')
        e.fail(f"{trace}: a {tfmt} trace holds one video; trace_video = {opts.video!r} belongs "
               "on an AVTrack360 trace")  # fmt: skip
    if user is None:
        return [None], n
    if user == "all":
        return (list(range(1, n + 1)) if n > 1 or tfmt == "360vidstr" else [None]), n
    return list(user_numbers(e, "user", user, n_users=n, where=f"{trace}: ")), n


def _viewing_render_opts(e: Entry, m: Path, where: str, data: dict, render: dict, hold=False) -> dict:
    """The study's render options with the viewing's own keys over them, checked as
    ``[render]`` is (its view by the one builder, :meth:`ViewSpec.from_options`);
    ``hold``: the viewing's trace option ``hold_last`` (it reaches the render too)."""
    own = {k: e.t[k] for k in _VIEWING_RENDER_KEYS if k in e.t}
    if hold:
        opts = _viewing_render_opts(e, m, where, data, render)
        return {**opts, "hold_last": True, "view": {**opts["view"], "hold_last": True}}
    if not own:
        return render
    table = dict(data.get("render") or {})
    if own.keys() & _FOV_KEYS:
        for k in _FOV_KEYS:
            table.pop(k, None)
    table.update({k: v for k, v in own.items() if k in _RENDER_KEYS})
    opts = _render(m, table, f"{where}: render options")
    opts["view"] = _view(m, data, own, where)
    return opts


def _viewing_ids(e: Entry, trace: Path, u, n: int, vid: str, condition: str) -> tuple[str, str]:
    """(viewing id, participant) of one user of a trace, from the entry's templates."""
    f = stem_fields(trace, u, n)
    default_p = f["stem"] + (f"_user{f['user']}" if u is not None else "")
    participant_t, id_t = e.get("participant", (str,)), e.get("id", (str,))
    try:
        participant = participant_t.format(**f) if participant_t else default_p
        f.update(participant=participant, video=vid, condition=condition)
        default_id = f"{vid}-{participant}" + (f"-{condition}" if condition else "")
        vw_id = id_t.format(**f) if id_t else default_id
    except (KeyError, IndexError, ValueError) as err:
        e.fail(
            f"bad template in id/participant ({err}); fields: stem, user, participant, video, condition"
        )
    if not _ID_RE.match(vw_id):
        e.fail(f"viewing id {vw_id!r}: use letters, digits, '.', '_' and '-' (it names files)")
    return vw_id, participant


def _viewings(
    m: Path, base: Path, tables, videos, data: dict, render: dict, traces: dict
) -> tuple[ViewingSpec, ...]:
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
        e = Entry(m, where, t, _VIEWING_KEYS)
        vid = e.get("video", (str,), required=True)
        if vid not in ids:
            e.fail(f"video {vid!r} is not a [[videos]] id; known: {', '.join(sorted(ids))}")
        if "viewers" in e.t:  # scripted viewers (simulator.study.viewers): no trace file
            ropts, cond = _viewing_render_opts(e, m, where, data, render), e.get("condition", (str,), "")
            r, plot = e.get("render", (bool,), False), e.get("plot", (bool,), False)
            out += [ViewingSpec(i, vid, None, SCRIPTED + k, s, p, cond, r, ropts if r else None, plot, own_render=ropts)
                    for i, p, s, k in scripted_viewers(e, vid, seen, where, _ID_RE)]  # fmt: skip
            viewing_trace_options(e, traces, scripted=True)  # its trace keys refused
            continue
        pattern = e.get("trace", (str,), required=True)
        topts, user = viewing_trace_options(e, traces, scripted=False)
        fmt = topts.format
        condition = e.get("condition", (str,), "")
        render_spec = e.get("render", (bool, int, str, list), False)
        plot = e.get("plot", (bool,), False)
        ropts = _viewing_render_opts(e, m, where, data, render, topts.hold_last)
        for trace in expand_traces(e, pattern, base):
            users, n = ([None], 1) if topts.columns else _users_of(e, trace, fmt, user, topts)
            rendered = render_users(e, render_spec, users)
            for u in users:
                vw_id, participant = _viewing_ids(e, trace, u, n, vid, condition)
                if vw_id in seen:
                    e.fail(
                        f"duplicate viewing id {vw_id!r} (also from {seen[vw_id]}); give each "
                        "viewing its own participant, condition or id"
                    )
                seen[vw_id] = where
                r = u in rendered
                out.append(ViewingSpec(vw_id, vid, trace, fmt, u, participant, condition, r,
                                       ropts if r else None, plot, topts, own_render=ropts))  # fmt: skip
    return tuple(out)


def _questionnaires(m: Path, base: Path, t) -> dict | None:
    if t is None:
        return None
    e = Entry(m, "[questionnaires]", t, _QUEST_KEYS)
    path = e.path("path", base)
    try:
        check_input_file(path, "questionnaire CSV")
        with open(path, newline="", encoding="utf-8-sig") as fh:
            rows = [r for r in csv.reader(ln for ln in fh if not ln.lstrip().startswith("#"))]
    except (InputError, UnicodeDecodeError, csv.Error) as err:
        bad = "not UTF-8 text" if isinstance(err, UnicodeDecodeError) else f"not CSV ({err})"
        e.fail(str(err) if isinstance(err, InputError) else f"{path}: {bad}")
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
        # The group-size-invariant K_OF by default; "paper" for the paper's formula.
        "k_of": e.get("k_of", (str,), "invariant", choices=("invariant", "paper")),
    }


def _epof(m: Path, t) -> dict:
    e = Entry(m, "[epof]", t or {}, _EPOF_KEYS)
    preset = e.get("preset", (str,), "vimsim", choices=SYSTEM_PRESETS)
    dflt = {"paper": "paper", "cao2021-code": None}.get(preset, OPACITY_RULE_DEFAULT)
    rule = e.get("opacity_rule", (str,), dflt, choices=OPACITY_RULES)
    dps = [e.number(k, None, lo=0.0) for k in ("low_dps", "high_dps")]
    if rule == "absolute":  # the defaults: the named bands' edges (rule_from_options checks)
        dps = [d if v is None else v for v, d in zip(dps, (ABSOLUTE_LOW_DPS, ABSOLUTE_HIGH_DPS))]
    h, v = e.fov((None, None))
    low = e.number("low_pct", 10.0, lo=0.0, hi=100.0)
    high = e.number("high_pct", 90.0, lo=0.0, hi=100.0)
    if not low < high:
        e.fail(f"low_pct ({low}) must be below high_pct ({high})")
    bad = [k for k in ("top_k", "artefacts", "fov", "hfov", "vfov", "headset") if k in e.t]
    if preset == "cao2021-code" and bad:  # the nearest window: no FOV, no top-k
        e.fail(f"preset = 'cao2021-code' cannot be combined with {bad[0]}")
    return {
        "hfov_deg": h,
        "vfov_deg": v,
        # as vimsim epof --headset: the headset's exact (asymmetric) per-eye frustum
        "headset": e.get("headset", (str,)),
        "method": e.get("method", (str,), "auto", choices=("auto", "paper", "sphere")),
        "top_k": e.number("top_k", None, lo=1, integer=True),
        "hold_last": e.get("hold_last", (bool,), False),
        "low_pct": low,
        "high_pct": high,
        "opacity_source": e.get("opacity_source", (str,), "grid", choices=("grid", "viewing")),
        "smooth_s": e.number("smooth", 0.0, lo=0.0),
        # As vimsim epof: the absolute rule by default, the paper's one option away.
        "opacity_rule": rule,
        "ease_in_s": e.number("ease_in", None, lo=0.0),
        "ease_out_s": e.number("ease_out", None, lo=0.0),
        "low_dps": dps[0],  # the absolute rule's (None with another rule)
        "high_dps": dps[1],
        # Codec keyframes, cuts, fades, overlays: detected, left out of thresholds, held.
        # keyframes, cuts, fades, overlays, camera-fixed: by default, not in the authors' system
        "artefacts": e.get("artefacts", (bool,), preset != "cao2021-code"),
        "preset": preset,  # as --preset (docs/parity.md); the render's too, checked by _view
    }


def _render(m: Path, t, where: str = "[render]") -> dict:
    """The render options of ``[render]`` (or of a viewing: [render] with its keys over it)."""
    e = Entry(m, where, t or {}, _RENDER_KEYS)
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
        "x264_preset": e.get("x264_preset", (str,), "veryfast", choices=_PRESETS),
        "crf": e.number("crf", 18, lo=0, hi=51, integer=True),
        "cpus": e.number("cpus", 1, lo=1, hi=256, integer=True),
        # As vimsim render --mitigation (docs/mitigation.md); checked when the task builds it.
        "mitigation": e.get("mitigation", (str,), "grf", choices=MITIGATIONS),
        "aperture_min_deg": e.number("aperture_min", APERTURE_MIN_DEG, lo=0.0),
        "feather_deg": e.number("feather", FEATHER_DEG, lo=0.0),
        "vignette_color": e.get("vignette_color", (str,), "0,0,0"),
        **_render_range(e),
    }


def _render_range(e: Entry) -> dict:
    """``start``/``end`` (seconds of video time), ``review``, ``eyes``, ``audio``."""
    start = e.number("start", None, lo=0.0)
    end = e.number("end", None, lo=0.0, lo_open=True)
    if start is not None and end is not None and not start < end:
        e.fail(f"start = {start:g} is not before end = {end:g}")
    return {"start_s": start, "end_s": end, "review": e.get("review", (bool,), False),
            "eyes": e.get("eyes", (str,), None, choices=("left", "right", "both")),
            "audio": e.get("audio", (bool,), True)}  # fmt: skip


def _grf(m: Path, t) -> dict:
    e = Entry(m, "[grf]", t or {}, _GRF_KEYS)
    cut = e.get("cutout", (list,), [18.0, 40.0])
    if len(cut) != 2 or not all(isinstance(c, (int, float)) and not isinstance(c, bool)
                                for c in cut):  # fmt: skip
        e.fail(f"cutout = {cut!r}: expected [INNER, OUTER] degrees, e.g. [18, 40]")
    return {
        "grain_deg": e.number("grain_size", 1.5, lo=0.0, lo_open=True),
        "density": e.number("density", 0.5, lo=0.0, hi=1.0),
        "inner_deg": float(cut[0]),
        "outer_deg": float(cut[1]),
        "seed": e.number("seed", 0, lo=0, integer=True),
        "distance_m": e.number("grain_distance", None, lo=0.0, lo_open=True),
    }


_FOV_KEYS = {"fov", "hfov", "vfov", "headset"}

#: The keys of each table that say what the eye sees in a render
#: (:meth:`simulator.viewing.spec.ViewSpec.from_options`, as ``vimsim render``'s options).
_VIEW_KEYS = {
    "render": ("eye_size", "fov", "hfov", "vfov", "headset", "grf", "opacity", "hold_last",
               "mitigation", "aperture_min", "feather", "vignette_color"),
    "grf": _GRF_KEYS,
    "epof": ("method", "low_pct", "high_pct", "opacity_source", "smooth", "ease_in",
             "ease_out", "opacity_rule", "low_dps", "high_dps", "preset"),
}  # fmt: skip


def _view(m: Path, data: dict, own: dict | None = None, own_where: str = "") -> dict:
    """The render's view options: the ``[render]`` and ``[grf]`` tables and the opacity
    rule of ``[epof]`` merged into one mapping of :data:`VIEW_OPTIONS` names (plain TOML
    values, as shipped to a render task), checked by building the view once. ``own``: a
    viewing's own render and grain keys over the tables (named ``own_where`` in errors)."""
    options: dict = {"grid": True}  # every viewing of a study has its video's grid
    where: dict = {}
    for table, keys in _VIEW_KEYS.items():
        t = data.get(table) or {}
        for k in keys:
            if k in t:
                options[k], where[k] = t[k], f"[{table}]"
    own = own or {}
    if own.keys() & _FOV_KEYS:  # a viewing's FOV replaces the table's, whichever spelling
        for k in _FOV_KEYS:
            options.pop(k, None)
    for k in own.keys() & set(_VIEW_KEYS["render"] + _VIEW_KEYS["grf"]):
        options[k], where[k] = own[k], own_where
    try:
        deflt = {k: "[epof]" for k in _VIEW_KEYS["epof"]}  # a key not given: its own table
        ViewSpec.from_options(options, label=lambda k: f"{where.get(k, deflt.get(k, '[render]'))} {k}")
    except InputError as e:
        raise InputError(f"{m}: {e}") from None
    return options


def load_manifest(path) -> Manifest:
    """Read and validate ``STUDY.toml``; InputError (one line: manifest, entry, problem)."""
    m = check_input_file(path, "study manifest")
    try:
        data = tomllib.loads(m.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise InputError(f"{m}: not UTF-8 text; expected a TOML study manifest") from None
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{m}: not valid TOML ({e})") from None
    except RecursionError:
        raise InputError(f"{m}: TOML nested too deeply to read") from None
    unknown = [k for k in data if k not in _TOP_KEYS]
    if unknown:
        raise InputError(f"{m}: unknown table {unknown[0]!r}; expected {', '.join(_TOP_KEYS)}")
    base = m.resolve().parent
    st = Entry(m, "[study]", data.get("study", {}), _STUDY_KEYS)
    videos = _videos(m, base, data.get("videos"))
    render = _render(m, data.get("render"))  # checked first: viewings build on it
    render["view"] = _view(m, data)
    traces = trace_defaults(m, data.get("traces"))  # [traces]: every viewing's trace defaults
    viewings = _viewings(m, base, data.get("viewings"), videos, data, render, traces)
    epof = _epof(m, data.get("epof"))  # artefacts: detected in the sphere-mode preprocessing
    videos = tuple(replace(v, artefacts=True) for v in videos) if epof["artefacts"] else videos
    return Manifest(
        path=m.resolve(),
        name=st.get("name", (str,), m.stem),
        videos=videos,
        viewings=viewings,
        epof=epof,
        render=render,
        grf=_grf(m, data.get("grf")),
        questionnaires=_questionnaires(m, base, data.get("questionnaires")),
        cache=st.path("cache", base, required=False),
        model=study_model(m, base, data.get("model"), [(v.id, v.method) for v in videos]),
    )
