"""The screening's one-page browser summary, ``OUTDIR/screen/index.html`` (offline, no script).

One self-contained page (inline CSS, no CDN, no JavaScript) a producer reads: the comparison
table across videos (``comparison.csv``'s columns), the named flow bands and their sources,
and per video its ``summary.png``, ``map.png``, the most provocative moments (thumbnail
and caption) and the artefacts left out. Every link and image is a file of the same
``screen/`` folder (relative paths), so the folder can be moved or mailed as it is.
"""

from __future__ import annotations

import html
import math
from pathlib import Path
from urllib.parse import quote

from simulator.core.fileio import atomic_output
from simulator.mitigation.bands import BANDS

__all__ = ["PAGE_NAME", "write_screen_page"]

PAGE_NAME = "index.html"

_CSS = """
body{font-family:system-ui,sans-serif;margin:1.5em auto;max-width:1100px;padding:0 1em;color:#222}
table{border-collapse:collapse;margin:.5em 0 1em;font-size:.9em}
th,td{border:1px solid #ccc;padding:.25em .5em;text-align:right}
th{background:#f2f2f2} td:first-child,th:first-child{text-align:left}
img.plot{max-width:100%;border:1px solid #ddd}
.moments{display:flex;flex-wrap:wrap;gap:.8em}
figure{margin:0} figcaption{font-size:.85em;max-width:240px}
.swatch{display:inline-block;width:1em;height:1em;border:1px solid #999;vertical-align:middle}
section.video{border-top:2px solid #ddd;margin-top:1.5em}
"""


def _e(x) -> str:
    return html.escape(str(x), quote=True)


def _cell(v) -> str:
    if isinstance(v, float):
        return f"{v:.3g}" if math.isfinite(v) else ""
    return _e(v)


def _table(header, rows) -> str:
    head = "".join(f"<th>{_e(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _href(vid: str, name: str) -> str:
    """A relative link to ``<vid>/<name>`` inside the screen folder (URL-escaped)."""
    return _e(f"{quote(vid)}/{quote(name)}")


def _video_section(vid: str, r: dict) -> str:
    if "error" in r:
        return f'<section class="video" id="v-{_e(vid)}"><h2>{_e(vid)}</h2><p>{_e(r["error"])}</p></section>'
    parts = [f'<section class="video" id="v-{_e(vid)}"><h2>{_e(vid)}</h2>',
             f'<img class="plot" src="{_href(vid, "summary.png")}" alt="summary of {_e(vid)}">',
             "<h3>Time x yaw map (artefact frames grey)</h3>",
             f'<img class="plot" src="{_href(vid, "map.png")}" alt="map of {_e(vid)}">',
             "<h3>Most provocative moments (artefacts left out)</h3>"]  # fmt: skip
    figs = []
    for mo in r.get("moments", []):
        cap = (f"#{mo['rank']}: {mo['time_s']:.1f} s (frame {mo['frame']}), yaw "
               f"{mo['yaw_deg']:+.0f} deg: {mo['pof_dps']:.0f} deg/s, {mo['band']}; "
               f"{mo['directions']} yaw directions within 80 %")  # fmt: skip
        img = (f'<img src="{_href(vid, mo["thumbnail"])}" alt="moment {mo["rank"]}">'
               if mo.get("thumbnail") else "")  # fmt: skip
        figs.append(f"<figure>{img}<figcaption>{_e(cap)}</figcaption></figure>")
    parts.append(f'<div class="moments">{"".join(figs)}</div>' if figs else "<p>No moment.</p>")
    events = r.get("artefacts") or []
    parts.append("<h3>Artefacts left out</h3>")
    if events:
        parts.append(_table(["kind", "frames", "from (s)", "to (s)"],
                            [[_e(ev["kind"]), f"{ev['first']}-{ev['last']}", _cell(ev["start_s"]),
                              _cell(ev["end_s"])] for ev in events]))  # fmt: skip
    elif r.get("artefacts_on", True):
        parts.append("<p>No artefacts found (keyframes, cuts, fades, overlays).</p>")
    else:
        parts.append("<p>Artefact detection was off for this screening.</p>")
    files = ("epof_distribution.csv", "map.csv", "sphere_flow.csv", "moments.csv")
    parts.append(
        "<p>Data: " + ", ".join(f'<a href="{_href(vid, f)}">{_e(f)}</a>' for f in files) + "</p>"
    )
    return "\n".join(parts) + "</section>"


def write_screen_page(folder: Path, report: dict, columns) -> Path:
    """Write ``folder/index.html`` (atomically) from :func:`write_screen_outputs`' report:
    ``report["rows"]`` (the comparison rows, ``columns`` their order) and
    ``report["videos"]`` (per video its moments and artefacts, or its error)."""
    rows = [[(f'<a href="#v-{_e(r[c])}">{_e(r[c])}</a>' if c == "video" else _cell(r[c]))
             for c in columns] for r in report["rows"]]  # fmt: skip
    bands = [[f'<span class="swatch" style="background:{_e(b.colour)}"></span> {_e(b.name)}',
              f"{b.lo_dps:g}", f"{b.hi_dps:g}" if math.isfinite(b.hi_dps) else "", _e(b.source)]
             for b in BANDS]  # fmt: skip
    body = [
        "<h1>vimsim screen: comparison of the videos</h1>",
        (
            "<p>EPOF statistics over all viewers and frames, artefact frames left out; "
            '<a href="comparison.csv">comparison.csv</a>, <a href="screen.json">screen.json</a>.</p>'
        ),
        _table(columns, rows),
        *([f'<p class="model">{_e(report["model"]["note"])}</p>'] if report.get("model") else []),
        "<h2>Flow bands (deg/s) and their sources</h2>",
        _table(["band", "from", "to", "source"], bands),
        *(_video_section(vid, r) for vid, r in report["videos"].items()),
    ]
    text = ('<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            '<link rel="icon" href="data:,">\n<title>vimsim screen</title>\n'
            f"<style>{_CSS}</style>\n</head>\n<body>\n" + "\n".join(body) + "\n</body>\n</html>\n")  # fmt: skip
    path = Path(folder) / PAGE_NAME
    with atomic_output(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
    return path
