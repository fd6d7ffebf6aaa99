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


def step_lengths(stamps: np.ndarray, input_stamps: Sequence[int] | None = None) -> np.ndarray:
    """(T,) s: the integrator step that ended at each stamp.

    From the input stamps when given (a dropped answer leaves no gap then): a
    stamp's step is its distance to the previous input stamp; the first
    stamp's is the next one's (the integrator's first step).
    """
    stamps = np.asarray(stamps, np.int64)
    base = np.unique(np.asarray(input_stamps if input_stamps is not None and len(input_stamps)
                                else stamps, np.int64))
    if len(base) < 2:
        return np.zeros(len(stamps))
    lengths = np.diff(base) * 1e-9
    lengths = np.concatenate(([lengths[0]], lengths))
    k = np.clip(np.searchsorted(base, stamps), 0, len(base) - 1)
    return lengths[k]


def energy(traj: Trajectory, specs: Sequence[BodySpec], gravity: np.ndarray,
           dt: np.ndarray | float | None = None) -> np.ndarray:
    """Total mechanical energy of the trajectory's bodies at each stamp, J, shape (T,).

    ``collres_ros.ros.energy.total_energy`` with the linear velocity at the stamp,
    ``integrator.stamp_velocity``: the reported twist is the semi-implicit Euler's
    mid-step one, v + g dt/2 at the stamp. With it free flight is flat (to
    rounding). ``dt``: (T,) or scalar step length, s (default: from the stamps;
    0 reads the reported twist as is).
    """
    from collres_ros.ros.integrator import stamp_velocity
    if dt is None:
        dt = step_lengths(traj.stamps)
    dt = np.broadcast_to(np.asarray(dt, float), traj.time.shape)
    linear = stamp_velocity(traj.linear, gravity, dt[:, None])     # (T, N, 3)
    return total_energy(traj.position, traj.orientation, linear, traj.angular, specs, gravity)


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


TOUCHES_SHOWN = 8   # pairs of what touched what a report lists, most points first


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
    # the scene drives bodies (kinematic or a robot's scripted joints): a box at rest at the
    # start may be pushed, as the arm scene's stack is meant to be
    driven: bool = False
    ball_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ball_height: np.ndarray = field(default_factory=lambda: np.zeros(0))  # m, above touch-down
    speed: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # (T, N) m/s reported
    speed_names: list[str] = field(default_factory=list)                 # (N) dynamic bodies
    # what touched what: contact points that carried impulse, by "a[/piece] - b[/piece]"
    touches: dict[str, int] = field(default_factory=dict)

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
            out.append(f'energy at the stamps: {e0:.4f} J -> {e1:.4f} J (largest gain in a '
                       f'step {max(gain, 0.0):.2e} J)')
        out.append(f'momentum drift orthogonal to gravity: {self.momentum_drift:.2e} N s')
        for name, drift in self.resting_drift.items():   # the farthest from its start
            meant = 'driven bodies may push it' if self.driven else 'nothing should move it'
            out.append(f'box at rest at the start, {name}: moved {1000 * drift:.3f} mm '
                       f'({meant})')
        if any('/' in pair for pair in self.touches):   # a scene of compounds or robots
            out.append('what touched what (contact points with impulse):')
            ranked = sorted(self.touches.items(), key=lambda item: (-item[1], item[0]))
            out += [f'  {pair}: {count}' for pair, count in ranked[:TOUCHES_SHOWN]]
            if len(ranked) > TOUCHES_SHOWN:
                out.append(f'  ... and {len(ranked) - TOUCHES_SHOWN} more pairs')
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
            initial: Any = None, driven: bool = False) -> RunReport:
    """Measure a run from its bag messages (``collres_ros.ros.bag.BagMessage`` list).

    ``initial``: the scene's BodyStates (``Scene.initial``), for the static
    bodies' poses (the floor's top face is the bounce law's reference height).
    ``driven``: the scene drives bodies (``RunReport.driven``).
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
    report = RunReport(steps_in=len(input_stamps), steps_out=len(corrected), driven=driven)
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
            if c.normal_impulse > 0.0:
                pair = (f'{c.body_a}{"/" + c.piece_a if c.piece_a else ""} - '
                        f'{c.body_b}{"/" + c.piece_b if c.piece_b else ""}')
                report.touches[pair] = report.touches.get(pair, 0) + 1
            if c.state == 1:
                first_impact.setdefault(c.body_a, c)
                first_impact.setdefault(c.body_b, c)

    if not corrected or not dynamic:
        return report
    g = np.asarray(gravity, float)
    traj = trajectory(corrected, [s.name for s in dynamic])
    dt = step_lengths(traj.stamps, input_stamps)
    report.energy_time, report.energy = traj.time, energy(traj, dynamic, g, dt)
    report.speed_names = traj.names
    # speeds as reported (a body at rest reads 0; at the stamp it would read g dt/2)
    report.speed = np.linalg.norm(traj.linear, axis=2)
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


MAX_LINES = 8   # bodies drawn one by one in the speed panel; more: their mean and maximum


def plot_series(report: RunReport) -> dict[str, list[tuple[str, np.ndarray, np.ndarray, str]]]:
    """What the plot draws: {'top' | 'bottom': [(label, t s, values, style), ...]}.

    Top: the ball's height against the e^2 law's apexes when a ball bounced,
    else the speed of each dynamic body as reported (their mean and maximum
    beyond ``MAX_LINES`` bodies). Bottom: the total energy at the stamps.
    """
    top: list[tuple[str, np.ndarray, np.ndarray, str]] = []
    b = report.bounce
    if b is not None and len(report.ball_time):
        top += [(f'{b.ball}: lowest point above the floor', report.ball_time,
                 report.ball_height, '-'),
                ('measured apex', np.array(b.times), np.array(b.measured), 'o'),
                (f'h0 e^2n (e = {b.restitution:g})', np.array(b.times), np.array(b.expected),
                 'x')]
    elif report.speed.size:
        t = report.energy_time
        if report.speed.shape[1] <= MAX_LINES:
            top += [(name, t, report.speed[:, i], '-')
                    for i, name in enumerate(report.speed_names)]
        else:
            count = report.speed.shape[1]
            top += [(f'mean of {count} bodies', t, report.speed.mean(axis=1), '-'),
                    (f'fastest of {count} bodies', t, report.speed.max(axis=1), '-')]
    bottom = [('kinetic (at the stamp) + potential', report.energy_time, report.energy, '-')] \
        if len(report.energy) else []
    return {'top': top, 'bottom': bottom}


def plot(report: RunReport, path: str | Path) -> Path:
    """PNG of ``plot_series``: a height or speed panel over an energy panel."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    series = plot_series(report)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for label, t, values, style in series['top']:
        top.plot(t, values, style, label=label, **({'markersize': 10} if style == 'x' else {}))
    if series['top']:
        top.legend(loc='upper right', fontsize='small')
    bounced = report.bounce is not None and len(report.ball_time)
    top.set_ylabel('height, m' if bounced else 'speed, m/s')
    top.set_title('collres demo')
    top.grid(True)
    for label, t, values, style in series['bottom']:
        bottom.plot(t, values, style, label=label)
    if series['bottom']:
        bottom.legend(loc='upper right', fontsize='small')
    bottom.set_ylabel('total energy, J')
    bottom.set_xlabel('time, s')
    bottom.grid(True)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
