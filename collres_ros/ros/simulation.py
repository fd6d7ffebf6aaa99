"""The test simulator's stepping, shared by ``collres_sim`` live and offline.

A ``SimScene`` (bodies, initial state, gravity, rate, duration) is integrated
with ``collres_ros.ros.integrator.euler_step``; each step its dynamic bodies'
states go to an ``exchange`` (live: publish and wait for the node's answer;
offline: the core in-process) and the corrected states that come back are
adopted, closing the loop. Kinematic bodies (``body.<n>.kinematic: true``:
static, infinite mass) move at their prescribed ``linear_velocity`` /
``angular_velocity`` and are published with it, so the node sees a conveyor or
a turntable move; their corrected states are never adopted. No messages are
built here: the exchange does that with the shared builders. ROS-free.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Optional, Sequence

import numpy as np

from collres_ros.core.config import (REALTIME_JITTER_STEPS, REALTIME_LAG, REALTIME_SHORTFALL,
                                     REALTIME_WARN_PERIOD)
from collres_ros.core.types import BodyStates
from collres_ros.ros.integrator import euler_step

START_NS = 1_000_000_000  # stamp of the first state: t = 1 s of simulated time (never 0)

# exchange(stamp_ns, states of all N bodies) -> the corrected (names, states), None if lost
Exchange = Callable[[int, BodyStates], Optional[tuple[Sequence[str], BodyStates]]]


def stamps(rate_hz: float, duration: float, start_ns: int = START_NS) -> list[int]:
    """Stamps (ns) of every published state: t0, t0 + 1/rate, ... up to t0 + duration."""
    count = int(round(duration * rate_hz))
    return [start_ns + int(round(k * 1e9 / rate_hz)) for k in range(count + 1)]


@dataclass
class SimScene:
    """What the sim needs from a Scene (params.py): bodies, initial state, sim settings."""

    scene: Any                  # collres_ros.ros.params.Scene
    names: list[str]
    dynamic: np.ndarray         # (N,) bool
    initial: BodyStates
    gravity: np.ndarray         # (3,) m/s^2, world
    rate_hz: float
    duration: float             # s of simulated time
    world_frame: str
    per_body: bool = False
    kinematic: np.ndarray | None = None   # (N,) bool: static bodies moved at their twist
    namespace: str = '/'                   # of the sim and the node ('/' or '/r1')
    # t (s from the first state) -> {body index: (position, quaternion)} of the links that
    # scripted joints move (SimSettings.joint_motion), or None
    drive: Callable[[float], dict[int, tuple[np.ndarray, np.ndarray]]] | None = None

    @property
    def driven(self) -> np.ndarray:
        """(N,) bool: the kinematic bodies (all False when there are none)."""
        return np.zeros_like(self.dynamic) if self.kinematic is None else self.kinematic

    @property
    def rows(self) -> list[int]:
        """Indices of the bodies the sim publishes (dynamic and kinematic ones)."""
        return [i for i in range(len(self.names)) if self.dynamic[i] or self.driven[i]]

    @property
    def steps(self) -> int:
        """Number of states a run publishes (the first one included)."""
        return int(round(self.duration * self.rate_hz)) + 1


def load_sim_scene(path: str | Path, duration: float | None = None,
                   rate_hz: float | None = None, namespace: str = '/',
                   overrides: Mapping[str, Any] | None = None) -> SimScene:
    """Load a params file (ValueError/OSError with a one-line reason when bad).

    ``namespace``: the sim's (and the node's) namespace: the file's sections
    are chosen for ``<namespace>/collres_sim`` and ``<namespace>/collres_node``
    as rcl chooses them for those nodes. ``overrides``: ``-p NAME:=VALUE`` values,
    which win over the file.
    """
    from collres_ros.ros import params
    scene = params.load_scene(path, namespace, overrides)
    sim = scene.sim
    return SimScene(
        scene=scene,
        names=[b.name for b in scene.bodies],
        dynamic=np.array([not b.static for b in scene.bodies], bool),
        initial=scene.initial.copy(),
        gravity=np.asarray(sim.gravity, float),
        rate_hz=float(rate_hz if rate_hz is not None else sim.rate_hz),
        duration=float(duration if duration is not None else sim.duration),
        world_frame=scene.world_frame,
        per_body=bool(getattr(sim, 'publish_per_body', False)),
        kinematic=scene.kinematic,
        namespace=params.fully_qualified_name(namespace, '').rstrip('/') or '/',
        drive=joint_drive(scene))


def joint_drive(scene: Any) -> Callable[[float], dict[int, tuple[np.ndarray, np.ndarray]]] | None:
    """The link poses of the scene's scripted joints at time t (``SimScene.drive``)."""
    motion = scene.sim.joint_motion
    if not motion:
        return None
    from collres_ros.ros.robot import Kinematics
    kinematics = Kinematics(scene.values['robot_description'])
    index = {name: i for i, name in enumerate(scene.names)}

    def drive(t: float) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        positions = {joint: amplitude * math.sin(2.0 * math.pi * frequency * t + phase)
                     for joint, amplitude, frequency, phase in motion}
        return {index[link]: pose for link, pose in kinematics.poses(positions).items()
                if link in index}
    return drive


def follow(states: BodyStates, poses: dict[int, tuple[np.ndarray, np.ndarray]],
           last: BodyStates, dt: float) -> BodyStates:
    """``states`` with the driven links at ``poses``, their twists the motion from their
    ``last`` poses over ``dt`` s (zero when dt is 0: the first state)."""
    from collres_ros.core.rotation import multiply
    out = states.copy()
    for i, (position, orientation) in poses.items():
        if dt > 0.0:
            out.linear[i] = (position - last.position[i]) / dt
            turn = multiply(orientation, last.orientation[i] * [-1.0, -1.0, -1.0, 1.0])
            turn = turn if turn[3] >= 0.0 else -turn
            sine = float(np.linalg.norm(turn[:3]))
            angle = 2.0 * math.atan2(sine, turn[3])
            out.angular[i] = turn[:3] / sine * angle / dt if sine > 0.0 else 0.0
        else:
            out.linear[i] = out.angular[i] = 0.0
        out.position[i], out.orientation[i] = position, orientation
    return out


class RealtimePace:
    """Whether a real-time run keeps its rate: the warnings of ``collres_sim --realtime``.

    Step ``k`` is due ``k / rate_hz`` s of wall time after the start; a step that waits for
    the node's answer longer than a step makes the run fall behind, and it then steps as
    fast as the answers come. Times in s (a monotonic clock).
    """

    def __init__(self, rate_hz: float, start: float) -> None:
        self.rate_hz, self.start = rate_hz, start
        self._warned = -math.inf

    def late(self, steps: int, now: float) -> Optional[str]:
        """A warning when ``steps`` steps are done at ``now`` and the run is more than
        REALTIME_LAG s behind (at most one per REALTIME_WARN_PERIOD s), else None."""
        lag = now - self.start - steps / self.rate_hz
        if lag <= REALTIME_LAG or now - self._warned < REALTIME_WARN_PERIOD:
            return None
        self._warned = now
        return (f'realtime: {lag:.1f} s behind the wall clock, '
                f'{self._reached(steps, now):.0f} steps/s so far of {self.rate_hz:g} Hz')

    def summary(self, steps: int, now: float) -> Optional[str]:
        """The warning at the end of a run that reached less than REALTIME_SHORTFALL of its
        rate and ended more than REALTIME_JITTER_STEPS periods behind, else None. ``now``:
        when the last of the ``steps`` steps was published (the first at ``start``). A short
        run whose last step alone came a period late (the scheduler's jitter) kept its rate."""
        elapsed = max(now - self.start, 1e-9)
        reached = (steps - 1) / elapsed
        behind = elapsed - (steps - 1) / self.rate_hz
        if (steps < 2 or reached >= REALTIME_SHORTFALL * self.rate_hz
                or behind <= REALTIME_JITTER_STEPS / self.rate_hz):
            return None
        return (f'realtime: reached {reached:.0f} steps/s of the {self.rate_hz:g} Hz asked '
                '(each step waits for the answer of collres_node)')

    def _reached(self, steps: int, now: float) -> float:
        return steps / max(now - self.start, 1e-9)


def adopt(states: BodyStates, names: Sequence[str], corrected_names: Sequence[str],
          corrected: BodyStates, only: np.ndarray | None = None) -> BodyStates:
    """``states`` with the bodies named in ``corrected_names`` replaced by ``corrected``.

    ``only``: (N,) bool, adopt only these bodies (the others keep their state).
    """
    index = {name: i for i, name in enumerate(names) if only is None or only[i]}
    out = states.copy()
    for k, name in enumerate(corrected_names):
        i = index.get(name)
        if i is None:
            continue
        out.position[i] = corrected.position[k]
        out.orientation[i] = corrected.orientation[k]
        out.linear[i] = corrected.linear[k]
        out.angular[i] = corrected.angular[k]
    return out


def run_loop(sim: SimScene, exchange: Exchange,
             on_step: Callable[[int, int], None] | None = None) -> tuple[int, int]:
    """Integrate and exchange states every step; returns (steps, dropped)."""
    all_stamps = stamps(sim.rate_hz, sim.duration)
    states = sim.initial.copy()
    dropped = 0
    for k, stamp in enumerate(all_stamps):
        dt = (stamp - all_stamps[k - 1]) * 1e-9 if k > 0 else 0.0
        last = states
        if k > 0:
            states = euler_step(states, sim.dynamic, sim.gravity, dt, sim.driven)
        if sim.drive is not None:   # scripted joints: their links follow, with their twists
            states = follow(states, sim.drive((stamp - all_stamps[0]) * 1e-9), last, dt)
        answer = exchange(stamp, states)
        if answer is None:
            dropped += 1
        else:
            states = adopt(states, sim.names, *answer, sim.dynamic)   # kinematic: prescribed
        if on_step is not None:
            on_step(k + 1, len(all_stamps))
    return len(all_stamps), dropped


def rows_of(states: BodyStates, rows: Sequence[int]) -> BodyStates:
    """The bodies ``rows`` of ``states`` (copies)."""
    index = np.asarray(rows, np.int64)
    return BodyStates(states.position[index], states.orientation[index],
                      states.linear[index], states.angular[index])
