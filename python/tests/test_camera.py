"""Camera helpers: Observation.points is bit-identical to `objview render --points`; K,
cam_to_world, objview.camera's projection, back-projection and the roll sign."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import run_bin
from objview import camera

INTR = {"width": 512, "height": 512, "fx": 256 / np.tan(np.radians(22.5)),
        "fy": 256 / np.tan(np.radians(22.5)), "cx": 256.0, "cy": 256.0, "znear": 0.01,
        "zfar": 10.0}


def read_ply_points(path):
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode()
    assert "format binary_little_endian 1.0" in header and "property float x" in header
    n = int(header.split("element vertex ")[1].split()[0])
    pts = np.frombuffer(data[end:], dtype="<f4").reshape(-1, 3)
    assert pts.shape == (n, 3)
    return pts


POSES = [
    None,  # the start view
    [0.0, -3.0, 0.5, 0.0, 0.0, 0.1, 0.3],  # off-centre look-at, a roll
    [0.0, 0.0, 3.0, 0.0, 0.0, 0.0, 1.3],  # the pole rule
    [-1.7, 2.1, -1.2, 0.05, -0.1, 0.0, -2.0],
]


def test_points_are_bit_identical_to_the_cli(client, pool, objview_bin, tmp_path):
    mesh = pool.root / pool.entries["cone"]["mesh"]
    ep = client.create_episode("tiny", "cone", budget=5, method="t-camera")
    for k, pose in enumerate(POSES):
        obs = ep.observation() if pose is None else ep.move(pose)
        assert not obs.done
        pts = obs.points()
        assert pts.dtype == np.float64 and pts.shape == ((obs.depth > 0).sum(), 3)
        ply = tmp_path / f"v{k}.ply"
        pose_s = ",".join(repr(float(x)) for x in obs.pose)
        run_bin(objview_bin, "render", str(mesh), "--normalize", "none", "--pose", pose_s,
                "--depth", str(tmp_path / f"v{k}.npy"), "--points", str(ply))
        np.testing.assert_array_equal(obs.depth, np.load(tmp_path / f"v{k}.npy"))
        want = read_ply_points(ply)
        got = pts.astype(np.float32)
        assert got.shape == want.shape
        # Bit for bit (float32 of the same float64 values), not merely close.
        assert got.tobytes() == want.tobytes(), (k, np.abs(got - want).max())
        # The points lie on the object (normalized: inside the unit ball).
        assert np.linalg.norm(pts, axis=1).max() <= 1.0 + 1e-6
        # stride keeps every stride-th row and column, same values.
        s2 = obs.points(stride=2)
        v, u = np.nonzero(obs.depth > 0)
        keep = (u % 2 == 0) & (v % 2 == 0)
        np.testing.assert_array_equal(s2, pts[keep])
    ep.stop("plan_end")
    with pytest.raises(ValueError):
        obs.points(stride=0)


def test_k_and_cam_to_world(client):
    ep = client.create_episode("tiny", 0, budget=5, method="t-camera")
    obs = ep.observation()
    k = obs.K
    assert k.shape == (3, 3)
    np.testing.assert_array_equal(
        k, [[obs.intrinsics["fx"], 0, 256.0], [0, obs.intrinsics["fy"], 256.0], [0, 0, 1]])
    t = obs.cam_to_world
    assert t.shape == (4, 4)
    np.testing.assert_array_equal(t[3], [0, 0, 0, 1])
    r = t[:3, :3]
    np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)  # right-handed: right × down = forward
    np.testing.assert_array_equal(t[:3, 3], obs.pose[:3])
    # The camera's z axis (OpenCV: forward) points from the centre to the look-at point.
    fwd = obs.pose[3:6] - obs.pose[:3]
    np.testing.assert_allclose(t[:3, 2], fwd / np.linalg.norm(fwd), atol=1e-12)
    # K · (world → camera) of a point = the pixel it is seen at; the centre pixel's point
    # is the look-at direction.
    pts = obs.points()
    w2c = np.linalg.inv(t)
    cam = (w2c[:3, :3] @ pts.T).T + w2c[:3, 3]
    uvw = (k @ cam.T).T
    uv = uvw[:, :2] / uvw[:, 2:]
    v, u = np.nonzero(obs.depth > 0)
    np.testing.assert_allclose(uv, np.stack([u + 0.5, v + 0.5], axis=1), atol=1e-6)
    np.testing.assert_allclose(cam[:, 2], obs.depth[v, u], rtol=1e-6)
    np.testing.assert_allclose(camera.world_to_cam(obs.pose), w2c, atol=1e-12)
    ep.stop("plan_end")


def test_project_inverts_backproject():
    pose = [0.4, -2.5, 1.1, 0.1, 0.0, -0.2, 0.7]
    depth = np.zeros((512, 512), dtype=np.float32)
    depth[100:110, 300:305] = 2.5
    depth[400, 20] = 1.25
    pts = camera.backproject(depth, pose, INTR)
    uv, z = camera.project(pts, pose, INTR)
    v, u = np.nonzero(depth)
    np.testing.assert_allclose(uv, np.stack([u + 0.5, v + 0.5], axis=1), atol=1e-9)
    np.testing.assert_allclose(z, depth[v, u], rtol=1e-12)
    # Behind the camera: NaN coordinates.
    c, r, d, f = camera.camera_axes(pose)
    uv, z = camera.project([c - f], pose, INTR)
    assert np.isnan(uv).all() and z[0] < 0


def test_roll_sign():
    """A positive roll turns the camera clockwise about its viewing direction (right axis
    towards down): the picture turns counter-clockwise — a point right of the centre at roll 0
    moves up (smaller v) at a small positive roll."""
    base = [3.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    point = None
    c, r, d, f = camera.camera_axes(base + [0.0])
    point = c + 3.0 * f + 0.5 * r  # right of the centre, on the look-at plane
    (u0, v0), = camera.project([point], base + [0.0], INTR)[0]
    (u1, v1), = camera.project([point], base + [0.2], INTR)[0]
    assert u0 > 256 and v0 == pytest.approx(256)
    assert v1 < v0 and 256 < u1 < u0
    _, r2, d2, _ = camera.camera_axes(base + [0.2])
    np.testing.assert_allclose(r2, np.cos(0.2) * r + np.sin(0.2) * d, atol=1e-15)
    np.testing.assert_allclose(d2, -np.sin(0.2) * r + np.cos(0.2) * d, atol=1e-15)
