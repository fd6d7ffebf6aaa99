#!/usr/bin/env python3
"""Regenerate the regression bags in test/data/ and print their physical checks.

Usage (also ``make goldens``)::

    .venv/bin/python tools/regenerate_goldens.py [--out DIR] [SCENE ...]

``--out DIR`` writes elsewhere (e.g. to review the physical checks of a core
change before replacing the shipped goldens).

For each shipped scene (config/scenes/<scene>.yaml), over a short duration:

1. ``test/data/<scene>/input``: ``collres_sim --offline`` of the scene,
   recording only ``/body_states`` (the inputs the node would receive);
2. ``test/data/<scene>/golden``: ``collres_replay`` of that input, keeping
   ``/body_states/corrected`` and ``/contacts`` (markers and diagnostics are
   derived or timing-dependent);
3. the physical checks of the run: bounce law, momentum, stopping distance,
   slope hold and slide, resting drift, tunnelling. Read them before
   committing: a golden must be physically right, not just new.

Both bags are mcap with zstd chunks. A scene whose regenerated messages (topic,
type, log time and bytes of each) equal the ones in place is left as it is, files
untouched: on a clean clone with nothing changed, ``make goldens`` changes nothing.
Exit code 1 when a check fails.
"""

from __future__ import annotations

import math
import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from collres_ros.ros import analysis  # noqa: E402
from collres_ros.ros.bag import read_messages  # noqa: E402
from collres_ros.ros.offline import replay, run_offline  # noqa: E402
from collres_ros.ros.simulation import load_sim_scene  # noqa: E402

SCENES_DIR = ROOT / 'config' / 'scenes'
DATA_DIR = ROOT / 'test' / 'data'
GOLDEN_TOPICS = ('body_states/corrected', 'contacts')

# seconds of simulated time kept in the goldens (the pile: a short slice)
DURATIONS = {
    'bouncing_ball': 2.1,
    'billiard_break': 0.3,
    'box_slide': 1.0,
    'slope_hold': 1.0,
    'slope_slide': 1.0,
    'box_stack': 0.5,
    'fast_sphere_wall': 0.05,
    'pile': 0.1,
    'arm': 0.8,
}


@dataclass
class Check:
    """One physical check: what, measured, expected, passed."""

    name: str
    measured: str
    expected: str
    ok: bool

    def line(self) -> str:
        return f'  [{"ok" if self.ok else "FAIL"}] {self.name}: {self.measured} ' \
               f'(expected {self.expected})'


@dataclass
class Run:
    """The decoded run of a scene: input and golden messages plus the scene."""

    sim: object
    report: analysis.RunReport
    traj: analysis.Trajectory


def _run(scene: str, messages: list) -> Run:
    sim = load_sim_scene(SCENES_DIR / f'{scene}.yaml', DURATIONS[scene])
    specs = sim.scene.bodies
    report = analysis.analyse(messages, specs, sim.gravity,
                              sim.scene.solver.restitution_rule, initial=sim.scene.initial)
    dynamic = [s.name for s in specs if not s.static]
    corrected = [m.msg for m in messages if m.topic == '/body_states/corrected']
    return Run(sim, report, analysis.trajectory(corrected, dynamic))


def _common(run: Run) -> list[Check]:
    r = run.report
    finite = bool(np.all(np.isfinite(run.traj.position)) and np.all(np.isfinite(run.traj.linear)))
    checks = [Check('every input answered once', f'{r.steps_in} in, {r.steps_out} out, '
                    f'{r.unanswered} unanswered, {r.duplicated} duplicated', 'one each',
                    r.unanswered == 0 and r.duplicated == 0 and r.steps_in == r.steps_out),
              Check('finite states', str(finite), 'True', finite)]
    if len(r.energy) > 1 and not run.sim.driven.any():   # a driven body does work
        gain = float(np.max(np.diff(r.energy)))
        scale = max(1.0, float(np.max(np.abs(r.energy))))
        checks.append(Check('no energy gain per step', f'largest gain {gain:.2e} J',
                            f'<= 1e-3 x {scale:.3g} J', gain <= 1e-3 * scale))
    return checks


def _bouncing_ball(run: Run) -> list[Check]:
    b = run.report.bounce
    if b is None or len(b.measured) < 3:
        return [Check('three bounces', str(0 if b is None else len(b.measured)), '>= 3', False)]
    return [Check(f'apex {n}', f'{m:.4f} m', f'{e:.4f} m = h0 e^{2 * n} within 2 %',
                  abs(m / e - 1) <= 0.02)
            for n, (m, e) in enumerate(zip(b.measured[:3], b.expected[:3]), 1)]


def _billiard(run: Run) -> list[Check]:
    drift = run.report.momentum_drift
    return [Check('momentum conserved', f'drift {drift:.2e} N s', '<= 1e-9 N s', drift <= 1e-9),
            Check('the break happened', f'{run.report.contacts.get("IMPACT", 0)} impacts',
                  '>= 1', run.report.contacts.get('IMPACT', 0) >= 1)]


def _box_slide(run: Run) -> list[Check]:
    sim = run.sim
    i = run.traj.names.index('box')
    v0 = float(np.linalg.norm(sim.initial.linear[sim.names.index('box')]))
    spec = sim.scene.bodies[sim.names.index('box')]
    mu, g = spec.kinetic_friction, float(np.linalg.norm(sim.gravity))
    expected = v0 ** 2 / (2 * mu * g)
    x = run.traj.position[:, i, 0]
    travelled = float(x[-1] - sim.initial.position[sim.names.index('box'), 0])
    speed = float(np.linalg.norm(run.traj.linear[-1, i]))
    return [Check('stopping distance', f'{travelled:.4f} m', f'{expected:.4f} m within 2 %',
                  abs(travelled / expected - 1) <= 0.02),
            Check('at rest at the end', f'{speed:.2e} m/s', '< 1e-3 m/s', speed < 1e-3)]


def _slope(hold: bool) -> Callable[[Run], list[Check]]:
    def check(run: Run) -> list[Check]:
        sim = run.sim
        i = run.traj.names.index('box')
        j = sim.names.index('box')
        moved = np.linalg.norm(run.traj.position[:, i] - sim.initial.position[j], axis=1)
        if hold:
            return [Check('holds on the slope', f'drift {1000 * moved.max():.3f} mm', '< 1 mm',
                          moved.max() < 1e-3)]
        spec = sim.scene.bodies[j]
        g = float(np.linalg.norm(sim.gravity))
        angle = math.radians(20.0)
        expected = g * (math.sin(angle) - spec.kinetic_friction * math.cos(angle))
        t = run.traj.time
        late = t > 0.2  # fit after the first contacts settled
        speed = np.linalg.norm(run.traj.linear[:, i], axis=1)
        slope = float(np.polyfit(t[late], speed[late], 1)[0])
        return [Check('slide acceleration', f'{slope:.4f} m/s^2',
                      f'{expected:.4f} m/s^2 within 3 %', abs(slope / expected - 1) <= 0.03)]
    return check


def _box_stack(run: Run) -> list[Check]:
    sim = run.sim
    i = run.traj.names.index('box4')
    j = sim.names.index('box4')
    drift = float(np.max(np.linalg.norm(run.traj.position[:, i] - sim.initial.position[j],
                                        axis=1)))
    return [Check('top box stays', f'drift {1000 * drift:.3f} mm', '< 10 mm', drift < 0.01)]


def _fast_sphere_wall(run: Run) -> list[Check]:
    i = run.traj.names.index('bullet')
    vx = float(run.traj.linear[-1, i, 0])
    x = float(run.traj.position[-1, i, 0])
    return [Check('caught by the wall', f'x = {x:.3f} m', '< 0 (it did not pass)', x < 0),
            Check('bounced back', f'vx = {vx:.3f} m/s', '-100 m/s (e = 0.5) within 1 %',
                  abs(vx / -100.0 - 1) <= 0.01)]


def _arm(run: Run) -> list[Check]:
    sim = run.sim
    i = run.traj.names.index('box2')
    moved = float(np.linalg.norm(run.traj.position[-1, i] - sim.initial.position[
        sim.names.index('box2')]))
    return [Check('the arm knocks the stack over', f'top box moved {100 * moved:.1f} cm',
                  '> 5 cm', moved > 0.05)]


CHECKS: dict[str, Callable[[Run], list[Check]]] = {
    'bouncing_ball': _bouncing_ball,
    'billiard_break': _billiard,
    'box_slide': _box_slide,
    'slope_hold': _slope(hold=True),
    'slope_slide': _slope(hold=False),
    'box_stack': _box_stack,
    'fast_sphere_wall': _fast_sphere_wall,
    'pile': lambda run: [],
    'arm': _arm,
}


def _recorded(bag: Path) -> list[tuple[str, str, int, bytes]] | None:
    """(topic, type, log time, CDR bytes) of every message of a bag; None without one."""
    from collres_ros.ros.bag import BagError, BagReader
    try:
        with BagReader(bag) as reader:
            return list(reader.raw())
    except BagError:
        return None


def regenerate(scene: str, data_dir: Path = DATA_DIR) -> tuple[list[Check], int, bool]:
    """Write <data_dir>/<scene>/{input,golden} unless their messages are the same already;
    returns the checks, the bytes of the scene's files and whether they were written."""
    params = SCENES_DIR / f'{scene}.yaml'
    target = data_dir / scene
    with tempfile.TemporaryDirectory() as scratch:
        tmp = Path(scratch)
        sim = load_sim_scene(params, DURATIONS[scene])
        run_offline(sim, tmp / 'input', topics=['body_states'], compress=True)
        replay(tmp / 'input', tmp / 'golden', params, topics=GOLDEN_TOPICS, compress=True)
        messages = read_messages(tmp / 'input') + read_messages(tmp / 'golden')
        written = not all(_recorded(target / part) == _recorded(tmp / part)
                          for part in ('input', 'golden'))
        if written:
            if target.exists():
                shutil.rmtree(target)
            target.mkdir(parents=True)
            shutil.copytree(tmp / 'input', target / 'input')
            shutil.copytree(tmp / 'golden', target / 'golden')
    run = _run(scene, messages)
    size = sum(f.stat().st_size for f in target.rglob('*') if f.is_file())
    return _common(run) + CHECKS[scene](run), size, written


def main(argv: list[str]) -> int:
    data_dir = DATA_DIR
    if argv[:1] == ['--out']:
        if len(argv) < 2:
            print('error: --out needs a directory', file=sys.stderr)
            return 1
        data_dir, argv = Path(argv[1]), argv[2:]
    scenes = argv or list(DURATIONS)
    unknown = [s for s in scenes if s not in DURATIONS]
    if unknown:
        print(f'error: unknown scene(s) {", ".join(unknown)} (known: {", ".join(DURATIONS)})',
              file=sys.stderr)
        return 1
    failed = 0
    total = 0
    for scene in scenes:
        checks, size, written = regenerate(scene, data_dir)
        total += size
        print(f'{scene}: {DURATIONS[scene]} s, {size / 1024:.1f} KiB '
              + (f'-> {data_dir / scene}/' if written else '(unchanged: the same messages)'))
        for check in checks:
            print(check.line())
        failed += sum(not c.ok for c in checks)
    print(f'total {total / 1024:.1f} KiB; {failed} failed check(s)')
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
