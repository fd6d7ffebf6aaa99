// Waves of a velocity sweep (wavefronts): the order in which the sweeps visit a solve's
// manifolds, for lanes and threads, without changing a bit of their answer.
//
// A sweep solves the manifolds one after the other in their order (Gauss-Seidel). Two
// manifolds that share no movable body (immovable ones, static or held, are only read)
// commute: solving them in either order gives the same bits. A manifold's wave is one
// more than the highest wave of the manifolds before it that share a movable body with
// it (0 without one). Visiting the waves in turn is then the same sweep as the order,
// bit for bit, and the manifolds of one wave share no movable body: they may be solved
// in any order, four at a time in lanes (wide groups) and on two threads. A manifold may
// as well sit in a later wave, before that of the next manifold on each of its movable
// bodies (the order in which each body's manifolds are solved is what the bits depend
// on): the manifolds a wave's wide groups leave over (fewer than four of a row count and
// side) move to the next wave where they all may, to fill its groups. (Box2D v3
// colours its constraint graph greedily instead; that reorders the sweep, and measured
// here it broke the pile and heap laws whose margins the order had tuned.)
//
// Two sides, for two threads, where the waves are large enough (SweepPlan::parallel),
// whatever the threads: the movable bodies are ranked breadth first through the
// manifolds joining two of them, from a body farthest from where the search began (in
// each group of bodies so joined), and cut in two at a rank (the one that leaves the most
// rows in the smaller side). The sweep's order is then side 0's manifolds (every movable
// body of it before the cut), side 1's (every one at or after it), then the seam's (one
// movable body each side), each in the solve's order: the two sides' manifolds share no
// movable body, so their waves run side by side, each side's parts its thread's, sweep
// after sweep (each a connected region of the pile, whose bodies stay in its thread's
// cache), without waiting for the other's; the seam's manifolds, the last on their bodies,
// take waves of their own after both sides' rows and spin rows (SweepWave::seam,
// SweepPlan::sequence), on side 1, waiting for side 0's last parts on their bodies: the
// worker's, which then runs on from the seam into the next sweep while the caller waits for
// it (the other way round, the worker waited through the seam and had fallen asleep by the
// next sweep: it started 20-100 us late). On one thread (no worker), or where the worker's
// cost model runs the sweeps alone (Worker::pairs), a wave's two sides are one part and
// nothing waits: the same order, with no more part-filled groups than one side leaves.
// Below that size, one side in the solve's order.
#pragma once

#include <cstdint>
#include <vector>

#include "contact_solver.h"

namespace collres {

// wave_manifolds' scratch, kept between calls
struct WaveScratch {
  std::vector<int32_t> last;     // (N,) per body: the last wave or part that moved it
  std::vector<int32_t> rank;     // (N,) per body: its place breadth first (-1: immovable)
  int32_t ranked = 0;            // bodies ranked
  uint64_t epoch = ~uint64_t{0};   // the rows (SweepPlan::rows_epoch) they were ranked for
  std::vector<int32_t> begin, adjacent, queue;   // the movable bodies' neighbours; search
  std::vector<int32_t> side;     // per manifold of the sweep's order: its side (sides(): class)
  std::vector<int64_t> before, from;   // sides(): rows per rank
  std::vector<int32_t> sorted;   // the sweep's order with two sides (indices into manifolds)
  std::vector<size_t> bucket, start;
  std::vector<int32_t> order, index;
  std::vector<uint8_t> speculative;   // per chosen manifold: every row with allowance > 0
  std::vector<int8_t> kind;          // per chosen manifold: its rows (1 to 4) where they
                                     // share one frame (WideGroup), else 5 (one by one)
  std::vector<int8_t> framing;       // per manifold of `manifolds`: its kind, 0 until found
  uint64_t framed = ~uint64_t{0};    // the rows (SweepPlan::rows_epoch) framing is for
  std::vector<int8_t> key;           // per chosen manifold: 4 side + kind - 1 (-1: kind 5)
  std::vector<int32_t> next;         // per chosen manifold: the next one on its body A, B
  std::vector<int32_t> members, carry, moved;   // fill_lanes: the waves' manifolds
};

// The manifolds `chosen` (indices into `manifolds`, ascending: the solve's order), in the
// sweep's order (above: the solve's, or with two sides the sides' then the seam's) wave by
// wave, each wave side 0's part then side 1's (the parts that are not empty; one part on
// one thread: plan.worker null, or its sweeps run alone), into `out`
// (SweepPlan's layout, a part per SweepWave: within a part, wide groups of kLanes
// manifolds of one row count 1..4 first, then the rest of each row count 1..4 left two or
// three (padded groups), then the rest left one and the longer manifolds one by one (and
// those whose rows do not share one frame, n, t1 and t2: a wide group keeps one a lane);
// within a row count the speculative manifolds, every row with allowance > 0, last), each
// copied once; fills plan.waves (with each part's side, after, spin_after and seam; with
// two parts a wave the waits, else none),
// plan.sequence and plan.spin_rows, and clears plan.packed (its other fields are left as
// they are). The manifolds keep their rows and
// spin rows (Manifold::spin); the rows keep their ContactRow::manifold. `inv_mass` (N,)
// 1/kg: 0 for immovable bodies. A manifold's kind is found once while plan.rows_epoch
// stays: the caller changes it whenever it changes a row's frame (a one-row manifold's
// may change: its kind is 1 whatever its frame).
void wave_manifolds(const std::vector<Manifold>& manifolds, const std::vector<int32_t>& chosen,
                    const std::vector<ContactRow>& rows, const double* inv_mass,
                    int64_t body_count, SweepPlan& plan, std::vector<Manifold>& out,
                    WaveScratch& scratch);

}  // namespace collres
