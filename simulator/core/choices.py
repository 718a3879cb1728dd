"""Every fixed list of choices (modes, layouts, formats), once: light enough for the CLI to import.

Library modules take their ``Literal`` types and tuples from here and the CLI's
``choices=`` use the same tuples, so the two cannot drift apart. Nothing here imports
anything heavier than :mod:`typing`.
"""

from __future__ import annotations

from typing import Literal, get_args

__all__ = [
    "CAMERA_INTERPS",
    "DIS_PRESETS",
    "EPOF_METHODS",
    "EYES",
    "FLOW_STATS",
    "GRID_PRESET_NAMES",
    "HEADPATH_FORMATS",
    "HEADSET_NAMES",
    "INTERPS",
    "LAYOUTS",
    "MAX_CLIP_FPS",
    "MAX_CLIP_FRAMES",
    "MITIGATIONS",
    "MITIGATION_HELP",
    "OPACITY_RULES",
    "OPACITY_RULE_DEFAULT",
    "OPACITY_RULE_HELP",
    "OPACITY_SOURCES",
    "PREPROCESS_METHODS",
    "PROJECTIONS",
    "SCENES",
    "STILL_FPS",
    "STILL_SECONDS",
    "SYNTH_KINDS",
    "SYNTH_LAYOUTS",
    "SYSTEM_PRESETS",
    "X264_PRESETS",
    "DISPreset",
    "Eye",
    "Interp",
]

#: Headset profiles (:data:`simulator.sphere.headsets.HEADSETS`, in the same order).
HEADSET_NAMES: tuple[str, ...] = ("vive-pro-eye", "vive-focus-3", "pimax-crystal", "quest-2")

#: Stereo layouts of an equirect frame: ``top-bottom`` (left eye on top),
#: ``side-by-side`` (left eye on the left).
LAYOUTS: tuple[str, ...] = ("mono", "top-bottom", "side-by-side")

#: Input projections, ffmpeg ``v360``'s names (:data:`simulator.sphere.projections.PROJECTIONS`).
PROJECTIONS: tuple[str, ...] = ("equirect", "eac", "c3x2", "c6x1", "dfisheye", "hequirect")

#: A still image given to ``render`` / ``frames`` is a clip of this many seconds at this rate
#: (``--seconds`` / ``--fps``).
STILL_SECONDS = 10.0
STILL_FPS = 30.0

#: Upper bounds of a clip vimsim makes (``synth``, ``demo``, a still's ``--seconds`` x
#: ``--fps``): a typo such as ``--fps 1e9`` or ``--seconds 1e9`` fails at once, not after hours.
MAX_CLIP_FPS = 240.0
MAX_CLIP_FRAMES = 100_000

#: Eyes of a stereo source or render.
Eye = Literal["left", "right"]
EYES: tuple[str, ...] = get_args(Eye)

#: Interpolation kernels of :func:`simulator.sphere.geometry.sample_equirect`. ``cubic``: OpenCV's
#: bicubic (Keys, a = -0.75); ``lagrange``: ffmpeg v360's 4-point Lagrange kernel.
Interp = Literal["cubic", "lagrange", "linear", "nearest"]
INTERPS: tuple[str, ...] = get_args(Interp)

#: Window-grid presets (:data:`simulator.sphere.windows.GRID_PRESETS`).
GRID_PRESET_NAMES: tuple[str, ...] = ("default", "paper-198", "cao2021")

#: Preprocessing methods: the paper's windows, or one field per frame on the sphere.
PREPROCESS_METHODS: tuple[str, ...] = ("paper", "sphere")

#: EPOF methods: ``auto`` = exact (sphere) when the grid holds a field, else paper.
EPOF_METHODS: tuple[str, ...] = ("auto", "paper", "sphere")

#: Whole-system presets (``--preset``; docs/parity.md): ``vimsim`` = vimsim's own defaults;
#: ``paper`` = the paper's text (overlap-weighted EPOF, per-video 10th/90th percentiles, 1.5 deg
#: grains, 36-80 deg soft cutout); ``cao2021-code`` = the authors' Unity code (nearest window
#: with its list indexing, fixed 0.18..53.73 px/frame scale, 0.5 deg Fibonacci grains, no
#: cutout; :mod:`simulator.mitigation.cao2021`).
SYSTEM_PRESETS: tuple[str, ...] = ("vimsim", "paper", "cao2021-code")

#: OpenCV DIS presets (:class:`simulator.flow.dis.DISFlow`).
DISPreset = Literal["ultrafast", "fast", "medium"]
DIS_PRESETS: tuple[str, ...] = get_args(DISPreset)

#: What is drawn over the video, each kind with its one-line help (``--mitigation``, the
#: study's ``mitigation``); what each draws and lets through is its entry in
#: :data:`simulator.mitigation.kinds.KINDS` (same names, same order).
MITIGATION_HELP: dict[str, str] = {
    "grf": "the paper's grains; the default, see --grf",
    "vignette": "head-fixed tunneling: the aperture shrinks with the opacity",
    "grf+vignette": "both, same opacity",
    "local-grf": "grains only where the flow is high: each direction's own flow from a "
    "sphere-mode --grid",
    "none": "nothing",
}
MITIGATIONS: tuple[str, ...] = tuple(MITIGATION_HELP)

#: Where the opacity percentiles come from: every window of the grid, or this viewing's EPOF.
OPACITY_SOURCES: tuple[str, ...] = ("grid", "viewing")

#: Opacity rules, one entry each (a new rule: one entry here and one branch in
#: :func:`simulator.mitigation.grf.rule_from_options`): ``absolute`` (the default) is eased,
#: between fixed deg/s (``low_dps``/``high_dps``, the same for every video); ``comfort``
#: (eased) and ``paper`` are relative (percentiles of the video's flow).
OPACITY_RULE_HELP: dict[str, str] = {
    "comfort": "eased as absolute, opacity 0 at --low-pct and 1 at --high-pct percentile of "
    "this video's flow (relative)",
    "paper": "the paper's rule: opacity 0 at the 10th, 1 at the 90th percentile of this "
    "video's flow (relative; --low-pct/--high-pct), frame by frame (no smoothing, no easing)",
    "absolute": "the default: opacity 0 at --low-dps (5) and 1 at --high-dps (30) deg/s "
    "whatever the video, eased (--ease-in/--ease-out); a calm video gets no grains",
}
OPACITY_RULES: tuple[str, ...] = tuple(OPACITY_RULE_HELP)
#: The rule every command, manifest, report and export uses unless told otherwise.
OPACITY_RULE_DEFAULT = "absolute"

#: Scripted head paths (:func:`simulator.traces.path.synth`).
SYNTH_KINDS: tuple[str, ...] = ("static", "sweep", "sine", "look-around", "keyframes")

#: Head-path file formats :func:`simulator.traces.readers.load_headpath` reads (``auto`` detects
#: one of these from the content).
HEADPATH_FORMATS: tuple[str, ...] = (
    "canonical",
    "quat",
    "keyframes-json",
    "corbillon",
    "corbillon-euler",
    "salient360-dyn",
    "salient360-static",
    "avtrack360",
    "360vidstr",
)

#: Synthetic scenes (:mod:`simulator.synth`) and their layouts.
SCENES: tuple[str, ...] = ("rotate", "forward", "coaster", "trajectory")

#: How camera positions are interpolated between the poses of a trajectory CSV.
CAMERA_INTERPS: tuple[str, ...] = ("linear", "cubic")
SYNTH_LAYOUTS: tuple[str, ...] = ("mono", "top-bottom")

#: How a session's flow is summarised from its EPOF CSV (:mod:`simulator.analyze`).
FLOW_STATS: tuple[str, ...] = ("mean", "median", "sum")

#: x264 presets ``vimsim render --preset`` accepts.
X264_PRESETS: tuple[str, ...] = (
    "ultrafast",
    "superfast",
    "veryfast",
    "faster",
    "fast",
    "medium",
    "slow",
)
