#include "shapes.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <coal/shape/geometric_shapes.h>

namespace collres {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

std::shared_ptr<coal::CollisionGeometry> convex_hull(const std::vector<double>& points) {
  auto vertices = std::make_shared<std::vector<coal::Vec3s>>();
  for (std::size_t k = 0; k + 2 < points.size(); k += 3) {
    vertices->emplace_back(points[k], points[k + 1], points[k + 2]);
  }
  if (vertices->size() < 4) throw std::invalid_argument("convex needs at least 4 points");
  const auto count = static_cast<unsigned int>(vertices->size());
  return std::shared_ptr<coal::CollisionGeometry>(
      coal::ConvexBase::convexHull(vertices, count, true, "Qt"));
}

}  // namespace

BodyShape make_shape(int kind, const std::vector<double>& size,
                     const std::vector<double>& points, double radius, bool is_static) {
  BodyShape shape;
  shape.kind = static_cast<ShapeKind>(kind);
  shape.radius = radius;
  shape.is_static = is_static;
  auto need = [&size](std::size_t count) {
    if (size.size() < count) throw std::invalid_argument("shape size has too few values");
  };
  switch (shape.kind) {
    case ShapeKind::sphere:
      need(1);
      shape.geometry = std::make_shared<coal::Sphere>(size[0]);
      shape.curved = shape.single_point = true;
      break;
    case ShapeKind::box:
      need(3);
      shape.geometry = std::make_shared<coal::Box>(size[0], size[1], size[2]);
      break;
    case ShapeKind::capsule:
      need(2);
      shape.geometry = std::make_shared<coal::Capsule>(size[0], size[1]);
      shape.curved = true;
      break;
    case ShapeKind::cylinder:
      need(2);
      shape.geometry = std::make_shared<coal::Cylinder>(size[0], size[1]);
      shape.curved = true;
      break;
    case ShapeKind::cone:
      need(2);
      shape.geometry = std::make_shared<coal::Cone>(size[0], size[1]);
      shape.offset = Vec3(0.0, 0.0, 0.25 * size[1]);
      shape.curved = true;
      break;
    case ShapeKind::plane: {
      need(4);
      const Vec3 normal(size[0], size[1], size[2]);
      const double length = normal.norm();
      if (!(length > 0.0) || !std::isfinite(length)) {
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
    case ShapeKind::convex:
      shape.geometry = convex_hull(points);
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

}  // namespace collres
