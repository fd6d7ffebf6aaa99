"""Link poses from /tf and /tf_static: the static bodies of a scene (a robot's links) whose
name is a frame of the transform tree, posed in the world frame.

Each transform (``codec.Transform``) says where ``child`` is in ``parent``: translation (m),
rotation x, y, z, w. A body's world pose is the chain of the latest transforms from its
frame up to the node's world frame, or up to a frame that is a body of the scene not posed
by the tree (the robot's root link as ``robot_state_publisher`` leaves it: at its params pose,
or as body_states last set it). A chain that reaches neither, or loops, poses nothing. The
latest transform of each edge is used (a controller's latest state, no interpolation in
time); /tf_static ones never expire. A body's twist (world frame, the body's origin) is the
difference of its last two distinct world poses over their stamps' difference (zero until
it has moved twice), so the solver sees a driven link's speed.

No ROS import: the node subscribes and hands the decoded transforms over.
"""

from __future__ import annotations

from typing import Callable, Optional, Sequence

import numpy as np

from collres_ros.core.rotation import multiply, normalize, to_matrix
from collres_ros.core.types import InputBatch
from collres_ros.ros.codec import Transform

MAX_CHAIN = 64   # frames up to the world frame: a longer chain is taken for a loop


class TfLinks:
    """The latest transform of each child frame, and the world poses of the bodies it poses."""

    def __init__(self, bodies: Sequence[str], roots: Sequence[str], world_frame: str,
                 body_pose: Callable[[str], np.ndarray]) -> None:
        """``bodies``: the names the tree may pose (static bodies); ``roots``: the scene's
        bodies, which root a chain where the tree does not pose them; ``body_pose(name)``:
        the current pose (7,) of such a root."""
        self.bodies = tuple(bodies)
        self.roots = frozenset(roots)
        self.world_frame = world_frame
        self.body_pose = body_pose
        self._edges: dict[str, tuple[str, np.ndarray, int]] = {}   # child: parent, pose, ns
        # body: (pose, stamp) of its last two distinct world poses
        self._last: dict[str, list[tuple[np.ndarray, int]]] = {}

    def take(self, transforms: Sequence[Transform]) -> None:
        """Keep each child's newest transform (an older stamp than the kept one is ignored;
        a non-finite or zero rotation is ignored)."""
        for t in transforms:
            values = np.asarray(t.values, float)
            if not np.isfinite(values).all() or not np.linalg.norm(values[3:]) > 0.5 \
                    or t.child == t.parent:
                continue
            kept = self._edges.get(t.child)
            if kept is None or t.stamp_ns >= kept[2]:
                values[3:] = normalize(values[3:])
                self._edges[t.child] = (t.parent, values, t.stamp_ns)

    def world_pose(self, frame: str) -> Optional[tuple[np.ndarray, int]]:
        """(pose (7,) in the world frame, stamp of the newest transform of its chain), or
        None when the chain reaches neither the world frame nor a body off the tree."""
        chain: list[np.ndarray] = []
        stamp = 0
        for _ in range(MAX_CHAIN):
            if frame == self.world_frame:
                root = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
                break
            edge = self._edges.get(frame)
            if edge is None:
                if frame in self.roots:
                    root = np.asarray(self.body_pose(frame), float)
                    break
                return None
            parent, pose, ns = edge
            chain.append(pose)
            stamp = max(stamp, ns)
            frame = parent
        else:
            return None
        for pose in reversed(chain):   # root * edge * ... : child poses composed outward
            position = root[:3] + to_matrix(root[3:]) @ pose[:3]
            root = np.concatenate([position, normalize(multiply(root[3:], pose[3:]))])
        return root, stamp

    def inputs(self) -> InputBatch:
        """Every posable body whose chain resolves: world pose and twist (K, 13), world
        frame."""
        names, rows = [], []
        for name in self.bodies:
            if name not in self._edges:
                continue
            found = self.world_pose(name)
            if found is None:
                continue
            pose, stamp = found
            history = self._last.setdefault(name, [])
            if not history or stamp != history[-1][1]:
                history.append((pose, stamp))
                del history[:-2]
            else:   # the chain changed without a newer stamp (a parent's transform came
                history[-1] = (pose, stamp)   # after its child's): the pose it gives now
            twist = np.zeros(6)
            if len(history) == 2 and history[1][1] > history[0][1]:
                (p0, s0), (p1, s1) = history
                dt = (s1 - s0) * 1e-9
                twist[:3] = (p1[:3] - p0[:3]) / dt
                turn = multiply(p1[3:], p0[3:] * np.array([-1.0, -1.0, -1.0, 1.0]))
                turn = turn if turn[3] >= 0.0 else -turn
                angle = 2.0 * np.arctan2(np.linalg.norm(turn[:3]), turn[3])
                axis = turn[:3] / max(np.linalg.norm(turn[:3]), 1e-300)
                twist[3:] = axis * angle / dt
            names.append(name)
            rows.append(np.concatenate([history[-1][0], twist]))
        values = np.array(rows, float).reshape(len(rows), 13)
        return InputBatch(names, values)


def with_links(batch: InputBatch, links: InputBatch) -> InputBatch:
    """``batch`` and then the rows of ``links`` for bodies it does not hold (a link posed on
    body_states by name keeps that pose); world-frame poses and twists."""
    given = set(batch.names)
    keep = [k for k, name in enumerate(links.names) if name not in given]
    if not keep:
        return batch

    def frames(value: str | Sequence[str]) -> list[str]:
        return [value] * len(batch) if isinstance(value, str) else list(value)

    return InputBatch(list(batch.names) + [links.names[k] for k in keep],
                      np.concatenate([np.asarray(batch.values, float).reshape(-1, 13),
                                      links.values[keep]]),
                      frames(batch.frame_id) + [''] * len(keep),
                      frames(batch.twist_frame_id) + [''] * len(keep))
