// Detection bindings: a placeholder until the compiled detection lands.
#include <coal/config.hh>
#include <coal/shape/geometric_shapes.h>

#include "bindings.h"

void bind_detection(pybind11::module_& m) {
  m.attr("coal_version") = COAL_VERSION;
  m.def("coal_sphere_aabb_size", [](double radius) {
    coal::Sphere sphere(radius);        // calls into libcoal: proves the link at import time
    sphere.computeLocalAABB();
    return sphere.aabb_local.width();
  }, pybind11::arg("radius"), "Edge (m) of coal's local AABB of a sphere (a link check).");
}
