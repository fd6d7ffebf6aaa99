// Solver bindings: combine rules (the solver step follows).
#include <pybind11/numpy.h>

#include "bindings.h"
#include "contact_solver.h"

namespace py = pybind11;

void bind_solver(py::module_& m) {
  py::enum_<collres::CombineRule>(m, "CombineRule")
      .value("average", collres::CombineRule::kAverage)
      .value("min", collres::CombineRule::kMin)
      .value("max", collres::CombineRule::kMax)
      .value("multiply", collres::CombineRule::kMultiply)
      .value("geometric", collres::CombineRule::kGeometric);
  m.def("combine", py::vectorize(&collres::combine), py::arg("a"), py::arg("b"),
        py::arg("rule"), "One coefficient per contact from the two bodies' (numpy arrays).");
}
