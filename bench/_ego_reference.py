"""An independent camera-rotation estimate for bench/flow_at_speed.py: sparse feature tracks (OpenCV) on cube faces and a RANSAC rotation fit.

Per frame pair: six 90-degree perspective faces of each gray frame (``extract_view``),
Shi-Tomasi corners tracked with pyramidal Lucas-Kanade (forward-backward checked); per
face OpenCV's essential matrix (RANSAC) and ``recoverPose`` give the rotation (with the
translation allowed for); the faces' rotation vectors (world frame), weighted by their
inliers, are averaged. (``_kabsch``/``_fit``: a rotation-only RANSAC fit of the rays,
kept for comparison.) Nothing here shares code with sphere mode's
dense flow or its fit. The camera's angular velocity is minus the content rotation
vector times fps (deg/s, world frame), as ``vimsim ego`` reports it.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from simulator.media.video import iter_frames, probe
from simulator.sphere.geometry import extract_view, head_rotation

FACES = ((0, 0), (90, 0), (180, 0), (-90, 0), (0, 90), (0, -90))
SIZE = 400
INLIER_DEG = 0.3


def _rays(pts: np.ndarray, R: np.ndarray) -> np.ndarray:
    t = math.tan(math.radians(45.0))
    u = ((pts[:, 0] + 0.5) / SIZE * 2 - 1) * t
    v = (1 - (pts[:, 1] + 0.5) / SIZE * 2) * t
    d = np.column_stack([u, v, np.ones_like(u)])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d @ R.T


def _kabsch(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation R minimising |R a_i - b_i|^2 (OpenCV's SVD)."""
    H = (a.T @ b).astype(np.float64)
    _, u, vt = cv2.SVDecomp(H)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    return vt.T @ np.diag([1.0, 1.0, d]) @ u.T


def _face_tracks(f0: np.ndarray, f1: np.ndarray, yaw: float, pitch: float):
    """Forward-backward checked LK tracks of one 90-degree face: (p0, p1) pixels."""
    v0 = extract_view(f0, yaw, pitch, hfov_deg=90.0, size=(SIZE, SIZE), interp="linear")
    v1 = extract_view(f1, yaw, pitch, hfov_deg=90.0, size=(SIZE, SIZE), interp="linear")
    p0 = cv2.goodFeaturesToTrack(v0, 200, 0.01, 8)
    if p0 is None:
        return None
    p1, st, _ = cv2.calcOpticalFlowPyrLK(v0, v1, p0, None, winSize=(21, 21), maxLevel=4)
    back, st2, _ = cv2.calcOpticalFlowPyrLK(v1, v0, p1, None, winSize=(21, 21), maxLevel=4)
    ok = (st[:, 0] == 1) & (st2[:, 0] == 1) & (np.linalg.norm(back - p0, axis=2)[:, 0] < 0.5)
    return (p0[ok, 0], p1[ok, 0]) if ok.sum() >= 12 else None


def _face_rotation(p0, p1, F):
    """Content rotation (world frame) of one face's tracks: OpenCV's essential matrix
    (RANSAC) and recoverPose on normalised coordinates (rotation with translation)."""
    t = math.tan(math.radians(45.0))
    n0 = np.column_stack([((p0[:, 0] + 0.5) / SIZE * 2 - 1) * t, (1 - (p0[:, 1] + 0.5) / SIZE * 2) * t])
    n1 = np.column_stack([((p1[:, 0] + 0.5) / SIZE * 2 - 1) * t, (1 - (p1[:, 1] + 0.5) / SIZE * 2) * t])
    # OpenCV's camera: x right, y down, z forward; ours y up: flip y (S), then back
    n0[:, 1] *= -1
    n1[:, 1] *= -1
    E, mask = cv2.findEssentialMat(n0, n1, np.eye(3), cv2.RANSAC, 0.999, 1.0 / SIZE)
    if E is None or E.shape != (3, 3):
        return None, 0
    n_in, R, _, _ = cv2.recoverPose(E, n0, n1, np.eye(3), mask=mask)
    S = np.diag([1.0, -1.0, 1.0])
    return F @ (S @ R @ S) @ F.T, int(n_in)


def _fit(a: np.ndarray, b: np.ndarray, rng) -> tuple[np.ndarray, int]:
    best, best_n = np.eye(3), -1
    thr = math.radians(INLIER_DEG)
    for _ in range(200):
        i = rng.choice(len(a), 2, replace=False)
        R = _kabsch(a[i], b[i])
        n = int((np.linalg.norm(a @ R.T - b, axis=1) < thr).sum())
        if n > best_n:
            best, best_n = R, n
    inl = np.linalg.norm(a @ best.T - b, axis=1) < thr
    if inl.sum() >= 3:
        best = _kabsch(a[inl], b[inl])
    return best, int(inl.sum())


def feature_rotation_dps(path, max_frames: int | None = None):
    """``(omega (T, 3) deg/s world frame, ok (T,) bool)``; row 0 repeats row 1: per frame
    pair the inlier-weighted mean of the faces' rotation vectors (essential matrix per
    face, faces with >= 20 inliers)."""
    info = probe(path)
    Fs = head_rotation([f[0] for f in FACES], [f[1] for f in FACES], 0.0).as_matrix()
    prev, out, ok = None, [], []
    for k, f in enumerate(iter_frames(path, fmt="gray")):
        f = np.asarray(f)
        if prev is not None:
            vecs, wts = [], []
            for (yaw, pitch), F in zip(FACES, Fs):
                tr = _face_tracks(prev, f, yaw, pitch)
                if tr is None:
                    continue
                R, n = _face_rotation(*tr, F)
                if R is not None and n >= 20:
                    vecs.append(Rotation.from_matrix(R).as_rotvec())
                    wts.append(n)
            if vecs:
                rv = np.average(np.array(vecs), axis=0, weights=wts)
                out.append(-rv * math.degrees(1.0) * info.fps)
            else:
                out.append(np.zeros(3))
            ok.append(bool(vecs))
        prev = f
        if max_frames and k + 1 >= max_frames:
            break
    return np.array(out[:1] + out), np.array(ok[:1] + ok)
