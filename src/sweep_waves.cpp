#include "sweep_waves.h"

#include <algorithm>

namespace collres {

void wave_manifolds(const std::vector<Manifold>& manifolds, const std::vector<int32_t>& chosen,
                    const std::vector<ContactRow>& rows, const double* inv_mass,
                    int64_t body_count, SweepPlan& plan, std::vector<Manifold>& out,
                    std::vector<int32_t>& wave, std::vector<size_t>& bucket,
                    std::vector<size_t>& start, std::vector<int32_t>& order) {
  const size_t count = chosen.size();
  // stable counting sort by (wave, row count, speculative): bucket wave * 10 + 2 (count -
  // 1) + speculative (counts 1 to 4; the last two buckets of a wave for longer manifolds).
  // A speculative manifold (every row with a gap to close: allowance > 0) is the kind that
  // carries no impulse (at 30 Hz about 60 % of a settled pile's rows): after the others
  // of its row count, so that most wide groups are all of one kind and a group whose four
  // lanes all stay idle costs only its approach test (solve_velocities)
  constexpr int kKinds = 5, kBuckets = 2 * kKinds;
  auto speculative = [&](const Manifold& m) {
    for (int32_t i = m.first; i < m.first + m.count; ++i)
      if (!(rows[i].allowance > 0.0)) return false;
    return true;
  };
  // each manifold's bucket (bucket[index]), from its wave; wave[body]: the last wave that
  // moved it
  wave.assign(static_cast<size_t>(body_count), -1);
  bucket.resize(count);
  int32_t waves = 0;
  for (size_t index = 0; index < count; ++index) {
    const Manifold& m = manifolds[static_cast<size_t>(chosen[index])];
    const bool move_a = inv_mass[m.a] > 0.0, move_b = inv_mass[m.b] > 0.0;
    const int32_t own = std::max(move_a ? wave[m.a] : -1, move_b ? wave[m.b] : -1) + 1;
    if (move_a) wave[m.a] = own;
    if (move_b) wave[m.b] = own;
    waves = std::max(waves, own + 1);
    bucket[index] = static_cast<size_t>(own) * kBuckets +
                    2 * static_cast<size_t>(std::min(m.count, kKinds) - 1) +
                    (speculative(m) ? 1 : 0);
  }
  start.assign(static_cast<size_t>(waves) * kBuckets + 1, 0);
  for (size_t index = 0; index < count; ++index) ++start[bucket[index] + 1];
  for (size_t i = 0; i + 1 < start.size(); ++i) start[i + 1] += start[i];
  order.resize(count);
  for (size_t index = 0; index < count; ++index)
    order[start[bucket[index]]++] = chosen[index];   // (start: ends now)
  // per wave: the wide groups of each row count 1..4 (kLanes manifolds each), then counts
  // 1..4's remainders of two or three (padded groups), then the remainders of one and the
  // longer manifolds (one by one: a group of one lane costs more than its one manifold);
  // each copied in once (not over a new entry's zeros)
  out.clear();
  out.reserve(count);
  auto place = [&](size_t from, size_t end) {
    for (size_t k = from; k < end; ++k) out.push_back(manifolds[static_cast<size_t>(order[k])]);
  };
  plan.waves.clear();
  plan.packed = false;
  size_t from = 0;
  for (int32_t l = 0; l < waves; ++l) {
    size_t first[kKinds + 1];   // row count k + 1's manifolds: [first[k], first[k + 1])
    first[0] = from;
    for (int k = 0; k < kKinds; ++k)
      first[k + 1] = start[static_cast<size_t>(l) * kBuckets + 2 * static_cast<size_t>(k) + 1];
    from = first[kKinds];
    SweepWave part;
    part.first = out.size();
    for (int k = 0; k < 4; ++k) {
      const size_t n = first[k + 1] - first[k];
      place(first[k], first[k] + (n - n % kLanes));
    }
    part.wide_end = out.size();
    for (int k = 0; k < 4; ++k) {
      const size_t n = first[k + 1] - first[k];
      if (n % kLanes >= 2) place(first[k] + (n - n % kLanes), first[k + 1]);
    }
    part.lone = out.size();
    for (int k = 0; k < 4; ++k) {
      const size_t n = first[k + 1] - first[k];
      if (n % kLanes == 1) place(first[k + 1] - 1, first[k + 1]);
    }
    place(first[4], first[5]);
    part.end = out.size();
    plan.waves.push_back(part);
  }
}

}  // namespace collres
