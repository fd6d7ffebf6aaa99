// Narrow phase and manifolds: coal GJK/EPA queries, contact patches reduced to at most
// four points, feature ids for warm starting, and the store of last step's manifolds.
//
// Conventions: every query takes coal geometries and their world poses; signed distance
// in m (negative when the shapes interpenetrate, EPA), unit normal from the first shape
// to the second, and a witness point on each (world, m). A manifold is the list of
// point pairs (on A, on B) that share one normal; each point pair gets a `feature` id,
// the same every step for the same corner, edge or face of both bodies.
//
// Triangles (shapes.h MeshTriangle, the pieces of a triangle-mesh body) give their face's
// normal, as far as the triangle's witness point says:
// - inside the triangle: the face's front normal exactly (the depth as found);
// - on an active edge (the mesh's boundary, a convex crease): the normal GJK/EPA found,
//   so a shape rolls over the edge;
// - on inactive edges only (between coplanar triangles, in a concave crease): the face's
//   normal when it is that already, else no contact: it is the shadow of the contact the
//   neighbour across the edge gives (a box resting on a floor of many triangles does not
//   catch on the edges between them);
// - a shape overlapping the triangle from behind (a normal to its back) is turned to the
//   front, as deep as its deepest point behind the plane (it is pushed out to the front);
//   apart behind it, the contact stays as found.
#pragma once

#include <algorithm>
#include <cstdint>
#include <memory>
#include <vector>

#include <coal/collision.h>
#include <coal/collision_data.h>
#include <coal/contact_patch.h>
#include <coal/distance.h>

#include "detection_types.h"
#include "shapes.h"

namespace collres {

constexpr double kPatchTolerance = 0.01;  // m: points within this of the separating plane
                                          // join a patch (coal's 1 mm drops tilted faces)
constexpr double kPatchThickness = 0.25;  // ... and within this fraction of the thinner
                                          // shape's least extent (its far face stays out)
constexpr int kMaxManifoldPoints = 4;     // as Box2D, Bullet and Jolt

struct PointPair {
  Vec3 on_a, on_b;  // m, world, each body's own point
};

// coal's collide for one pair of node types, on any two geometries of those types, with
// one GJK/EPA solver kept from query to query: coal::collide builds a solver, and EPA its
// buffers, on every call (a fifth of a settled pile's detection went to allocation). Each
// query starts the solver as a new one would (no warm start from the last pair): the same
// answer as coal::collide.
class TypedCollide : public coal::ComputeCollision {
 public:
  using coal::ComputeCollision::ComputeCollision;
  std::size_t operator()(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                         const coal::CollisionGeometry& gb, const coal::Transform3s& tb,
                         const coal::CollisionRequest& request, coal::CollisionResult& result);
};

// coal's distance for one pair of node types, kept as TypedCollide is: coal::distance builds
// a GJK solver (and EPA its buffers for overlapping shapes) on every call. Each query
// starts the solver's guesses as a new solver's: the same answer as coal::distance.
class TypedDistance : public coal::ComputeDistance {
 public:
  using coal::ComputeDistance::ComputeDistance;
  double operator()(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                    const coal::CollisionGeometry& gb, const coal::Transform3s& tb,
                    const coal::DistanceRequest& request, coal::DistanceResult& result);
};

// coal's contact patch for one pair of node types, kept: coal::computeContactPatch builds a
// patch solver and reserves its three support sets on every call (most of a fresh
// manifold's allocations). Each query starts the support guesses at zero (a new solver
// leaves them unset; only a convex of many vertices reads them, as a first vertex for its
// hill climb, whose support set does not depend on it).
class TypedPatch : public coal::ComputeContactPatch {
 public:
  using coal::ComputeContactPatch::ComputeContactPatch;
  void operator()(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                  const coal::CollisionGeometry& gb, const coal::Transform3s& tb,
                  const coal::CollisionResult& collision, const coal::ContactPatchRequest& request,
                  coal::ContactPatchResult& result);
};

// Reusable coal requests and results for the queries on one pair at a time.
class PairQuery {
 public:
  PairQuery();

  // Signed distance (m) at any range, with the normal A->B and the witness points; the
  // contact stays loaded for `manifold`.
  double signed_distance(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                         const coal::CollisionGeometry& gb, const coal::Transform3s& tb,
                         Vec3& normal, PointPair& witness);
  // True when closer than `margin` (m); the contact stays loaded for `manifold`.
  bool contact(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
               const coal::CollisionGeometry& gb, const coal::Transform3s& tb,
               double margin, double& distance, Vec3& normal, PointPair& witness);
  // The loaded contact's normal replaced by `normal` (a unit direction trusted over EPA's
  // on a shallow overlap): `manifold` then finds the patch about it.
  void turn_loaded(const Vec3& normal);
  // True when the shapes interpenetrate (distance < 0); a failed coal query counts as apart.
  bool overlaps(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                const coal::CollisionGeometry& gb, const coal::Transform3s& tb);
  // Distance >= 0 (m, 0 when they overlap) and the closest points (GJK; coal's distance()
  // has no triangle, so a pair with one takes them from a collision query at any range,
  // which leaves the loaded contact alone too).
  double distance(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                  const coal::CollisionGeometry& gb, const coal::Transform3s& tb,
                  PointPair& closest);
  // The manifold of the loaded contact on the same pair (same poses): the coal patch
  // where faces touch, with the witness points (coal's deepest) where no patch point comes
  // within `tie` (m) of their depth, reduced to at most four points that keep the deepest
  // one (to within `tie`: reduce_manifold), else the witness points. The patch's points lie on
  // the separating plane; each body's point is where the line along the normal through
  // it meets that body's surface (boxes and half-spaces), else half the patch's one depth
  // along the normal from there.
  void manifold(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                const coal::CollisionGeometry& gb, const coal::Transform3s& tb,
                double tie, std::vector<PointPair>& points);

 private:
  bool loaded_is_valid() const;  // the loaded contact's depth is a number coal computed
  // coal::collide's answer, through the kept TypedCollide of the two node types
  std::size_t collide(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                      const coal::CollisionGeometry& gb, const coal::Transform3s& tb,
                      const coal::CollisionRequest& request, coal::CollisionResult& result);
  // The loaded contact of a triangle as the file comment says; false when it is none.
  // B's pose of the loaded query is `tb` moved by `shift` (m, world; the pose is built only
  // for a triangle's contact).
  bool onto_face(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                 const coal::CollisionGeometry& gb, const coal::Transform3s& tb,
                 const Vec3& shift);

  coal::CollisionRequest request_;
  coal::CollisionResult result_;
  coal::DistanceRequest distance_request_;
  coal::DistanceResult distance_result_;
  coal::CollisionRequest range_request_;   // distance() of a pair with a triangle
  coal::CollisionResult range_result_;
  coal::ContactPatchRequest patch_request_;
  coal::ContactPatchResult patch_result_;
  std::vector<Vec3> polygon_;
  std::vector<PointPair> surface_;   // each polygon point's pair on the two surfaces
  std::vector<double> separation_;   // m, each polygon point's (on_b - on_a) . normal
  std::vector<int> keep_;
  // coal's distance and contact patch, through the kept solvers of the two node types
  double distance_of(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                     const coal::CollisionGeometry& gb, const coal::Transform3s& tb);
  void patch(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
             const coal::CollisionGeometry& gb, const coal::Transform3s& tb);
  std::unique_ptr<TypedCollide> collide_[coal::NODE_COUNT][coal::NODE_COUNT];
  std::unique_ptr<TypedDistance> distance_[coal::NODE_COUNT][coal::NODE_COUNT];
  std::unique_ptr<TypedPatch> patch_[coal::NODE_COUNT][coal::NODE_COUNT];
  Vec3 loaded_shift_ = Vec3::Zero();  // m, B's step of the loaded contact (failed queries)
  int loaded_types_[2] = {-1, -1};    // the node types of the last collide's geometries
};

// Indices (at most four) of the polygon's points that keep its deepest point and the most
// of its area: first the one farthest along a fixed tangent, or the deepest point when it
// is deeper than that one by more than `tie` (m; `separation` per point, m, negative when
// overlapping: a patch's points do not share one depth where its faces are tilted to one
// another, and where two boxes cross edge on edge the deepest is where the edges cross,
// a point no area rule picks), then the one farthest from it, the one that makes the
// largest triangle with both, and the one that adds the most area on the other side
// (Bullet's and Jolt's reduction). `normal` is the patch normal.
void reduce_manifold(const std::vector<Vec3>& polygon, const std::vector<double>& separation,
                     const Vec3& normal, double tie, std::vector<int>& keep);

// Feature id of a point pair from its body-frame points and the bodies' half extents: each
// coordinate is coded by whether it lies in the outer quarter of the half extent on either
// side (corner, edge or face of each body), 27 * code on A + code on B, in [0, 729). The
// caller adds 729 * rank (0, 1, ...) to separate repeated codes within one pair.
std::int64_t feature_code(const Vec3& local_a, const Vec3& half_a, const Vec3& local_b,
                          const Vec3& half_b);

// Last step's persistent manifolds, in the two body frames, keyed by pair; and the pairs
// measured apart (beyond the margin), with their distance.
struct StoredManifold {
  Vec3 rel_p = Vec3::Zero();        // m, B's origin in A's frame when computed
  Quat rel_q = Quat::Identity();    // B's orientation in A's frame when computed
  int first = 0, count = 0;         // rows in ManifoldStore's row arrays
  double apart = 0.0;               // m, > 0: the pair's distance then (no rows); 0: a manifold
};

struct StoredRow {
  Vec3 local_a, local_b;  // m, point on A in A's frame, on B in B's frame
  Vec3 normal_a;          // unit normal A->B in A's frame
  std::int64_t feature;
};

// Manifolds are stored, and looked up, in increasing pair key order (a * N + b).
class ManifoldStore {
 public:
  void clear() {
    keys_.clear();
    pairs_.clear();
    rows_.clear();
  }
  // The manifold of `key`, or null; `cursor` is the caller's place in the store (0 to
  // start; one per reader): keys asked in increasing order cost O(1) each.
  const StoredManifold* find(std::int64_t key, std::size_t& cursor) const {
    if (cursor > keys_.size() || (cursor > 0 && keys_[cursor - 1] > key)) cursor = 0;
    // the next keys first (the asked keys mostly follow the stored ones), then a search
    const std::size_t near = std::min(keys_.size(), cursor + 4);
    while (cursor < near && keys_[cursor] < key) ++cursor;
    if (cursor == near && near < keys_.size()) {
      cursor = static_cast<std::size_t>(
          std::lower_bound(keys_.begin() + cursor, keys_.end(), key) - keys_.begin());
    }
    if (cursor == keys_.size() || keys_[cursor] != key) return nullptr;
    return &pairs_[cursor];
  }
  const StoredRow& row(int index) const { return rows_[index]; }
  // Whether a manifold of `key` would be here rather than in a store of lesser keys
  // (its first key is at most `key`)
  bool starts_by(std::int64_t key) const { return !keys_.empty() && keys_.front() <= key; }
  // Starts the manifold of `key` (keys in increasing order); rows follow with `add_row`.
  void begin(std::int64_t key, const Vec3& rel_p, const Quat& rel_q) {
    keys_.push_back(key);
    pairs_.push_back({rel_p, rel_q, static_cast<int>(rows_.size()), 0});
  }
  // A pair measured `distance` (> 0) apart at the relative pose rel_p, rel_q (no rows).
  void begin_apart(std::int64_t key, const Vec3& rel_p, const Quat& rel_q, double distance) {
    keys_.push_back(key);
    pairs_.push_back({rel_p, rel_q, static_cast<int>(rows_.size()), 0, distance});
  }
  void add_row(const StoredRow& row) {
    rows_.push_back(row);
    ++pairs_.back().count;
  }
  // `count` rows at once (a reused manifold's, from another store)
  void add_rows(const StoredRow* rows, int count) {
    rows_.insert(rows_.end(), rows, rows + count);
    pairs_.back().count += count;
  }
  void swap(ManifoldStore& other) {
    keys_.swap(other.keys_);
    pairs_.swap(other.pairs_);
    rows_.swap(other.rows_);
  }

 private:
  std::vector<std::int64_t> keys_;
  std::vector<StoredManifold> pairs_;
  std::vector<StoredRow> rows_;
};

}  // namespace collres
