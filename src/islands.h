// Islands and sleep: a settled group of bodies costs no detection and no solve.
//
// As Box2D v3 and Jolt: bodies joined by this step's contacts form an island, whether or
// not a contact carried impulse (touching or within the speculative margin, as Box2D v3's
// touching manifolds, which include its speculative points: a pile whose contacts carry
// impulse only now and then is one island, not pieces that fall asleep one by one and wake
// each other); static, kinematic and inactive bodies never join one (they do not pass
// motion on); each dynamic body has a sleep timer, the time its speed has stayed below
// `threshold` (speed of its farthest point, |v| + |w| r, m/s, r its bounding radius about
// the centre of mass); an island whose bodies have all been still for `time_to_sleep`
// (s) falls asleep. A body whose speed has risen in each of its last steps for
// `rise_time` times `time_to_sleep` or longer (each rise more than `rise_step` times
// `threshold`) is accelerating, not at rest: an unbalanced load (a ball on a slope just
// steeper than its rolling resistance allows) speeds it up step after step however slowly,
// while a body at rest under balanced loads has a speed that decays or jitters (round-off,
// the solve's residual); it keeps its still time but keeps its island awake until a step
// in which its speed did not rise (or it passes the threshold). Awake islands are rebuilt
// every step (union-find over the step's contacts, Jolt's way); a sleeping island keeps
// its members until it wakes.
//
// In a pipeline the bodies keep arriving: upstream integrates a sleeping body from the
// held answer (held pose, zero twist), so its input is the held pose plus what its
// integrator adds (gravity dt). Each body's velocity change per input, dv = v_in - v_last,
// and its external acceleration a = dv / dt are kept (6 values each: linear, angular, world
// frame); while asleep they are the ones measured when it fell asleep, and an input departs
// from the held state when
//   jolt  = speed of the smaller of (v_in - v_last - a dt) and (v_in - v_last - dv)
//         > threshold                 (a push; the second form holds when an input was lost
//                                      and dt spans two of the upstream's periods), or
//   |x_in - x_held| > (|v_in| + threshold) dt, or the turn from the held orientation
//   times r > (|w_in| r + threshold) dt                           (a teleport, a correction);
// unless the input is the held state integrated k = 2 .. `late_steps` times by the same
// change (an upstream that integrated an answer k - 1 periods old: one came late):
//   speed of (v_in - v_last - k dv) <= threshold and
//   |x_in - x_held - k (k + 1) / 2 dv dt| <= threshold dt (and the turn's test above).
// Before detection (Islands::wake) an island wakes when one of its bodies departs, or when
// the swept bounds of a moving body touch one of its bodies' bounds (spheres of radius r
// about the centre of mass, padded by half the speculative margin as detection's boxes).
// Moving: a body the caller flags (kinematic, back from held, restarted fresh; a sleeper so
// flagged wakes its own island), or an awake dynamic body whose last answer
// was faster than the threshold or whose input jolts beyond it. An awake body at rest
// beside a sleeping island does not wake it (detection treats the sleeper as fixed; a
// contact with it that carries impulse wakes it after the step, Islands::update).
//
// Frames: world. Units: SI. All arrays are rows of N bodies (positions (N, 3), orientations
// (N, 4) x y z w, twists (N, 3)).
#pragma once

#include <cstdint>
#include <vector>

namespace collres {

struct SleepSettings {
  double threshold = 0.05;     // m/s, speed of the farthest point under which a body is still
  double time_to_sleep = 0.5;  // s a whole island must stay still before it sleeps
  double margin = 0.02;        // m, speculative margin: bounds are padded by half of it
  int late_steps = 1;          // most periods an upstream's input may be integrated from the
                               // held state and keep it asleep (1: only the usual one)
  double rise_time = 0.6;      // fraction of time_to_sleep: a body whose speed rose in each
                               // step for this long keeps its island awake (accelerating)
  double rise_step = 1e-6;     // fraction of threshold: the least rise (m/s a step) counted
};

// Rows of N states (read only).
struct SleepStates {
  const double* position = nullptr;
  const double* orientation = nullptr;
  const double* linear = nullptr;
  const double* angular = nullptr;
};

class Islands {
 public:
  // `radius` (m, bounding radius about the centre of mass; inf for half-spaces),
  // `dynamic` (1: can move and sleep) per body.
  Islands(std::vector<double> radius, std::vector<std::uint8_t> dynamic);

  void set_settings(const SleepSettings& settings) { settings_ = settings; }
  const SleepSettings& settings() const { return settings_; }
  int count() const { return static_cast<int>(radius_.size()); }

  // (N,) 1 where the body is asleep.
  const std::vector<std::uint8_t>& asleep() const { return asleep_; }
  // (N,) s each body has been still (timer).
  const std::vector<double>& still_time() const { return timer_; }

  // Everything awake, timers to zero (a body added or removed, a material, filter or
  // settings change, a clock jump).
  void wake_all();

  // Before detection: wake the islands whose inputs depart from the held state or that a
  // moving body's swept bounds touch (see the file comment); remember each awake body's
  // acceleration. `previous` is the last answer (held state for the sleepers), `current`
  // the inputs; `active` (N,) 0 = no input this step (held, never moving); `kinematic`
  // (N,) 1 = a body moving this step whatever its twists say (a static body that moves, an
  // awake dynamic one back from held, a body restarted fresh: a sleeper so flagged wakes its
  // island). dt > 0 (s). Returns the bodies woken.
  int wake(const SleepStates& previous, const SleepStates& current,
           const std::uint8_t* active, const std::uint8_t* kinematic, double dt);

  // After the solve: islands of the `movable` bodies (awake, active, dynamic) joined by the
  // M contacts (a, b) (any normal impulse), timers from the answers' twists, islands all
  // still for time_to_sleep and none of whose bodies is accelerating fall asleep (their
  // answer's twist is zeroed: the held state).
  // A contact with impulse between a movable body and a sleeper wakes the sleeper's island
  // from the next step, its bodies' still time restarting as every woken body's does (Box2D
  // v3): it is solved from then on and may move (a lower body sinks under the new load), so
  // it sleeps again only after time_to_sleep awake, with the island that leaned on it, and
  // a body answered asleep in two consecutive steps has not moved between them (while
  // time_to_sleep >= dt). Returns the bodies that fell asleep.
  int update(double* out_linear, double* out_angular,
             const std::uint8_t* movable, const std::int64_t* a, const std::int64_t* b,
             const double* normal_impulse, std::int64_t m, double dt);

  int sleeping_bodies() const;
  int sleeping_islands() const;
  int awake_islands() const { return awake_islands_; }  // of the last update

 private:
  int find(int i);
  double speed(int i, const double* v, const double* w) const;
  // Whether body i's input (v1, w1, x1) is its held state (v0, w0, x0) integrated k = 2 ..
  // late_steps times by its kept change (within the threshold; see the file comment).
  bool late(int i, const double* v0, const double* w0, const double* v1, const double* w1,
            const double* x0, const double* x1, double dt) const;

  std::vector<double> radius_;
  std::vector<std::uint8_t> dynamic_;
  SleepSettings settings_;
  std::vector<std::uint8_t> asleep_;
  std::vector<std::int64_t> island_;  // sleeping island id (-1: awake)
  std::vector<double> timer_;         // s still
  std::vector<double> speed_;         // m/s, farthest point's speed in the last answer
  std::vector<double> rising_;        // s the speed has risen in every step
  std::vector<double> accel_;         // (N, 6) last external acceleration, m/s^2, rad/s^2
  std::vector<double> change_;        // (N, 6) last velocity change per input, m/s, rad/s
  std::vector<int> parent_;           // union-find of the last update
  std::vector<int> root_still_;       // per root: 1 while every member is ready
  std::int64_t next_id_ = 0;
  int awake_islands_ = 0;
};

}  // namespace collres
