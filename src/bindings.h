// The Python bindings of collres_ros/core/_native, one function per half of the core.
//
// Bindings only bind: every function they expose is implemented in the stage sources
// (contact_solver, step, broad_phase, manifold, time_of_impact, islands). Arrays cross as numpy
// arrays without copies (C-contiguous float64 / int64, checked, never converted), and
// the GIL is released while C++ works on them. Body states may also come as strided views
// (the resolver's (N, 13) rows, column blocks of them): ``float_rows`` gathers those.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstring>
#include <memory>
#include <string>
#include <vector>

// Room for one gathered copy (float_rows): left uninitialised, as the gather writes every
// number (a zero-filled vector cost a pass over it each call).
using RowScratch = std::unique_ptr<double[]>;

// Copies `count` rows of `width` float64 numbers between a strided array (`base`, byte
// strides `row` and `column`) and packed rows `packed` (count x width): into `packed`, or
// back into the array when `scatter`. Widths 3 and 4 (the states' blocks) have their own
// loops, each row's numbers a fixed count the compiler unrolls (the same numbers copied; a
// step of a settled pile of 100 bodies, whose solver, detection and hold-back calls gather
// 9,100 numbers and scatter 1,300: 0.03 M fewer instructions than a loop over a run-time
// width, 0.4 % of the step).
template <int W, bool scatter>
inline void copy_fixed_rows(char* base, pybind11::ssize_t row, pybind11::ssize_t column,
                            pybind11::ssize_t count, double* packed) {
  for (pybind11::ssize_t i = 0; i < count; ++i) {
    char* const at = base + i * row;
    for (int j = 0; j < W; ++j) {
      if (scatter) std::memcpy(at + j * column, packed + i * W + j, sizeof(double));
      else std::memcpy(packed + i * W + j, at + j * column, sizeof(double));
    }
  }
}

template <bool scatter>
inline void copy_rows(char* base, pybind11::ssize_t row, pybind11::ssize_t column,
                      pybind11::ssize_t count, pybind11::ssize_t width, double* packed) {
  if (width == 3) return copy_fixed_rows<3, scatter>(base, row, column, count, packed);
  if (width == 4) return copy_fixed_rows<4, scatter>(base, row, column, count, packed);
  for (pybind11::ssize_t i = 0; i < count; ++i) {   // number by number (any other width)
    char* const at = base + i * row;
    for (pybind11::ssize_t j = 0; j < width; ++j) {
      if (scatter) std::memcpy(at + j * column, packed + i * width + j, sizeof(double));
      else std::memcpy(packed + i * width + j, at + j * column, sizeof(double));
    }
  }
}

// The numbers of `array`, a float64 (count, width) array, row by row: its own data when it is
// C-contiguous, else (a strided view, e.g. columns 0-2 of the resolver's (N, 13) state rows)
// a copy gathered into `scratch` (write one back with `scatter_rows`). A TypeError /
// ValueError names `name` when its dtype, shape or (`out`) writability does not fit.
inline double* float_rows(const pybind11::array& array, pybind11::ssize_t count,
                          pybind11::ssize_t width, const char* name,
                          RowScratch& scratch, bool out = false) {
  namespace py = pybind11;
  if (!array.dtype().is(py::dtype::of<double>()))
    throw py::type_error(std::string(name) + ": wrong dtype " +
                         py::str(array.dtype()).cast<std::string>() + ", float64 expected");
  if (array.ndim() != 2 || array.shape(0) != count || array.shape(1) != width)
    throw py::value_error(std::string(name) + ": expected shape (" + std::to_string(count) +
                          ", " + std::to_string(width) + ")");
  if (out && !array.writeable()) throw py::value_error(std::string(name) + ": read-only");
  if (array.flags() & py::array::c_style)
    return static_cast<double*>(const_cast<void*>(array.data()));
  scratch.reset(new double[static_cast<size_t>(count * width)]);
  double* const to = scratch.get();
  copy_rows<false>(static_cast<char*>(const_cast<void*>(array.data())), array.strides(0),
                   array.strides(1), count, width, to);
  return to;
}

// Writes `data` (a float_rows copy of `array`) back into `array`; nothing when `data` is
// the array's own.
inline void scatter_rows(const pybind11::array& array, const double* data) {
  char* base = static_cast<char*>(const_cast<void*>(array.data()));
  if (data == reinterpret_cast<const double*>(base)) return;
  copy_rows<true>(base, array.strides(0), array.strides(1), array.shape(0), array.shape(1),
                  const_cast<double*>(data));
}

// The solver half: combine rules, the contact cache and the solver step (bind_solver.cpp).
void bind_solver(pybind11::module_& m);

// The detection half: broad phase, narrow phase, manifolds, time of impact
// (bind_detection.cpp).
void bind_detection(pybind11::module_& m);

// Islands and sleep timers (bind_islands.cpp).
void bind_islands(pybind11::module_& m);

// The usual step's input check (bind_input_check.cpp).
void bind_input_check(pybind11::module_& m);
