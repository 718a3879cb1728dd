"""Spherical metadata of a video file (Spherical Video V2 ``sv3d`` / ``st3d``, Matroska's projection and stereo mode) as FFmpeg reports it.

FFmpeg's demuxers turn ``sv3d`` / ``st3d`` boxes (MP4) and Matroska's ``Projection`` /
``StereoMode`` into "spherical" and "stereo3d" side data of the video stream; PyAV does not
expose stream side data, so :func:`read_spherical` reads FFmpeg's own report of the stream
(``ffmpeg -i FILE``, the binary of the ``imageio-ffmpeg`` package; about 50 ms) and, for
Matroska, the stream's ``stereo_mode`` tag. Nothing is run but that binary on that file.
"""

from __future__ import annotations

import re
import subprocess

import imageio_ffmpeg

__all__ = ["parse_report", "read_spherical"]

#: FFmpeg's spherical projection names -> ours (``v360``'s). FFmpeg does not tell an
#: equi-angular cubemap from a plain one in ``sv3d``; 360 cameras and YouTube write EAC.
_PROJECTIONS = {
    "equirectangular": "equirect",
    "half equirectangular": "hequirect",
    "cubemap": "eac",
}
_STEREO = {
    "top and bottom": "top-bottom",
    "top_bottom": "top-bottom",
    "bottom_top": "top-bottom",
    "side by side": "side-by-side",
    "side_by_side": "side-by-side",
    "left_right": "side-by-side",
    "2d": "mono",
    "mono": "mono",
}
_SPH = re.compile(r"spherical(?: mapping)?\s*:\s*([a-z ]+?)\s*(?:\(|,|$)", re.IGNORECASE | re.MULTILINE)
_ORI = re.compile(r"\(?\s*(-?[\d.]+)\s*/\s*(-?[\d.]+)\s*/\s*(-?[\d.]+)\s*\)?")
_ST3 = re.compile(r"stereo ?3d\s*:\s*([a-z_ ]+?)\s*(?:,|$)", re.IGNORECASE | re.MULTILINE)


def parse_report(text: str, tags: dict | None = None) -> dict:
    """The spherical metadata in FFmpeg's report of a file (and a stream's tags):
    ``{"projection", "layout", "orientation_deg", "raw"}``, each None when absent."""
    out: dict = {"projection": None, "layout": None, "orientation_deg": None, "raw": []}
    m = _SPH.search(text)
    if m:
        name = m.group(1).strip().lower()
        out["raw"].append(f"spherical: {name}")
        out["projection"] = _PROJECTIONS.get(name)
        o = _ORI.search(text[m.end() - 1 : m.end() + 80])
        if o:
            out["orientation_deg"] = [float(v) for v in o.groups()]  # yaw/pitch/roll
    s = _ST3.search(text)
    mode = (tags or {}).get("stereo_mode")
    if s:
        out["raw"].append(f"stereo3d: {s.group(1).strip().lower()}")
        out["layout"] = _STEREO.get(s.group(1).strip().lower())
    elif mode:
        out["raw"].append(f"stereo_mode: {mode}")
        out["layout"] = _STEREO.get(str(mode).strip().lower())
    return out


def read_spherical(path: str, tags: dict | None = None) -> dict:
    """:func:`parse_report` of ``ffmpeg -i path``; all None if FFmpeg cannot report."""
    try:
        r = subprocess.run(
            [imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(path)],
            capture_output=True,
            check=False,
            timeout=30,
        )
    except (OSError, RuntimeError, subprocess.TimeoutExpired):
        return parse_report("", tags)
    text = r.stderr.decode(errors="replace")
    # only the first video stream's block
    i = text.find("Video:")
    return parse_report(text[i:] if i >= 0 else "", tags)
