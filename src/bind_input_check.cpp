// Input check binding: the usual step's test of a step's input rows and of detection's
// contacts (input_check.h).
//
// The rows may be a strided view (float_rows gathers it); the answer is a new C-contiguous
// (count, 13) float64 array, or None. The contacts' arrays are taken as they are: any that
// is not C-contiguous float64 of its shape answers None (the caller's numpy check takes
// it). The GIL is kept: a step's rows take a microsecond or two, less than releasing and
// taking it back.
#include <pybind11/numpy.h>

#include <string>
#include <vector>

#include "bindings.h"
#include "input_check.h"

namespace py = pybind11;
using namespace collres;

void bind_input_check(py::module_& m) {
  m.def(
      "usual_inputs",
      [](const py::array& values, const py::array& limits, double tolerance) -> py::object {
        const auto count = values.ndim() == 2 ? values.shape(0) : -1;
        RowScratch scratch, limit_scratch;
        const double* in = float_rows(values, count, kInputWidth, "values", scratch);
        const double* limit = float_rows(limits, 1, kInputWidth, "limits", limit_scratch);
        py::array_t<double> out({count, static_cast<py::ssize_t>(kInputWidth)});
        if (!usual_inputs(in, static_cast<std::size_t>(count), limit, tolerance,
                          out.mutable_data()))
          return py::none();
        return std::move(out);
      },
      py::arg("values"), py::arg("limits"), py::arg("tolerance"),
      "The usual step's input rows (K, 13) float64 (position m, orientation x, y, z, w, "
      "linear m/s, angular rad/s) with unit quaternions, when every number is within its "
      "limit (limits (1, 13): magnitudes; NaN is not within) and every quaternion's norm "
      "within tolerance of 1; None when one is not (the per-reason checks say which).");
  m.def(
      "usual_contacts",
      [](const py::array& point, const py::array& normal, const py::array& separation,
         const py::array& toi) -> py::object {
        const py::ssize_t count = separation.ndim() == 1 ? separation.shape(0) : -1;
        auto fits = [count](const py::array& a, py::ssize_t width) {
          return a.dtype().is(py::dtype::of<double>()) && (a.flags() & py::array::c_style) &&
                 a.ndim() == (width > 0 ? 2 : 1) && a.shape(0) == count &&
                 (width == 0 || a.shape(1) == width);
        };
        if (!(fits(point, 3) && fits(normal, 3) && fits(separation, 0) && fits(toi, 0)))
          return py::none();
        py::array_t<double> unit({count, static_cast<py::ssize_t>(3)});
        if (!usual_contacts(static_cast<const double*>(point.data()),
                            static_cast<const double*>(normal.data()),
                            static_cast<const double*>(separation.data()),
                            static_cast<const double*>(toi.data()),
                            static_cast<std::size_t>(count), unit.mutable_data()))
          return py::none();
        return std::move(unit);
      },
      py::arg("point"), py::arg("normal"), py::arg("separation"), py::arg("toi"),
      "The usual step's unit contact normals (M, 3) float64: each normal (M, 3) divided by "
      "its length, when every number of point (M, 3) m, normal, separation (M,) m and toi "
      "(M,) is finite and every normal's length exceeds 0.5; None when one is not, or when "
      "an array is not C-contiguous float64 of its shape (the caller checks row by row).");
}
