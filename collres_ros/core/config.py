"""The single source of truth for every parameter: default, unit, range, why.

The ROS parameter descriptors of ``collres_node``/``collres_sim`` and the
README's parameter table are generated from (or checked against) these
tables by tests. No ROS import here.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any, Optional, Sequence


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: name (dotted below its namespace), type, default, range, docs."""

    name: str
    # 'double' | 'integer' | 'bool' | 'string' | 'double_array' | 'string_array'
    type: str
    default: Any
    description: str
    minimum: Optional[float] = None  # inclusive, numbers only
    maximum: Optional[float] = None  # inclusive
    choices: tuple[str, ...] = ()    # allowed strings (empty: any)
    unit: str = ''
    reason: str = ''                 # why this default


RESTITUTION_RULES = ('average', 'min', 'max', 'multiply', 'per_object')
FRICTION_RULES = ('geometric', 'average', 'min', 'max', 'multiply')

# Solver settings: the `solver.*` parameters of collres_node.
SOLVER_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec('toi_tolerance', 'double', 1e-4,
              'Bisection stops when the time-of-impact interval is below this fraction of dt',
              1e-9, 0.5, unit='fraction of dt',
              reason='1e-4 of a 4 ms step is 0.4 us: far below any visible error'),
    ParamSpec('toi_max_iterations', 'integer', 30,
              'Cap on bisection / conservative-advancement iterations per pair', 1, 200,
              reason='2^-30 of dt is below double resolution of a step'),
    ParamSpec('velocity_iterations', 'integer', 10,
              'Sequential-impulse sweeps in each substep of the resting solve (max_substep; '
              'more while resting contacts are new, and at least SOLVER_TUNING depth_sweeps '
              'per level of the deepest stack)', 1, 1000,
              reason='Box2D and Jolt default to 8-10 with warm starting; each substep is '
                     'warm started from the last one, yet needs its own: at 5 the 1000:1 '
                     'stack moved 40 mm in 10 s at 30 Hz; a step\'s sweeps shared by its '
                     'substeps (ceil(10 / S) each) moved towers of 20 28 mm at 30 Hz and '
                     'toppled them at 60 Hz, and sank the 1000:1 stack 0.38 m at 30 Hz; the '
                     'first substep at the full count and 7 in each later one (more while '
                     'contacts are new) let a dropped column of 8 cubes '
                     '(bench_laws column, 20 layouts) overlap up to 2.7 mm at 30 Hz and '
                     '19.5 mm at 60 Hz, against 1.9 and 1.1 mm'),
    ParamSpec('restitution_threshold', 'double', 0.5,
              'Approach speed below which a contact is RESTING and does not bounce, where the '
              'step\'s external change acts on one of its two bodies (a load, as gravity; '
              'between free bodies every approach bounces); so is one slower than 1.5 times '
              'the approach that change alone brought it (g dt on a floor: above 0.5 m/s '
              'below 30 Hz)',
              0.0, 100.0, unit='m/s',
              reason='below a visible bounce (Box2D: 1 m/s); a resting body is kept from '
                     'bouncing on its g dt by the rule\'s second part at any value. Applied '
                     'to free bodies too, it made an elastic gas inelastic below it (97.7-98.4 '
                     '% of the energy left after 5 s at 30-240 Hz; 100.00 % with it on loaded '
                     'pairs only) and stopped a ball drifting into a wall in space; 0.05 '
                     'everywhere kept the gas but let a column of cubes dropped apart '
                     '(bench_laws column, 20 layouts) overlap up to 6.2 mm at 30 Hz and 3.6 '
                     'mm at 240 Hz (0.5: 1.9 and 0.7 mm); on pairs pressed together along '
                     'their normal only, cubes side by side in a pile rattled between their '
                     'neighbours (100 cubes at 120 Hz, seed 1: 0.087 m/s after 2 s)'),
    ParamSpec('sticking_speed', 'double', 0.01,
              'Tangential speed below which static friction may hold a contact (STICKING)',
              0.0, 100.0, unit='m/s', reason='1 cm/s: slower is perceived as at rest'),
    ParamSpec('linear_slop', 'double', 0.0001,
              'Penetration allowed without position correction', 0.0, 1.0, unit='m',
              reason='0.1 mm: resting contacts stay still (no jitter) while a body sliding '
                     'over a curved surface, or a stack, does not settle into it'),
    ParamSpec('position_correction', 'double', 0.4,
              'Fraction of the penetration beyond the slop removed per step (no velocity added)',
              0.0, 1.0, reason='split impulses move poses only, so 0.4 per step recovers '
                               'overlap in a few steps without energy gain or popping; at 0.5 '
                               'the push-out kept columns of cubes swaying, below 0.35 a ball '
                               'pushed over a dome sinks beyond 0.2 mm'),
    ParamSpec('max_correction', 'double', 0.2,
              'Largest position correction per step', 0.0, 10.0, unit='m',
              reason='bounds the push-out of a deep overlap (Box2D: 0.2 m)'),
    ParamSpec('speculative_margin', 'double', 0.02,
              'Pairs closer than this are in contact: a pair\'s own margin is a quarter of it '
              '(or more at a long step) while neither body moves, grown by how far each moves '
              'over the step',
              0.0, 10.0, unit='m',
              reason='keeps resting and stacked contacts alive between steps'),
    ParamSpec('restitution_rule', 'string', 'max',
              'How two bodies\' restitution combine', choices=RESTITUTION_RULES,
              reason='one e per contact conserves momentum; max (Box2D) lets a bouncy ball '
                     'bounce on a dead floor'),
    ParamSpec('friction_rule', 'string', 'geometric',
              'How two bodies\' friction coefficients combine', choices=FRICTION_RULES,
              reason='geometric mean as Box2D and Jolt: two equal coefficients give that value'),
    ParamSpec('warm_start', 'bool', True,
              'Start each contact from the impulses of the same pair and feature last step',
              reason='stacks converge in few iterations'),
    ParamSpec('ccd', 'bool', True,
              'Sweep test (conservative advancement) for pairs separated at both ends of a step',
              reason='catches tunnelling of fast thin bodies'),
    ParamSpec('max_dt', 'double', 0.5,
              'A step longer than this is treated as a fresh start (no sweep, no warm start)',
              1e-6, 3600.0, unit='s',
              reason='after a pause the interpolated motion is meaningless'),
    ParamSpec('max_substep', 'double', 0.0067,
              'The resting solve of a step runs in ceil(dt / max_substep) substeps (at most '
              'SOLVER_TUNING max_substeps) after one detection: each adds its share of the '
              'external change (gravity), lets each contact close by its separation as the '
              'substeps so far moved its bodies, and moves the poses', 1e-4, 1.0, unit='s',
              reason='one solve per 30 Hz step does not converge a deep stack (a column of 7 '
                     'cubes toppled, towers of 20 fell); substeps of 6.7 ms hold towers of '
                     '20 cubes within 2 mm at 30, 60 and 120 Hz (1/120 s: 5.2 mm at 60 Hz); '
                     '240 Hz is one substep, 120 Hz two, 30 Hz five, and each substep costs '
                     'the sweeps of a step (velocity_iterations): a settled pile of 1000 '
                     'cubes sweeps 5 x 11 times in a 30 Hz step, 117.5M instructions '
                     '(callgrind), against 2 x 11 and 59.4M at 120 Hz'),
    ParamSpec('max_pairs', 'integer', 20000,
              'Budget of pairs queried per step (broad-phase pairs whose bounding spheres come '
              'within reach); beyond it the pairs whose spheres overlap deepest are kept '
              '(counted: contact_budget)', 1, 10_000_000,
              reason='bounds a step\'s time and memory whatever the poses (MuJoCo nconmax): '
                     '2000 boxes at one point take 0.5 s; a falling 1000-body pile needs 8500'),
    ParamSpec('max_contacts', 'integer', 40000,
              'Budget of contact rows per step; beyond it the deepest are kept '
              '(counted: contact_budget)', 1, 10_000_000,
              reason='bounds the solver\'s work (PhysX contact buffer); a 1000-cube pile has '
                     '16000'),
    ParamSpec('max_contacts_per_pair', 'integer', 8,
              'Contact rows kept per pair of bodies, the deepest (a pair of compound bodies '
              'has up to 4 per pair of pieces)', 1, 1000,
              reason='two flat feet of a compound keep 4 points each; more points add '
                     'solver work, not support (Gazebo caps a pair with max_contacts)'),
    ParamSpec('sleeping', 'bool', True,
              'Islands of bodies at rest for time_to_sleep sleep: answered with their held '
              'pose and zero twist, without detection or solve, until a push, a touch, a '
              'change or a clock jump wakes them (BodyState.sleeping flags them)',
              reason='a settled pile then costs almost nothing (Box2D v3 and Jolt sleep by '
                     'default; MuJoCo 4 leaves it off)'),
    ParamSpec('sleep_threshold', 'double', 0.05,
              'A body is still while the speed of its farthest point (linear + angular speed '
              'times its bounding radius) stays below this; an input that departs from the '
              'held state by more wakes its island',
              0.0, 10.0, unit='m/s',
              reason='Box2D v3\'s b2_sleepThreshold (0.05 m/s); Jolt uses 0.03 m/s'),
    ParamSpec('time_to_sleep', 'double', 0.5,
              'How long every body of an island must stay still before the island sleeps',
              0.0, 3600.0, unit='s',
              reason='Box2D\'s b2_timeToSleep and Jolt\'s mTimeBeforeSleep (0.5 s)'),
)


@dataclass(frozen=True)
class SolverSettings:
    """Solver settings; see SOLVER_PARAMS for units, ranges and reasons."""

    toi_tolerance: float = 1e-4
    toi_max_iterations: int = 30
    velocity_iterations: int = 10
    restitution_threshold: float = 0.5
    sticking_speed: float = 0.01
    linear_slop: float = 0.0001
    position_correction: float = 0.4
    max_correction: float = 0.2
    speculative_margin: float = 0.02
    restitution_rule: str = 'max'
    friction_rule: str = 'geometric'
    warm_start: bool = True
    ccd: bool = True
    max_dt: float = 0.5
    max_substep: float = 0.0067
    max_pairs: int = 20000
    max_contacts: int = 40000
    max_contacts_per_pair: int = 8
    sleeping: bool = True
    sleep_threshold: float = 0.05
    time_to_sleep: float = 0.5

    def with_values(self, **values: Any) -> 'SolverSettings':
        """Copy with some fields changed, each validated (ValueError names the field)."""
        for name, value in values.items():
            check_value(_SOLVER_BY_NAME[name], value)
        return replace(self, **values)


_SOLVER_BY_NAME = {p.name: p for p in SOLVER_PARAMS}

# Tunings of the compiled solver that are not parameters: each handed to
# ``_native.SolverParams`` by its name (``world.solver_params``).
SOLVER_TUNING: tuple[ParamSpec, ...] = (
    ParamSpec('warm_start_ratio', 'double', 10.0,
              'Last step\'s impulses are scaled by the step\'s growth (the load m |dv| its '
              'external change dv gives the bodies in contact over theirs last step; dt / '
              'last dt without a load) and warm start a contact only while that lies in '
              '[1 / this, this] (and the last step was not fresh); otherwise the step starts '
              'cold', 1.0, 1e3,
              reason='a resting contact carries its load, so a step of up to 10 periods of '
                     'load (a node that fell behind dropped inputs) starts from the answer (a '
                     'cold pile under 8 periods of load slid 5 mm into its floor), and a step '
                     'of k periods whose source integrated one period (it integrates each '
                     'answer it gets) starts from 1 times, not k times, the impulses (k times '
                     'kept a pile of 100 cubes awake for good); '
                     'a 1 ns step or a 1 ms fresh step before a 30 Hz one would launch a '
                     'resting body'),
    ParamSpec('match_radius', 'double', 0.02,
              'A contact whose feature id changed (a rolling sphere) warm starts from the '
              'nearest stored point of its pair within this distance', 0.0, 1.0, unit='m',
              reason='a 0.1 m ball rolling at 2 m/s moves 8 mm a 240 Hz step: its point is '
                     'found again; points of another corner of a box are farther'),
    ParamSpec('reuse_shift', 'double', 0.02,
              'A stored manifold (a pair of flat-faced bodies in contact) is reused, its gaps '
              'measured again without a query, while the pair has shifted relative to each '
              'other along its contact plane, since the query that found it, by less than '
              'this fraction of the thinner body\'s smallest half extent (and turned by less '
              'than 10 mrad): its points are then about that far from where a fresh query '
              'finds them (a shift along the normal moves no point along either face)',
              0.0, 1.0, unit='fraction of a half extent',
              reason='1 mm for the 0.1 m bodies of the bench piles (a fixed 1 mm before: the '
                     'same answers there), which a 1 cm cube shifted 0.6 mm in two steps '
                     'kept, 0.3 mm (6 % of its half extent) from a fresh query\'s points. '
                     'Looser does not pay: a settled pile of 1000 cubes at 30 Hz spends '
                     '4.7M of its 135M instructions a step (callgrind) in the narrow phase; '
                     'a bound on each point\'s drift instead (shift plus turn times lever) '
                     'of 4 % of the half extent (2 mm) saved 2.1M of them but let settled '
                     '100-body piles rest up to 0.63 mm deep at 120 Hz (3 %: 0.40 mm, 2 %: '
                     '0.49 mm; this rule 0.14-0.19 mm, seeds 1-4, both kinds): a manifold '
                     'kept while its box rocks a few mrad misses the corner that went '
                     'deepest. Only the shift along the contact plane counts: in the settled '
                     'pile of 1000 cubes at 30 Hz its box pairs move 0.02 / 0.23 mm (median / '
                     '90th percentile) a step along their normals (the push-out rocking a box '
                     'up and back) and 0.04 / 0.27 mm along their faces (at 120 Hz 0.006 / '
                     '0.07 and 0.012 / 0.08 mm); the whole shift had 397 pairs a step queried '
                     'again over 24 steps, the shift along the faces 301, and the 100-body '
                     'piles rest as deep (seeds 1-2, both kinds: 0.15-0.19 mm at 120 Hz, '
                     '1.01-1.06 mm at 30 Hz; 0.14-0.19 and 0.94-1.05 before)'),
    ParamSpec('margin_speed', 'double', 1.2,
              'A pair of bodies that do not move over the step keeps as its margin the larger '
              'of a quarter of speculative_margin and this times dt (grown by how far each '
              'body moves, up to speculative_margin)', 0.0, 1e3, unit='m/s',
              reason='a gap a pair at rest closes within the step at this speed keeps a row: '
                     'the whole margin at 60 Hz and below, 10 mm at 120 Hz, the quarter (5 mm) '
                     'at 240 Hz and above. A settled pile of 100 cubes and spheres at 60 Hz, '
                     'seeds 1-10, had its fastest point above 0.05 m/s at 2 s from the drop '
                     'in 1 of 10 seeds with the whole margin, 3 of 10 at 0.6 (10 mm) and with '
                     'the quarter alone, 1 of 10 at 0.9 (15 mm); at 120 Hz 0.9 (7.5 mm) let a '
                     'pour of 100 spheres (test_heap, seed 3) settle at 14.0 deg against '
                     '21-22 deg at 1.2 (seeds 1-3)'),
    ParamSpec('position_iterations', 'integer', 1,
              'Split-impulse sweeps of the position pass', 1, 1000,
              reason='the push-out is a fraction of the penetration per step anyway, and '
                     'one sweep pushes each contact out where it is: 4 sweeps moved and '
                     'tilted whole columns of cubes at once, which kept a cubes pile '
                     'swaying for ever'),
    ParamSpec('fixed_sweeps', 'integer', 4,
              'Push-out sweeps over the rows on an immovable body (a fixed shape or a '
              'sleeper) after the sweeps of every row, and again after deep_sweeps', 0, 1000,
              reason='the sweep of every row pushes a pile\'s lowest bodies out of those '
                     'above and into the floor, and the hold-back let that through by the '
                     'slop a step: at 30 Hz a 200-cube pile rested 4.0 mm into its floor and '
                     'a mixed one 9.1 mm (bench/bench_rest.py, 6 s); with these 0.1 mm'),
    ParamSpec('deep_sweeps', 'integer', 16,
              'Push-out sweeps over the rows between two movable bodies that overlap beyond '
              'the slop by more than deep_overlap, after fixed_sweeps; a row between two '
              'contact levels moves its upper body only', 0, 1000,
              reason='the floor\'s sweeps push the lowest bodies back up into those above: '
                     'alone they left 7.4 mm between the cubes of a 1000-cube pile at 30 Hz '
                     '(1.6 mm with these) and 2.36 mm between the lowest two cubes of a '
                     'dropped column (1.32 mm); sweeps of every row instead (more '
                     'position_iterations) kept a cubes pile rocking, and sharing these '
                     'rows\' push by the masses left the column at 2.26 mm'),
    ParamSpec('deep_overlap', 'double', 1e-3,
              'The overlap beyond the slop from which a row between two movable bodies is '
              'deep (deep_sweeps)', 0.0, 1.0, unit='m',
              reason='at 30 Hz with 1 mm the settled 100 piles (seeds 1, 2 of both kinds) rest '
                     '0.88-1.11 mm deep between bodies, asleep after 1.2-2.1 s, and 1000 piles '
                     '1.04-1.47 mm, 1.5-3.5 s; with 0.2 mm 0.30-0.37 mm (1000 piles '
                     '0.30-0.48 mm, 2.0-4.9 s), but a 200-cube pile fell asleep after 5.4 s '
                     '(1.2 s); with 0.1 mm a 1000-cube pile was awake after 8 s, and '
                     'sweeping every overlapping row (0) kept a 100-cube pile awake: a free '
                     'column of cubes rocks as one (5 mrad), the push-out lifting it every '
                     'step'),
    ParamSpec('support_cosine', 'double', 0.5,
              'A row on an immovable body roots the contact levels (shock propagation, '
              'the push-out\'s hold of the lower body) only where the step\'s external '
              'change of the other body\'s velocity presses it into the immovable one with '
              'at least this cosine to the normal (or it has none)', 0.0, 1.0,
              reason='a wall beside a pile\'s outer columns is no support: as a root it '
                     'made their bodies level 1 at any height, and the push-out pushed the '
                     'body under one down (the settled 100 piles at 30 Hz 1.24-1.98 mm deep '
                     'between bodies); 0.5: a support within 60 degrees of the load'),
    ParamSpec('shock_sweeps', 'integer', 2,
              'Shock-propagation sweeps per level, from the ground up', 0, 1000,
              reason='two sweeps hold a heavy body on a light one in the step'),
    ParamSpec('shock_ratio', 'double', 4.0,
              'Shock propagation (in the impact stages and the resting solve) treats a lower '
              'body as immovable only under a body at least this many times heavier (or on '
              'an immovable one); so does the push-out, which then moves the upper body '
              'only', 1.0, 1e12,
              reason='a 1 kg box under 1000 kg is held in the step (0.04 mm in 10 s), while '
                     'a tower of equal cubes is left to the sweeps: shock propagation '
                     'between equal masses made 20 cubes collapse; a push-out shared by the '
                     'masses drove a 1 kg cube under an overlapping 1000 kg one 10 mm into '
                     'the floor at 30 Hz (0.013 mm when only the heavy one moves)'),
    ParamSpec('depth_sweeps', 'double', 1.5,
              'Least velocity sweeps per level of the deepest stack (contact distance from '
              'an immovable body); more sweeps than velocity_iterations only for deep stacks',
              0.0, 100.0,
              reason='a load passes down a stack one level per sweep: 20 cubes of 5 cm to '
                     '1 m move 1.5 mm in 10 s at 240 Hz (measured before the per-point '
                     'patch depths with 1 sweep per level: 20 cm cubes 2.4 mm, 5 cm cubes '
                     'fell); per substep, not per step: at 1 per level towers of 20 cubes '
                     'of 0.05 and 0.2 m toppled at 240 Hz (one substep), 1 m ones moved 38 '
                     'mm, and 1.5 per level '
                     'shared by the substeps (6 per substep at 30 Hz) moved them 28 mm at '
                     '30 Hz'),
    ParamSpec('converged', 'double', 1e-6,
              'Velocity sweeps stop when no impulse changes by more than this times the '
              'largest normal impulse', 0.0, 1.0,
              reason='a settled tower or heavy stack stops within the sweeps (their rows '
                     'change by less than 1e-6 m/s); a settled pile does not (at the 11th '
                     'sweep of a substep ~78 % of the rows still change by more than this, '
                     'the largest by 6e-4 to 2.4e-2, and 200 sweeps by 5e-4: '
                     'StepSolver::sweep), and skipping '
                     'the manifolds of a pile that changed less than 1e-5 m/s let towers '
                     'of 20 drift 4-12 mm in 10 s (1e-3 m/s: the top cube slid 0.8 mm/s), '
                     'and skipping those that changed less than 3 % of the sweep\'s '
                     'largest change let the 1000:1 stack slide 0.5-1.3 mm: a stop per '
                     'manifold saves nothing the laws allow'),
    ParamSpec('activation_margin', 'double', 0.1,
              'A manifold whose points hold no impulse and separate faster than their '
              'speculative allowance by more than this is left out of the velocity sweeps '
              '(the landing\'s, whose allowances are the step\'s: by this over the '
              'substeps); '
              'after the sweeps every one left out is checked against the solved '
              'velocities, and any they drive beyond its allowance is let in and the sweeps '
              'go on (the answer is the one of every manifold swept)', 0.0, 1e3, unit='m/s',
              reason='it only sets the work, never the answer (a manifold left out that '
                     'the answer reaches is let in and the substep solved again): at 30 Hz '
                     'a settled pile of 1000 cubes sweeps about a third of its rows, and '
                     '0.05 to 0.2 m/s cost the same (0.5: +6 %); below, more substeps are '
                     'solved twice, above, more idle rows are swept; the pour and sleep '
                     'laws (test_heap, test_sleeping) pass at 0.1'),
    ParamSpec('row_bound', 'double', 0.5,
              'A speculative contact separating faster than this times (1 + e) the '
              'fastest approach of the step (before the solve) gets no solver row; at the '
              "step's end every contact without a row is checked against the solved poses "
              '(and, after a landing, velocities), and if one closes beyond its allowance it '
              'gets a row and the step is solved again (every contact without a row ends '
              'the step idle)', 0.0, 1e3,
              reason='the net makes a contact without a row hold, and at 0.5 a settled pile '
                     'of 1000 cubes at 30 Hz prepares 7.3k rows against 16.3k at 2 (127M '
                     'instructions a step against 160M; 148M at 1); the rows also make the '
                     'contact levels and the energy check\'s islands, so the answer moves, '
                     'which chaotic scenes amplify, and it was judged over seeds: the pour of '
                     'test_heap (seeds 1-30) rests within 5.8 s at 0.5 and 4.2 s at 2 (median '
                     '2.4 and 2.6 s), at 17-39 deg against 15-35; the scripted arm and the '
                     'dropped-input piles differ by the seed, not the bound'),
    ParamSpec('cold_extra', 'double', 1.0,
              'Extra velocity sweeps (times velocity_iterations) when every persistent '
              'contact is new (nothing to warm start)', 0.0, 100.0,
              reason='a cold stack needs about twice the sweeps of a warm one'),
    ParamSpec('balanced_friction', 'double', 1e-3,
              'A sticking pair whose net friction is below this fraction of its net normal '
              'impulse is reported RESTING', 0.0, 1.0,
              reason='a box at rest on a flat floor carries equal and opposite corner friction'),
    ParamSpec('impact_stages', 'integer', 64,
              'Most impact stages per step: each resolves the contacts approaching faster '
              'than restitution_threshold at once; the contacts it drives into approach '
              'take part in the next (a chain of touching bodies passes an impact on)',
              1, 10000,
              reason='a row of 60 touching balls passes a hit on in 60 stages; the rest '
                     'of a longer chain is caught inelastically by the resting solve'),
    ParamSpec('impact_sweeps', 'integer', 100,
              'Most sequential-impulse sweeps of one impact stage\'s compression', 1, 10000,
              reason='a stage is solved to convergence (impact_converged) so that its '
                     'restitution is the simultaneous answer; few contacts take part'),
    ParamSpec('threads', 'integer', 2,
              'Threads of detection and of the solve: with 2, the pairs of a step (64 or '
              'more) are shared by two threads, and so is each velocity sweep whose waves '
              'are large enough (parallel_wave: the pile cut in two sides, connected halves '
              'solved side by side, one per thread, then the seam between them), and the '
              'step\'s per-contact passes (reference frame, rows, warm start, first '
              'admission, report); the answer is the same bits with 1 or 2', 1, 2,
              reason='pairs are independent, a wave\'s manifolds share no movable body and '
                     'each contact\'s reference frame is its own, so the second core can '
                     'take part of each; the cost model leaves the worker alone where it does '
                     'not pay: settled piles, the step on one thread over two (30 steps, '
                     'five runs, load 1.3-4.0): 1000 cubes 1.03-1.22 at 120 Hz and 1.10-1.23 '
                     'at '
                     '30 Hz, mixed 0.97-1.07 and 0.92-1.25, piles of 100 0.98-1.00, with a '
                     'busy loop beside them 0.91-0.98 (two sides\' leftovers; the caller '
                     'runs every part the worker has not begun; timings on a machine other '
                     'processes kept busy vary by 5-10 %)'),

    ParamSpec('max_substeps', 'integer', 32,
              'Most substeps of a step\'s resting solve (max_substep)', 1, 64,
              reason='a long step (10 Hz, a fresh start of 0.5 s) costs at most 32 solves; '
                     'the stack bound (stack_sink) asks 15 for towers of 20 cubes of 5 cm '
                     'at 30 Hz with sleeping off (at 8 they fell, 2.69 m in 10 s, at 9 '
                     'drifted 9.6 mm, at 10 stand within 0.65 mm) and 32 for cubes of 1 cm '
                     '(at 10 towers of 1 cm cubes fell at 30 and 60 Hz, of 2 cm at 30 Hz; '
                     'at 32 they stand within 0.10, 0.03 and 0.20 mm in 10 s); settled piles '
                     'keep theirs at 30-240 Hz, '
                     'a dropped pile of 100 at 30 Hz too (a dropped mixed pile of 1000 takes '
                     '503 substeps over 3 s, 2 steps above 10, against 518); at 10 Hz '
                     '(max_substep asks 15) a '
                     'dropped pile of 100 takes 537-565 substeps over 3 s instead of 300'),
    ParamSpec('landing_substeps', 'integer', 5,
              'From this many substeps on, the landing (StepSolver::land) replaces sweeps: the '
              'last substep\'s first sweeps give the poses\' travel, its last landing_sweeps, '
              'the landing rows\' allowance removed, the answer\'s velocities; with fewer, '
              'velocity_iterations sweeps of every row after the substeps', 1, 1000,
              reason='the answer needs the landing\'s own sweeps the more, the larger the '
                     'last substep\'s share of the step: shared at one substep (240 Hz) '
                     'towers of 20 cubes of 0.2 m fell, at two (120 Hz) a pile of 100 cubes '
                     '(bench/pile.py, seed 1) was awake after 6 s and a 1000 kg cube on a '
                     '1 kg one slid 3.6 mm, at three (60 Hz) a column of 8 cubes dropped '
                     'apart (bench_laws column) overlapped 10.6 mm, and at three and four '
                     'piles of 100 fell asleep 0.2-0.3 s later; at five (30 Hz) the tests '
                     'and bench_laws hold and a settled step sweeps 10 times fewer'),
    ParamSpec('landing_sweeps', 'integer', 3,
              'Of the last substep\'s sweeps, the landing\'s (landing_substeps)', 1, 1000,
              reason='at 30 Hz the poses need the substep\'s first sweeps and the landing a '
                     'few: five for the landing left a box dropped on a settled pile 0.20 mm '
                     'deep in it (test_box_on_pile; 0.11 mm with three and with a landing of '
                     'its own); two and three keep the column of 8 cubes within 1.8 and 1.2 '
                     'mm (1.9 mm with a landing of its own)'),
    ParamSpec('later_impact', 'double', 1e-3,
              'A detected impact whose time of impact is later than the earliest of one of '
              'its bodies by more than this fraction of the step, behind it (behind_cosine), '
              'is no impact of the step: speculative from the start, the impact stages take '
              'it only if it still closes after the earlier impact', 0.0, 1.0,
              unit='fraction of dt',
              reason='ten times the time-of-impact bisection\'s tolerance (toi_tolerance): '
                     'impacts closer in time are one simultaneous impact; a striker that '
                     'passed through a cradle\'s first ball within the step also met the '
                     'second and hit both at once (1 cm balls at 1 m/s, 30-60 Hz: the last '
                     'ball left at 0.59-0.89 v0)'),
    ParamSpec('behind_cosine', 'double', 0.7,
              'A later impact of a body lies behind its earliest one (later_impact) where '
              'their normals out of the body are within acos of this', -1.0, 1.0,
              reason='a body reaches what lies behind the body it strikes (a cradle\'s second '
                     'ball: the same normal) only through it, and two strikers that hit a '
                     'ball from 90 deg apart or more meet each other only if that hit leaves '
                     'them approaching, which it does not (their contact 45 deg or less from '
                     'each hit\'s: at 0.9 the three contacts were struck at once, 2 m/s balls '
                     'of 5 mm-5 cm at 30-240 Hz left up to 1.4 m/s from the simultaneous '
                     'Newton answer); impacts on different sides (a ball struck while it '
                     'passes another, 48 deg; a sphere landing in the pocket of two touching '
                     'ones, 60 deg) are struck as they come'),
    ParamSpec('substep_sink', 'double', 0.02,
              'The resting solve\'s substeps are also at most sqrt(this * reach / a) long for '
              'every solver row and its movable bodies (a: the body\'s external acceleration, '
              'gravity; reach: the row\'s lever from its centre of mass), up to '
              'max_substeps: a substep sinks no body by more than this fraction of the '
              'levers it stands on; 0: off',
              0.0, 1.0,
              reason='the residual of a substep\'s sweeps sinks a body by a fraction of a h^2, '
                     'which across a small body\'s contacts tilts it, and a tall stack of it '
                     'amplifies the tilt: towers of 20 cubes of 1 cm toppled at 30 and 50 Hz '
                     '(6.7 ms substeps: a h^2 is 5 % of the cubes\' 8.7 mm reach) and of 5 mm '
                     'at 60 and 100 Hz; at 0.02 (4.2-4.5 ms for 1 cm) they stand within 3 mm '
                     'at 30-1000 Hz; bodies of a reach above 2 cm keep max_substep'),
    ParamSpec('stack_sink', 'double', 0.5,
              'The resting solve\'s substeps are also at most sqrt(this * reach / a) / D long '
              '(reach and a as substep_sink; D: the levels of the deepest stack, contact '
              'distance from an immovable body), up to max_substeps: a stack D levels tall '
              'tips over its lowest contacts with D times the weight at D times the lever; '
              '0: off',
              0.0, 100.0,
              reason='with sleeping off, towers of 20 default cubes swayed from round-off '
                     'and fell where the substep was longer than about 0.6 sqrt(reach / g) '
                     '/ D (1.3 for this; 5 cm: 3.8 ms, 10 cm: 5.3 ms): 5 cm cubes at 30 and '
                     '60 Hz, 10 cm at 30 Hz (1.97, 3.03, 5.45 m in 10 s); at 0.5 the towers '
                     'of 5 to 20 cm stand within 0.9 mm at 30-240 Hz (the 5 cm ones at 30 Hz '
                     'with 10 substeps), of 1 and 2 cm within 0.2 mm at 30 Hz with 32 '
                     '(max_substeps); a settled pile of 1000 '
                     'keeps max_substep (5 substeps at 30 Hz, 3 at 60 Hz, as before)'),
    ParamSpec('exact_rows', 'integer', 32,
              'An island of two or more movable bodies (joined by rows between movable '
              'bodies) with at most this many rows is solved exactly after a substep\'s '
              'sweeps (and the landing\'s) where they gave it more mechanical energy than '
              'exact_work (StepSolver::exact_islands: every row an equality of its rule, '
              'one dense system, taken where it leaves no more kinetic energy); 0: never',
              0, 1000,
              reason='the sweeps of a rocking column of 7 cubes (28 rows), warm started from '
                     'the impulses that held it leaning the other way, gave it up to 17 mJ a '
                     'step (test_column_rocking); solved exactly it gains at most 3.3e-7 J a '
                     'step and rests after 0.67 / 0.83 s (30 / 120 Hz); a dense system of 3 '
                     'unknowns a row costs (3 R)^3 / 3 a round, 0.3 M operations at 32 rows'),
    ParamSpec('exact_rounds', 'integer', 16,
              'Most changes of an exact island solve\'s active set (exact_rows): the rows '
              'breaking their rule the most change each round, from the set its rows\' '
              'solve found in the substep before (else, or where that finds none within '
              'these, from every row held); unsolved, the sweeps\' answer stays', 1, 1000,
              reason='from every row held, the rocking column finds its set in 16 at 30 and '
                     '120 Hz (while it rocks: the exact answer of one substep warm starts '
                     'the next); from the set before it changes 1.4 times a solve (5.9 from '
                     'every row held); a column of 8 cubes landing as one island (bench_laws '
                     'column, 30 Hz) started from the set of its landing substep (its base '
                     'sliding along the impact\'s friction) changed its rows between sliding '
                     'and sticking for all 16 (from every row held: found in 15)'),
    ParamSpec('exact_work', 'double', 3e-4,
              'An island (exact_rows) is solved exactly from the substep in which its '
              'contacts gave it more mechanical energy than this (kinetic energy at the '
              'end less at the start without the substep\'s external change, plus the '
              'external force\'s potential energy over the substep), and from then on while '
              'it is held (exact_hold)',
              0.0, 1.0, unit='J',
              reason='the rocking column shows 1e-4-6e-3 J in a substep before its first '
                     'exact solve: at 1e-3 it gained 0.65 mJ a step at 120 Hz, at 3e-4 and '
                     '1e-4 at most 2.2e-8 J; settled bench piles (bench/pile.py, 100 and 1000 '
                     'cubes at 120 Hz) show up to 1.1e-4 J in towers of 7 cubes (at 1e-4 one '
                     'or two a pile were solved exactly for 5-20 substeps, at 1e-9 towers of '
                     '6-7 bodies of every pile 171 times in 10 steps each); at 3e-4 none'),
    ParamSpec('exact_hold', 'double', 0.2,
              'An island solved exactly (exact_work) stays so in every substep until this '
              'long has passed since the last substep in which its sweeps gave it more than '
              'exact_quiet and its exact answer was taken; one whose first solve finds no '
              'set (exact_rounds) is not held, nor solved again for this long', 0.0, 10.0,
              unit='s',
              reason='the rocking column changes the edge it rocks on (where the sweeps, '
                     'warm started from the impulses that held it leaning the other way, '
                     'gain) at most 0.15 s apart: held 0.1 s it gained 1.8 mJ a step at 30 '
                     'Hz, 0.15-0.3 s at most 2.2e-8 J; held while its kinetic energy was '
                     'above 1e-9 J instead, the towers of piles settled from the drop '
                     '(bench/bench_step.py) never got below it (the rows\' allowances move '
                     'them at 1e-4 m/s) and were solved in every substep (cubes 100 at 120 '
                     'Hz 1.06 -> 7.58 ms a step); let go at a first unsolved substep, the '
                     'column (with the push-out, 30 Hz) rested after 1.83 s; towers of '
                     'piles settling from the drop (1000 cubes at 120 Hz) whose first solve '
                     'found no set found none in the later substeps either while their '
                     'sweeps gained more than exact_work (1087 solves in the 1 s settle of '
                     'bench/bench_step.py, 806 unsolved), solved again in every one'),
    ParamSpec('exact_quiet', 'double', 1e-7,
              'A substep in which the sweeps gave an island held exactly (exact_hold) more '
              'mechanical energy than this, where its exact answer was taken, starts its '
              'hold again', 0.0, 1.0, unit='J',
              reason='a tenth of the rocking column\'s law (1e-6 J a step): the sweeps of '
                     'the towers of settled piles give them at most 3e-9 J a substep, the '
                     'column up to 4.7e-3 J where it changes edges; from 0 to 1e-5 the '
                     'column gains and rests alike'),
    ParamSpec('exact_tolerance', 'double', 1e-9,
              'An exact island solve (exact_rows) has found its set where no row breaks its '
              'rule by more than this (apart: approaching faster than its allowance; '
              'active: pulling, or its friction beyond the cone or along its slip, as the '
              'speed its own diagonal gives that impulse)', 0.0, 1.0, unit='m/s',
              reason='the rounding of a found set\'s answer, far below the rows\' '
                     'allowances (1e-4 m/s in settled piles): 33 nm in a 30 Hz step; the '
                     'rocking column\'s sets break their rules by rounding or by far more: '
                     'from 0 to 1e-4 it gains at most 2.2e-8 / 5.0e-9 J a step and rests '
                     'after 0.67-0.73 / 0.83 s at 30 / 120 Hz (1e-3: 1.1e-7 J at 120 Hz)'),
    ParamSpec('exact_regularise', 'double', 1e-8,
              'An exact island solve (exact_rows) weighs each unknown\'s own equation this '
              'fraction more on its diagonal: a redundant set (a box on four coplanar '
              'points: four normal rows, three motions) has one answer, near the least '
              'weighted norm, whatever the rows\' order', 0.0, 1.0,
              unit='fraction of the diagonal',
              reason='the least that finds the rocking column\'s sets: at 1e-10 it gained '
                     '9.2 mJ a step at 30 Hz, at 1e-9 0.68 mJ, at 0 17 mJ (the sweeps\' '
                     'answer; at 120 Hz 4.4 mJ, 1e-9 and 1e-10 within the law); the '
                     'weight moves the answer, so its gain grows with it: at most 2.2e-8 / '
                     '5.0e-9 J a step at 30 / 120 Hz at 1e-8, 2.3e-7 at 1e-7, 1.7e-6 at 1e-6 '
                     '(beyond the law, 1e-6 J)'),
    ParamSpec('aim_turn', 'double', 1e-3,
              'A contact of two spheres pressed one onto the other is aimed along their '
              'centres\' line in each substep (StepSolver::aim); its row\'s frame is turned '
              'only where that line leans from its normal by more than this',
              0.0, 0.1, unit='rad',
              reason='a normal that leans by an angle a from the aimed line lets the centres '
                     'close by about their distance times a^2 over the substep\'s motion, '
                     'which is itself under a times that distance: 1e-7 m for balls of 5 cm at '
                     '1e-3 rad; a settled pile\'s rows then keep their frames and their packed '
                     'lanes (turning every aimed row in every substep cost 5 % of a 30 Hz step '
                     'of a settled mixed pile of 1000 bodies)'),
    ParamSpec('parallel_wave', 'integer', 16,
              'A sweep whose waves (manifolds that share no movable body, solved one after '
              'the other in the solve\'s order) average at least twice this many manifolds '
              'is cut in two sides, whatever the threads: each side\'s manifolds, then the '
              'seam\'s (those joining the two), with two threads the sides side by side '
              '(smaller sweeps stay whole, in the solve\'s order, on one thread); with two '
              'threads a per-contact pass is split in 8 parts of at least this many contacts',
              1, 10**9,
              reason='a part handed over costs its thread a claim and the other side\'s count '
                     '(a cache line there and back 0.47 us) against 64 ns a manifold, and a '
                     'sweep cut in two leaves more manifolds one by one: settled piles of 100 '
                     '(waves of 8-10 manifolds on average), cut at 4, a sweep took 23-35 us '
                     'on two threads against 12-15 on one; settled piles of 1000 (36-58 on '
                     'average; a seam of 0.5-5 % of the rows) solve 1.26-1.32 times as fast '
                     'on two threads as on one'),
    ParamSpec('wide_rows', 'bool', True,
              'Solve each wave\'s manifolds four at a time (wide rows: structure of arrays, '
              'SIMD); off, one by one: the same bits', None, None,
              reason='a row update is a chain of dependent arithmetic: four independent '
                     'manifolds in lanes fill the pipeline and the vector unit'),
    ParamSpec('resting_factor', 'double', 1.5,
              'A contact is RESTING (does not bounce) while its approach is below this many '
              'times the approach the step\'s external change alone brought it (its bodies\' '
              'current less previous twists along its normal), or below '
              'restitution_threshold where that change acts on one of its bodies', 1.0, 1e3,
              reason='a body resting on a floor (or on a body its supports hold) gathers '
                     'exactly that approach, g dt, in every step, and must not bounce on it; '
                     'free bodies gather none from each other, so an elastic gas in a closed '
                     'box bounces at every approach (100.00 % of its energy kept over 5 s at '
                     '30-240 Hz with default settings). With restitution_threshold 0.05 m/s a '
                     'ball dropped from 0.3 m (e 0.8) rests 3.8, 4.4, 4.7 and 7.5 steps before '
                     'the bounce law with this resting speed at 30, 60, 120 and 240 Hz (at 2: '
                     '1.2 to 8.8); at 1.5 g dt is below the default 0.5 m/s from 30 Hz up (the '
                     'default answers as before), above it at 20 Hz and slower'),
    ParamSpec('impact_converged', 'double', 1e-10,
              'A stage\'s compression ends when a sweep changes no impulse by more than '
              'this times the largest', 0.0, 1.0,
              reason='the simultaneous Newton answer to 1e-9, far below any visible error'),
)


def check_value(spec: ParamSpec, value: Any) -> None:
    """Raise ValueError with a one-line reason when ``value`` is outside ``spec``."""
    def fail(why: str) -> None:
        raise ValueError(f'{spec.name}: {why} (got {value!r})')

    if spec.type in ('double', 'integer'):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            fail(f'must be a {spec.type}')
        if value != value or value in (float('inf'), float('-inf')):
            fail('must be finite')
        lo, hi = spec.minimum, spec.maximum
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            fail(f'allowed range [{lo}, {hi}]')
    elif spec.type == 'bool':
        if not isinstance(value, bool):
            fail('must be true or false')
    elif spec.type == 'string':
        if not isinstance(value, str):
            fail('must be a string')
        if spec.choices and value not in spec.choices:
            fail(f'allowed values {", ".join(spec.choices)}')


def range_text(spec: ParamSpec) -> str:
    """The allowed range as written in the README and in error messages."""
    if spec.choices:
        return ' | '.join(spec.choices)
    if spec.minimum is not None or spec.maximum is not None:
        return f'[{spec.minimum}, {spec.maximum}]'
    return ''


assert [f.name for f in fields(SolverSettings)] == [p.name for p in SOLVER_PARAMS]
assert all(getattr(SolverSettings(), p.name) == p.default for p in SOLVER_PARAMS)

__all__: Sequence[str] = ('ParamSpec', 'SOLVER_PARAMS', 'SOLVER_TUNING', 'SolverSettings',
                          'check_value',
                          'range_text', 'RESTITUTION_RULES', 'FRICTION_RULES')


# Generous physical ranges: wider than any scene we know of, narrow enough that no product of
# two of them overflows a double (so no overflow warning can reach stderr). Inputs over the
# topics are held to the same position and velocity limits (core/validation.py).
SIZE_RANGE = (1e-6, 1e6)       # m: sphere radius, box edge, lengths; 1 um to 1000 km
POSITION_LIMIT = 1e9           # m, |coordinate|: well beyond the Moon
VELOCITY_LIMIT = 1e9           # m/s and rad/s, |component|
INERTIA_RANGE = (1e-30, 1e30)  # kg m^2: a 1e-9 kg body of 1 um to a 1e9 kg body of 1000 km
MESH_MAX_BYTES = 64 * 1024 * 1024   # a larger vertex file is not a collision hull
MESH_SUFFIXES = ('.obj', '.stl')
# A convex hull keeps at most this many vertices: a larger set (a scanned mesh) is simplified
# to its vertices extreme along as many evenly spread directions (as PhysX caps a convex
# mesh at 255 vertices); contact queries on a hull cost with its vertex count.
HULL_MAX_VERTICES = 256
# A params file (and a bag's recorded params) is read within these bounds, as rcl reads it:
# no aliases, no tags but !!str; larger or deeper documents are refused before parsing ends.
PARAMS_FILE_MAX_BYTES = 64 * 1024 * 1024   # a scene of inlined hull vertices fits
PARAMS_FILE_MAX_DEPTH = 32                 # nested mappings and lists
# collres_sim --realtime: it warns when it falls behind the wall clock by more than
# REALTIME_LAG s (at most once per REALTIME_WARN_PERIOD s), and at the end when the rate it
# reached is below REALTIME_SHORTFALL of the rate asked (each step waits for the node's answer)
# and the run ended more than REALTIME_JITTER_STEPS periods behind (one late last step of a
# short run is the scheduler's jitter, not a rate)
REALTIME_LAG = 0.5             # s
REALTIME_WARN_PERIOD = 5.0     # s
REALTIME_SHORTFALL = 0.95      # fraction of rate_hz
REALTIME_JITTER_STEPS = 3      # periods (1 / rate_hz)
# Collision filtering (Box2D category/mask bits, Gazebo collide_bitmask): 16 bits, a body in
# bit 0 that collides with every bit, so a scene that does not filter is unchanged.
DEFAULT_COLLISION_GROUP = 1
ALL_COLLISION_BITS = 0xFFFF
COLLISION_RULE = 'a pair collides when (group_a & mask_b) != 0 and (group_b & mask_a) != 0'

# Sleep (core.sleep, handed to _native.SleepSettings.late_steps): an asleep body's input that
# is its held state integrated by its kept change up to this many periods (an upstream that
# integrated an answer that came late, k - 1 periods old) keeps it asleep. 3: a 100-body
# pile at 100 Hz given one input from an answer two steps old woke (up to 4 cm/s) and was
# not asleep 1.1 s later; an answer three periods late is already a node far behind.
SLEEP_LATE_STEPS = 3
# Tunings of the still rule (core.sleep): each handed to _native.SleepSettings by its name.
SLEEP_TUNING: tuple[ParamSpec, ...] = (
    ParamSpec('rise_time', 'double', 0.6,
              'A body whose farthest point\'s speed has risen in each step for this long is '
              'accelerating (an unbalanced load drives it), not at rest: its island does not '
              'fall asleep until a step in which that speed did not rise', 0.05, 1.0,
              unit='fraction of time_to_sleep',
              reason='0.3 s with the default time_to_sleep; below 1, or a body whose '
                     'rises start a step after its still time would sleep first: a ball '
                     'from rest on a slope of tan = 1.01-1.1 mu_r (mu_r 0.05 and 0.1, 30 and '
                     '240 Hz) rises in every step (by 2.9e-5 m/s a step at 240 Hz and more), '
                     'but dropped 2 mm onto it its rises start a step after the landing: at '
                     '1 it slept after 0.52 s at 240 Hz, at 0.8 and 0.6 it rolls on. In the '
                     'settling 100-body piles (seeds 1-2, both kinds, 30 and 120 Hz, '
                     'sleeping off) bodies under the threshold rose up to 16-24 steps in a '
                     'row at 30 Hz (0.5-0.8 s, while they settle) and up to 20-118 at 120 Hz: '
                     'counted from the traces, all their bodies were ready as early at 0.6, '
                     '0.8 and 1 as with no such rule (0.97-1.73 s), 0.03-0.1 s later at 0.4 '
                     'and 0.5, and up to 1 s later or never at 0.2. The 1000-body piles '
                     '(seed 1) fall asleep after 2.77 s (cubes, 30 Hz; 2.67 at 0.8, 2.6 at 1 '
                     'and by speed alone), 2.18 (cubes, 120 Hz; 2.1), 4.8 (mixed, 30 Hz; '
                     '4.77) and 2.16 (mixed, 120 Hz; the same)'),
    ParamSpec('rise_step', 'double', 1e-6,
              'The least rise of a body\'s farthest-point speed from one step to the next that '
              'counts for rise_time', 0.0, 1.0, unit='fraction of sleep_threshold',
              reason='5e-8 m/s with the default threshold: round-off counts no rise (a ball '
                     'held on a slope of tan = mu_r answers 1.2e-4 m/s, rising by 2e-18 m/s '
                     'in each of its steps at 30 Hz, and would never sleep at 0), a body '
                     'accelerating at 1.5e-6 m/s^2 or more at 30 Hz (1.2e-5 at 240 Hz) '
                     'counts (a ball at tan = 1.01 mu_r, mu_r 0.05: 7e-3 m/s^2 at its '
                     'farthest point); the piles were ready as early at 0, 5e-11 and 5e-8 m/s'),
)

# /diagnostics: fresh starts (time going back, jumps, gaps) in at least this fraction of a
# window's steps are a WARN (two clocks on one topic, a source whose time keeps jumping)
TIME_JUMP_WARN_FRACTION = 0.25

# Convex decomposition (collres_decompose, body.<name>.decompose): CoACD's default concavity
# threshold and SDFormat's default most hulls.
DECOMPOSE_THRESHOLD = 0.05
DECOMPOSE_MAX_HULLS = 16

# Rolling resistance and torsional friction defaults (dimensionless; see BODY_PARAMS).
ROLLING_RESISTANCE = 0.01
TORSIONAL_FRICTION = 0.01
ROLLING_REASON = ('a ball set rolling at 1 m/s on a floor still does 0.93 m/s after 1 s '
                  'and stops after 7.1 m, while a settled pile comes to rest within 2 s: '
                  'the bench\'s settled 100-body piles (boxes, or boxes and spheres, seeds '
                  '1-12, 30-240 Hz) have every point under 0.05 m/s after 0-1.73 s (without '
                  'it and torsional friction 4 of 32 mixed piles still move after 2 s)')
TORSIONAL_REASON = ('a ball of r 0.05 m spinning on the spot at 5 rad/s stops within 1 s '
                    '(5/2 mu_t g / r = 4.9 rad/s^2)')

# Per-body parameters: `body.<name>.<param>` in the shared `/**` section.
BODY_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec('shape', 'string', 'sphere',
              'Collision shape; triangle_mesh: a static body that is the surface of its mesh '
              '(one-sided triangles, their front counter-clockwise), for scenery that must stay '
              'concave (a bin, a shelf)',
              choices=('sphere', 'box', 'capsule', 'cylinder', 'cone', 'plane', 'convex',
                       'triangle_mesh'),
              reason='a ball; a mesh is a convex hull unless decomposed or a static '
                     'triangle_mesh'),
    ParamSpec('size', 'double_array', [0.1],
              'sphere [r]; box [x, y, z] full edges; capsule, cylinder, cone [r, length] along z; '
              'plane [nx, ny, nz, d] (|d| up to the position limit)', *SIZE_RANGE, unit='m',
              reason='1 um to 1000 km: beyond that the solver loses every digit'),
    ParamSpec('static', 'bool', False, 'Infinite mass; the pose may still be set or published'),
    ParamSpec('kinematic', 'bool', False,
              'Static (infinite mass) and moved by collres_sim at its linear_velocity and '
              'angular_velocity: a conveyor belt, a turntable, a driven platform',
              reason='bodies driven from outside push others but are never pushed'),
    ParamSpec('mass', 'double', 1.0, 'Mass (dynamic bodies)', 1e-9, 1e9, unit='kg'),
    ParamSpec('inertia', 'double_array', [],
              'Principal inertia [ixx, iyy, izz] about the origin; empty: from shape and mass',
              *INERTIA_RANGE, unit='kg m^2'),
    ParamSpec('restitution', 'double', 0.5, 'Coefficient of restitution', 0.0, 1.0),
    ParamSpec('static_friction', 'double', 0.5, 'Static friction coefficient', 0.0, 10.0),
    ParamSpec('kinetic_friction', 'double', 0.3,
              'Kinetic friction coefficient (<= static_friction)', 0.0, 10.0),
    ParamSpec('rolling_resistance', 'double', ROLLING_RESISTANCE,
              'Rolling resistance: the torque against rolling is at most this times the '
              'contact\'s lever (a ball\'s radius) times the normal force (a ball rolling on '
              'a floor slows at 5/7 of it times g; it holds on a slope while tan(slope) <= it); '
              'combined as friction (solver.friction_rule)', 0.0, 10.0,
              reason=ROLLING_REASON),
    ParamSpec('torsional_friction', 'double', TORSIONAL_FRICTION,
              'Torsional friction: the torque against spinning about the contact normal is at '
              'most this times the contact\'s lever times the normal force; combined as '
              'friction (solver.friction_rule)', 0.0, 10.0,
              reason=TORSIONAL_REASON),
    ParamSpec('position', 'double_array', [0.0, 0.0, 0.0],
              'Initial position (sim); pose of a static body (node)', -POSITION_LIMIT,
              POSITION_LIMIT, unit='m'),
    ParamSpec('orientation', 'double_array', [0.0, 0.0, 0.0, 1.0],
              'Initial orientation, quaternion x, y, z, w'),
    ParamSpec('linear_velocity', 'double_array', [0.0, 0.0, 0.0],
              'Initial linear velocity, world frame (sim); kinematic: its constant velocity',
              -VELOCITY_LIMIT, VELOCITY_LIMIT, unit='m/s'),
    ParamSpec('angular_velocity', 'double_array', [0.0, 0.0, 0.0],
              'Initial angular velocity, world frame (sim); kinematic: its constant velocity',
              -VELOCITY_LIMIT, VELOCITY_LIMIT,
              unit='rad/s'),
    ParamSpec('mesh', 'string', '',
              'convex: mesh file (OBJ/STL), relative to the params file or absolute; '
              f'a regular .obj or .stl file of at most {MESH_MAX_BYTES // 2**20} MiB; the '
              'body is the convex hull of its vertices unless decompose is true; '
              'triangle_mesh: its triangles (those with an area)',
              reason='a hull, as MuJoCo and Drake make of a mesh: a concave mesh needs '
                     'decompose'),
    ParamSpec('points', 'double_array', [],
              'convex: vertices [x0, y0, z0, x1, ...] in the body frame; triangle_mesh '
              'without a mesh: nine values (three corners) a triangle', -SIZE_RANGE[1],
              SIZE_RANGE[1], unit='m'),
    ParamSpec('shapes', 'string_array', [],
              'Compound body: the names of its convex pieces (letters, digits, _), each '
              'described by body.<name>.piece.<piece>.*; shape, size, mesh and points of the '
              'body are then not set. Mass spreads over the pieces\' volumes; a dynamic '
              'compound\'s pieces must have their centre of mass at the body origin',
              reason='empty: the body is the one shape above'),
    ParamSpec('decompose', 'bool', False,
              'convex with a mesh: the body is the convex decomposition of the mesh (CoACD), '
              'read from the cache next to the mesh (collres_decompose writes it; made at start '
              'when missing, with a log line)',
              reason='decomposition takes seconds to minutes: opt-in, cached'),
    ParamSpec('decompose_threshold', 'double', DECOMPOSE_THRESHOLD,
              'decompose: CoACD\'s concavity threshold (smaller: more, finer hulls)', 0.01, 1.0,
              reason='CoACD\'s default'),
    ParamSpec('decompose_max_hulls', 'integer', DECOMPOSE_MAX_HULLS,
              'decompose: most convex hulls of the decomposition', 1, 256,
              reason='SDFormat\'s default max_convex_hulls'),
    ParamSpec('collision_group', 'integer', DEFAULT_COLLISION_GROUP,
              f'Collision category bits the body is in: {COLLISION_RULE} (Box2D category '
              'bits, Gazebo collide_bitmask); 0: it collides with nothing',
              0, ALL_COLLISION_BITS,
              reason='every body in bit 0 with a mask of all bits: every pair collides'),
    ParamSpec('collision_mask', 'integer', ALL_COLLISION_BITS,
              f'Collision bits the body collides with ({ALL_COLLISION_BITS:#x}: all 16; '
              'see collision_group)', 0, ALL_COLLISION_BITS,
              reason='all bits: a scene that does not filter collides as before'),
)


# The pieces of a compound body: `body.<name>.piece.<piece>.<param>`.
PIECE_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec('shape', 'string', 'box', 'Collision shape of the piece',
              choices=('sphere', 'box', 'capsule', 'cylinder', 'cone', 'convex')),
    ParamSpec('size', 'double_array', [0.1, 0.1, 0.1],
              'As body.<name>.size (no plane)', *SIZE_RANGE, unit='m'),
    ParamSpec('mesh', 'string', '', 'convex: mesh file, as body.<name>.mesh (its hull)'),
    ParamSpec('points', 'double_array', [],
              'convex: vertices [x0, y0, z0, x1, ...] in the piece frame', -SIZE_RANGE[1],
              SIZE_RANGE[1], unit='m'),
    ParamSpec('position', 'double_array', [0.0, 0.0, 0.0],
              'Position of the piece\'s frame (its centre; a cone\'s centre of mass) in the '
              'body frame', -SIZE_RANGE[1], SIZE_RANGE[1], unit='m'),
    ParamSpec('orientation', 'double_array', [0.0, 0.0, 0.0, 1.0],
              'Orientation of the piece\'s frame in the body frame, quaternion x, y, z, w'),
)


# Node settings: the non-solver parameters of collres_node (its own section).
NODE_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec('sync_slop', 'double', 0.0,
              'Per-body topics: largest stamp difference grouped into one step (0: exact)',
              0.0, 1.0, unit='s', reason='exact stamps are deterministic; a simulator sends them'),
    ParamSpec('stale_timeout', 'double', 1.0,
              'A body not updated for longer than this is reported stale in /diagnostics',
              1e-3, 3600.0, unit='s', reason='one second is many steps at any control rate'),
    ParamSpec('marker_lifetime', 'double', 0.5,
              'Lifetime of contact markers (each message also starts with DELETEALL)',
              0.0, 60.0, unit='s',
              reason='stale markers vanish even if the node stops publishing'),
    ParamSpec('diagnostics_period', 'double', 1.0,
              'Period of the /diagnostics status', 0.01, 60.0, unit='s',
              reason='1 Hz is the diagnostic_updater default'),
    ParamSpec('per_body_outputs', 'bool', True,
              'Publish bodies/<name>/{pose,twist}/corrected for steps from per-body inputs',
              reason='per-body users expect per-body answers; batched users read the array'),
    ParamSpec('queue_depth', 'integer', 10,
              'Depth of the reliable QoS (keep last) of the node\'s subscriptions and of its '
              'markers (its other publishers keep the last 1000 steps for readers that fall '
              'behind)', 1, 1000,
              reason='a few steps of buffering; old states are worthless to a control loop'),
    ParamSpec('max_message_bodies', 'integer', 10000,
              'Most bodies a body_states message may hold; a longer one is refused whole '
              '(too_many_bodies) before it is read. Bodies the scene does not know are refused '
              'one by one (unknown_body), the others served',
              1, 1000000,
              reason='an estimator may publish every object it tracks; a bound on the memory '
                     'and time one message takes (10,000 bodies: 1.2 MB)'),
    ParamSpec('min_rate', 'double', 0.0,
              'Expected step rate: /diagnostics warns when the rate over its window falls '
              'below it, and reports an error when no step comes (0: no rate check)',
              0.0, 100000.0, unit='Hz',
              reason='the source\'s rate is the user\'s to state, as diagnostic_updater\'s '
                     'FrequencyStatus min_freq'),
    ParamSpec('contact_wrench', 'bool', False,
              'Publish bodies/<name>/contact_wrench (WrenchStamped, world frame) every step: '
              'the net contact force (sum of impulses / dt) and torque about the centre of mass',
              reason='one message per body per step: opt-in, for users of contact forces'),
    ParamSpec('body_markers_period', 'double', 0.05,
              'Least stamp interval between two body_markers messages (each body\'s shape at '
              'its corrected pose; built only while subscribed; 0: every step)',
              0.0, 60.0, unit='s',
              reason='20 Hz looks smooth; the triangles of 1000 boxes are 1.3 MB a message'),
    ParamSpec('publish_tf', 'bool', False,
              'Publish /tf world_frame -> <body> for every body every step (tf2_msgs: a '
              'ROS install\'s, or the one make setup generates where it is missing)',
              reason='N transforms per step: opt-in'),
    ParamSpec('contact_state', 'bool', False,
              'Publish bodies/<name>/in_contact (std_msgs/Bool, reliable, transient local, on '
              'change) for every body: true from the step whose normal impulses on the body '
              'sum to more than contact_on_impulse, false after contact_off_steps steps in a '
              'row at or below it',
              reason='one publisher per body: opt-in, for controllers that wait for a touch'),
    ParamSpec('contact_on_impulse', 'double', 1e-6,
              'in_contact: least sum of normal impulses on a body in one step that is a touch '
              '(a speculative contact that carries no impulse is none)', 1e-12, 1e6,
              unit='N s',
              reason='below the weight of a 1 g part over a 1 kHz step (1e-5 N s), above the '
                     'solver\'s round-off'),
    ParamSpec('contact_off_steps', 'integer', 3,
              'in_contact: steps in a row without a touch before a body is out of contact '
              '(hysteresis: a bounce or a slide over an edge does not make it chatter)', 1, 10000,
              reason='a few steps debounce a bounce at any control rate'),
)


@dataclass(frozen=True)
class NodeSettings:
    """collres_node settings outside the solver; see NODE_PARAMS."""

    sync_slop: float = 0.0
    stale_timeout: float = 1.0
    marker_lifetime: float = 0.5
    diagnostics_period: float = 1.0
    per_body_outputs: bool = True
    queue_depth: int = 10
    max_message_bodies: int = 10000
    min_rate: float = 0.0
    contact_wrench: bool = False
    body_markers_period: float = 0.05
    publish_tf: bool = False
    contact_state: bool = False
    contact_on_impulse: float = 1e-6
    contact_off_steps: int = 3


# Simulator settings: the parameters of collres_sim (its own section).
SIM_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec('gravity', 'double_array', [0.0, 0.0, -9.81], 'Gravity, world frame',
              unit='m/s^2'),
    ParamSpec('rate_hz', 'double', 240.0, 'Integration and publishing rate', 1.0, 100000.0,
              unit='Hz', reason='a common physics rate (Bullet, Unity: 60-240 Hz)'),
    ParamSpec('duration', 'double', 5.0, 'Simulated time to run', 0.0, 86400.0, unit='s'),
    ParamSpec('publish_per_body', 'bool', False,
              'Also publish bodies/<name>/pose and twist (live mode)'),
    ParamSpec('joint_motion', 'string_array', [],
              'Scripted joints of robot_description, each "joint:amplitude:frequency[:phase]": '
              'the joint moves as amplitude sin(2 pi frequency t + phase) (rad, or m for a '
              'prismatic joint; Hz; rad; t from the first state) and the links follow by '
              'forward kinematics, posed with their twists every step',
              reason='none: the links keep the poses they start with'),
)


@dataclass(frozen=True)
class SimSettings:
    """collres_sim settings; see SIM_PARAMS. ``gravity`` in m/s^2, world frame."""

    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    rate_hz: float = 240.0
    duration: float = 5.0
    publish_per_body: bool = False
    # (joint, amplitude rad or m, frequency Hz, phase rad) of each scripted joint
    joint_motion: tuple[tuple[str, float, float, float], ...] = ()


assert [f.name for f in fields(NodeSettings)] == [p.name for p in NODE_PARAMS]
assert all(getattr(NodeSettings(), p.name) == p.default for p in NODE_PARAMS)
assert [f.name for f in fields(SimSettings)] == [p.name for p in SIM_PARAMS]


# Scene parameters shared by every node (the `/**` section), besides `body.<name>.*`.
SCENE_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec('world_frame', 'string', 'world',
              'Frame of every pose and world-frame twist (inputs in other frames are refused)'),
    ParamSpec('bodies', 'string_array', [],
              'Body names, in order (letters, digits, _; used in topic names)'),
    ParamSpec('ignore_pairs', 'string_array', [],
              'Pairs of bodies that never collide, each "a:b" (two different names from '
              'bodies), whatever their collision bits (as MoveIt\'s allowed collision matrix)',
              reason='none: every pair the bits allow collides'),
    ParamSpec('robot_description', 'string', '',
              'URDF text (as robot_state_publisher\'s parameter): every link with <collision> '
              'elements becomes a kinematic body named after the link (sphere, box, cylinder, '
              'mesh hull with scale; one piece per element), posed from /tf and /tf_static '
              '(child frame = link name) or from body_states by link name; its '
              'body.<link>.* parameters may still be set',
              reason='empty: no robot'),
    ParamSpec('robot_description_topic', 'bool', False,
              'When robot_description is empty, wait at start for the URDF on the '
              'robot_description topic (std_msgs/String, reliable, transient local, as '
              'robot_state_publisher publishes it) and take it as robot_description',
              reason='off: a scene without a robot starts at once'),
    ParamSpec('robot_self_collision', 'bool', False,
              'Links of robot_description collide with one another (links joined by a joint '
              'never do)',
              reason='off, as MoveIt\'s default allowed collision matrix for a posed arm'),
)
