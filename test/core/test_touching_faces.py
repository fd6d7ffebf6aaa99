"""Two cubes whose faces just touch get the faces' normal, at any gap below a micrometre.

A cube resting on another, both tilted by a few 1e-5 rad, the upper one 10 nm to 1 um above
the lower (a pose a landed column passes through every step): the contact's normal is the
faces' (world z, within the tilt) and its points lie within the gap and the tilt's rise
(a few um) of touching. coal's GJK stopped at its default tolerance (1e-6) with these
faces "touching", and the penetration query that followed on that degenerate simplex gave a
normal 9-88 deg off the faces' and separations of +-11 mm to -0.1 m: a column landed
intact read as a cube 11 mm deep in the one below, and the next solve would act on it
(random poses of this kind: 8 of 2000 so; none since every GJK query of a pair runs to a
tolerance of 1e-9).
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.detection import Detection
from collres_ros.core.types import BodySpec, BodyStates

# (positions (m), orientations (x y z w)) of the lower and the upper cube of 0.1 m
POSES = [
    # a column of cubes landing at 120 Hz: the upper cube 0.96 um above the lower
    ([[0.0006159649041219114, -0.000760676484888465, 0.2498675270744422],
      [0.0018130423098068138, -0.0019686975111883986, 0.3498729681964851]],
     [[1.9730245672487398e-05, -5.29046086545559e-05, 1.7710176471714827e-05,
       0.9999999982490847],
      [2.4703011427806594e-05, -1.2726818192231355e-05, 1.6732615007005014e-05,
       0.9999999994739046]]),
    # 10 nm apart
    ([[0.0, 0.0, 0.3382173154838221],
      [-0.001316348285335279, 0.002627121507736945, 0.4382213610560457]],
     [[-9.213043189858421e-06, -3.654242486313874e-06, -5.175140369221224e-06,
       0.9999999999374921],
      [9.51413003462012e-06, -1.797491165259404e-05, 1.4423672021327482e-05,
       0.9999999996891707]]),
    # 100 nm apart
    ([[0.0, 0.0, 0.39293111226226957],
      [-0.00044567093452792163, 0.0009048980146044538, 0.4929348154704731]],
     [[1.3282158475674574e-05, 1.1714786123951673e-05, 5.508123283309601e-06,
       0.9999999998280044],
      [-1.9973092265119956e-06, -9.038060443323343e-06, 2.4959621523087265e-05,
       0.9999999996456708]]),
    # 300 nm apart
    ([[0.0, 0.0, 0.12188048435622373],
      [1.2063402650487262e-05, 2.3229819378596268e-05, 0.2218867919329815]],
     [[-2.0656087519817538e-05, -8.472134660564847e-06, 1.2185609239188091e-05,
       0.99999999967653],
      [-9.149993376157747e-07, 3.0033397929937528e-05, -2.3968482234275967e-05,
       0.9999999992613349]]),
]


@pytest.mark.parametrize('pose', range(len(POSES)))
def test_cubes_whose_faces_just_touch_get_the_faces_normal(pose):
    positions, orientations = POSES[pose]
    cubes = [BodySpec(name, 'box', (0.1, 0.1, 0.1), mass=1.0) for name in ('lower', 'upper')]
    state = BodyStates.zeros(2)
    state.position[:] = positions
    state.orientation[:] = orientations
    contacts = Detection(cubes, SolverSettings()).detect(state, state)
    print(f'normal {contacts.normal[0]}, separations (um) {contacts.separation * 1e6}')
    assert contacts.count >= 1
    assert np.all(contacts.normal[:, 2] > 0.9999)           # the faces' (tilts ~3e-5 rad)
    assert np.all(np.abs(contacts.separation) < 2e-5)       # m: touching, within the tilts
