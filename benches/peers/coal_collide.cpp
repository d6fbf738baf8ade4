// Collide peer: coal 3.0.3's boolean collision between the convex hulls of two OFF meshes, at the cold poses of
// `sublevel bench` and of the coal peer benchmark (its bench_coal.cpp, not part of this repository): A at
// t ~ U[-2.5, 2.5]^3, q = normalize(U[-1, 1]^4) from mt19937_64 seeded 7 (drawn in that script's order), B at the
// identity. The query a sampling planner asks most: "do these bodies touch?" with no contact details
// (CollisionRequest(NO_REQUEST, 1), security margin 0), so GJK stops as soon as it proves separation or overlap.
// Two ways a coal user asks it: the narrow phase alone (ComputeCollision: coal 3 runs GJK's distance with an early
// break at the margin), and the narrow phase behind the world AABB test that coal's broad-phase managers apply
// first (CollisionObject::computeAABB of the posed hull against the static one's; GJK only when they overlap),
// the counterpart of the bounding spheres and separating axis `sublevel bench` puts before its own solve.
// Each pose: the mean of 20 back-to-back calls. Output, one "key value" line each (times in microseconds):
//   hull_gjk_collide_cold_us           narrow phase: mean over the poses (what `sublevel bench` reports for its own)
//   hull_gjk_collide_cold_median_us    narrow phase: median over the poses
//   hull_aabb_gjk_collide_cold_us      AABB test, then the narrow phase: mean over the poses
//   hull_aabb_gjk_collide_decided      poses the AABB test alone decides (no overlap)
//   hull_gjk_collide_colliding         poses whose hulls touch
//   hull_gjk_collide_poses             poses timed
// Run through scripts/peer-coal-collide, which builds it against the coal wheel the shared script installs.
#include <coal/collision.h>
#include <coal/collision_object.h>
#include <coal/shape/convex.h>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <numeric>
#include <random>
#include <string>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

// The vertices of an OFF file (faces are not needed for a hull); exits with a message on a malformed file.
std::vector<coal::Vec3s> off_vertices(const char* path) {
  std::ifstream in(path);
  std::string magic;
  size_t vertices = 0, faces = 0, edges = 0;
  if (!(in >> magic) || magic != "OFF" || !(in >> vertices >> faces >> edges) || vertices < 4) {
    std::fprintf(stderr, "%s: not an OFF file with at least 4 vertices\n", path);
    std::exit(2);
  }
  std::vector<coal::Vec3s> out(vertices);
  for (auto& v : out) {
    if (!(in >> v[0] >> v[1] >> v[2])) {
      std::fprintf(stderr, "%s: truncated vertex list\n", path);
      std::exit(2);
    }
  }
  return out;
}

std::shared_ptr<coal::ConvexBase> convex_hull(const std::vector<coal::Vec3s>& vertices) {
  auto points = std::make_shared<std::vector<coal::Vec3s>>(vertices);
  std::shared_ptr<coal::ConvexBase> hull(
      coal::ConvexBase::convexHull(points, static_cast<unsigned>(points->size()), true, nullptr));
  hull->computeLocalAABB();
  return hull;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s A.off B.off [cold_poses=300]\n", argv[0]);
    return 2;
  }
  const int poses = argc > 3 ? std::atoi(argv[3]) : 300;
  const int repeats = 20;
  auto a = convex_hull(off_vertices(argv[1]));
  auto b = convex_hull(off_vertices(argv[2]));
  // The shared script's cold poses: the same generator, seed and expressions (the order in which the
  // arguments of one constructor call are drawn is the compiler's, as there).
  std::mt19937_64 g(7);
  std::uniform_real_distribution<double> ut(-2.5, 2.5), uq(-1, 1);
  std::vector<coal::Transform3s> cold(static_cast<size_t>(std::max(poses, 0)));
  for (auto& pose : cold) {
    coal::Vec3s t(ut(g), ut(g), ut(g));
    Eigen::Quaterniond q(uq(g), uq(g), uq(g), uq(g));
    q.normalize();
    pose = coal::Transform3s(q.toRotationMatrix(), t);
  }
  const coal::Transform3s identity = coal::Transform3s::Identity();
  coal::CollisionRequest request(coal::CollisionRequestFlag::NO_REQUEST, 1);
  request.security_margin = 0;
  coal::ComputeCollision collide(a.get(), b.get());
  coal::CollisionResult result;
  // The static body's world AABB once; the posed one's per query, as a broad-phase manager updates it.
  coal::CollisionObject object_a(a, identity), object_b(b, identity);
  object_b.computeAABB();
  std::vector<double> times, times_aabb;
  int colliding = 0, decided = 0;
  for (const auto& pose : cold) {
    bool touching = false;
    auto start = Clock::now();
    for (int r = 0; r < repeats; ++r) {
      result.clear();
      collide(pose, identity, request, result);
      touching = result.isCollision();
    }
    times.push_back(std::chrono::duration<double, std::micro>(Clock::now() - start).count() / repeats);
    colliding += touching ? 1 : 0;
    bool apart = false, touching_aabb = false;
    start = Clock::now();
    for (int r = 0; r < repeats; ++r) {
      object_a.setTransform(pose);
      object_a.computeAABB();
      apart = !object_a.getAABB().overlap(object_b.getAABB());
      touching_aabb = false;
      if (!apart) {
        result.clear();
        collide(pose, identity, request, result);
        touching_aabb = result.isCollision();
      }
    }
    times_aabb.push_back(std::chrono::duration<double, std::micro>(Clock::now() - start).count() / repeats);
    decided += apart ? 1 : 0;
    if (touching_aabb != touching) {
      std::fprintf(stderr, "the AABB test changed an answer\n");
      return 1;
    }
  }
  if (times.empty()) {
    std::fprintf(stderr, "no poses\n");
    return 2;
  }
  const double mean = std::accumulate(times.begin(), times.end(), 0.0) / times.size();
  const double mean_aabb = std::accumulate(times_aabb.begin(), times_aabb.end(), 0.0) / times_aabb.size();
  std::sort(times.begin(), times.end());
  const size_t n = times.size();
  const double median = n % 2 ? times[n / 2] : 0.5 * (times[n / 2 - 1] + times[n / 2]);
  std::printf("hull_gjk_collide_cold_us %.4f\nhull_gjk_collide_cold_median_us %.4f\n", mean, median);
  std::printf("hull_aabb_gjk_collide_cold_us %.4f\nhull_aabb_gjk_collide_decided %d\n", mean_aabb, decided);
  std::printf("hull_gjk_collide_colliding %d\nhull_gjk_collide_poses %zu\n", colliding, n);
  return 0;
}
