// Input check binding: the usual step's test of a step's input rows (input_check.h).
//
// The rows may be a strided view (float_rows gathers it); the answer is a new C-contiguous
// (count, 13) float64 array, or None. The GIL is kept: a step's rows take a microsecond or
// two, less than releasing and taking it back.
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
}
