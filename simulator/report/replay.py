"""What the replay of a viewing draws: its own mitigation, opacity and grains, from its render options in study.json."""

from __future__ import annotations

from pathlib import Path

from simulator.core.errors import InputError
from simulator.mitigation.grf import GrfConfig
from simulator.viewing.spec import ViewSpec

__all__ = ["replay_settings", "viewing_render"]


def viewing_render(s: dict, viewing: str) -> dict:
    """The render options of one viewing of study.json ``s``: its own (``settings.viewings``,
    written for a viewing with its own render or grain keys), else the study's ``[render]``."""
    own = ((s.get("settings") or {}).get("viewings") or {}).get(viewing)
    return own or (s.get("settings") or {}).get("render") or {}


def replay_settings(render: dict) -> dict:
    """What the replay of a viewing draws, from its render options (its ``view``, built by
    :meth:`ViewSpec.from_options` as its render is): ``kind`` (the web runtime's mitigation:
    ``none`` when the view draws nothing), the vignette's ``apertureMinDeg``, ``featherDeg``,
    ``color`` (RGB 0..1), ``opacity`` (a constant, or None: the EPOF CSV's), ``grf`` (the
    grain layout's settings), ``note`` (what the browser cannot draw as the render does)."""
    opts = render.get("view")
    if not isinstance(opts, dict):  # a study written before views were recorded
        opts = {"grf": render.get("grf"), "mitigation": render.get("mitigation"), "grid": True}
    try:
        view = ViewSpec.from_options(opts, video=False)
    except InputError:
        view = ViewSpec.from_options({"grid": True}, video=False)
    m, notes = view.mitigation, []
    kind = m.kind if view.grains is not None else ("vignette" if m.vignette else "none")
    if kind == "local-grf":
        kind = "grf"
        notes.append("local-grf is replayed as uniform grains at the viewing's opacity (the "
                     "render draws them only where the image moves)")  # fmt: skip
    opacity = view.opacity if isinstance(view.opacity, float) else None
    if isinstance(view.opacity, str) and view.opacity != "auto":
        notes.append(f"the render's opacity came from {Path(view.opacity).name}; the replay "
                     "draws the study's EPOF opacity")  # fmt: skip
    g = view.grains or GrfConfig()
    return {"kind": kind, "apertureMinDeg": m.aperture_min_deg, "featherDeg": m.feather_deg,
            "color": list(m.color), "opacity": opacity,
            "grf": {"grain_deg": g.grain_deg, "density": g.density, "inner_deg": g.inner_deg,
                    "outer_deg": g.outer_deg, "seed": g.seed},
            "note": "; ".join(notes)}  # fmt: skip
