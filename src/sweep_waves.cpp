#include "sweep_waves.h"

#include <algorithm>
#include <cstring>

namespace collres {
namespace {

// A manifold's kind (WaveScratch::kind): its row count 1 to 4 (solved in wide groups), or
// this (one by one: more rows, or rows of more than one frame)
constexpr int kKinds = 5;

// The movable bodies' ranks (s.rank), breadth first through the manifolds that join two
// of them, each group of bodies so joined from a body its search from its first body
// reached last; a movable body in no manifold then ranks after all of them (s.ranked), an
// immovable one -1.
void rank_bodies(const std::vector<Manifold>& manifolds, const double* inv_mass,
                 int64_t body_count, WaveScratch& s) {
  const size_t n = static_cast<size_t>(body_count);
  auto movable = [&](int32_t body) { return inv_mass[body] > 0.0; };
  s.begin.assign(n + 1, 0);
  for (const Manifold& k : manifolds) {
    if (movable(k.a) && movable(k.b)) {
      ++s.begin[static_cast<size_t>(k.a) + 1];
      ++s.begin[static_cast<size_t>(k.b) + 1];
    }
  }
  for (size_t i = 0; i < n; ++i) s.begin[i + 1] += s.begin[i];
  s.adjacent.resize(static_cast<size_t>(s.begin[n]));
  s.last.assign(s.begin.begin(), s.begin.end() - 1);   // (each body's next neighbour slot)
  for (const Manifold& k : manifolds) {
    if (movable(k.a) && movable(k.b)) {
      s.adjacent[static_cast<size_t>(s.last[k.a]++)] = k.b;
      s.adjacent[static_cast<size_t>(s.last[k.b]++)] = k.a;
    }
  }
  s.rank.assign(n, -1);
  s.queue.resize(n);
  int32_t ranked = 0;
  // breadth first from `from` through the unranked bodies: with `keep`, ranking them;
  // else only to find the last one reached (their ranks are left -1); returns it
  auto search = [&](int32_t from, bool keep) {
    size_t head = 0, tail = 0;
    s.queue[tail++] = from;
    s.rank[from] = keep ? ranked++ : -2;
    while (head < tail) {
      const int32_t body = s.queue[head++];
      for (int32_t e = s.begin[body]; e < s.begin[body + 1]; ++e) {
        const int32_t next = s.adjacent[static_cast<size_t>(e)];
        if (s.rank[next] != -1) continue;
        s.rank[next] = keep ? ranked++ : -2;
        s.queue[tail++] = next;
      }
    }
    if (!keep)
      for (size_t i = 0; i < tail; ++i) s.rank[s.queue[i]] = -1;
    return s.queue[tail - 1];
  };
  for (const Manifold& k : manifolds)
    for (const int32_t body : {k.a, k.b})
      if (movable(body) && s.rank[body] < 0) search(search(body, false), true);
  s.ranked = ranked;
  for (size_t body = 0; body < n; ++body)
    if (!movable(static_cast<int32_t>(body)))
      s.rank[body] = -1;
    else if (s.rank[body] < 0)
      s.rank[body] = ranked;
}

// Each chosen manifold's class into s.side: 0 where every movable body of it is ranked
// before the cut, 1 where every one is ranked at or after it, 2 (the seam) where it has
// one on each side; the cut the rank that leaves the most rows in the smaller of classes
// 0 and 1 (a sweep's two halves run side by side, the seam after both: what it costs is
// the rows left out of the smaller half). A movable body not ranked counts as ranked
// after all of them.
void sides(const std::vector<Manifold>& manifolds, const std::vector<int32_t>& chosen,
           WaveScratch& s) {
  const int32_t ranked = s.ranked;
  auto rank = [&](int32_t body) { return s.rank[body]; };   // (-1: immovable)
  // rows per rank: of the manifolds whose highest-ranked movable body has it (before), and
  // of those whose lowest-ranked one has it (from)
  const size_t keys = static_cast<size_t>(ranked) + 1;
  s.before.assign(keys, 0);
  s.from.assign(keys + 1, 0);
  for (const int32_t index : chosen) {
    const Manifold& k = manifolds[static_cast<size_t>(index)];
    const int32_t a = rank(k.a), b = rank(k.b);
    const int32_t high = std::max(a, b), low = a < 0 ? b : (b < 0 ? a : std::min(a, b));
    s.before[static_cast<size_t>(std::max(high, 0))] += k.count;
    s.from[static_cast<size_t>(std::max(low, 0))] += k.count;
  }
  // rows of class 0 and 1 for cut c: the sum of before[0, c), that of from[c, keys)
  for (size_t c = keys; c-- > 0;) s.from[c] += s.from[c + 1];
  int32_t cut = 0;
  int64_t best = -1, below = 0;
  for (size_t c = 0; c <= keys; ++c) {
    const int64_t smaller = std::min(below, s.from[c]);
    if (smaller > best) {
      best = smaller;
      cut = static_cast<int32_t>(c);
    }
    if (c < keys) below += s.before[c];
  }
  s.side.resize(chosen.size());
  for (size_t index = 0; index < chosen.size(); ++index) {
    const Manifold& k = manifolds[static_cast<size_t>(chosen[index])];
    const int32_t a = rank(k.a), b = rank(k.b);
    const bool low = (a >= 0 && a < cut) || (b >= 0 && b < cut);
    const bool high = a >= cut || b >= cut;
    s.side[index] = low && high ? 2 : (high ? 1 : 0);
  }
}

// Moves manifolds to later waves where that fills lanes (s.bucket[index]: each chosen
// manifold's wave, as found, then as moved), keeping the sweep's bits: a manifold may sit
// in any wave after those of the manifolds before it and before those of the manifolds
// after it that share a movable body with it (s.next: the next one on each of its movable
// bodies), so the order in which each body's manifolds are solved is kept. Wave by wave,
// for each side and row count 1..4 (s.side; the longer manifolds are solved one by one),
// the r manifolds left over by its wide groups of kLanes (r = n mod kLanes, a padded group
// or one solved one by one) are moved to the next wave when r of them may be (their next
// manifolds two waves on or later; s.speculative ones first): there they join its
// manifolds of the same side and row count, so no wave is left with more part-filled
// groups or lone manifolds than before (the remainders of two waves become at most one).
// `waves`: the number of waves (none is added).
void fill_lanes(const std::vector<Manifold>& manifolds, const std::vector<int32_t>& chosen,
                const double* inv_mass, int32_t waves, int32_t fence, WaveScratch& s) {
  const size_t count = chosen.size();
  // each manifold's side and kind (key: 4 side + kind - 1; -1 for kind 5, one by one),
  // and its next one on its bodies A and B (-1: none, or the body immovable)
  s.key.resize(count);
  s.next.resize(2 * count);
  std::fill(s.last.begin(), s.last.end(), -1);
  for (size_t index = count; index-- > 0;) {
    const Manifold& m = manifolds[static_cast<size_t>(chosen[index])];
    s.key[index] = static_cast<int8_t>(s.kind[index] <= 4 ? 4 * s.side[index] + s.kind[index] - 1
                                                          : -1);
    const int32_t bodies[2] = {m.a, m.b};
    for (int j = 0; j < 2; ++j) {
      const bool movable = inv_mass[bodies[j]] > 0.0;
      s.next[2 * index + static_cast<size_t>(j)] = movable ? s.last[bodies[j]] : -1;
      if (movable) s.last[bodies[j]] = static_cast<int32_t>(index);
    }
  }
  // the manifolds of each wave as found, in order: wave w's members[start[w - 1], start[w])
  // once the counts are placed (start[-1]: 0)
  s.start.assign(static_cast<size_t>(waves) + 1, 0);
  for (size_t index = 0; index < count; ++index) ++s.start[s.bucket[index] + 1];
  for (size_t w = 0; w < static_cast<size_t>(waves); ++w) s.start[w + 1] += s.start[w];
  s.members.resize(count);
  for (size_t index = 0; index < count; ++index)
    s.members[s.start[s.bucket[index]]++] = static_cast<int32_t>(index);   // (start: ends)
  s.carry.clear();   // the manifolds moved into the wave at hand, and into the next
  s.moved.clear();
  for (size_t w = 0; w + 1 < static_cast<size_t>(waves); ++w) {
    auto movable = [&](int32_t index) {   // to wave w + 1
      if (w + 1 == static_cast<size_t>(fence)) return false;
      for (int j = 0; j < 2; ++j) {
        const int32_t next = s.next[2 * static_cast<size_t>(index) + static_cast<size_t>(j)];
        if (next >= 0 && s.bucket[static_cast<size_t>(next)] < w + 2) return false;
      }
      return true;
    };
    // the wave's manifolds: those found in it, then those moved into it
    const int32_t* found = s.members.data() + (w == 0 ? 0 : s.start[w - 1]);
    const size_t found_count = s.start[w] - (w == 0 ? 0 : s.start[w - 1]);
    const size_t total = found_count + s.carry.size();
    auto at = [&](size_t i) { return i < found_count ? found[i] : s.carry[i - found_count]; };
    int32_t left[8] = {}, may[8] = {};   // per key: the manifolds, those that may move
    for (size_t i = 0; i < total; ++i) {
      const int32_t index = at(i), k = s.key[static_cast<size_t>(index)];
      if (k < 0) continue;
      ++left[k];
      if (movable(index)) ++may[k];
    }
    int32_t need = 0;   // manifolds to move
    for (int k = 0; k < 8; ++k) {
      left[k] %= kLanes;   // (now: how many to move)
      if (may[k] < left[k]) left[k] = 0;
      need += left[k];
    }
    for (int pass = 0; pass < 2 && need > 0; ++pass)   // the speculative ones first
      for (size_t i = total; i-- > 0 && need > 0;) {
        const int32_t index = at(i), k = s.key[static_cast<size_t>(index)];
        if (k < 0 || left[k] == 0 ||
            (s.speculative[static_cast<size_t>(index)] != 0) != (pass == 0) || !movable(index))
          continue;
        --left[k];
        --need;
        s.bucket[static_cast<size_t>(index)] = w + 1;
        s.moved.push_back(index);
      }
    s.carry.swap(s.moved);
    s.moved.clear();
  }
}

}  // namespace

void wave_manifolds(const std::vector<Manifold>& manifolds, const std::vector<int32_t>& chosen,
                    const std::vector<ContactRow>& rows, const double* inv_mass,
                    int64_t body_count, SweepPlan& plan, std::vector<Manifold>& out,
                    WaveScratch& s) {
  const size_t count = chosen.size();
  plan.waves.clear();
  plan.sequence.clear();
  plan.packed = false;
  if (count == 0) {
    out.clear();
    return;
  }
  // each manifold of `order` its wave (bucket[index], for now), from wave `least` on;
  // last[body]: the last wave that moved it; returns one past the last wave
  auto wave = [&](const std::vector<int32_t>& order, size_t from, size_t to, int32_t least) {
    int32_t waves = least;
    for (size_t index = from; index < to; ++index) {
      const Manifold& m = manifolds[static_cast<size_t>(order[index])];
      const bool move_a = inv_mass[m.a] > 0.0, move_b = inv_mass[m.b] > 0.0;
      const int32_t own = std::max({move_a ? s.last[m.a] : -1, move_b ? s.last[m.b] : -1,
                                    least - 1}) + 1;
      if (move_a) s.last[m.a] = own;
      if (move_b) s.last[m.b] = own;
      waves = std::max(waves, own + 1);
      s.bucket[index] = static_cast<size_t>(own);
    }
    return waves;
  };
  s.last.assign(static_cast<size_t>(body_count), -1);
  s.bucket.resize(count);
  int32_t waves = wave(chosen, 0, count, 0);
  // two sides where the waves of the solve's order average at least twice plan.parallel
  // manifolds (else side 0 only: a smaller part costs more to hand over than it holds;
  // plan.parallel 0: one side), whatever the threads (the order is the sides')
  const bool split = plan.parallel > 0 && count >= 2 * plan.parallel * static_cast<size_t>(waves);
  // with a worker whose cost model pairs the later sweeps (kind 0, solve_velocities) each
  // side its own parts (its thread's) and waits; else, and on one thread, a wave's two
  // sides are one part (they share no movable body: the same bits) and nothing waits, so
  // that the sides leave no more part-filled groups than one side does (cut for two, a
  // settled mixed pile of 1000 at 120 Hz has 56 against 30: a sweep of it run alone took
  // 0.156-0.162 ms, cut for one thread 0.145-0.151)
  const bool sided = split && plan.worker != nullptr && plan.worker->pairs(0);
  const std::vector<int32_t>* order = &chosen;
  int32_t fence = waves;   // the seam's first wave
  if (split) {
    if (s.epoch != plan.rows_epoch || s.rank.size() != static_cast<size_t>(body_count)) {
      rank_bodies(manifolds, inv_mass, body_count, s);
      s.epoch = plan.rows_epoch;
    }
    sides(manifolds, chosen, s);
    // the sweep's order: class 0's manifolds, class 1's, then the seam's, each in the
    // solve's order; the seam in waves of its own after the others' (its manifolds are
    // the last on their bodies: any later wave keeps the bits of the order), on side 1
    s.sorted.clear();
    size_t starts[4] = {0, 0, 0, 0};   // class c: s.sorted[starts[c], starts[c + 1])
    for (int32_t part = 0; part < 3; ++part) {
      for (size_t index = 0; index < count; ++index)
        if (s.side[index] == part) s.sorted.push_back(chosen[index]);
      starts[part + 1] = s.sorted.size();
    }
    const size_t first = starts[2];   // the seam's first
    for (size_t index = 0; index < count; ++index)
      s.side[index] = sided && index >= starts[1] ? 1 : 0;
    order = &s.sorted;
    s.last.assign(static_cast<size_t>(body_count), -1);
    fence = wave(*order, 0, first, 0);
    waves = wave(*order, first, count, fence);
  } else {
    s.side.assign(count, 0);
  }
  s.speculative.resize(count);
  s.kind.resize(count);
  // a manifold's kind, found once for the rows prepared (a frame that changes without
  // them is a one-row manifold's: kind 1 whatever it is)
  if (s.framed != plan.rows_epoch || s.framing.size() != manifolds.size()) {
    s.framing.assign(manifolds.size(), 0);
    s.framed = plan.rows_epoch;
  }
  auto same = [](const Vec3& a, const Vec3& b) {
    return std::memcmp(a.data(), b.data(), 3 * sizeof(double)) == 0;
  };
  plan.spin_rows = false;
  for (size_t index = 0; index < count; ++index) {
    const auto at = static_cast<size_t>((*order)[index]);
    const Manifold& m = manifolds[at];
    plan.spin_rows = plan.spin_rows || m.spin >= 0;
    bool all = true;
    for (int32_t i = m.first; i < m.first + m.count && all; ++i) all = rows[i].allowance > 0.0;
    s.speculative[index] = all ? 1 : 0;
    if (s.framing[at] == 0) {
      bool framed = m.count <= 4;
      const ContactRow& r = rows[static_cast<size_t>(m.first)];
      for (int32_t i = m.first + 1; i < m.first + m.count && framed; ++i)
        framed = same(rows[i].n, r.n) && same(rows[i].t1, r.t1) && same(rows[i].t2, r.t2);
      s.framing[at] = static_cast<int8_t>(framed ? m.count : kKinds);
    }
    s.kind[index] = s.framing[at];
  }
  fill_lanes(manifolds, *order, inv_mass, waves, fence, s);
  // stable counting sort by (wave, side, kind, speculative): bucket (2 wave + side) *
  // 10 + 2 (kind - 1) + speculative (row counts 1 to 4; the last two buckets of a part for
  // the manifolds solved one by one). A speculative manifold (every row with a gap to
  // close: allowance > 0) is the sort that carries no impulse (at 30 Hz about 60 % of a
  // settled pile's rows): after the others of its row count, so that most wide groups
  // are all of one sort and a group whose four lanes all stay idle costs only its
  // approach test (solve_velocities)
  constexpr int kBuckets = 2 * kKinds;
  // each manifold's bucket
  for (size_t index = 0; index < count; ++index) {
    const int32_t part = 2 * static_cast<int32_t>(s.bucket[index]) + s.side[index];
    s.bucket[index] = static_cast<size_t>(part) * kBuckets +
                      2 * static_cast<size_t>(s.kind[index] - 1) + s.speculative[index];
  }
  const size_t parts = 2 * static_cast<size_t>(waves);
  s.start.assign(parts * kBuckets + 1, 0);
  for (size_t index = 0; index < count; ++index) ++s.start[s.bucket[index] + 1];
  for (size_t i = 0; i + 1 < s.start.size(); ++i) s.start[i + 1] += s.start[i];
  s.order.resize(count);
  for (size_t index = 0; index < count; ++index)
    s.order[s.start[s.bucket[index]]++] = (*order)[index];   // (start: ends now)
  // per part: the wide groups of each row count 1..4 (kLanes manifolds each), then counts
  // 1..4's remainders of two or three (padded groups), then the remainders of one and the
  // longer manifolds (one by one: a group of one lane costs more than its one manifold);
  // each copied in once, constructed in its place (each step's first plan follows
  // prepare's empty one: resized, every entry was zeroed first, then copied over)
  out.clear();
  out.reserve(count);
  size_t placed = 0;
  auto place = [&](size_t from, size_t end) {
    for (size_t k = from; k < end; ++k, ++placed)
      out.push_back(manifolds[static_cast<size_t>(s.order[k])]);
  };
  size_t from = 0;
  for (size_t p = 0; p < parts; ++p) {
    size_t first[kKinds + 1];   // row count k + 1's manifolds: [first[k], first[k + 1])
    first[0] = from;
    for (int k = 0; k < kKinds; ++k)
      first[k + 1] = s.start[p * kBuckets + 2 * static_cast<size_t>(k) + 1];
    from = first[kKinds];
    if (first[0] == first[kKinds]) continue;
    SweepWave part;
    part.side = static_cast<int32_t>(p % 2);
    part.seam = p / 2 >= static_cast<size_t>(fence);
    part.first = placed;
    for (int k = 0; k < 4; ++k) {
      const size_t n = first[k + 1] - first[k];
      place(first[k], first[k] + (n - n % kLanes));
    }
    part.wide_end = placed;
    for (int k = 0; k < 4; ++k) {
      const size_t n = first[k + 1] - first[k];
      if (n % kLanes >= 2) place(first[k] + (n - n % kLanes), first[k + 1]);
    }
    part.lone = placed;
    for (int k = 0; k < 4; ++k) {
      const size_t n = first[k + 1] - first[k];
      if (n % kLanes == 1) place(first[k + 1] - 1, first[k + 1]);
    }
    place(first[4], first[5]);
    part.end = placed;
    plan.waves.push_back(part);
  }
  // the sweep's parts in order (SweepPlan::sequence): the rows of the parts before the
  // seam's, their spin rows, the seam's rows, their spin rows (spin parts only where a
  // manifold has a spin row); with two sides, each part's wait: the other side's part
  // last in that order to move one of its bodies (s.last[body]: the last part that moved
  // it, s.index[part]: its place in the order)
  const auto size = static_cast<int32_t>(plan.waves.size());
  int32_t seam = size;   // the seam's first part
  while (seam > 0 && plan.waves[static_cast<size_t>(seam) - 1].seam) --seam;
  for (const auto [from, to] : {std::pair<int32_t, int32_t>{0, seam}, {seam, size}}) {
    for (int32_t i = from; i < to; ++i) plan.sequence.push_back(i);
    if (plan.spin_rows)
      for (int32_t i = from; i < to; ++i) plan.sequence.push_back(size + i);
  }
  if (!sided) return;
  s.last.assign(static_cast<size_t>(body_count), -1);
  s.index.assign(plan.sequence.size(), -1);
  for (size_t at = 0; at < plan.sequence.size(); ++at) {
    const int32_t id = plan.sequence[at];
    SweepWave& part = plan.waves[static_cast<size_t>(id % size)];
    int32_t after = -1;
    for (size_t k = part.first; k < part.end; ++k) {
      for (const int32_t body : {out[k].a, out[k].b}) {
        if (!(inv_mass[body] > 0.0)) continue;
        const int32_t last = s.last[body];
        if (last >= 0 && plan.waves[static_cast<size_t>(last % size)].side != part.side &&
            (after < 0 || s.index[static_cast<size_t>(last)] > s.index[static_cast<size_t>(after)]))
          after = last;
        s.last[body] = id;
      }
    }
    s.index[static_cast<size_t>(id)] = static_cast<int32_t>(at);
    (id < size ? part.after : part.spin_after) = after;
  }
}

}  // namespace collres
