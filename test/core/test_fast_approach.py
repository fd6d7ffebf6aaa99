"""Bodies that fall onto one another within one step land touching, not inside each other.

A column of 8 cubes of 0.1 m, each 20 mm above the one below (the speculative margin), is
dropped onto a floor: the lowest lands first, and each of the others lands on a cube that
has just landed, at up to 1.3 m/s (43 mm per 30 Hz step). Landed, every pair may overlap
by the slop and what the push-out has not yet removed, never by a centimetre: a user
sees a cube sunk into the one below it.

A cube that rests on another (touching it at the step's start) and is struck late in a
step is held by what it rests on until the impact: the solve rewinds it along its previous
twist, not along the path its source integrated under gravity through its support (16 mm
at 30 Hz), and times the impact against that held path. Measured on the old solve
(b64680e), which rewound it along the integrated path: 120 Hz 1.07 mm, 30 Hz 15.34 mm (the
fifth cube struck at 0.98 of a step); with the held path: 0.94 and 1.92 mm.
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.detection import Detection
from collres_ros.core.types import BodySpec, ContactKind

from contacts import box, states  # noqa: I100
from integrator import Simulation

SIZE = 0.1       # m, cube edge
GAP = 0.02       # m, between one cube and the next at the start
COUNT = 8
OVERLAP = 2e-3   # m: the most two landed cubes may overlap


def column(rate: float, threshold: float = SolverSettings().restitution_threshold
           ) -> Simulation:
    """COUNT cubes in a column, GAP apart and 5 mm above the floor, at rest (``threshold``:
    the restitution threshold, m/s)."""
    floor = BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True,
                     static_friction=0.6, kinetic_friction=0.4)
    cubes = [box(f'cube{k}', (SIZE,) * 3, 1.0, e=0.2, mu_s=0.6, mu_k=0.4)
             for k in range(COUNT)]
    start = [[0.0, 0.0, 0.0]] + [[0.002 * k, 0.001 * k, 0.005 + SIZE / 2 + (SIZE + GAP) * k]
                                 for k in range(COUNT)]
    return Simulation([floor] + cubes, states(start, np.zeros((COUNT + 1, 3))), rate,
                      SolverSettings(sleeping=False, restitution_threshold=threshold))


def deepest_overlap(sim: Simulation, seconds: float) -> float:
    """The deepest overlap of two cubes (m) at any step of ``seconds`` of the column."""
    probe = Detection(sim.world.specs, SolverSettings(sleeping=False))
    deepest = 0.0
    for _ in range(int(round(seconds / sim.dt))):
        sim.step()
        seen = probe.detect(sim.state, sim.state)
        cubes = seen.body_a > 0
        if cubes.any():
            deepest = max(deepest, float(-seen.separation[cubes].min()))
    return deepest


@pytest.mark.parametrize('rate', [120.0, 30.0])
def test_a_column_dropped_apart_lands_without_sinking_into_itself(rate: float) -> None:
    sim = column(rate)
    probe = Detection(sim.world.specs, SolverSettings(sleeping=False))
    deepest, landed = 0.0, set()
    for _ in range(int(round(1.0 * rate))):
        result = sim.step()
        contacts = result.report.contacts
        between = (contacts.body_a > 0) & (contacts.kind != ContactKind.PERSISTENT)
        landed |= set(zip(contacts.body_a[between].tolist(), contacts.body_b[between].tolist()))
        seen = probe.detect(sim.state, sim.state)
        cubes = seen.body_a > 0
        if cubes.any():
            deepest = max(deepest, float(-seen.separation[cubes].min()))
    heights = np.sort(sim.state.position[1:, 2])
    print(f'{rate:g} Hz: deepest overlap of two cubes {deepest * 1e3:.2f} mm, '
          f'{len(landed)} pairs of cubes met in an impact')
    assert landed    # cubes struck cubes (at 30 Hz most pairs meet as speculative contacts)
    # landed: a column, each cube one edge above the one below (within the overlap allowed)
    assert np.allclose(np.diff(heights), SIZE, atol=OVERLAP)
    assert deepest < OVERLAP


@pytest.mark.parametrize('rate', [30.0, 120.0])
@pytest.mark.parametrize('gap', [0.045, 0.057, 0.065])   # m: the impact at 0.35-0.95 of a step
def test_a_box_sliding_on_a_floor_strikes_a_box_resting_there(rate: float, gap: float) -> None:
    """Two equal boxes on a frictionless floor, one sliding at v0 into the other (e): the
    struck box leaves at (1 + e) / 2 v0, the striker keeps (1 - e) / 2 v0, and neither
    sinks into the floor nor rises from it. Both rest on the floor when they meet, so the
    solve must not rewind them along the path their source integrated under gravity
    (through the floor: 7-11 mm at 30 Hz): the hold-back against fixed shapes then held
    them where they were, at rest, and the impact was lost (on b64680e both boxes stopped
    dead, 0.00 m/s, at 30 and at 120 Hz)."""
    e, v0 = 0.5, 1.0
    floor = BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True)
    boxes = [box(name, (SIZE,) * 3, 1.0, e=e) for name in ('striker', 'struck')]
    start = states([[0.0, 0.0, 0.0], [0.0, 0.0, SIZE / 2], [SIZE + gap, 0.0, SIZE / 2]],
                   [[0.0, 0.0, 0.0], [v0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    sim = Simulation([floor] + boxes, start, rate, SolverSettings(sleeping=False))
    struck, lowest, highest = False, SIZE, 0.0
    for _ in range(int(round(0.4 * rate))):
        contacts = sim.step().report.contacts
        struck |= bool(((contacts.body_a == 1) & (contacts.body_b == 2)
                        & (contacts.kind != ContactKind.PERSISTENT)).any())
        lowest = min(lowest, float(sim.state.position[1:, 2].min()))
        highest = max(highest, float(sim.state.position[1:, 2].max()))
    after = sim.state.linear[1:, 0]
    print(f'{rate:g} Hz, gap {gap * 1e3:.0f} mm: after {after.round(4)} m/s (law '
          f'{(1 - e) / 2 * v0:.3f}, {(1 + e) / 2 * v0:.3f}); heights '
          f'{(lowest - SIZE / 2) * 1e3:.3f} .. {(highest - SIZE / 2) * 1e3:.3f} mm')
    assert struck
    np.testing.assert_allclose(after, [(1 - e) / 2 * v0, (1 + e) / 2 * v0], atol=0.01 * v0)
    assert lowest > SIZE / 2 - 5e-4 and highest < SIZE / 2 + 5e-4


def test_a_cube_landing_on_one_its_floor_holds_rests_as_on_the_floor() -> None:
    """The column dropped apart at 30 Hz with restitution_threshold 0.05 m/s: a cube that
    lands on one its floor holds gathers g dt of approach relative to it in every step, as
    on the floor (not the none of two cubes falling together), and its landing slower than
    1.5 g dt rests. No two cubes overlap by half a step of gravity's travel, g dt^2 / 2
    (5.4 mm; with a fixed resting speed of 0.05 m/s the landings bounced and two cubes
    overlapped 12.4 mm)."""
    rate = 30.0
    deepest = deepest_overlap(column(rate, threshold=0.05), 1.0)
    print(f'deepest overlap of two cubes {deepest * 1e3:.2f} mm')
    assert deepest < 0.5 * 9.81 / rate ** 2
