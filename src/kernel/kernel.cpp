// SPDX-License-Identifier: Apache-2.0
//
// qpretarget._kernel: the compiled hot path of one velocity-level tick (issue 17).
//
// What each Python module computes per tick runs here, in one call and with no Python loop:
//   * tasks (qpretarget/tasks/frame.py, com.py, posture.py): error e, Jacobian J and reference
//     velocity v* = K e (Dariush 2009 eq. 9, CRAC eq. 15), written into the controller's stacked
//     buffers; the orientation error is Dariush 2009 eq. 11 (CRAC eq. 12);
//   * box bounds (constraints/joint_limits.py): gamma (q_min - q) / dt <= v <= gamma (q_max - q) / dt
//     and |v| <= v_max, merged most important first exactly as Controller._merge_bounds does;
//   * contact rows (constraints/contacts.py): J_f v = K e_f - dt/2 Jdot_f v (CRAC eq. 34-42 and
//     the second-order drift anticipation documented there);
//   * augmentation (strategies/augmentation.py, Dariush 2009 4.3.1): H = Jw' Jw + lambda^2 I,
//     g = -Jw' rw with Jw = sqrt(w) J, rw = sqrt(w) v*;
//   * the direct DAQP solve (solvers/daqp_.py): DAQP's C entry point, hot-started from the
//     previous active set, with the same inputs as the Python backend.
// The Python classes keep their configuration, validation and every rarely used path; the
// controller uses this kernel only when every module of its config has a compiled part
// (qpretarget/control/compiled.py), and the Python path otherwise.
//
// The pinocchio Model and Data are the Python objects' own (extracted through boost.python),
// so the kernel and the Python modules share one kinematics pass.

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <boost/python.hpp>

#include <pinocchio/multibody.hpp>
#include <pinocchio/algorithm/center-of-mass.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/joint-configuration.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/spatial.hpp>
#include <pinocchio/geometry.hpp>
#include <pinocchio/algorithm/geometry.hpp>
#include <pinocchio/collision/distance.hpp>

#include <dlfcn.h>

#include <chrono>
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <memory>
#include <string>
#include <vector>

namespace nb = nanobind;
namespace bp = boost::python;
using pinocchio::Data;
using pinocchio::Model;

using RowMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using MapRM = Eigen::Map<RowMat>;
using MapV = Eigen::Map<Eigen::VectorXd>;
using Mat6x = Eigen::Matrix<double, 6, Eigen::Dynamic>;
using Arr = nb::ndarray<double, nb::c_contig, nb::device::cpu>;
using CArr = nb::ndarray<const double, nb::c_contig, nb::device::cpu>;  // read-only is fine
using IArr = nb::ndarray<int64_t, nb::c_contig, nb::device::cpu>;
using BArr = nb::ndarray<bool, nb::c_contig, nb::device::cpu>;

static const double INF = std::numeric_limits<double>::infinity();

template <class T>
static T *extract_ref(nb::handle h, const char *what) {
  bp::object o{bp::handle<>(bp::borrowed(h.ptr()))};
  bp::extract<T &> ex(o);
  if (!ex.check()) throw nb::type_error((std::string("expected a ") + what).c_str());
  return &ex();
}

// A float64 C-contiguous numpy array held by Python: pointer and size.
struct Buf {
  nb::object owner;
  double *p = nullptr;
  size_t n = 0;
  Buf() = default;
  explicit Buf(Arr a) : owner(nb::find(a)), p(a.data()), n(a.size()) {}
};

// Read a float64 array attribute of a Python object (a task's current target). `keep` holds a
// reference until the next read, so the data stays valid while the tick uses it (a target that
// is not a C-contiguous float64 array is converted; the tasks store such arrays already).
static const double *attr_array(PyObject *obj, PyObject *name, size_t expect, nb::object &keep) {
  PyObject *a = PyObject_GetAttr(obj, name);
  if (!a) throw nb::python_error();
  keep = nb::steal(a);
  CArr arr;
  if (!nb::try_cast<CArr>(keep, arr)) {
    keep = nb::module_::import_("numpy").attr("ascontiguousarray")(keep, "float64");
    arr = nb::cast<CArr>(keep);
  }
  if (arr.size() != expect) throw std::runtime_error("a task target of unexpected size");
  return arr.data();
}

// ---------------------------------------------------------------- tasks
struct TaskK {
  int row = 0, dim = 0;
  int identity_col = -1;  // >= 0: the rows are [0 I] from this column on (posture)
  double gain = -1.0;  // <= 0: None (K = 1/dt)
  nb::object py;       // the Python task (targets are read from it every tick)
  nb::object keep1, keep2;  // the target arrays read this tick
  virtual ~TaskK() = default;
  // Writes e (dim) and J (dim x nv) at row `row`.
  virtual void compute(const Model &m, Data &d, const Eigen::VectorXd &q, MapRM &J, double *e) = 0;
  double k(double dt) const { return (gain <= 0 || gain * dt > 1.0) ? 1.0 / dt : gain; }
};

struct FrameTaskK : TaskK {
  int fid = 0, mode = 2;  // 0 position, 1 orientation, 2 pose
  bool has_offset = false;
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();
  PyObject *s_pos, *s_rot;
  Mat6x J6;
  FrameTaskK() {
    s_pos = PyUnicode_InternFromString("position_target");
    s_rot = PyUnicode_InternFromString("rotation_target");
  }
  void compute(const Model &m, Data &d, const Eigen::VectorXd &, MapRM &J, double *e) override {
    const auto &M = d.oMf[fid];
    const Eigen::Matrix3d &R = M.rotation();
    J6.setZero(6, m.nv);
    pinocchio::getFrameJacobian(m, d, fid, pinocchio::LOCAL_WORLD_ALIGNED, J6);
    int r = row;
    if (mode != 1) {
      Eigen::Map<const Eigen::Vector3d> pt(attr_array(py.ptr(), s_pos, 3, keep1));
      Eigen::Vector3d p = M.translation();
      if (has_offset) {
        Eigen::Vector3d ro = R * offset;
        p += ro;
        Eigen::Matrix3d S;
        S << 0, -ro[2], ro[1], ro[2], 0, -ro[0], -ro[1], ro[0], 0;
        J.block(r, 0, 3, m.nv) = J6.topRows<3>() - S * J6.bottomRows<3>();
      } else {
        J.block(r, 0, 3, m.nv) = J6.topRows<3>();
      }
      for (int i = 0; i < 3; ++i) e[i] = pt[i] - p[i];
      r += 3;
      e += 3;
    }
    if (mode != 0) {
      // rotation_target is a row-major (3, 3) numpy array
      Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> Rt(attr_array(py.ptr(), s_rot, 9, keep2));
      Eigen::Matrix3d A = Rt * R.transpose();
      e[0] = 0.5 * (A(2, 1) - A(1, 2));
      e[1] = 0.5 * (A(0, 2) - A(2, 0));
      e[2] = 0.5 * (A(1, 0) - A(0, 1));
      J.block(r, 0, 3, m.nv) = J6.bottomRows<3>();
    }
  }
};

struct ComTaskK : TaskK {
  std::vector<int> rows;
  PyObject *s_t;
  ComTaskK() { s_t = PyUnicode_InternFromString("target"); }
  void compute(const Model &m, Data &d, const Eigen::VectorXd &, MapRM &J, double *e) override {
    const auto &Jc = pinocchio::jacobianCenterOfMass(m, d, true);
    Eigen::Map<const Eigen::Vector3d> t(attr_array(py.ptr(), s_t, 3, keep1));
    const Eigen::Vector3d &c = d.com[0];
    for (size_t i = 0; i < rows.size(); ++i) {
      e[i] = t[rows[i]] - c[rows[i]];
      J.row(row + int(i)) = Jc.row(rows[i]);
    }
  }
};

struct PostureTaskK : TaskK {
  int root_nv = 0;
  PyObject *s_t;
  Eigen::VectorXd diff;
  PostureTaskK() { s_t = PyUnicode_InternFromString("q_target"); }
  void compute(const Model &m, Data &, const Eigen::VectorXd &q, MapRM &J, double *e) override {
    Eigen::Map<const Eigen::VectorXd> qt(attr_array(py.ptr(), s_t, m.nq, keep1), m.nq);
    diff.resize(m.nv);
    pinocchio::difference(m, q, qt, diff);
    for (int i = 0; i < dim; ++i) e[i] = diff[root_nv + i];
    J.block(row, 0, dim, m.nv).setZero();
    for (int i = 0; i < dim; ++i) J(row + i, root_nv + i) = 1.0;
  }
};

// ---------------------------------------------------------------- bounds
struct BoundsK {
  std::string name;
  Eigen::VectorXd lo_out, hi_out;  // the module's own box (when Python merges the box)
  bool has_out = false;
  virtual ~BoundsK() = default;
  // Writes the module's box; false: no box this tick (skipped by the merge, as a Python None).
  virtual bool compute(const Eigen::VectorXd &q, double dt, Eigen::VectorXd &lb, Eigen::VectorXd &ub) = 0;
};

struct JointLimitsK : BoundsK {
  std::vector<int> qi, vi;
  Eigen::VectorXd lo, hi;
  double gain = 0.9;
  bool compute(const Eigen::VectorXd &q, double dt, Eigen::VectorXd &lb, Eigen::VectorXd &ub) override {
    lb.setConstant(-INF);
    ub.setConstant(INF);
    double k = gain / dt;
    for (size_t j = 0; j < qi.size(); ++j) {
      double qj = q[qi[j]];
      lb[vi[j]] = k * (lo[j] - qj);
      ub[vi[j]] = k * (hi[j] - qj);
    }
    return true;
  }
};

struct ConstBoundsK : BoundsK {
  Eigen::VectorXd lo, hi;
  bool compute(const Eigen::VectorXd &, double, Eigen::VectorXd &lb, Eigen::VectorXd &ub) override {
    lb = lo;
    ub = hi;
    return true;
  }
};

// ---------------------------------------------------------------- contacts
struct ContactsK {
  int row = 0;
  std::vector<int> fids;
  double gain = -1.0;
  bool second_order = true;
  double cap_lin = 0.5, cap_ang = 2.0;
  Buf active_b, anchor_p, anchor_R, anchor_step;  // the Python constraint's arrays (in place)
  bool *active = nullptr;
  Mat6x J6;
  // The sole velocity contact i's rows ask for, before the second-order anticipation: the
  // capped drift correction plus a moving anchor's step (constraints/contacts.py,
  // Contacts._target_velocity).
  void target(size_t i, const pinocchio::SE3 &M, double k, double dt, Eigen::Vector3d &lin,
              Eigen::Vector3d &ang) const {
    const Eigen::Matrix3d &R = M.rotation();
    Eigen::Map<const Eigen::Vector3d> pa(anchor_p.p + 3 * i);
    Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> Ra(anchor_R.p + 9 * i);
    Eigen::Map<const Eigen::Matrix<double, 6, 1>> step(anchor_step.p + 6 * i);
    bool moving = !step.isZero(0.0);  // a moving anchor's step: fed forward, not capped
    lin = pa - M.translation();
    Eigen::Matrix3d Rrel = R.transpose() * Ra;
    ang = R * pinocchio::log3(Rrel);
    if (moving) {
      lin -= step.head<3>();
      ang -= step.tail<3>();
    }
    lin *= k;
    ang *= k;
    double n2 = lin.dot(lin);
    if (n2 > cap_lin * cap_lin) lin *= cap_lin / std::sqrt(n2);
    n2 = ang.dot(ang);
    if (n2 > cap_ang * cap_ang) ang *= cap_ang / std::sqrt(n2);
    if (moving) {
      lin += step.head<3>() / dt;
      ang += step.tail<3>() / dt;
    }
  }
  // The corrector step (Contacts.refine_rows): d holds the tick's kinematics, rd is scratch.
  // Shifts this block's rows in l, u (the block's own views) by the residual / dt and returns
  // true when a residual exceeds tol (linear [m]; angular [rad] times half_length).
  std::vector<Eigen::Matrix<double, 6, 1>> res;  // refine()'s residuals (sized once)
  bool refine(const Model &m, const Data &d, Data &rd, const Eigen::VectorXd &qn, double dt,
              double tol, double half_length, double *l, double *u) {
    bool any = false;
    for (size_t i = 0; i < fids.size(); ++i) any = any || active[i];
    if (!any) return false;
    pinocchio::forwardKinematics(m, rd, qn);
    double k = (gain <= 0) ? 1.0 / dt : std::min(gain, 1.0 / dt);
    double worst = 0.0;
    res.resize(fids.size());
    for (size_t i = 0; i < fids.size(); ++i) {
      if (!active[i]) continue;
      int fid = fids[i];
      const auto &M = d.oMf[fid];
      Eigen::Vector3d lin, ang;
      target(i, M, k, dt, lin, ang);
      pinocchio::updateFramePlacement(m, rd, fid);
      const auto &Mn = rd.oMf[fid];
      res[i].head<3>() = Mn.translation() - (M.translation() + lin * dt);
      Eigen::Vector3d w = ang * dt;
      Eigen::Matrix3d Rstar = pinocchio::exp3(w) * M.rotation();
      Eigen::Matrix3d Rn = Mn.rotation() * Rstar.transpose();
      res[i].tail<3>() = pinocchio::log3(Rn);
      worst = std::max(worst, res[i].head<3>().cwiseAbs().maxCoeff() / tol);
      worst = std::max(worst, res[i].tail<3>().cwiseAbs().maxCoeff() * half_length / tol);
    }
    if (worst <= 1.0) return false;
    for (size_t i = 0; i < fids.size(); ++i) {
      if (!active[i]) continue;
      int r0 = 6 * int(i);
      for (int j = 0; j < 6; ++j) {
        l[r0 + j] -= res[i][j] / dt;
        u[r0 + j] = l[r0 + j];
      }
    }
    return true;
  }
  void compute(const Model &m, Data &d, Data &vd, bool &vd_ready, const Eigen::VectorXd &q,
               const Eigen::VectorXd &v, double dt, MapRM &C, double *l, double *u) {
    double k = (gain <= 0) ? 1.0 / dt : std::min(gain, 1.0 / dt);
    bool any = false;
    for (size_t i = 0; i < fids.size(); ++i) any = any || active[i];
    bool drift = second_order && any && !v.isZero(0.0);
    if (drift && !vd_ready) {
      pinocchio::forwardKinematics(m, vd, q, v, Eigen::VectorXd::Zero(m.nv));
      vd_ready = true;
    }
    double half_dt = 0.5 * dt;
    for (size_t i = 0; i < fids.size(); ++i) {
      int r0 = row + 6 * int(i);
      if (!active[i]) {
        C.block(r0, 0, 6, m.nv).setZero();
        for (int j = 0; j < 6; ++j) {
          l[r0 + j] = -INF;
          u[r0 + j] = INF;
        }
        continue;
      }
      int fid = fids[i];
      const auto &M = d.oMf[fid];
      J6.setZero(6, m.nv);
      pinocchio::getFrameJacobian(m, d, fid, pinocchio::LOCAL_WORLD_ALIGNED, J6);
      C.block(r0, 0, 6, m.nv) = J6;
      Eigen::Vector3d lin, ang;
      target(i, M, k, dt, lin, ang);
      for (int j = 0; j < 3; ++j) {
        l[r0 + j] = lin[j];
        l[r0 + 3 + j] = ang[j];
      }
      if (drift) {
        auto acc = pinocchio::getFrameClassicalAcceleration(m, vd, fid, pinocchio::LOCAL_WORLD_ALIGNED);
        Eigen::Matrix<double, 6, 1> a = acc.toVector();
        a *= half_dt;
        for (int j = 0; j < 6; ++j) l[r0 + j] -= a[j];
      }
      for (int j = 0; j < 6; ++j) u[r0 + j] = l[r0 + j];
    }
  }
};


static double sq(double x) { return x * x; }

// ---------------------------------------------------------------- distance damper (self-collision)
// constraints/self_collision.py DistanceDamper on collision/model.py CollisionModel, per tick:
// the broad phase (temporal-coherence lower bounds d - sum_j lever_pj |dq_j|), coal's exact
// distances of the candidates (capped rows: only what the K smallest gaps need), the rows
// -dd/dq v <= max(rate (d - d_s), -recovery) (Faverjon-Tournassoud velocity damper, CRAC eq. 22-27
// distances), the trust-region box |v_j| dt <= sqrt(2 s_p eps / r_pj) with its adaptation from
// the last tick's first-order prediction, and that prediction after the step; a pair against a
// static plane of normal n bounds coordinate j by that divided by sqrt|n x a_j|, a_j its world
// rotation axis (the second-order change of a height, DistanceDamper.compute_bounds). Same operations, in
// the same order, as the Python modules; the Python object keeps its configuration and reads the
// results through this object.
struct DamperK : BoundsK {
  const Model *m = nullptr;
  Data *d = nullptr;
  pinocchio::GeometryModel *gm = nullptr;
  pinocchio::GeometryData *gd = nullptr;
  nb::object keep_gm, keep_gd;
  int P = 0, nv = 0, row = 0, n_rows = 0;
  RowMat pair_lever, support, step0;  // (P, nv), (nbodies, nv), (P, nv)
  RowMat plane;                       // (P, 3) world normal of a pair's static half-space, or 0
  std::vector<char> planar;           // pair against a plane
  double min_plane_sine = 1e-6;
  std::vector<int> ga, gb;
  Eigen::VectorXd safety;
  bool broad_phase = true, direct = true, has_nearest = false;
  int nearest = 0;
  double hysteresis = 0.0, rank_margin = 0.005, d_i = 0.1, recovery = 0.1;
  int rate_form = 0;  // 0 gain_per_tick, 1 gain, 2 xi
  double rate_value = 0.0, d_s = 0.0;
  double trust = -1.0, trust_gap = 0.0, min_scale = 1.0 / 4096;
  // state
  Buf dist;  // CollisionModel.distances (Python's array, updated in place)
  Eigen::VectorXd q_last, dq, scale, sqrt_scale, pred, thr;
  bool fresh = true, scaled = false, thr_valid = false;
  double thr_influence = std::numeric_limits<double>::quiet_NaN(), cut = INF;
  std::vector<char> flags, thr_flags;
  std::vector<int> idx, act, row_pairs, pred_pairs, last_rows, last_pairs, slot, slot_pair, slot_rows;
  RowMat wpa, wn, grad;  // witness points / normals of `act` (k, 3); row gradients (k, nv)
  Eigen::VectorXd gap_rows;
  double last_time = 0.0, update_time = 0.0;
  std::vector<int> slots_key;
  bool updated = false;

  void set_geometry(nb::handle pgm, nb::handle pgd) {
    gm = extract_ref<pinocchio::GeometryModel>(pgm, "pinocchio.GeometryModel");
    gd = extract_ref<pinocchio::GeometryData>(pgd, "pinocchio.GeometryData");
    keep_gm = nb::borrow(pgm);
    keep_gd = nb::borrow(pgd);
  }

  void reset() {
    fresh = true;
    thr_valid = false;
    scale.setOnes(P);
    sqrt_scale.setOnes(P);
    scaled = false;
    pred_pairs.clear();
    cut = INF;
    flags.assign(P, 1);
    last_rows.clear();
    last_pairs.clear();
    row_pairs.clear();
    slot.assign(P, -1);
    slot_pair.assign(n_rows, -1);
    slots_key.clear();
    slot_rows.clear();
    grad.resize(0, nv);
    gap_rows.resize(0);
  }

  double rate(double dt) const {
    if (rate_form == 0) return rate_value / dt;
    if (rate_form == 1) return rate_value;
    return rate_value / (d_i - d_s);
  }

  // coal distances of the flagged pairs (index order), into dist; witness data by pair
  RowMat wpa_all, wn_all;
  void exact(bool placed) {
    if (!placed) pinocchio::updateGeometryPlacements(*m, *d, *gm, *gd);
    for (int i : idx) {
      const coal::DistanceResult &r = pinocchio::computeDistance(*gm, *gd, size_t(i));
      dist.p[i] = r.min_distance;
      for (int k = 0; k < 3; ++k) {
        wpa_all(i, k) = r.nearest_points[0][k];
        wn_all(i, k) = r.normal[k];
      }
    }
  }
  void set_flags(const std::vector<char> &need) {
    flags = need;
    idx.clear();
    for (int i = 0; i < P; ++i)
      if (flags[i]) idx.push_back(i);
  }

  // CollisionModel.update + DistanceDamper._update
  void update(const Eigen::VectorXd &q) {
    double influence = d_i;
    double *lb = dist.p;
    bool full = fresh || !broad_phase || !std::isfinite(influence);
    bool ranked = has_nearest && !full;
    // candidates
    if (full) {
      for (int i = 0; i < P; ++i) lb[i] = -INF;
      fresh = false;
    } else {
      dq.resize(nv);
      pinocchio::difference(*m, q_last, q, dq);
      dq = dq.cwiseAbs();
      Eigen::VectorXd dec = pair_lever * dq;
      for (int i = 0; i < P; ++i) lb[i] -= dec[i];
    }
    q_last = q;
    std::vector<char> cand(P);
    if (hysteresis > 0) {
      if (!thr_valid || thr_influence != influence || thr_flags != flags) {
        thr.setConstant(P, influence);
        for (int i = 0; i < P; ++i)
          if (flags[i]) thr[i] += hysteresis;
        thr_influence = influence;
        thr_flags = flags;
        thr_valid = true;
      }
      for (int i = 0; i < P; ++i) cand[i] = lb[i] < thr[i];
    } else {
      for (int i = 0; i < P; ++i) cand[i] = lb[i] < influence;
    }
    std::vector<char> need(P);
    for (int i = 0; i < P; ++i) need[i] = ranked ? (cand[i] && (lb[i] - safety[i] < cut)) : cand[i];
    set_flags(need);
    if (!idx.empty()) exact(false);
    if (ranked) {
      int found = 0;
      bool more = false;
      for (int i : idx) found += (dist.p[i] - safety[i] < cut) && (dist.p[i] < influence);
      for (int i = 0; i < P; ++i) more = more || (cand[i] && !need[i]);
      if (found < nearest && more) {
        bool placed = !idx.empty();
        set_flags(cand);
        if (!idx.empty()) exact(placed);
      }
    }
    act.clear();
    for (int i : idx)
      if (dist.p[i] < influence) act.push_back(i);
    if (has_nearest) {
      std::vector<double> g;
      for (int i : act) g.push_back(dist.p[i] - safety[i]);
      if (int(g.size()) >= nearest) {
        std::nth_element(g.begin(), g.begin() + (nearest - 1), g.end());
        cut = g[nearest - 1] + rank_margin;
      } else {
        cut = INF;
      }
    }
    // the pairs that get a row (the closest n_rows when capped)
    std::vector<int> sel(act.size());
    for (size_t j = 0; j < act.size(); ++j) sel[j] = int(j);
    if (!direct && !act.empty() && int(act.size()) > n_rows) {
      std::vector<double> gap(act.size());
      for (size_t j = 0; j < act.size(); ++j) gap[j] = dist.p[act[j]] - safety[act[j]];
      std::stable_sort(sel.begin(), sel.end(), [&](int a, int b) { return gap[a] < gap[b]; });
      sel.resize(n_rows);
      std::sort(sel.begin(), sel.end());
    }
    row_pairs.clear();
    for (int j : sel) row_pairs.push_back(act[j]);
    // gradients n'(J_b(p) - J_a(p)) = (c' J^W) o (S_b - S_a), c = [n; p_a x n]
    int k = int(row_pairs.size());
    grad.setZero(k, nv);
    for (int r = 0; r < k; ++r) {
      int pi = row_pairs[r];
      double px = wpa_all(pi, 0), py = wpa_all(pi, 1), pz = wpa_all(pi, 2);
      double nx = wn_all(pi, 0), ny = wn_all(pi, 1), nz = wn_all(pi, 2);
      double c[6] = {nx, ny, nz, py * nz - pz * ny, pz * nx - px * nz, px * ny - py * nx};
      for (int j = 0; j < nv; ++j) {
        double mask = support(gb[pi], j) - support(ga[pi], j);
        if (mask == 0.0) continue;
        double acc = 0.0;
        for (int t = 0; t < 6; ++t) acc += c[t] * d->J(t, j);
        grad(r, j) = acc * mask;
      }
    }
    // trust region: adapt to last tick's prediction error
    if (!pred_pairs.empty()) {
      std::vector<int> good;
      for (size_t j = 0; j < pred_pairs.size(); ++j) {
        int pi = pred_pairs[j];
        double err = dist.p[pi] - pred[j];
        double tol = trust;
        if (trust_gap > 0) tol = std::max(tol, trust_gap * (pred[j] - safety[pi]));
        if (err < -tol) {
          double f = std::min(std::max(sq(tol / err), 1.0 / 64), 0.5);
          scale[pi] = std::max(scale[pi] * f, min_scale);
          scaled = true;
        } else {
          good.push_back(pi);
        }
      }
      if (scaled) {
        for (int pi : good) scale[pi] = std::min(scale[pi] * 1.25, 1.0);
        sqrt_scale = scale.cwiseSqrt();
        scaled = scale.minCoeff() < 1.0;
      }
      pred_pairs.clear();
    }
    updated = true;
  }

  // the trust-region box (compute_bounds): called first in the tick, so it also updates
  bool compute(const Eigen::VectorXd &q, double dt, Eigen::VectorXd &lb, Eigen::VectorXd &ub) override {
    auto t0 = std::chrono::steady_clock::now();
    update(q);
    auto t1 = std::chrono::steady_clock::now();
    update_time = std::chrono::duration<double>(t1 - t0).count();
    if (trust <= 0 || row_pairs.empty()) return false;
    ub.setConstant(INF);
    for (int pi : row_pairs) {
      double f = 1.0;
      if (trust_gap > 0) f = std::sqrt(std::max(1.0, trust_gap * (dist.p[pi] - safety[pi]) / trust));
      double sc = scaled ? sqrt_scale[pi] : 1.0;
      const bool pl = planar[pi] != 0;
      const double s2min = min_plane_sine * min_plane_sine;
      for (int j = 0; j < nv; ++j) {
        double st = step0(pi, j);
        if (pl) {  // |n x a_j|^(-1/2), a_j = angular rows of the WORLD Jacobian's column j
          double ax = d->J(3, j), ay = d->J(4, j), az = d->J(5, j);
          double a2 = ax * ax + ay * ay + az * az;
          double na = plane(pi, 0) * ax + plane(pi, 1) * ay + plane(pi, 2) * az;
          double sin2 = 1.0 - na * na / (a2 > 0.0 ? a2 : 1.0);
          st = st * std::pow(std::max(sin2, s2min), -0.25);
        }
        if (trust_gap > 0) st = st * f;
        if (scaled) st = st * sc;
        ub[j] = std::min(ub[j], st);
      }
    }
    ub *= 1.0 / dt;
    lb = -ub;
    return true;
  }

  // QP rows of this tick's pairs (capped rows keep their slot while they stay among the closest)
  const std::vector<int> &slots() {
    if (row_pairs == slots_key) return slot_rows;
    std::vector<char> keep(P, 0);
    for (int pi : row_pairs) keep[pi] = 1;
    for (int r = 0; r < n_rows; ++r) {
      int owner = slot_pair[r];
      if (owner >= 0 && !keep[owner]) {
        slot[owner] = -1;
        slot_pair[r] = -1;
      }
    }
    int free_r = 0;
    for (int pi : row_pairs) {
      if (slot[pi] >= 0) continue;
      while (slot_pair[free_r] >= 0) ++free_r;
      slot[pi] = free_r;
      slot_pair[free_r] = pi;
    }
    slots_key = row_pairs;
    slot_rows.clear();
    for (int pi : row_pairs) slot_rows.push_back(slot[pi]);
    return slot_rows;
  }

  void rows(double dt, MapRM &C, double *u) {
    auto t0 = std::chrono::steady_clock::now();
    if (!updated) update(Eigen::Map<const Eigen::VectorXd>(q_cur, m->nq));
    std::vector<int> rws = row_pairs;
    if (!direct) rws = slots();
    if (!last_rows.empty() && last_rows != rws) {
      for (int r : last_rows) {
        C.row(row + r).setZero();
        u[row + r] = INF;
      }
    }
    double rt = rate(dt);
    gap_rows.resize(row_pairs.size());
    for (size_t j = 0; j < row_pairs.size(); ++j) {
      int pi = row_pairs[j], r = rws[j];
      double gp = dist.p[pi] - safety[pi];
      gap_rows[j] = gp;
      C.row(row + r) = -grad.row(int(j));
      u[row + r] = std::max(gp * rt, -recovery);
    }
    last_rows = rws;
    last_pairs = row_pairs;
    updated = false;
    last_time = update_time + std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  const double *q_cur = nullptr;

  void after_step(CArr v, double dt) {
    if (trust <= 0 || row_pairs.empty()) return;
    pred_pairs = row_pairs;
    pred.resize(row_pairs.size());
    for (size_t j = 0; j < row_pairs.size(); ++j) {
      double acc = 0.0;
      for (int t = 0; t < nv; ++t) acc += grad(int(j), t) * (v.data()[t] * dt);
      pred[j] = dist.p[row_pairs[j]] + acc;
    }
  }

  // read-outs for the Python object (violations, CRAC distances and gradients, witnesses)
  nb::tuple state_arrays() {
    auto vec = [](const std::vector<int> &x) {
      int64_t *p = new int64_t[x.size() ? x.size() : 1];
      for (size_t i = 0; i < x.size(); ++i) p[i] = x[i];
      nb::capsule owner(p, [](void *q) noexcept { delete[] (int64_t *)q; });
      return nb::ndarray<nb::numpy, int64_t, nb::ndim<1>>(p, {x.size()}, owner);
    };
    auto mat = [](const RowMat &x) {
      double *p = new double[x.size() ? x.size() : 1];
      std::copy(x.data(), x.data() + x.size(), p);
      nb::capsule owner(p, [](void *q) noexcept { delete[] (double *)q; });
      return nb::ndarray<nb::numpy, double, nb::ndim<2>>(p, {size_t(x.rows()), size_t(x.cols())}, owner);
    };
    RowMat wa(act.size(), 3), wnn(act.size(), 3);
    for (size_t j = 0; j < act.size(); ++j) {
      wa.row(int(j)) = wpa_all.row(act[j]);
      wnn.row(int(j)) = wn_all.row(act[j]);
    }
    RowMat gr = gap_rows.transpose();
    return nb::make_tuple(vec(act), vec(row_pairs), mat(grad), vec(last_pairs), mat(gr), mat(wa), mat(wnn),
                          last_time);
  }
};


// ---------------------------------------------------------------- support polygon rows
// constraints/support_polygon.py: n_k' J_com,xy v <= gamma/dt (o_k - n_k' c_xy) (recovery_depth
// further in outside an edge) - dt/2 n_k' cdd_xy (second order). The hull lives in the Python
// object (recomputed when the contacts change); the kernel asks it to resync when the contacts'
// version moved, then reads its edge arrays.
struct PolygonK {
  int row = 0, n_rows = 0;
  double gain = 1.0, recovery_depth = 0.0;
  bool second_order = true;
  nb::object py, contacts;  // the Python constraint and its contacts (or None)
  Buf N, o, nk;             // (n_rows, 2), (n_rows,), (1,) edge count (nk: owner only)
  int64_t *nk_i = nullptr;
  PyObject *s_version, *s_seen, *s_sync;
  PolygonK() {
    s_version = PyUnicode_InternFromString("version");
    s_seen = PyUnicode_InternFromString("_seen_version");
    s_sync = PyUnicode_InternFromString("_kernel_sync");
  }
  void compute(const Model &m, Data &d, Data &vd, bool &vd_ready, const Eigen::VectorXd &q,
               const Eigen::VectorXd &v, double dt, MapRM &C, double *u) {
    if (!contacts.is_none()) {
      nb::object ver = nb::steal(PyObject_GetAttr(contacts.ptr(), s_version));
      nb::object seen = nb::steal(PyObject_GetAttr(py.ptr(), s_seen));
      if (!ver.is_valid() || !seen.is_valid()) throw nb::python_error();
      int eq = PyObject_RichCompareBool(ver.ptr(), seen.ptr(), Py_EQ);
      if (eq < 0) throw nb::python_error();
      if (!eq) {
        nb::object r = nb::steal(PyObject_CallMethodNoArgs(py.ptr(), s_sync));
        if (!r.is_valid()) throw nb::python_error();
      }
    }
    int k = int(nk_i[0]);
    for (int r = k; r < n_rows; ++r) {
      C.row(row + r).setZero();
      u[row + r] = INF;
    }
    if (k == 0) return;
    const auto &Jc = pinocchio::jacobianCenterOfMass(m, d, true);
    const Eigen::Vector3d c = d.com[0];
    Eigen::Vector2d acc = Eigen::Vector2d::Zero();
    bool drift = second_order && !v.isZero(0.0);
    if (drift) {
      if (!vd_ready) {
        pinocchio::forwardKinematics(m, vd, q, v, Eigen::VectorXd::Zero(m.nv));
        vd_ready = true;
      }
      pinocchio::centerOfMass(m, vd, pinocchio::ACCELERATION, false);
      acc = vd.acom[0].head<2>();
    }
    double g = gain / dt;
    for (int e = 0; e < k; ++e) {
      double nx = N.p[2 * e], ny = N.p[2 * e + 1];
      C.row(row + e) = nx * Jc.row(0) + ny * Jc.row(1);
      double dist = o.p[e] - (nx * c[0] + ny * c[1]);
      if (dist < 0.0) dist -= recovery_depth;
      double ue = g * dist;
      if (drift) ue -= (0.5 * dt) * (nx * acc[0] + ny * acc[1]);
      u[row + e] = ue;
    }
  }
};


// ---------------------------------------------------------------- augmentation with slacks
// strategies/augmentation.py Augmentation._with_slacks: the QP x = (v, s) with one slack slot per
// soft row in play this tick (a finite side), in row order: C_i v - s_i <= u_i (or + s_i >= l_i
// for a row bounded from below only), cost w s + eps/2 s^2 (eps on the slots' diagonal, set when
// the slots were allocated). Returns the number of slots used, or -k when k exceed the slots
// allocated (nothing written: the caller grows the QP and calls again). `slot_rows` holds last
// tick's rows on entry (their slack entries are cleared) and this tick's on exit.
static int slack_core(const double *Hv, const double *gv, const double *Cp, const double *lp,
                      const double *up, const double *lbp, const double *ubp, int nv, int nin,
                      const int64_t *si, int ns, const double *sw, double *pH, double *g, double *pC,
                      double *pl, double *pu, double *plb, double *pubp, int n, int64_t *sr,
                      int n_last) {
  int n_slots = n - nv;
  int k = 0;
  for (int j = 0; j < ns; ++j)
    if (std::isfinite(up[si[j]]) || std::isfinite(lp[si[j]])) ++k;
  if (k > n_slots) return -k;
  MapRM PC(pC, nin, n);
  for (int j = 0; j < n_last; ++j) PC(sr[j], nv + j) = 0.0;
  PC.leftCols(nv) = Eigen::Map<const RowMat>(Cp, nin, nv);
  MapRM PH(pH, n, n);
  PH.topLeftCorner(nv, nv) = Eigen::Map<const RowMat>(Hv, nv, nv);
  std::copy(gv, gv + nv, g);
  std::fill(g + nv, g + n, 0.0);
  std::fill(pubp + nv, pubp + n, 0.0);
  int t = 0;
  for (int j = 0; j < ns; ++j) {
    int r = int(si[j]);
    bool upf = std::isfinite(up[r]);
    if (!upf && !std::isfinite(lp[r])) continue;
    PC(r, nv + t) = upf ? -1.0 : 1.0;
    g[nv + t] = sw[j];
    pubp[nv + t] = INF;
    sr[t] = r;
    ++t;
  }
  std::copy(lp, lp + nin, pl);
  std::copy(up, up + nin, pu);
  std::copy(lbp, lbp + nv, plb);
  std::copy(ubp, ubp + nv, pubp);
  return k;
}

static int slack_qp(CArr Hv, CArr gv, CArr C, CArr l, CArr u, CArr lb, CArr ub, IArr soft_idx,
                    CArr soft_w, Arr pH, Arr pg, Arr pC, Arr pl, Arr pu, Arr plb, Arr pub,
                    IArr slot_rows, int n_last) {
  return slack_core(Hv.data(), gv.data(), C.data(), l.data(), u.data(), lb.data(), ub.data(),
                    int(gv.size()), int(l.size()), soft_idx.data(), int(soft_idx.size()), soft_w.data(),
                    pH.data(), pg.data(), pC.data(), pl.data(), pu.data(), plb.data(), pub.data(),
                    int(pg.size()), slot_rows.data(), n_last);
}

// ---------------------------------------------------------------- DAQP (C API of the installed daqp)
extern "C" {
typedef struct {
  int n, m, ms;
  double *H, *f, *A, *bupper, *blower;
  int *sense;
  int *break_points;
  int nh;
  int problem_type;
} KDAQPProblem;
typedef struct {  // DAQP 0.11 DAQPSettings (include/types.h), field for field
  double primal_tol, dual_tol, zero_tol, pivot_tol, progress_tol;
  int cycle_tol, iter_limit;
  double fval_bound, eps_prox, eta_prox, rho_soft, rel_subopt, abs_subopt, sing_tol, refactor_tol,
      time_limit, w_soft;
  int eq_reduction, presolve;
  double pad[16];  // room should a later DAQP add fields (only the leading ones are written)
} KDAQPSettings;
typedef struct {
  double *x, *lam;
  double fval, soft_slack;
  int exitflag, iter, nodes;
  double solve_time, setup_time;
  double pad[8];
} KDAQPResult;
typedef void (*quadprog_fn)(KDAQPResult *, KDAQPProblem *, KDAQPSettings *);
typedef void (*default_settings_fn)(KDAQPSettings *);
}

struct Daqp {
  quadprog_fn quadprog = nullptr;
  default_settings_fn defaults = nullptr;
  std::string error;
  bool load(const std::string &path) {
    void *h = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!h) {
      error = dlerror();
      return false;
    }
    quadprog = (quadprog_fn)dlsym(h, "daqp_quadprog");
    defaults = (default_settings_fn)dlsym(h, "daqp_default_settings");
    if (!quadprog || !defaults) {
      error = "daqp_quadprog/daqp_default_settings not exported by " + path;
      quadprog = nullptr;
      return false;
    }
    return true;
  }
};
static Daqp g_daqp;

static bool daqp_load(const std::string &path) { return g_daqp.quadprog != nullptr || g_daqp.load(path); }

// Defaults as DAQP sets them (for the layout check in Python: these must be DAQP's documented
// defaults, else the struct layout differs and the compiled solve is not used).
static std::vector<double> daqp_defaults() {
  KDAQPSettings s;
  g_daqp.defaults(&s);
  return {s.primal_tol, s.dual_tol, s.zero_tol, s.pivot_tol, s.progress_tol, double(s.cycle_tol),
          double(s.iter_limit), s.fval_bound, s.eps_prox, s.eta_prox, s.rho_soft};
}

// One hot-started DAQP solve of  min 1/2 x'Hx + g'x  s.t. lb <= x <= ub, l <= C x <= u, the same
// inputs as solvers/daqp_.py: rows with no finite side are left out; bounds clipped at 1e30; the
// previous multipliers `lam` (n + n_in) mark the hot-start active set (sense 1), equal bounds are
// equalities (sense 5). Returns (exitflag, iterations); x and lam (for the next hot start) are
// written in place, lam zeroed when the solve failed with `lam_valid` false.
struct DaqpWork {
  std::vector<int> rows, sense;
  std::vector<double> A, bu, bl, x, lamr;
};

struct DaqpOut {
  int flag = 0, iters = 0;
  bool ok = false;
};


// The previous tick's active set, checked for optimality before DAQP runs (fused tick only).
// With W the constraints active at the last solution (each on the side of its multiplier's sign,
// equalities always), the equality-constrained QP  min 1/2 x'Hx + g'x  s.t. the W constraints
// held as equalities  is solved by its KKT system (variables fixed at their active bounds, the
// rest through a Cholesky factor of H's free block and the Schur complement of the active rows).
// If every multiplier has the sign of its side and no other constraint is violated (DAQP's
// tolerances), that point satisfies the KKT conditions of the whole QP: it is the unique optimum
// (H positive definite), the one DAQP would return to round-off, found without its setup and
// iterations. Otherwise (a change of active set, a singular system) DAQP solves the tick.
struct KKTWork {
  std::vector<int> freev, fixedv, rowsA;
  std::vector<char> isfixed;
  Eigen::MatrixXd HFF, AF, Y, S;
  Eigen::VectorXd h, bA, z, mu, xF, x, grad;
};

static bool kkt_shortcut(const double *Hp, const double *gp, const double *Cp, const double *lp,
                         const double *up, const double *lbp, const double *ubp, int n, int nin,
                         double *xo, double *lamio, double primal_tol, double dual_tol) {
  static KKTWork k;
  Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> H(Hp, n, n);
  Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> C(Cp, nin, n);
  Eigen::Map<const Eigen::VectorXd> g(gp, n);
  bool any = false;
  for (int i = 0; i < n + nin && !any; ++i) any = lamio[i] != 0.0;
  if (!any) return false;
  k.freev.clear();
  k.fixedv.clear();
  k.rowsA.clear();
  k.isfixed.assign(n, 0);
  k.x.setZero(n);
  for (int i = 0; i < n; ++i) {
    bool eq = lbp[i] == ubp[i];
    if (eq || lamio[i] != 0.0) {
      double b = eq ? lbp[i] : (lamio[i] > 0.0 ? ubp[i] : lbp[i]);
      if (!std::isfinite(b)) return false;
      k.isfixed[i] = 1;
      k.fixedv.push_back(i);
      k.x[i] = b;
    } else {
      k.freev.push_back(i);
    }
  }
  for (int r = 0; r < nin; ++r) {
    bool eq = std::isfinite(lp[r]) && lp[r] == up[r];
    if (eq || lamio[n + r] != 0.0) k.rowsA.push_back(r);
  }
  int nF = int(k.freev.size()), mA = int(k.rowsA.size());
  if (mA > nF || nF == 0) return false;
  k.HFF.resize(nF, nF);
  k.h.resize(nF);
  for (int a = 0; a < nF; ++a) {
    int ia = k.freev[a];
    double hv = g[ia];
    for (int j : k.fixedv) hv += H(ia, j) * k.x[j];
    k.h[a] = hv;
    for (int b = 0; b < nF; ++b) k.HFF(a, b) = H(ia, k.freev[b]);
  }
  Eigen::LLT<Eigen::MatrixXd> llt(k.HFF);
  if (llt.info() != Eigen::Success) return false;
  k.AF.resize(nF, mA);  // A_F' (free columns of the active rows, transposed)
  k.bA.resize(mA);
  for (int c = 0; c < mA; ++c) {
    int r = k.rowsA[c];
    double b = (std::isfinite(lp[r]) && lp[r] == up[r]) ? up[r] : (lamio[n + r] > 0.0 ? up[r] : lp[r]);
    if (!std::isfinite(b)) return false;
    for (int j : k.fixedv) b -= C(r, j) * k.x[j];
    k.bA[c] = b;
    for (int a = 0; a < nF; ++a) k.AF(a, c) = C(r, k.freev[a]);
  }
  const auto L = llt.matrixL();
  k.z = L.solve(k.h);
  k.mu.resize(mA);
  if (mA > 0) {
    k.Y = L.solve(k.AF);
    k.S.noalias() = k.Y.transpose() * k.Y;
    Eigen::LLT<Eigen::MatrixXd> sl(k.S);
    if (sl.info() != Eigen::Success) return false;
    double dmin = k.S.diagonal().minCoeff(), dmax = k.S.diagonal().maxCoeff();
    Eigen::VectorXd ld = sl.matrixLLT().diagonal();
    if (!(dmin > 0) || ld.minCoeff() * ld.minCoeff() < 1e-12 * dmax) return false;  // near-singular
    k.mu = -sl.solve(k.bA + k.Y.transpose() * k.z);
    k.xF = -(L.transpose().solve(k.z + k.Y * k.mu));
  } else {
    k.xF = -(L.transpose().solve(k.z));
  }
  for (int a = 0; a < nF; ++a) k.x[k.freev[a]] = k.xF[a];
  if (!k.x.allFinite() || !k.mu.allFinite()) return false;
  // dual feasibility of the active rows (equalities: any sign)
  for (int c = 0; c < mA; ++c) {
    int r = k.rowsA[c];
    if (std::isfinite(lp[r]) && lp[r] == up[r]) continue;
    if (lamio[n + r] > 0.0 ? k.mu[c] < -dual_tol : k.mu[c] > dual_tol) return false;
  }
  // bound multipliers nu_B = -((Hx + g)_B + (A' mu)_B) and their signs
  k.grad.noalias() = H * k.x;
  k.grad += g;
  std::vector<double> nu(k.fixedv.size());
  for (size_t t = 0; t < k.fixedv.size(); ++t) {
    int j = k.fixedv[t];
    double v = k.grad[j];
    for (int c = 0; c < mA; ++c) v += C(k.rowsA[c], j) * k.mu[c];
    nu[t] = -v;
    if (lbp[j] == ubp[j]) continue;
    if (lamio[j] > 0.0 ? nu[t] < -dual_tol : nu[t] > dual_tol) return false;
  }
  // primal feasibility of everything else
  for (int i = 0; i < n; ++i) {
    if (k.isfixed[i]) continue;
    if (k.x[i] < lbp[i] - primal_tol || k.x[i] > ubp[i] + primal_tol) return false;
  }
  std::vector<char> act(nin, 0);
  for (int r : k.rowsA) act[r] = 1;
  for (int r = 0; r < nin; ++r) {
    if (act[r] || (!std::isfinite(lp[r]) && !std::isfinite(up[r]))) continue;
    double cx = C.row(r).dot(k.x);
    if (cx < lp[r] - primal_tol || cx > up[r] + primal_tol) return false;
  }
  // the optimum: x and the multipliers in DAQP's layout (bounds, then rows; sign = side)
  std::copy(k.x.data(), k.x.data() + n, xo);
  std::fill(lamio, lamio + n + nin, 0.0);
  for (size_t t = 0; t < k.fixedv.size(); ++t) lamio[k.fixedv[t]] = nu[t];
  for (int c = 0; c < mA; ++c) lamio[n + k.rowsA[c]] = k.mu[c];
  return true;
}

static DaqpOut daqp_core(const double *H, const double *g, const double *Cp, const double *lp,
                         const double *up, const double *lbp, const double *ubp, int n, int nin,
                         double *xo, double *lamio, bool warm, double primal_tol, double dual_tol,
                         int iter_limit, double eps_prox, bool release_gil, bool shortcut = false) {
  if (shortcut && warm &&
      kkt_shortcut(H, g, Cp, lp, up, lbp, ubp, n, nin, xo, lamio, primal_tol, dual_tol)) {
    DaqpOut out;
    out.flag = 1;
    out.iters = 0;
    out.ok = true;
    return out;
  }
  static DaqpWork w;
  const double BIG = 1e30;
  w.rows.clear();
  for (int i = 0; i < nin; ++i)
    if (std::isfinite(lp[i]) || std::isfinite(up[i])) w.rows.push_back(i);
  int m = int(w.rows.size());
  w.A.resize(size_t(m) * n);
  for (int r = 0; r < m; ++r)
    std::copy(Cp + size_t(w.rows[r]) * n, Cp + size_t(w.rows[r] + 1) * n, w.A.begin() + size_t(r) * n);
  w.bu.resize(n + m);
  w.bl.resize(n + m);
  w.sense.assign(n + m, 0);
  for (int i = 0; i < n; ++i) {
    w.bu[i] = std::min(ubp[i], BIG);
    w.bl[i] = std::max(lbp[i], -BIG);
  }
  for (int r = 0; r < m; ++r) {
    w.bu[n + r] = std::min(up[w.rows[r]], BIG);
    w.bl[n + r] = std::max(lp[w.rows[r]], -BIG);
  }
  if (warm) {  // the last active set, marked active (solvers/daqp_.py explains the side)
    for (int i = 0; i < n; ++i)
      if (lamio[i] != 0.0) w.sense[i] = 1;
    for (int r = 0; r < m; ++r)
      if (lamio[n + w.rows[r]] != 0.0) w.sense[n + r] = 1;
  }
  for (int i = 0; i < n + m; ++i)
    if (w.bl[i] == w.bu[i]) w.sense[i] = 5;
  w.x.assign(n, 0.0);
  w.lamr.assign(n + m, 0.0);
  KDAQPProblem qp{n, n + m, n, const_cast<double *>(H), const_cast<double *>(g), w.A.data(),
                  w.bu.data(), w.bl.data(), w.sense.data(), nullptr, 0, 0};
  KDAQPSettings st;
  g_daqp.defaults(&st);
  st.primal_tol = primal_tol;
  st.dual_tol = dual_tol;
  st.iter_limit = iter_limit;
  st.eps_prox = eps_prox;
  KDAQPResult res;
  res.x = w.x.data();
  res.lam = w.lamr.data();
  if (release_gil) {
    nb::gil_scoped_release release;
    g_daqp.quadprog(&res, &qp, &st);
  } else {
    g_daqp.quadprog(&res, &qp, &st);
  }
  DaqpOut out;
  out.flag = res.exitflag;
  if (out.flag == -5 && eps_prox == 0.0) {  // singular H: proximal iterations (solvers/daqp_.py)
    st.eps_prox = 1e-6;
    g_daqp.quadprog(&res, &qp, &st);
    out.flag = res.exitflag;
  }
  out.iters = res.iter;
  out.ok = (out.flag == 1 || out.flag == 2);
  for (int i = 0; i < n && out.ok; ++i) out.ok = std::isfinite(w.x[i]);
  if (out.ok) {
    std::copy(w.x.begin(), w.x.end(), xo);
    std::fill(lamio, lamio + n + nin, 0.0);
    std::copy(w.lamr.begin(), w.lamr.begin() + n, lamio);
    for (int r = 0; r < m; ++r) lamio[n + w.rows[r]] = w.lamr[n + r];
  } else {
    std::fill(lamio, lamio + n + nin, 0.0);  // no hot start from a failed solve
  }
  return out;
}

static nb::tuple daqp_solve(Arr H, Arr g, CArr C, CArr l, CArr u, CArr lb, CArr ub, Arr x_out, Arr lam,
                            bool warm, double primal_tol, double dual_tol, int iter_limit,
                            double eps_prox) {
  int n = int(g.size());
  int nin = int(l.size());
  DaqpOut o = daqp_core(H.data(), g.data(), C.data(), l.data(), u.data(), lb.data(), ub.data(), n, nin,
                        x_out.data(), lam.data(), warm, primal_tol, dual_tol, iter_limit, eps_prox, true);
  return nb::make_tuple(o.flag, o.iters, o.ok);
}

// ---------------------------------------------------------------- collision distances
// The exact distances of the pairs marked in `need` (collision/model.py CollisionModel): the
// geometry placements of this tick's kinematics (unless `placed`), then coal's signed distance
// of each marked pair in index order (pinocchio computeDistance, the call computeDistances makes
// for an active pair: same GJK warm starts, same results), its witness point on body a and unit
// normal from a to b written into (P,) and (P, 3) arrays, in one call instead of a Python loop
// over the pairs. Returns the number of pairs computed.
static int geometry_distances(nb::handle py_model, nb::handle py_data, nb::handle py_gmodel,
                              nb::handle py_gdata, BArr need, bool placed, Arr d_out, Arr pa_out,
                              Arr n_out) {
  const Model &m = *extract_ref<Model>(py_model, "pinocchio.Model");
  Data &d = *extract_ref<Data>(py_data, "pinocchio.Data");
  const pinocchio::GeometryModel &gm = *extract_ref<pinocchio::GeometryModel>(py_gmodel, "pinocchio.GeometryModel");
  pinocchio::GeometryData &gd = *extract_ref<pinocchio::GeometryData>(py_gdata, "pinocchio.GeometryData");
  const bool *nd = need.data();
  size_t P = need.size();
  if (P != gm.collisionPairs.size() || d_out.size() != P || pa_out.size() != 3 * P || n_out.size() != 3 * P)
    throw std::invalid_argument("geometry_distances: arrays do not match the pairs");
  if (!placed) pinocchio::updateGeometryPlacements(m, d, gm, gd);
  double *dp = d_out.data(), *pap = pa_out.data(), *np_ = n_out.data();
  int count = 0;
  for (size_t i = 0; i < P; ++i) {
    if (!nd[i]) continue;
    const coal::DistanceResult &r = pinocchio::computeDistance(gm, gd, i);
    dp[i] = r.min_distance;
    for (int k = 0; k < 3; ++k) {
      pap[3 * i + k] = r.nearest_points[0][k];
      np_[3 * i + k] = r.normal[k];
    }
    ++count;
  }
  return count;
}

// ---------------------------------------------------------------- the tick
struct Tick {
  Model *model;
  Data *data;
  Data vdata;
  std::unique_ptr<Data> rdata;  // scratch kinematics of the corrector step (refine_contacts)
  nb::object keep_model, keep_data;
  std::vector<std::unique_ptr<TaskK>> tasks;
  std::vector<std::shared_ptr<BoundsK>> bounds;  // merge order (most important first)
  std::vector<std::shared_ptr<DamperK>> dampers;  // distance dampers (self-collision)
  std::vector<std::shared_ptr<DamperK>> damper_rows_;  // those whose rows the kernel writes
  std::vector<ContactsK> contacts;
  std::vector<PolygonK> polygons;
  Buf J_all, v_all, e_all, C, l, u, lb, ub;
  int m_tasks = 0, n_rows = 0;
  Eigen::VectorXd q, v, blo, bhi, nlb, nub;
  std::vector<double> gave;
  // augmentation
  RowMat Jw;
  Eigen::MatrixXd Hl;
  Eigen::VectorXd rw;
  std::vector<int> dense_rows;
  size_t dense_tasks = size_t(-1);

  Tick(nb::handle py_model, nb::handle py_data)
      : model(extract_ref<Model>(py_model, "pinocchio.Model")),
        data(extract_ref<Data>(py_data, "pinocchio.Data")),
        vdata(*model),
        keep_model(nb::borrow(py_model)),
        keep_data(nb::borrow(py_data)) {}
  Tick(const Tick &) = delete;
  Tick &operator=(const Tick &) = delete;

  void set_buffers(Arr J, Arr ve, Arr e, Arr C_, Arr l_, Arr u_, Arr lb_, Arr ub_) {
    J_all = Buf(J);
    v_all = Buf(ve);
    e_all = Buf(e);
    C = Buf(C_);
    l = Buf(l_);
    u = Buf(u_);
    lb = Buf(lb_);
    ub = Buf(ub_);
    m_tasks = int(ve.size());
    n_rows = int(l_.size());
  }

  void add_frame_task(nb::object py, int row, int fid, int mode, CArr offset, bool has_offset, double gain) {
    auto t = std::make_unique<FrameTaskK>();
    t->py = py;
    t->row = row;
    t->fid = fid;
    t->mode = mode;
    t->dim = mode == 2 ? 6 : 3;
    t->has_offset = has_offset;
    if (has_offset) t->offset = Eigen::Map<const Eigen::Vector3d>(offset.data());
    t->gain = gain;
    tasks.push_back(std::move(t));
  }
  void add_com_task(nb::object py, int row, std::vector<int> rows, double gain) {
    auto t = std::make_unique<ComTaskK>();
    t->py = py;
    t->row = row;
    t->rows = rows;
    t->dim = int(rows.size());
    t->gain = gain;
    tasks.push_back(std::move(t));
  }
  void add_posture_task(nb::object py, int row, int dim, int root_nv, double gain) {
    auto t = std::make_unique<PostureTaskK>();
    t->py = py;
    t->row = row;
    t->dim = dim;
    t->root_nv = root_nv;
    t->identity_col = root_nv;
    t->gain = gain;
    tasks.push_back(std::move(t));
  }
  void add_joint_limits(std::string name, std::vector<int> qi, std::vector<int> vi, CArr lo, CArr hi, double gain) {
    auto b = std::make_shared<JointLimitsK>();
    b->name = name;
    b->qi = qi;
    b->vi = vi;
    b->lo = Eigen::Map<const Eigen::VectorXd>(lo.data(), lo.size());
    b->hi = Eigen::Map<const Eigen::VectorXd>(hi.data(), hi.size());
    b->gain = gain;
    bounds.push_back(std::move(b));
  }
  void add_const_bounds(std::string name, CArr lo, CArr hi) {
    auto b = std::make_shared<ConstBoundsK>();
    b->name = name;
    b->lo = Eigen::Map<const Eigen::VectorXd>(lo.data(), lo.size());
    b->hi = Eigen::Map<const Eigen::VectorXd>(hi.data(), hi.size());
    bounds.push_back(std::move(b));
  }
  int add_contacts(int row, std::vector<int> fids, double gain, bool second_order, double cap_lin,
                    double cap_ang, BArr active, Arr anchor_p, Arr anchor_R, Arr anchor_step) {
    ContactsK c;
    c.row = row;
    c.fids = fids;
    c.gain = gain;
    c.second_order = second_order;
    c.cap_lin = cap_lin;
    c.cap_ang = cap_ang;
    c.active_b.owner = nb::find(active);
    c.active = active.data();
    c.anchor_p = Buf(anchor_p);
    c.anchor_R = Buf(anchor_R);
    c.anchor_step = Buf(anchor_step);
    contacts.push_back(std::move(c));
    return int(contacts.size()) - 1;
  }
  // The corrector step of contacts block `index` (Contacts.refine_rows): l, u are its rows.
  bool refine_contacts(int index, CArr q_next, double dt, double tol, double half_length, Arr l_,
                       Arr u_) {
    const Model &m = *model;
    if (!rdata) rdata = std::make_unique<Data>(m);
    Eigen::Map<const Eigen::VectorXd> qn(q_next.data(), m.nq);
    return contacts.at(index).refine(m, *data, *rdata, qn, dt, tol, half_length, l_.data(),
                                     u_.data());
  }

  void add_polygon(nb::object py, nb::object contacts_, int row, int n_rows, double gain,
                   double recovery_depth, bool second_order, Arr N_, Arr o_, IArr nk_) {
    PolygonK pk;
    pk.py = py;
    pk.contacts = contacts_;
    pk.row = row;
    pk.n_rows = n_rows;
    pk.gain = gain;
    pk.recovery_depth = recovery_depth;
    pk.second_order = second_order;
    pk.N = Buf(N_);
    pk.o = Buf(o_);
    pk.nk.owner = nb::find(nk_);
    pk.nk.p = nullptr;
    pk.nk_i = nk_.data();
    polygons.push_back(std::move(pk));
  }
  int add_damper(nb::handle gmodel, nb::handle gdata, Arr distances, CArr pair_lever, CArr support,
                 std::vector<int> ga, std::vector<int> gb, CArr safety, CArr step0, CArr plane,
                 double min_plane_sine, bool broad_phase,
                 double hysteresis, double rank_margin, double d_i, double d_s, int rate_form,
                 double rate_value, double recovery, double trust, double trust_gap,
                 double min_scale, int n_rows, bool direct, int nearest) {
    auto dk = std::make_shared<DamperK>();
    dk->m = model;
    dk->d = data;
    dk->set_geometry(gmodel, gdata);
    dk->P = int(distances.size());
    dk->nv = model->nv;
    dk->dist = Buf(distances);
    int P = dk->P, nv = dk->nv;
    dk->pair_lever = Eigen::Map<const RowMat>(pair_lever.data(), P, nv);
    dk->support = Eigen::Map<const RowMat>(support.data(), support.size() / nv, nv);
    dk->step0 = Eigen::Map<const RowMat>(step0.data(), P, nv);
    dk->plane = Eigen::Map<const RowMat>(plane.data(), P, 3);
    dk->planar.assign(P, 0);
    for (int i = 0; i < P; ++i) dk->planar[i] = dk->plane.row(i).squaredNorm() > 0.0;
    dk->min_plane_sine = min_plane_sine;
    dk->ga = ga;
    dk->gb = gb;
    dk->safety = Eigen::Map<const Eigen::VectorXd>(safety.data(), P);
    dk->broad_phase = broad_phase;
    dk->hysteresis = hysteresis;
    dk->rank_margin = rank_margin;
    dk->d_i = d_i;
    dk->d_s = d_s;
    dk->rate_form = rate_form;
    dk->rate_value = rate_value;
    dk->recovery = recovery;
    dk->trust = trust;
    dk->trust_gap = trust_gap;
    dk->min_scale = min_scale;
    dk->n_rows = n_rows;
    dk->direct = direct;
    dk->has_nearest = nearest > 0;
    dk->nearest = nearest;
    dk->q_last = Eigen::VectorXd::Zero(model->nq);
    dk->wpa_all.setZero(P, 3);
    dk->wn_all.setZero(P, 3);
    dk->name = "damper";
    dk->reset();
    dampers.push_back(dk);
    return int(dampers.size()) - 1;
  }
  void add_damper_bounds(int id, std::string name) {
    dampers.at(id)->name = name;
    bounds.push_back(dampers.at(id));
  }
  void add_damper_rows(int id, int row) {
    dampers.at(id)->row = row;
    damper_rows_.push_back(dampers.at(id));
  }
  void damper_reset(int id, nb::handle gdata) {
    auto &dk = dampers.at(id);
    dk->set_geometry(dk->keep_gm, gdata);
    dk->reset();
    MapRM Cm(C.p, n_rows, model->nv);
    for (int r = 0; r < dk->n_rows; ++r) {  // a reset run is the same as a fresh one
      Cm.row(dk->row + r).setZero();
      u.p[dk->row + r] = INF;
    }
  }
  void damper_after_step(int id, CArr v, double dt) { dampers.at(id)->after_step(v, dt); }
  nb::tuple damper_state(int id) { return dampers.at(id)->state_arrays(); }
  double damper_last_time(int id) { return dampers.at(id)->last_time; }

  // Tasks, bounds (merged) and rows of this tick. Returns the amounts each bound gave
  // (NaN: nothing), one per bound module in merge order.
  // merge: the kernel merges the box (every box module compiled). Otherwise each compiled box
  // module's own box is computed (read with `box(i)`, merged in Python in order with the
  // others) and the returned values are 1 (a box this tick) or NaN (none).
  bool merge = true;
  void set_merge(bool mg) { merge = mg; }
  nb::tuple box(int i) {
    auto &b = bounds.at(i);
    auto copy = [](const Eigen::VectorXd &x) {
      double *p = new double[x.size() ? x.size() : 1];
      std::copy(x.data(), x.data() + x.size(), p);
      nb::capsule owner(p, [](void *q) noexcept { delete[] (double *)q; });
      return nb::ndarray<nb::numpy, double, nb::ndim<1>>(p, {size_t(x.size())}, owner);
    };
    return nb::make_tuple(copy(b->lo_out), copy(b->hi_out));
  }

  std::vector<double> build(CArr q_, CArr v_, double dt) {
    const Model &m = *model;
    Data &d = *data;
    q = Eigen::Map<const Eigen::VectorXd>(q_.data(), m.nq);
    v = Eigen::Map<const Eigen::VectorXd>(v_.data(), m.nv);
    for (auto &dk : dampers) {
      dk->q_cur = q.data();
      dk->updated = false;
    }
    MapRM J(J_all.p, m_tasks, m.nv);
    for (auto &t : tasks) {
      double *e = e_all.p + t->row;
      t->compute(m, d, q, J, e);
      double k = t->k(dt);
      for (int i = 0; i < t->dim; ++i) v_all.p[t->row + i] = e[i] * k;
    }
    gave.assign(bounds.size(), std::numeric_limits<double>::quiet_NaN());
    if (merge && !bounds.empty())
      merge_boxes(dt);
    else
      own_boxes(dt);
    MapRM Cm(C.p, n_rows, m.nv);
    bool vd_ready = false;
    for (auto &c : contacts) c.compute(m, d, vdata, vd_ready, q, v, dt, Cm, l.p, u.p);
    for (auto &pk : polygons) pk.compute(m, d, vdata, vd_ready, q, v, dt, Cm, u.p);
    for (auto &dk : damper_rows_) dk->rows(dt, Cm, u.p);
    return gave;
  }

  // Each compiled box module's own box, merged in Python with the others (gave: 1 = a box).
  void own_boxes(double dt) {
    int nv = model->nv;
    for (size_t b = 0; b < bounds.size(); ++b) {
      auto &bk = bounds[b];
      bk->lo_out.resize(nv);
      bk->hi_out.resize(nv);
      bk->has_out = bk->compute(q, dt, bk->lo_out, bk->hi_out);
      if (bk->has_out) gave[b] = 1.0;
    }
  }

  // The box, most important first; a less important one gives (Controller._merge_bounds).
  void merge_boxes(double dt) {
    int nv = model->nv;
    MapV LB(lb.p, nv), UB(ub.p, nv);
    LB.setConstant(-INF);
    UB.setConstant(INF);
    blo.resize(nv);
    bhi.resize(nv);
    bool first = true;
    for (size_t b = 0; b < bounds.size(); ++b) {
      if (!bounds[b]->compute(q, dt, blo, bhi)) continue;
      if (first) {  // the most important box goes in as it is
        LB = blo;
        UB = bhi;
        first = false;
        continue;
      }
      double amount = -INF;
      bool any = false;
      for (int i = 0; i < nv; ++i) {
        double nl = std::max(LB[i], blo[i]), nu = std::min(UB[i], bhi[i]);
        if (nl > nu) {
          any = true;
          amount = std::max(amount, std::max(nl - UB[i], LB[i] - nu));
          nl = std::min(std::max(blo[i], LB[i]), UB[i]);
          nu = std::min(std::max(bhi[i], LB[i]), UB[i]);
          nl = std::min(nl, nu);
        }
        LB[i] = nl;
        UB[i] = nu;
      }
      if (any) gave[b] = amount;
    }
  }

  // Augmentation's cost (strategies/augmentation.py, Dariush 2009 4.3.1, CRAC eq. 10):
  // H = Jw' Jw + lambda^2 I and g = -Jw' rw, Jw = diag(sw) J, rw = sw .* v*, over every stacked
  // task row (compiled or not). Rows of [0 I] form (posture) add their weights to the diagonal
  // instead of going through the dense product.
  void hessian(CArr sw_, double lambda2, Arr H_, Arr g_) { hessian_core(sw_.data(), lambda2, H_.data(), g_.data()); }

  void hessian_core(const double *swp, double lambda2, double *Hp, double *gp) {
    int nv = model->nv;
    MapRM J(J_all.p, m_tasks, nv);
    MapRM H(Hp, nv, nv);
    MapV g(gp, nv);
    if (dense_tasks != tasks.size()) {  // rows outside the [0 I] tasks, once per task set
      dense_rows.clear();
      std::vector<char> ident(m_tasks, 0);
      for (auto &t : tasks)
        if (t->identity_col >= 0)
          for (int i = 0; i < t->dim; ++i) ident[t->row + i] = 1;
      for (int r = 0; r < m_tasks; ++r)
        if (!ident[r]) dense_rows.push_back(r);
      dense_tasks = tasks.size();
    }
    int md = int(dense_rows.size());
    Jw.resize(md, nv);
    rw.resize(md);
    for (int i = 0; i < md; ++i) {
      int r = dense_rows[i];
      Jw.row(i) = swp[r] * J.row(r);
      rw[i] = swp[r] * v_all.p[r];
    }
    Hl.setZero(nv, nv);
    Hl.selfadjointView<Eigen::Lower>().rankUpdate(Jw.transpose());
    H = Hl.selfadjointView<Eigen::Lower>();
    g.noalias() = -(Jw.transpose() * rw);
    for (auto &t : tasks) {
      if (t->identity_col < 0) continue;
      for (int i = 0; i < t->dim; ++i) {
        int r = t->row + i, c = t->identity_col + i;
        double w = swp[r] * swp[r];
        H(c, c) += w;
        g[c] -= w * v_all.p[r];
      }
    }
    if (lambda2 > 0) H.diagonal().array() += lambda2;
  }

  // Copies of this tick's rows and box into a QP's buffers.
  void copy_constraints(Arr C_, Arr l_, Arr u_, Arr lb_, Arr ub_) {
    copy_core(C_.data(), l_.data(), u_.data(), lb_.data(), ub_.data());
  }
  void copy_core(double *C_, double *l_, double *u_, double *lb_, double *ub_) const {
    int nv = model->nv;
    if (n_rows) {
      std::copy(C.p, C.p + size_t(n_rows) * nv, C_);
      std::copy(l.p, l.p + n_rows, l_);
      std::copy(u.p, u.p + n_rows, u_);
    }
    std::copy(lb.p, lb.p + nv, lb_);
    std::copy(ub.p, ub.p + nv, ub_);
  }


  // ------------------------------------------------------------ the fused velocity-level tick
  // Augmentation's QP (H, g, rows or the slack QP) into the strategy's buffers, DAQP on it with
  // the solver's hot start, then v clipped to the box and q+ = q (+) v dt, in one call
  // (control/compiled.py CompiledTick.solve_velocity: the Python level takes over on any tick
  // this does not finish cleanly).
  struct QPBufs {
    Buf H, g, C, l, u, lb, ub, x, lam, slot, sidx_owner, sw;
    const int64_t *sidx = nullptr;
    int64_t *slotp = nullptr;
    int ns = 0, n = 0;
    bool soft = false, warm = true, shortcut = true;
    double primal_tol = 1e-9, dual_tol = 1e-12, eps_prox = 0.0;
    int iter_limit = 1000;
    Eigen::MatrixXd Hv_rm;
    Eigen::VectorXd gv;
  } qp;
  Eigen::VectorXd qn;
  void set_shortcut(bool on) { qp.shortcut = on; }
  void set_qp(Arr H_, Arr g_, Arr C_, Arr l_, Arr u_, Arr lb_, Arr ub_, Arr x_, Arr lam_, bool soft,
              IArr slot_buf, IArr soft_idx, CArr soft_w, bool warm, double primal_tol,
              double dual_tol, int iter_limit, double eps_prox) {
    qp.H = Buf(H_);
    qp.g = Buf(g_);
    qp.C = Buf(C_);
    qp.l = Buf(l_);
    qp.u = Buf(u_);
    qp.lb = Buf(lb_);
    qp.ub = Buf(ub_);
    qp.x = Buf(x_);
    qp.lam = Buf(lam_);
    qp.n = int(g_.size());
    qp.soft = soft;
    qp.slot.owner = nb::find(slot_buf);
    qp.slotp = slot_buf.data();
    qp.sidx_owner.owner = nb::find(soft_idx);
    qp.sidx = soft_idx.data();
    qp.ns = int(soft_idx.size());
    qp.sw.owner = nb::find(soft_w);
    qp.sw.p = const_cast<double *>(soft_w.data());
    qp.warm = warm;
    qp.primal_tol = primal_tol;
    qp.dual_tol = dual_tol;
    qp.iter_limit = iter_limit;
    qp.eps_prox = eps_prox;
  }
  // Returns (k slots or -k to grow, flag, iterations, ok, largest slack, solve seconds,
  // assembly seconds); on ok, x (the QP's variable) is clipped and q_out holds q+.
  nb::tuple fused(CArr sw_, double lambda2, int n_last, double dt, Arr q_out) {
    auto t0 = std::chrono::steady_clock::now();
    int nv = model->nv;
    int nin = n_rows;
    int k = 0;
    if (qp.soft) {
      qp.Hv_rm.resize(nv, nv);
      qp.gv.resize(nv);
      hessian_core(sw_.data(), lambda2, qp.Hv_rm.data(), qp.gv.data());  // symmetric: any order
      k = slack_core(qp.Hv_rm.data(), qp.gv.data(), C.p, l.p, u.p, lb.p, ub.p, nv, nin, qp.sidx,
                     qp.ns, qp.sw.p, qp.H.p, qp.g.p, qp.C.p, qp.l.p, qp.u.p, qp.lb.p, qp.ub.p, qp.n,
                     qp.slotp, n_last);
      if (k < 0) return nb::make_tuple(k, 0, 0, false, 0.0, 0.0, 0.0);
    } else {
      hessian_core(sw_.data(), lambda2, qp.H.p, qp.g.p);
      copy_core(qp.C.p, qp.l.p, qp.u.p, qp.lb.p, qp.ub.p);
    }
    auto t1 = std::chrono::steady_clock::now();
    DaqpOut o = daqp_core(qp.H.p, qp.g.p, qp.C.p, qp.l.p, qp.u.p, qp.lb.p, qp.ub.p, qp.n, nin,
                          qp.x.p, qp.lam.p, qp.warm, qp.primal_tol, qp.dual_tol, qp.iter_limit,
                          qp.eps_prox, false, qp.shortcut);
    auto t2 = std::chrono::steady_clock::now();
    double smax = 0.0;
    if (o.ok) {
      double *x = qp.x.p;
      for (int i = 0; i < nv; ++i) x[i] = std::min(std::max(x[i], lb.p[i]), ub.p[i]);
      for (int j = 0; j < k; ++j) smax = std::max(smax, x[nv + j]);
      qn.resize(nv);
      for (int i = 0; i < nv; ++i) qn[i] = x[i] * dt;
      Eigen::Map<Eigen::VectorXd> qo(q_out.data(), model->nq);
      pinocchio::integrate(*model, q, qn, qo);
    }
    double solve_s = std::chrono::duration<double>(t2 - t1).count();
    double asm_s = std::chrono::duration<double>(t1 - t0).count();
    return nb::make_tuple(k, o.flag, o.iters, o.ok, smax, solve_s, asm_s);
  }

};

NB_MODULE(_kernel, m) {
  m.doc() = "qpretarget's compiled per-tick kernel (tasks, bounds, contact rows, augmentation, DAQP)";
  m.attr("PINOCCHIO_VERSION") = PINOCCHIO_VERSION;
  m.def("daqp_load", &daqp_load, "Load DAQP's C entry points from its installed extension module.");
  m.def("daqp_defaults", &daqp_defaults);
  m.def("daqp_solve", &daqp_solve);
  m.def("slack_qp", &slack_qp);
  m.def("geometry_distances", &geometry_distances);
  nb::class_<Tick>(m, "Tick")
      .def(nb::init<nb::handle, nb::handle>())
      .def("set_buffers", &Tick::set_buffers)
      .def("add_frame_task", &Tick::add_frame_task)
      .def("add_com_task", &Tick::add_com_task)
      .def("add_posture_task", &Tick::add_posture_task)
      .def("add_joint_limits", &Tick::add_joint_limits)
      .def("add_const_bounds", &Tick::add_const_bounds)
      .def("add_contacts", &Tick::add_contacts)
      .def("refine_contacts", &Tick::refine_contacts)
      .def("add_polygon", &Tick::add_polygon)
      .def("add_damper", &Tick::add_damper)
      .def("add_damper_bounds", &Tick::add_damper_bounds)
      .def("add_damper_rows", &Tick::add_damper_rows)
      .def("set_merge", &Tick::set_merge)
      .def("box", &Tick::box)
      .def("damper_reset", &Tick::damper_reset)
      .def("damper_after_step", &Tick::damper_after_step)
      .def("damper_state", &Tick::damper_state)
      .def("damper_last_time", &Tick::damper_last_time)
      .def("build", &Tick::build)
      .def("hessian", &Tick::hessian)
      .def("set_qp", &Tick::set_qp)
      .def("set_shortcut", &Tick::set_shortcut)
      .def("fused", &Tick::fused)
      .def("copy_constraints", &Tick::copy_constraints);
}
