#!/usr/bin/env python3
"""Peer baseline for `objview bench render`: Open3D's Embree ray caster on the same views.

Given a mesh (OBJ/PLY/STL/OFF/glTF, anything Open3D reads) and a poses file (one
`cx cy cz lx ly lz roll` per line, '#' comments allowed; object frame, roll in radians), it
builds an `open3d.t.geometry.RaycastingScene`, casts one ray through every pixel centre
(u + 0.5, v + 0.5) of a 512x512, 45-degree camera built with the objview camera convention
(SPEC section 2: OpenCV axes, pole rule, roll about the viewing axis), converts the hit
distance to camera-frame depth z, and prints one JSON object:

    {"median_ms": ..., "p10_ms": ..., "p90_ms": ..., "depth_sha": ..., ...}

`median_ms` etc. are per frame (cast + depth conversion; the BVH is built once, rays are
precomputed per pose and uploaded to Open3D tensors outside the timed region). `depth_sha` is the SHA-256 of the first pose's depth as little-endian
float32, row-major (row = image v), 0 where nothing is hit -- the layout objview writes.
`--save-depth out.npy` stores that depth for a pixel-by-pixel comparison.

Open3D's camera helpers are deliberately not used: their axis conventions differ. Depth is
kept only within [znear, zfar] = [0.01, 10]; unlike objview, a hit nearer than znear hides
what is behind it (irrelevant for cameras at radius >= 1 around unit-ball objects unless the
camera touches the surface).

Usage: peer_open3d.py MESH POSES [--repeats N] [--normalize none|unit] [--save-depth F.npy]
Single-core timing: run it under `taskset -c 0`.
"""

import argparse
import hashlib
import json
import sys
import time

try:
    import numpy as np
except ImportError:  # pragma: no cover - environment check
    sys.exit("peer_open3d.py: numpy is not installed (pip install numpy open3d)")
try:
    import open3d as o3d
except ImportError as e:  # pragma: no cover - environment check
    sys.exit(f"peer_open3d.py: open3d is not installed or cannot be imported ({e}); "
             "install it with `pip install open3d` (needs libusb-1.0 on Linux)")

WIDTH = HEIGHT = 512
FOV_DEG = 45.0
ZNEAR, ZFAR = 0.01, 10.0


def camera_axes(center, look_at, roll):
    """Right, down, forward unit vectors (object frame) of a pose, SPEC section 2."""
    c = np.asarray(center, dtype=np.float64)
    f = np.asarray(look_at, dtype=np.float64) - c
    f /= np.linalg.norm(f)
    for s in (1.0, -1.0):
        if np.linalg.norm(f - np.array([0.0, 0.0, s])) < 1e-6:
            f = np.array([1e-8, 1e-8, s])
            f /= np.linalg.norm(f)
    x = np.cross(f, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(f, x)
    cr, sr = np.cos(roll), np.sin(roll)
    right = cr * x + sr * y
    down = -sr * x + cr * y
    return right, down, f


def pixel_rays(center, look_at, roll):
    """(H*W, 6) float32 rays [origin, unit direction] through the pixel centres and the
    camera-frame z of each unit direction (to turn hit distances into depth)."""
    cx = WIDTH / 2.0
    cy = HEIGHT / 2.0
    fx = cx / np.tan(np.radians(FOV_DEG) / 2.0)
    fy = cy / np.tan(np.radians(FOV_DEG) / 2.0)
    right, down, fwd = camera_axes(center, look_at, roll)
    px = (np.arange(WIDTH) + 0.5 - cx) / fx
    py = (np.arange(HEIGHT) + 0.5 - cy) / fy
    qx, qy = np.meshgrid(px, py)  # row = v, column = u
    d = qx[..., None] * right + qy[..., None] * down + fwd  # camera-frame z = 1
    norm = np.linalg.norm(d, axis=-1, keepdims=True)
    d = (d / norm).reshape(-1, 3)
    o = np.broadcast_to(np.asarray(center, dtype=np.float64), d.shape)
    rays = np.concatenate([o, d], axis=1).astype(np.float32)
    return rays, (1.0 / norm).reshape(-1)  # z of a unit direction = 1 / |d|


def read_poses(path):
    poses = []
    with open(path) as fh:
        for n, line in enumerate(fh, 1):
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            vals = [float(x) for x in line.replace(",", " ").split()]
            if len(vals) != 7:
                sys.exit(f"{path}:{n}: expected 7 numbers `cx cy cz lx ly lz roll`, got {len(vals)}")
            poses.append((vals[0:3], vals[3:6], vals[6]))
    if not poses:
        sys.exit(f"{path}: no poses")
    return poses


def load_mesh(path, normalize):
    mesh = o3d.io.read_triangle_mesh(path)
    v = np.asarray(mesh.vertices, dtype=np.float64)
    t = np.asarray(mesh.triangles, dtype=np.int64)
    if len(t) == 0:
        sys.exit(f"{path}: no triangles (or unreadable by Open3D)")
    if normalize == "unit":
        used = v[np.unique(t)]
        centre = (used.min(axis=0) + used.max(axis=0)) / 2.0
        v = v - centre
        v /= np.linalg.norm(v[np.unique(t)], axis=1).max()
    return v, t


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mesh")
    ap.add_argument("poses")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--normalize", choices=["none", "unit"], default="none")
    ap.add_argument("--save-depth", metavar="NPY")
    a = ap.parse_args()

    verts, tris = load_mesh(a.mesh, a.normalize)
    poses = read_poses(a.poses)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(verts.astype(np.float32)), o3d.core.Tensor(tris.astype(np.uint32)))
    # Rays are built and uploaded to Open3D tensors outside the timed region.
    prepared = [(o3d.core.Tensor(r), zs) for r, zs in (pixel_rays(*p) for p in poses)]

    def frame(rays, zscale):
        t = scene.cast_rays(rays)["t_hit"].numpy()
        z = (t * zscale).astype(np.float32)
        z[~np.isfinite(z) | (z < ZNEAR) | (z > ZFAR)] = 0.0
        return z.reshape(HEIGHT, WIDTH)

    first = frame(*prepared[0])  # also warms up the BVH
    times = []
    for _ in range(a.repeats):
        for rays, zscale in prepared:
            t0 = time.perf_counter()
            frame(rays, zscale)
            times.append((time.perf_counter() - t0) * 1e3)
    times.sort()
    q = lambda p: times[min(len(times) - 1, max(0, int(np.ceil(p * len(times))) - 1))]
    if a.save_depth:
        np.save(a.save_depth, first)
    print(json.dumps({
        "median_ms": float(np.median(times)),
        "p10_ms": q(0.1),
        "p90_ms": q(0.9),
        "depth_sha": hashlib.sha256(first.astype("<f4").tobytes()).hexdigest(),
        "hits_first_pose": int((first > 0).sum()),
        "triangles": int(len(tris)),
        "poses": len(poses),
        "repeats": a.repeats,
        "open3d": o3d.__version__,
    }))


if __name__ == "__main__":
    main()
