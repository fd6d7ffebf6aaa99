"""What happened in a recorded run: bounces, energy, momentum, contacts, dropped steps.

Reads a bag with ``/body_states`` (the sim's inputs) and the node's outputs
(``/body_states/corrected``, ``/contacts``) and measures the physics the
demo reports and the tests assert: the ball's apex heights against the
analytic e^2 law, total energy over time, drift of the momentum orthogonal to
gravity, the displacement of resting boxes, contacts by state, and whether
every input step got exactly one corrected output. No ROS node needed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from collres_ros.core.rotation import to_matrix
from collres_ros.core.types import BodySpec
from collres_ros.ros.energy import total_energy
from collres_ros.ros.names import STATE_NAMES, state_name
from collres_ros.ros.stamps import stamp_ns
MIN_BOUNCE = 0.01  # m: rebounds lower than this are not counted as apexes


@dataclass
class Trajectory:
    """States of the dynamic bodies over time, from a BodyStateArray topic."""

    names: list[str]
    time: np.ndarray          # (T,) s since the first stamp
    stamps: np.ndarray        # (T,) int64 ns
    position: np.ndarray      # (T, N, 3) m
    orientation: np.ndarray   # (T, N, 4) x, y, z, w
    linear: np.ndarray        # (T, N, 3) m/s
    angular: np.ndarray       # (T, N, 3) rad/s


def trajectory(msgs: Sequence[Any], names: Sequence[str]) -> Trajectory:
    """Stack BodyStateArray messages; bodies missing from a message keep the previous row."""
    from collres_ros.ros.messages import read_body_state_array
    index = {n: i for i, n in enumerate(names)}
    count, steps = len(names), len(msgs)
    pos, ori = np.zeros((steps, count, 3)), np.tile([0.0, 0.0, 0.0, 1.0], (steps, count, 1))
    lin, ang = np.zeros((steps, count, 3)), np.zeros((steps, count, 3))
    stamps = np.zeros(steps, np.int64)
    for k, msg in enumerate(msgs):
        stamps[k] = stamp_ns(msg.header.stamp)
        if k > 0:
            pos[k], ori[k], lin[k], ang[k] = pos[k - 1], ori[k - 1], lin[k - 1], ang[k - 1]
        got, states = read_body_state_array(msg)
        for j, name in enumerate(got):
            i = index.get(name)
            if i is None:
                continue
            pos[k, i], ori[k, i] = states.position[j], states.orientation[j]
            lin[k, i], ang[k, i] = states.linear[j], states.angular[j]
    time = (stamps - stamps[0]) * 1e-9 if steps else np.zeros(0)
    return Trajectory(list(names), time, stamps, pos, ori, lin, ang)


def energy(traj: Trajectory, specs: Sequence[BodySpec], gravity: np.ndarray) -> np.ndarray:
    """Total mechanical energy of the trajectory's bodies, J per sample, shape (T,).

    The definition is ``collres_ros.ros.energy.total_energy``.
    """
    return total_energy(traj.position, traj.orientation, traj.linear, traj.angular, specs,
                        gravity)


def horizontal_momentum_drift(traj: Trajectory, specs: Sequence[BodySpec],
                              gravity: np.ndarray) -> float:
    """Largest change of the total momentum orthogonal to gravity, N s."""
    mass = np.array([s.mass for s in specs])
    momentum = np.einsum('n,tni->ti', mass, traj.linear)
    norm = float(np.linalg.norm(gravity))
    if norm > 0:
        down = gravity / norm
        momentum = momentum - np.outer(momentum @ down, down)
    if len(momentum) == 0:
        return 0.0
    return float(np.max(np.linalg.norm(momentum - momentum[0], axis=1)))


def apexes(time: np.ndarray, height: np.ndarray, vertical_speed: np.ndarray,
           minimum: float = MIN_BOUNCE) -> list[tuple[float, float]]:
    """(t, h) of each apex after a bounce: rising then falling, at least ``minimum`` high."""
    found = []
    for k in range(1, len(height) - 1):
        if vertical_speed[k - 1] > 0 and height[k] >= height[k - 1] \
                and height[k] > height[k + 1] and height[k] >= minimum:
            found.append((float(time[k]), float(height[k])))
    return found


@dataclass
class BounceCheck:
    """The ball's apex heights against h_n = h0 e^(2n)."""

    ball: str
    restitution: float
    drop_height: float                  # m, lowest point above the contact height at start
    measured: list[float]               # m
    expected: list[float]               # m
    times: list[float]                  # s
    contact_height: float = 0.0         # m, centre height (along -g) at touch-down

    @property
    def errors(self) -> list[float]:
        """Relative errors of each apex (measured / expected - 1)."""
        return [m / e - 1.0 for m, e in zip(self.measured, self.expected)]


@dataclass
class RunReport:
    """Measured facts of one run (see the module docstring)."""

    steps_in: int = 0
    steps_out: int = 0
    unanswered: int = 0                 # input stamps without a corrected output
    duplicated: int = 0                 # input stamps with more than one output
    contacts: dict[str, int] = field(default_factory=dict)
    bounce: BounceCheck | None = None
    energy_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    energy: np.ndarray = field(default_factory=lambda: np.zeros(0))
    momentum_drift: float = 0.0         # N s
    resting_drift: dict[str, float] = field(default_factory=dict)   # m, per box at rest
    ball_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ball_height: np.ndarray = field(default_factory=lambda: np.zeros(0))  # m, above touch-down

    @property
    def dropped(self) -> int:
        return self.unanswered

    def lines(self) -> list[str]:
        out = [f'steps: {self.steps_in} in, {self.steps_out} corrected out, '
               f'dropped {self.unanswered}, duplicated {self.duplicated}',
               'contacts: ' + ', '.join(f'{n} {self.contacts.get(n, 0)}'
                                        for n in STATE_NAMES.values())]
        b = self.bounce
        if b is not None:
            out.append(f'bounces of {b.ball} (e = {b.restitution:g}, dropped from '
                       f'{b.drop_height:.3f} m): apex measured vs h0 e^2n')
            for n, (m, e, err) in enumerate(zip(b.measured, b.expected, b.errors), 1):
                out.append(f'  #{n}: {m:.4f} m vs {e:.4f} m ({100 * err:+.2f} %)')
            if not b.measured:
                out.append('  (no bounce)')
        if len(self.energy):
            e0, e1 = self.energy[0], self.energy[-1]
            gain = float(np.max(np.diff(self.energy))) if len(self.energy) > 1 else 0.0
            out.append(f'energy: {e0:.4f} J -> {e1:.4f} J (largest gain in a step '
                       f'{max(gain, 0.0):.2e} J)')
        out.append(f'momentum drift orthogonal to gravity: {self.momentum_drift:.2e} N s')
        for name, drift in self.resting_drift.items():
            out.append(f'resting {name}: moved {1000 * drift:.3f} mm')
        return out


def _pair_restitution(ball: BodySpec, other: BodySpec | None, rule: str) -> float:
    if other is None:
        return ball.restitution
    from collres_ros.core.world import combine
    return float(combine(np.array([ball.restitution]), np.array([other.restitution]), rule)[0])


def _stamp(msg: Any) -> int:
    return stamp_ns(msg.header.stamp)


def analyse(messages: Sequence[Any], specs: Sequence[BodySpec], gravity: Sequence[float],
            restitution_rule: str = 'max', namespace: str = '/',
            initial: Any = None) -> RunReport:
    """Measure a run from its bag messages (``collres_ros.ros.bag.BagMessage`` list).

    ``initial``: the scene's BodyStates (``Scene.initial``), for the static
    bodies' poses (the floor's top face is the bounce law's reference height).
    """
    ns = namespace.rstrip('/')
    by_topic: dict[str, list[Any]] = {}
    for m in messages:
        by_topic.setdefault(m.topic, []).append(m.msg)
    inputs = by_topic.get(f'{ns}/body_states', [])
    corrected = by_topic.get(f'{ns}/body_states/corrected', [])
    dynamic = [s for s in specs if not s.static]
    if inputs:
        input_stamps = [_stamp(msg) for msg in inputs]
    else:  # per-body inputs: one step per stamp of the first dynamic body's pose
        poses = by_topic.get(f'{ns}/bodies/{dynamic[0].name}/pose', []) if dynamic else []
        input_stamps = sorted({_stamp(msg) for msg in poses})
    report = RunReport(steps_in=len(input_stamps), steps_out=len(corrected))
    answers: dict[int, int] = {}
    for msg in corrected:
        answers[_stamp(msg)] = answers.get(_stamp(msg), 0) + 1
    for stamp in input_stamps:
        n = answers.get(stamp, 0)
        report.unanswered += n == 0
        report.duplicated += n > 1
    first_impact: dict[str, Any] = {}
    for msg in by_topic.get(f'{ns}/contacts', []):
        for c in msg.contacts:
            name = state_name(c.state)
            report.contacts[name] = report.contacts.get(name, 0) + 1
            if c.state == 1:
                first_impact.setdefault(c.body_a, c)
                first_impact.setdefault(c.body_b, c)

    if not corrected or not dynamic:
        return report
    g = np.asarray(gravity, float)
    traj = trajectory(corrected, [s.name for s in dynamic])
    report.energy_time, report.energy = traj.time, energy(traj, dynamic, g)
    report.momentum_drift = horizontal_momentum_drift(traj, dynamic, g)
    start = trajectory(inputs[:1], [s.name for s in dynamic]) if inputs else traj
    if initial is not None:  # the scene's initial state (also right for per-body inputs)
        rows = [i for i, spec in enumerate(specs) if not spec.static]
        start = Trajectory(start.names, np.zeros(1), np.zeros(1, np.int64),
                           initial.position[rows][None], initial.orientation[rows][None],
                           initial.linear[rows][None], initial.angular[rows][None])
    for i, spec in enumerate(dynamic):
        if spec.shape == 'box' and np.linalg.norm(start.linear[0, i]) < 1e-9:
            moved = np.linalg.norm(traj.position[:, i] - start.position[0, i], axis=1)
            report.resting_drift[spec.name] = float(np.max(moved))
    poses = None if initial is None else {
        spec.name: (initial.position[i], initial.orientation[i]) for i, spec in enumerate(specs)}
    report.bounce = _bounce(traj, start, dynamic, specs, g, first_impact, restitution_rule,
                            poses)
    if report.bounce is not None:
        i = traj.names.index(report.bounce.ball)
        up = -g / np.linalg.norm(g)
        report.ball_time = traj.time
        report.ball_height = traj.position[:, i] @ up - report.bounce.contact_height
    return report


def _top_height(spec: BodySpec, pose: tuple[np.ndarray, np.ndarray] | None,
                up: np.ndarray) -> float | None:
    """Height along ``up`` of the top of a static box (support function), else None."""
    if pose is None or not spec.static or spec.shape != 'box':
        return None
    position, orientation = pose
    axes = to_matrix(np.asarray(orientation, float))      # columns: body axes in world
    half = 0.5 * np.asarray(spec.size, float)
    return float(np.asarray(position) @ up + np.sum(half * np.abs(axes.T @ up)))


def _bounce(traj: Trajectory, start: Trajectory, dynamic: Sequence[BodySpec],
            specs: Sequence[BodySpec], g: np.ndarray, first_impact: dict[str, Any],
            rule: str, initial: dict[str, tuple[np.ndarray, np.ndarray]] | None = None
            ) -> BounceCheck | None:
    """Check the e^2 law on the first sphere dropped from rest that hit something."""
    norm = float(np.linalg.norm(g))
    if norm == 0:
        return None
    up = -g / norm
    by_name = {s.name: s for s in specs}
    for i, spec in enumerate(dynamic):
        contact = first_impact.get(spec.name)
        if spec.shape != 'sphere' or contact is None \
                or np.linalg.norm(start.linear[0, i]) > 1e-9:
            continue
        other_name = contact.body_b if contact.body_a == spec.name else contact.body_a
        other = by_name.get(other_name)
        e = _pair_restitution(spec, other, rule)
        surface = None if other is None or initial is None else \
            _top_height(other, initial[other_name], up)
        if surface is None:  # no analytic surface: the reported contact point
            surface = float(np.array([contact.position.x, contact.position.y,
                                      contact.position.z]) @ up)
        contact_height = surface + spec.size[0]    # centre height at touch-down
        height = traj.position[:, i] @ up - contact_height
        speed = traj.linear[:, i] @ up
        drop = float(start.position[0, i] @ up) - contact_height
        found = apexes(traj.time, height, speed)
        expected = [drop * e ** (2 * n) for n in range(1, len(found) + 1)]
        return BounceCheck(spec.name, e, drop, [h for _, h in found], expected,
                           [t for t, _ in found], contact_height)
    return None


def plot(report: RunReport, path: str | Path) -> Path:
    """PNG with the ball's height (and the e^2 law's apexes) and the energy over time."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    b = report.bounce
    if b is not None:
        top.plot(report.ball_time, report.ball_height,
                 label=f'{b.ball}: lowest point above the floor')
        top.plot(b.times, b.measured, 'o', label='measured apex')
        top.plot(b.times, b.expected, 'x', markersize=10,
                 label=f'h0 e^2n (e = {b.restitution:g})')
        top.legend(loc='upper right')
    top.set_ylabel('height, m')
    top.set_title('collres demo')
    top.grid(True)
    bottom.plot(report.energy_time, report.energy)
    bottom.set_ylabel('total energy, J')
    bottom.set_xlabel('time, s')
    bottom.grid(True)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
