// The ray aiming's maps and their adjoint by a taped trace (trace/aiming_adjoint.h).
//
// The tape: every operation of the kernel on the scalar `Var` (a value and its place on the
// tape) appends a node with its parents and partial derivatives; the reverse sweep then
// propagates adjoints from the last node to the first, a_parent += (d node / d parent) a_node.
// Values, partials and adjoints are duals in the aimed ray's pupil coordinate,
// ceres::Jet<double, 1> (see the header for why the dual part of the input adjoints is the
// gradient). A value is computed by the same Jet operation as in prepare_system's
// Jet<Jet<double, N>, 1>, whose scalar parts follow the same arithmetic: the same bits.
#include "lensopt/trace/aiming_adjoint.h"

#include <ceres/jet.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

namespace lensopt {
namespace {
namespace aiming_tape {

using Dual = ceres::Jet<double, 1>;

struct Node {
  int a = -1, b = -1;  // parents (-1: none; an input has none)
  Dual da, db;         // d node / d parent
};

struct Tape {
  std::vector<Node> nodes;
};

thread_local Tape* active = nullptr;

// A taped scalar: idx < 0 is a constant (no node).
struct Var {
  Dual val;
  int idx = -1;
  Var() : val(0.0) {}
  explicit Var(const Dual& v, int i = -1) : val(v), idx(i) {}
};

inline Var node1(const Dual& val, const Var& x, const Dual& dx) {
  if (x.idx < 0) return Var(val);
  Tape& t = *active;
  t.nodes.push_back(Node{x.idx, -1, dx, Dual(0.0)});
  return Var(val, static_cast<int>(t.nodes.size()) - 1);
}

inline Var node2(const Dual& val, const Var& x, const Dual& dx, const Var& y, const Dual& dy) {
  if (x.idx < 0) return node1(val, y, dy);
  if (y.idx < 0) return node1(val, x, dx);
  Tape& t = *active;
  t.nodes.push_back(Node{x.idx, y.idx, dx, dy});
  return Var(val, static_cast<int>(t.nodes.size()) - 1);
}

inline Var operator+(const Var& x, const Var& y) {
  return node2(x.val + y.val, x, Dual(1.0), y, Dual(1.0));
}
inline Var operator-(const Var& x, const Var& y) {
  return node2(x.val - y.val, x, Dual(1.0), y, Dual(-1.0));
}
inline Var operator*(const Var& x, const Var& y) {
  return node2(x.val * y.val, x, y.val, y, x.val);
}
// q = x / y:  dq/dx = 1 / y,  dq/dy = -q / y.
inline Var operator/(const Var& x, const Var& y) {
  const Dual q = x.val / y.val;
  const Dual inv = Dual(1.0) / y.val;
  return node2(q, x, inv, y, -q * inv);
}
inline Var operator-(const Var& x) {
  return node1(-x.val, x, Dual(-1.0));
}
inline Var& operator+=(Var& x, const Var& y) {
  return x = x + y;
}
inline Var& operator-=(Var& x, const Var& y) {
  return x = x - y;
}
inline Var& operator*=(Var& x, const Var& y) {
  return x = x * y;
}
inline Var& operator/=(Var& x, const Var& y) {
  return x = x / y;
}
// d sqrt(x) = 1 / (2 sqrt(x)), d sin = cos, d cos = -sin.
inline Var sqrt(const Var& x) {
  using std::sqrt;
  const Dual s = sqrt(x.val);
  return node1(s, x, Dual(1.0) / (Dual(2.0) * s));
}
inline Var sin(const Var& x) {
  using std::cos;
  using std::sin;
  return node1(sin(x.val), x, cos(x.val));
}
inline Var cos(const Var& x) {
  using std::cos;
  using std::sin;
  return node1(cos(x.val), x, -sin(x.val));
}
// Comparisons on the value, as Jets compare their scalar parts.
inline bool operator<(const Var& x, const Var& y) {
  return x.val.a < y.val.a;
}
inline bool operator>(const Var& x, const Var& y) {
  return x.val.a > y.val.a;
}
inline bool operator<=(const Var& x, const Var& y) {
  return x.val.a <= y.val.a;
}
inline bool operator>=(const Var& x, const Var& y) {
  return x.val.a >= y.val.a;
}
inline bool operator==(const Var& x, const Var& y) {
  return x.val.a == y.val.a;
}
inline bool operator!=(const Var& x, const Var& y) {
  return x.val.a != y.val.a;
}

// The sweep over nodes [first, size): adj (sized to the tape) holds the seeds on entry and the
// inputs' adjoints (nodes before `first`) accumulate.
void sweep(const Tape& t, std::size_t first, std::vector<Dual>& adj) {
  for (std::size_t i = t.nodes.size(); i-- > first;) {
    const Dual g = adj[i];
    if (g.a == 0.0 && g.v[0] == 0.0) continue;
    const Node& n = t.nodes[i];
    adj[n.a] += n.da * g;
    if (n.b >= 0) adj[n.b] += n.db * g;
  }
}

}  // namespace aiming_tape
}  // namespace

template <>
struct ScalarTraits<aiming_tape::Var> {
  static aiming_tape::Var make(double value) { return aiming_tape::Var(aiming_tape::Dual(value)); }
  static double value(const aiming_tape::Var& x) { return x.val.a; }
};

namespace detail {
// Two Newton steps at an asphere, as on prepare_system's Jet<Jet<double, N>, 1>.
template <>
struct JetDepth<aiming_tape::Var> {
  static constexpr int value = 2;
};
}  // namespace detail

namespace {

using aiming_tape::Dual;
using aiming_tape::Var;

// detail::trace_aiming_rays (system.h) on the tape: the upper, lower and sagittal rays of field
// h and wavelength w under `map`; out = their stop coordinates y, y, x (duals in the pupil
// coordinate).
void trace_aiming(const TraceLens<Var>& lens, int w, const TraceSystem<double>& sys, int h,
                  const Var& r, const Var& z_ep, const PupilMap<double>& map, RayBundle<Var>& rays,
                  Var out[3]) {
  rays.resize(3);
  const Var top_y(Dual(map.offset_y + map.scale_y, 0));
  const Var bottom_y(Dual(map.offset_y - map.scale_y, 0));
  const Var side_x(Dual(map.scale_x, 0));
  const Var zero = K<Var>(0.0);
  const Var x[3] = {zero, zero, r * side_x};
  const Var y[3] = {r * top_y, r * bottom_y, r * Var(Dual(map.offset_y))};
  const double theta = sys.fields_deg[h] * kPi / 180.0;
  for (int i = 0; i < 3; ++i)
    start_pupil_ray(rays, i, x[i], y[i], z_ep, sys.object_distance_mm, std::sin(theta),
                    std::cos(theta), sys.field_object_y_mm[h]);
  set_field_frame(sys, h, rays);
  trace_bundle(lens, w, lens.stop + 1, false, rays, static_cast<RayRecord<Var>*>(nullptr));
  out[0] = rays.y[0];
  out[1] = rays.y[1];
  out[2] = rays.x[2];
}

// 1 + (R_s - c) / d (sign +1) or -1 + (-R_s - c) / d (sign -1), on a Jet as prepare_system
// computes it (its scalar part: the same bits).
double aimed_edge(double sign, double r_s, double c, double d) {
  const Dual rs(r_s);
  return (K<Dual>(sign) + ((sign > 0.0 ? rs : -rs) - Dual(c)) / Dual(d)).a;
}
double half_sum(double a, double b) {
  return ((Dual(a) + Dual(b)) / K<Dual>(2.0)).a;
}
double half_difference(double a, double b) {
  return ((Dual(a) - Dual(b)) / K<Dual>(2.0)).a;
}

// The seeds of one aimed edge e = sign + (sign R_s - c) / d with adjoint a_e:
// a_c = -a_e / d, a_d = -a_e (sign R_s - c) / d^2, a_Rs += sign a_e / d. The dual seed of the
// stop coordinate is a_d + e a_c (header).
void seed_edge(double sign, double r_s, double c, double d, double a_e, const Var& out,
               std::vector<Dual>& adj, double& a_rs) {
  if (a_e == 0.0 || out.idx < 0) return;
  Dual s;
  s.a = -a_e * (sign * r_s - c) / (d * d);
  s.v[0] = -a_e / d;
  adj[static_cast<std::size_t>(out.idx)] += s;
  a_rs += sign * a_e / d;
}

// prepare_system's aiming loop on the tape; with `start`, the reverse sweep of every field and
// wavelength with the seeds of the start adjoints.
AimingAdjoint aim_pass(TraceSystem<double>& sys, const SystemSetup& setup,
                       const std::vector<double>* start) {
  aiming_tape::Tape tape;
  struct Activate {  // the tape of this thread while the pass runs
    aiming_tape::Tape* previous;
    explicit Activate(aiming_tape::Tape* t) : previous(aiming_tape::active) {
      aiming_tape::active = t;
    }
    ~Activate() { aiming_tape::active = previous; }
  } activate(&tape);
  auto input = [&](double value) {
    tape.nodes.push_back(aiming_tape::Node{});
    return Var(Dual(value), static_cast<int>(tape.nodes.size()) - 1);
  };
  auto inputs = [&](const std::vector<double>& values) {
    std::vector<Var> r;
    r.reserve(values.size());
    for (double v : values) r.push_back(input(v));
    return r;
  };
  const TraceLens<double>& in = sys.lens;
  TraceLens<Var> lens;
  lens.curvature_per_mm = inputs(in.curvature_per_mm);
  lens.thickness_mm = inputs(in.thickness_mm);
  lens.nd = inputs(in.nd);
  lens.vd = inputs(in.vd);
  lens.is_glass = in.is_glass;
  lens.model_dpgf = in.model_dpgf;
  lens.profile = in.profile;
  lens.conic = inputs(in.conic);
  lens.asphere = inputs(in.asphere);
  lens.catalog_offset = in.catalog_offset;
  lens.wavelengths_nm = in.wavelengths_nm;
  lens.semi_diameter_mm = in.semi_diameter_mm;
  lens.stop = in.stop;
  lens.geometry = in.geometry.template convert<Var>([&](double v) { return input(v); });
  // R_EP = EPD / 2 as prepare_system divides (exact: a power of two).
  const Var r_ep = input(sys.epd_mm / 2.0);
  const Var z_ep = input(sys.entrance_pupil_z_mm);
  const std::size_t inputs_end = tape.nodes.size();

  AimingAdjoint out;
  std::vector<Dual> adj(inputs_end, Dual(0.0));
  const int field_count = static_cast<int>(sys.fields_deg.size());
  const int spec_w = sys.wavelength_count;
  const int wl = spec_w + 1;
  const PupilMap<double> identity{1.0, 0.0, 1.0};
  sys.pupil_maps.assign(static_cast<std::size_t>(field_count) * wl, identity);
  const double r_s = sys.stop_radius_mm;
  const double r = sys.epd_mm / 2.0;
  // The three rays of (h, w) under `map`: their stop coordinates c and derivatives d, on the
  // tape (out) when there is a backward pass, else as prepare_system on Jet<double, 1> traces
  // them, on Jet<Jet<double, 1>, 1> (the same values, two Newton steps at an asphere as on the
  // tape, without the tape's cost).
  RayBundle<Var> rays;
  using J = ceres::Jet<Dual, 1>;
  RayBundle<J> plain_rays;
  const TraceLens<J> lens_a =
      start ? TraceLens<J>{}
            : convert_trace_lens<J>(
                  convert_trace_lens<Dual>(in, {}, 0, 0, [](double v, int) { return K<Dual>(v); }),
                  {}, 0, 0, [](double v, int) { return K<J>(v); });
  const Dual r_dual(r), z_dual(sys.entrance_pupil_z_mm);
  auto trace = [&](int h, int w, const PupilMap<double>& map, Var out[3], double c[3],
                   double d[3]) {
    if (!start) {
      const PupilMap<Dual> map_dual{Dual(map.scale_x), Dual(map.offset_y), Dual(map.scale_y)};
      Dual cd[3], dd[3];
      detail::trace_aiming_rays<Dual>(lens_a, w, sys, h, r_dual, z_dual, map_dual, cd, dd,
                                      &plain_rays);
      for (int i = 0; i < 3; ++i) {
        c[i] = cd[i].a;
        d[i] = dd[i].a;
      }
      return;
    }
    trace_aiming(lens, w, sys, h, r_ep, z_ep, map, rays, out);
    for (int i = 0; i < 3; ++i) {
      c[i] = out[i].val.a;
      d[i] = out[i].val.v[0];
    }
  };
  Var stop[3], stop_minus[3];
  for (int h = 0; h < field_count; ++h) {
    const bool axial =
        sys.fields_deg[h] == 0.0 && setup.aperture_type != ApertureType::kFloatByStop;
    if (axial && !sys.lens.geometry.placed()) continue;
    for (int w = axial ? wl - 1 : 0; w < wl; ++w) {
      tape.nodes.resize(inputs_end);
      double c[3], d[3];
      trace(h, w, identity, stop, c, d);
      const double top = aimed_edge(1.0, r_s, c[0], d[0]);
      const double bottom = aimed_edge(-1.0, r_s, c[1], d[1]);
      const double side = aimed_edge(1.0, r_s, c[2], d[2]);
      PupilMap<double>& map = sys.pupil_maps[static_cast<std::size_t>(h) * wl + w];
      map.scale_x = side;
      map.offset_y = half_sum(top, bottom);
      map.scale_y = half_difference(top, bottom);
      double c_minus = 0.0, d_minus = 0.0;
      if (axial) {
        const PupilMap<double> mirrored{-1.0, 0.0, 1.0};
        double cm[3], dm[3];
        trace(h, w, mirrored, stop_minus, cm, dm);
        c_minus = cm[2];
        d_minus = dm[2];
        map.scale_x = half_difference(side, aimed_edge(-1.0, r_s, c_minus, d_minus));
        for (int v = 0; v + 1 < wl; ++v) sys.pupil_maps[static_cast<std::size_t>(h) * wl + v] = map;
      }
      if (!start) continue;
      // A = a R_EP of the map entries (s_x, o_y, s_y), summed over the wavelengths that take
      // this map (the spec wavelengths; the reference one has no start adjoint).
      double a_sx = 0.0, a_oy = 0.0, a_sy = 0.0;
      for (int v = axial ? 0 : w; v < (axial ? spec_w : w + 1); ++v) {
        if (v >= spec_w) continue;
        const double* a = &(*start)[(static_cast<std::size_t>(h) * spec_w + v) * 4];
        a_sx += a[0] * r;
        a_oy += a[1] * r;
        a_sy += a[2] * r;
      }
      if (a_sx == 0.0 && a_oy == 0.0 && a_sy == 0.0) continue;
      // The inputs' adjoints (before inputs_end) accumulate over fields and wavelengths.
      adj.resize(tape.nodes.size());
      std::fill(adj.begin() + static_cast<std::ptrdiff_t>(inputs_end), adj.end(), Dual(0.0));
      seed_edge(1.0, r_s, c[0], d[0], 0.5 * (a_oy + a_sy), stop[0], adj, out.stop_radius);
      seed_edge(-1.0, r_s, c[1], d[1], 0.5 * (a_oy - a_sy), stop[1], adj, out.stop_radius);
      if (axial) {
        seed_edge(1.0, r_s, c[2], d[2], 0.5 * a_sx, stop[2], adj, out.stop_radius);
        seed_edge(-1.0, r_s, c_minus, d_minus, -0.5 * a_sx, stop_minus[2], adj, out.stop_radius);
      } else {
        seed_edge(1.0, r_s, c[2], d[2], a_sx, stop[2], adj, out.stop_radius);
      }
      aiming_tape::sweep(tape, inputs_end, adj);
    }
  }
  auto gradient = [&](const std::vector<Var>& vars) {
    std::vector<double> g(vars.size(), 0.0);
    for (std::size_t i = 0; i < vars.size(); ++i)
      g[i] = adj[static_cast<std::size_t>(vars[i].idx)].v[0];
    return g;
  };
  out.curvature = gradient(lens.curvature_per_mm);
  out.thickness = gradient(lens.thickness_mm);
  out.nd = gradient(lens.nd);
  out.vd = gradient(lens.vd);
  out.conic = gradient(lens.conic);
  out.asphere = gradient(lens.asphere);
  out.placement = gradient(lens.geometry.placement);
  out.entrance_pupil_radius = adj[static_cast<std::size_t>(r_ep.idx)].v[0];
  out.entrance_pupil_z = adj[static_cast<std::size_t>(z_ep.idx)].v[0];
  return out;
}

}  // namespace

void aim_pupil_maps(TraceSystem<double>& sys, const SystemSetup& setup) {
  aim_pass(sys, setup, nullptr);
}

AimingAdjoint aim_pupil_maps_adjoint(TraceSystem<double>& sys, const SystemSetup& setup,
                                     const std::vector<double>& start) {
  return aim_pass(sys, setup, &start);
}

}  // namespace lensopt
