"""A resting pile streamed as the node sees it: no step timing makes it gain energy.

The settled pile of ``bench/pile.py`` (100 boxes and spheres in a bin, the latency
benchmark's), then a fresh resolver (the node at start: its first step is ``FRESH_DT``
long) takes it at 30 Hz, each input the last answer integrated one step with gravity
(semi-implicit Euler, as a simulator upstream does), every 5th input lost on the way (its
stamp never reaches the resolver: the next step is twice as long). The contacts of a
resting pile only take kinetic energy away: no answer may carry more than its input.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from collres_ros.core.pipeline import Resolver
from collres_ros.core.types import InputBatch
from collres_ros.ros.energy import kinetic_energy
from collres_ros.ros.messages import state_values

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'bench'))
from pile import integrate, make_pile  # noqa: E402

FIELDS = ('position', 'orientation', 'linear', 'angular')


def stream(resolver, states, rate, steps, start_ns, lost=()):
    """Each input integrated from the last answer; [(input KE, answer KE) J], last states."""
    bodies = resolver.bodies
    dynamic = resolver.dynamic
    rows = np.flatnonzero(dynamic)
    names = [bodies[i].name for i in rows]
    dt_ns = int(round(1e9 / rate))
    energies = []
    for k in range(1, steps + 1):
        current = integrate(states, dynamic, dt_ns * 1e-9)
        if k in lost:
            continue
        out = resolver.resolve(start_ns + k * dt_ns,
                               InputBatch(names, state_values(current)[rows], 'world', 'world'))
        assert not out.rejected
        states = current.copy()
        for name in FIELDS:
            getattr(states, name)[out.index] = getattr(out.states, name)
        energies.append([kinetic_energy(s.orientation, s.linear, s.angular, bodies).sum()
                         for s in (current, states)])
    return np.array(energies), states


@pytest.mark.slow
def test_a_resting_pile_streamed_at_30_hz_with_losses_gains_no_energy():
    bodies, initial = make_pile(100)
    _, rest = stream(Resolver(bodies, initial=initial), initial, 120.0, 120, 10**9)
    energies, _ = stream(Resolver(bodies, initial=rest), rest, 30.0, 60, 100 * 10**9,
                         lost=set(range(5, 61, 5)))
    inputs, answers = energies[:, 0], energies[:, 1]
    worst = int(np.argmax(answers - inputs))
    print(f'kinetic energy in {inputs.min():.3f} .. {inputs.max():.3f} J, out '
          f'{answers.min():.3g} .. {answers.max():.3f} J; worst step {worst}: '
          f'{inputs[worst]:.3f} -> {answers[worst]:.3f} J')
    assert (answers <= inputs).all(), \
        f'step {worst}: the resting pile gained {answers[worst] - inputs[worst]:.3f} J'
