"""RViz / Foxglove markers of a step, as serialised ``visualization_msgs/MarkerArray`` bytes.

Each marker topic has one function that returns the ``MarkerSpec`` list of a
step (``contact_marker_specs``); ``codec.encode_markers`` turns a list into
bytes. A constant number of markers per step, whatever the number of
contacts: the cost is a few numpy operations, not one Python object per
contact. Add a topic (e.g. body markers) as another ``*_marker_specs``
function and one line in ``messages.OutputEncoder``.

``contact_markers``: eleven markers every step (README "Contact markers"):

* ``DELETEALL`` first, so markers of contacts that ended disappear at once
  (each marker also has a ``lifetime``, so they vanish when the node stops);
* per contact state (IMPACT, RESTING, SLIDING, STICKING, SLEEPING; the marker id is the
  ``Contact.state`` value), in that state's colour:
  ``contact_points`` (SPHERE_LIST): a sphere per contact point, and
  ``contact_normals`` (LINE_LIST): a segment per contact from the point along
  the normal (from body_a towards body_b), ``NORMAL_MIN`` long plus
  ``NORMAL_PER_IMPULSE`` per N s of normal impulse, at most ``NORMAL_MAX``.
  A state without contacts this step gets a DELETE of its two markers
  instead (RViz warns about list markers without points).

One colour per marker rather than per point keeps the message 40 % smaller
(no ``colors`` arrays) for the same picture.
"""

from __future__ import annotations

import numpy as np

from collres_ros.core.pipeline import ResolvedStep
from collres_ros.core.types import ContactState
from collres_ros.ros.codec import MarkerSpec

# visualization_msgs/Marker constants (Marker.msg)
SPHERE_LIST, LINE_LIST = 7, 5
ADD, DELETE, DELETEALL = 0, 2, 3

# Contact state -> RGBA (README "Contact markers").
STATE_COLOURS = {
    ContactState.IMPACT: (1.0, 0.2, 0.1, 1.0),     # red: it bounced
    ContactState.RESTING: (0.2, 0.6, 1.0, 1.0),    # blue: held, no friction needed
    ContactState.SLIDING: (1.0, 0.8, 0.1, 1.0),    # yellow: kinetic friction
    ContactState.STICKING: (0.2, 0.9, 0.3, 1.0),   # green: static friction held
    ContactState.SLEEPING: (0.6, 0.6, 0.6, 1.0)}   # grey: its island sleeps
POINT_DIAMETER = 0.02      # m, contact point sphere
LINE_WIDTH = 0.004         # m, normal segments
NORMAL_MIN = 0.03          # m, normal length at zero impulse
NORMAL_PER_IMPULSE = 0.1   # m per N s of normal impulse
NORMAL_MAX = 0.3           # m
POINTS_NS, NORMALS_NS = 'contact_points', 'contact_normals'


def normal_lengths(normal_impulse: np.ndarray) -> np.ndarray:
    """Length (M,) m of each normal segment, from its normal impulse (N s)."""
    return np.minimum(NORMAL_MIN + NORMAL_PER_IMPULSE * np.maximum(normal_impulse, 0.0),
                      NORMAL_MAX)


def contact_marker_specs(step: ResolvedStep, lifetime: float = 0.5) -> list[MarkerSpec]:
    """DELETEALL, then the points and the normals of each contact state (module docstring)."""
    report = step.report
    c = report.contacts
    point = np.asarray(c.point, float).reshape(-1, 3)
    tip = point + normal_lengths(np.asarray(report.normal_impulse, float))[:, None] \
        * np.asarray(c.normal, float).reshape(-1, 3)
    states = np.asarray(report.state, np.uint8)
    order = np.argsort(states, kind='stable')            # contacts grouped by state, in order
    ends = np.searchsorted(states[order], np.arange(1, len(STATE_COLOURS) + 2))
    segments = np.stack([point, tip], 1)[order]
    point = point[order]
    life = int(round(lifetime * 1e9))
    specs = [MarkerSpec(action=DELETEALL)]
    for k, (state, colour) in enumerate(STATE_COLOURS.items()):
        mine = slice(ends[k], ends[k + 1])                # the contacts of this state
        if mine.start == mine.stop:
            specs += [MarkerSpec(action=DELETE, ns=POINTS_NS, id=int(state)),
                      MarkerSpec(action=DELETE, ns=NORMALS_NS, id=int(state))]
            continue
        specs.append(MarkerSpec(action=ADD, type=SPHERE_LIST, ns=POINTS_NS, id=int(state),
                                scale=(POINT_DIAMETER,) * 3, color=colour, lifetime_ns=life,
                                points=point[mine]))
        specs.append(MarkerSpec(action=ADD, type=LINE_LIST, ns=NORMALS_NS, id=int(state),
                                scale=(LINE_WIDTH, 0.0, 0.0), color=colour, lifetime_ns=life,
                                points=segments[mine].reshape(-1, 3)))
    return specs
