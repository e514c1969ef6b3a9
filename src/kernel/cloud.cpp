// SPDX-License-Identifier: Apache-2.0
// qpretarget's compiled point-cloud kernel (qpretarget/_cloud): the inner loops of the point-cloud
// fit (qpretarget/cloud/estep.py, io.py) in C++. Optional, like the controller's _kernel: without it
// qpretarget.cloud runs its numpy code, with the same results (tests/cloud/test_compiled.py).
//
//  * knn: exact k nearest neighbours (a kd-tree, Euclidean), the squared distances computed as
//    pykdtree and the numpy E-step compute them (sum over the coordinates in order of the squared
//    differences), so that the same neighbours come with the same distances to the bit.
//  * estep: the k-d tree E-step's posteriors (log-sum-exp over each cloud point's k pairs) and the
//    posterior-weighted sums P^T [1 S Sn] the M-step needs, in the order of operations of the numpy
//    code (estep._log_posteriors, then scipy's CSC product), so that its results are the same to the bit.
//  * scatter: the 3x3 scatter matrices of each point's neighbours (io.estimate_normals).
//
// The searches and the E-step's posteriors run on `threads` threads (Pool below): each cloud
// point's are computed alone, and the sums over the points in one fixed order, so the results do
// not depend on the number of threads.
//
// Built without -march=native and with -ffp-contract=off: no fused multiply-adds, which would
// round differently from numpy.

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/pair.h>
#include <nanobind/stl/tuple.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <thread>
#include <vector>

namespace nb = nanobind;

namespace {

using CArr2 = nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using CIArr2 = nb::ndarray<const int64_t, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Out1 = nb::ndarray<nb::numpy, double, nb::ndim<1>>;
using Out2 = nb::ndarray<nb::numpy, double, nb::ndim<2>>;
using Out3 = nb::ndarray<nb::numpy, double, nb::ndim<3>>;
using OutI2 = nb::ndarray<nb::numpy, int64_t, nb::ndim<2>>;

template <class T>
nb::capsule owner_of(T *p) {
  return nb::capsule(p, [](void *q) noexcept { delete[] static_cast<T *>(q); });
}

// ------------------------------------------------------------------------------------ threads
// Helper threads kept between calls. A job is split in chunks handed out one at a time; the
// calling thread works through them too and then waits only for the helpers that took part (a
// helper that did not get a core before the chunks ran out is not waited for). Every chunk is
// computed the same way whichever thread runs it. On a loaded machine a helper that took a chunk
// can lose its core, and the caller then waits for it: when a job's helpers took part in none of
// it or kept the caller waiting for more than a tenth of the job, the next BACKOFF jobs run on
// the calling thread alone (then helpers are tried again); and no helper is woken while every
// core is running a thread (free_core).
class Pool {
 public:
  static constexpr int BACKOFF = 32;

  // Run fn(chunk) for chunk in [0, chunks) on the caller and up to `helpers` helper threads.
  template <class F>
  void run(int chunks, int helpers, F &&fn) {
    helpers = std::min(helpers, chunks - 1);
    // One job at a time: a job started while another thread's runs gets no helpers.
    std::unique_lock<std::mutex> one(serial_, std::try_to_lock);
    if (!one.owns_lock()) helpers = 0;
    if (helpers > 0 && skip_ > 0) {
      --skip_;
      helpers = 0;
    }
    if (helpers > 0 && !free_core()) helpers = 0;
    if (helpers <= 0) {
      if (one.owns_lock()) one.unlock();
      for (int c = 0; c < chunks; ++c) fn(c);
      return;
    }
    ensure(helpers);
    Job job{[&fn](int c) { fn(c); }, chunks};
    auto t0 = std::chrono::steady_clock::now();
    {
      std::lock_guard<std::mutex> lk(m_);
      job_ = &job;
      wanted_ = helpers;
      ++gen_;
      open_.store(true);
    }
    cv_.notify_all();
    int mine = work(job);
    open_.store(false);
    auto t1 = std::chrono::steady_clock::now();
    while (running_.load() > 0) std::this_thread::yield();
    auto t2 = std::chrono::steady_clock::now();
    {
      std::lock_guard<std::mutex> lk(m_);
      job_ = nullptr;
    }
    if (mine == chunks || (t2 - t1) * 10 > (t1 - t0)) skip_ = BACKOFF;
  }

  ~Pool() {
    {
      std::lock_guard<std::mutex> lk(m_);
      stop_ = true;
    }
    cv_.notify_all();
    for (auto &t : threads_) t.join();
  }

 private:
  struct Job {
    std::function<void(int)> fn;
    int chunks;
    std::atomic<int> next{0};
  };
  // Whether a core is free for a helper: fewer threads running now (/proc/loadavg's fourth
  // field, this one included) than cores. Read at most once a millisecond; true where the file
  // does not exist.
  bool free_core() {
    auto now = std::chrono::steady_clock::now();
    if (now - checked_ < std::chrono::milliseconds(1)) return free_;
    checked_ = now;
    free_ = true;
    if (FILE *f = std::fopen("/proc/loadavg", "r")) {
      double l1, l5, l15;
      int running = 0, total = 0;
      if (std::fscanf(f, "%lf %lf %lf %d/%d", &l1, &l5, &l15, &running, &total) == 5)
        free_ = running < int(std::max(1u, std::thread::hardware_concurrency()));
      std::fclose(f);
    }
    return free_;
  }

  static int work(Job &job) {  // the chunks done by this thread
    int done = 0;
    for (int c; (c = job.next.fetch_add(1)) < job.chunks; ++done) job.fn(c);
    return done;
  }
  void ensure(int n) {
    while (int(threads_.size()) < n) {
      int me = int(threads_.size());
      threads_.emplace_back([this, me] { loop(me); });
    }
  }
  void loop(int me) {
    uint64_t seen = 0;
    for (;;) {
      Job *job = nullptr;
      {
        std::unique_lock<std::mutex> lk(m_);
        cv_.wait(lk, [&] { return stop_ || gen_ != seen; });
        if (stop_) return;
        seen = gen_;
        if (me >= wanted_) continue;
        if (!open_.load()) continue;  // the job is over already
        job = job_;
        running_.fetch_add(1);  // before reading open_ again: run() waits for this helper if open
      }
      if (job && open_.load()) work(*job);
      running_.fetch_sub(1);
    }
  }
  std::mutex serial_, m_;
  std::condition_variable cv_;
  std::vector<std::thread> threads_;
  Job *job_ = nullptr;
  int wanted_ = 0;
  int skip_ = 0;  // jobs left to run on the calling thread alone (backoff)
  bool free_ = true;
  std::chrono::steady_clock::time_point checked_{};
  uint64_t gen_ = 0;
  bool stop_ = false;
  std::atomic<bool> open_{false};
  std::atomic<int> running_{0};
};

Pool &pool() {
  static Pool *p = new Pool();  // never destroyed: no joins at interpreter exit
  return *p;
}

// ------------------------------------------------------------------------------------ kd-tree
constexpr int LEAF = 12;

struct Node {
  int lo, hi;        // range in the permuted points
  int dim;           // split coordinate (-1: leaf)
  double split;      // left: coordinate <= split, right: >= split
  int left, right;   // children
};

template <int D>
struct Tree {
  std::vector<double> pts;  // permuted points, D per point
  std::vector<int64_t> id;  // original index of each permuted point
  std::vector<Node> nodes;

  Tree(const double *data, int m) : pts(size_t(m) * D), id(m) {
    std::vector<int> perm(m);
    for (int i = 0; i < m; ++i) perm[i] = i;
    nodes.reserve(size_t(2 * m / LEAF + 2));
    build(data, perm, 0, m);
    for (int i = 0; i < m; ++i) {
      id[i] = perm[i];
      for (int c = 0; c < D; ++c) pts[size_t(i) * D + c] = data[size_t(perm[i]) * D + c];
    }
  }

  int build(const double *data, std::vector<int> &perm, int lo, int hi) {
    int me = int(nodes.size());
    nodes.push_back(Node{lo, hi, -1, 0.0, -1, -1});
    if (hi - lo <= LEAF) return me;
    // Split the widest coordinate at its median.
    double mn[D], mx[D];
    for (int c = 0; c < D; ++c) mn[c] = mx[c] = data[size_t(perm[lo]) * D + c];
    for (int i = lo + 1; i < hi; ++i)
      for (int c = 0; c < D; ++c) {
        double v = data[size_t(perm[i]) * D + c];
        mn[c] = std::min(mn[c], v);
        mx[c] = std::max(mx[c], v);
      }
    int dim = 0;
    for (int c = 1; c < D; ++c)
      if (mx[c] - mn[c] > mx[dim] - mn[dim]) dim = c;
    if (!(mx[dim] > mn[dim])) return me;  // all equal: one leaf
    int mid = lo + (hi - lo) / 2;
    std::nth_element(perm.begin() + lo, perm.begin() + mid, perm.begin() + hi, [&](int a, int b) {
      return data[size_t(a) * D + dim] < data[size_t(b) * D + dim];
    });
    double split = data[size_t(perm[mid]) * D + dim];
    int l = build(data, perm, lo, mid);
    int r = build(data, perm, mid, hi);
    Node &n = nodes[me];
    n.dim = dim;
    n.split = split;
    n.left = l;
    n.right = r;
    return me;
  }

  // The k best so far, ascending (dist, index into pts); worst = dist[k-1].
  struct Best {
    double *d;
    int64_t *i;
    int k;
    void insert(double dd, int64_t ii) {
      int j = k - 1;
      while (j > 0 && d[j - 1] > dd) {
        d[j] = d[j - 1];
        i[j] = i[j - 1];
        --j;
      }
      d[j] = dd;
      i[j] = ii;
    }
  };

  void search(int ni, const double *q, double *off, double rd, Best &best) const {
    const Node &n = nodes[ni];
    if (n.dim < 0) {
      for (int p = n.lo; p < n.hi; ++p) {
        const double *x = &pts[size_t(p) * D];
        double d = 0.0;
        for (int c = 0; c < D; ++c) {
          double t = x[c] - q[c];
          d += t * t;
        }
        if (d < best.d[best.k - 1]) best.insert(d, p);
      }
      return;
    }
    double diff = q[n.dim] - n.split;
    int near = diff < 0 ? n.left : n.right, far = diff < 0 ? n.right : n.left;
    search(near, q, off, rd, best);
    double old = off[n.dim];
    double rd_far = rd - old * old + diff * diff;
    if (rd_far <= best.d[best.k - 1]) {
      off[n.dim] = diff;
      search(far, q, off, rd_far, best);
      off[n.dim] = old;
    }
  }

  void query(const double *q, int k, double *d2, int64_t *idx) const {
    for (int j = 0; j < k; ++j) {
      d2[j] = std::numeric_limits<double>::infinity();
      idx[j] = -1;
    }
    Best best{d2, idx, k};
    double off[D] = {};
    search(0, q, off, 0.0, best);
  }
};

template <int D>
void knn_dim(const double *data, int m, const double *query, int n, int k, double *d2,
             int64_t *idx, int threads) {
  Tree<D> tree(data, m);
  constexpr int CHUNK = 64;
  pool().run((n + CHUNK - 1) / CHUNK, threads - 1, [&](int c) {
    int a = c * CHUNK, b = std::min(n, a + CHUNK);
    for (int i = a; i < b; ++i) {
      double *di = d2 + size_t(i) * k;
      int64_t *ii = idx + size_t(i) * k;
      tree.query(query + size_t(i) * D, k, di, ii);
      for (int j = 0; j < k; ++j) ii[j] = tree.id[size_t(ii[j])];
    }
  });
}

std::pair<Out2, OutI2> knn(CArr2 data, CArr2 query, int k, int threads) {
  size_t m = data.shape(0), n = query.shape(0), d = data.shape(1);
  if (query.shape(1) != d) throw std::invalid_argument("data and query differ in dimension");
  if (k < 1 || size_t(k) > m) throw std::invalid_argument("k must be in [1, len(data)]");
  double *d2 = new double[std::max<size_t>(n * k, 1)];
  int64_t *idx = new int64_t[std::max<size_t>(n * k, 1)];
  {
    nb::gil_scoped_release release;
    if (d == 3)
      knn_dim<3>(data.data(), int(m), query.data(), int(n), k, d2, idx, threads);
    else if (d == 6)
      knn_dim<6>(data.data(), int(m), query.data(), int(n), k, d2, idx, threads);
    else {
      delete[] d2;
      delete[] idx;
      throw std::invalid_argument("knn: only 3 or 6 coordinates");
    }
  }
  return {Out2(d2, {n, size_t(k)}, owner_of(d2)), OutI2(idx, {n, size_t(k)}, owner_of(idx))};
}

// ------------------------------------------------------------------------------------ E-step
// numpy's logaddexp (npy_math_internal.h.src, npy_logaddexp).
inline double logaddexp(double x, double y) {
  if (x == y) return x + 0.693147180559945309417232121458176568;
  double tmp = x - y;
  if (tmp > 0) return x + std::log1p(std::exp(-tmp));
  if (tmp <= 0) return y + std::log1p(std::exp(tmp));
  return tmp;
}

// See estep._kdtree_sums / estep._log_posteriors. d2 empty (0 rows): computed from the pairs.
std::tuple<Out1, Out1, Out2> estep(CArr2 B, CArr2 A, CIArr2 pairs, CArr2 d2in, double sigma2,
                                   double log_in, double log_out, CArr2 cols, int64_t mtot,
                                   int threads) {
  size_t n = pairs.shape(0), k = pairs.shape(1), d = B.shape(1), nc = cols.shape(1);
  bool given = d2in.shape(0) != 0;
  if (B.shape(0) != n || cols.shape(0) != n || A.shape(1) != d)
    throw std::invalid_argument("estep: inconsistent shapes");
  if (given && (d2in.shape(0) != n || d2in.shape(1) != k))
    throw std::invalid_argument("estep: d2 must be (N, k)");
  double *logp = new double[std::max<size_t>(n, 1)];
  double *w = new double[std::max<size_t>(n, 1)];
  double *R = new double[std::max<size_t>(size_t(mtot) * nc, 1)]();
  const int64_t *pr = pairs.data();
  const double *a_ = A.data(), *b_ = B.data(), *c_ = cols.data();
  const double *g = given ? d2in.data() : nullptr;
  size_t na = A.shape(0);
  for (size_t i = 0; i < n * k; ++i)
    if (pr[i] < 0 || size_t(pr[i]) >= size_t(mtot) || (!given && size_t(pr[i]) >= na)) {
      delete[] logp;
      delete[] w;
      delete[] R;
      throw std::invalid_argument("estep: pair index out of range");
    }
  {
    nb::gil_scoped_release release;
    const double f = -0.5 / sigma2;
    // Posteriors point by point (in chunks, on `threads` threads), then the sums in order.
    std::vector<double> post(n * k);
    constexpr size_t CHUNK = 128;
    pool().run(int((n + CHUNK - 1) / CHUNK), threads - 1, [&](int ch) {
      size_t i0 = size_t(ch) * CHUNK, i1 = std::min(n, i0 + CHUNK);
      for (size_t i = i0; i < i1; ++i) {
        double *a = &post[i * k];
        const int64_t *p = pr + i * k;
        for (size_t j = 0; j < k; ++j) {
          double v;
          if (given) {
            v = g[i * k + j];
          } else {
            v = 0.0;
            const double *x = a_ + size_t(p[j]) * d, *s = b_ + i * d;
            for (size_t c = 0; c < d; ++c) {
              double t = s[c] - x[c];
              v += t * t;
            }
          }
          a[j] = v * f;
        }
        double amax = a[0];
        for (size_t j = 1; j < k; ++j) amax = std::max(amax, a[j]);  // no NaNs here
        double sum = 0.0;
        for (size_t j = 0; j < k; ++j) {
          a[j] = std::exp(a[j] - amax);
          sum = j ? sum + a[j] : a[j];
        }
        double lse = amax + std::log(sum);
        double lp = logaddexp(log_in + lse, log_out);
        double scale = std::exp(log_in + amax - lp);
        logp[i] = lp;
        double ws = 0.0;
        for (size_t j = 0; j < k; ++j) {
          a[j] *= scale;
          ws = j ? ws + a[j] : a[j];
        }
        w[i] = ws;
      }
    });
    // scipy's CSC product P^T cols: cloud point by cloud point, pair by pair.
    for (size_t i = 0; i < n; ++i) {
      const int64_t *p = pr + i * k;
      const double *ci = c_ + i * nc, *a = &post[i * k];
      for (size_t j = 0; j < k; ++j) {
        double *r = R + size_t(p[j]) * nc;
        for (size_t c = 0; c < nc; ++c) r[c] += a[j] * ci[c];
      }
    }
  }
  return {Out1(logp, {n}, owner_of(logp)), Out1(w, {n}, owner_of(w)),
          Out2(R, {size_t(mtot), nc}, owner_of(R))};
}

// ------------------------------------------------------------------------------------ normals
// Scatter matrices (n, 3, 3) of each point's k neighbours about their mean (io.estimate_normals).
Out3 scatter(CArr2 points, CIArr2 idx) {
  size_t n = idx.shape(0), k = idx.shape(1), np_ = points.shape(0);
  if (points.shape(1) != 3) throw std::invalid_argument("scatter: points must be (N, 3)");
  const int64_t *ix = idx.data();
  for (size_t i = 0; i < n * k; ++i)
    if (ix[i] < 0 || size_t(ix[i]) >= np_) throw std::invalid_argument("scatter: index out of range");
  double *C = new double[std::max<size_t>(n * 9, 1)];
  {
    nb::gil_scoped_release release;
    const double *x = points.data();
    std::vector<double> cs(3 * k);
    for (size_t i = 0; i < n; ++i) {
      const int64_t *p = ix + i * k;
      for (int a = 0; a < 3; ++a) {
        double s = 0.0;
        for (size_t j = 0; j < k; ++j) {
          double v = x[size_t(p[j]) * 3 + a];
          cs[a * k + j] = v;
          s = j ? s + v : v;
        }
        double mean = s / double(k);
        for (size_t j = 0; j < k; ++j) cs[a * k + j] -= mean;
      }
      double *Ci = C + i * 9;
      for (int a = 0; a < 3; ++a)
        for (int b = a; b < 3; ++b) {
          double s = 0.0;
          for (size_t j = 0; j < k; ++j) {
            double v = cs[a * k + j] * cs[b * k + j];
            s = j ? s + v : v;
          }
          Ci[a * 3 + b] = Ci[b * 3 + a] = s;
        }
    }
  }
  return Out3(C, {n, size_t(3), size_t(3)}, owner_of(C));
}

}  // namespace

NB_MODULE(_cloud, m) {
  m.doc() = "qpretarget's compiled point-cloud kernel (k-d tree searches, E-step sums, normals)";
  m.def("knn", &knn, nb::arg("data"), nb::arg("query"), nb::arg("k"), nb::arg("threads") = 1,
        "Exact k nearest neighbours: (squared distances (N, k) ascending, indices (N, k)).");
  m.def("estep", &estep, nb::arg("B"), nb::arg("A"), nb::arg("pairs"), nb::arg("d2"),
        nb::arg("sigma2"), nb::arg("log_in"), nb::arg("log_out"), nb::arg("cols"), nb::arg("mtot"), nb::arg("threads") = 1,
        "k-d tree E-step: (log p(s_n) (N,), posterior mass per cloud point (N,), P^T cols (Mtot, c)).");
  m.def("scatter", &scatter, nb::arg("points"), nb::arg("idx"),
        "Scatter matrices (n, 3, 3) of each point's neighbours idx (n, k) about their mean.");
  m.attr("ABI") = 1;
}
