"""Flow backends: zero flow on identical frames, known translations, the TorchScript
interface and its validation, backend parsing."""

from __future__ import annotations

import numpy as np
import pytest

from simulator.core.errors import InputError
from simulator.flow.base import make_backend
from simulator.flow.dis import DISFlow
from simulator.flow.farneback import FarnebackFlow
from simulator.flow.rays import RayAngles
from simulator.flow.torchscript import TorchFlow
from simulator.sphere.geometry import perspective_rays


def _texture(h: int = 128, w: int = 128, seed: int = 0) -> np.ndarray:
    """Smooth random texture (uint8), enough structure for any flow method."""
    import cv2

    rng = np.random.default_rng(seed)
    t = rng.random((h // 4, w // 4)).astype(np.float32)
    t = cv2.resize(t, (w, h), interpolation=cv2.INTER_CUBIC)
    t = cv2.GaussianBlur(t, (0, 0), 1.0)
    return np.clip((t - t.min()) / (t.max() - t.min()) * 255, 0, 255).astype(np.uint8)


def _shift(img: np.ndarray, dx: float, dy: float) -> np.ndarray:
    """Content moved by (+dx right, +dy down) with sub-pixel bicubic sampling."""
    import cv2

    M = np.float32([[1, 0, dx], [0, 1, dy]])
    return cv2.warpAffine(
        img, M, img.shape[::-1], flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT
    )


@pytest.mark.parametrize(
    "backend",
    [DISFlow("ultrafast"), DISFlow("fast"), FarnebackFlow()],
    ids=lambda b: b.describe().get("preset", b.name),
)
def test_identical_frames_give_zero_flow(backend):
    a = np.stack([_texture(seed=1), _texture(seed=2)])
    f = backend(a, a.copy())
    assert f.shape == (2, 128, 128, 2) and f.dtype == np.float32
    # Farneback's polynomial expansion leaves small values in the outermost rows/columns.
    assert np.abs(f[:, 8:-8, 8:-8]).max() < 1e-3
    assert np.abs(f).mean() < 1e-2


@pytest.mark.parametrize(
    "backend",
    [DISFlow("ultrafast"), DISFlow("fast"), FarnebackFlow()],
    ids=lambda b: b.describe().get("preset", b.name),
)
@pytest.mark.parametrize("dx,dy", [(1.5, 0.0), (-0.7, 2.2)])
def test_known_translation(backend, dx, dy):
    img = _texture()
    f = backend(img[None], _shift(img, dx, dy)[None])[0]
    inner = f[16:-16, 16:-16].reshape(-1, 2)
    # Mean error of the recovered translation below 0.15 px (borders excluded).
    assert np.abs(np.median(inner[:, 0]) - dx) < 0.15
    assert np.abs(np.median(inner[:, 1]) - dy) < 0.15


def test_dis_deterministic_and_thread_local():
    import threading

    img = _texture()
    b = DISFlow()
    ref = b(img[None], _shift(img, 1.0, 0.5)[None])
    out = []
    th = threading.Thread(target=lambda: out.append(b(img[None], _shift(img, 1.0, 0.5)[None])))
    th.start()
    th.join()
    assert np.array_equal(ref, out[0])


def test_bad_input_shapes():
    with pytest.raises(ValueError, match="uint8"):
        DISFlow()(np.zeros((1, 8, 8), np.float32), np.zeros((1, 8, 8), np.float32))


@pytest.mark.parametrize("spec", ["lucas", "dis:slowest", "farneback:x", "torch:"])
def test_make_backend_rejects(spec):
    with pytest.raises(InputError):
        make_backend(spec)


def test_make_backend_names():
    assert make_backend("dis").describe()["preset"] == "ultrafast"
    assert make_backend("dis:fast").describe()["preset"] == "fast"
    assert make_backend("farneback").name == "farneback"


# ----------------------------------------------------------------------------- torch
def _save_constant_model(path, dx: float, dy: float, channels: int = 2):
    torch = pytest.importorskip("torch")

    class Const(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.register_buffer("v", torch.tensor([dx, dy] + [0.0] * (channels - 2))[:channels])

        def forward(self, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
            n, _, h, w = a.shape
            return self.v.view(1, -1, 1, 1).expand(n, -1, h, w) + 0.0 * (a[:, :1] - b[:, :1])

    torch.jit.script(Const()).save(str(path))
    return path


@pytest.mark.slow
def test_torch_constant_model(tmp_path):
    p = _save_constant_model(tmp_path / "const.pt", 1.5, -0.5)
    b = TorchFlow(p, device="cpu", batch=3)
    a = np.stack([_texture(64, 96, s) for s in range(5)])
    f = b(a, a)
    assert f.shape == (5, 64, 96, 2)
    assert np.allclose(f[..., 0], 1.5) and np.allclose(f[..., 1], -0.5)
    assert b.describe()["method"] == "torch"


def test_torch_conv_model_sees_input(tmp_path):
    """A tiny traced conv net: flow = (mean of img2 - img1, 0); checks value range [0, 1]
    and channel layout of what the backend feeds the model."""
    torch = pytest.importorskip("torch")

    class Diff(torch.nn.Module):
        def forward(self, a, b):
            d = (b - a).mean(dim=1, keepdim=True)
            return torch.cat([d, torch.zeros_like(d)], dim=1)

    p = tmp_path / "diff.pt"
    torch.jit.trace(Diff(), (torch.zeros(1, 3, 8, 8), torch.zeros(1, 3, 8, 8))).save(str(p))
    a = np.full((2, 16, 16), 51, np.uint8)
    f = TorchFlow(p, device="cpu")(a, a + 51)
    assert np.allclose(f[..., 0], 0.2, atol=1e-6) and np.allclose(f[..., 1], 0.0)


def test_torch_not_a_flow_model(tmp_path):
    p = _save_constant_model(tmp_path / "one.pt", 1.0, 0.0, channels=1)
    with pytest.raises(InputError, match="not a flow model"):
        TorchFlow(p, device="cpu")


def test_torch_not_torchscript(tmp_path):
    pytest.importorskip("torch")
    p = tmp_path / "junk.pt"
    p.write_bytes(b"this is not a model")
    with pytest.raises(InputError, match="not a TorchScript model"):
        TorchFlow(p, device="cpu")
    with pytest.raises(InputError, match="not found"):
        make_backend(f"torch:{tmp_path / 'missing.pt'}")


# ------------------------------------------------------------------------ ray angles
@pytest.mark.parametrize(("size", "fov"), [((40, 30), (107.0, 90.0)), ((33, 33), (60.0, 60.0))])
def test_ray_angles_match_perspective_rays(size, fov):
    """A flow of whole pixels lands on another pixel centre: the angle must equal the
    angle between the two rays of geometry.perspective_rays (the one ray convention)."""
    w, h = size
    dirs, _ = perspective_rays(size, *fov)
    rng = np.random.default_rng(3)
    dx = rng.integers(-5, 6, (h, w))
    dy = rng.integers(-5, 6, (h, w))
    jj, ii = np.mgrid[0:h, 0:w]
    tx, ty = np.clip(ii + dx, 0, w - 1), np.clip(jj + dy, 0, h - 1)
    flow = np.stack([tx - ii, ty - jj], -1).astype(np.float32)
    a, b = dirs.astype(float), dirs[ty, tx].astype(float)
    want = np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), (a * b).sum(-1))
    got = RayAngles(size, *fov)(flow)
    assert got.shape == (h, w) and got.dtype == np.float32
    # cv2.phase: relative error < 3e-4; float32 rays: ~1e-6 rad absolute.
    assert np.allclose(got, want, rtol=3e-4, atol=2e-6)
    assert not RayAngles(size, *fov)(np.zeros((2, h, w, 2), np.float32)).any()


def test_ray_angles_stride_and_bad_input():
    r1 = RayAngles((64, 64), 100.0)
    r2 = RayAngles((64, 64), 100.0, stride=2)
    flow = np.random.default_rng(0).normal(0, 3, (3, 64, 64, 2)).astype(np.float32)
    a1, a2 = r1(flow), r2(flow)
    assert a2.shape == (3, 32, 32)
    assert np.array_equal(a2, a1[:, 1::2, 1::2])
    with pytest.raises(ValueError, match="flow must be"):
        r1(np.zeros((64, 32, 2), np.float32))
    with pytest.raises(InputError, match="hfov must be degrees"):
        RayAngles((8, 8), 180.0)


def test_registry_drives_the_cli_and_make_backend(monkeypatch):
    """--flow's help lists every registry entry; a new backend is one registered class
    and one entry; the stride rule goes through the declaration, not the type."""
    import subprocess
    import sys

    import simulator.flow.registry as reg
    from simulator.cli import build_parser
    from simulator.flow import base
    from simulator.preprocess import reduce_stride

    p = build_parser()
    sub = next(a for a in p._actions if a.dest == "command").choices["preprocess"]
    help_text = next(a for a in sub._actions if a.dest == "flow").help
    for e in reg.BACKENDS:
        assert all(s.split(":")[0] in help_text for s in e.spellings), e.name
    assert reg.FLOW_CHOICES.startswith("dis, dis:ultrafast")
    # the registry itself is light: no numpy, no OpenCV
    code = "import sys, simulator.flow.registry; print('numpy' in sys.modules or 'cv2' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"

    entry = reg.FlowEntry("shift", "nonexistent", ("shift:PX",), "shift:PX (test)")
    monkeypatch.setattr(reg, "BACKENDS", (*reg.BACKENDS, entry))
    monkeypatch.setattr(base, "_CLASSES", dict(base._CLASSES))

    @base.register
    class Shift(base.FlowBackend):
        name = "shift"

        def __init__(self, px):
            self.px, self.params = float(px), {"px": float(px)}

        @property
        def native_stride(self):
            return 3

        @classmethod
        def from_spec(cls, arg, size):
            return cls(arg or 1)

        def _pair(self, a, b):
            return np.full((*a.shape, 2), self.px, np.float32)

    be = make_backend("shift:2.5")
    assert isinstance(be, Shift) and be.describe() == {"method": "shift", "px": 2.5}
    assert be(np.zeros((2, 4, 4), np.uint8), np.zeros((2, 4, 4), np.uint8))[1, 0, 0, 0] == 2.5
    assert reduce_stride(be) == 3
    with pytest.raises(InputError, match="unknown flow backend 'nope'"):
        make_backend("nope")
    with pytest.raises(ValueError, match="no entry"):

        @base.register
        class Orphan(base.FlowBackend):
            name = "orphan"


def test_dis_refinement_spelling():
    """dis:PRESET+refineN sets N variational-refinement iterations (recorded in meta);
    anything else after + is refused with the spelling."""
    be = make_backend("dis:ultrafast+refine5")
    assert be.describe()["refine"] == 5 and be.native_stride == 2
    assert "refine" not in make_backend("dis").describe()  # the default's meta is unchanged
    a = _texture(64, 64, seed=2)
    b = _shift(a, 1.3, -0.7)
    f = be(a[None], b[None])[0][16:48, 16:48].reshape(-1, 2)
    assert np.allclose(np.median(f, axis=0), [1.3, -0.7], atol=0.2)
    for bad in ("dis:ultrafast+foo", "dis:ultrafast+refine", "dis:fast+refine101"):
        with pytest.raises(InputError, match="refine"):
            make_backend(bad)
