#include "manifold.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <coal/narrowphase/support_functions.h>

namespace collres {

namespace {

constexpr double kAnyRange = 1e300;  // security margin that makes every query report
constexpr double kFailedDepth = 1e300;  // |depth| of a failed GJK/EPA query (coal: DBL_MAX)
constexpr double kRetryStep = 1e-6;     // m, B's step for a failed query (below any slop)
// GJK's tolerance on every query of a pair. At coal's default (1e-6) GJK stopped on faces
// 10 nm to 1 um apart as if they touched, and the penetration query that followed on that
// degenerate simplex gave a normal 9-88 deg off the faces' and separations of +-11 mm to
// -0.1 m (two cubes landed flat, tilted 3e-5 rad: 8 of 2000 random such poses); to 1e-9
// the closest points, their normal and distance hold down to a gap of ~1e-8 m
constexpr double kGjkTolerance = 1e-9;

Vec3 to_vec(const coal::Vec3s& v) { return Vec3(v[0], v[1], v[2]); }

// Where the line p + t n (world, n unit) meets the surface of a box or a half-space
// (t in m): for `entry` the smallest t in the solid (its surface facing -n, as B's faces
// A), else the largest (facing +n, as A's faces B). False for other shapes and when the
// line misses the solid.
bool surface_along(const coal::CollisionGeometry& g, const coal::Transform3s& tf,
                   const Vec3& p, const Vec3& n, bool entry, double& t) {
  const Vec3 q = tf.getRotation().transpose() * (p - to_vec(tf.getTranslation()));
  const Vec3 d = tf.getRotation().transpose() * n;
  if (g.getNodeType() == coal::GEOM_BOX) {
    // slabs grown by a rounding allowance: a patch's corner point grazes the box's corner
    const Vec3 h = to_vec(static_cast<const coal::Box&>(g).halfSide);
    const double grow = 1e-9 * h.maxCoeff();
    double lo = -std::numeric_limits<double>::infinity(), hi = -lo;
    for (int i = 0; i < 3; ++i) {
      if (std::abs(d[i]) < 1e-12) {
        if (std::abs(q[i]) > h[i] + grow) return false;
        continue;
      }
      const double t1 = (-h[i] - grow - q[i]) / d[i], t2 = (h[i] + grow - q[i]) / d[i];
      lo = std::max(lo, std::min(t1, t2));
      hi = std::min(hi, std::max(t1, t2));
    }
    if (lo > hi) return false;
    t = entry ? lo : hi;
    return true;
  }
  if (g.getNodeType() == coal::GEOM_HALFSPACE) {
    const auto* half = static_cast<const coal::Halfspace*>(&g);
    const double along = to_vec(half->n).dot(d);
    if (std::abs(along) < 1e-12) return false;
    t = (half->d - to_vec(half->n).dot(q)) / along;
    return true;
  }
  return false;
}

constexpr double kBeside = 1e-6;   // |cosine| of a normal that lies in the face's plane
constexpr double kOnEdge = 1e-5;   // barycentric weight below which a point is on the
                                   // opposite edge (GJK's witness is good to about 1e-6 m)

// Where a triangle's point `p` (world) lies: near an active edge, on inactive edges only,
// or inside it (manifold.h).
enum class Where { active_edge, inactive_edge, inside };
Where where_on(const MeshTriangle& t, const coal::Transform3s& tf, const Vec3& p) {
  const Vec3 q = tf.getRotation().transpose() * (p - to_vec(tf.getTranslation()));
  const Vec3 a = t.a, b = t.b, c = t.c;
  const Vec3 n = (b - a).cross(c - a);
  const double area = n.squaredNorm();
  // barycentric weights of a, b, c: each is 0 on the opposite edge (b-c, c-a, a-b)
  const double wa = (c - b).cross(q - b).dot(n) / area;
  const double wb = (a - c).cross(q - c).dot(n) / area;
  const double wc = 1.0 - wa - wb;
  const bool on[3] = {wc < kOnEdge, wa < kOnEdge, wb < kOnEdge};   // a-b, b-c, c-a
  Where where = Where::inside;
  for (int edge = 0; edge < 3; ++edge) {
    if (on[edge] && t.active[edge]) return Where::active_edge;
    if (on[edge]) where = Where::inactive_edge;
  }
  return where;
}

}  // namespace

PairQuery::PairQuery() {
  request_.num_max_contacts = 1;
  request_.gjk_tolerance = kGjkTolerance;
  range_request_.num_max_contacts = 1;
  range_request_.gjk_tolerance = kGjkTolerance;
  distance_request_.gjk_tolerance = kGjkTolerance;
  range_request_.security_margin = kAnyRange;
  patch_request_.setPatchTolerance(kPatchTolerance);
}

double PairQuery::signed_distance(const coal::CollisionGeometry& ga,
                                  const coal::Transform3s& ta,
                                  const coal::CollisionGeometry& gb,
                                  const coal::Transform3s& tb, Vec3& normal,
                                  PointPair& witness) {
  double distance = std::numeric_limits<double>::infinity();
  if (!contact(ga, ta, gb, tb, kAnyRange, distance, normal, witness)) {
    normal = Vec3::UnitZ();
    witness = {to_vec(ta.getTranslation()), to_vec(tb.getTranslation())};
  }
  return distance;
}

std::size_t TypedCollide::operator()(const coal::CollisionGeometry& ga,
                                     const coal::Transform3s& ta,
                                     const coal::CollisionGeometry& gb,
                                     const coal::Transform3s& tb,
                                     const coal::CollisionRequest& request,
                                     coal::CollisionResult& result) {
  o1 = &ga;
  o2 = &gb;
  // a new solver's guesses (ComputeCollision keeps the last query's support hints)
  solver.cached_guess = coal::Vec3s(1, 0, 0);
  solver.support_func_cached_guess = coal::support_func_guess_t::Zero();
  if (swap_geoms || request.enable_timings || request.enable_cached_gjk_guess ||
      request.gjk_initial_guess == coal::GJKInitialGuess::CachedGuess ||
      !(request.security_margin > -std::numeric_limits<double>::infinity())) {
    return coal::ComputeCollision::operator()(ta, tb, request, result);
  }
  // what ComputeCollision::operator() does then, without its two calls (about a tenth of
  // a sphere's query): the solver set from the request, then the pair's collision
  // function (the guesses run() then copies into the result are never read here; into the
  // request only in the cases above)
  solver.set(request);
  return func(o1, ta, o2, tb, &solver, request, result);
}

namespace {

// the two node types of plain geometries (the kept solvers' index), or false
bool node_types(const coal::CollisionGeometry& ga, const coal::CollisionGeometry& gb, int& a,
                int& b) {
  a = ga.getNodeType();
  b = gb.getNodeType();
  return ga.getObjectType() == coal::OT_GEOM && gb.getObjectType() == coal::OT_GEOM && a >= 0 &&
         b >= 0 && a < coal::NODE_COUNT && b < coal::NODE_COUNT;
}

}  // namespace

std::size_t PairQuery::collide(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                               const coal::CollisionGeometry& gb, const coal::Transform3s& tb,
                               const coal::CollisionRequest& request,
                               coal::CollisionResult& result) {
  int a = 0, b = 0;
  const bool plain = node_types(ga, gb, a, b);
  loaded_types_[0] = a;
  loaded_types_[1] = b;
  if (!plain) return coal::collide(&ga, ta, &gb, tb, request, result);
  std::unique_ptr<TypedCollide>& typed = collide_[a][b];
  if (!typed) typed = std::make_unique<TypedCollide>(&ga, &gb);
  return (*typed)(ga, ta, gb, tb, request, result);
}

double TypedDistance::operator()(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                                 const coal::CollisionGeometry& gb, const coal::Transform3s& tb,
                                 const coal::DistanceRequest& request,
                                 coal::DistanceResult& result) {
  o1 = &ga;
  o2 = &gb;
  solver.cached_guess = coal::Vec3s(1, 0, 0);
  solver.support_func_cached_guess = coal::support_func_guess_t::Zero();
  return coal::ComputeDistance::operator()(ta, tb, request, result);
}

void TypedPatch::operator()(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                            const coal::CollisionGeometry& gb, const coal::Transform3s& tb,
                            const coal::CollisionResult& collision,
                            const coal::ContactPatchRequest& request,
                            coal::ContactPatchResult& result) {
  o1 = &ga;
  o2 = &gb;
  csolver.setSupportGuess(coal::support_func_guess_t::Zero());
  coal::ComputeContactPatch::operator()(ta, tb, collision, request, result);
}

double PairQuery::distance_of(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                              const coal::CollisionGeometry& gb, const coal::Transform3s& tb) {
  int a = 0, b = 0;
  if (!node_types(ga, gb, a, b)) {
    return coal::distance(&ga, ta, &gb, tb, distance_request_, distance_result_);
  }
  std::unique_ptr<TypedDistance>& typed = distance_[a][b];
  if (!typed) typed = std::make_unique<TypedDistance>(&ga, &gb);
  return (*typed)(ga, ta, gb, tb, distance_request_, distance_result_);
}

void PairQuery::patch(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                      const coal::CollisionGeometry& gb, const coal::Transform3s& tb) {
  int a = 0, b = 0;
  if (!node_types(ga, gb, a, b)) {
    coal::computeContactPatch(&ga, ta, &gb, tb, result_, patch_request_, patch_result_);
    return;
  }
  std::unique_ptr<TypedPatch>& typed = patch_[a][b];
  if (!typed) typed = std::make_unique<TypedPatch>(&ga, &gb);
  (*typed)(ga, ta, gb, tb, result_, patch_request_, patch_result_);
}

bool PairQuery::loaded_is_valid() const {
  const double depth = result_.getContact(0).penetration_depth;
  return std::isfinite(depth) && std::abs(depth) < kFailedDepth;
}

bool PairQuery::contact(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                        const coal::CollisionGeometry& gb, const coal::Transform3s& tb,
                        double margin, double& distance, Vec3& normal, PointPair& witness) {
  request_.security_margin = margin;
  result_.clear();
  if (collide(ga, ta, gb, tb, request_, result_) == 0) return false;
  Vec3 shift = Vec3::Zero();
  if (!loaded_is_valid()) {
    // GJK/EPA fail on some just-touching poses (depth -DBL_MAX, a wrong normal): query B
    // moved by a tiny step along each world axis until one answers, and undo the step
    bool found = false;
    for (int k = 0; k < 6 && !found; ++k) {
      shift = Vec3::Unit(k / 2) * (k % 2 ? -kRetryStep : kRetryStep);
      const coal::Transform3s moved(tb.getRotation(), tb.getTranslation() + shift);
      result_.clear();
      found = collide(ga, ta, gb, moved, request_, result_) > 0 && loaded_is_valid();
    }
    if (!found) {
      result_.clear();
      return false;
    }
  }
  if (!onto_face(ga, ta, gb, tb, shift)) {
    result_.clear();
    return false;
  }
  const coal::Contact& c = result_.getContact(0);
  normal = to_vec(c.normal);
  distance = c.penetration_depth - shift.dot(normal);   // the step along the normal undone
  witness = {to_vec(c.nearest_points[0]), to_vec(c.nearest_points[1]) - shift};
  loaded_shift_ = shift;
  return true;
}

void PairQuery::turn_loaded(const Vec3& normal) {
  coal::Contact c = result_.getContact(0);
  c.normal = normal;
  result_.clear();
  result_.addContact(c);
}

bool PairQuery::onto_face(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                          const coal::CollisionGeometry& gb, const coal::Transform3s& tb_query,
                          const Vec3& shift) {
  const bool on_a = loaded_types_[0] == coal::GEOM_TRIANGLE;
  if (!on_a && loaded_types_[1] != coal::GEOM_TRIANGLE) return true;
  const coal::Transform3s tb(tb_query.getRotation(), tb_query.getTranslation() + shift);
  const auto& triangle = static_cast<const MeshTriangle&>(on_a ? ga : gb);
  const coal::Transform3s& pose = on_a ? ta : tb;
  coal::Contact c = result_.getContact(0);
  const Vec3 front = (pose.getRotation() *
                      (triangle.b - triangle.a).cross(triangle.c - triangle.a)).normalized();
  const Vec3 out = on_a ? front : Vec3(-front);   // A -> B: the other shape to the front
  const double along = to_vec(c.normal).dot(out);
  if (along < -kBeside) {
    // behind the triangle: only an overlap is turned (a shape apart behind it is no
    // contact of its front), as deep as the shape's deepest point behind the plane
    if (!(c.penetration_depth < 0.0)) return true;
    const coal::CollisionGeometry& other = on_a ? gb : ga;
    const coal::Transform3s& other_pose = on_a ? tb : ta;
    int hint = 0;
    const Vec3 deepest = other_pose.transform(
        coal::details::getSupport<coal::details::WithSweptSphere>(
            static_cast<const coal::ShapeBase*>(&other),
            other_pose.getRotation().transpose() * (-front), hint));
    const double depth = front.dot(deepest - pose.transform(triangle.a));   // m, < 0
    const Vec3 on_plane = deepest - depth * front;
    c.penetration_depth = depth;
    c.nearest_points[0] = on_a ? on_plane : deepest;
    c.nearest_points[1] = on_a ? deepest : on_plane;
    c.pos = 0.5 * (on_plane + deepest);
  } else {
    switch (where_on(triangle, pose, to_vec(c.nearest_points[on_a ? 0 : 1]))) {
      case Where::active_edge:
        return true;   // the edge's (or corner's) own normal
      case Where::inactive_edge:
        // along another normal: the shadow of the neighbour's contact, which has it
        if (along < 1.0 - kBeside) return false;
        break;
      case Where::inside:
        break;
    }
  }
  c.normal = out;
  result_.clear();
  result_.addContact(c);
  return true;
}

bool PairQuery::overlaps(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                         const coal::CollisionGeometry& gb, const coal::Transform3s& tb) {
  request_.security_margin = 0.0;
  result_.clear();
  loaded_shift_ = Vec3::Zero();
  // a failed query (just touching, see `contact`) counts as apart: bisection then ends on
  // a pose whose contact coal computes
  return collide(ga, ta, gb, tb, request_, result_) > 0 && loaded_is_valid();
}

double PairQuery::distance(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                           const coal::CollisionGeometry& gb, const coal::Transform3s& tb,
                           PointPair& closest) {
  if (ga.getNodeType() == coal::GEOM_TRIANGLE || gb.getNodeType() == coal::GEOM_TRIANGLE) {
    range_result_.clear();
    if (collide(ga, ta, gb, tb, range_request_, range_result_) == 0) return 0.0;
    const coal::Contact& c = range_result_.getContact(0);
    closest = {to_vec(c.nearest_points[0]), to_vec(c.nearest_points[1])};
    // a failed query (depth -DBL_MAX) counts as touching: advancement stops there
    return std::isfinite(c.penetration_depth) ? std::max(0.0, c.penetration_depth) : 0.0;
  }
  distance_result_.clear();
  const double gap = distance_of(ga, ta, gb, tb);
  closest = {to_vec(distance_result_.nearest_points[0]),
             to_vec(distance_result_.nearest_points[1])};
  return std::max(0.0, gap);
}

void PairQuery::manifold(const coal::CollisionGeometry& ga, const coal::Transform3s& ta,
                         const coal::CollisionGeometry& gb, const coal::Transform3s& tb,
                         double tie, std::vector<PointPair>& points) {
  points.clear();
  const coal::Contact& c = result_.getContact(0);
  patch_result_.clear();
  const coal::Transform3s moved(tb.getRotation(), tb.getTranslation() + loaded_shift_);
  // points within kPatchTolerance of the plane, or within kPatchThickness of the thinner
  // shape's least extent: a 1 cm cube's far face lies within 1 cm, and a point of it
  // taken for one of its touching corners left that corner out (it rested tilted, a
  // corner 0.15 mm deep and another in the air)
  double least = kPatchTolerance / kPatchThickness;
  for (const coal::CollisionGeometry* g : {&ga, &gb}) {
    const coal::AABB& box = g->aabb_local;
    const double extent = std::min({box.width(), box.height(), box.depth()});
    if (extent > 0.0 && std::isfinite(extent)) least = std::min(least, extent);
  }
  patch_request_.setPatchTolerance(kPatchThickness * least);
  patch(ga, ta, gb, moved);
  if (patch_result_.numContactPatches() > 0) {
    const coal::ContactPatch& patch = patch_result_.getContactPatch(0);
    if (patch.size() > 1) {
      const Vec3 normal = to_vec(c.normal);
      const Vec3 half = 0.5 * patch.penetration_depth * normal;
      polygon_.clear();
      surface_.clear();
      separation_.clear();
      // each point in the world frame, as ContactPatch::getPoint gives it (whose range
      // check builds a std::logic_error on every call, thrown or not), and its own depth
      // where the surface is known (boxes, half-spaces): a patch gathers points within
      // kPatchTolerance of the plane, and a tilted face's far corners are not at the
      // patch's one depth (a box would rest on them in the air)
      for (const coal::Vec2s& point : patch.points()) {
        const Vec3 p = to_vec(patch.tf.transform(coal::Vec3s(point(0), point(1), 0.0)));
        Vec3 on_a = p - half, on_b = p + half;
        double t = 0.0;
        if (surface_along(ga, ta, p, normal, false, t)) on_a = p + t * normal;
        if (surface_along(gb, moved, p, normal, true, t)) on_b = p + t * normal;
        polygon_.push_back(p);
        surface_.push_back({on_a - 0.5 * loaded_shift_, on_b - 0.5 * loaded_shift_});
        separation_.push_back((on_b - on_a).dot(normal));
      }
      // and the pair's deepest point (coal's witness) where no patch point comes within
      // `tie` of its depth: two boxes crossing edge on edge overlap deepest where the
      // edges cross, inside the patch's edge, while its ends along it barely touch (the
      // reduction then keeps it)
      const PointPair witness{to_vec(c.nearest_points[0]),
                              to_vec(c.nearest_points[1]) - loaded_shift_};
      const double depth = (witness.on_b - witness.on_a).dot(normal);
      if (depth < *std::min_element(separation_.begin(), separation_.end()) - tie) {
        polygon_.push_back(0.5 * (witness.on_a + witness.on_b) + 0.5 * loaded_shift_);
        surface_.push_back(witness);
        separation_.push_back(depth);
      }
      reduce_manifold(polygon_, separation_, normal, tie, keep_);
      for (int k : keep_) points.push_back(surface_[k]);
      return;
    }
  }
  points.push_back({to_vec(c.nearest_points[0]), to_vec(c.nearest_points[1]) - loaded_shift_});
}

void reduce_manifold(const std::vector<Vec3>& polygon, const std::vector<double>& separation,
                     const Vec3& normal, double tie, std::vector<int>& keep) {
  const int count = static_cast<int>(polygon.size());
  keep.clear();
  if (count <= kMaxManifoldPoints) {
    for (int k = 0; k < count; ++k) keep.push_back(k);
    return;
  }
  // a tangent fixed by the normal alone: the same points are chosen step after step
  int least = 0;
  normal.cwiseAbs().minCoeff(&least);
  const Vec3 axis = Vec3::Unit(least);
  const Vec3 tangent = normal.cross(axis).normalized();
  auto best = [count](auto score) {
    int index = -1;
    double top = 0.0;
    for (int k = 0; k < count; ++k) {
      const double value = score(k);
      if (index < 0 || value > top) {
        index = k;
        top = value;
      }
    }
    return std::make_pair(index, top);
  };
  int i0 = best([&](int k) { return polygon[k].dot(tangent); }).first;
  if (!separation.empty()) {
    const int deepest = best([&](int k) { return -separation[k]; }).first;
    if (separation[deepest] < separation[i0] - tie) i0 = deepest;
  }
  const Vec3& p0 = polygon[i0];
  const int i1 = best([&](int k) { return (polygon[k] - p0).squaredNorm(); }).first;
  const Vec3& p1 = polygon[i1];
  auto area = [&normal](const Vec3& a, const Vec3& b, const Vec3& c) {
    return (b - a).cross(c - a).dot(normal);  // twice the signed area about the normal
  };
  const auto [i2, a2] = best([&](int k) { return std::abs(area(p0, p1, polygon[k])); });
  keep = {i0, i1};
  if (a2 <= 0.0) {
    std::sort(keep.begin(), keep.end());
    return;
  }
  keep.push_back(i2);
  // the point that adds the most area outside the triangle (p0, p1, p2)
  const Vec3& p2 = polygon[i2];
  const double side = area(p0, p1, p2) > 0.0 ? 1.0 : -1.0;
  const auto [i3, a3] = best([&](int k) {
    const Vec3& p = polygon[k];
    return std::max({-side * area(p0, p1, p), -side * area(p1, p2, p), -side * area(p2, p0, p),
                     0.0});
  });
  if (a3 > 0.0) keep.push_back(i3);
  std::sort(keep.begin(), keep.end());
}

std::int64_t feature_code(const Vec3& local_a, const Vec3& half_a, const Vec3& local_b,
                          const Vec3& half_b) {
  auto code = [](const Vec3& local, const Vec3& half) {
    std::int64_t value = 0, weight = 1;
    for (int k = 0; k < 3; ++k, weight *= 3) {
      const int side = local[k] > 0.5 * half[k] ? 2 : (local[k] < -0.5 * half[k] ? 1 : 0);
      value += side * weight;
    }
    return value;
  };
  return 27 * code(local_a, half_a) + code(local_b, half_b);
}

}  // namespace collres
