"""Does a pile come to rest? A pile of ``bench/pile.py`` dropped at one rate, its settling.

Usage::

    .venv/bin/python bench/bench_rest.py [--kind mixed|cubes] [--size 1000] [--rate 30]
        [--seconds 12] [--every 1] [--substep S] [--seed 1] [--why]

The simulator's loop (semi-implicit Euler under gravity, each answer integrated for one
period), sleeping on. Every ``--every`` s it prints: the bodies whose farthest point moves
faster than 0.05 m/s (Box2D's sleep speed) and the fastest, the deepest penetration of the
answer (any pair, into the floor, and between two dynamic bodies: a detector of its own on
the answered poses), the fastest approach left at a touching contact (the answered twists),
solver rows and velocity sweeps per step and the step's median time, and the sleeping
bodies; at the end the time the pile fell asleep, the steps in which a body answered
asleep in that step and the one before had moved between them (more than 1e-9 m at its
bounding radius) with the largest such move (none since a woken island's still time
restarts), and the depths into the floor and between bodies at the end and the deepest of
each at any report. ``--substep``:
``solver.max_substep`` (s; default: the setting's).

``--why``: how the pairs got deep. Every step, each pair of bodies whose overlap grew by
more than 1 mm in the step (measured on the answers, by a probe with a 0.2 m margin, so
pairs beyond the speculative margin count too) is put in one of four classes, and at the
end the count and the millimetres grown per class are printed (with the pair's gap at the
step's start: beyond the margin, within it, touching (overlapping by less than 2 mm) or
deeper already):

* ``missed``: the step's detection gave the pair no contact (its bodies fell into each
  other from beyond the margin within the step);
* ``impact``: the pair's own contact was an impact (IMPACT/TUNNELLED, or a persistent
  contact that closed faster than the restitution threshold);
* ``impact of a third``: a body of the pair had an impact with a third body in the step;
* ``resting``: the pair's contacts were in the step and no impact touched it.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from collres_ros.core.config import SolverSettings
from collres_ros.core.detection import Detection
from collres_ros.core.types import ContactKind, ContactState, StepResult
from collres_ros.core.world import World

from pile import PILES, integrate, make_pile  # noqa: I100


def figures(probe: Detection, state, dynamic: np.ndarray, radius: np.ndarray) -> dict:
    """Speeds (m/s, farthest point), deepest penetration (m: of any pair, into the floor,
    and between two dynamic bodies), the fastest approach left at a contact within 1 mm
    (m/s)."""
    speed = np.linalg.norm(state.linear, axis=1) + np.linalg.norm(state.angular, axis=1) * radius
    speed = np.where(dynamic, speed, 0.0)
    seen = probe.detect(state, state)
    if seen.count == 0:
        return {'speed': speed, 'deepest': 0.0, 'floor': 0.0, 'pair': 0.0, 'approach': 0.0}
    a, b, point = seen.body_a, seen.body_b, seen.point
    va = state.linear[a] + np.cross(state.angular[a], point - state.position[a])
    vb = state.linear[b] + np.cross(state.angular[b], point - state.position[b])
    normal_speed = np.einsum('ij,ij->i', vb - va, seen.normal)
    touching = seen.separation < 1e-3
    on_floor = (a == 0) | (b == 0)
    between = dynamic[a] & dynamic[b]
    return {'speed': speed, 'deepest': float(max(0.0, -seen.separation.min())),
            'floor': float(max(0.0, -seen.separation[on_floor].min())) if on_floor.any()
            else 0.0,
            'pair': float(max(0.0, -seen.separation[between].min())) if between.any() else 0.0,
            'approach': float(max(0.0, -normal_speed[touching].min())) if touching.any()
            else 0.0}


def asleep_move(before, after, radius: np.ndarray) -> np.ndarray:
    """(N,) m each body moved between two answers: the larger of its shift and its turn
    (2 |dq| rad, the quaternions' sign aligned) times its bounding radius."""
    shift = np.linalg.norm(after.position - before.position, axis=1)
    q, q0 = after.orientation, before.orientation
    turn = 2.0 * np.minimum(np.linalg.norm(q - q0, axis=1), np.linalg.norm(q + q0, axis=1))
    return np.maximum(shift, turn * radius)


GREW = 1e-3    # m: a pair whose overlap grew by more than this in one step is counted (--why)
WIDE = 0.2     # m: the --why probe's margin (pairs that far apart have a gap)
TOUCHING = 2e-3   # m: a pair overlapping less than this at a step's start is touching


def pair_gaps(probe: Detection, state) -> dict[tuple[int, int], float]:
    """Per pair of bodies (a < b), the least separation of the probe's contacts (m)."""
    seen = probe.detect(state, state)
    gaps: dict[tuple[int, int], float] = {}
    for a, b, gap in zip(seen.body_a.tolist(), seen.body_b.tolist(), seen.separation.tolist()):
        gaps[(a, b)] = min(gaps.get((a, b), gap), gap)
    return gaps


class Why:
    """The --why classes of the overlaps that grew (see the module docstring)."""

    def __init__(self, probe: Detection, margin: float, state) -> None:
        self.probe, self.margin = probe, margin
        self.gaps = pair_gaps(probe, state)
        self.grown: dict[str, list[float]] = {}

    def step(self, result: StepResult) -> None:
        gaps = pair_gaps(self.probe, result.states)
        contacts = result.report.contacts
        impact = (contacts.kind != ContactKind.PERSISTENT) | (result.report.state ==
                                                              ContactState.IMPACT)
        pairs = set(zip(contacts.body_a.tolist(), contacts.body_b.tolist()))
        own = set(zip(contacts.body_a[impact].tolist(), contacts.body_b[impact].tolist()))
        struck = set(contacts.body_a[impact].tolist()) | set(contacts.body_b[impact].tolist())
        for pair, gap in gaps.items():
            before = self.gaps.get(pair, WIDE)
            grew = min(before, 0.0) - gap
            if gap >= 0.0 or grew <= GREW:
                continue
            cause = ('missed' if pair not in pairs else 'impact' if pair in own
                     else 'impact of a third' if set(pair) & struck else 'resting')
            start = ('beyond the margin' if before > self.margin else 'within the margin'
                     if before > 0.0 else 'touching' if before > -TOUCHING else
                     f'over {TOUCHING * 1e3:g} mm deep')
            self.grown.setdefault(f'{cause}, at the start {start}', []).append(grew)
        self.gaps = gaps

    def table(self) -> str:
        total = sum(sum(grown) for grown in self.grown.values())
        lines = [f'overlaps that grew > {GREW * 1e3:g} mm in a step: '
                 f'{sum(len(g) for g in self.grown.values())} times, {total * 1e3:.0f} mm']
        for cause, grown in sorted(self.grown.items(), key=lambda item: -sum(item[1])):
            lines.append(f'  {sum(grown) * 1e3:8.0f} mm ({100 * sum(grown) / total:4.1f} %) '
                         f'in {len(grown):5d}: {cause}')
        return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--kind', choices=PILES, default='mixed')
    parser.add_argument('--size', type=int, default=1000)
    parser.add_argument('--rate', type=float, default=30.0, help='Hz')
    parser.add_argument('--seconds', type=float, default=12.0)
    parser.add_argument('--every', type=float, default=1.0, help='s between reports')
    parser.add_argument('--substep', type=float, default=SolverSettings().max_substep,
                        help='solver.max_substep, s')
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--why', action='store_true',
                        help='classify how the overlaps grew (see the module docstring)')
    args = parser.parse_args(argv)
    dt = 1.0 / args.rate
    bodies, state = make_pile(args.size, seed=args.seed, kind=args.kind)
    world = World(bodies, SolverSettings(max_substep=args.substep))
    probe = Detection(world.specs, SolverSettings(sleeping=False))
    dynamic = world.dynamic
    radius = np.array([0.5 * np.linalg.norm(b.size) if b.shape == 'box' else b.size[0]
                       if b.shape == 'sphere' else 0.0 for b in bodies])
    steps = int(round(args.seconds * args.rate))
    every = max(1, int(round(args.every * args.rate)))
    why = Why(Detection(world.specs, SolverSettings(sleeping=False, speculative_margin=WIDE)),
              world.settings.speculative_margin, state) if args.why else None
    asleep_at, times, rows, sweeps = None, [], [], []
    worst = {'floor': 0.0, 'pair': 0.0}   # the deepest at any report
    was = np.zeros(len(bodies), bool)
    moved_steps, moved_most = 0, 0.0   # steps with a body answered asleep twice that moved
    for k in range(steps):
        current = integrate(state, dynamic, dt)
        start = time.perf_counter()
        result = world.step(state, current, dt)
        times.append(time.perf_counter() - start)
        rows.append(world.timing['rows'])
        sweeps.append(world.timing['iterations'])
        now = result.sleeping & dynamic
        moved = asleep_move(state, result.states, radius)[was & now].max(initial=0.0)
        moved_steps += moved > 1e-9
        moved_most = max(moved_most, moved)
        was = now
        state = result.states
        if why is not None:
            why.step(result)
        if asleep_at is None and result.sleeping[dynamic].all():
            asleep_at = (k + 1) * dt
        if (k + 1) % every == 0:
            f = figures(probe, state, dynamic, radius)
            worst = {key: max(value, f[key]) for key, value in worst.items()}
            print(f't {(k + 1) * dt:5.2f} s: {int((f["speed"] > 0.05).sum()):4d} faster than '
                  f'0.05 m/s (fastest {f["speed"].max():.3f}), deepest {f["deepest"] * 1e3:6.2f} '
                  f'mm, into the floor {f["floor"] * 1e3:5.2f} mm, between bodies '
                  f'{f["pair"] * 1e3:5.2f} mm, approach left {f["approach"]:.3f} m/s, rows '
                  f'{np.mean(rows[-every:]):6.0f}, sweeps {np.mean(sweeps[-every:]):5.1f}, step '
                  f'{np.median(times[-every:]) * 1e3:6.1f} ms, asleep '
                  f'{int(result.sleeping[dynamic].sum())}', flush=True)
    print(f'{args.kind} {args.size} at {args.rate:g} Hz, max_substep {args.substep:g} s: '
          f'asleep after {asleep_at if asleep_at is None else round(asleep_at, 2)} s; answered '
          f'asleep in two consecutive steps and moved: {moved_steps} of {steps} steps, up to '
          f'{moved_most * 1e3:.3f} mm')
    if steps >= every:
        print(f'at the end: into the floor {f["floor"] * 1e3:.2f} mm, between bodies '
              f'{f["pair"] * 1e3:.2f} mm; deepest at any report: into the floor '
              f'{worst["floor"] * 1e3:.2f} mm, between bodies {worst["pair"] * 1e3:.2f} mm')
    if why is not None:
        print(why.table())
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
