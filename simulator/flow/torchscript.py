"""The TorchScript flow backend: a user's model file (RAFT, FlowNet2, ...) run in batches.

``torch:MODEL.pt``: a TorchScript model taking two ``(N, 3, H, W)`` float tensors in
``[0, 1]`` (RGB; gray windows are repeated over the 3 channels) and returning
``(N, 2, H, W)`` pixel flow ``(dx, dy)``. Run in batches on CUDA when available, else CPU.
torch is imported only here, when a model is loaded (optional dependency).
``docs/preprocess.md`` shows how to export RAFT (torchvision) or FlowNet2 to this
interface.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from simulator.core.errors import InputError
from simulator.flow.base import FlowBackend, _check_pair, register

__all__ = ["TorchFlow"]


@register
class TorchFlow(FlowBackend):
    """A TorchScript flow model: ``model(img1, img2)`` with ``(N, 3, H, W)`` float
    tensors in ``[0, 1]`` returns ``(N, 2, H, W)`` pixel flow ``(dx, dy)``.

    Parameters
    ----------
    path : the TorchScript file (``torch.jit.save``)
    device : ``"cuda"`` / ``"cpu"``; default CUDA when available
    batch : windows per forward pass (memory bound; all of a frame's windows are
        processed, ``batch`` at a time)
    probe_size : (width, height) of the pair the model is checked with on load: the size
        it will be given (the window size; ``preprocess`` and sphere mode pass theirs);
        ``None``: 64 x 64.
        Models have minimum sizes (RAFT: 128 px) or fixed ones (a traced FlowNet2).

    The model is checked on load with a ``(1, 3, h, w)`` pair of ``probe_size``:
    anything but a ``(1, 2, h, w)`` floating tensor raises InputError "not a flow model",
    with the model's own last error line when it raises (e.g. RAFT's "should be at least
    8 * 16 = 128").
    """

    name = "torch"
    thread_safe = False

    @classmethod
    def from_spec(cls, arg: str, size: tuple[int, int] | None) -> TorchFlow:
        """``torch:MODEL.pt``, checked at ``size``."""
        if not arg:
            raise InputError("--flow torch needs a model file: torch:MODEL.pt")
        return cls(arg, probe_size=size)

    def __init__(
        self,
        path: str | Path,
        *,
        device: str | None = None,
        batch: int = 32,
        probe_size: tuple[int, int] | None = None,
    ):
        try:
            import torch
        except ImportError:
            raise InputError(
                f"{path}: the torch flow backend needs PyTorch; install it (pip install torch) "
                "or use --flow dis"
            ) from None
        p = Path(path)
        if not p.is_file():
            raise InputError(f"{p}: TorchScript flow model file not found")
        self._torch = torch
        self.device = device or ("cuda" if torch.cuda.is_available() else "cpu")
        try:
            self.model = torch.jit.load(str(p), map_location=self.device).eval()
        except Exception as e:  # noqa: BLE001 - torch raises many types for a bad file
            first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
            raise InputError(f"{p}: not a TorchScript model ({first})") from None
        if batch < 1:
            raise InputError(f"torch flow batch must be >= 1; got {batch}")
        self.batch = int(batch)
        self.params = {"model": str(p), "model_bytes": p.stat().st_size, "device": self.device}
        self._path = p
        w, h = probe_size or (64, 64)
        self._validate(int(w), int(h))

    def _validate(self, w: int, h: int) -> None:
        torch = self._torch
        # Random noise and the same moved by one pixel: some models misbehave on constants.
        g = torch.Generator().manual_seed(0)
        a = torch.rand(1, 3, h + 1, w + 1, generator=g)
        x, y0 = a[..., :h, :w].to(self.device), a[..., 1:, 1:].to(self.device)
        try:
            with torch.inference_mode():
                y = self.model(x, y0)
        except Exception as e:  # noqa: BLE001 - any failure of the user's model
            # TorchScript puts the interpreter's frame first and the model's reason last.
            lines = [ln.strip() for ln in str(e).strip().splitlines() if ln.strip()]
            why = lines[-1] if lines else type(e).__name__
            raise InputError(
                f"{self._path}: not a flow model for {w}x{h} px windows: calling it with two "
                f"(1, 3, {h}, {w}) tensors failed ({why[:300]})"
            ) from None
        shape = tuple(y.shape) if isinstance(y, torch.Tensor) else type(y).__name__
        if not isinstance(y, torch.Tensor) or shape != (1, 2, h, w) or not y.is_floating_point():
            raise InputError(
                f"{self._path}: not a flow model: two (1, 3, {h}, {w}) inputs gave {shape}; "
                f"expected a (1, 2, {h}, {w}) float tensor (see docs/preprocess.md for the interface)"
            )

    def __call__(self, prev, nxt):
        torch = self._torch
        prev, nxt = _check_pair(prev, nxt)
        N, h, w = prev.shape
        out = np.empty((N, h, w, 2), np.float32)
        with torch.inference_mode():
            for s in range(0, N, self.batch):
                a = torch.from_numpy(np.ascontiguousarray(prev[s : s + self.batch])).to(self.device)
                b = torch.from_numpy(np.ascontiguousarray(nxt[s : s + self.batch])).to(self.device)
                a = (a.float() / 255.0)[:, None].expand(-1, 3, -1, -1).contiguous()
                b = (b.float() / 255.0)[:, None].expand(-1, 3, -1, -1).contiguous()
                f = self.model(a, b)
                if tuple(f.shape) != (a.shape[0], 2, h, w):
                    raise InputError(
                        f"{self._path}: not a flow model: gave {tuple(f.shape)} for {tuple(a.shape)} inputs"
                    )
                out[s : s + self.batch] = f.float().permute(0, 2, 3, 1).cpu().numpy()
        return out
