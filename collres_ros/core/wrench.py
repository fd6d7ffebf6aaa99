"""Net contact wrench on each body of a step: the solved impulses as a force and a torque.

Pure numpy over a ``ContactReport``: no ROS here.
"""

from __future__ import annotations

import numpy as np

from collres_ros.core.types import ContactReport


def contact_wrenches(report: ContactReport, centres: np.ndarray, dt: float) -> np.ndarray:
    """(N, 6) net contact wrench on each body: force (N), then torque (N m), world frame.

    force = the sum of the contact impulses on the body (normal and friction;
    on ``body_b`` along +normal, the opposite on ``body_a``) / ``dt``; torque =
    the sum of (contact point - centre) x that impulse / ``dt``, about the
    body's centre of mass ``centres`` (N, 3) m, world frame. A body without
    contacts gets zeros; ``dt`` <= 0 gives zeros (no step length, no force).
    """
    centres = np.asarray(centres, float).reshape(-1, 3)
    out = np.zeros((centres.shape[0], 6))
    c = report.contacts
    if c.count == 0 or not dt > 0.0:
        return out
    on_b = (np.asarray(report.normal_impulse, float)[:, None] * np.asarray(c.normal, float)
            + np.asarray(report.friction_impulse, float).reshape(-1, 3)) / dt   # (M, 3) N
    point = np.asarray(c.point, float).reshape(-1, 3)
    for body, sign in ((np.asarray(c.body_b, np.int64), 1.0),
                       (np.asarray(c.body_a, np.int64), -1.0)):
        force = sign * on_b
        np.add.at(out[:, 0:3], body, force)
        np.add.at(out[:, 3:6], body, np.cross(point - centres[body], force))
    return out
