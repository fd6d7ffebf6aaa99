#include "shapes.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>
#include <string>

#include <coal/narrowphase/support_functions.h>
#include <coal/shape/geometric_shapes.h>

namespace collres {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

std::shared_ptr<coal::CollisionGeometry> convex_hull(const std::vector<double>& points) {
  const std::string problem = hull_problem(points);
  if (!problem.empty()) throw std::invalid_argument("convex: " + problem);
  auto vertices = std::make_shared<std::vector<coal::Vec3s>>();
  for (std::size_t k = 0; k + 2 < points.size(); k += 3) {
    vertices->emplace_back(points[k], points[k + 1], points[k + 2]);
  }
  const auto count = static_cast<unsigned int>(vertices->size());
  return std::shared_ptr<coal::CollisionGeometry>(
      coal::ConvexBase::convexHull(vertices, count, true, "Qt"));
}

// Positive finite sizes (m) of the first `count` values, checked before coal sees them.
void check_sizes(const std::vector<double>& size, std::size_t count) {
  if (size.size() < count) throw std::invalid_argument("shape size has too few values");
  for (std::size_t k = 0; k < count; ++k) {
    if (!(size[k] > 0.0) || !(size[k] <= kHullCoordinateLimit)) {
      throw std::invalid_argument("shape sizes must be positive and finite");
    }
  }
}

}  // namespace

std::string hull_problem(const std::vector<double>& points) {
  if (points.size() % 3 != 0) return "vertices must be x, y, z triples";
  const std::size_t count = points.size() / 3;
  if (count < 4) return "needs at least 4 points";
  for (const double c : points) {
    if (!(std::abs(c) <= kHullCoordinateLimit)) {
      return "vertex coordinates must be finite and within 1e9 m";
    }
  }
  auto at = [&points](std::size_t k) { return Vec3(points[3 * k], points[3 * k + 1],
                                                   points[3 * k + 2]); };
  // The extreme points a first simplex is built from: lowest x, farthest from it, farthest
  // from their line, farthest from their plane (each distance over the extent).
  std::size_t first = 0;
  for (std::size_t k = 1; k < count; ++k) {
    if (points[3 * k] < points[3 * first]) first = k;
  }
  const Vec3 origin = at(first);
  double extent = 0.0;
  Vec3 axis = Vec3::Zero();
  for (std::size_t k = 0; k < count; ++k) {
    const double d = (at(k) - origin).norm();
    if (d > extent) { extent = d; axis = at(k) - origin; }
  }
  if (!(extent > 0.0)) return "all points coincide (no volume)";
  axis /= extent;
  double height = 0.0;
  Vec3 side = Vec3::Zero();
  for (std::size_t k = 0; k < count; ++k) {
    const Vec3 off = axis.cross(at(k) - origin);
    if (off.norm() > height) { height = off.norm(); side = off; }
  }
  if (!(height > kHullFlatness * extent)) return "points lie on one line (no volume)";
  const Vec3 normal = side / height;
  double depth = 0.0;
  for (std::size_t k = 0; k < count; ++k) {
    depth = std::max(depth, std::abs(normal.dot(at(k) - origin)));
  }
  if (!(depth > kHullFlatness * extent)) {
    return "points lie in one plane (flatter than 1e-6 of their extent: no volume)";
  }
  return "";
}

std::string triangle_problem(const std::vector<double>& corners) {
  if (corners.size() != 9) return "a triangle needs 3 corners (9 values)";
  for (const double c : corners) {
    if (!(std::abs(c) <= kHullCoordinateLimit)) {
      return "corner coordinates must be finite and within 1e9 m";
    }
  }
  const Vec3 a(corners[0], corners[1], corners[2]), b(corners[3], corners[4], corners[5]),
      c(corners[6], corners[7], corners[8]);
  const double longest = std::max({(b - a).squaredNorm(), (c - b).squaredNorm(),
                                   (a - c).squaredNorm()});
  if (!((b - a).cross(c - a).norm() > kHullFlatness * longest)) {
    return "corners on one line or one spot (no area)";
  }
  return "";
}

std::vector<std::int64_t> extreme_vertices(const std::vector<double>& points, int count) {
  const std::size_t vertices = points.size() / 3;
  std::vector<std::int64_t> chosen;
  if (vertices == 0 || count <= 0) return chosen;
  Vec3 lo = Vec3::Constant(kInf), hi = Vec3::Constant(-kInf);
  for (std::size_t k = 0; k < vertices; ++k) {
    const Vec3 p(points[3 * k], points[3 * k + 1], points[3 * k + 2]);
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const Vec3 centre = 0.5 * (lo + hi);
  const double golden = M_PI * (3.0 - std::sqrt(5.0));   // rad, the lattice's turn per point
  std::vector<Vec3> directions;
  directions.reserve(count);
  for (int d = 0; d < count; ++d) {
    const double z = 1.0 - (2.0 * d + 1.0) / count;
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    directions.emplace_back(r * std::cos(golden * d), r * std::sin(golden * d), z);
  }
  // one pass over the vertices (the directions stay in cache)
  std::vector<double> reach(count, -kInf);
  chosen.assign(count, 0);
  for (std::size_t k = 0; k < vertices; ++k) {
    const Vec3 p = Vec3(points[3 * k], points[3 * k + 1], points[3 * k + 2]) - centre;
    for (int d = 0; d < count; ++d) {
      const double along = directions[d].dot(p);
      if (along > reach[d]) {
        reach[d] = along;
        chosen[d] = static_cast<std::int64_t>(k);
      }
    }
  }
  std::sort(chosen.begin(), chosen.end());
  chosen.erase(std::unique(chosen.begin(), chosen.end()), chosen.end());
  return chosen;
}

void lowest_points(const BodyShape& shape, const Vec3& down, std::vector<Vec3>& out) {
  out.clear();
  if (!shape.vertices.empty()) {
    out = shape.vertices;
    return;
  }
  const double half = 0.5 * shape.axis;
  // the lowest points along `down` of the circle of radius `round` about the z axis at z
  auto rim = [&](double z) {
    const Vec3 centre(0.0, 0.0, z);
    const double across = norm2(down.x(), down.y());
    if (across > 1e-9 * (1.0 + std::fabs(down.z()))) {
      out.push_back(centre + (shape.round / across) * Vec3(down.x(), down.y(), 0.0));
      return;
    }
    for (const Vec3& u : {Vec3(1.0, 0.0, 0.0), Vec3(-1.0, 0.0, 0.0), Vec3(0.0, 1.0, 0.0),
                          Vec3(0.0, -1.0, 0.0)})
      out.push_back(centre + shape.round * u);
  };
  switch (shape.kind) {
    case ShapeKind::sphere:
      out.push_back(shape.round * down);
      break;
    case ShapeKind::capsule:
      for (const double z : {-half, half})
        out.push_back(Vec3(0.0, 0.0, z) + shape.round * down);
      break;
    case ShapeKind::cylinder:
      rim(-half);
      rim(half);
      break;
    case ShapeKind::cone:   // coal's cone: base at -half, apex at +half (about its origin)
      out.push_back(Vec3(0.0, 0.0, half));
      rim(-half);
      break;
    default:
      break;
  }
}

BodyShape make_shape(int kind, const std::vector<double>& size,
                     const std::vector<double>& points, double radius, bool is_static) {
  BodyShape shape;
  shape.kind = static_cast<ShapeKind>(kind);
  shape.radius = radius;
  shape.is_static = is_static;
  auto need = [&size](std::size_t count) { check_sizes(size, count); };
  switch (shape.kind) {
    case ShapeKind::sphere:
      need(1);
      shape.geometry = std::make_shared<coal::Sphere>(size[0]);
      shape.curved = shape.single_point = true;
      shape.round = size[0];
      break;
    case ShapeKind::box:
      need(3);
      shape.geometry = std::make_shared<coal::Box>(size[0], size[1], size[2]);
      for (int corner = 0; corner < 8; ++corner)
        shape.vertices.push_back(0.5 * Vec3(corner & 1 ? size[0] : -size[0],
                                            corner & 2 ? size[1] : -size[1],
                                            corner & 4 ? size[2] : -size[2]));
      break;
    case ShapeKind::capsule:
      need(2);
      shape.geometry = std::make_shared<coal::Capsule>(size[0], size[1]);
      shape.curved = true;
      shape.round = size[0];
      shape.axis = size[1];
      break;
    case ShapeKind::cylinder:
      need(2);
      shape.geometry = std::make_shared<coal::Cylinder>(size[0], size[1]);
      shape.curved = true;
      shape.round = size[0];
      shape.axis = size[1];
      break;
    case ShapeKind::cone:
      need(2);
      shape.geometry = std::make_shared<coal::Cone>(size[0], size[1]);
      shape.offset = Vec3(0.0, 0.0, 0.25 * size[1]);
      shape.curved = true;
      shape.round = size[0];
      shape.axis = size[1];
      break;
    case ShapeKind::plane: {
      if (size.size() < 4) throw std::invalid_argument("shape size has too few values");
      const Vec3 normal(size[0], size[1], size[2]);
      const double length = normal.norm();
      if (!(length > 0.0) || !std::isfinite(length) || !std::isfinite(size[3])) {
        throw std::invalid_argument("plane normal must be non-zero and finite");
      }
      shape.plane_normal = normal / length;
      shape.plane_offset = size[3] / length;
      shape.geometry = std::make_shared<coal::Halfspace>(shape.plane_normal,
                                                         shape.plane_offset);
      shape.is_static = true;
      shape.radius = kInf;
      shape.half = Vec3::Constant(kInf);
      shape.thickness = kInf;
      return shape;
    }
    case ShapeKind::triangle: {
      const std::string problem = triangle_problem(points);
      if (!problem.empty()) throw std::invalid_argument("triangle: " + problem);
      if (!is_static) throw std::invalid_argument("triangle: only a static body has them");
      for (std::size_t k = 0; k < 9; k += 3)
        shape.vertices.emplace_back(points[k], points[k + 1], points[k + 2]);
      shape.geometry = std::make_shared<MeshTriangle>(shape.vertices[0], shape.vertices[1],
                                                      shape.vertices[2]);
      shape.geometry->computeLocalAABB();
      shape.local_lo = shape.geometry->aabb_local.min_;
      shape.local_hi = shape.geometry->aabb_local.max_;
      shape.half = 0.5 * (shape.local_hi - shape.local_lo);
      shape.thickness = kInf;
      return shape;
    }
    case ShapeKind::convex:
      shape.geometry = convex_hull(points);
      for (std::size_t k = 0; k + 2 < points.size(); k += 3)
        shape.vertices.emplace_back(points[k], points[k + 1], points[k + 2]);
      break;
    default:
      throw std::invalid_argument("unknown shape code");
  }
  shape.geometry->computeLocalAABB();
  shape.local_lo = shape.geometry->aabb_local.min_ + shape.offset;
  shape.local_hi = shape.geometry->aabb_local.max_ + shape.offset;
  shape.half = 0.5 * (shape.local_hi - shape.local_lo);
  shape.thickness = shape.half.minCoeff();
  return shape;
}

void mark_active_edges(std::vector<BodyShape>& shapes) {
  using Corner = std::array<double, 3>;
  // an edge by its two corners (in increasing order) -> (shape, edge) of its triangles
  std::map<std::pair<Corner, Corner>, std::vector<std::pair<std::size_t, int>>> edges;
  auto flush = [&shapes, &edges]() {
    for (const auto& [key, sides] : edges) {
      if (sides.size() != 2) continue;   // a boundary, or more than two triangles: active
      for (int k = 0; k < 2; ++k) {
        const auto [index, edge] = sides[k];
        const auto [other, other_edge] = sides[1 - k];
        const std::vector<Vec3>& mine = shapes[index].vertices;
        const Vec3& far = shapes[other].vertices[(other_edge + 2) % 3];
        const Vec3 normal = (mine[1] - mine[0]).cross(mine[2] - mine[0]).normalized();
        const Vec3 to_far = far - mine[edge];
        const bool convex = normal.dot(to_far) < -kCreaseSine * to_far.norm();
        auto* triangle = static_cast<MeshTriangle*>(shapes[index].geometry.get());
        triangle->active[edge] = convex;
      }
    }
    edges.clear();
  };
  for (std::size_t k = 0; k < shapes.size(); ++k) {
    if (k > 0 && shapes[k].body != shapes[k - 1].body) flush();
    if (shapes[k].kind != ShapeKind::triangle) continue;
    const std::vector<Vec3>& v = shapes[k].vertices;
    for (int edge = 0; edge < 3; ++edge) {
      Corner p{v[edge].x(), v[edge].y(), v[edge].z()};
      Corner q{v[(edge + 1) % 3].x(), v[(edge + 1) % 3].y(), v[(edge + 1) % 3].z()};
      if (q < p) std::swap(p, q);
      edges[{p, q}].emplace_back(k, edge);
    }
  }
  flush();
}

void place_piece(BodyShape& shape, int body, int piece, const Vec3& position,
                 const Quat& orientation) {
  if (shape.kind == ShapeKind::plane) {
    throw std::invalid_argument("a plane cannot be a piece of a compound body");
  }
  shape.body = body;
  shape.piece = piece;
  shape.frame_position = position;
  shape.rotation = orientation.normalized().toRotationMatrix();
  shape.offset = position + shape.rotation * shape.offset;
  const Vec3 lo = shape.geometry->aabb_local.min_, hi = shape.geometry->aabb_local.max_;
  const Vec3 centre = shape.offset + shape.rotation * (0.5 * (lo + hi));
  const Vec3 reach = shape.rotation.cwiseAbs() * (0.5 * (hi - lo));
  shape.local_lo = centre - reach;
  shape.local_hi = centre + reach;
}

std::array<double, 2> pin_box_support() {
  const coal::Box unit(2.0, 2.0, 2.0);   // half sides 1
  const coal::Vec3s down(-1.0, -1.0, -1.0);
  coal::details::ShapeSupportData data;
  coal::Vec3s no_sweep, with_sweep;
  int hint = 0;
  coal::details::getShapeSupport<coal::details::NoSweptSphere>(&unit, down, no_sweep, hint, data);
  coal::details::getShapeSupport<coal::details::WithSweptSphere>(&unit, down, with_sweep, hint,
                                                                 data);
  return {-no_sweep.minCoeff(), -with_sweep.minCoeff()};
}

}  // namespace collres
