"""The pinhole camera of SPEC §2, as the renderer (``crates/objview-render/src/camera.rs``)
computes it.

Frames: the *object frame* is the object's normalized frame (poses and points are in it). The
*camera frame* is OpenCV's: x right, y down, z forward; depth is the camera-frame z. Pixel
``(u, v)`` is column ``u``, row ``v``; its centre is ``(u + 0.5, v + 0.5)``.

Axes of a pose ``[cx, cy, cz, lx, ly, lz, roll]``: forward f = normalize(look-at − centre) (at
the poles, |f − (0, 0, ±1)| < 1e-6, f = normalize(1e-8, 1e-8, ±1)); right x = normalize(f ×
(0, 0, 1)); down y = f × x; then the roll (radians) rotates (x, y) about f by the right-hand
rule: x' = cos r·x + sin r·y, y' = −sin r·x + cos r·y.

**Roll sign**: a positive roll turns the camera's right axis towards its down axis (clockwise
about the viewing direction, seen from behind the camera), so the picture content turns
counter-clockwise: a point seen right of the image centre at roll 0 is seen above-right of it
at a small positive roll.

:func:`backproject` reproduces the renderer's float64 arithmetic operation by operation, so its
points are bit-identical to ``objview render --points`` (which writes them as float32) and to
the server's observed points.
"""

from __future__ import annotations

import math
from typing import Any, List, Mapping, Sequence, Tuple

import numpy as np

__all__ = [
    "backproject",
    "cam_to_world",
    "camera_axes",
    "intrinsics_matrix",
    "project",
    "world_to_cam",
]

Vec = Tuple[float, float, float]


def _sub(a: Sequence[float], b: Sequence[float]) -> Vec:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _dot(a: Sequence[float], b: Sequence[float]) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a: Sequence[float], b: Sequence[float]) -> Vec:
    return (
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    )


def _normalize(a: Sequence[float]) -> Vec:
    n = math.sqrt(_dot(a, a))
    return (a[0] / n, a[1] / n, a[2] / n)


def _pose7(pose: Any) -> List[float]:
    p = [float(x) for x in np.asarray(pose, dtype=np.float64).reshape(-1)]
    if len(p) != 7:
        raise ValueError(f"a pose is 7 numbers [cx, cy, cz, lx, ly, lz, roll], not {len(p)}")
    return p


def camera_axes(pose: Any) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(centre, right, down, forward)`` of a pose, each float64 (3,), in the object frame.

    ``right``/``down``/``forward`` are the camera's x/y/z axes (OpenCV): orthonormal and
    right-handed (right × down = forward).  Computed in Python floats in the renderer's order,
    so they are bit-identical to its axes.
    """
    p = _pose7(pose)
    center = (p[0], p[1], p[2])
    look = (p[3], p[4], p[5])
    f = _normalize(_sub(look, center))
    for s in (1.0, -1.0):
        d = _sub(f, (0.0, 0.0, s))
        if math.sqrt(_dot(d, d)) < 1e-6:
            f = _normalize((1e-8, 1e-8, s))
    x = _normalize(_cross(f, (0.0, 0.0, 1.0)))
    y = _cross(f, x)
    s_, c = math.sin(p[6]), math.cos(p[6])
    right = (c * x[0] + s_ * y[0], c * x[1] + s_ * y[1], c * x[2] + s_ * y[2])
    down = (-s_ * x[0] + c * y[0], -s_ * x[1] + c * y[1], -s_ * x[2] + c * y[2])
    return (
        np.array(center, dtype=np.float64),
        np.array(right, dtype=np.float64),
        np.array(down, dtype=np.float64),
        np.array(f, dtype=np.float64),
    )


def cam_to_world(pose: Any) -> np.ndarray:
    """The 4×4 camera-to-object transform of a pose (OpenCV camera: x right, y down,
    z forward): columns ``right``, ``down``, ``forward``, ``centre``; ``T @ [x, y, z, 1]`` maps
    a camera-frame point to the object frame."""
    c, r, d, f = camera_axes(pose)
    t = np.eye(4, dtype=np.float64)
    t[:3, 0], t[:3, 1], t[:3, 2], t[:3, 3] = r, d, f, c
    return t


def world_to_cam(pose: Any) -> np.ndarray:
    """The inverse of :func:`cam_to_world` (object frame → camera frame), 4×4."""
    c, r, d, f = camera_axes(pose)
    rot = np.stack([r, d, f])  # rows
    t = np.eye(4, dtype=np.float64)
    t[:3, :3] = rot
    t[:3, 3] = -(rot @ c)
    return t


def intrinsics_matrix(intrinsics: Mapping[str, Any]) -> np.ndarray:
    """K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (float64 3×3) of an intrinsics dict."""
    k = intrinsics
    return np.array(
        [[float(k["fx"]), 0.0, float(k["cx"])], [0.0, float(k["fy"]), float(k["cy"])], [0.0, 0.0, 1.0]],
        dtype=np.float64,
    )


def project(
    points: Any, pose: Any, intrinsics: Mapping[str, Any]
) -> Tuple[np.ndarray, np.ndarray]:
    """Project object-frame points (M, 3) into the image of a pose.

    Returns ``(uv, z)``: continuous image coordinates float64 (M, 2) — pixel ``(u, v)`` covers
    ``[u, u+1) × [v, v+1)``, its centre is ``(u + 0.5, v + 0.5)`` — and the camera-frame depth
    float64 (M,).  Points with z ≤ 1e-9 (behind or on the camera plane) get ``uv = NaN``.
    Whether a point lies inside the image (``0 ≤ u < width``, ``0 ≤ v < height``) and in
    front of ``znear`` is left to the caller.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    c, r, d, f = camera_axes(pose)
    q = pts - c
    x = q[:, 0] * r[0] + q[:, 1] * r[1] + q[:, 2] * r[2]
    y = q[:, 0] * d[0] + q[:, 1] * d[1] + q[:, 2] * d[2]
    z = q[:, 0] * f[0] + q[:, 1] * f[1] + q[:, 2] * f[2]
    ok = z > 1e-9
    zs = np.where(ok, z, 1.0)
    fx, fy = float(intrinsics["fx"]), float(intrinsics["fy"])
    cx, cy = float(intrinsics["cx"]), float(intrinsics["cy"])
    u = np.where(ok, fx * x / zs + cx, np.nan)
    v = np.where(ok, fy * y / zs + cy, np.nan)
    return np.stack([u, v], axis=1), z


def backproject(
    depth: Any, pose: Any, intrinsics: Mapping[str, Any], stride: int = 1
) -> np.ndarray:
    """The observed points of a depth image, float64 (M, 3) in the object frame.

    Every pixel with a hit (depth > 0) at ``u`` and ``v`` multiples of ``stride``,
    back-projected through its centre at its depth, in row-major pixel order (row ``v`` outer).
    With ``stride=1`` this is bit for bit the renderer's observed point cloud (``objview render
    --points`` writes it rounded to float32: ``backproject(...).astype(np.float32)`` equals
    that file's points).
    """
    stride = int(stride)
    if stride < 1:
        raise ValueError(f"stride must be a positive integer, not {stride}")
    dep = np.asarray(depth)
    if dep.ndim != 2:
        raise ValueError(f"depth must be a 2-D image, not shape {dep.shape}")
    sub = dep[::stride, ::stride]
    vs, us = np.nonzero(sub > 0)  # row-major order
    z = sub[vs, us].astype(np.float64)
    u = (us * stride).astype(np.float64)
    v = (vs * stride).astype(np.float64)
    fx, fy = float(intrinsics["fx"]), float(intrinsics["fy"])
    cx, cy = float(intrinsics["cx"]), float(intrinsics["cy"])
    # Intrinsics::pixel_ray, then Camera::to_object: c + (qx·z)·r + (qy·z)·d + z·f, in that order.
    qx = (u + 0.5 - cx) / fx
    qy = (v + 0.5 - cy) / fy
    x = qx * z
    y = qy * z
    c, r, d, f = camera_axes(pose)
    out = np.empty((z.shape[0], 3), dtype=np.float64)
    for k in range(3):
        out[:, k] = c[k] + x * r[k] + y * d[k] + z * f[k]
    return out
