"""Spherical metadata of a video file (Spherical Video V2 ``sv3d`` / ``st3d``, Matroska's projection and stereo mode) as FFmpeg reports it.

FFmpeg's demuxers turn ``sv3d`` / ``st3d`` boxes (MP4) and Matroska's ``Projection`` /
``StereoMode`` into "spherical" and "stereo3d" side data of the video stream; PyAV does not
expose stream side data, so :func:`read_spherical` reads FFmpeg's own report of the stream
(``ffmpeg -i FILE``, the binary of the ``imageio-ffmpeg`` package; about 50 ms) and, for
Matroska, the stream's ``stereo_mode`` tag. Nothing is run but that binary on that file.

**Initial orientation** (``sv3d``'s ``prhd`` ``pose_yaw/pitch/roll_degrees``; FFmpeg's
"spherical" side data ``(yaw/pitch/roll)``) is taken as the direction a player looks at
when the head is at yaw = pitch = roll = 0, in the head convention of SPEC.md (yaw + turns
right, toward +lon; pitch + looks up; roll + right ear down; yaw, then pitch, then roll):
the view of head pose ``H`` is the frame seen at ``R(pose) R(H)``
(:func:`view_angles_deg`). Yaw agrees with the Spherical Video V2 RFC (the projection
turned counter-clockwise about the up vector: a head at yaw 0 sees what lies at
+yaw); the RFC's wording for pitch and roll and FFmpeg's ``AVSphericalMapping`` comment
read the other way round; docs/sources.md.
"""

from __future__ import annotations

import re
import subprocess

import imageio_ffmpeg
import numpy as np

from simulator.sphere.geometry import head_angles_deg, head_rotation

__all__ = ["parse_report", "read_spherical", "view_angles_deg"]

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
#: Matroska stereo modes that store the right eye first (top, or left half).
_RIGHT_FIRST = ("bottom_top", "right_left")
#: FFmpeg's "Spherical Mapping: NAME [(yaw/pitch/roll)] [[pad N]]" (a cubemap, as YouTube
#: and 360 cameras tag EAC, ends in "[pad N]").
_SPH = re.compile(r"spherical(?: mapping)?\s*:\s*([a-z ]+?)\s*(?:\(|\[|,|$)", re.IGNORECASE | re.MULTILINE)
_ORI = re.compile(r"\(?\s*(-?[\d.]+)\s*/\s*(-?[\d.]+)\s*/\s*(-?[\d.]+)\s*\)?")
_ST3 = re.compile(r"stereo ?3d\s*:\s*([a-z_ ]+?)\s*(?:,|$)", re.IGNORECASE | re.MULTILINE)


def parse_report(text: str, tags: dict | None = None) -> dict:
    """The spherical metadata in FFmpeg's report of a file (and a stream's tags):
    ``{"projection", "layout", "eye_order", "orientation_deg", "raw"}``, each None when
    absent. ``eye_order``: ``"right-first"`` when a stereo layout stores the right eye in the
    top (or left) half (FFmpeg's "(inverted)" stereo3d flag; Matroska's ``bottom_top``,
    ``right_left``), ``"left-first"`` for another stereo layout."""
    out: dict = {"projection": None, "layout": None, "eye_order": None, "orientation_deg": None,
                 "raw": []}  # fmt: skip
    m = _SPH.search(text)
    if m:
        name = m.group(1).strip().lower()
        out["raw"].append(f"spherical: {name}")
        out["projection"] = _PROJECTIONS.get(name)
        o = _ORI.search(text[m.end() - 1 : m.end() + 80].split("\n", 1)[0])  # this line only
        if o:
            out["orientation_deg"] = [float(v) for v in o.groups()]  # yaw/pitch/roll
    s = _ST3.search(text)
    mode = (tags or {}).get("stereo_mode")
    inverted = False
    if s:
        line = text[s.start() :].split("\n", 1)[0].lower()
        out["raw"].append(f"stereo3d: {s.group(1).strip().lower()}")
        out["layout"] = _STEREO.get(s.group(1).strip().lower())
        inverted = "(inverted)" in line or str(mode or "").strip().lower() in _RIGHT_FIRST
    elif mode:
        out["raw"].append(f"stereo_mode: {mode}")
        out["layout"] = _STEREO.get(str(mode).strip().lower())
        inverted = str(mode).strip().lower() in _RIGHT_FIRST
    if out["layout"] in ("top-bottom", "side-by-side"):
        out["eye_order"] = "right-first" if inverted else "left-first"
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


def view_angles_deg(pose_deg, yaw_deg, pitch_deg, roll_deg):
    """``(yaw, pitch, roll)`` degrees in the video frame of a head at ``(yaw_deg,
    pitch_deg, roll_deg)`` when the file's initial orientation is ``pose_deg`` (yaw,
    pitch, roll; None or zeros: the head's own angles): ``R(pose) R(head)``."""
    y, p, r = (np.asarray(v, float) for v in np.broadcast_arrays(yaw_deg, pitch_deg, roll_deg))
    if pose_deg is None or not np.any(np.asarray(pose_deg, float)):
        return y, p, r
    if not np.any(np.asarray(pose_deg, float)[1:]):  # a yaw alone: exact, no Euler round trip
        return (y + float(pose_deg[0]) + 180.0) % 360.0 - 180.0, p, r
    return head_angles_deg(head_rotation(*(float(v) for v in pose_deg)) * head_rotation(y, p, r))
