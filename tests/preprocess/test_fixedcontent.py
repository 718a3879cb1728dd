"""Screen-fixed graphics, camera-fixed content and the decoder's key-frame flags
(:mod:`simulator.preprocess.fixedcontent`) on block signals with a known answer."""

from __future__ import annotations

import numpy as np

from simulator.preprocess.artefacts import FrameSignals, detect_artefacts
from simulator.preprocess.fixedcontent import fixed_content, keyframe_flags

ROWS, COLS, FPS, T = 16, 32, 30.0, 180


def _scene(seed=0):
    """A moving textured scene: every block changes by ~5 gray levels, contrast ~10."""
    rng = np.random.default_rng(seed)
    d = rng.uniform(4.0, 6.0, (T, ROWS * COLS))
    s = rng.uniform(8.0, 12.0, (T, ROWS * COLS))
    return d, s


def _blocks(r0, r1, c0, c1):
    m = np.zeros((ROWS, COLS), bool)
    m[r0:r1, c0:c1] = True
    return m.ravel()


def test_moving_scene_has_no_fixed_content():
    d, s = _scene()
    out = fixed_content(d, s, FPS)
    assert not out["overlay"].any() and not out["camera-fixed"].any() and out["events"] == []


def test_animated_panel_appearing_is_an_overlay():
    """A lower third from frame 60 to 149: its panel is still, its bar animates."""
    d, s = _scene()
    panel, bar = _blocks(10, 12, 12, 20), _blocks(11, 12, 13, 15)
    d[60:150, panel] = 0.1
    d[60:150, bar] = 3.0  # the animation inside the panel
    out = fixed_content(d, s, FPS)
    (ev,) = out["events"]
    assert ev["kind"] == "overlay" and ev["blocks"] == [10, 11, 12, 19]
    assert out["overlay"][70:140].all() and not out["overlay"][:40].any()
    assert not out["overlay"][170:].any() and not out["camera-fixed"].any()


def test_hand_at_the_nadir_is_camera_fixed_and_only_its_moves_are_labelled():
    d, s = _scene()
    hand = _blocks(14, 16, 10, 16)  # bottom rows: where a hand or a rig is
    d[:, hand] = 0.2
    d[90:100, hand] = 2.5  # the hand moves
    out = fixed_content(d, s, FPS)
    assert [e["kind"] for e in out["events"]] == ["camera-fixed"]
    assert out["camera-fixed"][90:100].all() and out["camera-fixed"].sum() <= 15
    assert not out["overlay"].any()
    lon0, lon1, lat0, lat1 = out["events"][0]["region_deg"]
    assert (lon0, lon1, lat0, lat1) == (-67.5, 0.0, -90.0, -67.5)


def test_flat_still_blocks_are_no_evidence():
    """A flat region (clear sky) looks still whether it moves or not: never fixed content."""
    d, s = _scene()
    sky = _blocks(0, 4, 0, 32)
    d[:, sky], s[:, sky] = 0.05, 0.5
    assert fixed_content(d, s, FPS)["events"] == []


def test_end_card_after_a_cut():
    d, s = _scene()
    d[121:], s[121:] = 0.05, 0.2  # a flat, still card ...
    box = _blocks(7, 9, 5, 9)
    d[121:, box], s[121:, box] = 8.0, 20.0  # ... with a box sliding across
    onset = np.zeros(T, bool)
    onset[120] = True
    out = fixed_content(d, s, FPS, onset=onset)
    assert out["overlay"][121:].all() and not out["overlay"][:120].any()
    assert not fixed_content(d, s, FPS)["overlay"].any()  # no cut or fade: not a card


def test_keyframe_needs_the_decoders_flag():
    """A picture reset on a frame the encoder did not mark as a key frame (a thumb passing
    the lens) is not a codec keyframe; on a marked one it is."""
    rng = np.random.default_rng(3)
    bd = rng.uniform(1.0, 1.2, (T, ROWS * COLS)).astype(np.float32)
    bd[100] = 8.0  # a reset
    sig = {"mean": np.full(T, 100.0), "std": np.full(T, 30.0), "corr": np.full(T, 0.99),
           "block_diff": bd, "coarse": np.tile(np.linspace(50, 150, 128, dtype=np.float32), (T, 1)),
           "fps": FPS, "hist": np.full(T, 0.01)}  # fmt: skip
    assert detect_artefacts(FrameSignals(**sig)).kind[100] == "keyframe"
    key = np.zeros(T, bool)
    key[0] = True
    assert detect_artefacts(FrameSignals(**sig, key=key)).kind[100] == ""
    key[100] = True
    assert detect_artefacts(FrameSignals(**sig, key=key)).kind[100] == "keyframe"


def test_keyframe_flags_of_a_file(tmp_path):
    import av

    p = tmp_path / "k.mp4"
    with av.open(str(p), "w") as c:  # GOP 10, no B-frames, no scene-cut key frames
        st = c.add_stream("libx264", rate=10, options={"g": "10", "bf": "0", "sc_threshold": "0"})
        st.width, st.height, st.pix_fmt = 64, 32, "yuv420p"
        for i in range(25):
            img = np.full((32, 64, 3), 10 * i % 250, np.uint8)
            c.mux(st.encode(av.VideoFrame.from_ndarray(img, format="rgb24")))
        c.mux(st.encode())
    flags = keyframe_flags(p)
    assert flags is not None and len(flags) == 25
    assert list(np.flatnonzero(flags)) == [0, 10, 20]
    assert list(np.flatnonzero(keyframe_flags(p, start=5, end=15))) == [5]
    assert keyframe_flags(tmp_path / "missing.mp4") is None
