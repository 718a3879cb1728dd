"""vimsim compare reads frames.json too: what changed, the cause first."""

from __future__ import annotations

import copy

from simulator.testing.compare import frames_json_changes

GOLDEN = {
    "video": "v.mp4", "headpath": "p.csv", "grid": None, "layout": "mono", "hold": False,
    "video_size": [128, 64], "fps": 10.0,
    "renderer": {"eye_size": [96, 96], "hfov_deg": 107.0, "mitigation": "grf", "opacity": 0.8},
    "versions": {"vimsim": "1", "GL_RENDERER": "llvmpipe (LLVM 15)"},
    "frames": [{"file": f"t{k}.png", "yaw_deg": 10.0 * k, "pitch_deg": 0.0, "roll_deg": 0.0,
                "opacity": 0.8} for k in range(3)],
}  # fmt: skip


def _new(**kw):
    d = copy.deepcopy(GOLDEN)
    for k, v in kw.items():
        d[k] = v
    return d


def test_nothing_changed():
    assert frames_json_changes(GOLDEN, _new(), pixels_differ=False) == []


def test_head_path_changed_comes_first():
    new = _new()
    new["frames"][1]["yaw_deg"] += 2.5
    new["renderer"]["eye_size"] = [64, 64]
    out = frames_json_changes(GOLDEN, new, pixels_differ=True)
    assert out[0].startswith("the head path changed: 1 frame(s)") and "2.5 deg" in out[0]
    assert any(x.startswith("the render settings changed: eye_size") for x in out)


def test_renderer_changed_when_only_pixels_differ():
    new = _new(versions={"vimsim": "1", "GL_RENDERER": "llvmpipe (LLVM 17)"})
    out = frames_json_changes(GOLDEN, new, pixels_differ=True)
    assert out[0].startswith("the renderer changed") and "LLVM 17" in out[0]
    assert frames_json_changes(GOLDEN, _new(), pixels_differ=True)[0].startswith(
        "the renderer changed")


def test_opacity_and_missing_index():
    new = _new()
    new["frames"][0]["opacity"] = 0.5
    assert frames_json_changes(GOLDEN, new, True)[0].startswith("the opacity changed")
    assert "no frames.json" in frames_json_changes(None, GOLDEN, True)[0]
