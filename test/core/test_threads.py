"""The velocity sweeps give the same bits whatever their layout: waves, lanes, threads.

A sweep visits a solve's manifolds wave by wave (src/sweep_waves.h): a manifold's wave is
one more than the highest wave of the manifolds before it that share a movable body, or a
later one before the next manifold on each of its movable bodies (to fill a later wave's
wide groups with the manifolds a wave leaves over), so the manifolds of a wave share no
movable body and the waves in turn are the sweep in the solve's order, bit for bit. A wave
is solved four manifolds at a time in wide rows (``SOLVER_TUNING`` ``wide_rows``; the two
or three left of a row count in a group padded with idle lanes); with two threads
(``threads``) and waves that average at least twice ``parallel_wave`` manifolds, each wave
is cut in two sides (connected halves of the pile), each side's parts one thread's queue, a
part waiting only for the other side's last part that moved one of its bodies (where the
worker's cost model runs the sweeps paired; else one part a wave, as on one thread); the
per-contact passes of the step are shared too. Detection shares a step's stages
between the two threads too (``src/detection.h``: the bodies' motion and boxes, the broad
phase's fat pairs by halves; the pairs, a first part here, the rest on the worker, each into
its own lane, joined in pair order). Shock propagation sweeps its blocks
the same way, one level of lower bodies at a time (one thread).
The laws: the waves hold (no movable body twice in a wave, each body's manifolds in the
solve's order, wide groups of one row count, every manifold of up to four rows sharing one
frame in one but the one left of a row count, fewer manifolds left over than waves as early
as possible would leave), and each part waits for the other side's part that last moved one of its
bodies; whatever the thread count and with wide rows on or off, every step's corrected
states and impulses are the same bytes, and so is every array detection gives. Here a pile
of cubes and spheres falls into a bin and settles (impacts, stacking, friction, rolling
resistance), with a low ``parallel_wave`` so that most steps cut their waves in two sides.
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.detection import Detection
from collres_ros.core.types import (COMPOUND, TRIANGLE_MESH, BodySpec, BodyStates,
                                    CollisionFilter, ContactKind, ContactSet, pair_manifolds,
                                    Piece)
from collres_ros.core.world import World
from collres_ros.ros.integrator import euler_step

from contacts import box, FixedContacts  # noqa: I100

DT = 1.0 / 120.0
GRAVITY = np.array([0.0, 0.0, -9.81])
STEPS = 90


def pile(count: int = 48) -> tuple[list[BodySpec], BodyStates]:
    """A floor and four walls, then ``count`` cubes and spheres (0.1 m) on a jittered grid."""
    half = 0.25
    bodies = [BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True),
              BodySpec('wall_x0', 'plane', (1.0, 0.0, 0.0, -half), static=True),
              BodySpec('wall_x1', 'plane', (-1.0, 0.0, 0.0, -half), static=True),
              BodySpec('wall_y0', 'plane', (0.0, 1.0, 0.0, -half), static=True),
              BodySpec('wall_y1', 'plane', (0.0, -1.0, 0.0, -half), static=True)]
    rng = np.random.default_rng(3)
    positions = [np.zeros(3)] * len(bodies)
    for i in range(count):
        layer, cell = divmod(i, 16)
        row, col = divmod(cell, 4)
        if i % 2:
            bodies.append(BodySpec(f'box{i}', 'box', (0.1,) * 3, mass=1.0, restitution=0.2,
                                   static_friction=0.6, kinetic_friction=0.4,
                                   rolling_resistance=0.05))
        else:
            bodies.append(BodySpec(f'ball{i}', 'sphere', (0.05,), mass=0.5, restitution=0.2,
                                   static_friction=0.6, kinetic_friction=0.4,
                                   rolling_resistance=0.05, torsional_friction=0.05))
        positions.append(np.array([-0.18 + 0.12 * col, -0.18 + 0.12 * row, 0.06 + 0.12 * layer])
                         + rng.uniform(-0.01, 0.01, 3))
    state = BodyStates.zeros(len(bodies))
    state.position[:] = positions
    angles = rng.uniform(-0.3, 0.3, (len(bodies), 3))
    angles[:5] = 0.0
    size = np.linalg.norm(angles, axis=1, keepdims=True)
    axis = angles / np.maximum(size, 1e-12)
    state.orientation[:] = np.concatenate((axis * np.sin(size / 2), np.cos(size / 2)), 1)
    return bodies, state


def world(bodies: list[BodySpec], threads: int, wide_rows: bool = True) -> World:
    w = World(bodies, SolverSettings(sleeping=False))
    w._params.threads = threads
    w._params.parallel_wave = 2
    w._params.wide_rows = wide_rows
    return w


def answer(result) -> bytes:
    return b''.join(np.ascontiguousarray(a, '<f8').tobytes() for a in (
        result.states.position, result.states.orientation, result.states.linear,
        result.states.angular, result.report.normal_impulse, result.report.friction_impulse))


def test_two_threads_and_one_by_one_give_the_bytes_of_one_thread_in_lanes():
    bodies, start = pile()
    worlds = [world(bodies, 1), world(bodies, 2), world(bodies, 2), world(bodies, 1, False),
              world(bodies, 2, False)]
    states = [start.copy() for _ in worlds]
    shared_steps = 0
    for _ in range(STEPS):
        answers = []
        for k, w in enumerate(worlds):
            result = w.step(states[k], euler_step(states[k], w.dynamic, GRAVITY, DT), DT)
            states[k] = result.states
            answers.append(answer(result))
        assert all(a == answers[0] for a in answers[1:])
        shared_steps += any(part[4] == 1 for part in worlds[1]._solver.waves)
    # some steps had their waves cut in two sides: a sweep is cut for two threads where the
    # worker's cost model runs the sweeps paired (its first run of a kind, then as measured:
    # a pile this small may cost less alone, and the paired runs are then its bursts)
    assert shared_steps > 0
    assert np.isfinite(states[0].position).all()
    assert states[0].position[5:, 2].max() < 0.6          # it fell and piled up


def test_the_second_threads_part_is_counted_and_one_thread_posts_no_run():
    """``World.thread_runs`` (the node's /diagnostics ``threads.*``): at threads 2 every step
    posts its detect (64 shapes or more) for two threads and the cost model runs a kind's
    first run paired (no mode measured yet); the second thread runs no more chunks than
    were posted; at threads 1 no run is posted for two threads."""
    bodies, start = pile(64)
    one, two = world(bodies, 1), world(bodies, 2)
    states = [start.copy(), start.copy()]
    for _ in range(10):
        for k, w in enumerate((one, two)):
            states[k] = w.step(states[k], euler_step(states[k], w.dynamic, GRAVITY, DT),
                               DT).states
    assert (one.threads, two.threads) == (1, 2)
    assert one.thread_runs == (0, 0, 0, 0)
    runs, paired, chunks, helped = two.thread_runs
    assert runs >= 10 and 1 <= paired <= runs and 0 <= helped <= chunks


def test_shock_propagation_in_lanes_gives_the_bytes_of_one_by_one():
    # eight 20 kg boxes each on a 1 kg box on the floor: shock propagation holds each light
    # box under its heavy one (its rows one by one, the light box movable) and solves the
    # floor's manifolds as blocks, each level's blocks in waves, four at a time in lanes
    # (wide rows) or one by one; the same bytes, on one thread or two
    bodies = [BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True)]
    rng = np.random.default_rng(5)
    positions = [np.zeros(3)]
    for i in range(8):
        for name, mass, z in (('light', 1.0, 0.05), ('heavy', 20.0, 0.15 + 0.02 * (i % 3))):
            bodies.append(BodySpec(f'{name}{i}', 'box', (0.1,) * 3, mass=mass,
                                   static_friction=0.6, kinetic_friction=0.4))
            positions.append(np.array([0.3 * i + (rng.uniform(-0.02, 0.02) if mass > 1.0
                                                  else 0.0), 0.0, z]))
    start = BodyStates.zeros(len(bodies))
    start.position[:] = positions
    worlds = [world(bodies, 1), world(bodies, 1, False), world(bodies, 2), world(bodies, 1)]
    worlds[-1]._params.shock_sweeps = 0
    states = [start.copy() for _ in worlds]
    differs = 0
    for _ in range(60):
        answers = []
        for k, w in enumerate(worlds):
            result = w.step(states[k], euler_step(states[k], w.dynamic, GRAVITY, DT), DT)
            states[k] = result.states
            answers.append(answer(result))
        assert answers[1] == answers[0] and answers[2] == answers[0]
        differs += answers[3] != answers[0]
    assert differs == 60   # (shock propagation acted at every step)
    assert np.all(np.abs(states[0].position[1::2, 2] - 0.05) < 1e-3)   # the light boxes held


def test_a_sweep_with_waves_too_small_to_share_is_not_handed_over():
    # the default parallel_wave: this pile's waves average fewer than twice as many manifolds,
    # so they are not cut in sides and each sweep runs on the caller, not posted (a hand-over
    # that buys nothing); what the threads share is the per-contact passes, kParts (8) parts
    # each: seven a step (the reference frame's bodies before and after its contacts, contacts,
    # impacts, allowances, the report's contacts and manifolds), seven per solve (prepare's
    # rows counted, written and framed, the warm start, the first admission, the net's bodies
    # and contacts without a row) and four per substep of a solve at most (the rows' allowances
    # and the bodies' travel, the bodies' share of the external change and the rows' sums
    # between substeps); a pass over fewer than kParts parallel_wave items runs on the caller;
    # and, one chunk each in a step of at least kParts parallel_wave contacts, the cache's
    # lookup beside each solve's impact stages (done in the first) and the rows' copies for
    # shock propagation beside its warm start, and the cache's store beside the push-out; the
    # same bytes
    bodies, start = pile()
    one, two = (World(bodies, SolverSettings(sleeping=False)) for _ in range(2))
    one._params.threads, two._params.threads = 1, 2
    states = [start.copy(), start.copy()]
    beside = 0   # chunks run beside a stage (a step's store; a solve's lookup and copies)
    for _ in range(STEPS):
        redone = two._solver.redone
        answers = []
        for k, w in enumerate((one, two)):
            result = w.step(states[k], euler_step(states[k], w.dynamic, GRAVITY, DT), DT)
            states[k] = result.states
            answers.append(answer(result))
        assert answers[0] == answers[1]
        if result.report.contacts.count >= 8 * two._params.parallel_wave:
            beside += 3 + 2 * (two._solver.redone - redone)
        waves = two._solver.waves
        assert all(part[4] == 0 for part in waves)
        assert not waves or waves[-1][3] < 2 * two._params.parallel_wave * len(waves)
    posted = two._solver.helped[1] - beside
    solves = STEPS + two._solver.redone
    assert 0 < posted <= 8 * (7 * STEPS + (7 + 4 * two._params.max_substeps) * solves)
    assert posted % 8 == 0
    assert one._solver.helped[1] == 0


@pytest.mark.parametrize('threads', [1, 2])
def test_no_two_manifolds_of_a_wave_share_a_movable_body_and_each_follows_its_bodies(threads):
    bodies, state = pile()
    w = world(bodies, threads)
    movable = w.dynamic
    total = wide = lanes = split = whole_total = whole_wide = 0
    for _ in range(STEPS):
        state = w.step(state, euler_step(state, w.dynamic, GRAVITY, DT), DT).states
        waves = w._solver.waves
        sweep = w._solver.sweep_bodies
        assert [s[0] for s in waves[1:]] == [s[3] for s in waves[:-1]]    # in a row
        assert (waves[-1][3] if waves else 0) == len(sweep)                # all of them
        # the sweep's order: with two sides, side 0's manifolds, side 1's, then the seam's
        # (parts after all the others'), each in the solve's order (their first rows)
        seams = [part[7] for part in waves]
        assert seams == sorted(seams)
        own = [set(), set()]    # each side's bodies (but the seam's)
        order = {}       # per movable body: (class, first row) of its last manifold so far
        sided = any(part[4] == 1 for part in waves)   # (two threads, the sweeps paired)
        for first, wide_end, lone, end, side, _, _, seam in waves:
            assert first < wide_end or wide_end < end              # never empty
            assert first <= wide_end <= lone <= end and (wide_end - first) % 4 == 0
            counts = sweep[first:wide_end, 2].reshape(-1, 4)
            assert (counts == counts[:, :1]).all()     # a wide group: one row count
            # the two or three left of a row count 1 to 4: one padded group each, in order
            # of row count; one left, or more than four rows: one by one after them
            rest = sweep[wide_end:lone, 2]
            assert (np.diff(rest) >= 0).all() and (rest >= 1).all() and (rest <= 4).all()
            assert np.isin(np.bincount(rest, minlength=5), (0, 2, 3)).all()
            alone = sweep[lone:end, 2]
            assert np.isin(np.bincount(alone[alone <= 4], minlength=5), (0, 1)).all()
            pairs = sweep[first:end, :2]
            used = pairs[movable[pairs]]
            assert len(np.unique(used)) == len(used)   # none twice in a part
            # each movable body's manifolds in the sweep's order
            for pair, row in zip(pairs.tolist(), sweep[first:end, 3].tolist()):
                for b in pair:
                    if movable[b]:
                        key = (2 if seam else side, row)
                        assert order.get(b, (-1, -1)) < key
                        order[b] = key
            if seam:    # the seam joins two movable bodies, on side 1 (cut for one thread: 0)
                assert side == sided and movable[pairs].all()
            else:
                own[side].update(used.tolist())
            wide += wide_end - first
            lanes += lone - first
            total += end - first
        assert not own[0] & own[1]      # the two sides share no movable body
        # the sweep: the rows of the parts before the seam's, their spin rows (every
        # manifold of this pile has one), then the seam's rows and spin rows (part i's rows
        # numbered i, its spin rows size + i); each waits for the other side's part last
        # in that order to move one of its bodies
        size = len(waves)
        seam = seams.index(True) if True in seams else size
        last = {}        # per movable body: the last part that moved it
        place = {}       # per part: its place in the sweep
        for at, q in enumerate([*range(seam), *range(size, size + seam), *range(seam, size),
                                *range(size + seam, 2 * size)]):
            first, _, _, end, side, after, spin_after, _ = waves[q % size]
            pairs = sweep[first:end, :2]
            used = pairs[movable[pairs]].tolist()
            other = [last[b] for b in used if b in last and waves[last[b] % size][4] != side]
            assert (after if q < size else spin_after) == max(other, key=place.get, default=-1)
            last.update((b, q) for b in used)
            place[q] = at
        # cut in sides, each holds a fair share of the rows: halves by rows; cut for one
        # thread a wave's two sides are one part (side 0), the cut seen in the seam's waves
        rows = [sum(int(sweep[p[0]:p[3], 2].sum()) for p in waves if p[4] == k and not p[7])
                for k in (0, 1)]
        if rows[1]:
            split += 1
            assert min(rows) > 0.3 * int(sweep[:, 2].sum())
        else:
            split += any(seams)
            whole_total += sum(p[3] - p[0] for p in waves)
            whole_wide += sum(p[1] - p[0] for p in waves)
    assert total > 0 and lanes > wide   # some manifolds solved in padded groups
    if whole_total:                     # and, uncut, most in full ones (not a pile cut in
        assert whole_wide > whole_total // 2   # sides of a few manifolds a part)
    assert split > STEPS // 2   # cut in sides, whatever the threads (the order is theirs)


def part_filled(parts) -> int:
    """Per part (its manifolds' row counts), per row count 1 to 4 whose manifolds are not a
    multiple of four: one padded group or one manifold solved one by one; their sum."""
    return sum(int(np.count_nonzero(np.bincount(k[k <= 4], minlength=5) % 4)) for k in parts)


def left_over(waves: list[tuple], sweep: np.ndarray, movable: np.ndarray) -> tuple[int, int]:
    """part_filled() of the waves, and of the waves as early as possible for the same
    manifolds in the sweep's order (each part's side kept; the seam's waves after all the
    others'): (as solved, as early as possible)."""
    side = np.zeros(len(sweep), int)
    seam = np.zeros(len(sweep), bool)
    for first, _, _, end, s, _, _, joins in waves:
        side[first:end] = s
        seam[first:end] = joins
    solved = part_filled(sweep[w[0]:w[3], 2] for w in waves)
    wave = {}        # per movable body: the last wave (as early as possible) that moved it
    early = {}       # (wave, side) -> row counts
    least = 0        # the seam's first wave
    order = np.lexsort((sweep[:, 3], np.where(seam, 2, side)))   # the sweep's order
    for i in order:
        a, b, rows, _ = sweep[i].tolist()
        if seam[i] and not least:
            least = 1 + max(wave.values(), default=-1)
        own = max(least, 1 + max(wave.get(a, -1) if movable[a] else -1,
                                 wave.get(b, -1) if movable[b] else -1))
        for body in (a, b):
            if movable[body]:
                wave[body] = own
        early.setdefault((own, side[i]), []).append(rows)
    return solved, part_filled(np.array(k) for k in early.values())


@pytest.mark.parametrize('threads', [1, 2])
def test_a_waves_leftovers_fill_the_next_waves_groups(threads):
    # the manifolds a wave's wide groups leave over (fewer than four of a row count and a
    # side: a padded group, or one solved one by one) move to the next wave when they all
    # may: never more left over than with every manifold in its earliest wave, and fewer
    # in most steps of the pile settling
    bodies, state = pile()
    w = world(bodies, threads)
    fewer = steps = 0
    for _ in range(STEPS):
        state = w.step(state, euler_step(state, w.dynamic, GRAVITY, DT), DT).states
        if not w._solver.waves:
            continue
        solved, early = left_over(w._solver.waves, w._solver.sweep_bodies, w.dynamic)
        assert solved <= early
        fewer += solved < early
        steps += 1
    assert fewer > steps // 2


def assert_same_contacts(a, b) -> None:
    """Two detections' ContactSets hold the same bytes, field by field."""
    for name in ('body_a', 'body_b', 'point', 'normal', 'separation', 'toi', 'kind', 'feature',
                 'manifolds', 'piece_a', 'piece_b'):
        assert np.ascontiguousarray(getattr(a, name)).tobytes() == \
            np.ascontiguousarray(getattr(b, name)).tobytes(), name


@pytest.mark.parametrize('filtered', [False, True])
def test_detection_on_two_threads_gives_the_bytes_of_one_thread(filtered):
    # the pile falling (impacts, times of impact, speculative corners), then settling
    # (stored points reused): two detectors, one and two threads, on the same steps; with a
    # filter, the spheres and the walls pass through each other and some neighbours are
    # ignored (pairs dropped in either thread's part of the broad phase)
    bodies, state = pile(96)
    w = world(bodies, 1)
    settings = SolverSettings(sleeping=False)
    one, two = Detection(bodies, settings), Detection(bodies, settings)
    if filtered:
        sphere = [b.shape == 'sphere' for b in bodies]
        group = tuple(2 if s else 1 for s in sphere)
        mask = tuple(1 if 1 <= k <= 4 else 3 for k in range(len(bodies)))   # walls: no spheres
        ignored = tuple((k, k + 1) for k in range(5, len(bodies) - 1, 3))
        for d in (one, two):
            d.collision_filter = CollisionFilter(group, mask, ignored)
        assert any(sphere)
    kinds = set()
    for _ in range(STEPS):
        current = euler_step(state, w.dynamic, GRAVITY, DT)
        a = one.detect(state, current, None, 1)
        b = two.detect(state, current, None, 2)
        assert_same_contacts(a, b)
        if filtered:   # no sphere touches a wall, no ignored pair touches
            pairs = set(zip(a.body_a.tolist(), a.body_b.tolist()))
            assert not any(sphere[j] and 1 <= i <= 4 for i, j in pairs)
            assert not pairs & set(ignored)
        kinds.update(np.unique(a.kind).tolist())
        state = w.step(state, current, DT).states
    assert len(kinds) >= 2                       # impacts and persistent contacts met
    assert two._native.helped[1] >= STEPS        # every step split its pairs in two
    assert one._native.helped[1] == 0


def test_detection_of_compounds_and_a_mesh_on_two_threads_gives_the_bytes_of_one_thread():
    # compound bodies (the pieces of a body share its motion: each thread prepares whole
    # bodies) on a floor of two triangles (a mesh's pairs join the other pairs after both
    # threads' halves of the broad phase)
    bodies, state = pile(96)
    half = 0.25
    bodies[0] = BodySpec('floor', TRIANGLE_MESH, static=True,
                         points=((-half, -half, 0.0), (half, -half, 0.0), (half, half, 0.0),
                                 (-half, -half, 0.0), (half, half, 0.0), (-half, half, 0.0)))
    for k in range(6, len(bodies), 4):
        bodies[k] = BodySpec(bodies[k].name, COMPOUND, mass=1.0, pieces=(
            Piece('left', 'box', (0.05, 0.1, 0.1), position=(-0.025, 0.0, 0.0)),
            Piece('right', 'box', (0.05, 0.1, 0.1), position=(0.025, 0.0, 0.0))))
    w = world(bodies, 1)
    settings = SolverSettings(sleeping=False)
    one, two = Detection(bodies, settings), Detection(bodies, settings)
    on_floor = compounds = 0
    for _ in range(STEPS):
        current = euler_step(state, w.dynamic, GRAVITY, DT)
        a = one.detect(state, current, None, 1)
        b = two.detect(state, current, None, 2)
        assert_same_contacts(a, b)
        on_floor += int(np.count_nonzero(a.body_a == 0))
        compounds += int(np.count_nonzero((a.piece_a > 0) | (a.piece_b > 0)))
        state = w.step(state, current, DT).states
    assert on_floor > 0 and compounds > 0        # the mesh and the pieces met
    assert two._native.helped[1] >= STEPS


def test_a_manifold_whose_points_have_two_frames_is_solved_one_by_one_with_the_same_bytes():
    # five boxes resting on the floor on four points each, hand-made: one box's points carry
    # two normals (two of them tilted by 1e-3 rad), so its rows share no frame (n, t1, t2)
    # and no wide group takes it (a group keeps one frame a lane): solved one by one after
    # the group of the other four; with wide rows on or off, on one thread or two, the same
    # bytes
    size = 0.1
    bodies = [BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True)]
    bodies += [box(f'box{i}', (size,) * 3, 1.0, mu_s=0.6, mu_k=0.4) for i in range(5)]
    start = BodyStates.zeros(len(bodies))
    points, normals = [], []
    for i in range(5):
        start.position[i + 1] = (0.3 * i, 0.0, 0.5 * size - 0.001)
        for k, (x, y) in enumerate(((-1, -1), (1, -1), (1, 1), (-1, 1))):
            points.append((0.3 * i + 0.5 * size * x, 0.5 * size * y, -0.0005))
            tilt = 1e-3 if i == 2 and k >= 2 else 0.0
            normals.append((np.sin(tilt), 0.0, np.cos(tilt)))
    count = len(points)
    body_a = np.zeros(count, np.int64)
    body_b = np.repeat(np.arange(1, 6, dtype=np.int64), 4)
    contacts = ContactSet(body_a, body_b, np.array(points), np.array(normals),
                          np.full(count, -0.001), np.zeros(count),
                          np.full(count, int(ContactKind.PERSISTENT), np.int8),
                          np.arange(count, dtype=np.int64), pair_manifolds(body_a, body_b))
    answers = []
    for threads, wide in ((1, True), (2, True), (1, False)):
        w = World(bodies, SolverSettings(sleeping=False), FixedContacts(contacts))
        w._params.threads = threads
        w._params.wide_rows = wide
        state = start.copy()
        steps = []
        for _ in range(5):
            result = w.step(state, euler_step(state, w.dynamic, GRAVITY, DT), DT)
            state = result.states
            steps.append(answer(result))
            ((first, wide_end, lone, end, *_),) = w._solver.waves
            assert (wide_end - first, end - lone) == (4, 1)
            assert w._solver.sweep_bodies[lone, 1] == 3   # the box of two frames
        assert result.report.normal_impulse.min() > 0.0
        answers.append(steps)
    assert answers[1] == answers[0] and answers[2] == answers[0]
