#include "step.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <new>
#include <type_traits>

#include "sweep_waves.h"

namespace collres {
namespace {

// Twist (6 per body) of states; held bodies and non-finite entries read as 0.
void load_twists(const BodyStatesView& s, const BodyProperties& bodies, double* out) {
  for (int64_t i = 0; i < bodies.count; ++i) {
    for (int d = 0; d < 3; ++d) {
      double v = s.linear[3 * i + d], w = s.angular[3 * i + d];
      bool held = bodies.held[i] != 0;
      out[6 * i + d] = (!held && std::isfinite(v)) ? v : 0.0;
      out[6 * i + 3 + d] = (!held && std::isfinite(w)) ? w : 0.0;
    }
  }
}

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// Whether a row holds no impulse: its normal and friction impulses all +0 (not -0: a row
// holding -0 would be rewritten +0 by its update), tested on their bits at once
bool holds_nothing(const ContactRow& r) {
  uint64_t bits[3];
  std::memcpy(&bits[0], &r.normal, sizeof(double));
  std::memcpy(&bits[1], &r.tangent[0], sizeof(double));
  std::memcpy(&bits[2], &r.tangent[1], sizeof(double));
  return (bits[0] | bits[1] | bits[2]) == 0;
}

// A row's impulses (normal, tangent[0], tangent[1]: N s) stored at, or added to, at[0..2]
inline void save_impulses(const ContactRow& r, double* at) {
  at[0] = r.normal;
  at[1] = r.tangent[0];
  at[2] = r.tangent[1];
}
inline void add_impulses(const ContactRow& r, double* at) {
  at[0] += r.normal;
  at[1] += r.tangent[0];
  at[2] += r.tangent[1];
}

bool persistent(int8_t kind) { return kind == static_cast<int8_t>(ContactKind::persistent); }

// Normal velocity of B's point relative to A's (< 0 approaching) for A's twist at ta and
// B's at tb (6 each).
inline double normal_speed_of(const double* ta, const double* tb, const Vec3& ra, const Vec3& rb,
                              const Vec3& n) {
  Vec3 va = load3(ta) + cross(load3(ta + 3), ra);
  Vec3 vb = load3(tb) + cross(load3(tb + 3), rb);
  return dot(vb - va, n);
}

// ... for twists v (N, 6).
inline double normal_speed(const double* v, int64_t a, int64_t b, const Vec3& ra, const Vec3& rb,
                           const Vec3& n) {
  return normal_speed_of(v + 6 * a, v + 6 * b, ra, rb, n);
}

// How body i moved over the step, from the poses (a step of several periods that its source
// integrated under gravity is no straight line at the twist): (shift, turn), its centre's
// travel (m) and its turn q1 q0^-1 as a rotation vector (rad; an estimator's pose turned
// with a zero twist: a push-out from the last answer that turned a body must see that turn,
// or it pushes again every step and the body keeps turning into its neighbours)
std::array<Vec3, 2> body_motion(const BodyStatesView& previous, const BodyStatesView& current,
                                int64_t i) {
  const Quat turn = multiply(load4(current.orientation + 4 * i),
                             load4(previous.orientation + 4 * i).conjugate());
  return {Vec3(load3(current.position + 3 * i) - load3(previous.position + 3 * i)),
          to_rotation_vector(turn)};
}

// m: how far the point at r from a body's current centre of mass travelled over the step,
// from its motion (body_motion), to first order (a curved surface's contact point is no
// material point: a rolling ball's does not rise)
Vec3 travelled(const std::array<Vec3, 2>& motion, const Vec3& r) {
  return motion[0] + cross(motion[1], r);
}

}  // namespace

StepStats StepSolver::step(const BodyStatesView& previous, const BodyStatesView& current,
                           const BodyProperties& bodies, const ContactsView& contacts,
                           double dt, bool warm_enabled, const SolverParams& params,
                           BodyStatesOut& out, ContactsOut& report_out) {
  // the second thread spins between its runs while the step is on (Worker::stay: its
  // runs come with serial stages between them), woken now: where the last step on two
  // threads had its sweeps cut in two sides (a pile too small for that, 100 bodies, pays
  // more for the wake than its per-contact passes gain)
  struct Stay {
    Worker* worker;
    ~Stay() {
      if (worker != nullptr) worker->stay(false);
    }
  } stay{params.threads >= 2 && shared_ ? worker() : nullptr};
  if (stay.worker != nullptr) stay.worker->stay(true);
  const int64_t n = bodies.count;
  velocity_.resize(6 * n);
  pseudo_.resize(6 * n);
  inv_inertia_.resize(n);
  for (int64_t i = 0; i < n; ++i)
    inv_inertia_[i] = rotate_tensor(load4(current.orientation + 4 * i),
                                    bodies.inv_inertia_body + 9 * i);
  StepContext ctx{previous, current, bodies, contacts, dt, warm_enabled, params,
                  SolverBodies{n, bodies.inv_mass, inv_inertia_.data(), velocity_.data()},
                  out, report_out};
  // reference time of each contact and body, pre-solve velocities, speculative allowance
  reference_frame(ctx);
  // the stages from prepare to the landing, again (from the pre-solve velocities) while a
  // contact without a row escapes (escaped): it gets a row
  pre_.assign(velocity_.begin(), velocity_.end());
  // (an island's hold, lapse and set, as the step found them: again for a step solved
  // again)
  if (quiet_.size() != static_cast<size_t>(n)) quiet_.assign(n, -1.0);
  if (lapse_.size() != static_cast<size_t>(n)) lapse_.assign(n, -1.0);
  quiet_then_.assign(quiet_.begin(), quiet_.end());
  lapse_then_.assign(lapse_.begin(), lapse_.end());
  exact_set_then_ = exact_set_;
  forced_.assign(static_cast<size_t>(contacts.count), 0);
  struck_.assign(static_cast<size_t>(contacts.count), 0);
  recalled_ = false;
  StepStats stats;
  for (;; ++stats.redone) {
    if (stats.redone > 0) {
      std::copy(pre_.begin(), pre_.end(), velocity_.begin());
      std::copy(quiet_then_.begin(), quiet_then_.end(), quiet_.begin());
      std::copy(lapse_then_.begin(), lapse_then_.end(), lapse_.begin());
      exact_set_ = exact_set_then_;
    }
    // prepare: rows of the contacts that can carry an impulse, combined materials
    prepare(ctx);
    // impacts: successive stages of the rows approaching faster than the threshold
    ImpactSettings impacts{resting_speed_.data(), params.impact_stages,
                           params.impact_sweeps, params.impact_converged, params.shock_ratio};
    // a speculative row of a supported body closes on the held paths (reference_frame's
    // closing test) by drift_ less than its bodies' velocities say: the stages see that
    // allowance, or a body hopping within the slop of its floor, held above it, bounced
    // where it was (no rewind: it never reached the floor) and rose higher each hop
    for (ContactRow& r : rows_)
      if (!impact_[r.contact] && gap_[r.contact] > 0.0 && drift_[r.contact] > 0.0)
        r.allowance = (gap_[r.contact] + drift_[r.contact]) / span_[r.contact];
    // a speculative contact that the last solve closed within the step faster than the
    // threshold (struck_, land) is an impact: the stages take it from the reference time
    // (it bounces with its restitution, its gap not yet closed)
    for (ContactRow& r : rows_)
      if (struck_[r.contact]) r.allowance = 0.0;
    // (the cache's impulses of the contacts meanwhile on the second thread, for the warm
    // start: recall reads the contacts and the cache, writes only its own)
    int32_t depth = 0;
    int substeps = 1;
    beside(ctx, [&] {
      resolve_impacts(rows_, ctx.solver, impacts, shock_rows_, impact_blocks_,
                      impact_matrices_, order32_, impact_work_);
      for (ContactRow& r : rows_) r.allowance = allowance_[r.contact];
      // from here on an impacted body's velocity is the one its pose travels with over the
      // rest of the step (its velocity at the time of impact plus half the external change
      // over the rest, advance): the resting solve keeps that travel out of the partners
      // substeps of the resting solve: as many as keep each within params.max_substep,
      // and within sqrt(substep_sink r / a) for every solver row (a a movable body's
      // external acceleration, r the row's lever from its centre of mass), and within
      // sqrt(stack_sink r / a) / D (D the levels of the deepest stack)
      depth = levels(ctx);
      substeps = static_cast<int>(std::clamp(
          std::ceil(dt / longest_substep(ctx, depth) * (1.0 - 1e-6)), 1.0,
          static_cast<double>(std::max(params.max_substeps, 1))));
      to_travel(ctx, substeps);
    }, [&] { recall(ctx); }, kBesideRecall);
    aim(ctx, nullptr, velocity_.data(), 0.5 * dt / substeps);
    // warm start from last step's impulses of the same pair and feature (a substep's share)
    double cold = warm(ctx, substeps);
    start_.assign(velocity_.begin(), velocity_.end());
    resting_.assign(velocity_.begin(), velocity_.end());
    // the rows' copies for shock propagation meanwhile on the second thread (for every
    // substep of the solve: shock_rows reads the rows and their levels, which the warm
    // start leaves as they are, and writes only its own)
    beside(ctx, [&] { warm_start(rows_.data(), rows_.size(), ctx.solver); }, [&] {
      shock_rows(rows_, level_, order32_, shock_rows_, shock_blocks_, holding_,
                 params.shock_ratio, params.wide_rows);
    }, kBesideShock);
    // iterate: sequential impulses (more sweeps while resting contacts are new, for a step
    // k periods long sqrt(k) times as many: a load k times the last, whose residual sinks
    // the poses k^2 times as far, and at least depth_sweeps per level of the deepest
    // stack), then shock propagation from the ground up
    const double stretch = std::sqrt(std::clamp(growth_, 1.0, params.warm_start_ratio));
    int iterations = static_cast<int>(
        std::lround(params.velocity_iterations * (1.0 + params.cold_extra * cold) * stretch));
    iterations = std::max(iterations, static_cast<int>(std::lround(params.depth_sweeps * depth)));
    stats.rows = static_cast<int64_t>(rows_.size());
    stats.substeps = substeps;
    // the landing's sweeps: from landing_substeps substeps on, the last substep's last
    // landing_sweeps; fewer substeps: velocity_iterations sweeps after them (land)
    const int shared = substeps >= params.landing_substeps ? params.landing_sweeps : 0;
    stats.sweeps += soft_step(ctx, substeps, iterations, shared);
    // landing: the poses travel with the substeps' mean velocity; a speculative contact that
    // closes within the step ends it touching, and with no approach left for the next step
    bool struck = false;
    const bool landed = land(ctx, substeps, shared, struck);
    if (!escaped(ctx, landed) && !struck) break;
  }
  redone_ += static_cast<uint64_t>(stats.redone);
  for (size_t i = 0; i < rows_.size(); ++i) {   // the step's impulses: the substeps' sums
    rows_[i].normal += total_[3 * i];
    rows_[i].tangent[0] += total_[3 * i + 1];
    rows_[i].tangent[1] += total_[3 * i + 2];
  }
  // store impulses for next step's warm start, then report them
  report(ctx);
  last_dt_ = dt;
  last_load_.swap(load_);
  last_warm_ = warm_enabled;
  // correct poses: rewind / advance, then the split-impulse push-out (no velocity); the
  // cache's store meanwhile on the second thread (it reads the report, writes only itself)
  beside(ctx, [&] {
    advance(ctx);
    push_out(ctx);
  }, [&] {
    cache_.store(contacts.count, contacts.a, contacts.b, contacts.feature,
                 cached_normal_.data(), report_out.friction_impulse, contacts.point);
  }, kBesideStore);
  // (a step on one thread cuts no sweep for two: it leaves what the last step on two
  // threads found, so that the next one, on two, stays as that one would have)
  if (plan_.worker != nullptr)
    shared_ = std::find(plan_.sides.begin(), plan_.sides.end(), 1) != plan_.sides.end();
  return stats;
}

double StepSolver::longest_substep(const StepContext& ctx, int32_t depth) {
  // a substep's residual sinks a body by a fraction of a h^2; across a small body's
  // contacts that tilts it by that over their lever, which a tall stack of it amplifies
  // (20 cubes of 1 cm fell at 30 and 50 Hz with 6.7 ms substeps, stood with 4.5 ms); a
  // stack depth levels tall tips over its lowest contacts with depth times the weight at
  // depth times the lever (20 cubes of 5 cm swayed and fell at 60 Hz with 5.6 ms substeps)
  double longest = std::max(ctx.params.max_substep, 1e-300);
  double sink = ctx.params.substep_sink;
  if (ctx.params.stack_sink > 0.0) {
    const double levels = std::max(static_cast<double>(depth), 1.0);
    const double stack = ctx.params.stack_sink / (levels * levels);
    if (!(sink > 0.0) || stack < sink) sink = stack;
  }
  if (!(sink > 0.0)) return longest;
  // each movable body's external acceleration (m/s^2), once a body (not once a row of it)
  const int64_t n = ctx.bodies.count;
  accel_.resize(n);
  for (int64_t i = 0; i < n; ++i)
    accel_[i] = ctx.bodies.inv_mass[i] == 0.0
                    ? 0.0
                    : length(load3(now_.data() + 6 * i) - load3(then_.data() + 6 * i)) / ctx.dt;
  auto bound = [&](int64_t i, const Vec3& lever) {
    if (ctx.bodies.inv_mass[i] == 0.0) return;
    const double a = accel_[i];
    const double reach = length(lever);
    if (a * longest * longest > sink * reach) longest = std::sqrt(sink * reach / a);
  };
  for (const ContactRow& r : rows_) {
    bound(r.a, ra_[r.contact]);
    bound(r.b, rb_[r.contact]);
  }
  return std::max(longest, 1e-300);
}

COLLRES_CLONED
void StepSolver::reference_frame(StepContext& ctx) {
  // (the views by value, and below the flags' data: a store of a flag, a byte, may alias
  // anything in memory, so that otherwise every array's address was loaded again after it)
  const BodyStatesView previous = ctx.previous, current = ctx.current;
  const BodyProperties bodies = ctx.bodies;
  const ContactsView c = ctx.contacts;
  const double dt = ctx.dt;
  const double slop = ctx.params.linear_slop;
  const int64_t n = bodies.count, m = c.count;
  now_.resize(6 * n);
  then_.resize(6 * n);
  load_twists(current, bodies, now_.data());
  load_twists(previous, bodies, then_.data());
  ra_.resize(m);
  rb_.resize(m);
  travelled_.resize(2 * m);
  before_.resize(m);
  gap_.resize(m);
  toi_.resize(m);
  impact_.resize(m);
  remaining_.resize(m);
  span_.resize(m);
  allowance_.resize(m);
  touching_.resize(m);
  unsettled_.resize(m);
  moved_a_.resize(m);
  near_.assign(n, 0);
  fraction_.assign(n, 1.0);           // earliest time of impact per body (1: none)
  touched_.assign(n, 0);
  impacted_.assign(n, 0);
  rested_.assign(n, 0);
  supported_.assign(n, 0);
  motion_.resize(n);
  approach_.resize(m);
  start_speed_.resize(m);
  resting_speed_.resize(m);
  for (int64_t k = 0; k < m; ++k) touched_[c.a[k]] = touched_[c.b[k]] = 1;
  uint8_t *const touching = touching_.data(), *const rested = rested_.data();
  uint8_t *const near = near_.data(), *const supported = supported_.data();
  pressed_.assign(m, 0);
  const uint8_t* const pressed = pressed_.data();
  const double *const gap = gap_.data(), *const before = before_.data();
  const double* const resting = resting_speed_.data();
  // per body (each writes only its own entries: in parts): a body in contact's motion, and
  // whether the step's external change acts on it (external_change_acts: a pile restarted
  // after a gap, its twists the source's g dt into the supports, bounced on that approach
  // before unknown changes counted)
  loaded_.resize(n);
  in_parts(ctx, n, [&](int64_t lo, int64_t hi) {
    const double *const now = now_.data(), *const then = then_.data();
    for (int64_t i = lo; i < hi; ++i) {
      if (touched_[i]) motion_[i] = body_motion(previous, current, i);
      bool changed = false, moving = false, moved = false;
      for (int d = 0; d < 6; ++d) {
        changed = changed || now[6 * i + d] != then[6 * i + d];
        moving = moving || now[6 * i + d] != 0.0;
      }
      for (int d = 0; d < 3; ++d)
        moved = moved || previous.position[3 * i + d] != current.position[3 * i + d];
      for (int d = 0; d < 4; ++d)
        moved = moved || previous.orientation[4 * i + d] != current.orientation[4 * i + d];
      loaded_[i] = external_change_acts(changed, moving, moved);
    }
  });
  // per contact (frame_contacts), shared by the two threads; the bodies' flags after
  in_parts(ctx, m, [&](int64_t lo, int64_t hi) { frame_contacts(ctx, lo, hi); });
  // the bodies' flags, from their contacts: resting on one from the start, near, supported;
  // and each body's earliest detected impact (-1: none)
  earliest_.assign(n, -1);
  int64_t* const earliest = earliest_.data();
  for (int64_t k = 0; k < m; ++k) {
    const int64_t a = c.a[k], b = c.b[k];
    if (!persistent(c.kind[k])) {
      for (const int64_t i : {a, b})
        if (earliest[i] < 0 || c.toi[k] < c.toi[earliest[i]]) earliest[i] = k;
    }
    if (touching[k]) rested[a] = rested[b] = 1;
    // The gap then is measured along the current normal, a lower bound of the true one:
    // two balls that pass each other fast turn their normal over the step and read as
    // deep then though they were apart. So a pair leaving faster than the threshold is
    // not near (its speculative rows measured from the later reference time: stopped
    // short of a partner's late impact), and one leaving or approaching that fast is no
    // support (held by it, below): taken as each other's support, a ball that a third
    // hit within the step was held on the other as on a floor, one-sidedly (30 Hz elastic
    // gas: 1.4 N s of momentum made, 12 % of the three's energy lost in a step)
    if (persistent(c.kind[k]) && gap[k] <= slop && before[k] <= resting[k])
      near[a] = near[b] = 1;
    if (pressed[k]) supported[a] = supported[b] = 1;
  }
  for (int64_t i = 0; i < n; ++i) {
    rested_[i] = rested_[i] && bodies.movable[i] != 0;
    near_[i] = near_[i] && bodies.movable[i] != 0;
  }
  // a supported body (resting on something from the start) is held by its supports until
  // an impact: its path over the step is its previous twist (x0 + s dt then, less any
  // approach into what holds it, below), not the one
  // its source integrated under the step's external change (through its supports, g dt^2
  // at a step of 1/30 s: 11 mm); drift_: how much more a contact's separation grows over
  // the step on the held paths than on the integrated ones (m, 0 without a supported
  // body), and path_ the twists the bodies move with (supported: previous)
  for (int64_t i = 0; i < n; ++i) supported_[i] = supported_[i] && bodies.movable[i] != 0;
  path_.resize(6 * n);
  for (int64_t i = 0; i < 6 * n; ++i)
    path_[i] = supported_[i / 6] ? then_[i] : now_[i];
  // each settled contact's resting speed where a supported body holds the other
  // (held_resting); in the same pass, held: a supported body does not move into what holds
  // it (along the normal), a movable support taken as held still, an immovable or free one
  // as it moves
  double* const path = path_.data();
  double* const resting_of = resting_speed_.data();
  const double* const start = start_speed_.data();
  const Vec3 *const ra = ra_.data(), *const rb = rb_.data();
  const uint8_t* const unsettled = unsettled_.data();
  for (int64_t k = 0; k < m; ++k) {
    if (unsettled[k]) continue;   // (settle)
    resting_of[k] = held_resting(ctx, k, before[k], resting_of[k]);
    if (!persistent(c.kind[k]) || gap[k] > slop || std::abs(start[k]) > resting_of[k])
      continue;
    const int64_t a = c.a[k], b = c.b[k];
    const Vec3 normal = load3(c.normal + 3 * k);
    for (const int64_t i : {a, b}) {
      if (!supported[i]) continue;
      const int64_t other = i == a ? b : a;
      const Vec3 into = i == b ? normal : Vec3(-normal);   // from the support to i
      const Vec3 held = supported[other] ? Vec3::Zero() : load3(path + 6 * other);
      const double approach = dot(load3(path + 6 * i) - held, into);
      if (approach < 0.0) store3(path + 6 * i, load3(path + 6 * i) - approach * into);
    }
  }
  // the step's load: the momentum its external change gives each movable body (N s), and
  // its sum over the bodies in contact that had a load last step too, then and now
  load_.assign(n, 0.0);
  double load = 0.0, last_load = 0.0;
  for (int64_t i = 0; i < n; ++i) {
    if (!bodies.movable[i] || !(bodies.inv_mass[i] > 0.0)) continue;
    load_[i] = length(load3(now_.data() + 6 * i) - load3(then_.data() + 6 * i)) /
               bodies.inv_mass[i];
    if (touched_[i] && i < static_cast<int64_t>(last_load_.size()) && last_load_[i] > 0.0) {
      load += load_[i];
      last_load += last_load_[i];
    }
  }
  growth_ = load > 0.0 && last_load > 0.0 ? load / last_load : dt / std::max(last_dt_, 1e-300);
  drift_.resize(m);
  double *const toi_of = toi_.data(), *const fraction = fraction_.data();
  uint8_t *const impact_of = impact_.data(), *const impacted = impacted_.data();
  // per contact (impact_contacts), shared by the two threads; the bodies' impacts after
  in_parts(ctx, m, [&](int64_t lo, int64_t hi) { impact_contacts(ctx, lo, hi); });
  later_.resize(6 * n);
  for (int64_t k = 0; k < m; ++k) {
    if (!impact_of[k]) continue;
    const int64_t a = c.a[k], b = c.b[k];
    impacted[a] = impacted[b] = 1;
    fraction[a] = std::min(fraction[a], toi_of[k]);
    fraction[b] = std::min(fraction[b], toi_of[k]);
  }
  // per body (its own entries: in parts)
  in_parts(ctx, n, [&](int64_t lo, int64_t hi) {
    for (int64_t i = lo; i < hi; ++i) {
      bool movable = bodies.movable[i] != 0;
      touched_[i] = touched_[i] && movable;
      impacted_[i] = impacted_[i] && movable;
      rested_[i] = rested_[i] && !impacted_[i];
      double f = impacted_[i] ? std::clamp(fraction_[i], 0.0, 1.0) : 0.0;
      fraction_[i] = f;
      // pre-solve velocity: at the time of impact for impacted bodies (the twist of a
      // state is the velocity over the step that led to it, at mid-step); for a body
      // touching something from the start, its previous twist (what it did while in
      // contact: the step's external change is carried by the resting solve, to_travel),
      // also at its time of impact (held by its supports until then); else current; and
      // the twist its contacts' pre-solve approach takes (later_, below)
      for (int d = 0; d < 6; ++d) {
        double now = now_[6 * i + d], then = then_[6 * i + d], external = now - then;
        velocity_[6 * i + d] = impacted_[i] ? (supported_[i] ? path_[6 * i + d]
                                                             : now + (f - 0.5) * external)
                               : rested_[i] ? then
                                            : now;
        later_[6 * i + d] = rested_[i] ? now : velocity_[6 * i + d];
      }
    }
  });
  // speculative allowance. Two free bodies (neither within the slop of anything at the
  // step's start): the gap with each body at its own reference time, where the solve
  // moves it from (a body without an impact from the step's start, whatever its partner's
  // time), over the longest time either moves (the step less the earlier reference time),
  // so that no row lets its bodies close by more than its gap. (From the later reference
  // time, over the time left after it, a free body closed in on a partner's late impact
  // twice, on its path until then and again in the substeps, and was stopped short of it
  // inelastically: an elastic gas lost a fifth of its energy in 5 s at 120 Hz.) Else (a
  // body at rest or in a settled contact) the gap at the later of the two reference
  // times: a velocity row cannot move a settled body and its partner for different times
  // (with own times, piles after dropped inputs slept later and a column sank).
  // In the same pass: the pre-solve approach of each contact (a rested body's with the
  // step's external change, which the resting solve meets; a body without an impact: its
  // current twist). Per contact (allow_contacts), shared by the two threads; then, in one
  // pass, the
  // farthest contact point of each body, the fastest approach and the largest restitution
  // (prepare's row bound; the same for every solve of the step)
  in_parts(ctx, m, [&](int64_t lo, int64_t hi) { allow_contacts(ctx, lo, hi); });
  double fastest = 0.0, restitution = 0.0;
  reach_body_.assign(n, 0.0);   // (squared here)
  double* const reach = reach_body_.data();
  const double* const approach = approach_.data();
  for (int64_t k = 0; k < m; ++k) {
    const int64_t a = c.a[k], b = c.b[k];
    const Vec3 lever_a = ra[k], lever_b = rb[k];
    reach[a] = std::max(reach[a], dot(lever_a, lever_a));
    reach[b] = std::max(reach[b], dot(lever_b, lever_b));
    fastest = std::max(fastest, -approach[k]);
    restitution = std::max({restitution, bodies.restitution[a], bodies.restitution[b]});
  }
  fastest_ = fastest;
  restitution_ = restitution;
  for (int64_t i = 0; i < n; ++i) reach[i] = std::sqrt(reach[i]);
}

// The per-contact part of reference_frame for contacts [lo, hi) after the bodies' times:
// each one's gap at its reference time, the time left after it (remaining_, span_), its
// allowance and its pre-solve approach (approach_; settle for a contact of an impacted
// body); each writes only its own entries (on either thread: StepSolver::in_parts).
COLLRES_CLONED
void StepSolver::allow_contacts(const StepContext& ctx, int64_t lo, int64_t hi) {
  // (the arrays through local pointers, each value in a local and stored once: see
  // frame_contacts)
  const ContactsView c = ctx.contacts;
  const double dt = ctx.dt;
  const double* const fraction = fraction_.data();
  const uint8_t *const near_of = near_.data(), *const impacted = impacted_.data();
  const uint8_t* const impact_of = impact_.data();
  const double *const drift = drift_.data(), *const moved_a = moved_a_.data();
  const double *const later_of = later_.data(), *const toi_of = toi_.data();
  const Vec3 *const ra = ra_.data(), *const rb = rb_.data();
  double *const gap_of = gap_.data(), *const allowance = allowance_.data();
  double *const remaining_of = remaining_.data(), *const span = span_.data();
  double* const approach = approach_.data();
  for (int64_t k = lo; k < hi; ++k) {
    const int64_t a = c.a[k], b = c.b[k];
    const double later = std::max(fraction[a], fraction[b]);
    const bool own = !near_of[a] && !near_of[b];
    const double fa = own ? fraction[a] : later, fb = own ? fraction[b] : later;
    const double remaining = std::max((1.0 - std::min(fa, fb)) * dt, 1e-9 * dt);
    const double closed = allowance[k], moved_b = closed + drift[k] + moved_a[k];
    // an impact's own rows touch at its time of impact; its speculative corners (detected
    // impact rows with a positive separation) are that far from touching then; a demoted
    // impact: from the start
    const double gap_k = impact_of[k]
                             ? (persistent(c.kind[k]) ? 0.0 : std::max(c.separation[k], 0.0))
                         : fa == fb ? gap_of[k] + (closed + drift[k]) * fa
                                    : gap_of[k] + fb * moved_b - fa * moved_a[k];
    gap_of[k] = gap_k;
    remaining_of[k] = impact_of[k] ? (1.0 - toi_of[k]) * dt : remaining;
    span[k] = remaining;
    allowance[k] = std::max(gap_k, 0.0) / remaining;
    if (impacted[a] || impacted[b]) {
      settle(ctx, k);   // (before its approach_ changes: settle reads frame_contacts's)
      approach[k] = normal_speed(later_of, a, b, ra[k], rb[k], load3(c.normal + 3 * k));
    }
  }
}

// The per-contact part of reference_frame for contacts [lo, hi): their levers (ra_, rb_),
// travel, gaps, approach before, now and at the step's start, resting speed, touching_ and
// pressed_; each writes only its own entries (on either thread: StepSolver::in_parts).
COLLRES_CLONED
void StepSolver::frame_contacts(const StepContext& ctx, int64_t lo, int64_t hi) {
  // (the views by value, the arrays' data in locals: a store of a flag, a byte, may alias
  // anything in memory)
  const BodyStatesView previous = ctx.previous, current = ctx.current;
  const BodyProperties bodies = ctx.bodies;
  const ContactsView c = ctx.contacts;
  const double slop = ctx.params.linear_slop, sticking = ctx.params.sticking_speed;
  const double floor = ctx.params.restitution_threshold, factor = ctx.params.resting_factor;
  uint8_t *const touching = touching_.data(), *const pressed = pressed_.data();
  Vec3 *const ra = ra_.data(), *const rb = rb_.data(), *const travel = travelled_.data();
  double *const moved_a = moved_a_.data(), *const gap = gap_.data();
  double *const allowance = allowance_.data(), *const before = before_.data();
  const double* const then = then_.data();
  const double* const now = now_.data();
  double *const approach = approach_.data(), *const resting = resting_speed_.data();
  double* const start = start_speed_.data();
  const uint8_t* const loaded = loaded_.data();
  uint8_t* const unsettled = unsettled_.data();
  const std::array<Vec3, 2>* const motion = motion_.data();
  for (int64_t k = lo; k < hi; ++k) {
    const int64_t a = c.a[k], b = c.b[k];
    const bool detected = !persistent(c.kind[k]);   // IMPACT or TUNNELLED
    // contact points are at the time of impact (IMPACT/TUNNELLED) or the current state
    double at = detected ? c.toi[k] : 1.0;
    Vec3 point = load3(c.point + 3 * k), normal = load3(c.normal + 3 * k);
    Vec3 xa = load3(previous.position + 3 * a), xb = load3(previous.position + 3 * b);
    // against an immovable body the levers reach the movable body's own surface point
    // (detection's point is midway between the two surfaces; a persistent contact's
    // current poses overlap by -separation, at 30 Hz g dt^2 = 11 mm for a body resting on
    // a floor: from the midpoint a ball's lever was that half short, so its friction and
    // spin rows saw it turn 5 % too slowly). Two movable bodies keep one point for both
    // (midway: equal and opposite impulses at one point keep the angular momentum). The
    // normal rows see no change (r x n is the same along n)
    if (!detected) {
      const bool fixed_a = bodies.inv_mass[a] == 0.0, fixed_b = bodies.inv_mass[b] == 0.0;
      if (fixed_a != fixed_b)
        point += (fixed_a ? 0.5 : -0.5) * c.separation[k] * normal;
    }
    // (each value computed into a local and stored once: read back from its array after a
    // store, it was loaded again, since the compiler cannot tell the arrays apart)
    const Vec3 lever_a = point - (xa + at * (load3(current.position + 3 * a) - xa));
    const Vec3 lever_b = point - (xb + at * (load3(current.position + 3 * b) - xb));
    ra[k] = lever_a;
    rb[k] = lever_b;
    // how far the two points closed over the step (m, from the poses: a step of several
    // periods that its source integrated is no straight line at the twist); a persistent
    // contact's gap at the previous state is its separation less that
    const Vec3 travel_a = travelled(motion[a], lever_a), travel_b = travelled(motion[b], lever_b);
    travel[2 * k] = travel_a;
    travel[2 * k + 1] = travel_b;
    const double along_a = dot(travel_a, normal);
    moved_a[k] = along_a;
    const double closed = dot(travel_b, normal) - along_a;
    const double gap_then = c.separation[k] - closed;
    gap[k] = gap_then;
    allowance[k] = closed;           // (kept here for the loops below)
    // the pre-solve approach at the current twists (a body with an impact: below)
    const double speed_now = normal_speed(now, a, b, lever_a, lever_b, normal);
    approach[k] = speed_now;
    // a persistent contact beyond the slop at the previous state touches nothing from the
    // start: its speed then and its resting speed are found where they are read (settle:
    // most speculative points of a pile never are)
    const bool within = !detected && gap_then <= slop;
    unsettled[k] = !detected && !within;
    if (unsettled[k]) {
      touching[k] = 0;
      continue;
    }
    const double speed_then = normal_speed(then, a, b, lever_a, lever_b, normal);
    before[k] = speed_then;
    const double threshold = resting_speed(loaded, a, b, speed_then, speed_now, floor, factor);
    resting[k] = threshold;
    // touching at the previous state (within the slop) and not approaching then: in
    // contact from the start of the step; its bodies rest on it unless they have an impact
    touching[k] = within && speed_then >= -sticking;
    // (and only where the step's external change presses one of the two into the other:
    // without one, nothing holds a body there, and a ball that drifted into another in a
    // weightless gas, struck within the step, was held on it one-sidedly: momentum made,
    // 1.2 % of an elastic gas's energy lost in a step at 100 Hz). Its speed is the one at
    // the step's start, the mean of the previous and current twists (each is the velocity
    // at the middle of its step): a ball falling into the slop of its floor at 0.487 m/s
    // at the previous step's middle, 0.507 m/s by its end, was held there as resting on
    // it (below the 0.5 m/s threshold) and did not bounce at 0.508 m/s (240 Hz)
    const double speed_start = 0.5 * (speed_then + speed_now);
    start[k] = speed_start;
    if (within && std::abs(speed_start) <= threshold) {
      const Vec3 press_a = load3(now + 6 * a) - load3(then + 6 * a);
      const Vec3 press_b = load3(now + 6 * b) - load3(then + 6 * b);
      pressed[k] = dot(press_a, normal) > 0.0 || dot(press_b, normal) < 0.0;
    }
  }
}

// The resting speed of a contact of bodies a and b whose normal speed was `then` at the
// previous twists and is `now` at the current ones (m/s): slower approaches are RESTING and
// do not bounce. It is factor times the approach the step's external change alone brought
// the pair (current less previous twists along the normal: g dt for a body on a floor, none
// for two bodies falling together) and, where that change acts on one of the two (loaded:
// a load, as gravity), at least the floor: a resting body gathers that approach in every
// step and must not bounce on it, and a slower bounce under a load is pulled back at once.
// Free bodies (no external change: a weightless gas, a ball drifting into a wall in space)
// bounce at any approach: no load brings a slow bounce back, and resting it would take
// energy that nothing returns (an elastic gas keeps its energy)
double StepSolver::resting_speed(const uint8_t* loaded, int64_t a, int64_t b, double then,
                                 double now, double floor, double factor) {
  return std::max(loaded[a] || loaded[b] ? floor : 0.0, factor * std::max(then - now, 0.0));
}

// The external change of a supported body is taken by what holds it: a body that lands on
// it gathers the external change relative to it as on the floor (a cube falling onto one
// resting on the floor: g dt per step, not the none of two falling together), and its
// contact k rests below factor times that (else a column of cubes dropped apart at 30 Hz
// took their slow landings as impacts and sank 16 mm into itself): `resting` raised to it
// where a free movable body meets a supported one (not a body on the floor, nor two
// supported bodies). `then`: k's normal speed at the previous twists (m/s); the twists on
// the held paths as they start (path_ before any hold: a supported body's previous twist,
// another's current one)
double StepSolver::held_resting(const StepContext& ctx, int64_t k, double then,
                                double resting) const {
  const int64_t a = ctx.contacts.a[k], b = ctx.contacts.b[k];
  const uint8_t* const movable = ctx.bodies.movable;
  const bool free_a = movable[a] && !supported_[a], free_b = movable[b] && !supported_[b];
  if ((!supported_[a] && !supported_[b]) || (!free_a && !free_b)) return resting;
  const double held = then - normal_speed_of((supported_[a] ? then_ : now_).data() + 6 * a,
                                             (supported_[b] ? then_ : now_).data() + 6 * b,
                                             ra_[k], rb_[k], load3(ctx.contacts.normal + 3 * k));
  return std::max(resting, ctx.params.resting_factor * held);
}

void StepSolver::settle(const StepContext& ctx, int64_t k) {
  if (!unsettled_[k]) return;
  const ContactsView& c = ctx.contacts;
  const int64_t a = c.a[k], b = c.b[k];
  const Vec3 normal = load3(c.normal + 3 * k);
  const double then = normal_speed(then_.data(), a, b, ra_[k], rb_[k], normal);
  before_[k] = then;
  // (an unsettled contact's approach_ is still the one at the current twists: frame_contacts)
  resting_speed_[k] = held_resting(
      ctx, k, then, resting_speed(loaded_.data(), a, b, then, approach_[k],
                                  ctx.params.restitution_threshold, ctx.params.resting_factor));
  unsettled_[k] = 0;
}

// The per-contact part of reference_frame for contacts [lo, hi) after the bodies' flags:
// drift_, whether each is an impact and when (impact_, toi_, the report's toi and kind);
// each writes only its own entries (on either thread: StepSolver::in_parts).
COLLRES_CLONED
void StepSolver::impact_contacts(const StepContext& ctx, int64_t lo, int64_t hi) {
  const ContactsView c = ctx.contacts;
  const ContactsOut report = ctx.report;
  const double dt = ctx.dt;
  const uint8_t *const supported = supported_.data(), *const rested = rested_.data();
  const uint8_t* const touching = touching_.data();
  uint8_t* const impact_of = impact_.data();
  const Vec3 *const ra = ra_.data(), *const rb = rb_.data(), *const travel = travelled_.data();
  double *const moved_a = moved_a_.data(), *const gap = gap_.data(), *const drift = drift_.data();
  const double *const allowance = allowance_.data(), *const before = before_.data();
  const double *const approach = approach_.data(), *const resting = resting_speed_.data();
  double* const toi_of = toi_.data();
  const double* const path = path_.data();
  const int64_t* const earliest = earliest_.data();
  // a body's motion on its held path (supported_) less the one it made: none for others
  auto held = [&](int64_t i, const Vec3& r, const Vec3& moved) {
    if (!supported[i]) return Vec3(Vec3::Zero());
    return Vec3(moved - dt * (load3(path + 6 * i) + cross(load3(path + 6 * i + 3), r)));
  };
  // whether detected impact k of body i comes later in the step than i's earliest one and
  // lies behind it: the normals out of i within acos(behind_cosine). Body i reaches k's
  // other body only through the earlier one's (a striker that passes through a cradle's
  // first ball within the step meets the second too, behind it: struck at once, a third
  // of the impulse went to the second ball); the earlier impact turns it first
  auto behind = [&](int64_t k, int64_t i) {
    const int64_t e = earliest[i];
    if (e < 0 || e == k || c.toi[k] <= c.toi[e] + ctx.params.later_impact) return false;
    const Vec3 out_k = (c.a[k] == i ? 1.0 : -1.0) * load3(c.normal + 3 * k);
    const Vec3 out_e = (c.a[e] == i ? 1.0 : -1.0) * load3(c.normal + 3 * e);
    return dot(out_k, out_e) >= ctx.params.behind_cosine;
  };
  for (int64_t k = lo; k < hi; ++k) {
    const int64_t a = c.a[k], b = c.b[k];
    const bool detected = !persistent(c.kind[k]);
    const bool held_pair = supported[a] || supported[b];
    // (each value in a local, stored once: see frame_contacts)
    double drifts = 0.0;
    if (held_pair) {
      const Vec3 normal = load3(c.normal + 3 * k);
      const Vec3 held_a = held(a, ra[k], travel[2 * k]);
      drifts = dot(held_a - held(b, rb[k], travel[2 * k + 1]), normal);
      moved_a[k] -= dot(held_a, normal);
    }
    drift[k] = drifts;
    const double gap_then = gap[k];
    // a persistent contact that closes within the step faster than the threshold at the
    // time it closes (on the held paths: its separation at the end is drift_ more than
    // detection's; a twist is the velocity at mid-step, so the approach at fraction f is
    // v_in + (f - 1/2) (v_in - before) off the held paths: a ball landing at 0.51 m/s late
    // in a 120 Hz step whose mid-step approach was 0.50 m/s did not bounce)
    const double end = c.separation[k] + drifts;
    bool closing = false;
    double toi = detected ? c.toi[k] : 0.0;
    if (!detected && !touching[k] && gap_then > 0.0 && end < 0.0) {
      settle(ctx, k);
      const double v_in = approach[k];
      const double meets = gap_then / std::max(gap_then - end, 1e-300);
      const double v_then = held_pair ? v_in : v_in + (meets - 0.5) * (v_in - before[k]);
      closing = v_then < -resting[k];
      if (closing) toi = meets;
    }
    bool impact = detected || closing;
    // a detected impact of a supported body: the time its rows reach their separation at
    // detection's time of impact f on the held paths, f closed / (closed + drift) (its
    // points close by closed over the step on the integrated paths); none within the step
    // there: a persistent contact from the start, its gap then the one at the time of
    // impact less what closed before it
    if (detected && drifts != 0.0) {
      const double closed = allowance[k], held = closed + drifts;
      const double at = closed < 0.0 && held < 0.0 ? toi * closed / held : 2.0;
      if (at > 1.0) {
        gap[k] = std::max(c.separation[k], 0.0) - toi * closed;
        impact = false;
        toi = 0.0;
      } else {
        toi = at;
      }
    }
    // an impact behind an earlier one of one of its bodies is speculative from the start:
    // the impact stages take it only if it still closes after the earlier impact
    if (detected && impact && (behind(k, a) || behind(k, b))) {
      impact = false;
      toi = 0.0;
    }
    // a body resting on something from the start meets no impact that only the step's
    // external change brings (at the start its pair approached slower than the
    // threshold): after dropped inputs its source integrated it through its supports
    // into what lies below them; the contact is speculative from the start instead
    // (an impact is settled: detected, or closing)
    if (impact && (rested[a] || rested[b]) && before[k] >= -resting[k]) {
      // a detected impact's rows touch (its corners: their separation) at the time of
      // impact, and closed by toi of the step's closing before
      if (detected) gap[k] = std::max(c.separation[k], 0.0) - toi * (allowance[k] + drifts);
      impact = closing = false;
      toi = 0.0;
    }
    impact_of[k] = impact;
    toi_of[k] = toi;
    report.toi[k] = std::clamp(toi, 0.0, 1.0);
    report.kind[k] = closing  ? static_cast<int8_t>(ContactKind::impact)
                     : impact ? c.kind[k]
                              : static_cast<int8_t>(ContactKind::persistent);
  }
}

COLLRES_CLONED_FLAT
void StepSolver::prepare(StepContext& ctx) {
  const BodyProperties& bodies = ctx.bodies;
  const ContactsView& c = ctx.contacts;
  const SolverParams& p = ctx.params;
  const int64_t m = c.count;
  // a speculative contact is no row while it separates faster than row_bound (1 + e) times
  // the fastest pre-solve approach of the step (reference_frame): most impulses of the step
  // cannot turn it around ((1 + e) per hit); one that the answer does turn around gets a
  // row (escaped, forced_)
  const double bound = p.row_bound * (1.0 + restitution_) * fastest_;
  row_of_.assign(m, -1);
  rowless_.clear();
  // rows in the order of detection's manifolds, one constraint per manifold with rows,
  // written over the last step's rows (rows_ is cut to the ones used): each field is set
  // here or by prepare_row, none twice (a new row's constructor zeros every field). Per
  // manifold, in parts (each writes only its own contacts', rows' and constraint's
  // entries): its rows counted (row_of_ 0 until placed; and their contacts settled: the
  // impact stages and the landing read the resting speed), then, after the rows and
  // constraints of the manifolds before it (their counts' running sums), written
  const int64_t spans = c.manifold_count;
  placed_.resize(2 * (spans + 1));
  int32_t* const placed = placed_.data();
  in_parts(ctx, spans, [&](int64_t lo, int64_t hi) {
    for (int64_t span = lo; span < hi; ++span) {
      const int64_t* manifold = c.manifolds + kManifoldFields * span;
      int32_t count = 0;
      for (int64_t k = manifold[2]; k < manifold[2] + manifold[3]; ++k) {
        if (gap_[k] > 0.0 && !forced_[k] && approach_[k] + allowance_[k] > bound) continue;
        settle(ctx, k);
        row_of_[k] = 0;
        ++count;
      }
      placed[2 * span + 2] = count;
      placed[2 * span + 3] = count > 0;
    }
  });
  // (and how many of manifolds_ each body is in, from detection's pairs: see search below)
  placed[0] = placed[1] = 0;
  manifolds_of_.assign(static_cast<size_t>(ctx.solver.count), 0);
  for (int64_t span = 0; span < spans; ++span) {
    if (placed[2 * span + 3] != 0) {
      ++manifolds_of_[c.manifolds[kManifoldFields * span]];
      ++manifolds_of_[c.manifolds[kManifoldFields * span + 1]];
    }
    placed[2 * span + 2] += placed[2 * span];
    placed[2 * span + 3] += placed[2 * span + 1];
  }
  const auto used = static_cast<size_t>(placed[2 * spans]);
  const auto blocks = static_cast<size_t>(placed[2 * spans + 1]);
  rows_.resize(used);
  manifolds_.resize(blocks);   // (each constructed anew below)
  fit_matrices(matrices_, manifolds_);   // (block() writes an entry)
  friction_.resize(2 * blocks);
  in_parts(ctx, spans, [&](int64_t lo, int64_t hi) {
    for (int64_t span = lo; span < hi; ++span) {
      const int64_t* manifold = c.manifolds + kManifoldFields * span;
      const int32_t first_row = placed[2 * span], index = placed[2 * span + 1];
      if (placed[2 * span + 2] == first_row) continue;   // (no row)
      // the pair of every row of the manifold (the binding checks it) and its restitution,
      // once for them all
      const int64_t a = manifold[0], b = manifold[1];
      double e_a = bodies.restitution[a], e_b = bodies.restitution[b];
      if (p.restitution_rule != CombineRule::kPerObject)
        e_a = e_b = combine(e_a, e_b, p.restitution_rule);
      int32_t at = first_row;
      for (int64_t k = manifold[2]; k < manifold[2] + manifold[3]; ++k) {
        if (row_of_[k] < 0) continue;
        row_of_[k] = at;
        ContactRow& row = rows_[static_cast<size_t>(at++)];
        row.normal = row.tangent[0] = row.tangent[1] = 0.0;   // no impulse yet
        row.impact = row.impact_tangent[0] = row.impact_tangent[1] = 0.0;
        row.landing = row.push = row.pseudo = 0.0;
        row.a = static_cast<int32_t>(a);
        row.b = static_cast<int32_t>(b);
        row.contact = static_cast<int32_t>(k);
        row.manifold = index;
        row.n = load3(c.normal + 3 * k);
        row.ra = ra_[k];
        row.rb = rb_[k];
        row.allowance = allowance_[k];
        row.e_a = e_a;
        row.e_b = e_b;
      }
      // (constructed anew in its place, every field as a new constraint's: trivially
      // destructible, its old value needs no end)
      static_assert(std::is_trivially_destructible_v<Manifold>);
      Manifold& block = *new (&manifolds_[static_cast<size_t>(index)]) Manifold();
      block.a = rows_[first_row].a;   // (detection's manifold[0], [1])
      block.b = rows_[first_row].b;
      block.first = first_row;
      block.count = at - first_row;
      // a body's impact this step: its blocks with their friction as one (mirror hits keep
      // mirror impulses); a settled pile keeps the cheaper split solve
      block.coupled = impacted_[block.a] || impacted_[block.b];
      // its friction coefficients, once for its rows
      const double mu_s = combine(bodies.static_friction[a], bodies.static_friction[b],
                                  p.friction_rule);
      friction_[2 * index] = mu_s;
      friction_[2 * index + 1] = std::min(
          mu_s, combine(bodies.kinetic_friction[a], bodies.kinetic_friction[b], p.friction_rule));
    }
  });
  for (int64_t k = 0; k < m; ++k)
    if (row_of_[k] < 0) rowless_.push_back(static_cast<int32_t>(k));
  // each row's frame and friction coefficient (its own entry: on either thread; the
  // tangents of the row before in its part where their normals agree)
  in_parts(ctx, static_cast<int64_t>(rows_.size()), [&](int64_t lo, int64_t hi) {
    for (int64_t i = lo; i < hi; ++i) {
      ContactRow& row = rows_[static_cast<size_t>(i)];
      const double* mu = friction_.data() + 2 * row.manifold;
      prepare_row(row, i > lo ? &rows_[static_cast<size_t>(i - 1)] : nullptr, ctx.solver,
                  then_.data(), p.sticking_speed, mu[0], mu[1]);
    }
  });
  // Per manifold, in one pass over its rows (they are read once while at hand):
  // - a manifold with a point that slips (faster than the sticking speed, prepare_row): its
  //   blocks with their friction as one too. Split, a box sliding on four points of a wall
  //   (or of another box) was solved by an iteration whose mirror-antisymmetric part grew
  //   (8 of 42,700 random mirror hits, up to 0.62 of the largest normal impulse); a settled
  //   pile has none such (its cost per step unchanged within 1.5 %);
  // - a coupled block whose moves between states find no answer searches every state
  //   (solve_coupled) where it is the only manifold of each of its movable bodies
  //   (manifolds_of_): the block alone then answers for its bodies, and each sweep searches
  //   from the twists without its impulses, which no other manifold moves. Where a body is
  //   in other manifolds too, the block is solved split: the search's answer jumps between
  //   states as the neighbours' impulses change, and their next updates undo the jump (a
  //   pile of 100 cubes dropped at 120 Hz: 598 answers found, each moving 1 to 100 % of its
  //   block's largest normal impulse, kept a box rocking at 0.1 m/s a second longer), where
  //   the split solve's updates move the impulses a share at a time;
  // - the rows aim turns: of two spheres, alone in their manifold, one pressed onto the
  //   other from the start (pressed_), neither body impacted;
  // - the largest lever of its rows on A and on B (reach_);
  // - one SpinRow per manifold whose combined rolling resistance or torsional friction is
  //   not 0 (in manifold order), written over the last step's as the rows are.
  // None is in the sweeps yet (admit lets them in; the plan follows them), no block
  // prepared (only a manifold solved needs one: block())
  auto only = [&](int32_t i) { return ctx.solver.inv_mass[i] == 0.0 || manifolds_of_[i] == 1; };
  aimed_.clear();
  aiming_.assign(rows_.size(), 0);
  turned_.assign(rows_.size(), 0);
  aimed_gap_.resize(rows_.size());
  in_.assign(manifolds_.size(), 0);
  blocked_.assign(manifolds_.size(), 0);
  slack_.assign(manifolds_.size(), 0.0);
  reach_.resize(2 * manifolds_.size());
  size_t spun = 0;
  for (size_t m = 0; m < manifolds_.size(); ++m) {
    Manifold& manifold = manifolds_[m];
    double reach_a = 0.0, reach_b = 0.0;   // (squared here: one root a manifold)
    for (int32_t i = manifold.first; i < manifold.first + manifold.count; ++i) {
      const ContactRow& row = rows_[i];
      manifold.coupled = manifold.coupled || !row.sticking;
      reach_a = std::max(reach_a, dot(row.ra, row.ra));
      reach_b = std::max(reach_b, dot(row.rb, row.rb));
    }
    reach_[2 * m] = std::sqrt(reach_a);
    reach_[2 * m + 1] = std::sqrt(reach_b);
    manifold.search = manifold.coupled && only(manifold.a) && only(manifold.b);
    const ContactRow& r = rows_[manifold.first];
    if (manifold.count == 1 && bodies.radius[r.a] > 0.0 && bodies.radius[r.b] > 0.0 &&
        pressed_[r.contact] && !impact_[r.contact] && !impacted_[r.a] && !impacted_[r.b]) {
      aimed_.push_back(manifold.first);
      aiming_[manifold.first] = 1;
    }
    const double roll = combine(bodies.rolling_resistance[r.a], bodies.rolling_resistance[r.b],
                                p.friction_rule);
    const double twist = combine(bodies.torsional_friction[r.a],
                                 bodies.torsional_friction[r.b], p.friction_rule);
    // lever: from the centre of mass of the movable body nearer to the contact
    double lever = 0.0;
    if (r.ma > 0.0) lever = length(r.ra);
    if (r.mb > 0.0) lever = lever > 0.0 ? std::min(lever, length(r.rb)) : length(r.rb);
    if ((roll > 0.0 || twist > 0.0) && lever > 0.0) {
      manifold.spin = static_cast<int32_t>(spun);
      if (spun == spins_.size()) spins_.emplace_back();
      SpinRow& s = spins_[spun++];
      s.a = r.a;
      s.b = r.b;
      s.n = r.n;
      s.inv_a = inv_inertia_[r.a];
      s.inv_b = inv_inertia_[r.b];
      s.inv_ab = s.inv_a + s.inv_b;
      s.k_n = dot(s.n, mul(s.inv_ab, s.n));
      s.lever = lever;
      s.roll = roll * lever;
      s.twist = twist * lever;
      s.torque = Vec3::Zero();
      s.load = 0.0;
    }
  }
  spins_.resize(spun);
  islands_ = false;
  small_ = false;
  known_ = false;
  speed_.resize(rows_.size());
  chosen_.clear();
  ++plan_.rows_epoch;   // (rows anew: no wide group of the last ones is taken over)
  plan_sweeps(ctx);
}

bool StepSolver::idle(const Manifold& manifold) const {
  for (int32_t i = manifold.first; i < manifold.first + manifold.count; ++i)
    if (!holds_nothing(rows_[i])) return false;
  if (manifold.spin < 0) return true;
  const Vec3& torque = spins_[manifold.spin].torque;
  return torque.x() == 0.0 && torque.y() == 0.0 && torque.z() == 0.0;
}

void StepSolver::block(size_t manifold) {
  if (blocked_[manifold]) return;
  prepare_block(manifolds_[manifold], &rows_[static_cast<size_t>(manifolds_[manifold].first)],
                matrices_[manifold]);
  blocked_[manifold] = 1;
}

bool StepSolver::admit(StepContext& ctx, double margin, bool verify) {
  const double* v = velocity_.data();
  const int64_t n = ctx.bodies.count;
  // the check at a sweep's start knows the last sweep's start (from_velocity_) after the
  // first of the step
  const bool known = verify || known_;
  if (known) {    // each body's change of speed since the (last) sweeps' start
    change_.resize(2 * n);
    for (int64_t i = 0; i < n; ++i) {
      const double* now = v + 6 * i;
      const double* from = from_velocity_.data() + 6 * i;
      change_[2 * i] = length(Vec3(now[0] - from[0], now[1] - from[1], now[2] - from[2]));
      change_[2 * i + 1] = length(Vec3(now[3] - from[3], now[4] - from[4], now[5] - from[5]));
    }
  }
  // per manifold (each writes only its own entries, its block and rows): the step's first
  // check (every manifold's rows' speeds, most blocks prepared) on either thread, in parts
  std::atomic<bool> grew{false};
  const std::function<void(int64_t, int64_t)> check = [&](int64_t lo, int64_t hi) {
    // (in locals: a store of a flag, a byte, may alias anything in memory)
    const bool knows = known, after = verify;
    const double least_free = margin;
    const double* const vel = v;
    bool grew_part = false;
    for (auto m = static_cast<size_t>(lo); m < static_cast<size_t>(hi); ++m) {
      if (in_[m]) continue;
      const Manifold& manifold = manifolds_[m];
      // a row's normal speed changed by at most |dv_a| + |dw_a| |r_a| + (the same on B)
      double bound = 0.0;
      if (knows) {
        const double* ca = change_.data() + 2 * manifold.a;
        const double* cb = change_.data() + 2 * manifold.b;
        bound = ca[0] + ca[1] * reach_[2 * m] + cb[0] + cb[1] * reach_[2 * m + 1];
      }
      // after the sweeps: its impulses and spin torque are as at the start (not swept)
      if (after && bound + 1e-9 <= 0.5 * slack_[m]) continue;
      const bool quiet = idle(manifold);
      if (knows && !after && quiet) {
        // at a sweep's start: each row's normal speed at the last start (or a bound below
        // it) less the bound, plus its allowance now
        double least = std::numeric_limits<double>::infinity();
        for (int32_t i = manifold.first; i < manifold.first + manifold.count; ++i)
          least = std::min(least, speed_[i] - bound + rows_[i].allowance);
        if (least > least_free + 1e-9) {   // still out (its test's answer is known)
          for (int32_t i = manifold.first; i < manifold.first + manifold.count; ++i)
            speed_[i] -= bound;
          slack_[m] = least;
          continue;
        }
      }
      bool out = quiet;
      double slack = std::numeric_limits<double>::infinity();
      for (int32_t i = manifold.first; i < manifold.first + manifold.count && out; ++i) {
        const ContactRow& r = rows_[i];
        const double speed = normal_velocity(r, vel), free = speed + r.allowance;
        if (!after) speed_[i] = speed;
        out = free > least_free;
        slack = std::min(slack, free);
      }
      if (out) {
        if (!after) slack_[m] = slack;
        continue;
      }
      in_[m] = 1;
      block(m);
      grew_part = true;
    }
    if (grew_part) grew.store(true, std::memory_order_relaxed);
  };
  const auto count = static_cast<int64_t>(manifolds_.size());
  if (known) {
    check(0, count);
  } else {
    in_parts(ctx, count, check);
  }
  known_ = true;
  if (!grew.load(std::memory_order_relaxed)) return false;
  // the swept manifolds in detection's order, then in waves
  chosen_.clear();
  for (size_t m = 0; m < manifolds_.size(); ++m)
    if (in_[m]) chosen_.push_back(static_cast<int32_t>(m));
  plan_sweeps(ctx);
  return true;
}

// Why a settled pile's sweeps never stop early (the stop rule, `converged`: no impulse
// changes by more than 1e-6 of the largest normal impulse), measured sweep by sweep on the
// settled bench piles of cubes (bench/pile.py, 100 and 1000 bodies at 30 and 120 Hz,
// sleeping off; changes in units of the substep's largest normal impulse):
// - each substep's first sweep (and the landing's) changes 0.26-0.62: a face of four
//   points whose load moves between its two diagonals, its free direction (+-0.31 on the
//   four floor rows of one cube of 100 in the first substep, -+0.39 back in the landing;
//   0.42-0.62 in faces between cubes of 1000): the block's answer jumps between its
//   all-active one (least norm: the load spread over both diagonals) and one with a point
//   out (the other three carrying it), statically the same (no velocity moves). Not the
//   substeps' allowances: with none for points within 1 or 10 um of touching the jumps
//   (0.27-0.43) and the plateau below stay;
// - from the second sweep on the largest change stays at 6e-4 to 2.4e-2 a sweep (median
//   3e-5 to 7e-5; ~78 % of the swept rows above 1e-6 at the 11th sweep) and does not fall:
//   the rows' velocity error stays at 5e-4 to 5e-3 m/s (median 2e-5 to 7e-5 m/s) and the
//   bodies' velocities change 1e-4 to 2e-3 m/s a sweep. The largest changes are blocks with
//   one point at its friction cone, whose split solve (normal block, then friction block)
//   turns the load over each sweep (+-0.022 a sweep in a pile of 1000), yet every block
//   solved with its friction as one (solve_coupled) leaves the same plateau (1000 cubes at
//   30 Hz, 11th sweep: 5e-3 to 3.1e-2, velocity error 2.2e-3 to 5.5e-3 m/s; split 2.7e-3 to
//   2.4e-2, 2.2e-3 to 5.5e-3 m/s); and the faces of columns: a pile of 100 swept cold 1260
//   times still changes 1.7e-5 a sweep (halving every ~600 sweeps; velocity error 3e-4 m/s
//   at the 20th sweep, 1.7e-4 at the 100th, 2.4e-5 at the 1260th), its slowest mode a
//   column's faces' loads moving between their diagonals, the column rising at 2e-5 m/s;
// - the warm start is not what keeps them changing (cubes of 100 at 30 Hz, against the
//   answer of 200 sweeps of each substep): the substeps' warm-started impulses lie as close
//   to it (median 2.8e-3 to 5.3e-3) as the substeps' own sweeps' answer (2.4e-3 to 3.3e-3),
//   whose 200th sweep still changes 4.8e-4 to 6.7e-4; every row that changes is warm
//   started (none new), and the swept manifolds differ by under 1 % between substeps.
// Nor the sweeps' order: the manifolds taken top down (by their upper body's contact level,
// before the waves) leave the rows' velocity error at 6.1e-4 to 2.5e-3 m/s, median 1.1e-5
// to 3.2e-5 (cubes of 100 at 30 Hz, 11th sweep; as they are: 6.5e-4 to 1.4e-3, median
// 1.5e-5 to 3.6e-5; sorted bottom up: the same bits). Nor over-relaxation (projected SOR:
// a row's or a block's new normal impulses its old ones plus w times the update's change,
// then >= 0; not the impact stages, shock propagation or the push-out), measured the same
// way (the 3rd step from the settled state, 20 sweeps a substep; velocity error of the
// rows at the 11th sweep, range over the substeps, median): cubes of 100 at 30 Hz w 1.0
// 6.4e-4 to 6.7e-4 m/s, median 2.5e-5; 1.2 4.6e-4 to 7.2e-4, 1.7e-5; 1.4 4.2e-4 to 8.9e-4,
// 1.7e-5; 1.6 3.0e-4 to 1.6e-3, 1.3e-5; 1.8 1.5e-3 to 5.7e-3, 2.3e-5 (at 120 Hz 1.0 5.2e-4
// to 8.1e-4, 1.4 2.4e-4 to 6.4e-4, 1.8 3.8e-3 to 1.3e-2); 1000 at 30 Hz 1.0 2.2e-3 to
// 5.5e-3, median 4.7e-5; 1.3 2.6e-3 to 3.0e-3, 3.9e-5; 1.5 3.6e-3 to 1.1e-2, 2.9e-5. The
// median falls by a fifth to a half, the largest error stays (the plateau is the blocks'
// load turning over, not a slow mode), the largest change a sweep grows (2nd sweep 3.6e-3
// at 1.0, 0.15 at 1.4, 0.33 at 1.8); friction relaxed too changes nothing. And it breaks
// laws (bench_laws): with a block's answer relaxed row by row, w 1.1 lets the 1000:1 stack
// gain energy (60-240 Hz) and a mirror hit part 4.5e-6, 1.3 moves the stack 0.1-0.3 mm,
// lets the pyramid gain and a tower of 20 5-cm cubes walk 18 mm at 30 Hz, 1.7 moves the
// stack 0.3 m;
// a coupled block's normals relaxed under its friction part 2-point wall hits by 0.41.
// Relaxed along the segment from its old impulses to its answer (the largest factor up to
// w that keeps them >= 0: the normal problem's energy falls at every update), coupled
// blocks not relaxed, 1.1 keeps the 315 checks, 1.3 lets the 1000:1 stack gain 3e-6 of its
// energy at 120 and 240 Hz (the overshoot left at the sweeps' end lifts the heavy box a
// micrometre; shock propagation never pulls). With 9 sweeps w 1.1 fails a heap check as
// w 1.0 does. At 30 Hz the 100 piles rest 0.10-0.34 mm deep, asleep (seeds 1-6 of both
// kinds), with w 1.6-1.7 row by row and deep_overlap 0, but 200 cubes then stay awake
// after 8 s; law-keeping (1.1 along the segment, deep_overlap 0.2 mm) cubes seed 1 stays
// awake 0.47 mm deep as with w 1.0.
// Nor does a conjugate gradient over the sweeps take the plateau out (nonsmooth nonlinear
// CG: Silcowitz, Niebe and Erleben 2010, Bullet's btNNCGConstraintSolver; scratch build:
// after each sweep r = the change of every swept row's impulses, beta = |r|^2 / |r'|^2 of
// the sweep before, restarted above 1, and the impulses, twists with them, moved on by beta
// times the last step, normal >= 0 and friction scaled into its cone; not after the last
// sweep). Rows' velocity error, max / median (m/s), first substep: cubes of 100 at 30 Hz,
// 11th sweep 1.5e-3 / 1.1e-4 (as they are: 1.8e-3 / 1.2e-4), 20th 9.7e-4 / 8.0e-5 (1.2e-3 /
// 8.1e-5), 200th 7.1e-4 / 2.0e-5 (7.7e-4 / 2.9e-5); 1000 cubes at 30 Hz, 11th 5.6e-3 /
// 1.6e-4 (4.2e-3 / 1.6e-4); 100 cubes at 120 Hz 3.4e-4 / 5.9e-5 (3.4e-4 / 5.8e-5). From the
// third sweep on 35-45 % of the sweeps restart it (their change grew: the faces' loads and
// the cones' turns above are no descent). On a slow mode it does converge: a tower of 20
// cubes of 0.2 m started cold at 30 Hz, 40th / 60th sweep, 1.1e-3 / 2.3e-4 m/s (3.6e-3 /
// 3.0e-3), and the pyramid of 55 cubes (bench_laws) drifts 0.0003 mm (0.011 to 0.026 mm)
// but gains 3.7e-6 J in its first step at 240 Hz (the sweeps as they are leave it sinking,
// 9.5 um in that step: no gain). Its extra pass, with the wide rows unpacked and packed
// again at each sweep, costs about a sweep again (cubes of 1000 at 120 Hz: 1.0 M
// instructions a sweep, the sweep 0.92 M). With deep_overlap 0, of the 30 Hz piles of
// test_pile_rest (seeds 1-6 of both kinds, and 200 cubes of seeds 1-2) one of the 14 is
// awake after 4 s (200 cubes: 6 s), the others rest 0.11-0.34 mm deep (as they are: 4
// awake; with 20 sweeps cubes seed 1 too, 0.61 mm); restarted above 2 instead, one awake
// too (0.11-0.23 mm), and the pyramid gains 5.5e-5 J, a mirrored hit of bench_laws turns
// asymmetric (1.1e-6) and its dropped column overlaps 5.4 mm at 30 Hz (1.14 mm).
// So no rule on the change of the impulses stops a settled pile's sweeps before their
// count, and no acceleration of the sweeps as they are takes out their plateau; fewer
// sweeps need a solve that converges on those blocks and columns.
int StepSolver::sweep(StepContext& ctx, int iterations, double share, bool saved) {
  const SolverParams& p = ctx.params;
  admit(ctx, share * p.activation_margin, false);
  // what the sweeps start from: they start again from it with the manifolds let in, so
  // that the answer is the bits of sweeping every manifold whenever the ones left out stay
  // idle throughout (in the sweeps of all of them a manifold idle at each visit changes
  // nothing); `saved`: the rows' impulses are in from_impulse_ already (admit changes none)
  from_velocity_.assign(velocity_.begin(), velocity_.end());
  if (!saved) {
    from_impulse_.resize(3 * rows_.size());
    for (size_t i = 0; i < rows_.size(); ++i) save_impulses(rows_[i], &from_impulse_[3 * i]);
  }
  from_spin_.resize(4 * spins_.size());
  for (size_t i = 0; i < spins_.size(); ++i) {
    for (int d = 0; d < 3; ++d) from_spin_[4 * i + d] = spins_[i].torque[d];
    from_spin_[4 * i + 3] = spins_[i].load;
  }
  int sweeps = 0;
  for (;;) {
    sweeps += solve_velocities(rows_, swept_, ctx.solver, iterations, p.converged, &spins_,
                               &plan_);
    if (!admit(ctx, 0.0, true)) break;
    std::copy(from_velocity_.begin(), from_velocity_.end(), velocity_.begin());
    for (size_t i = 0; i < rows_.size(); ++i) {
      rows_[i].normal = from_impulse_[3 * i];
      rows_[i].tangent[0] = from_impulse_[3 * i + 1];
      rows_[i].tangent[1] = from_impulse_[3 * i + 2];
    }
    for (size_t i = 0; i < spins_.size(); ++i) {
      spins_[i].torque = Vec3(from_spin_[4 * i], from_spin_[4 * i + 1], from_spin_[4 * i + 2]);
      spins_[i].load = from_spin_[4 * i + 3];
    }
  }
  return sweeps;
}

void StepSolver::plan_sweeps(StepContext& ctx) {
  const SolverParams& p = ctx.params;
  plan_.wide = p.wide_rows;
  plan_.parallel = static_cast<size_t>(std::max(p.parallel_wave, 1));
  plan_.worker = p.threads >= 2 ? worker() : nullptr;
  wave_manifolds(manifolds_, chosen_, rows_, ctx.bodies.inv_mass, ctx.bodies.count, plan_,
                 swept_, waving_);
}

Worker* StepSolver::worker() {
  if (!worker_) worker_ = std::make_unique<Worker>();
  return worker_.get();
}

void StepSolver::in_parts(const StepContext& ctx, int64_t count,
                          const std::function<void(int64_t, int64_t)>& part) {
  const int64_t least = std::max<int64_t>(ctx.params.parallel_wave, 1);   // per part
  if (ctx.params.threads < 2 || count < kParts * least) {
    part(0, count);
    return;
  }
  // the first half of the parts the caller's, the second the worker's; no part waits for
  // another
  static constexpr uint8_t kSide[kParts] = {0, 0, 0, 0, 1, 1, 1, 1};
  static constexpr int32_t kFree[kParts] = {};
  const std::function<void(int)> chunk = [&](int i) {
    part(count * i / kParts, count * (i + 1) / kParts);
  };
  worker()->run_sides(chunk, kParts, kSide, kFree, 1, static_cast<double>(count));
}

void StepSolver::beside(const StepContext& ctx, const std::function<void()>& here,
                        const std::function<void()>& there, int kind) {
  const int64_t least = std::max<int64_t>(ctx.params.parallel_wave, 1);   // (as in_parts)
  if (ctx.params.threads < 2 || ctx.contacts.count < kParts * least) {
    here();
    there();
    return;
  }
  worker()->run_pair(here, [&](int) { there(); }, 1, kind,
                     static_cast<double>(std::max<int64_t>(ctx.contacts.count, 1)));
}

bool StepSolver::warmable(const StepContext& ctx) const {
  // impulses of a step of another length are a different answer: scaled by dt / last dt
  // only near 1, never from a fresh step (e.g. a nominal dt after a pause)
  const double scale = last_dt_ > 0.0 ? growth_ : 0.0, ratio = ctx.params.warm_start_ratio;
  return ctx.warm && last_warm_ && scale >= 1.0 / ratio && scale <= ratio;
}

void StepSolver::recall(const StepContext& ctx) {
  if (recalled_ || !warmable(ctx)) return;
  const ContactsView& c = ctx.contacts;
  const int64_t m = c.count;
  cached_normal_.resize(m);
  cached_friction_.resize(3 * m);
  found_.resize(m);
  cache_.lookup(m, c.a, c.b, c.feature, c.point, ctx.params.match_radius, cached_normal_.data(),
                cached_friction_.data(), found_.data());
  recalled_ = true;
}

double StepSolver::warm(StepContext& ctx, int substeps) {
  const ContactsView& c = ctx.contacts;
  const int64_t m = c.count;
  int64_t persistent = 0, cold = 0;
  for (int64_t k = 0; k < m; ++k) persistent += collres::persistent(c.kind[k]);
  const double scale = growth_;   // (warmable: the last step's impulses, scaled)
  const double share = 1.0 / substeps;   // a substep carries its share of the step's
  if (!warmable(ctx)) return persistent > 0 ? 1.0 : 0.0;
  recall(ctx);   // (done beside the impact stages)
  for (int64_t k = 0; k < m; ++k) cold += collres::persistent(c.kind[k]) && !found_[k];
  // per row (its own entries: on either thread)
  in_parts(ctx, static_cast<int64_t>(rows_.size()), [&](int64_t lo, int64_t hi) {
    for (int64_t i = lo; i < hi; ++i) {
      ContactRow& r = rows_[static_cast<size_t>(i)];
      const int64_t k = r.contact;
      Vec3 friction = load3(cached_friction_.data() + 3 * k);
      r.normal = cached_normal_[k] * scale * share;
      double tx = dot(r.t1, friction) * scale * share, ty = dot(r.t2, friction) * scale * share;
      double size = norm2(tx, ty), limit = r.mu * r.normal;
      if (size > limit) {
        tx *= limit / size;
        ty *= limit / size;
      }
      r.tangent[0] = tx;
      r.tangent[1] = ty;
    }
  });
  return static_cast<double>(cold) / static_cast<double>(std::max<int64_t>(1, persistent));
}

void StepSolver::aim(StepContext& ctx, const double* moved, const double* velocity,
                     double half) {
  if (aimed_.empty()) return;
  const double lean = std::sin(ctx.params.aim_turn);
  bool any = false;
  const double* x0 = ctx.previous.position;
  const double* radius = ctx.bodies.radius;
  auto centre = [&](int32_t i) {
    Vec3 x = load3(x0 + 3 * i);
    if (moved != nullptr) x += load3(moved + 6 * i);
    return x;
  };
  for (const int32_t i : aimed_) {
    ContactRow& r = rows_[static_cast<size_t>(i)];
    const Vec3 centres = centre(r.b) - centre(r.a);
    Vec3 mid = centres;
    if (velocity != nullptr)
      mid += half * (load3(velocity + 6 * r.b) - load3(velocity + 6 * r.a));
    aimed_gap_[static_cast<size_t>(i)] = length(centres) - radius[r.a] - radius[r.b];
    const double across = length(mid);
    turned_[static_cast<size_t>(i)] = 0;
    if (!(across > 0.0)) continue;
    const Vec3 n = mid / across;
    if (length(cross(n, r.n)) <= lean && dot(n, r.n) > 0.0) continue;
    turned_[static_cast<size_t>(i)] = 1;
    any = true;
    const Vec3 friction = r.tangent[0] * r.t1 + r.tangent[1] * r.t2;
    r.ra = length(r.ra) * n;
    r.rb = -length(r.rb) * n;
    r.n = n;
    frame_row(r, ctx.solver, nullptr);
    r.tangent[0] = dot(friction, r.t1);
    r.tangent[1] = dot(friction, r.t2);
    const int32_t spin = manifolds_[static_cast<size_t>(r.manifold)].spin;
    if (spin >= 0) {
      SpinRow& s = spins_[static_cast<size_t>(spin)];
      s.n = n;
      s.k_n = dot(n, mul(s.inv_ab, n));
    }
  }
  if (!any) return;
  // the turned rows' wide groups packed anew; a manifold of theirs left out of the sweeps
  // is tested again at the next sweep's start (its speed_ bound was along the old normal)
  repack(plan_, turned_.data());
  if (known_)
    for (const int32_t i : aimed_)
      if (turned_[static_cast<size_t>(i)]) speed_[static_cast<size_t>(i)] = -kInfinity;
}

void StepSolver::to_travel(StepContext& ctx, int substeps) {
  const int64_t n = ctx.bodies.count;
  const double share = 1.0 / substeps;
  // a rested body takes the external change a share per substep only where something
  // holds it: a row of it (a contact that can carry an impulse this step) and a contact
  // touching it from the start that it was not leaving then as from a bounce (faster than
  // the restitution threshold). Any other is free and takes all of it at once, as its
  // source did (x0 + now dt): ramped over the substeps, a box that bounced and was put
  // back on its floor by a later input, at rest or moving down at 0.05 m/s, travelled up
  // with the bounce's velocity for half the step (500 ms: answered 136 / 122 mm above the
  // floor). (Leaving faster than the sticking speed instead: a pile woken by an input at
  // rest and driven on by an integrator shook at up to 1.3 m/s, against 0.06-0.38 before)
  const ContactsView& c = ctx.contacts;
  ramped_.assign(n, 0);
  for (const ContactRow& r : rows_) ramped_[r.a] = ramped_[r.b] = 1;
  for (int64_t k = 0; k < c.count; ++k)
    if (touching_[k] && before_[k] <= resting_speed_[k]) {
      ramped_[c.a[k]] |= 2;
      ramped_[c.b[k]] |= 2;
    }
  // ... and only while the change loads what holds it: it makes a point of one of its rows
  // faster than it was, and than the sticking speed (gravity on a body at rest). A change
  // that only slows its points (a rolling ball or a sliding box that its source stopped)
  // is taken at once, as its source did (x0 + now dt): ramped, a ball rolling at 1 m/s
  // put at its last pose with zero twist was answered 13.3 mm (30 Hz) further along with
  // zero twist
  for (int64_t i = 0; i < n; ++i) ramped_[i] = ramped_[i] == 3 && rested_[i] ? 1 : 0;
  const double sticking = ctx.params.sticking_speed;
  auto loads = [&](int32_t i, const Vec3& r) {
    const double* v = now_.data() + 6 * i;
    const double* u = then_.data() + 6 * i;
    const double after = length(load3(v) + cross(load3(v + 3), r));
    return after > sticking && after > length(load3(u) + cross(load3(u + 3), r));
  };
  // (moved: a point of one of its rows was faster than the sticking speed before, turning
  // included: a ball rolling without slip has its contact point at rest; each body's
  // previous linear and angular speeds found once, in speeds_)
  moving_.assign(n, 0);
  speeds_.resize(2 * n);
  for (int64_t i = 0; i < n; ++i) {
    const double* u = then_.data() + 6 * i;
    speeds_[2 * i] = length(load3(u));
    speeds_[2 * i + 1] = length(load3(u + 3));
  }
  auto moved = [&](int32_t i, const Vec3& r) {
    return speeds_[2 * i] + speeds_[2 * i + 1] * length(r) > sticking;
  };
  for (const ContactRow& r : rows_) {
    if (ramped_[r.a] == 1 && loads(r.a, r.ra)) ramped_[r.a] = 2;
    if (ramped_[r.b] == 1 && loads(r.b, r.rb)) ramped_[r.b] = 2;
    moving_[r.a] |= moved(r.a, r.ra);
    moving_[r.b] |= moved(r.b, r.rb);
  }
  for (int64_t i = 0; i < n; ++i) ramped_[i] = ramped_[i] == 2;
  // Of a ramped body's change, only what loads is spread: the part that takes back the
  // motion it had (a moving body's change projected on minus its twist, with the kinetic
  // energy's metric, at most all of it) is its source's stop, taken at once; the rest (the
  // step of gravity) a share per substep. Spread whole, a ball rolling at 1 m/s that the
  // input stopped with one step of gravity was answered 13.3 mm (30 Hz) / 3.3 mm (100 Hz)
  // further along with zero twist
  const double* inv_mass = ctx.bodies.inv_mass;
  ramp_.resize(6 * n);
  for (int64_t i = 0; i < n; ++i) {
    if (!ramped_[i]) continue;
    const double* v = now_.data() + 6 * i;
    const double* u = then_.data() + 6 * i;
    for (int d = 0; d < 6; ++d) ramp_[6 * i + d] = v[d] - u[d];
    if (!moving_[i] || substeps <= 1) continue;
    const Mat3 inertia = inv_inertia_[i].inverse();
    const double mass = 1.0 / inv_mass[i];
    const Vec3 uv = load3(u), uw = load3(u + 3), iw = mul(inertia, uw);
    const double motion = mass * dot(uv, uv) + dot(uw, iw);
    const double against = -(mass * dot(load3(v) - uv, uv) + dot(load3(v + 3) - uw, iw));
    if (!(against > 0.0 && motion > 0.0)) continue;
    const double taken = std::min(1.0, against / motion);
    for (int d = 0; d < 6; ++d) {
      velocity_[6 * i + d] -= taken * u[d];
      ramp_[6 * i + d] += taken * u[d];
    }
  }
  for (int64_t i = 0; i < n; ++i) {
    if (ramped_[i] && substeps > 1) {   // the first substep's share of the external change
      for (int d = 0; d < 6; ++d) velocity_[6 * i + d] += share * ramp_[6 * i + d];
      continue;
    }
    if (rested_[i]) {   // the whole step's external change: now plus what impacts changed
      for (int d = 0; d < 6; ++d)
        velocity_[6 * i + d] = now_[6 * i + d] + (velocity_[6 * i + d] - then_[6 * i + d]);
      continue;
    }
    if (!impacted_[i]) continue;
    const double half_rest = 0.5 * (1.0 - fraction_[i]);
    for (int d = 0; d < 6; ++d)
      velocity_[6 * i + d] += half_rest * (now_[6 * i + d] - then_[6 * i + d]);
  }
}

int StepSolver::hold_energy(StepContext& ctx, int iterations) {
  const int64_t n = ctx.bodies.count;
  const double* inv_mass = ctx.bodies.inv_mass;
  // islands: bodies joined by rows between two movable bodies (union-find, by index; the
  // rows stay for the step, so found once), each body's entry its root (least index)
  if (!islands_) {
    island_.resize(n);
    for (int64_t i = 0; i < n; ++i) island_[i] = static_cast<int32_t>(i);
    auto find = [&](int32_t i) {
      while (island_[i] != i) i = island_[i] = island_[island_[i]];
      return i;
    };
    for (const ContactRow& r : rows_) {
      if (r.ma == 0.0 || r.mb == 0.0) continue;
      const int32_t x = find(r.a), y = find(r.b);
      if (x != y) island_[std::max(x, y)] = std::min(x, y);
    }
    for (int64_t i = 0; i < n; ++i) island_[i] = find(static_cast<int32_t>(i));
    // the world inertia of each body the energies are judged on (kg m^2)
    inertia_.resize(n);
    for (int64_t i = 0; i < n; ++i)
      if (touched_[i] && inv_mass[i] != 0.0) inertia_[i] = inv_inertia_[i].inverse();
    // the islands pushed by a moving immovable body (driven, kinematic): they may gain. An
    // immovable body's velocity is the same at every substep's start (nothing solves it)
    driven_.clear();
    auto moving = [&](int32_t i) {
      const double* v = start_.data() + 6 * i;
      return v[0] != 0.0 || v[1] != 0.0 || v[2] != 0.0 || v[3] != 0.0 || v[4] != 0.0 ||
             v[5] != 0.0;
    };
    for (const ContactRow& r : rows_) {
      if (r.ma == 0.0 && moving(r.a)) driven_.push_back(island_[r.b]);
      if (r.mb == 0.0 && moving(r.b)) driven_.push_back(island_[r.a]);
    }
    islands_ = true;
  }
  auto root = [&](int32_t i) { return island_[i]; };
  // kinetic energy change of each island (J) and the scale it is judged against; a driven
  // island is not judged
  gain_.assign(2 * n, 0.0);
  for (const int32_t x : driven_) gain_[2 * x + 1] = -1.0;
  for (int64_t i = 0; i < n; ++i) {
    if (!touched_[i] || inv_mass[i] == 0.0) continue;
    const double* v0 = start_.data() + 6 * i;
    const double* v1 = velocity_.data() + 6 * i;
    const Vec3 l0 = load3(v0), l1 = load3(v1), w0 = load3(v0 + 3), w1 = load3(v1 + 3);
    const Mat3& inertia = inertia_[i];
    const double before = (dot(l0, l0) / inv_mass[i] + dot(w0, mul(inertia, w0))) * 0.5;
    const double after = (dot(l1, l1) / inv_mass[i] + dot(w1, mul(inertia, w1))) * 0.5;
    const int32_t x = root(static_cast<int32_t>(i));
    gain_[2 * x] += after - before;
    if (gain_[2 * x + 1] >= 0.0) gain_[2 * x + 1] += before;
  }
  auto gained = [&](int32_t body) {
    const int32_t x = root(body);
    return gain_[2 * x + 1] >= 0.0 && gain_[2 * x] > 1e-10 * gain_[2 * x + 1] + 1e-300;
  };
  retry_.clear();
  bool any = false;   // (most substeps: no island gained, nothing to look for)
  for (int64_t i = 0; i < n && !any; ++i) any = island_[i] == i && gained(static_cast<int32_t>(i));
  if (!any) return 0;
  for (size_t m = 0; m < manifolds_.size(); ++m) {
    const Manifold& manifold = manifolds_[m];
    if (!gained(inv_mass[manifold.a] > 0.0 ? manifold.a : manifold.b)) continue;
    block(m);
    retry_.push_back(manifold);
  }
  if (retry_.empty()) return 0;
  // those islands again from their pre-solve velocities, without friction
  for (int64_t i = 0; i < n; ++i)
    if (touched_[i] && inv_mass[i] > 0.0 && gained(static_cast<int32_t>(i)))
      std::copy(start_.begin() + 6 * i, start_.begin() + 6 * i + 6, velocity_.begin() + 6 * i);
  for (const Manifold& m : retry_)
    for (int32_t i = m.first; i < m.first + m.count; ++i) {
      ContactRow& r = rows_[i];
      r.mu = r.normal = r.tangent[0] = r.tangent[1] = 0.0;
    }
  for (SpinRow& s : spins_)
    if (gained(inv_mass[s.a] > 0.0 ? s.a : s.b)) {
      s.roll = s.twist = 0.0;
      s.torque = Vec3::Zero();
    }
  return solve_velocities(rows_, retry_, ctx.solver, iterations, ctx.params.converged);
}

int StepSolver::exact_islands(StepContext& ctx, double share, double elapsed) {
  const SolverParams& p = ctx.params;
  const int64_t n = ctx.bodies.count;
  const double* inv_mass = ctx.bodies.inv_mass;
  if (!small_) {   // (the islands stay for the step: hold_energy found them)
    island_rows_.assign(n, 0);
    island_bodies_.assign(n, 0);
    for (const ContactRow& r : rows_) ++island_rows_[island_[r.ma != 0.0 ? r.a : r.b]];
    for (int64_t i = 0; i < n; ++i)
      if (touched_[i] && inv_mass[i] != 0.0) ++island_bodies_[island_[i]];
    for (const int32_t x : driven_) island_bodies_[x] = 0;
    small_ = true;
  }
  auto small = [&](int32_t x) {
    return island_bodies_[x] >= 2 && island_rows_[x] <= p.exact_rows;
  };
  // per small island: the mechanical energy its contacts' impulses gave it in the substep
  // (J): the kinetic energy at the end less at the start without the substep's external
  // change c (a ramped body's share), less the potential energy the change's force lost as
  // the pose moved with the end velocity (M c . v1: symplectic Euler); and how long it has
  // been held without such a gain (s, the least of its held bodies': quiet_; -1: not held)
  // and since its first solve found no set (lapse_, likewise). A body that left the small
  // islands is let go
  gain_exact_.assign(n, 0.0);
  island_quiet_.assign(n, -1.0);
  island_lapse_.assign(n, -1.0);
  bool any = false;
  // (an island's hold or lapse: the least of its bodies' that have one)
  auto least = [&any](double own, double& island) {
    if (own < 0.0) return;
    island = island < 0.0 ? own : std::min(island, own);
    any = true;
  };
  for (int64_t i = 0; i < n; ++i) {
    if (!touched_[i] || inv_mass[i] == 0.0) {
      quiet_[i] = lapse_[i] = -1.0;
      continue;
    }
    const int32_t x = island_[i];
    if (!small(x)) {
      quiet_[i] = lapse_[i] = -1.0;
      continue;
    }
    const double* v0 = start_.data() + 6 * i;
    const double* v1 = velocity_.data() + 6 * i;
    const Mat3& inertia = inertia_[i];
    const double mass = 1.0 / inv_mass[i];
    const Vec3 l1 = load3(v1), w1 = load3(v1 + 3), iw1 = mul(inertia, w1);
    Vec3 l0 = load3(v0), w0 = load3(v0 + 3), cl = Vec3::Zero(), cw = Vec3::Zero();
    if (ramped_[i]) {
      cl = share * load3(ramp_.data() + 6 * i);
      cw = share * load3(ramp_.data() + 6 * i + 3);
      l0 -= cl;
      w0 -= cw;
    }
    gain_exact_[x] += 0.5 * (mass * dot(l1, l1) + dot(w1, iw1)) -
                      0.5 * (mass * dot(l0, l0) + dot(w0, mul(inertia, w0))) -
                      mass * dot(cl, l1) - dot(cw, iw1);
    least(quiet_[i], island_quiet_[x]);
    least(lapse_[i], island_lapse_[x]);
    any = any || gain_exact_[x] > p.exact_work;
  }
  if (!any) {
    exact_set_.clear();
    return 0;
  }
  // the islands to solve (their roots' slots): those whose contacts gave more than
  // exact_work, and those held since such a substep until the sweeps have given them no
  // more than exact_quiet for exact_hold: a rocking column's sweeps gain where it changes
  // the edge it rocks on (the warm start's impulses held it leaning the other way), and
  // it changes edges within 0.15 s until it rests; a settled tower's sweeps lose. Not
  // those whose first solve found no set within exact_hold: towers of piles settling from
  // the drop whose sweeps gain 3e-4-1.3e-3 J a substep found none in every substep
  exact_slot_.assign(n, -1);
  exact_held_.resize(n);
  size_t islands = 0;
  for (int64_t i = 0; i < n; ++i) {
    if (island_[i] != i || !small(static_cast<int32_t>(i))) continue;
    double& quiet = island_quiet_[i];
    double& lapse = island_lapse_[i];
    if (lapse >= 0.0) lapse += elapsed;
    if (lapse > p.exact_hold) lapse = -1.0;
    const bool held = quiet >= 0.0, fired = gain_exact_[i] > p.exact_work && lapse < 0.0;
    if (held)
      quiet += elapsed;
    else if (fired)
      quiet = 0.0;
    if (quiet > p.exact_hold && !fired) quiet = -1.0;
    if (quiet < 0.0) continue;
    exact_held_[islands] = held;
    exact_slot_[i] = static_cast<int32_t>(islands++);
  }
  if (exact_rows_.size() < islands) {
    exact_rows_.resize(islands);
    exact_bodies_.resize(islands);
    exact_root_.resize(islands);
  }
  for (size_t k = 0; k < islands; ++k) {
    exact_rows_[k].clear();
    exact_bodies_[k].clear();
  }
  for (size_t i = 0; i < rows_.size(); ++i) {
    const ContactRow& r = rows_[i];
    const int32_t slot = exact_slot_[island_[r.ma != 0.0 ? r.a : r.b]];
    if (slot >= 0) exact_rows_[slot].push_back(static_cast<int32_t>(i));
  }
  for (int64_t i = 0; i < n; ++i) {
    if (!touched_[i] || inv_mass[i] == 0.0) continue;
    const int32_t slot = exact_slot_[island_[i]];
    if (slot >= 0) exact_bodies_[slot].push_back(static_cast<int32_t>(i));
    if (island_[i] == i && slot >= 0) exact_root_[slot] = static_cast<int32_t>(i);
  }
  // the velocities the rows' impulses act on: the substep's start with the spin rows' torques
  base_.assign(start_.begin(), start_.end());
  for (const SpinRow& spin : spins_) {
    if (exact_slot_[island_[inv_mass[spin.a] != 0.0 ? spin.a : spin.b]] < 0) continue;
    if (inv_mass[spin.a] != 0.0)
      store3(base_.data() + 6 * spin.a + 3,
             load3(base_.data() + 6 * spin.a + 3) - mul(spin.inv_a, spin.torque));
    if (inv_mass[spin.b] != 0.0)
      store3(base_.data() + 6 * spin.b + 3,
             load3(base_.data() + 6 * spin.b + 3) + mul(spin.inv_b, spin.torque));
  }
  const IslandSettings settings{p.exact_rounds, p.exact_tolerance, p.exact_regularise};
  int taken = 0;
  exact_next_.clear();
  for (size_t k = 0; k < islands; ++k) {
    // each row starts from the set its contact's last solve found (in the substep before),
    // else sticking: the rocking column (test_column_rocking) changed its set 1.4 times a
    // solve so, 5.9 from every row sticking. Where that start finds no set, the solve starts
    // again from every row sticking: the set a column of 8 cubes found in the substep it
    // landed as one island (bench_laws' dropped column, 30 Hz) slid its base rows along
    // the impact's friction directions, and from it the next substep's rows changed
    // between sliding and sticking for all of exact_rounds (from every row sticking: its
    // set in 15); left to the sweeps, the column sank 2.30 mm into itself (1.14 mm)
    const std::vector<int32_t>& members = exact_rows_[k];
    auto sticking = [&] {   // every row sticking (sliding along no direction)
      exact_state_.assign(members.size(), IslandSolve::kStick);
      exact_along_.assign(2 * members.size(), 0.0);
    };
    sticking();
    bool warm = false;
    for (size_t j = 0; j < members.size(); ++j) {
      const ContactRow& r = rows_[members[j]];
      const auto found = exact_set_.find({r.a, r.b, ctx.contacts.feature[r.contact]});
      if (found == exact_set_.end()) continue;
      warm = true;
      exact_state_[j] = found->second.state;
      if (found->second.state != IslandSolve::kSlide) continue;
      const double x = dot(found->second.along, r.t1), y = dot(found->second.along, r.t2);
      const double length = norm2(x, y);
      if (length > 0.0) {
        exact_along_[2 * j] = x / length;
        exact_along_[2 * j + 1] = y / length;
      }
    }
    IslandSolve::Outcome outcome =
        island_solve_.solve(rows_, members, exact_bodies_[k], ctx.solver, inertia_.data(),
                            base_.data(), velocity_.data(), settings, exact_state_.data(),
                            exact_along_.data());
    if (outcome == IslandSolve::kUnsolved && warm) {
      sticking();
      outcome = island_solve_.solve(rows_, members, exact_bodies_[k], ctx.solver,
                                    inertia_.data(), base_.data(), velocity_.data(), settings,
                                    exact_state_.data(), exact_along_.data());
    }
    for (size_t j = 0; j < members.size() && outcome != IslandSolve::kUnsolved; ++j) {
      const ContactRow& r = rows_[members[j]];
      exact_next_[{r.a, r.b, ctx.contacts.feature[r.contact]}] = ExactSet{
          exact_state_[j], exact_along_[2 * j] * r.t1 + exact_along_[2 * j + 1] * r.t2};
    }
    taken += outcome == IslandSolve::kTaken;
    double& quiet = island_quiet_[exact_root_[k]];
    if (outcome == IslandSolve::kTaken && gain_exact_[exact_root_[k]] > p.exact_quiet) {
      quiet = 0.0;
    } else if (outcome == IslandSolve::kUnsolved && !exact_held_[k]) {
      quiet = -1.0;
      island_lapse_[exact_root_[k]] = 0.0;   // not solved again for exact_hold
    }
  }
  exact_set_.swap(exact_next_);
  // the islands' holds, on their bodies (for the next substep and step)
  for (int64_t i = 0; i < n; ++i)
    if (touched_[i] && inv_mass[i] != 0.0 && small(island_[i])) {
      quiet_[i] = island_quiet_[island_[i]];
      lapse_[i] = island_lapse_[island_[i]];
    }
  return taken;
}

bool StepSolver::escaped(const StepContext& ctx, bool landed) {
  const ContactsView& c = ctx.contacts;
  const int64_t n = ctx.bodies.count;
  // per body: how far a point of it moved (m) and how much its speed changed from the
  // pre-solve velocity at most (m/s), over the reach of its contacts; a contact whose gap
  // or slack exceeds its two bodies' is known to hold (the test's answer: the same bits)
  // (per body, then per contact without a row: each writes only its own entries, in parts)
  change_.resize(2 * n);
  in_parts(ctx, n, [&](int64_t lo, int64_t hi) {
    for (int64_t i = lo; i < hi; ++i) {
      const double* x = moved_.data() + 6 * i;
      const double* v = velocity_.data() + 6 * i;
      const double* u = later_.data() + 6 * i;
      change_[2 * i] = length(load3(x)) + length(load3(x + 3)) * reach_body_[i];
      change_[2 * i + 1] = landed ? length(load3(v) - load3(u)) +
                                        length(load3(v + 3) - load3(u + 3)) * reach_body_[i]
                                  : 0.0;
    }
  });
  std::atomic<bool> any{false};
  in_parts(ctx, static_cast<int64_t>(rowless_.size()), [&](int64_t lo, int64_t hi) {
    if (escaped_part(ctx, landed, lo, hi)) any.store(true, std::memory_order_relaxed);
  });
  return any.load(std::memory_order_relaxed);
}

COLLRES_CLONED_FLAT
bool StepSolver::escaped_part(const StepContext& ctx, bool landed, int64_t lo, int64_t hi) {
  const ContactsView& c = ctx.contacts;
  constexpr double kSure = 1.0 + 1e-9;   // (rounding)
  bool forced = false;
  for (int64_t j = lo; j < hi; ++j) {
    const int32_t k = rowless_[static_cast<size_t>(j)];
    const int64_t a = c.a[k], b = c.b[k];
    const double* ca = change_.data() + 2 * a;
    const double* cb = change_.data() + 2 * b;
    if (gap_[k] > kSure * (ca[0] + cb[0]) &&
        (!landed || approach_[k] + allowance_[k] > kSure * (ca[1] + cb[1])))
      continue;
    const Vec3 normal = load3(c.normal + 3 * k);
    // its separation at the step's end: the reference gap plus how far the substeps moved
    // its two points along the normal; after a landing, its approach then
    bool out = gap_[k] + normal_speed(moved_.data(), a, b, ra_[k], rb_[k], normal) < 0.0;
    out = out || (landed && normal_speed(velocity_.data(), a, b, ra_[k], rb_[k], normal) +
                                    allowance_[k] < 0.0);
    if (out) {
      forced_[k] = 1;
      forced = true;
    }
  }
  return forced;
}

// What a 30 Hz step costs against a 120 Hz one, measured on the bench's settled mixed piles
// (bench/pile.py; instructions of a warm step, detection and solve, one thread): 100 bodies 5.23 ->
// 8.69 M (1.66x), 1000 bodies 50.0 -> 81.8 M (1.64x); wall, bench_step: 1.58x and 1.77x. The sweeps
// decide it: five substeps of 11 sweeps here (the last three the landing's) against two of 11 and a
// landing of 10 at 120 Hz, 55 against 32 (1.72x), and they cost 1.92x / 1.86x (a few more manifolds
// swept, in more part-filled groups: 100 bodies 183 manifolds in 53 groups a sweep against 176 in
// 47). With every other stage as at 120 Hz, the sweeps at their count alone would make the step
// 1.34x / 1.31x: a ratio near 1.3 needs fewer sweeps a substep or fewer substeps
// (velocity_iterations and max_substep, whose reasons are laws that failed), not less overhead. The
// rest, 30 / 120 Hz at 100 and 1000 bodies: detection 1.24x / 1.22x (the pair margin: 20 mm against
// 10, a third more points; at 1000 bodies 97 % of the stored manifolds reused against 99.8 %, the
// others shifted or turned beyond reuse_shift and kReuseRotation in the longer step); prepare 1.42x
// / 1.21x (rows 1.43x / 1.29x: 22-25 % of a 30 Hz step's rows are speculative ones never swept);
// admission 1.61x / 2.34x, of which the sweeps' plans 1.0x / 2.49x (manifolds let in at the
// substeps' starts: 7.5 plans a step against 4 at 1000 bodies); the substeps' own passes over every
// row (warm start 2.9x, aim 2.9x / 3.3x, shock propagation 2.0x / 2.2x, hold_energy 1.7x, the
// allowances, sums and the sweeps' starting impulses), which are bound by memory (at 1000 bodies
// 1.5 ms of a 30 Hz step against 0.4 ms of a 120 Hz one); push-out 1.57x / 1.34x; the landing 0.42x
// / 0.58x (shared); the net solved no step twice at either rate
int StepSolver::soft_step(StepContext& ctx, int substeps, int iterations, int shared) {
  const SolverParams& p = ctx.params;
  const int64_t n = ctx.bodies.count;
  const size_t rows = rows_.size();
  const double share = 1.0 / substeps;
  // per body: the displacement and turn (m, rad) since its reference time and the mean
  // velocity over the substeps (what the poses travel with); per row: the summed
  // impulses (N s) of the substeps before the last
  moved_.assign(6 * n, 0.0);
  travel_.assign(6 * n, 0.0);
  total_.assign(3 * rows, 0.0);
  from_impulse_.resize(3 * rows);
  // Each substep's one pass over the rows, after the warm start a few rows at a time while
  // they are in the cache (at 1000 bodies the rows, 3-5 MB at 30 Hz, do not fit in it: a
  // pass is bound by memory): the last substep's impulses summed (but an aimed row's,
  // summed before aim turns its frame), each row's allowance: its separation now, the
  // reference gap plus how far its two points moved along the normal in the substeps so far
  // (no new detection; two spheres': from their centres, aim), and the impulses the sweeps
  // start from (sweep's from_impulse_). As four passes (the warm start, the allowances, the
  // sums, sweep's copy), a step of 1000 settled cubes at 30 Hz took 4-6 % longer (one and
  // two threads)
  const auto ready = [&](int64_t lo, int64_t hi, bool sum) {
    const uint8_t* const aiming = aiming_.data();
    const double *const aimed = aimed_gap_.data(), *const moved = moved_.data();
    const double *const gap = gap_.data(), *const span = span_.data();
    ContactRow* const row = rows_.data();
    double *const total = total_.data(), *const from = from_impulse_.data();
    for (int64_t i = lo; i < hi; ++i) {
      ContactRow& r = row[i];
      if (sum && !aiming[i]) add_impulses(r, total + 3 * i);
      const double separation = aiming[i] ? aimed[i] : gap[r.contact] + normal_velocity(r, moved);
      r.allowance = std::max(separation, 0.0) / (span[r.contact] * share);
      save_impulses(r, from + 3 * i);
    }
  };
  int sweeps = 0;
  for (int s = 0; s < substeps; ++s) {
    if (s == 0) {
      in_parts(ctx, static_cast<int64_t>(rows),
               [&](int64_t lo, int64_t hi) { ready(lo, hi, false); });
    } else {
      // a rested body's share of the external change, then the warm start from the
      // last substep's impulses (the spin rows start cold); per body, in parts
      start_.resize(6 * n);
      in_parts(ctx, n, [&](int64_t lo, int64_t hi) {
        const uint8_t* const ramped = ramped_.data();
        const double* const ramp = ramp_.data();
        double *const v = velocity_.data(), *const start = start_.data();
        for (int64_t i = lo; i < hi; ++i) {
          if (ramped[i])
            for (int d = 0; d < 6; ++d) v[6 * i + d] += share * ramp[6 * i + d];
          for (int d = 0; d < 6; ++d) start[6 * i + d] = v[6 * i + d];
        }
      });
      for (SpinRow& spin : spins_) spin.torque = Vec3::Zero();
      if (!aimed_.empty()) {
        for (const int32_t i : aimed_) add_impulses(rows_[static_cast<size_t>(i)], &total_[3 * i]);
        aim(ctx, moved_.data(), velocity_.data(), 0.5 * ctx.dt * share);
        bool stale = false;   // (shock propagation's copy of a turned row)
        for (const ContactRow& r : shock_rows_) stale = stale || turned_[r.contact];
        if (stale)
          shock_rows(rows_, level_, order32_, shock_rows_, shock_blocks_, holding_, p.shock_ratio,
                     p.wide_rows);
      }
      // the warm start (in order: it writes the bodies' velocities) and the pass, a few
      // rows at a time, while those rows are in the cache
      for (size_t lo = 0; lo < rows; lo += kWarmRows) {
        const size_t hi = std::min(rows, lo + kWarmRows);
        warm_start(rows_.data() + lo, hi - lo, ctx.solver);
        ready(static_cast<int64_t>(lo), static_cast<int64_t>(hi), true);
      }
    }
    // (the last substep's last `shared` sweeps are the landing's, after the poses' travel)
    sweeps += sweep(ctx, s + 1 < substeps ? iterations : std::max(iterations - shared, 1), 1.0,
                    true);
    propagate_shock(rows_, ctx.solver, level_, shock_rows_, shock_blocks_, p.shock_sweeps);
    // judged after shock propagation: its rows, swept one by one from the sweeps'
    // impulses, can raise the energy the sweeps kept (a box on one point of a fixed
    // sphere: +2.6e-4)
    sweeps += hold_energy(ctx, iterations);
    exact_islands(ctx, share, ctx.dt * share);
    // the poses travel with the substep's velocity for its share of the body's time (per
    // body), in parts (the impulses are summed by the next substep's pass)
    const double dt = ctx.dt;
    in_parts(ctx, n, [&](int64_t lo, int64_t hi) {
      const double *const fraction = fraction_.data(), *const v = velocity_.data();
      double *const moved = moved_.data(), *const travel = travel_.data();
      for (int64_t i = lo; i < hi; ++i) {
        const double h = (1.0 - fraction[i]) * dt * share;
        for (int d = 0; d < 6; ++d) {
          moved[6 * i + d] += h * v[6 * i + d];
          travel[6 * i + d] += share * v[6 * i + d];
        }
      }
    });
  }
  return sweeps;   // (land sets the step's allowances again)
}

bool StepSolver::land(StepContext& ctx, int substeps, int shared, bool& struck) {
  const SolverParams& p = ctx.params;
  // the landing rows: speculative (a gap at the reference time) and holding, i.e. the
  // contact closes within the step and the solve let it approach by its gap only (an
  // impulse in any substep: one that closed in an earlier substep holds with none in the
  // last; missed, two 5 mm balls of an elastic gas, one driven into the other by a wall's
  // impact, stopped inelastically: 1.3 % of the gas's energy in a step at 30 Hz). One
  // that closes faster than the restitution threshold (its approach as the resting solve
  // began, after the impact stages: two balls passing each other, or one that a partner's
  // impact drives in) from a gap beyond the slop is an impact: marked in struck_, and the
  // step is solved again with it in the impact stages. (Landed, it stopped inelastically:
  // an elastic gas of 40 balls of 5 mm in a 10 cm box lost 6 % of its energy in one step
  // at 100 Hz. Within the slop it is touching: a ball hopping that close to its floor,
  // bounced there without a rewind, rose higher each hop.)
  landing_.resize(rows_.size());
  bool any = false;
  for (size_t i = 0; i < rows_.size(); ++i) {
    ContactRow& r = rows_[i];
    r.allowance = allowance_[r.contact];   // the step's again (the substeps' before)
    landing_[i] = r.normal;
    r.landing = 0.0;
    if (gap_[r.contact] > 0.0 && r.allowance > 0.0 && r.normal + total_[3 * i] > 0.0) {
      r.allowance = 0.0;
      any = true;
      if (!struck_[r.contact] && gap_[r.contact] > p.linear_slop &&
          normal_velocity(r, resting_.data()) < -resting_speed_[r.contact]) {
        struck_[r.contact] = 1;
        struck = true;
      }
    }
  }
  if (!any && shared == 0) return false;
  // every row again, the landing ones without allowance: the velocities (not the poses,
  // which travel_ holds) leave the touching contacts at rest along their normals. These
  // sweeps are also the last ones of the answer's velocities, which the laws need whole: a
  // settled pile lands 4-10 % of its rows at every step (bench/pile.py, 100 and 1000 bodies
  // at 30 and 120 Hz: nearly all within 5e-5 m of the touch and approaching slower than 1e-3
  // m/s) and its sweeps here change 50-87 % of its rows' impulses by more than `converged`
  // (they never converge). Sweeping only the manifolds of the approaching landing rows and
  // of their movable bodies (2.7-7.7 % fewer instructions a step) let a tower of 20 cubes of
  // 0.2 m fall at 240 Hz (its floor contact lands: the column above stops as one); falling
  // back to every row where that changed a row beyond them by 10 % of the fastest landing
  // approach, the piles fell back at 11-12 of 12-13 landings; landing only rows approaching
  // faster than 1 % of their bodies' g dt left a pile of 100 cubes awake after 4 s at 120
  // Hz; 5 sweeps of every row instead of velocity_iterations let the tower fall, and with no
  // landing at all its top sank 7 mm in 0.25 s, rocking at up to 0.07 m/s (landed: 0.8 mm,
  // then still).
  // From landing_substeps substeps on (30 Hz: five) the landing replaces sweeps instead of
  // adding them: the last substep's first sweeps give the poses' travel, its last `shared`
  // (landing_sweeps), every row with the step's allowance as above, the answer's
  // velocities (with no landing row too, so that they always get the substep's sweeps).
  // The answer needs the landing's own sweeps the more, the larger the last substep's
  // share of the step. Shared at one substep (240 Hz, five and five) towers of 20 cubes of
  // 0.2 m fell; at two (120 Hz) a 1000 kg cube on a 1 kg one slid 3.6 mm and a pile of 100
  // cubes (bench/pile.py, seed 1) was awake after 6 s (also with ten for the poses and five
  // more for the landing); at three (60 Hz) a column of 8 cubes dropped apart (bench_laws
  // column) overlapped 10.6 mm; at three and four piles of 100 fell asleep 0.2-0.3 s later.
  // At five: five for the landing left a box dropped on a settled pile 0.20 mm deep in it
  // (0.11 with three, as with a landing of its own); the last substep's allowances instead
  // of the step's let the column overlap 3.4 mm (1.2 mm now, 1.9 mm with a landing of its
  // own); the poses' last travel from the landed velocities failed test_fast_approach.py's
  // column and cube on a cube
  // Its sweeps admit manifolds by the margin a substep's do, over the substeps: their
  // allowances are the step's (gap / dt), a substep's times the substeps, and at the
  // substep's margin a settled pile let in every manifold within 3.3 mm of touching at 30 Hz
  // (0.67 mm in a substep), none of which carried anything (1000 cubes: 344 more manifolds,
  // each prepared, planned and swept for nothing); the check after the sweeps lets in any
  // that the answer reaches, as in a substep
  const int sweeps = shared > 0 ? shared : p.velocity_iterations;
  sweep(ctx, sweeps, 1.0 / substeps);
  // judged as a substep (against the last substep's start): the landing's sweeps with
  // friction can raise the energy too (a box on three close points: +7 % of the step's)
  hold_energy(ctx, sweeps);
  exact_islands(ctx, 1.0 / substeps, 0.0);
  for (size_t i = 0; i < rows_.size(); ++i) {
    ContactRow& r = rows_[i];
    r.landing = r.normal - landing_[i];     // reported, not warm started
    r.normal = landing_[i];
  }
  return true;
}

void StepSolver::report(StepContext& ctx) {
  cached_normal_.resize(ctx.contacts.count);   // what is stored for the warm start
  // per contact, its row's impulses and state (none: speculative, no impulse); each part
  // writes only its contacts' entries (on either thread)
  in_parts(ctx, ctx.contacts.count,
           [&](int64_t lo, int64_t hi) { report_contacts(ctx, lo, hi); });
  // STICKING -> RESTING where a manifold's friction impulses sum to nothing (a box at rest
  // on a flat floor may carry equal and opposite friction at its corners: no net friction);
  // each part writes only its manifolds' contacts
  in_parts(ctx, ctx.contacts.manifold_count,
           [&](int64_t lo, int64_t hi) { report_manifolds(ctx, lo, hi); });
}

COLLRES_CLONED_FLAT
void StepSolver::report_contacts(const StepContext& ctx, int64_t lo, int64_t hi) {
  // (the views by value and the arrays through local pointers: a store of a state, a
  // byte, may alias any memory, see reference_frame)
  const ContactsOut o = ctx.report;
  double* const cache = cached_normal_.data();
  const int32_t* const row = row_of_.data();
  const ContactRow* const rows = rows_.data();
  const double* const vel = velocity_.data();
  const double sticking = ctx.params.sticking_speed;
  for (int64_t k = lo; k < hi; ++k) {
    if (row[k] < 0) {
      cache[k] = 0.0;
      o.normal_impulse[k] = 0.0;
      store3(o.friction_impulse + 3 * k, Vec3::Zero());
      o.state[k] = kResting;
      continue;
    }
    const ContactRow& r = rows[row[k]];
    cache[k] = r.normal;
    o.normal_impulse[k] = r.normal + r.impact + r.landing;
    store3(o.friction_impulse + 3 * k, friction_world(r));
    o.state[k] = contact_state(r, vel, sticking);
  }
}

COLLRES_CLONED_FLAT
void StepSolver::report_manifolds(const StepContext& ctx, int64_t first, int64_t last) const {
  const ContactsOut o = ctx.report;   // (in locals: see report_contacts)
  const int64_t* const manifolds = ctx.contacts.manifolds;
  const double balanced = ctx.params.balanced_friction;
  for (int64_t span = first; span < last; ++span) {
    const int64_t lo = manifolds[kManifoldFields * span + 2];
    const int64_t hi = lo + manifolds[kManifoldFields * span + 3];
    bool sticking = false;
    for (int64_t k = lo; k < hi && !sticking; ++k) sticking = o.state[k] == kSticking;
    if (!sticking) continue;
    Vec3 friction = Vec3::Zero();
    double normal = 0.0;
    for (int64_t k = lo; k < hi; ++k) {
      friction += load3(o.friction_impulse + 3 * k);
      normal += o.normal_impulse[k];
    }
    if (length(friction) <= balanced * normal + 1e-15) {
      for (int64_t k = lo; k < hi; ++k)
        if (o.state[k] == kSticking) o.state[k] = kResting;
    }
  }
}

int32_t StepSolver::levels(StepContext& ctx) {
  const int64_t n = ctx.bodies.count;
  // contact graph of the rows (CSR), then breadth first from the immovable bodies. A row
  // on an immovable body is an edge only where that body holds the movable one up: the
  // step's external change of the movable body's linear velocity (now - then: gravity
  // dt) presses it into the immovable one, its component along the normal at least
  // support_cosine of its length, or it has none (a weightless input). A wall beside a
  // body is no support: counted as one, it made the bodies of a bin's outer columns
  // level 1 whatever their height, and the push-out's hold (solve_positions) then pushed
  // the body under one of them down. A body that a chain of near rows reaches (touching at
  // the previous state, within the slop, or closing within the step on the held paths) has
  // its level over those alone; the far rows count only for the others: at 30 Hz (g dt^2
  // 11 mm) the floor and a 1000 kg cube of 1 cm on a 1 kg one are a pair (1 cm apart,
  // within the speculative margin), and over it the heavy cube stood on the floor at level 1
  // beside the light one and sank through it (3.5 mm in the first step, onto the floor in
  // three)
  const double* now = now_.data();
  const double* then = then_.data();
  const double slop = ctx.params.linear_slop;
  const double* separation = ctx.contacts.separation;
  auto edge = [&](const ContactRow& r) {
    const bool a_fixed = touched_[r.a] == 0, b_fixed = touched_[r.b] == 0;
    if (a_fixed == b_fixed) return true;
    const int64_t i = a_fixed ? r.b : r.a;
    const Vec3 external = load3(now + 6 * i) - load3(then + 6 * i);
    const double into = a_fixed ? -dot(external, r.n) : dot(external, r.n);
    return into >= ctx.params.support_cosine * length(external);
  };
  auto near = [&](const ContactRow& r) {
    return gap_[r.contact] <= slop || separation[r.contact] + drift_[r.contact] <= slop;
  };
  first_.assign(n + 1, 0);
  for (const ContactRow& r : rows_) {
    if (!edge(r)) continue;
    ++first_[r.a + 1];
    ++first_[r.b + 1];
  }
  for (int64_t i = 0; i < n; ++i) first_[i + 1] += first_[i];
  adjacency_.resize(first_[n]);
  adjacent_near_.resize(first_[n]);
  order32_.assign(first_.begin(), first_.end() - 1);   // fill cursor per body
  for (const ContactRow& r : rows_) {
    if (!edge(r)) continue;
    const uint8_t close = near(r) ? 1 : 0;
    adjacent_near_[order32_[r.a]] = close;
    adjacency_[order32_[r.a]++] = r.b;
    adjacent_near_[order32_[r.b]] = close;
    adjacency_[order32_[r.b]++] = r.a;
  }
  // breadth first from the immovable bodies in contact, over the near rows (only_near)
  // or over all
  auto search = [&](std::vector<int32_t>& level, bool only_near) {
    level.assign(n, -1);
    queue_.clear();
    for (int64_t i = 0; i < n; ++i)
      if (!touched_[i] && first_[i + 1] > first_[i]) {   // immovable and in contact
        level[i] = 0;
        queue_.push_back(static_cast<int32_t>(i));
      }
    for (size_t head = 0; head < queue_.size(); ++head) {
      int32_t i = queue_[head];
      for (int32_t k = first_[i]; k < first_[i + 1]; ++k) {
        int32_t j = adjacency_[k];
        if (level[j] < 0 && (adjacent_near_[k] || !only_near)) {
          level[j] = level[i] + 1;
          queue_.push_back(j);
        }
      }
    }
  };
  search(level_far_, false);
  search(level_, true);
  int32_t depth = 0;
  for (int64_t i = 0; i < n; ++i) {
    if (level_[i] < 0) level_[i] = level_far_[i];
    depth = std::max(depth, level_[i]);
  }
  return depth;
}

void StepSolver::advance(StepContext& ctx) {
  const BodyStatesView &previous = ctx.previous, &current = ctx.current;
  const double dt = ctx.dt;
  BodyStatesOut& out = ctx.out;
  const int64_t n = static_cast<int64_t>(touched_.size());
  for (int64_t i = 0; i < n; ++i) {
    if (!touched_[i]) continue;
    const double* v = velocity_.data() + 6 * i;
    const double* u = travel_.data() + 6 * i;
    Vec3 x0 = load3(previous.position + 3 * i);
    Quat q0 = load4(previous.orientation + 4 * i);
    if (!impacted_[i]) {
      // persistent contact only: previous pose advanced by the travel velocity for dt
      store3(out.linear + 3 * i, load3(v));
      store3(out.angular + 3 * i, load3(v + 3));
      store3(out.position + 3 * i, x0 + dt * load3(u));
      store4(out.orientation + 4 * i, integrate(q0, load3(u + 3), dt));
      continue;
    }
    // impact: rewind to the time of impact, advance for the rest of the step with the
    // travel velocity (u, v: velocity at the time of impact + (1 - f) / 2 external)
    const double f = fraction_[i], tau = (1.0 - f) * dt;
    double end[6], mean[6];
    for (int d = 0; d < 6; ++d) {
      double external = now_[6 * i + d] - then_[6 * i + d];
      end[d] = v[d] - 0.5 * f * external;   // mid-step twist, as the input's: at the time
                                            // of impact v - (1 - f) / 2 ext, + (1/2 - f) ext
      mean[d] = u[d];                       // the travel of the poses
    }
    store3(out.linear + 3 * i, load3(end));
    store3(out.angular + 3 * i, load3(end + 3));
    // (a supported body from its pose at f on its held path: its previous twist)
    const double* held = path_.data() + 6 * i;
    Vec3 start = supported_[i] ? Vec3(x0 + f * dt * load3(held))
                               : Vec3(x0 + f * (load3(current.position + 3 * i) - x0));
    store3(out.position + 3 * i, start + tau * load3(mean));
    Quat turned = supported_[i] ? integrate(q0, load3(held + 3), f * dt)
                                : slerp(q0, load4(current.orientation + 4 * i), f);
    store4(out.orientation + 4 * i, integrate(turned, load3(mean + 3), tau));
  }
}

void StepSolver::push_out(StepContext& ctx) {
  const BodyProperties& bodies = ctx.bodies;
  const SolverParams& p = ctx.params;
  const double dt = ctx.dt;
  BodyStatesOut& out = ctx.out;
  // predicted gap at the end of the step = reference gap + new normal speed times the
  // remaining time (two spheres: from their centres there, aimed along that line: moved_
  // is the substeps' travel); beyond the slop a fraction of it (at most max_correction)
  // is removed
  aim(ctx, moved_.data(), nullptr, 0.0);
  for (size_t i = 0; i < rows_.size(); ++i) {
    ContactRow& r = rows_[i];
    double predicted =
        aiming_[i] ? aimed_gap_[i]
                   : gap_[r.contact] + normal_velocity(r, travel_.data()) * remaining_[r.contact];
    double depth = std::min(p.position_correction *
                                std::max(-predicted - p.linear_slop, 0.0),
                            p.max_correction);
    r.push = depth / dt;
  }
  if (!solve_positions(rows_, ctx.solver, level_, p.shock_ratio, pseudo_.data(),
                       p.position_iterations, p.fixed_sweeps, p.deep_sweeps,
                       p.position_correction * p.deep_overlap / dt))
    return;
  for (int64_t i = 0; i < bodies.count; ++i) {
    const double* w = pseudo_.data() + 6 * i;
    if (!touched_[i] || (w[0] == 0.0 && w[1] == 0.0 && w[2] == 0.0 && w[3] == 0.0 &&
                         w[4] == 0.0 && w[5] == 0.0))
      continue;
    store3(out.position + 3 * i, load3(out.position + 3 * i) + dt * load3(w));
    store4(out.orientation + 4 * i,
           integrate(load4(out.orientation + 4 * i), load3(w + 3), dt));
  }
}

}  // namespace collres
