// Peer timing bench: coal 3.0.3 distance and collision queries between primitive shapes.
//
// Reads the cases written by scripts/peers/coal_primitives.py (only the pair and pose columns) and prints,
// per pair type, one JSON line {"pair", "cases", "cold_ns", "warm_ns", "collide_ns"}, after one JSON line
// with coal's query settings (coal's defaults, untouched). Build and run it with
//     bash scripts/peers/coal_primitives.sh crates/query/tests/data/coal_primitives.csv
//
//   cold_ns:    coal::distance(shape, tf, shape, tf, request, result) with a fresh DistanceRequest and
//               DistanceResult per call (default initial guess); per case the mean of 20 back-to-back calls,
//               the median over the pair's cases.
//   warm_ns:    a motion per case: B moves 1 mm per step along a fixed direction and turns 0.5 mrad per step
//               about a fixed axis (world frame), 50 steps; the request carries coal's cached GJK guess from
//               step to step (gjk_initial_guess = CachedGuess, request.updateGuess(result) after each call,
//               timed with the call). Per case the mean over steps 1..49 of 20 runs of the motion (step 0
//               starts each run from the default guess, untimed); the median over cases. Pairs that coal
//               solves in closed form (sphere, halfspace and capsule-capsule pairs) have no guess to reuse.
//   collide_ns: coal::collide with a fresh CollisionRequest(NO_REQUEST, 1) and CollisionResult per call: the
//               boolean query of the project's collide peer (benches/peers/coal_collide.cpp), no contact or
//               penetration computed, margin 0. (coal's default CollisionRequest() has enable_contact on and
//               costs about a cold distance call.) Per case the mean of 20 calls, the median over cases.
#include <coal/collision.h>
#include <coal/config.hh>
#include <coal/distance.h>
#include <coal/shape/geometric_shapes.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

using namespace coal;
using clk = std::chrono::steady_clock;
using Shape = std::shared_ptr<CollisionGeometry>;

// The pair types of coal_primitives.py, shapes in meters (Box: full sides; Cylinder, Capsule: radius, full
// length along z; Halfspace: {x : n.x <= d}).
static std::pair<Shape, Shape> make_pair_shapes(const std::string& pair) {
  auto box = [] { return std::make_shared<Box>(0.4, 0.3, 0.2); };
  auto slab = [] { return std::make_shared<Box>(1.2, 1.0, 0.04); };
  auto rod = [] { return std::make_shared<Cylinder>(0.05, 0.3); };
  auto can = [] { return std::make_shared<Cylinder>(0.1, 0.2); };
  auto ball = [] { return std::make_shared<Sphere>(0.1); };
  auto capsule = [] { return std::make_shared<Capsule>(0.05, 0.3); };
  auto floor = [] { return std::make_shared<Halfspace>(Vec3s(0, 0, 1), 0.0); };
  if (pair == "box-box") return {box(), slab()};
  if (pair == "box-cylinder") return {box(), rod()};
  if (pair == "cylinder-cylinder") return {rod(), can()};
  if (pair == "sphere-sphere") return {ball(), std::make_shared<Sphere>(0.25)};
  if (pair == "sphere-box") return {ball(), box()};
  if (pair == "sphere-cylinder") return {ball(), rod()};
  if (pair == "capsule-capsule") return {capsule(), std::make_shared<Capsule>(0.08, 0.2)};
  if (pair == "capsule-box") return {capsule(), box()};
  if (pair == "capsule-cylinder") return {capsule(), can()};
  if (pair == "halfspace-box") return {floor(), box()};
  if (pair == "halfspace-cylinder") return {floor(), rod()};
  if (pair == "halfspace-capsule") return {floor(), capsule()};
  if (pair == "halfspace-sphere") return {floor(), ball()};
  fprintf(stderr, "unknown pair type %s\n", pair.c_str());
  exit(2);
}

struct Case { Transform3s a, b; };

static std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out; std::stringstream ss(line); std::string f;
  while (std::getline(ss, f, ',')) out.push_back(f);
  return out;
}

// Cases grouped by pair type, in the order the types first appear in the file.
static std::vector<std::pair<std::string, std::vector<Case>>> load(const char* fn) {
  std::ifstream in(fn);
  if (!in) { fprintf(stderr, "cannot read %s\n", fn); exit(2); }
  std::string line; std::getline(in, line);
  auto header = split(line);
  auto col = [&](const std::string& name) {
    auto it = std::find(header.begin(), header.end(), name);
    if (it == header.end()) { fprintf(stderr, "%s: no column %s\n", fn, name.c_str()); exit(2); }
    return size_t(it - header.begin());
  };
  const size_t pair = col("pair");
  auto pose = [&](const std::vector<std::string>& f, const std::string& s) {
    auto v = [&](const std::string& c) { return strtod(f[col(c)].c_str(), nullptr); };
    Eigen::Quaterniond q(v("q" + s + "_w"), v("q" + s + "_x"), v("q" + s + "_y"), v("q" + s + "_z"));
    return Transform3s(q.toRotationMatrix(), Vec3s(v("t" + s + "_x"), v("t" + s + "_y"), v("t" + s + "_z")));
  };
  std::vector<std::pair<std::string, std::vector<Case>>> groups;
  std::map<std::string, size_t> index;
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    auto f = split(line);
    auto it = index.find(f[pair]);
    if (it == index.end()) { it = index.emplace(f[pair], groups.size()).first; groups.push_back({f[pair], {}}); }
    groups[it->second].second.push_back({pose(f, "a"), pose(f, "b")});
  }
  return groups;
}

static double median(std::vector<double> v) {
  std::sort(v.begin(), v.end()); size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}
static double ns_since(clk::time_point t0) { return std::chrono::duration<double, std::nano>(clk::now() - t0).count(); }

int main(int argc, char** argv) {
  if (argc != 2) { fprintf(stderr, "usage: %s CASES.csv\n", argv[0]); return 2; }
  const int reps = 20, steps = 50;
  const double step_m = 1e-3, step_rad = 5e-4;
  const Vec3s dir = Vec3s(1.0, -2.0, 0.5).normalized(), axis = Vec3s(0.3, 0.4, 1.0).normalized();
  auto groups = load(argv[1]);

  const DistanceRequest dq; const CollisionRequest cq(CollisionRequestFlag::NO_REQUEST, 1);
  printf("{\"coal\": \"%s\", \"settings\": \"coal defaults\", \"gjk_tolerance\": %g, \"gjk_max_iterations\": %zu, "
         "\"gjk_variant\": \"DefaultGJK\", \"gjk_convergence_criterion\": \"Default/Relative\", "
         "\"epa_tolerance\": %g, \"epa_max_iterations\": %zu, \"enable_signed_distance\": %s, "
         "\"collision_request\": \"NO_REQUEST, 1 contact\", \"collision_gjk_tolerance\": %g, "
         "\"collision_distance_threshold\": %g, \"security_margin\": %g, "
         "\"reps\": %d, \"warm_steps\": %d, \"warm_step_m\": %g, \"warm_step_rad\": %g}\n",
         COAL_VERSION, dq.gjk_tolerance, dq.gjk_max_iterations, dq.epa_tolerance, dq.epa_max_iterations,
         dq.enable_signed_distance ? "true" : "false", cq.gjk_tolerance, cq.collision_distance_threshold,
         cq.security_margin, reps, steps, step_m, step_rad);
  if (dq.gjk_variant != GJKVariant::DefaultGJK || dq.gjk_convergence_criterion != GJKConvergenceCriterion::Default ||
      dq.gjk_convergence_criterion_type != GJKConvergenceCriterionType::Relative) {
    fprintf(stderr, "coal's default GJK variant or criterion differ from the ones printed\n"); return 2;
  }

  volatile double sink = 0;  // keeps the calls from being optimised away
  for (auto& [pair, cases] : groups) {
    auto [sa, sb] = make_pair_shapes(pair);
    const CollisionGeometry *a = sa.get(), *b = sb.get();
    std::vector<double> cold, warm, coll;
    for (const Case& c : cases) {
      auto t0 = clk::now();
      for (int r = 0; r < reps; ++r) {
        DistanceRequest rq; DistanceResult rs;
        sink = sink + distance(a, c.a, b, c.b, rq, rs);
      }
      cold.push_back(ns_since(t0) / reps);

      std::vector<Transform3s> path(steps);
      for (int k = 0; k < steps; ++k)
        path[k] = Transform3s(Eigen::AngleAxisd(k * step_rad, axis).toRotationMatrix() * c.b.getRotation(),
                              c.b.getTranslation() + k * step_m * dir);
      double t = 0;
      for (int r = 0; r < reps; ++r) {
        DistanceRequest rq; rq.gjk_initial_guess = GJKInitialGuess::CachedGuess; DistanceResult rs;
        sink = sink + distance(a, c.a, b, path[0], rq, rs);
        rq.updateGuess(rs);
        auto t1 = clk::now();
        for (int k = 1; k < steps; ++k) {
          rs.clear();
          sink = sink + distance(a, c.a, b, path[k], rq, rs);
          rq.updateGuess(rs);
        }
        t += ns_since(t1);
      }
      warm.push_back(t / (reps * (steps - 1)));

      t0 = clk::now();
      for (int r = 0; r < reps; ++r) {
        CollisionRequest rq(CollisionRequestFlag::NO_REQUEST, 1); CollisionResult rs;
        sink = sink + double(collide(a, c.a, b, c.b, rq, rs));
      }
      coll.push_back(ns_since(t0) / reps);
    }
    printf("{\"pair\": \"%s\", \"cases\": %zu, \"cold_ns\": %.1f, \"warm_ns\": %.1f, \"collide_ns\": %.1f}\n",
           pair.c_str(), cases.size(), median(cold), median(warm), median(coll));
  }
  return 0;
}
