// Fuzz target of the compiled core's input side: shapes from hostile numbers, then one
// detection step of the shapes that were accepted, from hostile poses.
//
// Property: every input either builds or gives std::invalid_argument; nothing crashes,
// and under AddressSanitizer / UndefinedBehaviorSanitizer (make sanitize) nothing reads or
// writes out of bounds or overflows. A case is a byte string read as doubles and small
// integers (fuzz_one); `collres_fuzz_core CASES SEED` runs CASES generated cases from the
// fixed SEED, weighted towards the sets qhull cannot build (flat, coplanar, collinear,
// duplicate and 3-point vertex sets, at many scales and offsets); `collres_fuzz_core FILE...`
// runs the given byte files (a regression corpus); FUZZ_KEEP=FILE writes each generated case
// there before it runs (the one a crash stops at stays). Exit 0 when every case held.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "detection.h"
#include "shapes.h"

namespace {

// Reads a case's bytes in order; past the end every value is 0.
class Bytes {
 public:
  Bytes(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}
  std::uint8_t byte() { return at_ < size_ ? data_[at_++] : 0; }
  double real() {
    std::uint64_t bits = 0;
    for (int k = 0; k < 8; ++k) bits |= static_cast<std::uint64_t>(byte()) << (8 * k);
    double value;
    std::memcpy(&value, &bits, sizeof value);
    return value;
  }
  bool done() const { return at_ >= size_; }

 private:
  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t at_ = 0;
};

int fuzz_one(const std::uint8_t* data, std::size_t size) {
  Bytes in(data, size);
  const int bodies = 1 + in.byte() % 6;
  std::vector<collres::BodyShape> shapes;
  std::vector<bool> mesh;
  for (int b = 0; b < bodies && !in.done(); ++b) {
    const int kind = static_cast<int>(in.byte() % 10) - 1;   // -1 and 8: unknown codes
    std::vector<double> size_values(in.byte() % 6);
    for (double& v : size_values) v = in.real();
    std::vector<double> points(in.byte() % 64);
    for (double& v : points) v = in.real();
    const double radius = in.real();
    const bool fixed = in.byte() & 1;
    const bool joins = in.byte() & 1;   // a triangle after a triangle: one mesh with it
    try {
      shapes.push_back(collres::make_shape(kind, size_values, points, radius, fixed));
      mesh.push_back(joins);
    } catch (const std::invalid_argument&) {
    }
  }
  if (shapes.empty()) return 0;
  // one shape per body, but a triangle may join the triangles before it (one mesh: its
  // shared edges go inactive)
  int n = 0;
  for (std::size_t k = 0; k < shapes.size(); ++k) {
    const bool joins = k > 0 && mesh[k] && shapes[k].kind == collres::ShapeKind::triangle &&
                       shapes[k - 1].kind == collres::ShapeKind::triangle;
    if (joins) {
      shapes[k].body = shapes[k - 1].body;
      shapes[k].piece = shapes[k - 1].piece + 1;
    } else {
      shapes[k].body = n++;
    }
  }
  collres::Detector detector(std::move(shapes), n);
  std::vector<double> p0(3 * n), q0(4 * n), p1(3 * n), q1(4 * n), linear(3 * n), angular(3 * n);
  for (auto* array : {&p0, &q0, &p1, &q1, &linear, &angular}) {
    for (double& v : *array) v = in.real();
  }
  collres::StepPoses poses;
  poses.count = n;
  poses.p0 = p0.data();
  poses.q0 = q0.data();
  poses.p1 = p1.data();
  poses.q1 = q1.data();
  poses.linear = linear.data();
  poses.angular = angular.data();
  collres::ContactRows rows;
  try {
    detector.detect(poses, rows);
  } catch (const std::invalid_argument&) {
  }
  return 0;
}

// Generated cases: bytes that decode (fuzz_one) to shapes of every kind, mostly convex
// vertex sets near the edge of what a hull can be built of, and poses near one another.
class Writer {
 public:
  void byte(int v) { out.push_back(static_cast<std::uint8_t>(v)); }
  void real(double v) {
    std::uint64_t bits;
    std::memcpy(&bits, &v, sizeof v);
    for (int k = 0; k < 8; ++k) out.push_back(static_cast<std::uint8_t>(bits >> (8 * k)));
  }
  std::vector<std::uint8_t> out;
};

std::vector<std::uint8_t> generate(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  auto pick = [&rng](int count) { return static_cast<int>(rng() % count); };
  auto hostile = [&]() {
    const double specials[] = {std::numeric_limits<double>::quiet_NaN(),
                               std::numeric_limits<double>::infinity(), -1.0, 0.0, 1e-300,
                               1e300, -0.0, 5e-324, 1e9, 1e10};
    return pick(8) == 0 ? specials[pick(10)] : std::pow(10.0, 6.0 * unit(rng) - 3.0);
  };
  Writer w;
  const int bodies = 1 + pick(6);
  w.byte(bodies - 1);
  for (int b = 0; b < bodies; ++b) {
    const int kind = pick(3) ? 6 : pick(10) - 1;   // 7: a triangle (static), often
    w.byte(kind + 1);
    const int sizes = pick(6);
    w.byte(sizes);
    for (int k = 0; k < sizes; ++k) w.real(pick(3) ? 0.05 + unit(rng) : hostile());
    // a vertex set: a random flat polygon lifted by an apex 10^-12 .. 10^0 of its extent,
    // or collinear, or all one point, or too few, rotated, scaled and offset
    const int count = kind == 7 && pick(2) ? 3 : 3 + pick(18);
    const int family = pick(5);
    const double lift = std::pow(10.0, -12.0 * unit(rng));
    const double scale = std::pow(10.0, 8.0 * unit(rng) - 5.0);
    const double offset = pick(2) ? scale * 100.0 * (unit(rng) - 0.5) : 0.0;
    const Eigen::Quaterniond turn = Eigen::Quaterniond::UnitRandom();
    w.byte(3 * count);
    for (int k = 0; k < count; ++k) {
      collres::Vec3 p(unit(rng), unit(rng), 0.0);
      if (family == 0 && k == count - 1) p.z() = lift;          // nearly flat
      if (family == 1) p = collres::Vec3(unit(rng), 0.0, 0.0);  // collinear
      if (family == 2) p = collres::Vec3(0.3, 0.3, 0.3);        // duplicates
      if (family == 3) p.z() = unit(rng);                       // a real volume
      p = turn * p * scale + collres::Vec3::Constant(offset);
      for (int c = 0; c < 3; ++c) w.real(pick(200) ? p[c] : hostile());
    }
    w.real(pick(4) ? 2.0 * scale + std::abs(offset) * 2.0 : hostile());
    w.byte(pick(2));
    w.byte(pick(2));   // a triangle joins the one before
  }
  for (int k = 0; k < 20 * bodies; ++k) {
    w.real(pick(30) ? 0.2 * (unit(rng) - 0.5) + (k % 7 == 3 ? 0.7 : 0.0) : hostile());
  }
  return w.out;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc >= 2 && std::strspn(argv[1], "0123456789") == std::strlen(argv[1])) {
    const long cases = std::atol(argv[1]);
    const unsigned long seed = argc >= 3 ? std::strtoul(argv[2], nullptr, 10) : 1;
    std::mt19937_64 rng(seed);
    const char* keep = std::getenv("FUZZ_KEEP");   // each case written there first: the
    for (long k = 0; k < cases; ++k) {              // one that kills the process stays
      const std::vector<std::uint8_t> bytes = generate(rng);
      if (keep != nullptr) {
        std::ofstream(keep, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()),
                                                    static_cast<std::streamsize>(bytes.size()));
      }
      fuzz_one(bytes.data(), bytes.size());
    }
    std::printf("collres_fuzz_core: %ld generated cases (seed %lu) held\n", cases, seed);
    return 0;
  }
  for (int k = 1; k < argc; ++k) {
    std::ifstream file(argv[k], std::ios::binary);
    const std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(file)),
                                          std::istreambuf_iterator<char>());
    fuzz_one(bytes.data(), bytes.size());
  }
  std::printf("collres_fuzz_core: %d files held\n", argc - 1);
  return 0;
}
