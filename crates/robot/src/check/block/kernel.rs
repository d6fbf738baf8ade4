//! The block kernel: a block of configurations through forward kinematics, ball placement and the
//! bound tests in lanes ([`decide`]).

use super::lanes::{sin_cos, Lanes};
use super::plan::{BlockPlan, Motion, Object, Shape, Step, Turn0, Value};
use sublevel_core::math::{Real, Vector3};
use sublevel_kernels::LaneMask;

/// What the lanes decided of one configuration: free, or colliding by a proof; `None` in
/// [`Decided`]'s slot of a lane they could not decide.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Decided {
    /// The world pair proved colliding, as (geometry, object).
    pub world: Option<(usize, usize)>,
    /// The self pair proved colliding, as geometry indices.
    pub self_pair: Option<(usize, usize)>,
    /// Self pairs decided free by a clearance table.
    pub tables: usize,
    /// Pairs proved colliding.
    pub proved: usize,
    /// Whether pairs were left undecided ([`Scratch::pending_world`], [`Scratch::pending_self`]).
    pub pending: bool,
    /// Whether the collision rests on the sphere model ([`BlockInput::conclusive`]), not on a
    /// contact proof.
    pub conservative: bool,
}

/// The inputs of one block besides the plan.
pub(crate) struct BlockInput<'a> {
    /// `q[k · W + lane]`: entry k of each lane's configuration (W = the lane width).
    pub q: &'a [Real],
    /// Each lane's configuration (for the clearance tables).
    pub configs: &'a [&'a [Real]],
    /// The base pose, row-major rotation then translation.
    pub base: [Real; 12],
    /// Padding (meters, ≥ 0).
    pub padding: Real,
    /// The rounding margin of the lanes' poses (meters, > 0; [`BlockPlan::inflation`]): a bound
    /// computed in lanes must clear the padding by it, a proof must hold by it.
    pub eps: Real,
    /// Link padding per geometry.
    pub pad: &'a [Real],
    /// Checked world pairs per geometry.
    pub world_pairs: &'a [Vec<usize>],
    /// Checked self pairs and their tables' lower bounds (`table(k, lane)`).
    pub self_pairs: &'a [(usize, usize)],
    /// Whether self pairs are checked.
    pub self_collision: bool,
    /// Whether contact proofs may decide lanes colliding.
    pub proofs: bool,
    /// Whether a pair left within the padding by modelled cuts ([`super::plan::Geometry::modelled`])
    /// collides (the [`crate::Fidelity::Spheres`] level) instead of going to the single path.
    pub conclusive: bool,
    /// Lanes the kernel must decide (bit i: lane i); the others are ignored.
    pub lanes: u32,
}

/// A pose in lanes: row-major rotation, then translation.
pub(crate) type Pose<L> = [L; 12];

/// Most configuration entries a robot may have for the block kernel (more: checked alone).
pub(crate) const MAX_DOF: usize = 64;

#[inline(always)]
fn place<L: Lanes>(p: &Pose<L>, v: &[Real]) -> [L; 3] {
    let z = p[0];
    let c = |x: Real| z.constant(x);
    let mut out = [p[9], p[10], p[11]];
    for (r, o) in out.iter_mut().enumerate() {
        *o = p[3 * r].mul_add(c(v[0]), p[3 * r + 1].mul_add(c(v[1]), p[3 * r + 2].mul_add(c(v[2]), *o)));
    }
    out
}

#[inline(always)]
fn sq<L: Lanes>(v: [L; 3]) -> L {
    v[0].mul_add(v[0], v[1].mul_add(v[1], v[2] * v[2]))
}

#[inline(always)]
fn sub<L: Lanes>(a: [L; 3], b: [L; 3]) -> [L; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline(always)]
fn splat3<L: Lanes>(z: L, v: &[Real]) -> [L; 3] {
    [z.constant(v[0]), z.constant(v[1]), z.constant(v[2])]
}

/// A world point in a primitive's frame.
#[inline(always)]
fn local<L: Lanes>(rt: &[Real; 9], t: &[Real; 3], x: [L; 3]) -> [L; 3] {
    let z = x[0];
    let d = sub(x, splat3(z, t));
    let c = |v: Real| z.constant(v);
    let mut out = [z; 3];
    for (r, o) in out.iter_mut().enumerate() {
        *o = d[0].mul_add(c(rt[3 * r]), d[1].mul_add(c(rt[3 * r + 1]), d[2] * c(rt[3 * r + 2])));
    }
    out
}

/// The signed distance from `x` (world, meters) to the object's boundary, positive outside
/// (`crate::spheres::primitive_signed_distance` in lanes; a lower bound for a mesh's ball).
#[inline(always)]
fn signed_distance<L: Lanes>(o: &Object, x: [L; 3]) -> L {
    let z = x[0];
    let c = |v: Real| z.constant(v);
    let zero = c(0.0);
    match o {
        Object::Ball { c: center, r } | Object::Cloud { c: center, r, .. } => {
            sq(sub(x, splat3(z, center))).sqrt() - c(*r)
        }
        Object::Plane { n, d } => x[0].mul_add(c(n[0]), x[1].mul_add(c(n[1]), x[2] * c(n[2]))) - c(*d),
        Object::Shape { rt, t, shape, .. } => {
            let p = local(rt, t, x);
            match *shape {
                Shape::Box(h) => {
                    let q = [p[0].abs() - c(h[0]), p[1].abs() - c(h[1]), p[2].abs() - c(h[2])];
                    let outside = sq([q[0].max(zero), q[1].max(zero), q[2].max(zero)]).sqrt();
                    outside + q[0].max(q[1]).max(q[2]).min(zero)
                }
                Shape::Sphere(r) => sq(p).sqrt() - c(r),
                Shape::Cylinder(r, h) => {
                    let qr = p[0].mul_add(p[0], p[1] * p[1]).sqrt() - c(r);
                    let qz = p[2].abs() - c(h);
                    let (a, b) = (qr.max(zero), qz.max(zero));
                    a.mul_add(a, b * b).sqrt() + qr.max(qz).min(zero)
                }
                Shape::Capsule(r, h) => {
                    let dz = p[2] - p[2].max(c(-h)).min(c(h));
                    sq([p[0], p[1], dz]).sqrt() - c(r)
                }
            }
        }
    }
}

/// The largest distance from `x` to a point of the object (+∞ for a halfspace, NaN for a mesh's
/// ball, which proves nothing).
#[inline(always)]
fn farthest<L: Lanes>(o: &Object, x: [L; 3]) -> L {
    let z = x[0];
    let c = |v: Real| z.constant(v);
    match o {
        Object::Ball { .. } | Object::Cloud { .. } => c(Real::NAN),
        Object::Plane { .. } => c(Real::INFINITY),
        Object::Shape { rt, t, shape, .. } => {
            let p = local(rt, t, x);
            match *shape {
                Shape::Box(h) => sq([p[0].abs() + c(h[0]), p[1].abs() + c(h[1]), p[2].abs() + c(h[2])]).sqrt(),
                Shape::Sphere(r) => sq(p).sqrt() + c(r),
                Shape::Cylinder(r, h) => {
                    let rho = p[0].mul_add(p[0], p[1] * p[1]).sqrt() + c(r);
                    let zz = p[2].abs() + c(h);
                    rho.mul_add(rho, zz * zz).sqrt()
                }
                Shape::Capsule(r, h) => sq([p[0], p[1], p[2].abs() + c(h)]).sqrt() + c(r),
            }
        }
    }
}

/// The value of a joint in lanes.
#[inline(always)]
fn value<L: Lanes>(v: Value, q: &[L]) -> L {
    match v {
        Value::Entry(k) => q[k],
        Value::Mimic(k, m, c) => q[k].mul_add(q[k].constant(m), q[k].constant(c)),
    }
}

/// Forward kinematics of the block: every link's pose in lanes (`poses`, one per link).
#[inline(always)]
pub(crate) fn forward<L: Lanes>(steps: &[Step], root: usize, z: L, base: &[Real; 12], q: &[L], poses: &mut [Pose<L>]) {
    let c = |v: Real| z.constant(v);
    poses[root] = base.map(c);
    for s in steps {
        let p = poses[s.parent];
        let mut n = p;
        match s.turn0 {
            Turn0::Perm { src, sign } => {
                for r in 0..3 {
                    for k in 0..3 {
                        n[3 * r + k] = p[3 * r + src[k]] * c(sign[k]);
                    }
                }
            }
            Turn0::General(m) => {
                for r in 0..3 {
                    for k in 0..3 {
                        n[3 * r + k] =
                            p[3 * r].mul_add(c(m[k]), p[3 * r + 1].mul_add(c(m[3 + k]), p[3 * r + 2] * c(m[6 + k])));
                    }
                }
            }
        }
        for r in 0..3 {
            n[9 + r] = p[3 * r]
                .mul_add(c(s.t0[0]), p[3 * r + 1].mul_add(c(s.t0[1]), p[3 * r + 2].mul_add(c(s.t0[2]), p[9 + r])));
        }
        match s.motion {
            Motion::Fixed => {}
            Motion::Turn { value: v, i, j, sign } => {
                let (sn, cs) = sin_cos(value(v, q));
                let sn = sn * c(sign);
                for r in 0..3 {
                    let (a, b) = (n[3 * r + i], n[3 * r + j]);
                    n[3 * r + i] = a.mul_add(cs, b * sn);
                    n[3 * r + j] = b.mul_add(cs, -(a * sn));
                }
            }
            Motion::TurnAxis { value: v, axis: a } => {
                let (sn, cs) = sin_cos(value(v, q));
                let one_c = c(1.0) - cs;
                let (x, y, zz) = (c(a[0]), c(a[1]), c(a[2]));
                // Rodrigues: R = cos I + sin [a]× + (1 − cos) a aᵀ.
                let m = [
                    one_c.mul_add(x * x, cs),
                    one_c.mul_add(x * y, -(sn * zz)),
                    one_c.mul_add(x * zz, sn * y),
                    one_c.mul_add(y * x, sn * zz),
                    one_c.mul_add(y * y, cs),
                    one_c.mul_add(y * zz, -(sn * x)),
                    one_c.mul_add(zz * x, -(sn * y)),
                    one_c.mul_add(zz * y, sn * x),
                    one_c.mul_add(zz * zz, cs),
                ];
                let o = n;
                for r in 0..3 {
                    for k in 0..3 {
                        n[3 * r + k] = o[3 * r].mul_add(m[k], o[3 * r + 1].mul_add(m[3 + k], o[3 * r + 2] * m[6 + k]));
                    }
                }
            }
            Motion::Slide { value: v, axis: a } => {
                let d = value(v, q);
                for r in 0..3 {
                    let along = n[3 * r].mul_add(c(a[0]), n[3 * r + 1].mul_add(c(a[1]), n[3 * r + 2] * c(a[2])));
                    n[9 + r] = along.mul_add(d, n[9 + r]);
                }
            }
        }
        poses[s.child] = n;
    }
}

/// Scratch space of the kernel, reused across blocks.
pub(crate) struct Scratch<L> {
    poses: Vec<Pose<L>>,
    centers: Vec<[L; 3]>,
    balls: Vec<[L; 4]>,
    /// World pairs the lanes left undecided: (lane, geometry, object).
    pub pending_world: Vec<(usize, usize, usize)>,
    /// Self pairs the lanes left undecided: (lane, index of the checked self pair), by
    /// increasing index per lane.
    pub pending_self: Vec<(usize, usize)>,
}

impl<L: Lanes> Scratch<L> {
    pub(crate) fn new(z: L, plan: &BlockPlan) -> Self {
        Self {
            poses: vec![[z; 12]; plan.links],
            centers: vec![[z; 3]; plan.geometries.len()],
            balls: Vec::new(),
            pending_world: Vec::new(),
            pending_self: Vec::new(),
        }
    }
}

/// Decides the lanes of one block (module docs of [`super`]): `out[lane]` is `Some` for every
/// lane of `input.lanes`, with the pairs it could not decide in `scratch`'s pending lists. `table(k, lane)` is self
/// pair k's clearance-table bound at the lane's configuration (−∞ without a table).
#[inline(always)]
pub(crate) fn decide<L: Lanes>(
    z: L,
    plan: &BlockPlan,
    input: &BlockInput<'_>,
    table: &dyn Fn(usize, usize) -> Real,
    scratch: &mut Scratch<L>,
    out: &mut [Option<Decided>],
) {
    let w = L::WIDTH;
    let c = |v: Real| z.constant(v);
    let mut q = [z; MAX_DOF];
    let dof = input.q.len() / w;
    for (k, v) in q.iter_mut().enumerate().take(dof) {
        *v = L::load(z.cpu(), &input.q[k * w..]);
    }
    let q = &q[..dof];
    forward(&plan.steps, plan.root, z, &input.base, q, &mut scratch.poses);
    let poses = &scratch.poses;
    for (g, geometry) in plan.geometries.iter().enumerate() {
        scratch.centers[g] = place(&poses[geometry.link], &geometry.ball);
    }
    let full = input.lanes;
    scratch.pending_world.clear();
    scratch.pending_self.clear();
    let mut decided = [Decided::default(); 8];
    // Lanes whose world verdict is still open, and lanes given up (left to the single path).
    let (mut open, mut unknown) = (full, 0u32);
    'world: for (g, geometry) in plan.geometries.iter().enumerate() {
        let pose = &poses[geometry.link];
        let center = scratch.centers[g];
        let pad = c(input.padding + input.eps + input.pad[g]);
        let rg = c(geometry.ball[3]);
        for &o in &input.world_pairs[g] {
            if open == 0 {
                break 'world;
            }
            let object = &plan.objects[o];
            let mut free = !open & full;
            let reach = rg + pad;
            let gap2 = match object {
                Object::Ball { c: oc, r } | Object::Cloud { c: oc, r, .. } => {
                    let reach = reach + c(*r);
                    Some((sq(sub(center, splat3(z, oc))), reach * reach))
                }
                Object::Shape { aabb: (ac, ah), .. } => {
                    let d = sub(center, splat3(z, ac));
                    let zero = c(0.0);
                    let out = [
                        (d[0].abs() - c(ah[0])).max(zero),
                        (d[1].abs() - c(ah[1])).max(zero),
                        (d[2].abs() - c(ah[2])).max(zero),
                    ];
                    Some((sq(out), reach * reach))
                }
                Object::Plane { .. } => None,
            };
            if let Some((d2, r2)) = gap2 {
                free |= r2.lt(d2).bits();
                if free & full == full {
                    continue;
                }
            }
            if let Object::Cloud { rt, t, index, .. } = object {
                let left = open & !free;
                let (proved, rest) =
                    cloud_lanes(plan, input, g, pose, center, (rt, t, *index), left, &mut scratch.balls);
                for (lane, d) in decided.iter_mut().enumerate().take(w) {
                    if proved >> lane & 1 == 1 {
                        d.world = Some((g, o));
                        d.proved += 1;
                    }
                }
                for lane in 0..w {
                    if rest >> lane & 1 == 1 {
                        scratch.pending_world.push((lane, g, o));
                    }
                }
                unknown |= rest;
                open &= !proved;
                continue;
            }
            if !matches!(object, Object::Ball { .. }) {
                free |= (pad + rg).lt(signed_distance(object, center)).bits();
                if free & full == full {
                    continue;
                }
            }
            if geometry.cut.len() > 1 {
                let mut all = full;
                for b in &plan.cut[geometry.cut.clone()] {
                    let x = place(pose, b);
                    all &= (pad + c(b[3])).lt(signed_distance(object, x)).bits() | free;
                    if all & open == 0 {
                        break;
                    }
                }
                free |= all;
                if free & full == full {
                    continue;
                }
            }
            let left = open & !free;
            let mut proved = 0u32;
            if input.proofs && !matches!(object, Object::Ball { .. }) {
                for comp in &plan.components[geometry.components.clone()] {
                    let bc = place(pose, &comp.bound);
                    let reaches = c(comp.bound[3] + input.eps).lt(farthest(object, bc));
                    if reaches.bits() & left == 0 {
                        continue;
                    }
                    for b in &plan.inner[comp.balls.clone()] {
                        let x = place(pose, b);
                        let touch = signed_distance(object, x).lt(c(b[3] - input.eps));
                        proved |= reaches.and(touch).bits() & left;
                        if proved == left {
                            break;
                        }
                    }
                }
            }
            for (lane, d) in decided.iter_mut().enumerate().take(w) {
                if proved >> lane & 1 == 1 {
                    d.world = Some((g, o));
                    d.proved += 1;
                }
            }
            let rest = left & !proved;
            if input.conclusive && geometry.modelled && matches!(object, Object::Shape { .. } | Object::Plane { .. }) {
                conclude(&mut decided, rest, w, |d| d.world = Some((g, o)));
                open &= !rest;
                continue;
            }
            for lane in 0..w {
                if rest >> lane & 1 == 1 {
                    scratch.pending_world.push((lane, g, o));
                }
            }
            unknown |= rest;
            open &= !proved;
        }
    }
    let mut open = full;
    if input.self_collision {
        let pairs = input.self_pairs;
        'pairs: for (k, &(a, b)) in pairs.iter().enumerate() {
            if open == 0 {
                break 'pairs;
            }
            let (ga, gb) = (&plan.geometries[a], &plan.geometries[b]);
            let extra = input.pad[a] + input.pad[b];
            let pad = c(input.padding + input.eps + extra);
            let mut free = !open & full;
            let reach = c(ga.ball[3] + gb.ball[3]) + pad;
            free |= (reach * reach).lt(sq(sub(scratch.centers[a], scratch.centers[b]))).bits();
            if free & full == full {
                continue;
            }
            for (lane, d) in decided.iter_mut().enumerate().take(w) {
                if (open & !free) >> lane & 1 == 1 && table(k, lane) > input.padding + extra {
                    free |= 1 << lane;
                    d.tables += 1;
                }
            }
            if free & full == full {
                continue;
            }
            // b's cut balls placed once; a's balls that reach b's ball tested against them.
            let (pa, pb) = (&poses[ga.link], &poses[gb.link]);
            scratch.balls.clear();
            for s in &plan.cut[gb.cut.clone()] {
                let x = place(pb, s);
                let reach = c(s[3] + ga.ball[3]) + pad;
                let far = (reach * reach).lt(sq(sub(x, scratch.centers[a]))).bits() | free;
                if far & full != full {
                    scratch.balls.push([x[0], x[1], x[2], c(s[3])]);
                }
            }
            let mut all = full;
            'cut: for s in &plan.cut[ga.cut.clone()] {
                let x = place(pa, s);
                let ra = c(s[3]) + pad;
                let reach = ra + c(gb.ball[3]);
                let near = (reach * reach).lt(sq(sub(x, scratch.centers[b]))).bits() | free;
                if near & full == full {
                    continue;
                }
                for t in &scratch.balls {
                    let reach = ra + t[3];
                    all &= (reach * reach).lt(sq(sub(x, [t[0], t[1], t[2]]))).bits() | near;
                    if all & open == 0 {
                        break 'cut;
                    }
                }
            }
            free |= all;
            if free & full == full {
                continue;
            }
            let left = open & !free;
            let mut proved = 0u32;
            if input.proofs {
                proved = inner_pair(plan, z, input.eps, pa, pb, ga, gb) & left;
            }
            for (lane, d) in decided.iter_mut().enumerate().take(w) {
                if proved >> lane & 1 == 1 {
                    d.self_pair = Some((a, b));
                    d.proved += 1;
                }
            }
            let rest = left & !proved;
            if input.conclusive && ga.modelled && gb.modelled {
                conclude(&mut decided, rest, w, |d| d.self_pair = Some((a, b)));
                open &= !rest;
                continue;
            }
            for lane in 0..w {
                if rest >> lane & 1 == 1 {
                    scratch.pending_self.push((lane, k));
                }
            }
            unknown |= rest;
            open &= !proved;
        }
    }
    for (lane, slot) in out.iter_mut().enumerate().take(w) {
        decided[lane].pending = unknown >> lane & 1 == 1;
        *slot = (full >> lane & 1 == 1).then_some(decided[lane]);
    }
}

/// Marks the lanes of `rest` colliding on the sphere model, with `pair` naming the pair.
#[inline(always)]
fn conclude(decided: &mut [Decided; 8], rest: u32, w: usize, pair: impl Fn(&mut Decided)) {
    for (lane, d) in decided.iter_mut().enumerate().take(w) {
        if rest >> lane & 1 == 1 {
            pair(d);
            d.conservative = true;
        }
    }
}

/// One geometry against a point cloud, lane by lane (the k-d tree answers one point at a time):
/// lanes of `left` where no point lies within the geometry's ball or within every cloud cut ball's
/// reach
/// are free; a point within the reach of a cut ball's whole ball (`r + padding − ρ`, less the
/// rounding margin) proves contact, since a cut ball holds part of the geometry. Returns the
/// lanes proved and the lanes left to the single path.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn cloud_lanes<L: Lanes>(
    plan: &BlockPlan,
    input: &BlockInput<'_>,
    g: usize,
    pose: &Pose<L>,
    center: [L; 3],
    (rt, t, index): (&[Real; 9], &[Real; 3], usize),
    left: u32,
    balls: &mut Vec<[L; 4]>,
) -> (u32, u32) {
    let geometry = &plan.geometries[g];
    let cloud = &plan.clouds[index];
    let pad = input.padding + input.eps + input.pad[g];
    let reach = cloud.radius() + pad;
    let proof = cloud.radius() + input.padding + input.pad[g] - input.eps;
    #[inline(always)]
    fn to_cloud<L: Lanes>(x: &[L; 3], lane: usize, rt: &[Real; 9], t: &[Real; 3]) -> Vector3 {
        let v = [x[0].lane(lane) - t[0], x[1].lane(lane) - t[1], x[2].lane(lane) - t[2]];
        Vector3::new(
            rt[0] * v[0] + rt[1] * v[1] + rt[2] * v[2],
            rt[3] * v[0] + rt[4] * v[1] + rt[5] * v[2],
            rt[6] * v[0] + rt[7] * v[1] + rt[8] * v[2],
        )
    }
    balls.clear();
    let cut = &plan.cloud_cut[geometry.cloud_cut.clone()];
    let (mut proved, mut rest) = (0u32, 0u32);
    for lane in 0..L::WIDTH {
        if left >> lane & 1 == 0 {
            continue;
        }
        // The geometry's ball by the grid alone (a large ball would cost a tree search), then
        // its cut balls by the grid and the tree.
        if cloud.clear_by_grid(&to_cloud(&center, lane, rt, t), geometry.ball[3] + reach) {
            continue;
        }
        if balls.is_empty() {
            // A loop, not a closure: the lane arithmetic must inline into the caller's
            // AVX2 + FMA code.
            for b in cut {
                let x = place(pose, b);
                balls.push([x[0], x[1], x[2], x[0]]);
            }
        }
        let mut near = false;
        for (b, x) in cut.iter().zip(balls.iter()) {
            let x = to_cloud(&[x[0], x[1], x[2]], lane, rt, t);
            if cloud.any_within(&x, b[3] + reach) {
                near = true;
                if input.proofs && proof > b[3] && cloud.any_within(&x, proof - b[3]) {
                    proved |= 1 << lane;
                    break;
                }
            }
        }
        if near && proved >> lane & 1 == 0 {
            rest |= 1 << lane;
        }
    }
    (proved, rest)
}

/// Lanes where a point of `ext` (posed by `pose`) lies farther than `r` from `center`.
#[inline(always)]
fn beyond<L: Lanes>(pose: &Pose<L>, ext: &[[Real; 3]], center: [L; 3], r: Real) -> u32 {
    let r2 = center[0].constant(r * r);
    let mut m = 0u32;
    for v in ext {
        m |= r2.lt(sq(sub(place(pose, v), center))).bits();
    }
    m
}

/// Lanes where two closed meshes' inner balls prove contact ([`crate::inner`]'s `touch_mesh`:
/// an inner ball of each overlapping, each component reaching outside the other's bounding
/// ball).
#[inline(always)]
fn inner_pair<L: Lanes>(
    plan: &BlockPlan,
    z: L,
    eps: Real,
    pa: &Pose<L>,
    pb: &Pose<L>,
    ga: &super::plan::Geometry,
    gb: &super::plan::Geometry,
) -> u32 {
    let c = |v: Real| z.constant(v);
    let mut proved = 0u32;
    for ca in &plan.components[ga.components.clone()] {
        let ba = place(pa, &ca.bound);
        for cb in &plan.components[gb.components.clone()] {
            let bb = place(pb, &cb.bound);
            let reach = beyond(pa, &plan.extremes[ca.extremes.clone()], bb, cb.bound[3] + eps)
                & beyond(pb, &plan.extremes[cb.extremes.clone()], ba, ca.bound[3] + eps);
            if reach == 0 {
                continue;
            }
            for sa in &plan.inner[ca.balls.clone()] {
                let xa = place(pa, sa);
                for sb in &plan.inner[cb.balls.clone()] {
                    let r = c((sa[3] + sb[3] - eps).max(0.0));
                    proved |= sq(sub(xa, place(pb, sb))).lt(r * r).bits() & reach;
                }
            }
        }
    }
    proved
}

#[cfg(test)]
mod tests {
    use super::super::plan::{pose_rows, program};
    use super::*;
    use crate::RobotModel;
    use nalgebra::{Translation3, UnitQuaternion};
    use sublevel_core::math::{Isometry3, Vector3};
    use sublevel_kernels::Scalar;

    /// Poses of every link in lanes against [`RobotModel::forward_kinematics`] (pinocchio's to
    /// 1e-12), at random configurations (some far outside the limits) and a random base.
    fn lanes_match_the_model(model: &RobotModel) {
        let (steps, _) = program(model);
        let mut state = 7u64;
        let mut next = || {
            state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as Real / (1u64 << 53) as Real * 2.0 - 1.0
        };
        let mut worst: Real = 0.0;
        for case in 0..200 {
            let scale = if case % 10 == 0 { 40.0 } else { 3.0 };
            let q: Vec<Real> = (0..model.dof()).map(|_| scale * next()).collect();
            let base = Isometry3::from_parts(
                Translation3::new(next(), next(), next()),
                UnitQuaternion::from_scaled_axis(Vector3::new(next(), next(), next())),
            );
            let expected = model.link_poses(&q, &base).unwrap();
            let rows = pose_rows(&base);
            let z = Scalar::<false>(0.0);
            let lanes: Vec<Scalar<false>> = q.iter().map(|&v| Scalar(v)).collect();
            let mut poses = vec![[z; 12]; model.links().len()];
            forward(&steps, model.root(), z, &rows, &lanes, &mut poses);
            for (p, e) in poses.iter().zip(&expected) {
                let em = e.rotation.to_rotation_matrix().into_inner();
                for r in 0..3 {
                    for k in 0..3 {
                        worst = worst.max((p[3 * r + k].0 - em[(r, k)]).abs());
                    }
                    worst = worst.max((p[9 + r].0 - e.translation.vector[r]).abs());
                }
            }
        }
        assert!(worst < 1e-12, "largest difference {worst}");
    }

    #[test]
    fn forward_kinematics_in_lanes_matches_the_model_on_every_joint_kind() {
        lanes_match_the_model(&RobotModel::from_urdf_str(include_str!("../../../tests/data/gantry.urdf")).unwrap());
        let panda = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/robots/panda/panda.urdf");
        lanes_match_the_model(&RobotModel::from_urdf_file(&panda).unwrap());
    }
}
