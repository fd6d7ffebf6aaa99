#include "island_solve.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

namespace collres {
namespace {

// rows whose breach is at least this fraction of the round's worst change with it (a
// mirror image's rows break theirs equally, up to rounding)
constexpr double kTie = 0.999;

Vec3 direction(const ContactRow& r, int k) { return k == 0 ? r.n : k == 1 ? r.t1 : r.t2; }

double kinetic(const double* v, double inv_mass, const Mat3& inertia) {
  const Vec3 l = load3(v), w = load3(v + 3);
  return 0.5 * (dot(l, l) / inv_mass + dot(w, mul(inertia, w)));
}

}  // namespace

IslandSolve::Outcome IslandSolve::solve(std::vector<ContactRow>& rows,
                                        const std::vector<int32_t>& members,
                                        const std::vector<int32_t>& bodies,
                                        const SolverBodies& solver, const Mat3* inertia,
                                        const double* base, double* velocity,
                                        const IslandSettings& settings, uint8_t* set,
                                        double* along) {
  const int64_t count = static_cast<int64_t>(members.size());
  const int64_t size = 3 * count;
  if (local_.size() < static_cast<size_t>(solver.count)) local_.assign(solver.count, -1);
  for (size_t j = 0; j < bodies.size(); ++j) local_[bodies[j]] = static_cast<int32_t>(j);
  // the rows' speeds at the base velocities and their responses to each other's unit
  // impulses: a unit impulse of row j along its direction l changes a movable body X by
  // +-(m_X d_l, I_X^-1 (r_X x d_l)), which row i reads along d_k through +-(d_k, r_X x d_k)
  b_.assign(size, 0.0);
  a_.assign(size * size, 0.0);
  for (int64_t i = 0; i < count; ++i) {
    const ContactRow& r = rows[members[i]];
    for (int k = 0; k < 3; ++k) b_[3 * i + k] = point_velocity(r, base, k, direction(r, k));
  }
  for (int64_t j = 0; j < count; ++j) {
    const ContactRow& q = rows[members[j]];
    for (int l = 0; l < 3; ++l) {
      const Vec3 d = direction(q, l);
      for (int64_t i = 0; i < count; ++i) {
        const ContactRow& r = rows[members[i]];
        // body X of row j (sign sj: B +1, A -1) as read by row i (sign si)
        for (int x = 0; x < 2; ++x) {
          const int32_t body = x == 0 ? q.a : q.b;
          const double mass = x == 0 ? q.ma : q.mb;
          if (mass == 0.0) continue;
          const double sj = x == 0 ? -1.0 : 1.0;
          const Vec3 dv = mass * d, dw = x == 0 ? q.dw_a[l] : q.dw_b[l];
          for (int y = 0; y < 2; ++y) {
            if ((y == 0 ? r.a : r.b) != body) continue;
            const double si = y == 0 ? -1.0 : 1.0;
            for (int k = 0; k < 3; ++k) {
              const Vec3& lever = y == 0 ? r.ang_a[k] : r.ang_b[k];
              a_[(3 * i + k) * size + 3 * j + l] +=
                  si * sj * (dot(dv, direction(r, k)) + dot(dw, lever));
            }
          }
        }
      }
    }
  }
  // the given set (a set that does not hang on the sweeps' answer, whose order a mirror
  // image changes), each row's state as its friction allows
  state_.assign(set, set + count);
  along_.assign(along, along + 2 * count);
  for (int64_t i = 0; i < count; ++i) {
    if (state_[i] == kApart) continue;
    if (rows[members[i]].mu == 0.0) {
      state_[i] = kSlide;
      along_[2 * i] = along_[2 * i + 1] = 0.0;
    } else if (state_[i] == kSlide && along_[2 * i] == 0.0 && along_[2 * i + 1] == 0.0) {
      state_[i] = kStick;
    }
  }
  lambda_.assign(size, 0.0);
  u_.assign(size, 0.0);
  breach_.assign(count, 0.0);
  bool solved = false;
  for (int round = 0; round <= settings.max_rounds; ++round) {
    // the active rows' equalities, each unknown's own equation weighed `regularise` more
    unknown_.clear();
    for (int64_t i = 0; i < count; ++i) {
      if (state_[i] == kApart) continue;
      unknown_.push_back(static_cast<int32_t>(3 * i));
      if (state_[i] == kStick) {
        unknown_.push_back(static_cast<int32_t>(3 * i + 1));
        unknown_.push_back(static_cast<int32_t>(3 * i + 2));
      }
    }
    const int64_t m = static_cast<int64_t>(unknown_.size());
    std::fill(lambda_.begin(), lambda_.end(), 0.0);
    if (m > 0) {
      Eigen::MatrixXd system(m, m);
      Eigen::VectorXd rhs(m);
      for (int64_t e = 0; e < m; ++e) {
        const int32_t row = unknown_[e];
        const int64_t i = row / 3;
        rhs(e) = (row % 3 == 0 ? -rows[members[i]].allowance : 0.0) - b_[row];
        const double* line = a_.data() + row * size;
        for (int64_t c = 0; c < m; ++c) {
          const int32_t col = unknown_[c];
          const int64_t j = col / 3;
          double value = line[col];
          if (state_[j] == kSlide) {   // its friction: mu N along its direction
            const double mu = rows[members[j]].mu;
            value += mu * (along_[2 * j] * line[col + 1] + along_[2 * j + 1] * line[col + 2]);
          }
          system(e, c) = value;
        }
        system(e, e) += settings.regularise * line[row];
      }
      const Eigen::VectorXd x = system.partialPivLu().solve(rhs);
      for (int64_t c = 0; c < m; ++c) {
        const int32_t col = unknown_[c];
        const int64_t j = col / 3;
        lambda_[col] = x(c);
        if (state_[j] == kSlide) {
          const double mu = rows[members[j]].mu;
          lambda_[col + 1] = mu * along_[2 * j] * x(c);
          lambda_[col + 2] = mu * along_[2 * j + 1] * x(c);
        }
      }
    }
    for (int64_t i = 0; i < size; ++i) {
      double sum = b_[i];
      const double* line = a_.data() + i * size;
      for (int64_t j = 0; j < size; ++j) sum += line[j] * lambda_[j];
      u_[i] = sum;
    }
    // each row's breach of its rule (m/s: an impulse through its own diagonal)
    double worst = 0.0;
    bool finite = true;
    for (int64_t i = 0; i < count; ++i) {
      const ContactRow& r = rows[members[i]];
      const double* l = lambda_.data() + 3 * i;
      const double* u = u_.data() + 3 * i;
      const double* diagonal = a_.data() + 3 * i * size + 3 * i;
      finite = finite && std::isfinite(l[0]) && std::isfinite(l[1]) && std::isfinite(l[2]);
      double breach = 0.0;
      if (state_[i] == kApart) {
        breach = -(u[0] + r.allowance);
      } else {
        breach = -l[0] * diagonal[0];
        if (state_[i] == kStick) {
          const double tangential = 0.5 * (diagonal[size + 1] + diagonal[2 * size + 2]);
          breach = std::max(breach, (norm2(l[1], l[2]) - r.mu * l[0]) * tangential);
        } else {
          breach = std::max(breach, u[1] * along_[2 * i] + u[2] * along_[2 * i + 1]);
        }
      }
      breach_[i] = breach;
      worst = std::max(worst, breach);
    }
    if (!finite) break;
    if (worst <= settings.tolerance) {
      solved = true;
      break;
    }
    for (int64_t i = 0; i < count; ++i) {
      if (breach_[i] < kTie * worst) continue;
      const ContactRow& r = rows[members[i]];
      const double* l = lambda_.data() + 3 * i;
      if (state_[i] == kApart) {
        state_[i] = r.mu == 0.0 ? kSlide : kStick;
        along_[2 * i] = along_[2 * i + 1] = 0.0;
      } else if (-l[0] * a_[3 * i * size + 3 * i] >= breach_[i] * kTie) {
        state_[i] = kApart;   // pulls: let go
      } else if (state_[i] == kStick) {   // beyond the cone: slides along its friction
        const double friction = norm2(l[1], l[2]);
        state_[i] = kSlide;
        along_[2 * i] = l[1] / friction;
        along_[2 * i + 1] = l[2] / friction;
      } else {
        state_[i] = kStick;   // slips along its friction: held
      }
    }
  }
  std::copy(state_.begin(), state_.end(), set);
  std::copy(along_.begin(), along_.end(), along);
  if (!solved) {
    for (const int32_t body : bodies) local_[body] = -1;
    return kUnsolved;
  }
  // the exact answer's velocities; taken where they leave the island no more kinetic energy
  answer_.resize(6 * bodies.size());
  for (size_t k = 0; k < bodies.size(); ++k)
    std::copy(base + 6 * bodies[k], base + 6 * bodies[k] + 6, answer_.begin() + 6 * k);
  for (int64_t j = 0; j < count; ++j) {
    const ContactRow& q = rows[members[j]];
    for (int l = 0; l < 3; ++l) {
      const double impulse = lambda_[3 * j + l];
      if (impulse == 0.0) continue;
      const Vec3 d = direction(q, l);
      if (q.ma != 0.0) {
        double* v = answer_.data() + 6 * local_[q.a];
        store3(v, load3(v) - impulse * q.ma * d);
        store3(v + 3, load3(v + 3) - impulse * q.dw_a[l]);
      }
      if (q.mb != 0.0) {
        double* v = answer_.data() + 6 * local_[q.b];
        store3(v, load3(v) + impulse * q.mb * d);
        store3(v + 3, load3(v + 3) + impulse * q.dw_b[l]);
      }
    }
  }
  double exact = 0.0, swept = 0.0;
  for (size_t k = 0; k < bodies.size(); ++k) {
    const int32_t body = bodies[k];
    exact += kinetic(answer_.data() + 6 * k, solver.inv_mass[body], inertia[body]);
    swept += kinetic(velocity + 6 * body, solver.inv_mass[body], inertia[body]);
  }
  const bool taken = exact <= swept;
  if (taken) {
    for (size_t k = 0; k < bodies.size(); ++k)
      std::copy(answer_.begin() + 6 * k, answer_.begin() + 6 * k + 6, velocity + 6 * bodies[k]);
    for (int64_t i = 0; i < count; ++i) {
      ContactRow& r = rows[members[i]];
      r.normal = lambda_[3 * i];
      r.tangent[0] = lambda_[3 * i + 1];
      r.tangent[1] = lambda_[3 * i + 2];
    }
  }
  for (const int32_t body : bodies) local_[body] = -1;
  return taken ? kTaken : kKept;
}

}  // namespace collres
