// One solver step: everything that is per-contact work after detection.
//
// Maps the states of N bodies at the previous and the current time (world frame, before
// resolution) and the M contacts that detection found to corrected current states, the
// contacts' impulses and states. Units SI; quaternions x, y, z, w; a state's twist is the
// velocity over the step that led to it (semi-implicit Euler: x1 = x0 + v1 dt), so the
// velocity at a fraction f of the step is v1 + (f - 1/2) a dt, a = (v1 - v0) / dt the
// step's constant external acceleration (e.g. gravity).
//
// In order (StepSolver::step):
// 1. reference frame: a persistent contact's gap at the previous state is its separation
//    less how far its points closed over the step (the centres' travel and the turns,
//    from the poses: a step of several periods that its source integrated under
//    gravity, after dropped inputs, is no straight line at the twist, and an estimator's
//    pose turns with a zero twist); one within the
//    slop then whose pair did not approach then (previous twists, faster than the
//    sticking speed) touches from the start, and its movable bodies rest (rested). A
//    body with an impact (IMPACT/TUNNELLED contact, or a persistent contact that closes
//    faster than the restitution threshold during the step) is rewound to its earliest
//    time of impact f and solved with the velocity it had then (a supported body, one
//    touching something from the start and neither approaching nor leaving it then
//    faster than the threshold, the step's external change pressing one of the two into
//    the other, along its held path: its previous twist less any approach into what it
//    touches, not the path its source integrated through its supports; its impacts are
//    timed against that path, and one that does not close on it is a persistent contact
//    from the start), except an impact of a
//    rested body that its pair's previous twists do not make (slower than the
//    threshold: only the step's external change brought it, as when the source integrated
//    a resting pile through its supports), which is a persistent contact from the start
//    instead, its gap then the one at the time of impact plus what closed before it; a
//    rested body without impact is solved with its previous twist, the step's external
//    change added after the impacts (to_travel): it is carried by the resting solve, and
//    never makes a bounce; a body in persistent contact only is solved with its current
//    velocity; a persistent contact may approach by its gap at the reference time
//    (speculative allowance, m/s), and so may an impact's speculative corner (a detected
//    impact row with a positive separation: its gap at the time of impact) over the rest
//    of the step;
// 2. prepare: one row per contact point that can carry an impulse this step (a
//    speculative contact that separates faster than `row_bound` (1 + e) times the step's
//    fastest pre-solve approach is no row: a net checks it, below), combined
//    materials by the combine rules, rows in the order of detection's manifolds, one
//    Manifold constraint per manifold with rows; per manifold with rolling resistance or
//    torsional friction one SpinRow (its coefficients combined by the friction rule);
// 3. impacts: successive stages of the rows that approach faster than the restitution
//    threshold, each an exact inelastic compression with friction then restitution
//    (resolve_impacts: no stage gains energy; a chain passes an impact on); then an
//    impacted body's velocity becomes the one its pose travels with over the rest of the
//    step (+ (1 - f) / 2 of the step's external change), so the resting solve keeps that
//    travel, gravity included, out of its partners (an impact's speculative corners, rows
//    with a gap at the time of impact, among them);
// 4. warm start from last step's impulses of the same pair and feature (ContactCache),
//    scaled by the step's growth (the load its external change gives the bodies in
//    contact over theirs last step: k for a step its source integrated for k periods
//    after dropped inputs, 1 for one it integrated for one period whatever dt says; dt /
//    last dt without a load), only while that lies in [1 / r, r] (r = warm_start_ratio)
//    and the last step was itself not fresh (warm = false): otherwise every row starts
//    cold, so no timing of the inputs can launch a resting body;
// 5. iterate, in S = ceil(dt / max_substep) substeps (at most max_substeps; soft_step, as
//    Box2D v3's soft step without its soft push-out): each adds 1/S of the step's external
//    change to the rested bodies that something holds (a row of theirs, and a contact
//    touching them from the start that they were not leaving faster than the restitution
//    threshold) while the change loads them (makes a point of one of their rows faster
//    than it was and than the sticking speed, as gravity at rest; a source stopping a
//    rolling ball only slows its points; of a body that moved, the part of the change
//    that takes back its motion is its source's stop, taken at once: only the rest, the
//    step of gravity, is spread); any other rested body takes all of it at
//    once, as its source did, in to_travel) (the first share: in to_travel), warm
//    starts from the last
//    substep's impulses (the first: from the cache, 1/S of last step's), lets each row
//    approach by its separation now (its gap at the reference time plus how far the
//    substeps so far moved its two points along the normal: no new detection) over the
//    substep (a contact of two spheres pressed one onto the other from the start, with
//    no impact: aimed first along the line of their centres where the substeps moved
//    them, half a substep on, and its separation measured there: aim), solves as below,
//    and moves the poses by the substep's velocity; the poses
//    travel with the substeps' mean velocity, the impulses are the substeps' sums.
//    Each substep: sequential impulses over the manifolds that can carry something (an
//    active set with verification: those idle and separating beyond their allowance are
//    left out while the solved velocities leave them so, StepSolver::sweep), the normal
//    rows of a manifold of 2-4 points solved as
//    a block (more sweeps while the resting contacts are new; sqrt(k) times as many for a
//    step of k times the last one's load (growth), up to warm_start_ratio: whose
//    residual would sink the poses k^2 times as far; and at least depth_sweeps per level
//    of the deepest stack: a load passes down one level per sweep); then shock
//    propagation from the ground up (a heavy body on a light one); then an island
//    (bodies joined by rows through movable bodies) whose kinetic energy the sweeps and
//    shock propagation raised above what it had before the warm start is solved again
//    from its pre-solve velocities without friction (coupled Coulomb friction can have no
//    answer the sweeps converge to: they cycle, and may stop where energy was gained; the
//    frictionless solve is a projection, which never gains) (hold_energy); then a small
//    island whose contacts gave it mechanical energy (a rocking column, which the warm
//    start from the impulses that held it leaning the other way drives) is solved exactly,
//    and so while it moves (exact_islands, IslandSolve);
// 6. landing: the poses travel with the substeps' mean velocity; a speculative contact
//    that closes within the step and holds (gap > 0 at the reference time, impulse > 0)
//    is solved again with no allowance, for the velocities only, so it ends the step
//    touching and with no approach left to bounce on next step (land), an island it
//    raised above the last substep's start energy solved as hold_energy does (from
//    landing_substeps substeps on, its sweeps are the last substep's last landing_sweeps,
//    after the poses' travel, instead of velocity_iterations more); one that
//    closes from a gap beyond the slop faster than the restitution threshold (its approach
//    when the resting solve began) is an impact instead: the step is solved again from the
//    pre-solve velocities (stages 2-6) with it in the impact stages (struck_), where it
//    bounces with its restitution;
//    The net: at the landing's end every contact without a row is checked: if one ends
//    the step closer than touching (on the substeps' poses) or, after a landing, approaches
//    faster than its allowance (it would have carried an impulse), it gets a row and the
//    step is solved again from the pre-solve velocities (stages 2-6), until none does:
//    every contact without a row ends the step idle;
// 7. store impulses for the next step (without the impact stages' and landing's part);
// 8. advance: impacted bodies from their time of impact with the travel velocity for the
//    rest of the step, (1 - f) dt, their twist the mid-step one (velocity - f / 2
//    external); persistent-only bodies from the previous pose for dt with the substeps'
//    mean velocity; the state's twist is the landed velocity (of the last substep);
// 9. split-impulse position pass: penetration beyond the slop predicted at the end of the
//    step (an aimed contact of two spheres: from their centres there) is pushed out
//    (poses only, no velocity: no energy gain);
// 10. report: normal impulse (with the impact stages' and landing's), friction impulse,
//    state per contact; a sticking manifold whose friction impulses cancel is RESTING.
// Bodies without contact keep their current state (the caller's output arrays start as
// a copy of the current states and only touched movable bodies are written). Every stage
// reads the step's inputs, settings and outputs from one StepContext.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <vector>

#include "contact_cache.h"
#include "contact_solver.h"
#include "detection_types.h"
#include "island_solve.h"
#include "sweep_waves.h"

namespace collres {

// States of N bodies at one time: (N, 3) m, (N, 4) x y z w, (N, 3) m/s, (N, 3) rad/s.
struct BodyStatesView {
  const double* position = nullptr;
  const double* orientation = nullptr;
  const double* linear = nullptr;
  const double* angular = nullptr;
};

struct BodyStatesOut {
  double* position = nullptr;
  double* orientation = nullptr;
  double* linear = nullptr;
  double* angular = nullptr;
};

// Per-body constants of the step.
struct BodyProperties {
  int64_t count = 0;
  const double* inv_mass = nullptr;          // (N,) 1/kg, 0 for static and held bodies
  const double* inv_inertia_body = nullptr;  // (N, 3, 3) 1/(kg m^2), body frame, 0 likewise
  const uint8_t* movable = nullptr;          // (N,) 1: dynamic and active this step
  const uint8_t* held = nullptr;             // (N,) 1: inactive this step, reads zero twist
  const double* restitution = nullptr;       // (N,) 0..1
  const double* static_friction = nullptr;   // (N,) >= 0
  const double* kinetic_friction = nullptr;  // (N,) >= 0
  const double* rolling_resistance = nullptr;  // (N,) >= 0, dimensionless (see SpinRow)
  const double* torsional_friction = nullptr;  // (N,) >= 0, dimensionless (see SpinRow)
  const double* radius = nullptr;            // (N,) m: a sphere's radius about its centre
                                             // of mass, 0 for every other shape (aim)
};

// M contacts from detection (types.ContactSet): finite, unit normals.
struct ContactsView {
  int64_t count = 0;
  const int64_t* a = nullptr;          // (M,) body A (a < b)
  const int64_t* b = nullptr;          // (M,) body B
  const double* point = nullptr;       // (M, 3) m, world, at the contact configuration
  const double* normal = nullptr;      // (M, 3) unit, world, from A to B
  const double* separation = nullptr;  // (M,) m, signed gap at the current state (< 0: overlap)
  const double* toi = nullptr;         // (M,) time of impact, fraction of the step in [0, 1]
  const int8_t* kind = nullptr;        // (M,) ContactKind
  const int64_t* feature = nullptr;    // (M,) feature id within the pair (warm start key)
  int64_t manifold_count = 0;          // K
  const int64_t* manifolds = nullptr;  // (K, 4) a, b, first row, row count: detection's
                                       // manifolds, tiling the M rows in order
};

// Per-contact results, caller order.
struct ContactsOut {
  double* normal_impulse = nullptr;    // (M,) N s >= 0, on B along +n (on A along -n)
  double* friction_impulse = nullptr;  // (M, 3) N s, world, on B (opposite on A), _|_ n
  uint8_t* state = nullptr;            // (M,) ContactStateCode
  double* toi = nullptr;               // (M,) reported time of impact in [0, 1]
  int8_t* kind = nullptr;              // (M,) reported kind (a closing persistent: IMPACT)
};

// What every stage of one step reads and writes (as Box2D v3's b2StepContext): the
// inputs, the settings, the solver's view of the bodies (inverse masses, world inertia,
// the working velocity) and the outputs.
struct StepContext {
  const BodyStatesView& previous;
  const BodyStatesView& current;
  const BodyProperties& bodies;
  const ContactsView& contacts;
  double dt;            // s, > 0
  bool warm;            // warm start allowed (see StepSolver::step)
  const SolverParams& params;
  SolverBodies solver;  // velocity: the working velocity (N, 6)
  BodyStatesOut& out;
  ContactsOut& report;
};

struct StepStats {
  int sweeps = 0;   // velocity sweeps done
  int64_t rows = 0; // contact points solved (the others were speculative, inactive)
  int substeps = 1;  // substeps of the resting solve (StepSolver::soft_step)
  int redone = 0;    // times the step was solved again: a contact without a row escaped
};

class StepSolver {
 public:
  // `warm`: warm start from the cache (false after a pause: a fresh start, whose
  // impulses do not warm start the next step either).
  StepStats step(const BodyStatesView& previous, const BodyStatesView& current,
                 const BodyProperties& bodies, const ContactsView& contacts, double dt,
                 bool warm, const SolverParams& params, BodyStatesOut& out,
                 ContactsOut& report);

  ContactCache& cache() { return cache_; }
  // the last step's order of its velocity sweeps (waves, wide groups) and the manifolds
  // it sweeps, in that order (those admit let in by the end of the step)
  const SweepPlan& plan() const { return plan_; }
  const std::vector<Manifold>& manifolds() const { return swept_; }
  // chunks of the waves' second halves run so far: by the second thread, in all
  uint64_t helped() const { return worker_ ? worker_->helped() : 0; }
  uint64_t chunks_run() const { return worker_ ? worker_->chunks_run() : 0; }
  // runs posted for two threads so far, and of those run paired (Worker::runs, paired_runs)
  uint64_t runs() const { return worker_ ? worker_->runs() : 0; }
  uint64_t paired_runs() const { return worker_ ? worker_->paired_runs() : 0; }
  // steps solved again since construction (a contact without a row escaped: StepSolver::escaped)
  uint64_t redone() const { return redone_; }

 private:
  void reference_frame(StepContext& ctx);
  // its per-contact parts, contacts [lo, hi) (in_parts)
  void frame_contacts(const StepContext& ctx, int64_t lo, int64_t hi);
  void impact_contacts(const StepContext& ctx, int64_t lo, int64_t hi);
  void allow_contacts(const StepContext& ctx, int64_t lo, int64_t hi);
  static double resting_speed(const uint8_t* loaded, int64_t a, int64_t b, double then,
                              double now, double floor, double factor);
  double held_resting(const StepContext& ctx, int64_t k, double then, double resting) const;
  // an unsettled contact's before_ and resting_speed_ (frame_contacts leaves them to this:
  // unsettled_), once
  void settle(const StepContext& ctx, int64_t k);
  double longest_substep(const StepContext& ctx, int32_t depth);   // s: the substeps' bound
  void prepare(StepContext& ctx);
  double warm(StepContext& ctx, int substeps);   // returns the fraction of persistent
                                                 // contacts cold
  // whether this step's rows may start from the cache's impulses (warm)
  bool warmable(const StepContext& ctx) const;
  // the cache's impulses of this step's contacts (cached_normal_, cached_friction_, found_),
  // where warmable: once a step (the cache changes only at its end)
  void recall(const StepContext& ctx);
  int32_t levels(StepContext& ctx);   // contact levels (level_); returns the largest
  // returns the sweeps; the last substep's last `shared` sweeps are left to land
  int soft_step(StepContext& ctx, int substeps, int iterations, int shared);
  // The net under prepare's row bound, at the step's end: true when a contact without a
  // row ends the step closer than touching (its gap at the reference time plus how far the
  // substeps moved its points along the normal, moved_) or, after a landing (`landed`),
  // approaches faster than its allowance: its row would have carried an impulse. Each such
  // is marked in forced_ (a row from then on).
  bool escaped(const StepContext& ctx, bool landed);
  // escaped's check of the contacts without a row rowless_[lo, hi): marks those that
  // escaped in forced_; returns whether one did
  bool escaped_part(const StepContext& ctx, bool landed, int64_t lo, int64_t hi);
  // A contact of two spheres, one pressed onto the other from the start, without an
  // impact in the step (aimed_), is aimed along the line of their centres where the solve
  // moves them: at their previous poses plus `moved` (N, 6; null: none), plus half a
  // substep `half` (s) at `velocity` (N, 6; null: none): its row's frame (the friction
  // impulse kept as a vector) and spin row anew where that line leans from its normal by
  // more than aim_turn (turned_), and its separation there (aimed_gap_).
  // The normal at the middle of a motion is perpendicular to its chord between two points
  // of the sphere of the radii's sum: a velocity along that surface keeps the gap
  // (detection's normal, from the input pose that the source dropped by g dt^2, leaned
  // downhill and took a ball rolling off a fixed ball deeper every step)
  void aim(StepContext& ctx, const double* moved, const double* velocity, double half);
  void to_travel(StepContext& ctx, int substeps);  // impacted bodies: + (1 - f) / 2 external change;
                                     // rested ones: the whole of it
  int hold_energy(StepContext& ctx, int iterations);   // returns the sweeps done again
  // The manifolds the sweeps visit (active set with verification): a manifold is left out
  // while every row of it is idle, no impulse held (+0) and separating faster than its
  // allowance by more than `margin` (m/s), and its spin row holds no torque: its update
  // would change nothing. admit lets in each manifold left out that is no longer so
  // (monotone within a step) and plans the sweeps again; returns true when one came in.
  // sweep solves the swept manifolds (solve_velocities, `iterations` sweeps) after
  // admitting by `share` times activation_margin (a substep's all of it, the landing's
  // 1 / substeps: StepSolver::land), then admits by margin 0 every manifold the solved
  // velocities drive beyond its allowance (or that gained impulse) and, if one came in,
  // solves again from the velocities and impulses it started from, until none: every
  // manifold left out is idle in the answer (it carries nothing and approaches no faster
  // than its allowance), and the answer is the bits of sweeping all of them whenever the
  // ones left out stay idle throughout (a manifold idle at each visit changes nothing).
  // Returns the sweeps done (every round's).
  // Neither check tests a manifold whose answer is known: `verify` (the check after the
  // sweeps, margin 0) passes over one whose bodies' changes of speed since the sweeps'
  // start (from_velocity_) cannot have taken half its slack_ then; the check at a sweep's
  // start (verify false), over one left out at the last start that holds no impulse and
  // whose rows' speed_ less those changes, plus their allowances now, stay beyond the
  // margin. Both answers are the test's (still out): the same bits.
  bool admit(StepContext& ctx, double margin, bool verify);
  // after a substep's sweeps, shock propagation and hold_energy (and the landing's): each
  // island of two or more movable bodies and at most exact_rows rows (not driven) whose
  // contacts gave it more mechanical energy than exact_work in the substep is solved
  // exactly (IslandSolve) from the substep's start velocities (start_) and the spin rows'
  // torques, and so in the later substeps (and steps) until its sweeps have given it no
  // more than exact_quiet for exact_hold, or its set is not found; one whose first solve
  // found no set is not solved again for exact_hold (its next solves found none either).
  // Each solve starts from the set its rows' last solve found (if in the substep before),
  // else, or where that start finds no set, from every row sticking. The gain: the kinetic
  // energy at the end (v1) less at the start without the substep's share of the external
  // change c, less M c . v1 (a body resting under gravity: none; a converged inelastic
  // solve: at most none). `share`: the substep's share of a ramped body's change (ramp_);
  // `elapsed`: the substep's time (s; the landing: 0). Returns the islands whose exact
  // answer was taken
  int exact_islands(StepContext& ctx, double share, double elapsed);
  void block(size_t manifold);   // prepare_block of manifolds_[manifold], once a step
  bool idle(const Manifold& manifold) const;   // no impulse held (+0), no spin torque
  // `saved`: the rows' impulses are in from_impulse_ already (soft_step's pass)
  int sweep(StepContext& ctx, int iterations, double share = 1.0, bool saved = false);
  // (after soft_step: it gives every row the step's allowance, allowance_, again)
  // true when it swept (a landing row, or `shared`); `struck`: a landing row closed faster
  // than the restitution threshold and was newly marked in struck_ (an impact when solved
  // again)
  // `shared` > 0: the last substep's last `shared` sweeps (soft_step left them), with or
  // without a landing row, instead of velocity_iterations sweeps after the substeps
  bool land(StepContext& ctx, int substeps, int shared, bool& struck);
  // the sweeps' plan_ of swept_: waves (sweep_waves.h), wide groups, threads
  void plan_sweeps(StepContext& ctx);
  Worker* worker();   // the second thread, started at its first use
  // rows a substep's warm start takes before soft_step's pass over them (20 KB: in the
  // first level cache)
  static constexpr size_t kWarmRows = 32;
  // part(lo, hi) over [0, count) of independent items (each part writes only its items'
  // entries): in kParts parts on the two threads with threads 2 and parts of at least
  // parallel_wave items, else at once here
  static constexpr int kParts = 8;
  void in_parts(const StepContext& ctx, int64_t count,
                const std::function<void(int64_t, int64_t)>& part);
  // here() on this thread and there() on the second one at once (they share no data), with
  // threads 2 and at least kParts parallel_wave contacts (Worker::run_pair, run `kind`:
  // each pairing its own, kBeside...); else one after the other, here
  static constexpr int kBesideStore = 2;   // the cache's store beside the push-out
  static constexpr int kBesideRecall = 4;  // recall beside the impacts to the travel
  static constexpr int kBesideShock = 5;   // shock_rows beside the first warm start
  void beside(const StepContext& ctx, const std::function<void()>& here,
              const std::function<void()>& there, int kind);
  void report(StepContext& ctx);
  // report's passes over the contacts [lo, hi) (their impulses and states, the warm start's
  // cache) and over the manifolds [lo, hi) (sticking -> resting where balanced)
  void report_contacts(const StepContext& ctx, int64_t lo, int64_t hi);
  void report_manifolds(const StepContext& ctx, int64_t first, int64_t last) const;
  void advance(StepContext& ctx);
  void push_out(StepContext& ctx);

  ContactCache cache_;
  double last_dt_ = 0.0;              // s, dt of the step the cache holds
  // how many times the last step's impulses this step's need (reference_frame): the
  // load of the bodies in contact over theirs last step, where a body's load is the
  // momentum m |dv| the step's external change dv of its linear twist gives it (N s); dt
  // / last dt when there is none (no gravity, nothing in contact). A source that
  // integrated one period while the step spans k of them (inputs dropped on the way)
  // gives its bodies one period's load, whatever dt says
  double growth_ = 1.0;
  std::vector<double> load_, last_load_;   // (N,) N s, this and the last step's loads
  bool last_warm_ = false;            // that step was not fresh: its impulses may seed
  // per body (scratch, reused across steps)
  std::vector<double> velocity_;     // (N, 6) working velocity
  std::vector<double> travel_;       // (N, 6) velocity the poses advance with (before landing)
  std::vector<double> now_;          // (N, 6) current twist (held, non-finite: 0)
  std::vector<double> then_;         // (N, 6) previous twist (held, non-finite: 0)
  std::vector<double> pseudo_;       // (N, 6) split-impulse pseudo velocity
  std::vector<double> moved_;        // (N, 6) m, rad: displacement and turn (soft_step)
  std::vector<double> total_;        // (rows, 3) N s: the substeps' summed impulses
  std::vector<double> start_;        // (N, 6) velocity before the warm start
  std::vector<double> resting_;      // (N, 6) velocity the resting solve starts from (after
                                     // the impact stages, before the first warm start)
  std::vector<double> later_;        // (N, 6) pre-solve velocity, rested bodies' current
  std::vector<int32_t> island_;      // (N,) island root (hold_energy; the rows' islands,
                                     // found at its first call of a step)
  bool islands_ = false;             // island_ holds this step's islands (and inertia_ the
                                     // world inertias of its movable bodies in contact)
  std::vector<Mat3> inertia_;        // (N,) kg m^2, world frame: inv_inertia_^-1 (hold_energy)
  std::vector<double> gain_;         // (N, 2) J, per island root: the energy change, the
                                     // energy before (-1: driven, not judged)
  std::vector<int32_t> driven_;      // island roots pushed by a moving immovable body (found
                                     // with the islands)
  std::vector<double> fraction_;     // (N,) reference fraction of the step
  std::vector<int64_t> earliest_;    // (N,) its earliest detected impact (-1: none)
  std::vector<uint8_t> touched_, impacted_;
  std::vector<uint8_t> rested_;      // (N,) touching something from the start, no impact
  std::vector<uint8_t> ramped_;      // (N,) rested, in a row and touching something it was
                                     // not leaving faster than the restitution threshold,
                                     // the change making a point of one of its rows faster:
                                     // the external change a share per substep
  std::vector<uint8_t> moving_;      // (N,) a point of one of its rows faster than the
                                     // sticking speed before the step
  std::vector<double> ramp_;         // (N, 6) a ramped body's change spread over the
                                     // substeps (its stop taken at once, to_travel)
  std::vector<uint8_t> loaded_;      // (N,) the step's external change acts on it (current
                                     // and previous twists differ) or is unknown (its pose
                                     // stayed, its twist moves it: a fresh start): the
                                     // resting speed's floor applies to its contacts
  std::vector<uint8_t> supported_;   // (N,) touching something from the start (held by it
                                     // until an impact: moves with its previous twist)
  std::vector<double> path_;         // (N, 6) twist on the held paths (supported: previous)
  std::vector<uint8_t> pressed_;     // (M,) within the slop at the previous state, neither
                                     // approaching nor leaving faster than the threshold,
                                     // the step's external change pressing one body into
                                     // the other (what makes its bodies supported_)
  std::vector<uint8_t> touching_;    // (M,) persistent, within the slop at the previous state
  std::vector<uint8_t> unsettled_;   // (M,) persistent, beyond the slop at the previous state,
                                     // its before_ and resting_speed_ not yet found (settle),
                                     // nor ever its start_speed_ (read within the slop only)
  std::vector<uint8_t> near_;        // (N,) movable, a persistent contact within the slop at
                                     // the previous state (approaching or not)
  std::vector<Mat3> inv_inertia_;    // (N,) world frame
  std::vector<std::array<Vec3, 2>> motion_;   // (N,) of a body in contact (touched_): its
                                     // centre's travel over the step (m) and its turn as a
                                     // rotation vector (rad), from the poses
  // per contact (scratch)
  std::vector<Vec3> ra_, rb_;
  std::vector<Vec3> travelled_;      // (M, 2) m: how far the points of A and B travelled
                                     // over the step (reference_frame)
  std::vector<double> before_;       // m/s: normal speed at the previous twists (< 0
                                     // approaching; reference_frame)
  std::vector<double> gap_, remaining_, allowance_, toi_, approach_;
  std::vector<double> start_speed_;  // m/s: normal speed at the step's start, the mean of the
                                     // previous and current twists' (< 0 approaching)
  std::vector<double> resting_speed_;   // m/s: per contact, slower approaches rest (do not
                                        // bounce): reference_frame (an unsettled_ one: settle)
  std::vector<double> drift_;        // m: how much more the separation grows over the step
                                     // on the held paths than on the integrated ones
  std::vector<double> moved_a_;      // m: how far A's point moves along the normal over the
                                     // step on its path (A's part of closed + drift_)
  std::vector<double> span_;         // s: the time a row's allowance spans (> 0)
  std::vector<int32_t> level_far_;   // (N,) stack levels over every row (levels)
  std::vector<double> accel_;        // (N,) m/s^2: external acceleration (longest_substep)
  std::vector<double> speeds_;       // (N, 2) m/s, rad/s: previous linear, angular speed
                                     // (to_travel)
  std::vector<uint8_t> adjacent_near_;   // per adjacency_ entry: over a near row (levels)
  std::vector<uint8_t> impact_;
  std::vector<int32_t> row_of_;      // row index per contact, -1 when no row
  std::vector<int32_t> aimed_;       // the rows that aim turns: two spheres, one row,
                                     // pressed_, no impact in the step
  std::vector<uint8_t> aiming_;      // (rows) 1: in aimed_
  std::vector<uint8_t> turned_;      // (rows) 1: its frame turned by the last aim (its
                                     // centres' line leaned from its normal by more than
                                     // aim_turn)
  std::vector<double> aimed_gap_;    // (rows) m: an aimed row's separation where aim
                                     // measured it
  std::vector<int32_t> rowless_;     // the contacts without a row (prepare)
  std::vector<int32_t> placed_;      // (K + 1, 2) prepare: the rows and the constraints of
                                     // detection's manifolds before each one
  std::vector<uint8_t> forced_;      // (M,) 1: a row whatever the bound (the net let it in)
  std::vector<uint8_t> struck_;      // (M,) 1: a speculative contact the impact stages take
                                     // (land found it closing faster than the threshold)
  std::vector<double> pre_;          // (N, 6) pre-solve velocities (a redo starts from them)
  std::vector<double> reach_body_;   // (N,) m: the farthest contact point from its centre
  double fastest_ = 0.0;             // m/s: the step's fastest pre-solve approach (approach_)
  double restitution_ = 0.0;         // the largest restitution of a body in contact
  uint64_t redone_ = 0;
  std::vector<double> cached_normal_, cached_friction_, impact_work_, landing_;
  std::vector<uint8_t> found_;
  bool recalled_ = false;            // cached_normal_, ... hold this step's (recall)
  std::vector<ContactRow> rows_, shock_rows_;
  std::vector<Manifold> manifolds_, impact_blocks_;  // constraints over rows_ / shock_rows_
                                                     // (manifolds_ in detection's order)
  std::vector<BlockMatrices> matrices_, impact_matrices_;   // their blocks' matrices
                                                            // (manifolds_: by index, block())
  std::vector<double> friction_;     // (manifolds_, 2) its pair's static and kinetic
                                     // friction coefficients (prepare)
  std::vector<int32_t> manifolds_of_;  // (N,) how many of manifolds_ each body is in (prepare)
  ShockBlocks shock_blocks_;                         // shock_rows_' blocks (shock_rows)
  std::vector<uint8_t> holding_;                     // (shock_rows' scratch, per body)
  std::vector<Manifold> swept_;      // the manifolds in the sweeps, in plan_'s order
  std::vector<int32_t> chosen_;      // their indices in manifolds_, ascending (admit)
  std::vector<uint8_t> in_;          // (manifolds_) 1: in the sweeps this step (admit)
  std::vector<uint8_t> blocked_;     // (manifolds_) 1: prepare_block done (at admission,
                                     // or for hold_energy's retry)
  // (manifolds_) for a manifold left out at a sweep's start: its least normal speed plus
  // allowance then (m/s, > the margin), and the largest lever of its rows on A and on B
  // (m); (N, 2) each body's change of linear and angular speed since (m/s, rad/s): the
  // check after the sweeps skips a manifold whose rows cannot have closed by half of it
  std::vector<double> slack_, reach_, change_;
  // (rows) a row's normal speed at the last sweeps' start, or a bound below it (m/s), for
  // a manifold left out then; the check at a sweep's start skips a manifold whose rows
  // stay beyond the margin with the bodies' changes of speed since (known_: after the
  // step's first check)
  std::vector<double> speed_;
  bool known_ = false;
  std::vector<double> from_velocity_, from_impulse_, from_spin_;   // what sweep started
                                     // from: velocities (N, 6), the rows' normal and
                                     // friction impulses (rows, 3), the spin rows' torque
                                     // and load (spins, 4)
  std::vector<Manifold> retry_;      // manifolds of the islands solved again (hold_energy)
  // exact_islands: per island root, its rows and movable bodies (found once a step, with
  // the islands: small_ false until then); per root, the substep's gain of mechanical
  // energy (J), its hold and its lapse (island_quiet_, island_lapse_); per body, its
  // island's hold: how long it has been held without a gain beyond exact_quiet, and its
  // lapse: how long since its first solve found no set (s; -1: not held, no lapse), kept
  // from step to step (quiet_, lapse_; as the step found them: quiet_then_, lapse_then_);
  // the islands solved: their slots (per root), rows, bodies and roots; the velocities
  // their impulses act on (N, 6)
  bool small_ = false;
  std::vector<int32_t> island_rows_, island_bodies_;
  std::vector<double> gain_exact_, island_quiet_, quiet_, quiet_then_;
  std::vector<double> island_lapse_, lapse_, lapse_then_;
  std::vector<int32_t> exact_slot_, exact_root_;
  std::vector<uint8_t> exact_held_;
  std::vector<std::vector<int32_t>> exact_rows_, exact_bodies_;
  std::vector<double> base_;
  IslandSolve island_solve_;
  // the active set each exact solve of the last substep that solved any found (none where
  // it found none), per contact (its bodies a < b and feature): its row's
  // IslandSolve::State and a sliding row's friction direction (unit, world), where the
  // next solve of its island starts (as the step found it: exact_set_then_; the
  // substep's: exact_next_); a solve's set (its rows: R states, (R, 2) friction
  // directions along t1, t2)
  struct ExactSet {
    uint8_t state;
    Vec3 along;
  };
  std::map<std::array<int64_t, 3>, ExactSet> exact_set_, exact_set_then_, exact_next_;
  std::vector<uint8_t> exact_state_;
  std::vector<double> exact_along_;
  std::vector<SpinRow> spins_;       // rolling resistance and torsional friction per manifold
  SweepPlan plan_;                   // the sweeps' waves (plan_sweeps)
  std::unique_ptr<Worker> worker_;   // the sweeps' second thread (threads >= 2)
  bool shared_ = false;              // the last step on two threads had its sweeps cut in
                                     // two sides
  WaveScratch waving_;               // plan_sweeps: scratch
  std::vector<int32_t> level_, queue_, adjacency_, first_, order32_;
};

}  // namespace collres
