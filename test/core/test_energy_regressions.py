"""Regression cases of the no-energy-gain law found by ``bench/random_energy.py``.

Each case is one ``World.step`` on hand-made contacts with the current state equal to the
previous one (every change comes from the contact impulses), e <= 1: the kinetic energy
after the step may not exceed the one before.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from collres_ros.core.config import SolverSettings
from collres_ros.core.rotation import integrate
from collres_ros.core.types import BodySpec, ContactKind
from collres_ros.core.world import World

from contacts import contact_set, FixedContacts, states  # noqa: I100
from test_physics_properties import totals

ZERO = np.zeros(3)   # kinetic energy does not depend on the point momenta are taken about


def test_cycling_friction_of_a_cluster_gains_no_energy():
    """random_energy seed 0, case 10852: five bodies, four manifolds of three points (two of
    them coincident points), all impacts at toi 0, restitution threshold 0. The friction of
    the manifold between the small heavy sphere b3 and b4 lifts its own normal rows, which
    then let go of the friction: the sweeps cycle with period two and ended (+9.5e-5 of the
    energy) on an iterate that is no answer. Its island is solved again without friction."""
    def sphere(name, r, m, e, mu_s, mu_k):
        return BodySpec(name, 'sphere', (r,), mass=m, restitution=e, static_friction=mu_s,
                        kinetic_friction=mu_k)
    bodies = [
        sphere('b0', 0.9732790882948238, 29.7743652238217, 0.5445649050976303,
               1.321463226630416, 0.633253882699448),
        sphere('b1', 0.10376215957545046, 43.36032834516945, 0.45574399366409957,
               0.34822857897215026, 0.6518892898899009),
        BodySpec('b2', 'box', (0.40559409061464674, 0.4638155956613395, 0.46262038819569035),
                 mass=71.23708935762588, restitution=0.7527797723975319,
                 static_friction=0.8495286482749457, kinetic_friction=1.4772331596863328),
        sphere('b3', 0.06008290998979785, 70.96813417774504, 0.9937289378237063,
               0.5052365952154427, 0.8419216734469946),
        sphere('b4', 0.9420905048078894, 76.61115541520145, 0.2538649604239842,
               1.3765184088513507, 1.1694969584322126),
    ]
    before = states(
        [[-0.3903177885975611, -0.3264867260318816, -0.43538511326324364],
         [0.23305450096576807, 0.4627546842698641, -0.5370623930080671],
         [-0.07420966810126658, 0.42234899199501896, 0.227621516033068],
         [0.07586392081652668, -0.3494372797525354, 0.3945270806856948],
         [-0.3215774478150145, -0.12197460029708429, 0.35420961878181517]],
        [[1.628620108222309, -2.738101692446999, 0.88311966832301],
         [4.539605558732104, -3.080202455242814, -1.677777246755665],
         [-2.369189140469836, -3.2291139067086725, 4.282360766279666],
         [4.696189769033623, 4.899575524513237, 2.7410540908045036],
         [-2.632620904645284, -0.3244007337754784, 1.5316537776386987]],
        [[-2.3086815566719254, -0.25069745406078425, 3.519668314686543],
         [-1.2573648794088976, 4.269209120577141, 0.6732982805267547],
         [4.70067811340035, 2.303142093622675, 2.070091417531832],
         [4.749425394126337, 0.06894872275419672, 1.7676104014303782],
         [3.707898406155202, 2.583386412731982, -1.909499146195964]],
        [[0.2839176593965225, -0.6875864331215571, 0.6671158153077882, 0.039650329585007325],
         [-0.44596727947981474, 0.3836362767058557, 0.8066521804641426, 0.056996952384188726],
         [0.6271116627669991, 0.41678474967888657, 0.6420928624724465, 0.14400760680831137],
         [0.0074081076823996105, -0.9048564792022692, -0.3720948315052534, 0.206701011979421],
         [-0.27971764457202575, -0.5032114143212532, -0.7749057305598579,
          0.2608781718683551]])
    point = [[-0.15245662615775762, -0.3446489505393719, -0.00845689782157811],
             [-0.22593012361390005, -0.24165487584495043, -0.19285452267571332],
             [-0.07394539880200798, -0.454704841365252, 0.1885839992369154],
             [-0.34499228528384857, -0.17142768361765162, 0.04248221046755496],
             [-0.34499234780697313, -0.17142763513376802, 0.042482161596944325],
             [-0.34499239138422727, -0.1714276285748411, 0.04248214259369798],
             [-0.052859433299398795, -0.07937536309213722, 0.4049517842584682],
             [-0.052859433299398795, -0.07937536309213722, 0.4049517842584682],
             [-0.052859433299398795, -0.07937536309213722, 0.4049517842584682],
             [-0.018628829113785883, -0.18711126275876855, 0.06951319473294043],
             [-0.07769729367058312, -0.21465102922025034, 0.24228190615657333],
             [-0.11726490803569066, -0.23309882310196278, 0.35801279232839284]]
    normals = [[-0.5444604133818602, 0.48787160748608666, 0.682307960432088],
               [-0.3654357968032228, -0.03155419568298508, 0.9303015700027565],
               [-0.3805411749971158, 0.8742336062073071, -0.3015029285257142],
               [-0.35567141374266553, 0.8645946573592623, -0.35492805455769944]]
    separation = [1.9231665368090942e-03, 8.4469429005769921e-05, 4.4084514463484407e-04,
                  1.7921161385178221e-04, 7.3622328374996606e-04, 3.1452223823929659e-04,
                  1.2710889258275315e-03, 1.4776381696862189e-03, -1.2459121652387535e-03,
                  -6.0206142163182416e-06, 3.3114042637567842e-04, -3.5775736224367928e-04]
    contacts = contact_set([0, 0, 0, 0, 0, 0, 2, 2, 2, 3, 3, 3],
                           [3, 3, 3, 4, 4, 4, 4, 4, 4, 4, 4, 4], point,
                           np.repeat(normals, 3, axis=0), separation, kind=ContactKind.IMPACT)
    config = SolverSettings(restitution_rule='max', friction_rule='max',
                            restitution_threshold=0.0)
    for iterations in (9, 10, 11, 50):   # the cycle's both ends
        settings = dataclasses.replace(config, velocity_iterations=iterations)
        world = World(bodies, settings, FixedContacts(contacts, settings))
        result = world.step(before, before.copy(), 0.01)
        solved = result.states.copy()
        solved.position, solved.orientation = before.position, before.orientation
        assert np.isfinite(solved.linear).all() and np.isfinite(solved.angular).all()
        k0, k1 = totals(world, before, ZERO)[2], totals(world, solved, ZERO)[2]
        assert k1 <= k0 * (1 + 1e-9), (iterations, (k1 - k0) / k0)


def one_step_energies(bodies, before, contacts, dt, **settings):
    """Kinetic energy (J) before and after one step on hand-made contacts, the current
    state equal to the previous one (after: the solved twists at the solve's poses)."""
    config = SolverSettings(**settings)
    world = World(bodies, config, FixedContacts(contacts, config))
    result = world.step(before, before.copy(), dt)
    solved = result.states.copy()
    solved.position, solved.orientation = before.position, before.orientation
    assert np.isfinite(solved.linear).all() and np.isfinite(solved.angular).all()
    return totals(world, before, ZERO)[2], totals(world, solved, ZERO)[2], result


def test_shock_propagation_after_the_sweeps_gains_no_energy():
    """random_energy (widened) seed 3, case 19195, reduced: a thin box spinning slowly
    against a fixed sphere on one speculative point (0.08 mm), friction, rolling
    resistance and torsional friction, 1/120 s (two substeps). In the second substep the
    sweeps' answer kept the energy, then shock propagation (its rows on the fixed body,
    one by one from the sweeps' impulses) raised it by 2.6e-4 after the energy check had
    judged the substep. The check now judges the substep after shock propagation."""
    bodies = [
        BodySpec('b0', 'box', (0.009685901519115936, 0.002651568259136185, 0.1570070818025511),
                 mass=0.014618196671513765, restitution=0.0,
                 static_friction=0.9777568507372107, kinetic_friction=0.32098954952368497,
                 rolling_resistance=0.4151742067285257, torsional_friction=0.08677622294866993),
        BodySpec('b1', 'sphere', (0.899284261395288,), static=True, restitution=0.0,
                 static_friction=0.742515137672001, kinetic_friction=0.9682574972441198,
                 rolling_resistance=0.6814010283754781, torsional_friction=0.7721885327048914),
    ]
    before = states(
        [[-0.04989044691279024, -0.03916774266217704, -0.17869077668377278],
         [-0.17049309194692241, 0.11273506273461345, 0.0037067605546253104]],
        [[-0.03851688236435159, 0.042575085979825004, 0.03603473890554392], ZERO],
        [[0.1227013507411422, 0.014309546642166267, -0.06051249413123113], ZERO],
        [[0.6553531584939837, 0.4161810607429129, 0.6174347096409688, 0.1268067098439036],
         [0.18083250543382995, 0.6077525704459067, -0.7591520534788547, 0.1470529761472214]])
    contacts = contact_set(0, 1, [[-0.10168587252852927, 0.04225609537180421,
                                   -0.07506049539445474]],
                           [-0.8034923337462299, -0.5848797407680443, 0.1109763869034423],
                           8e-5, kind=ContactKind.PERSISTENT)
    k0, k1, _ = one_step_energies(bodies, before, contacts, 1 / 120, restitution_rule='min',
                                  restitution_threshold=0.05)
    assert k1 <= k0 * (1 + 1e-9) + 1e-12, (k1 - k0) / k0


def test_landing_gains_no_energy():
    """random_energy (widened) seed 21, case 50546, reduced: a box touching a fixed box on
    three close points of one normal, sticking friction and torsional friction, 1/240 s.
    The landing (every row swept again, those closing within the step without allowance)
    raised the energy the substeps had left (7.9e-10 J) to 1.39e-9 J, 7 % above the
    1.29e-9 J the step began with. The energy check now judges the landing too."""
    bodies = [
        BodySpec('b0', 'box', (0.005566892831674889, 0.050730038733384886, 0.06976692269936591),
                 mass=0.026246003317219848, restitution=0.0, static_friction=1.3585567872091027,
                 kinetic_friction=0.0, rolling_resistance=0.0,
                 torsional_friction=0.33532790635691434),
        BodySpec('b1', 'box', (0.01767928947753128, 0.015292459534681528, 0.000338571914233148),
                 static=True, restitution=0.0, static_friction=1.0393783882627319,
                 kinetic_friction=0.0, rolling_resistance=0.0,
                 torsional_friction=0.1765748100519341),
    ]
    before = states(
        [[0.005737926760032375, 0.12127724006280666, 0.1477659128213026],
         [-0.1386099941579558, 0.03037125033685304, 0.02608729776201817]],
        [[0.00029639347687914337, 8.360102036231654e-05, -6.045285392856337e-05], ZERO],
        [[-0.00010893196521482468, 0.00010331623382900856, -6.935041894524882e-05], ZERO],
        [[-0.14186122524042707, 0.9238216366287576, -0.28768639156566284, 0.20896295503695522],
         [0.9560578100925066, -0.08006567970392807, 0.27293792134935824, 0.07104816524133742]])
    point = [[-0.06824286121424285, 0.07607164284714102, 0.08583649474326423],
             [-0.06538744201015761, 0.07716673707495952, 0.0875807645690125],
             [-0.06437900168112282, 0.07706216207665507, 0.08858361464047786]]
    contacts = contact_set(0, 1, point,
                           [0.20578101867263104, 0.40868769720987597, 0.8891729519634204],
                           0.0, kind=ContactKind.PERSISTENT)
    k0, k1, _ = one_step_energies(bodies, before, contacts, 1 / 240, restitution_rule='average',
                                  friction_rule='min', restitution_threshold=0.05)
    assert k1 <= k0 * (1 + 1e-9) + 1e-12, (k1 - k0) / k0


def test_heavy_ball_on_a_sliding_plank_gains_no_energy():
    """A 10 kg ball falls at 3 m/s on a 0.3 kg plank that slides at 5 m/s over a fixed floor
    (e = 1, friction 1). Shock propagation holds the plank in the impact stage (it rests on
    the floor under a body 33 times heavier), so its friction drags the ball along at
    1.45 m/s while the plank keeps its speed; the stage's energy budget, measured with the
    held plank's motion in the relative velocities, counted that work as taken from the
    ball and the ball still bounced at 3 m/s: +74 % of the kinetic energy. The budget is now
    the energy the ball's own motion gives and takes."""
    bodies = [BodySpec('plank', 'box', (1.0, 0.1, 0.02), mass=0.3, restitution=1.0,
                       static_friction=1.0, kinetic_friction=1.0),
              BodySpec('ball', 'sphere', (0.1,), mass=10.0, restitution=1.0,
                       static_friction=1.0, kinetic_friction=1.0),
              BodySpec('floor', 'box', (10.0, 10.0, 1.0), static=True, restitution=1.0,
                       static_friction=1.0, kinetic_friction=1.0)]
    before = states([(0.0, 0.0, 0.01), (0.0, 0.0, 0.119), (0.0, 0.0, -0.5)],
                    [(5.0, 0.0, 0.0), (0.0, 0.0, -3.0), ZERO])
    # the ball on the plank's top, the plank's four bottom corners on the floor (touching)
    corners = [(x, y, 0.0) for x in (-0.5, 0.5) for y in (-0.05, 0.05)]
    contacts = contact_set([0] * 5, [1, 2, 2, 2, 2], [(0.0, 0.0, 0.02)] + corners,
                           [(0.0, 0.0, 1.0)] + [(0.0, 0.0, -1.0)] * 4,
                           [-0.001] + [-0.0005] * 4, kind=ContactKind.PERSISTENT)
    k0, k1, result = one_step_energies(bodies, before, contacts, 1 / 60)
    assert result.report.normal_impulse[0] > 0.0   # the ball struck the plank
    assert k1 <= k0 * (1 + 1e-9) + 1e-12, (k1 - k0) / k0


def test_a_held_body_driven_into_its_upper_one_gains_no_energy():
    """random_energy clusters seed 3, case 9409 (coal's contacts): a cylinder, four boxes of
    41 g to 652 kg spinning up to 340 rad/s, overlapping one another and a fixed floor under
    gravity, 1 ms. An impact stage holds a light body under a heavy one (shock
    propagation) while another row of the stage drives the light one into the heavy one,
    which the held row then pushes at no cost to the light one: even without friction
    the stage's compression gained 50 J of 3364, and the step ended 9.5 % above what
    gravity can give. Such a stage is compressed last without holding any body."""
    def box(name, size, mass, e, mu_s, mu_k, roll, twist):
        return BodySpec(name, 'box', size, mass=mass, restitution=e, static_friction=mu_s,
                        kinetic_friction=mu_k, rolling_resistance=roll, torsional_friction=twist)
    bodies = [
        BodySpec('b0', 'cylinder', (0.07851043251757121, 0.2790034385749089),
                 mass=9.685777980792079, restitution=0.5, static_friction=1.3162158417446688,
                 kinetic_friction=0.8370020690387341, rolling_resistance=0.6999052109806405,
                 torsional_friction=0.3367790900476517),
        box('b1', (0.07605844083745195, 0.0034827494835459757, 0.09582163718869209),
            0.04115479479112289, 0.79, 0.238932278881115, 1.003619002250453,
            0.6301690310629364, 0.0),
        box('b2', (0.014957658918373853, 0.012716215967199955, 0.01054290993791049),
            270.1803037956099, 0.79, 1.2156806266490279, 0.8210539956054906,
            0.16144159420832915, 0.9418852010374955),
        box('b3', (0.06840691696810447, 0.12755573034307524, 0.0947896039239132),
            651.5295733362439, 0.5, 0.039639610575081585, 0.5976725275329011,
            0.32616004176838376, 0.5978185337285451),
        box('b4', (0.12526450325617214, 0.07527509704461811, 0.0502615544727953),
            0.3238115374886551, 1.0, 1.197766064590294, 0.6861962574455078,
            0.7847154239386511, 0.6553009370361104),
        BodySpec('floor', 'box', (20.0, 20.0, 1.0), static=True, restitution=0.79,
                 static_friction=0.818368360543791, kinetic_friction=0.6262508687172328,
                 rolling_resistance=0.2749253313758542, torsional_friction=0.8142927836840932),
    ]
    current = states(
        [[0.0, 0.0, 0.0], [0.05047272181397601, -0.07041753461323254, 0.09867945472739983],
         [0.06576502197982466, -0.09787243308405659, 0.14685387012500065],
         [-0.022851092437012027, -0.007352109711749821, 0.17278401565563045],
         [-0.07452186207585051, -0.07007910074239948, 0.1488228569200754],
         [0.0, 0.0, -0.5527393187491656]],
        [[1.1904669527097482, 1.424525370027101, -0.7807132585965908],
         [1.769495489886407, 1.2269220481091248, -0.8736919752647511],
         [0.2764115131723123, -1.6917969125719798, 0.00683276263542541],
         [1.4207656317845552, -1.65076736989784, 0.39319630558133145],
         [1.3963978906231427, 1.6688029020098216, -1.279955587113145], ZERO],
        [[8.16121292735752, 5.1188738409443255, -2.1759872524238157],
         [-45.65097100326809, 4.592227884798018, 28.22260994711512],
         [-198.15953753987807, 213.12002770899326, -154.7617633545436],
         [-29.507594734342817, 20.944392789272108, 0.35524416369780104],
         [8.580908856998636, 32.22654538677645, -1.901928876973312], ZERO],
        [[0.7629335867786611, -0.6243081962686602, -0.05193745078313717, 0.15960613848774308],
         [-0.09669467414624566, -0.6845676654585464, -0.6382336367403874, 0.33863708647093904],
         [-0.23021806420848684, 0.6166425317184584, -0.5178239347090029, 0.5464521970222405],
         [-0.1620757694231398, -0.03166383214312629, -0.2857445364834082, 0.9439697593513213],
         [-0.3904895558819033, -0.5432514236960814, -0.496136838957083, 0.5533932005626813],
         [0.0, 0.0, 0.0, 1.0]])
    dt = 0.001
    gravity = np.zeros((6, 3))
    gravity[:5, 2] = -9.81 * dt      # the step's change of the dynamic bodies' twists
    previous = current.copy()        # one step back along the twists (before gravity)
    previous.linear = current.linear - gravity
    previous.position = current.position - current.linear * dt
    previous.orientation = integrate(current.orientation, current.angular, -dt)
    world = World(bodies, SolverSettings(restitution_rule='average', restitution_threshold=0.05))
    result = world.step(previous, current, dt)
    assert result.report.contacts.count > 0
    solved = result.states.copy()
    solved.position, solved.orientation = current.position, current.orientation
    k0, k1 = totals(world, current, ZERO)[2], totals(world, solved, ZERO)[2]
    change = current.copy()
    change.linear, change.angular = gravity, np.zeros((6, 3))
    k_dv = totals(world, change, ZERO)[2]
    # contact impulses never raise the energy norm; gravity's change adds at most its own
    assert np.sqrt(k1) <= (np.sqrt(k0) + np.sqrt(k_dv)) * (1 + 1e-9), k1 / k0
