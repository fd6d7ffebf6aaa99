// Waves of a velocity sweep (wavefronts): the order in which the sweeps visit a solve's
// manifolds, for lanes and threads, without changing a bit of their answer.
//
// A sweep solves the manifolds one after the other in their order (Gauss-Seidel). Two
// manifolds that share no movable body (immovable ones, static or held, are only read)
// commute: solving them in either order gives the same bits. A manifold's wave is one
// more than the highest wave of the manifolds before it that share a movable body with
// it (0 without one). Visiting the waves in turn is then the same sweep as the order,
// bit for bit, and the manifolds of one wave share no movable body: they may be solved
// in any order, four at a time in lanes (wide groups) and on two threads. (Box2D v3
// colours its constraint graph greedily instead; that reorders the sweep, and measured
// here it broke the pile and heap laws whose margins the order had tuned.)
#pragma once

#include <cstdint>
#include <vector>

#include "contact_solver.h"

namespace collres {

// The manifolds `chosen` (indices into `manifolds`, ascending: the sweep's order) wave by
// wave into `out` (SweepPlan's layout: within a wave, wide groups of kLanes manifolds of
// one row count 1..4 first, then the rest of each row count 1..4 left two or three
// (padded groups), then the rest left one and the longer manifolds one by one; within a row count the speculative
// manifolds, every row with allowance > 0, last), each copied once; fills plan.waves and
// clears plan.packed (its other fields are left as they are). The manifolds keep their
// rows and spin rows (Manifold::spin); the rows keep their ContactRow::manifold.
// `inv_mass` (N,) 1/kg: 0 for immovable bodies. `wave`, `bucket`, `start` and `order` are
// scratch.
void wave_manifolds(const std::vector<Manifold>& manifolds, const std::vector<int32_t>& chosen,
                    const std::vector<ContactRow>& rows, const double* inv_mass,
                    int64_t body_count, SweepPlan& plan, std::vector<Manifold>& out,
                    std::vector<int32_t>& wave, std::vector<size_t>& bucket,
                    std::vector<size_t>& start, std::vector<int32_t>& order);

}  // namespace collres
