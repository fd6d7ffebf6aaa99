"""Quaternion and rotation helpers, vectorised over leading axes.

Quaternions are ``x, y, z, w`` (ROS order), unit length, rotating body-frame
vectors into the world frame. Angular velocities are world-frame rad/s.
"""

from __future__ import annotations

import numpy as np


def normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternions with w >= 0 (the same rotation); q must be non-zero."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0.0, -q, q)


def to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4)."""
    q = np.asarray(q, dtype=float)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0] = 1.0 - 2.0 * (yy + zz)
    m[..., 0, 1] = 2.0 * (xy - wz)
    m[..., 0, 2] = 2.0 * (xz + wy)
    m[..., 1, 0] = 2.0 * (xy + wz)
    m[..., 1, 1] = 1.0 - 2.0 * (xx + zz)
    m[..., 1, 2] = 2.0 * (yz - wx)
    m[..., 2, 0] = 2.0 * (xz - wy)
    m[..., 2, 1] = 2.0 * (yz + wx)
    m[..., 2, 2] = 1.0 - 2.0 * (xx + yy)
    return m


def multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b (apply b first, then a)."""
    ax, ay, az, aw = np.moveaxis(np.asarray(a, dtype=float), -1, 0)
    bx, by, bz, bw = np.moveaxis(np.asarray(b, dtype=float), -1, 0)
    return np.stack((
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ), axis=-1)


def from_rotation_vector(v: np.ndarray) -> np.ndarray:
    """Quaternions of rotation vectors (axis * angle, rad); exact, safe at zero."""
    v = np.asarray(v, dtype=float)
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(half)/angle, with its limit 0.5 at angle -> 0
    scale = np.where(angle > 1e-12, np.sin(half) / np.where(angle > 1e-12, angle, 1.0),
                     0.5 - angle * angle / 48.0)
    return np.concatenate((v * scale, np.cos(half)), axis=-1)


def integrate(q: np.ndarray, angular: np.ndarray, dt: float | np.ndarray) -> np.ndarray:
    """Orientation after rotating at constant world-frame ``angular`` (rad/s) for ``dt`` s."""
    dt = np.asarray(dt, dtype=float)
    if dt.ndim:
        dt = dt[..., None]
    return normalize(multiply(from_rotation_vector(np.asarray(angular) * dt), q))


def slerp(q0: np.ndarray, q1: np.ndarray, s: float | np.ndarray) -> np.ndarray:
    """Spherical interpolation from q0 (s=0) to q1 (s=1) along the shorter arc."""
    q0 = np.asarray(q0, dtype=float)
    q1 = np.asarray(q1, dtype=float)
    s = np.asarray(s, dtype=float)
    if s.ndim:
        s = s[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0.0, -q1, q1)
    dot = np.clip(np.abs(dot), 0.0, 1.0)
    theta = np.arccos(dot)
    sin_theta = np.sin(theta)
    near = sin_theta < 1e-9
    safe = np.where(near, 1.0, sin_theta)
    w0 = np.where(near, 1.0 - s, np.sin((1.0 - s) * theta) / safe)
    w1 = np.where(near, s, np.sin(s * theta) / safe)
    return normalize(w0 * q0 + w1 * q1)


def world_inverse_inertia(q: np.ndarray, inv_inertia_body: np.ndarray) -> np.ndarray:
    """World-frame inverse inertia tensors R I_body^-1 R^T, (N, 3, 3)."""
    r = to_matrix(q)
    return r @ inv_inertia_body @ np.swapaxes(r, -1, -2)
