"""The report's HTML pages: summary, viewings table, one page per video and per viewing, the analysis."""

from __future__ import annotations

import csv
import html
import json
import re
from pathlib import Path

__all__ = ["Site", "video_href", "viewing_href"]

_SAFE = re.compile(r"[^A-Za-z0-9._-]")


def _slug(x: str) -> str:
    return _SAFE.sub("_", str(x))


def viewing_href(vid: str) -> str:
    return f"viewing-{_slug(vid)}.html"


def video_href(vid: str) -> str:
    return f"video-{_slug(vid)}.html"


def _e(x) -> str:
    return html.escape(str(x), quote=True)


def _json_script(id_: str, obj) -> str:
    text = json.dumps(obj, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    return f'<script type="application/json" id="{id_}">{text}</script>'


def _page(title: str, body: str, scripts: str = "") -> str:
    nav = ('<nav><a href="index.html">summary</a> <a href="viewings.html">viewings</a> '
           '<a href="analysis.html">analysis</a></nav>')  # fmt: skip
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<link rel="icon" href="data:,">\n'
        f"<title>{_e(title)} - vimsim study report</title>\n"
        '<link rel="stylesheet" href="assets/report.css">\n</head>\n<body>\n'
        f"{nav}\n<main>\n<h1>{_e(title)}</h1>\n{body}\n</main>\n"
        '<script src="assets/report.js"></script>\n'
        f"{scripts}</body>\n</html>\n"
    )


def _table(header: list[str], rows: list[list], cls: str = "") -> str:
    head = "".join(f"<th>{_e(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    return f'<table class="{cls}"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>'


def _dl(d: dict) -> str:
    return "<dl>" + "".join(f"<dt>{_e(k)}</dt><dd>{_e(v)}</dd>" for k, v in d.items()) + "</dl>"


class Site:
    """The pages of one study's report (``study``: study.json; ``rows``: viewings.csv rows;
    ``videos``: what :mod:`simulator.report.build` made per video)."""

    def __init__(self, study: dict, rows: list[dict], videos: dict):
        # each viewing's system preset (the study's [epof] preset; docs/parity.md)
        preset = ((study.get("settings") or {}).get("epof") or {}).get("preset") or "vimsim"
        self.s, self.videos = study, videos
        self.rows = [{**r, "preset": preset} for r in rows]

    def static_pages(self):
        yield "index.html", self.summary_page()
        yield "viewings.html", self.viewings_page()
        for vid in self.videos:
            yield video_href(vid), self.video_page(vid)

    def summary_page(self) -> str:
        s = self.s
        c = s.get("counts", {})
        parts = ["<h2>Counts</h2>", _dl(c)]
        warn = s.get("warnings") or []
        parts += ["<h2>Warnings</h2>", "<ul>" + "".join(f"<li>{_e(w)}</li>" for w in warn) + "</ul>"
                  if warn else "<p>none</p>"]  # fmt: skip
        fails = s.get("failures") or []
        parts += ["<h2>Failures</h2>", _table(["viewing", "status"], [
            [f'<a href="{viewing_href(f["viewing"])}">{_e(f["viewing"])}</a>', _e(f["status"])]
            for f in fails]) if fails else "<p>none</p>"]  # fmt: skip
        parts += ["<h2>Videos</h2>", _table(["video", "grid", "source", "browser copy"], [
            [f'<a href="{video_href(v)}">{_e(v)}</a>', _e((d.get("export") or {}).get("mode", "none")),
             _e(Path((s.get("videos") or {}).get(v, {}).get("path", "")).name),
             _e(_copy_text(d.get("copy")))] for v, d in self.videos.items()])]  # fmt: skip
        parts += ["<h2>Settings</h2>", f"<pre>{_e(json.dumps(s.get('settings'), indent=1))}</pre>"]
        t = {
            k: (f"{v:.2f} s" if isinstance(v, float) else v)
            for k, v in (s.get("timings_s") or {}).items()
        }
        parts += ["<h2>Timings</h2>", _dl(t), "<h2>Versions</h2>", _dl(s.get("versions") or {})]
        parts.insert(0, f"<p>Study <b>{_e(s.get('name') or '')}</b>, manifest "
                        f"{_e(Path(str(s.get('manifest', ''))).name)}, executor {_e(s.get('executor', ''))}.</p>")  # fmt: skip
        return _page("Study summary", "\n".join(parts))

    def viewings_page(self) -> str:
        cols = list(self.rows[0].keys()) if self.rows else ["viewing"]
        body = []
        for r in self.rows:
            cells = []
            for c in cols:
                v = r.get(c) or ""
                if c == "viewing":
                    cells.append(f'<a href="{viewing_href(v)}">{_e(v)}</a>')
                elif c == "video":
                    cells.append(f'<a href="{video_href(v)}">{_e(v)}</a>')
                elif c == "trace":
                    cells.append(f'<span title="{_e(v)}">{_e(Path(v).name)}</span>')
                else:
                    cells.append(_short_number(v))
            body.append(cells)
        filters = "".join(
            f'<label>{_e(c)} <select data-filter="{_e(c)}"><option value="">all</option>'
            + "".join(f"<option>{_e(v)}</option>" for v in sorted({r.get(c) or "" for r in self.rows}))
            + "</select></label> "
            for c in ("condition", "video", "status") if c in cols
        )  # fmt: skip
        if "warnings" in cols:
            filters += (
                '<label>warnings <input data-filter-text="warnings" placeholder="contains"></label>'
            )
        filters += ' <span id="shown"></span>'
        text = ("<p>Click a column header to sort; the filters keep matching rows. "
                f"{len(self.rows)} viewings.</p>")  # fmt: skip
        if (self.s.get("model") or {}).get("note"):  # [model]: the predictions' accuracy
            text += f'<p class="model">{_e(self.s["model"]["note"])}</p>'
        return _page("Viewings", text + f'<p class="filters">{filters}</p>'
                     + _table(cols, body, "viewings sortable"))  # fmt: skip

    def video_page(self, vid: str) -> str:
        d = self.videos[vid]
        parts = []
        ex = d.get("export")
        if ex:
            vp = ex["viewport"]
            parts.append(f"<p>Grid: {_e(ex['mode'])} mode, {ex['fps']:g} fps, viewport "
                         f"{vp['hfov_deg']:g} x {vp['vfov_deg']:g} deg. Browser copy: "
                         f"{_e(_copy_text(d.get('copy')))}.</p>")  # fmt: skip
        titles = {"epof_viewers.png": "EPOF across viewers (median, 10-90 % band)",
                  "provocative.png": "Time x yaw map of the flow on the horizon row, viewers' yaw as dots"}  # fmt: skip
        for name in d.get("plots", []):
            parts.append(f"<h2>{_e(titles.get(name, name))}</h2>"
                         f'<img class="plot" src="media/{_e(vid)}/{_e(name)}" alt="{_e(name)}">')  # fmt: skip
        ms = d.get("moments") or []
        if ms:
            rows = [[_e(m.get("rank", "")), _e(m.get("time_s", "")), _e(m.get("yaw_deg", "")),
                     _e(m.get("pitch_deg", "")), _e(m.get("pof_dps", "")),
                     (f'<img class="thumb" src="media/{_e(vid)}/{_e(m["thumbnail"])}" alt="moment">'
                      if m.get("thumbnail") else "")] for m in ms]  # fmt: skip
            n_art = int(d.get("artefacts_left_out") or 0)
            kinds = ", ".join(f"{k}: {c}" for k, c in (d.get("artefact_kinds") or {}).items())
            parts += ["<h2>Most provocative moments</h2>",
                      (f'<p class="artefacts">{n_art} frames left out as artefacts'
                      f"{f' ({_e(kinds)})' if kinds else ''}.</p>"),
                      _table(["rank", "time (s)", "yaw (deg)", "pitch (deg)", "POF (deg/s)", "view"], rows)]  # fmt: skip
        mine = [r for r in self.rows if r.get("video") == vid]
        parts += ["<h2>Viewings</h2>", "<ul>" + "".join(
            f'<li><a href="{viewing_href(r["viewing"])}">{_e(r["viewing"])}</a> ({_e(r.get("status", ""))})</li>'
            for r in mine) + "</ul>"]  # fmt: skip
        return _page(f"Video {vid}", "\n".join(parts))

    def viewing_page(self, row: dict, data: dict | None) -> str:
        vid = row["viewing"]
        info = _dl({k: v for k, v in row.items() if k not in ("viewing",)})
        if data is None:
            return _page(
                f"Viewing {vid}", info + "<p>No EPOF for this viewing (see its status).</p>"
            )
        video = self.videos.get(row["video"], {})
        copy = video.get("copy") or {}
        data = {**data, "media": f"media/{row['video']}.mp4" if copy else None,
                "media_start_s": float(copy.get("start_s", 0.0)),
                "export": f"data/{row['video']}/" if video.get("export") else None}  # fmt: skip
        body = f"""{info}
<h2>EPOF and opacity</h2>
<p>EPOF (deg/s, blue) and GRF opacity (0..1, orange) per frame; click to move the cursor.</p>
<canvas id="timeline" width="960" height="200"></canvas>
<h2>Replay</h2>
<p id="replay-note" class="note"></p>
<div id="replay" hidden>
<p><button id="play">play</button> <button id="freelook">free look: off</button>
<button id="xr" hidden>enter VR</button>
time <b id="t">0</b> s, frame <b id="frame">0</b>, yaw/pitch/roll <b id="pose">-</b> deg,
EPOF <b id="epof">-</b> deg/s, opacity <b id="opacity">-</b> <span id="mode"></span></p>
<canvas id="eye"></canvas>
<video id="video" muted playsinline preload="auto" hidden></video>
</div>
{_json_script("viewing-data", data)}"""
        loader = ('<script>if (location.protocol !== "file:") { const s = document.createElement("script");'
                  ' s.type = "module"; s.src = "assets/replay.js"; document.body.appendChild(s); }</script>\n')  # fmt: skip
        return _page(f"Viewing {vid}", body, loader)

    def analysis_page(self, folder: Path) -> str:
        an = (self.s.get("outputs") or {}).get("analysis")
        if not an:
            return _page("Analysis", "<p>This study has no [questionnaires]: no analysis.</p>")
        if an.get("error"):
            return _page("Analysis", f"<p>The analysis was not made: {_e(an['error'])}</p>")
        parts = []
        for name, title in (("tests.csv", "Tests of the design (effect sizes, 95 % intervals, Holm)"),
                            ("model.csv", "Mixed model: ssq_total ~ condition + flow + mssq"),
                            ("power.csv", "Power (participants needed)"),
                            ("table.csv", "The paper's table: K_OF means per condition, Mann-Whitney"),
                            ("normality.csv", "Normality (Shapiro-Wilk)"), ("scores.csv", "Scores")):  # fmt: skip
            p = folder / name
            if p.is_file():
                with open(p, newline="", encoding="utf-8") as f:
                    rows = [r for r in csv.reader(f) if r and not r[0].startswith("#")]
                if rows:
                    parts += [
                        f"<h2>{_e(title)}</h2>",
                        _table(rows[0], [[_e(c) for c in r] for r in rows[1:]]),
                    ]
        if (folder / "boxplots.png").is_file():
            parts += [
                "<h2>Boxplots</h2>",
                '<img class="plot" src="media/analysis/boxplots.png" alt="boxplots">',
            ]
        if (folder / "analysis.md").is_file():
            parts += ["<h2>In plain words: which test, why, what the effect means</h2>",
                      f"<pre>{_e((folder / 'analysis.md').read_text(encoding='utf-8'))}</pre>"]  # fmt: skip
        if (folder / "report.md").is_file():
            parts += ["<h2>Report (formula used, exclusions)</h2>",
                      f"<pre>{_e((folder / 'report.md').read_text(encoding='utf-8'))}</pre>"]  # fmt: skip
        return _page("Analysis", "\n".join(parts) or "<p>No analysis files.</p>")


def _short_number(v: str) -> str:
    """A long decimal shown with 4 significant digits (the full value as its title)."""
    if "." in v and len(v) > 8:
        try:
            return f'<span title="{_e(v)}">{float(v):.4g}</span>'
        except ValueError:
            pass
    return _e(v)


def _copy_text(c: dict | None) -> str:
    if not c:
        return "none (source missing)"
    return f"{c['width']}x{c['height']} H.264, {c['how']}"
