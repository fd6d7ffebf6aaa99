// Collision shapes of the detection half: coal geometries built from plain numbers.
//
// Frames and units: the body frame is the shape frame and its origin is the centre of mass
// (m). Every coal geometry is centred on its own origin, which sits at `offset` in the body
// frame (non-zero only for cones: coal centres a cone on the middle of its axis, our cone's
// origin is its centre of mass, a quarter of the length above the base). Planes are coal
// half-spaces n.x <= d (body frame, n unit); they are never put in a tree (their bounds
// are infinite) and are tested against every finite body directly.
#pragma once

#include <memory>
#include <vector>

#include <coal/collision_object.h>

#include "detection_types.h"

namespace collres {

// Shape codes: the index of the shape name in collres_ros.core.types.SHAPE_KINDS.
enum class ShapeKind : int { sphere = 0, box = 1, capsule = 2, cylinder = 3, cone = 4,
                             plane = 5, convex = 6 };

struct BodyShape {
  ShapeKind kind = ShapeKind::sphere;
  std::shared_ptr<coal::CollisionGeometry> geometry;
  Vec3 offset = Vec3::Zero();      // m, geometry origin in the body frame
  Vec3 local_lo = Vec3::Zero();    // m, body-frame box of the shape (offset included)
  Vec3 local_hi = Vec3::Zero();
  Vec3 half = Vec3::Zero();        // m, half extents of that box (+inf for planes)
  double radius = 0.0;             // m, origin-centred bounding sphere (+inf for planes)
  double thickness = 0.0;          // m, smallest half extent (+inf for planes)
  Vec3 plane_normal = Vec3::UnitZ();  // planes: unit normal, body frame
  double plane_offset = 0.0;          // planes: d (m), the solid is n.x <= d
  bool is_static = false;          // static or a plane: never moved by the solver
  bool curved = false;             // a curved surface (sphere, capsule, cylinder, cone):
                                   // its contact points slide over it as it rolls
  bool single_point = false;       // touches at one point only (sphere)
};

// A shape from its code, sizes (sphere [r]; box [x, y, z] full edges; capsule, cylinder,
// cone [r, length] along z; plane [nx, ny, nz, d]) and, for convex, its vertices (K x 3,
// row-major, body frame). `radius` is the bounding radius about the body origin (m), as
// collres_ros.core.shapes.bounding_radius gives it. Sizes are validated by the caller.
BodyShape make_shape(int kind, const std::vector<double>& size,
                     const std::vector<double>& points, double radius, bool is_static);

}  // namespace collres
