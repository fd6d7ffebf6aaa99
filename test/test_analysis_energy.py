"""The demo's report and plot: energy at the stamps, and a useful plot for every shipped scene.

The integrator (``ros/integrator.py``, semi-implicit Euler) reports the
mid-step velocity: v_n = v_(n-1) + g dt, x_n = x_(n-1) + v_n dt, so v_n is the
velocity at t_n - dt/2 of the parabola through the positions, and the velocity
at the stamp is v_n + g dt/2. With it, 1/2 m v^2 - m g.x is constant in free
flight: to rounding when the stamps are exact (250 Hz: 4 ms), and within the
1 ns rounding of the stamps otherwise (240 Hz: steps of 4166667 and 4166666 ns
give |dE| ~ m |v| g (1 ns) / 2 ~ 2e-8 J per step here, 1e-7 J over a second of a
39 J flight: within 1e-8 of the energy). The mid-step velocity
instead makes free flight lose or gain m g.v dt/2 (~0.1 J here).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip('rclpy')

from collres_ros.ros.analysis import analyse, energy, plot, plot_series  # noqa: E402
from collres_ros.ros.bag import read_messages  # noqa: E402
from collres_ros.ros.offline import run_offline  # noqa: E402
from collres_ros.ros.simulation import load_sim_scene  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / 'config' / 'scenes'
FREE_FLIGHT = '''
/**:
  ros__parameters:
    bodies: [ball, box]
    body:
      ball: {shape: sphere, size: [0.1], mass: 1.0, position: [0.0, 0.0, 1.0],
             linear_velocity: [1.0, 0.0, 3.0]}
      box: {shape: box, size: [0.2, 0.1, 0.3], mass: 2.0, position: [5.0, 0.0, 1.0],
            linear_velocity: [0.0, -1.0, 2.0], angular_velocity: [0.0, 3.0, 1.0]}
/**/collres_sim:
  ros__parameters: {rate_hz: RATE, duration: 1.0}
'''


def run(tmp_path: Path, params: Path, duration: float | None = None):
    sim = load_sim_scene(params, duration)
    bag = tmp_path / f'bag_{params.stem}'
    run_offline(sim, bag)
    report = analyse(read_messages(bag), sim.scene.bodies, sim.gravity,
                     sim.scene.solver.restitution_rule, initial=sim.scene.initial)
    return sim, report, bag


@pytest.mark.parametrize('rate, relative', [(250.0, 1e-12), (240.0, 1e-8)])
def test_free_flight_energy_is_flat(tmp_path: Path, rate: float, relative: float) -> None:
    """Spread of the total energy over 1 s of flight below ``relative`` of the energy."""
    params = tmp_path / 'flight.yaml'
    params.write_text(FREE_FLIGHT.replace('RATE', str(rate)))
    sim, report, bag = run(tmp_path, params)
    assert sum(report.contacts.values()) == 0, 'free flight must not touch anything'
    assert len(report.energy) == int(rate) + 1
    spread = float(np.ptp(report.energy))
    tolerance = relative * float(np.abs(report.energy).max())
    # the mid-step reading of the same trajectory (the former definition) is not flat
    from collres_ros.ros.analysis import trajectory
    corrected = [m.msg for m in read_messages(bag) if m.topic == '/body_states/corrected']
    traj = trajectory(corrected, ['ball', 'box'])
    mid_step = float(np.ptp(energy(traj, sim.scene.bodies, sim.gravity, dt=0.0)))
    print(f'{rate:g} Hz: energy {report.energy[0]:.9f} J, spread {spread:.2e} J '
          f'(tolerance {tolerance:.1e} J); with the mid-step velocity: {mid_step:.3e} J')
    assert spread < tolerance
    assert mid_step > 0.05


def test_energy_is_flat_between_bounces_and_falls_at_them(tmp_path: Path) -> None:
    sim, report, bag = run(tmp_path, SCENES / 'bouncing_ball.yaml', 1.5)
    touching = [bool(m.msg.contacts) for m in read_messages(bag, ['/contacts'])]
    assert len(touching) == len(report.energy)
    change = np.diff(report.energy)               # step k-1 -> k
    contact = np.array(touching[1:]) | np.array(touching[:-1])
    free = ~contact
    print(f'flight steps: largest |dE| {np.abs(change[free]).max():.2e} J over {free.sum()} '
          f'steps; steps with a contact: lowest dE {np.sort(change[contact])[:3]} J')
    assert free.sum() > 200 and np.abs(change[free]).max() < 1e-7
    assert change.max() < 1e-7, 'energy gained in a step'
    assert change[contact].min() < -0.5, 'the bounces dissipate (e = 0.8)'
    line = next(ln for ln in report.lines() if ln.startswith('energy at the stamps'))
    assert f'{report.energy[0]:.4f} J -> {report.energy[-1]:.4f} J' in line


@pytest.mark.parametrize('scene', sorted(p.stem for p in SCENES.glob('*.yaml')))
def test_the_plot_shows_something_for_every_shipped_scene(tmp_path: Path, scene: str) -> None:
    sim = load_sim_scene(SCENES / f'{scene}.yaml')
    duration = min(sim.duration, 0.3 if scene != 'pile' else 0.05)
    sim, report, _ = run(tmp_path, SCENES / f'{scene}.yaml', duration)
    series = plot_series(report)
    for panel in ('top', 'bottom'):
        assert series[panel], f'{scene}: empty {panel} panel'
        for label, t, values, _ in series[panel]:
            assert len(t) == len(values) and np.isfinite(values).all(), (scene, label)
        assert max(len(t) for _, t, _, _ in series[panel]) > 1, (scene, panel)
    # something moves in the top panel: a height or a speed that is not all zero
    assert any(np.ptp(values) > 0 for _, _, values, _ in series['top']), scene
    print(scene, [label for label, *_ in series['top']])
    path = plot(report, tmp_path / f'{scene}.png')
    assert path.stat().st_size > 10_000
