#!/usr/bin/env python3
"""Reference distances between primitive shapes from coal 3.0.3 (the collision library, ex hpp-fcl).

Writes a CSV of random pose pairs with coal's signed distance, nearest points and collision flag, for the
13 pair types below, and prints an accuracy summary of coal's answers to stderr.

    python scripts/peers/coal_primitives.py --per-pair 150 --seed 7 \
        --output crates/query/tests/data/coal_primitives.csv

Needs numpy and coal==3.0.3 (`pip install coal==3.0.3`; scripts/peers/coal_primitives.sh makes such a venv
under ${COAL_WORK:-/tmp/coal-peer}). The output is deterministic for a given seed (numpy's PCG64).

Shapes (coal's constructors, meters, each centered at the origin of its frame):
    Box(x, y, z)      full side lengths
    Sphere(r)
    Cylinder(r, h)    axis z, full height h
    Capsule(r, h)     axis segment [-h/2, h/2] on z, radius r
    Halfspace(n, d)   {x : n.x <= d}; always shape A of its pair

Poses. Each case draws two uniformly random rotations (unit quaternions, w >= 0) and A's translation uniformly
in [-0.2, 0.2]^3. For the convex pairs B's translation is A's plus a random direction times a center distance
uniform in [0.3, 1.3] x (sum of the bounding-sphere radii). For halfspace pairs B is placed at a signed
distance uniform in [-0.25, 0.75] x (B's bounding radius) from the plane, plus a tangential offset uniform in
[-0.2, 0.2]^3 projected onto the plane. Exactly round(0.75 N) cases of each pair are separated: a draw whose
coal.collide verdict is not the one wanted for its case is redrawn, and so is a draw where coal's answer
fails the checks below (EPA failure, or off the reference by more than 1e-9).

Columns (one header row; numbers are Python repr, so they read back bit for bit):
    pair                    e.g. "box-cylinder": shape A then shape B, as in PAIRS below
    qa_w..qa_z, ta_x..ta_z  pose of A: rotation quaternion (w, x, y, z; w >= 0, unit) and translation
    qb_w..qb_z, tb_x..tb_z  pose of B; world point = R(q) p + t, R(q) as Eigen's toRotationMatrix()
    distance                coal.distance with enable_signed_distance (its default): the separation distance
                            when apart, minus the penetration depth when overlapping (negative)
    wa_x..wa_z, wb_x..wb_z  coal's nearest points in the world frame, on A's and on B's boundary. Apart: the
                            closest pair, |wb - wa| = distance. Overlapping: the ends of the penetration
                            vector, wb = wa + distance * normal with normal (not stored) pointing from A to B,
                            so wb is B's deepest point behind A's surface point wa. For the halfspace, wa
                            lies on its plane: the projection of wb onto it.
    overlapping             1 when coal.collide reports a contact (CollisionRequest with the GJK settings
                            below, margin 0; coal counts distance <= 1e-12 as contact), else 0. It agrees
                            with distance <= 0 on every row of the committed file.

Coal settings: DistanceRequest with gjk_tolerance 1e-12, gjk_max_iterations 1000, epa_tolerance 1e-12,
epa_max_iterations 1000, GJK's default variant and convergence criterion (Default, Relative). Tolerances
below 1e-12 gave no better answers (at 1e-14 a capsule-cylinder depth came out 6e-3 too deep).

Checks, run on every draw and summarised per pair on stderr:
  * reference: the closed form for sphere-sphere, sphere-box, sphere-cylinder (the shape's exact signed
    distance at the center, minus r), capsule-capsule (segment distance minus both radii) and halfspace-X
    (n.t_B - h_B(-n) - d). For box-box, box-cylinder, cylinder-cylinder, capsule-box and capsule-cylinder it
    is the largest s(u) = min_B u.x - max_A u.x found over unit directions u (a 4000-point grid, then a
    shrinking random search from the best grid points and from coal's normal). Any s(u) is a lower bound on
    the true signed distance, apart or overlapping, and the signed distance is the max of s.
  * bracket (apart): s(coal's normal) <= true distance <= |wb - wa| (witnesses on the shapes).
  * witness gap | |wb - wa| - |distance| | and each witness's distance to its own surface.

Accuracy measured with these settings (committed file: --per-pair 150 --seed 7; max over the rows):
  * closed-form pairs: within 4.4e-16 of the closed form, apart and overlapping.
  * GJK/EPA pairs: coal's distance is at most 8.3e-11 below the certified lower bound for box-box and at
    most 2.8e-11 below it for the others, and at most 2.8e-11 above it; apart, the bracket is at most
    3.4e-11 wide. The grid search alone (40000 points, without coal's normal as a seed) never beat coal by
    more than 7.5e-11 on the committed rows. The box-box excess fits coal's Box support function, which (in
    coal's source) scales the half-sides on a box's negative side by 1 + 1e-10, through a function-static
    flag set on its first call.
  * witnesses: within 7.8e-11 of their surfaces where a box is involved (same cause), 1.6e-11 otherwise;
    | |wb - wa| - |distance| | <= 4.4e-16, and wb - wa = distance * coal's unit normal to 6.7e-16.
  * coal's EPA is unreliable at tight tolerances on curved shapes: at epa_tolerance 1e-12 about 21 % of
    cylinder-cylinder and 8 % of capsule-cylinder penetrations either fail (distance -DBL_MAX) or stop on a
    wrong face (depth 1e-3 to 0.4 m too deep, caught by the reference check), measured over 300 draws. Looser
    tolerances fail less (1e-7: 1 wrong in 1000 cylinder-cylinder draws; 3e-7 and 1e-6: none in 1000) but
    are less accurate: coal's defaults (1e-6) move the committed curved-pair answers by up to 1.0e-6 (apart
    and overlapping; polytope pairs are bit-identical). The committed file redraws 9 cylinder-cylinder and
    2 capsule-cylinder draws for this, so it under-represents the penetrations coal's EPA gets wrong.
"""
import argparse
import sys

import numpy as np

import coal

# name, (kind, params) of A, (kind, params) of B
PAIRS = [
    ("box-box", ("box", (0.4, 0.3, 0.2)), ("box", (1.2, 1.0, 0.04))),
    ("box-cylinder", ("box", (0.4, 0.3, 0.2)), ("cylinder", (0.05, 0.3))),
    ("cylinder-cylinder", ("cylinder", (0.05, 0.3)), ("cylinder", (0.1, 0.2))),
    ("sphere-sphere", ("sphere", (0.1,)), ("sphere", (0.25,))),
    ("sphere-box", ("sphere", (0.1,)), ("box", (0.4, 0.3, 0.2))),
    ("sphere-cylinder", ("sphere", (0.1,)), ("cylinder", (0.05, 0.3))),
    ("capsule-capsule", ("capsule", (0.05, 0.3)), ("capsule", (0.08, 0.2))),
    ("capsule-box", ("capsule", (0.05, 0.3)), ("box", (0.4, 0.3, 0.2))),
    ("capsule-cylinder", ("capsule", (0.05, 0.3)), ("cylinder", (0.1, 0.2))),
    ("halfspace-box", ("halfspace", ((0.0, 0.0, 1.0), 0.0)), ("box", (0.4, 0.3, 0.2))),
    ("halfspace-cylinder", ("halfspace", ((0.0, 0.0, 1.0), 0.0)), ("cylinder", (0.05, 0.3))),
    ("halfspace-capsule", ("halfspace", ((0.0, 0.0, 1.0), 0.0)), ("capsule", (0.05, 0.3))),
    ("halfspace-sphere", ("halfspace", ((0.0, 0.0, 1.0), 0.0)), ("sphere", (0.1,))),
]
COLUMNS = ("pair,qa_w,qa_x,qa_y,qa_z,ta_x,ta_y,ta_z,qb_w,qb_x,qb_y,qb_z,tb_x,tb_y,tb_z,"
           "distance,wa_x,wa_y,wa_z,wb_x,wb_y,wb_z,overlapping")
SEPARATED_FRACTION = 0.75
EPA_FAILED = -1e300  # coal returns -DBL_MAX as the distance when EPA fails
MAX_ERROR = 1e-9  # a draw whose coal distance is further than this from the reference is redrawn


def make_shape(kind, p):
    if kind == "box":
        return coal.Box(*p)
    if kind == "sphere":
        return coal.Sphere(*p)
    if kind == "cylinder":
        return coal.Cylinder(*p)
    if kind == "capsule":
        return coal.Capsule(*p)
    if kind == "halfspace":
        return coal.Halfspace(np.array(p[0]), p[1])
    raise ValueError(kind)


def bounding_radius(kind, p):
    if kind == "box":
        return 0.5 * float(np.linalg.norm(p))
    if kind == "sphere":
        return p[0]
    if kind == "cylinder":
        return float(np.hypot(p[0], 0.5 * p[1]))
    if kind == "capsule":
        return p[0] + 0.5 * p[1]
    raise ValueError(kind)


def support(kind, p, u):
    """max over the shape (local frame, centered) of u.x, for one direction u (3,) or many (m, 3); u need not
    be unit. Not for the halfspace (unbounded)."""
    u = np.asarray(u)
    if kind == "box":
        return 0.5 * np.abs(u) @ np.asarray(p)
    if kind == "sphere":
        return p[0] * np.linalg.norm(u, axis=-1)
    if kind == "cylinder":
        return p[0] * np.hypot(u[..., 0], u[..., 1]) + 0.5 * p[1] * np.abs(u[..., 2])
    if kind == "capsule":
        return p[0] * np.linalg.norm(u, axis=-1) + 0.5 * p[1] * np.abs(u[..., 2])
    raise ValueError(kind)


def signed_distance(kind, p, x):
    """Exact signed distance from the local point x to the shape's boundary (negative inside)."""
    if kind == "box":
        q = np.abs(x) - 0.5 * np.asarray(p)
        return float(np.linalg.norm(np.maximum(q, 0.0)) + min(q.max(), 0.0))
    if kind == "sphere":
        return float(np.linalg.norm(x)) - p[0]
    if kind == "cylinder":
        q = np.array([np.hypot(x[0], x[1]) - p[0], abs(x[2]) - 0.5 * p[1]])
        return float(np.linalg.norm(np.maximum(q, 0.0)) + min(q.max(), 0.0))
    if kind == "capsule":
        z = np.clip(x[2], -0.5 * p[1], 0.5 * p[1])
        return float(np.linalg.norm(x - np.array([0.0, 0.0, z]))) - p[0]
    if kind == "halfspace":
        return float(np.dot(p[0], x)) - p[1]
    raise ValueError(kind)


def segment_distance(p0, p1, q0, q1):
    """Distance between the segments [p0, p1] and [q0, q1] (Ericson, Real-Time Collision Detection 5.1.9)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e, f = d1 @ d1, d2 @ d2, d2 @ r
    c, b = d1 @ r, d1 @ d2
    den = a * e - b * b
    s = np.clip((b * f - c * e) / den, 0.0, 1.0) if den > 1e-300 else 0.0
    t = (b * s + f) / e
    if t < 0.0:
        t, s = 0.0, np.clip(-c / a, 0.0, 1.0)
    elif t > 1.0:
        t, s = 1.0, np.clip((b - c) / a, 0.0, 1.0)
    return float(np.linalg.norm(p0 + s * d1 - q0 - t * d2))


def has_closed_form(name, A):
    return A[0] in ("halfspace", "sphere") or name == "capsule-capsule"


def closed_form(name, A, B, Ra, ta, Rb, tb):
    """Exact signed distance for the pairs with a closed form, else None."""
    (ka, pa), (kb, pb) = A, B
    if not has_closed_form(name, A):
        return None
    if ka == "halfspace":
        n, d = Ra @ np.asarray(pa[0]), pa[1] + float(Ra @ np.asarray(pa[0]) @ ta)
        return float(n @ tb) - support(kb, pb, Rb.T @ -n) - d
    if ka == "sphere":  # sphere vs a convex shape: the shape's signed distance at the center, minus r
        return signed_distance(kb, pb, Rb.T @ (ta - tb)) - pa[0]
    # capsule-capsule: segment-segment distance minus both radii, apart or overlapping
    ea, eb = Ra[:, 2] * 0.5 * pa[1], Rb[:, 2] * 0.5 * pb[1]
    return segment_distance(ta - ea, ta + ea, tb - eb, tb + eb) - pa[0] - pb[0]


def separation(A, B, Ra, ta, Rb, tb, U):
    """s(u) = min over B of u.x - max over A of u.x for unit directions U (m, 3), A and B convex and bounded.
    Every s(u) is a lower bound on the signed distance, and the signed distance is the max of s over the unit
    sphere, whether the shapes are apart or overlap (minus the penetration depth)."""
    (ka, pa), (kb, pb) = A, B
    return U @ tb - support(kb, pb, -U @ Rb) - U @ ta - support(ka, pa, U @ Ra)


def fibonacci_sphere(n):
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r, phi = np.sqrt(1.0 - z * z), np.pi * (1.0 + 5.0 ** 0.5) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


SPHERE_GRID = fibonacci_sphere(4000)


def max_separation(A, B, Ra, ta, Rb, tb, seed_dirs):
    """Best s(u) found: a 4000-direction grid, then a shrinking random search (to steps of 1e-14) from the
    6 best grid directions and from seed_dirs (coal's normal). Independent of coal's GJK/EPA."""
    rng = np.random.default_rng(0)  # own stream: the search never shifts the pose draws
    seeds = np.asarray(seed_dirs, dtype=float).reshape(-1, 3)
    s = separation(A, B, Ra, ta, Rb, tb, SPHERE_GRID)
    best = -np.inf
    for u in [*SPHERE_GRID[np.argsort(s)[-6:]], *seeds]:
        u = u / np.linalg.norm(u)
        su, step = separation(A, B, Ra, ta, Rb, tb, u[None])[0], 0.05
        while step > 1e-14:
            W = u + step * rng.normal(size=(48, 3))
            W /= np.linalg.norm(W, axis=1)[:, None]
            sw = separation(A, B, Ra, ta, Rb, tb, W)
            k = int(np.argmax(sw))
            if sw[k] > su:
                su, u = sw[k], W[k]
            else:
                step *= 0.5
        best = max(best, su)
    return float(best)


def reference_distance(name, A, B, Ra, ta, Rb, tb, normal):
    """The closed form where there is one, else the best separating direction found (max_separation)."""
    if has_closed_form(name, A):
        return closed_form(name, A, B, Ra, ta, Rb, tb)
    return max_separation(A, B, Ra, ta, Rb, tb, [normal])


def random_quaternion(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def transform(q, t):
    # Built from the quaternion as it is written to the CSV, so coal sees exactly the stored pose.
    return coal.Transform3s(coal.Quaternion(*map(float, q)), np.asarray(t, dtype=float))


def distance_request():
    req = coal.DistanceRequest()  # enable_signed_distance is on by default
    req.gjk_tolerance = 1e-12
    req.gjk_max_iterations = 1000
    req.epa_tolerance = 1e-12
    req.epa_max_iterations = 1000
    return req


def collision_request():
    req = coal.CollisionRequest()  # default flags, margin 0; contact when distance <= 1e-12. Only the verdict
    # is used.
    req.gjk_tolerance = 1e-12
    req.gjk_max_iterations = 1000
    return req


def draw_pose(rng, A, B, want_separated):
    (ka, pa), (kb, pb) = A, B
    qa, qb = random_quaternion(rng), random_quaternion(rng)
    ta = rng.uniform(-0.2, 0.2, 3)
    if ka == "halfspace":
        n = transform(qa, ta).getRotation() @ np.asarray(pa[0])
        rb = bounding_radius(kb, pb)
        s = rng.uniform(0.0, 0.75 * rb) if want_separated else rng.uniform(-0.25 * rb, 0.0)
        offset = rng.uniform(-0.2, 0.2, 3)
        offset -= (offset @ n) * n
        Rb = transform(qb, np.zeros(3)).getRotation()
        tb = ta + offset + (pa[1] + s + support(kb, pb, Rb.T @ -n)) * n
    else:
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        tb = ta + u * rng.uniform(0.3, 1.3) * (bounding_radius(ka, pa) + bounding_radius(kb, pb))
    return qa, ta, qb, tb


def generate(name, A, B, n, rng, dreq, creq):
    """n validated cases of one pair type, exactly round(0.75 n) of them separated. Returns the rows and the
    number of draws redrawn because coal's EPA failed and because coal's distance was off the reference."""
    sa, sb = make_shape(*A), make_shape(*B)
    want = rng.permutation(np.arange(n) < int(round(SEPARATED_FRACTION * n)))
    rows, epa_failed, off_reference = [], 0, 0
    for want_separated in want:
        while True:
            qa, ta, qb, tb = draw_pose(rng, A, B, want_separated)
            Ta, Tb = transform(qa, ta), transform(qb, tb)
            overlapping = coal.collide(sa, Ta, sb, Tb, creq, coal.CollisionResult()) > 0
            if overlapping == want_separated:
                continue
            res = coal.DistanceResult()
            d = coal.distance(sa, Ta, sb, Tb, dreq, res)
            wa, wb, normal = res.getNearestPoint1().copy(), res.getNearestPoint2().copy(), res.normal.copy()
            if not (d > EPA_FAILED and np.all(np.isfinite(np.concatenate([wa, wb, normal])))):
                epa_failed += 1
                continue
            ref = reference_distance(name, A, B, Ta.getRotation(), ta, Tb.getRotation(), tb, normal)
            if abs(d - ref) > MAX_ERROR:
                off_reference += 1
                continue
            rows.append(dict(qa=qa, ta=ta, qb=qb, tb=tb, d=d, wa=wa, wb=wb, normal=normal, ref=ref,
                             overlapping=overlapping))
            break
    return rows, epa_failed, off_reference


def check(A, B, rows):
    """Max errors of coal's answers for one pair type (see the module docstring)."""
    (ka, pa), (kb, pb) = A, B
    st = dict(low=0.0, high=0.0, wgap=0.0, surf=0.0, bracket=0.0, sign_mismatch=0)
    for r in rows:
        Ra, Rb = transform(r["qa"], r["ta"]).getRotation(), transform(r["qb"], r["tb"]).getRotation()
        wa, wb, d = r["wa"], r["wb"], r["d"]
        st["low"] = max(st["low"], r["ref"] - d)
        st["high"] = max(st["high"], d - r["ref"])
        st["wgap"] = max(st["wgap"], abs(np.linalg.norm(wb - wa) - abs(d)))
        st["surf"] = max(st["surf"], abs(signed_distance(ka, pa, Ra.T @ (wa - r["ta"]))),
                         abs(signed_distance(kb, pb, Rb.T @ (wb - r["tb"]))))
        st["sign_mismatch"] += int(r["overlapping"] != (d <= 0.0))
        if ka != "halfspace" and d > 0.0:  # apart: s(normal) <= true distance <= |wb - wa|
            s = separation(A, B, Ra, r["ta"], Rb, r["tb"], r["normal"][None])[0]
            st["bracket"] = max(st["bracket"], np.linalg.norm(wb - wa) - s)
    return st


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--per-pair", type=int, default=150, help="cases per pair type")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--output", required=True, help="CSV file to write")
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    dreq, creq = distance_request(), collision_request()
    print(f"coal {coal.__version__}, gjk_tolerance {dreq.gjk_tolerance:g}, "
          f"epa_tolerance {dreq.epa_tolerance:g}. "
          "Max per pair of: low/high = reference - distance / distance - reference (reference: the closed "
          "form, or the best separating direction found, a lower bound on the true value), "
          "bracket = |wb-wa| - s(normal) when apart, wgap = | |wb-wa| - |distance| |, surf = a witness's "
          "distance to its surface; redrawn = draws dropped as EPA failed / as off the reference by > "
          f"{MAX_ERROR:g}", file=sys.stderr)
    with open(args.output, "w") as out:
        out.write(COLUMNS + "\n")
        for name, A, B in PAIRS:
            rows, epa_failed, off_reference = generate(name, A, B, args.per_pair, rng, dreq, creq)
            for r in rows:
                nums = [*r["qa"], *r["ta"], *r["qb"], *r["tb"], r["d"], *r["wa"], *r["wb"]]
                fields = [name, *(repr(float(x)) for x in nums), str(int(r["overlapping"]))]
                out.write(",".join(fields) + "\n")
            st = check(A, B, rows)
            kind = "closed" if has_closed_form(name, A) else "search"
            bracket = "" if A[0] == "halfspace" else f" bracket {st['bracket']:.1e}"
            print(f"{name:18s} n {len(rows)} overlapping {sum(r['overlapping'] for r in rows)} "
                  f"{kind} low {st['low']:.1e} high {st['high']:.1e}{bracket} wgap {st['wgap']:.1e} "
                  f"surf {st['surf']:.1e} sign_mismatch {st['sign_mismatch']} "
                  f"redrawn {epa_failed}/{off_reference}", file=sys.stderr)


if __name__ == "__main__":
    main()
