// Islands and sleep (see islands.h).
#include "islands.h"

#include <algorithm>
#include <cmath>

namespace collres {

namespace {

double norm3(const double* v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }

// rad, angle of the rotation between two unit quaternions (x, y, z, w)
double turn(const double* p, const double* q) {
  const double d = std::fabs(p[0] * q[0] + p[1] * q[1] + p[2] * q[2] + p[3] * q[3]);
  return 2.0 * std::atan2(std::sqrt(std::max(0.0, 1.0 - d * d)), std::min(d, 1.0));
}

struct Box {
  double lo[3], hi[3];
  int body;
};

bool overlap(const Box& a, const Box& b) {
  for (int k = 0; k < 3; ++k) {
    if (a.hi[k] < b.lo[k] || b.hi[k] < a.lo[k]) return false;
  }
  return true;
}

}  // namespace

Islands::Islands(std::vector<double> radius, std::vector<std::uint8_t> dynamic)
    : radius_(std::move(radius)), dynamic_(std::move(dynamic)) {
  const std::size_t n = radius_.size();
  dynamic_.resize(n, 0);
  asleep_.assign(n, 0);
  island_.assign(n, -1);
  timer_.assign(n, 0.0);
  speed_.assign(n, 0.0);
  rising_.assign(n, 0.0);
  accel_.assign(6 * n, 0.0);
  change_.assign(6 * n, 0.0);
  parent_.resize(n);
  root_still_.resize(n);
}

void Islands::wake_all() {
  std::fill(asleep_.begin(), asleep_.end(), 0);
  std::fill(island_.begin(), island_.end(), -1);
  std::fill(timer_.begin(), timer_.end(), 0.0);
  std::fill(speed_.begin(), speed_.end(), 0.0);
  std::fill(rising_.begin(), rising_.end(), 0.0);
}

double Islands::speed(int i, const double* v, const double* w) const {
  const double r = std::isfinite(radius_[i]) ? radius_[i] : 0.0;
  return norm3(v) + norm3(w) * r;
}

bool Islands::late(int i, const double* v0, const double* w0, const double* v1,
                   const double* w1, const double* x0, const double* x1, double dt) const {
  const double tau = settings_.threshold;
  for (int k = 2; k <= settings_.late_steps; ++k) {
    double dv[3], dw[3], dx[3];
    const double rise = 0.5 * k * (k + 1) * dt;
    for (int d = 0; d < 3; ++d) {
      dv[d] = v1[d] - v0[d] - k * change_[6 * i + d];
      dw[d] = w1[d] - w0[d] - k * change_[6 * i + 3 + d];
      dx[d] = x1[d] - x0[d] - rise * change_[6 * i + d];
    }
    if (speed(i, dv, dw) <= tau && norm3(dx) <= tau * dt) return true;
  }
  return false;
}

int Islands::wake(const SleepStates& previous, const SleepStates& current,
                  const std::uint8_t* active, const std::uint8_t* kinematic, double dt) {
  const int n = count();
  const double tau = settings_.threshold;
  const double pad = 0.5 * settings_.margin;
  std::vector<std::int64_t> wake_ids;   // sleeping islands to wake
  auto mark = [&](int i) { wake_ids.push_back(island_[i]); };
  std::vector<Box> movers, sleepers;
  bool sweeping_all = false;   // a moving half-space (infinite bounds) touches every sleeper
  for (int i = 0; i < n; ++i) {
    const double* v0 = previous.linear + 3 * i;
    const double* w0 = previous.angular + 3 * i;
    const double* v1 = current.linear + 3 * i;
    const double* w1 = current.angular + 3 * i;
    const double* x0 = previous.position + 3 * i;
    const double* x1 = current.position + 3 * i;
    const double r = radius_[i];
    bool moving = kinematic != nullptr && kinematic[i];
    if (dynamic_[i] && active[i]) {
      // the velocity change beyond the acceleration's over dt, or beyond last step's change
      // (an upstream that integrates its own period while the node's dt spans a lost input)
      double per_dt_v[3], per_dt_w[3], per_step_v[3], per_step_w[3];
      for (int k = 0; k < 3; ++k) {
        per_dt_v[k] = v1[k] - v0[k] - accel_[6 * i + k] * dt;
        per_dt_w[k] = w1[k] - w0[k] - accel_[6 * i + 3 + k] * dt;
        per_step_v[k] = v1[k] - v0[k] - change_[6 * i + k];
        per_step_w[k] = w1[k] - w0[k] - change_[6 * i + 3 + k];
      }
      const double jolt = std::min(speed(i, per_dt_v, per_dt_w),
                                   speed(i, per_step_v, per_step_w));
      if (asleep_[i]) {
        double dx[3] = {x1[0] - x0[0], x1[1] - x0[1], x1[2] - x0[2]};
        const double rr = std::isfinite(r) ? r : 0.0;
        bool departs =
            !(jolt <= tau) ||
            !(norm3(dx) <= (norm3(v1) + tau) * dt) ||
            !(turn(previous.orientation + 4 * i, current.orientation + 4 * i) * rr <=
              (norm3(w1) * rr + tau) * dt);
        if (departs && settings_.late_steps > 1 && late(i, v0, w0, v1, w1, x0, x1, dt) &&
            !(turn(previous.orientation + 4 * i, current.orientation + 4 * i) * rr >
              (norm3(w1) * rr + tau) * dt))
          departs = false;
        if (departs) mark(i);
      } else {
        moving = moving || !(speed(i, v0, w0) <= tau) || !(jolt <= tau);
      }
    }
    // a sleeper the caller moves (a fresh restart): its island wakes, and its swept
    // bounds wake the islands they touch
    if (asleep_[i] && moving) mark(i);
    if (asleep_[i] && !moving) {
      Box box;
      for (int k = 0; k < 3; ++k) {
        box.lo[k] = x0[k] - r - pad;
        box.hi[k] = x0[k] + r + pad;
      }
      box.body = i;
      sleepers.push_back(box);
    } else if (moving) {
      if (!std::isfinite(r)) {
        sweeping_all = true;
        continue;
      }
      Box box;
      for (int k = 0; k < 3; ++k) {
        box.lo[k] = std::min(x0[k], x1[k]) - r - pad;
        box.hi[k] = std::max(x0[k], x1[k]) + r + pad;
      }
      box.body = i;
      movers.push_back(box);
    }
  }
  if (!sleepers.empty() && (sweeping_all || !movers.empty())) {
    if (sweeping_all) {
      for (const Box& s : sleepers) mark(s.body);
    } else {
      std::sort(sleepers.begin(), sleepers.end(),
                [](const Box& a, const Box& b) { return a.lo[0] < b.lo[0]; });
      for (const Box& m : movers) {
        for (const Box& s : sleepers) {
          if (s.lo[0] > m.hi[0]) break;
          if (overlap(m, s)) mark(s.body);
        }
      }
    }
  }
  int woken = 0;
  if (!wake_ids.empty()) {
    std::sort(wake_ids.begin(), wake_ids.end());
    for (int i = 0; i < n; ++i) {
      if (asleep_[i] && std::binary_search(wake_ids.begin(), wake_ids.end(), island_[i])) {
        asleep_[i] = 0;
        island_[i] = -1;
        timer_[i] = 0.0;
        ++woken;
      }
    }
  }
  // each awake body's external acceleration, for the next step's jolt
  for (int i = 0; i < n; ++i) {
    if (asleep_[i] || !dynamic_[i] || !active[i]) continue;
    for (int k = 0; k < 3; ++k) {
      change_[6 * i + k] = current.linear[3 * i + k] - previous.linear[3 * i + k];
      change_[6 * i + 3 + k] = current.angular[3 * i + k] - previous.angular[3 * i + k];
      accel_[6 * i + k] = change_[6 * i + k] / dt;
      accel_[6 * i + 3 + k] = change_[6 * i + 3 + k] / dt;
    }
  }
  return woken;
}

int Islands::find(int i) {
  while (parent_[i] != i) {
    parent_[i] = parent_[parent_[i]];
    i = parent_[i];
  }
  return i;
}

int Islands::update(double* out_linear, double* out_angular,
                    const std::uint8_t* movable, const std::int64_t* a, const std::int64_t* b,
                    const double* normal_impulse, std::int64_t m, double dt) {
  const int n = count();
  for (int i = 0; i < n; ++i) parent_[i] = i;
  std::vector<std::int64_t> touched;   // sleeping islands a movable body leaned on
  for (std::int64_t k = 0; k < m; ++k) {
    const int i = static_cast<int>(a[k]), j = static_cast<int>(b[k]);
    if (i < 0 || j < 0 || i >= n || j >= n) continue;
    if (movable[i] && movable[j]) {
      const int ri = find(i), rj = find(j);
      if (ri != rj) parent_[std::max(ri, rj)] = std::min(ri, rj);
    } else if (!(normal_impulse[k] > 0.0)) {
      continue;
    } else if (movable[i] && asleep_[j]) {
      touched.push_back(island_[j]);
    } else if (movable[j] && asleep_[i]) {
      touched.push_back(island_[i]);
    }
  }
  // timers and rises, then per root: ready while every member is (still for
  // time_to_sleep, and not accelerating: its speed not risen in each step for rise_time)
  const double least_rise = settings_.rise_step * settings_.threshold;
  const double accelerating = settings_.rise_time * settings_.time_to_sleep;
  for (int i = 0; i < n; ++i) {
    if (!movable[i]) {
      if (!asleep_[i]) timer_[i] = 0.0;
      speed_[i] = rising_[i] = 0.0;   // held or asleep: answered at rest
      continue;
    }
    const double s = speed(i, out_linear + 3 * i, out_angular + 3 * i);
    timer_[i] = s < settings_.threshold ? timer_[i] + dt : 0.0;
    rising_[i] = s - speed_[i] > least_rise ? rising_[i] + dt : 0.0;
    speed_[i] = s;
  }
  std::fill(root_still_.begin(), root_still_.end(), 1);
  awake_islands_ = 0;
  for (int i = 0; i < n; ++i) {
    if (!movable[i]) continue;
    const int root = find(i);
    if (root == i) ++awake_islands_;
    if (!(timer_[i] >= settings_.time_to_sleep) || rising_[i] >= accelerating)
      root_still_[root] = 0;
  }
  int fell = 0;
  for (int i = 0; i < n; ++i) {
    if (!movable[i]) continue;
    const int root = find(i);
    if (!root_still_[root]) continue;
    if (root == i) --awake_islands_;
    asleep_[i] = 1;
    island_[i] = next_id_ + root;   // one id per root, unique across updates (below)
    for (int k = 0; k < 3; ++k) out_linear[3 * i + k] = out_angular[3 * i + k] = 0.0;
    speed_[i] = rising_[i] = 0.0;
    ++fell;
  }
  next_id_ += n;
  if (!touched.empty()) {
    std::sort(touched.begin(), touched.end());
    for (int i = 0; i < n; ++i) {
      if (asleep_[i] && std::binary_search(touched.begin(), touched.end(), island_[i])) {
        asleep_[i] = 0;   // awake from the next step, its still time restarts: the solve
        island_[i] = -1;  // may move it, so it sleeps again only after time_to_sleep awake
        timer_[i] = 0.0;
      }
    }
  }
  return fell;
}

int Islands::sleeping_bodies() const {
  return static_cast<int>(std::count(asleep_.begin(), asleep_.end(), 1));
}

int Islands::sleeping_islands() const {
  std::vector<std::int64_t> ids;
  for (std::size_t i = 0; i < asleep_.size(); ++i) {
    if (asleep_[i]) ids.push_back(island_[i]);
  }
  std::sort(ids.begin(), ids.end());
  return static_cast<int>(std::unique(ids.begin(), ids.end()) - ids.begin());
}

}  // namespace collres
