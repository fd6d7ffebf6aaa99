"""RViz / Foxglove markers of a step (``visualization_msgs/MarkerArray``).

``contact_markers``: the contacts of one step. One function per marker topic;
each takes a ``ResolvedStep`` and the world frame and returns a MarkerArray.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from collres_ros.core.pipeline import ResolvedStep
from collres_ros.core.types import ContactState
from collres_ros.ros.stamps import to_duration, to_stamp

# Contact state -> RGB (README: "Contact markers").
STATE_COLOURS = {
    ContactState.IMPACT: (1.0, 0.2, 0.1), ContactState.RESTING: (0.2, 0.6, 1.0),
    ContactState.SLIDING: (1.0, 0.8, 0.1), ContactState.STICKING: (0.2, 0.9, 0.3)}
POINT_DIAMETER = 0.02   # m, contact point sphere
ARROW_LENGTH = 0.1      # m, normal arrow


def _point(v: np.ndarray) -> Any:
    from geometry_msgs.msg import Point
    return Point(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def contact_markers(step: ResolvedStep, world_frame: str, lifetime: float = 0.5) -> Any:
    """contact_markers: DELETEALL, then a sphere and a normal arrow per contact.

    Namespace per body pair (``a/b``); ids count the pair's points (point 2k,
    arrow 2k+1). Each marker also has ``lifetime`` (s; 0 = forever).
    """
    from geometry_msgs.msg import Vector3
    from std_msgs.msg import ColorRGBA, Header
    from visualization_msgs.msg import Marker, MarkerArray
    header = Header(stamp=to_stamp(step.stamp_ns), frame_id=world_frame)
    markers = [Marker(header=header, action=Marker.DELETEALL)]
    c = step.report.contacts
    seen: dict[str, int] = {}
    life = to_duration(lifetime)
    for k in range(c.count):
        a, b = step.contact_names(k)
        namespace = f'{a}/{b}'
        n = seen.get(namespace, 0)
        seen[namespace] = n + 1
        r, g, bl = STATE_COLOURS.get(ContactState(int(step.report.state[k])), (1.0, 1.0, 1.0))
        colour = ColorRGBA(r=r, g=g, b=bl, a=1.0)
        # check_fields=False: the fields are typed here; rclpy's checks cost ~100 us a marker
        point = Marker(header=header, ns=namespace, id=2 * n, type=Marker.SPHERE,
                       action=Marker.ADD, color=colour, lifetime=life, check_fields=False)
        point.pose.position = _point(c.point[k])
        point.scale = Vector3(x=POINT_DIAMETER, y=POINT_DIAMETER, z=POINT_DIAMETER)
        arrow = Marker(header=header, ns=namespace, id=2 * n + 1, type=Marker.ARROW,
                       action=Marker.ADD, color=colour, lifetime=life,
                       points=[_point(c.point[k]),
                               _point(c.point[k] + ARROW_LENGTH * c.normal[k])],
                       check_fields=False)
        arrow.scale = Vector3(x=0.005, y=0.01, z=0.02)  # shaft, head diameters, head length
        markers += [point, arrow]
    return MarkerArray(markers=markers)
