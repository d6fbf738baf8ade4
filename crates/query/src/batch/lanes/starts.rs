//! The lanes' cold starts: cube-map cells of four directions, the radial and support tables
//! read per lane, and the separated starts of four pairs at once (the single-pair solver's
//! `cold_start`, per lane).

use super::*;

/// Cells per cube-face side of both tables the cold starts read ([`RADIAL_GRID`] =
/// [`SUPPORT_GRID`]: one cell computation serves both look-ups of a direction).
const GRID: usize = RADIAL_GRID;
const _: () = assert!(RADIAL_GRID == SUPPORT_GRID);
/// Nodes per face side, and per face.
const NODES: usize = GRID + 1;
const FACE_NODES: usize = NODES * NODES;

/// `fx` where `on_x`, else `fy` where `on_y`, else `fz`, per lane.
#[inline(always)]
fn select3(on_x: M4, on_y: M4, fx: F4, fy: F4, fz: F4) -> F4 {
    F4::select(on_x, fx, F4::select(on_y, fy, fz))
}

/// The cube-map cells of four directions (one per lane): [`sublevel_core::poly::radial`]'s face
/// coordinates and bilinear interpolation, per lane.
struct CubeCells {
    /// Flat node index `face · (G + 1)² + j · (G + 1) + i` of each cell's first node (an
    /// integer, as a real).
    k: F4,
    /// The direction's position within its cell (interpolation weights along a and b).
    ta: F4,
    tb: F4,
    /// Lanes whose direction is nonzero and finite (the others read node 0 and are marked).
    ok: M4,
}

impl CubeCells {
    /// The cells of the directions `v` (any nonzero length): the face of the largest |vᵢ|
    /// (faces +x, −x, +y, −y, +z, −z, ties to the earlier axis), face coordinates the other two
    /// components in cyclic order over its modulus (the scalar look-ups' rules and arithmetic).
    #[inline(always)]
    fn new(v: V3<F4>) -> Self {
        let [x, y, z] = v.0;
        let cpu = x.cpu();
        let (ax, ay, az) = (x.abs(), y.abs(), z.abs());
        let (zero, one) = (F4::splat(cpu, 0.0), F4::splat(cpu, 1.0));
        let on_x = ay.le(ax).and(az.le(ax));
        let on_y = on_x.not().and(az.le(ay));
        let major = select3(on_x, on_y, ax, ay, az);
        let sign = select3(on_x, on_y, x, y, z).lt(zero);
        let face = select3(on_x, on_y, zero, F4::splat(cpu, 2.0), F4::splat(cpu, 4.0)) + F4::select(sign, one, zero);
        let (a, b) = (select3(on_x, on_y, y, z, x) / major, select3(on_x, on_y, z, x, y) / major);
        let ok = a.finite().and(b.finite());
        let half = F4::splat(cpu, 0.5 * GRID as Real);
        let fa = F4::select(ok, (a + one) * half, zero);
        let fb = F4::select(ok, (b + one) * half, zero);
        let last = F4::splat(cpu, (GRID - 1) as Real);
        let (i, j) = (fa.floor().max(zero).min(last), fb.floor().max(zero).min(last));
        let k = face.mul_add(F4::splat(cpu, FACE_NODES as Real), j.mul_add(F4::splat(cpu, NODES as Real), i));
        Self { k, ta: fa - i, tb: fb - j, ok }
    }

    /// Bilinear interpolation of the four nodes around each direction, of the node quantity at
    /// `coordinate` of `stride`-real nodes in the flat table `table`
    /// ([`sublevel_core::poly::RadialTable::radius`]'s arithmetic; [`F4::gather`] keeps every
    /// read in the table).
    #[inline(always)]
    fn interpolate(&self, table: &[Real], stride: usize, coordinate: usize) -> F4 {
        // No closure: one compiled out of line would lose the AVX target features.
        let (k, c) = (self.k, coordinate);
        let (n00, n01) = (k.gather(table, stride, c), k.gather(table, stride, stride + c));
        let (n10, n11) =
            (k.gather(table, stride, stride * NODES + c), k.gather(table, stride, stride * (NODES + 1) + c));
        let low = n00 + (n01 - n00) * self.ta;
        let high = n10 + (n11 - n10) * self.ta;
        low + (high - low) * self.tb
    }

    /// The radial table's radius per lane (0 where the direction is not `ok`).
    #[inline(always)]
    fn radius(&self, table: &RadialTable) -> F4 {
        let r = self.interpolate(table.nodes().as_flattened(), 1, 0);
        F4::select(self.ok, r, r.constant(0.0))
    }

    /// The support table's interpolated support point per lane (normalized units; meaningless
    /// where the direction is not `ok`).
    #[inline(always)]
    fn support(&self, table: &SupportTable) -> V3<F4> {
        let nodes = table.nodes().as_flattened().as_flattened();
        V3([self.interpolate(nodes, 3, 0), self.interpolate(nodes, 3, 1), self.interpolate(nodes, 3, 2)])
    }
}

/// The fraction min(r / ‖du‖, 1) of the way from a body's interior point towards a target
/// whose direction in the body's normalized frame is `du`, for the radial table's radius `r`
/// there (0 where ‖du‖ is 0 or not a number: [`PosedBody::boundary_towards`]'s rule, per lane).
#[inline(always)]
fn reach(r: F4, du: V3<F4>) -> F4 {
    let cpu = r.cpu();
    let n = du.dot(du).sqrt();
    F4::select(F4::splat(cpu, 0.0).lt(n), (r / n).min(F4::splat(cpu, 1.0)), F4::splat(cpu, 0.0))
}

/// The rotation matrix (row-major) of unit quaternions (w, x, y, z) per lane.
#[inline(always)]
fn rotation_matrix(w: F4, x: F4, y: F4, z: F4) -> M3<F4> {
    let cpu = w.cpu();
    let (one, two) = (F4::splat(cpu, 1.0), F4::splat(cpu, 2.0));
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, xz, yz, wx, wy, wz) = (x * y, x * z, y * z, w * x, w * y, w * z);
    [
        one - two * (yy + zz),
        two * (xy - wz),
        two * (xz + wy),
        two * (xy + wz),
        one - two * (xx + zz),
        two * (yz - wx),
        two * (xz - wy),
        two * (yz + wx),
        one - two * (xx + yy),
    ]
}

/// The cold starts of the pairs whose relative poses (B in A's frame) are `rels`: the start
/// [`cold_start`] gives each (the same tests and choices, at the same points up to rounding),
/// computed four pairs at a time: the posed interior points, the bounding-sphere test, both
/// bodies' support and radial look-ups (one cube-map cell per body and lane, gathered nodes) in
/// 4-lane arithmetic; only the overlap tests of pairs whose spheres meet (two polynomial values,
/// at points mapped on the lanes) stay scalar.
#[inline(always)]
pub(super) fn cold_starts(cpu: Avx2Fma, a: &Body, b: &Body, rels: &[Isometry3]) -> Vec<Option<(Vector3, Vector3)>> {
    let ba = PosedBody::unposed(a);
    let ca = ba.interior_point();
    let ca4 = V3::splat(cpu, &ca);
    let quadric = a.degree() <= 2 || b.degree() <= 2;
    let spheres = match (a.bounding_sphere(), b.bounding_sphere()) {
        (Some((c1, r1)), Some((c2, r2))) => Some((V3::splat(cpu, &ba.to_world(&c1.coords)), c2.coords, r1 + r2)),
        _ => None,
    };
    let (sa, sb) = (F4::splat(cpu, a.scale()), F4::splat(cpu, b.scale()));
    let (center_a, center_b) = (V3::splat(cpu, &a.center()), V3::splat(cpu, &b.center()));
    let (inv_sa, neg_inv_sb) = (F4::splat(cpu, 1.0 / a.scale()), F4::splat(cpu, -1.0 / b.scale()));
    let interior_b = b.interior_point().coords;
    let mut out = Vec::with_capacity(rels.len());
    for chunk in rels.chunks(4) {
        // The chunk's poses by lanes (a short chunk repeats its last pose).
        let (mut q, mut t) = ([[0.0; 4]; 4], [[0.0; 4]; 3]);
        for i in 0..4 {
            let rel = &chunk[i.min(chunk.len() - 1)];
            let r = rel.rotation.quaternion();
            (q[0][i], q[1][i], q[2][i], q[3][i]) = (r.w, r.i, r.j, r.k);
            for (c, row) in t.iter_mut().enumerate() {
                row[i] = rel.translation.vector[c];
            }
        }
        // No closures here: one compiled out of line loses the AVX target features (measured: each
        // of these was a call of about 280 instructions, 5 % of a 2d = 6 batch).
        let rot =
            rotation_matrix(F4::load(cpu, &q[0]), F4::load(cpu, &q[1]), F4::load(cpu, &q[2]), F4::load(cpu, &q[3]));
        let t4 = V3::load(cpu, &t);
        let cb = mat_mul(&rot, V3::splat(cpu, &interior_b)).add(t4);
        let apart = match &spheres {
            Some((c1, c2, rsum)) => {
                let d = c1.sub(mat_mul(&rot, V3::splat(cpu, c2)).add(t4));
                F4::splat(cpu, rsum * rsum).lt(d.dot(d))
            }
            None => F4::none(cpu),
        };
        // The directions of the look-ups in each body's normalized frame: A's towards B, B's
        // towards A (A·n for the world direction n = ±(cb − ca)).
        let axis = cb.sub(ca4);
        let (du_a, du_b) = (axis.scale(inv_sa), mat_t_mul(&rot, axis).scale(neg_inv_sb));
        let (cells_a, cells_b) = (CubeCells::new(du_a), CubeCells::new(du_b));
        let xs = cells_a.support(a.support_table()).mul_add(sa, center_a);
        let ys = mat_mul(&rot, cells_b.support(b.support_table()).mul_add(sb, center_b)).add(t4);
        let supports = cells_a.ok.and(cells_b.ok);
        let facing = if quadric { F4::none(cpu) } else { apart.and(supports) };
        // Facing lanes: one bisector refinement (`distance::bisector_start`), the support
        // points for n = (y − x)/‖y − x‖ + axis/‖axis‖ where they are closer to each other.
        let (xs, ys) = if facing.bits() != 0 {
            let d = ys.sub(xs);
            let dd = d.dot(d);
            let one = F4::splat(cpu, 1.0);
            let n = d.scale(one / dd.sqrt()).add(axis.scale(one / axis.dot(axis).sqrt()));
            let (du_a, du_b) = (n.scale(inv_sa), mat_t_mul(&rot, n).scale(neg_inv_sb));
            let (cells_a, cells_b) = (CubeCells::new(du_a), CubeCells::new(du_b));
            let xr = cells_a.support(a.support_table()).mul_add(sa, center_a);
            let yr = mat_mul(&rot, cells_b.support(b.support_table()).mul_add(sb, center_b)).add(t4);
            let dr = yr.sub(xr);
            let closer = facing.and(cells_a.ok).and(cells_b.ok).and(dr.dot(dr).lt(dd));
            (V3::select(closer, xr, xs), V3::select(closer, yr, ys))
        } else {
            (xs, ys)
        };
        let (xs, ys, cb_lanes) = (xs.to_arrays(), ys.to_arrays(), cb.to_arrays());
        let (mut x0, mut y0, mut order, mut use_supports) = (xs, ys, 0, 0);
        if facing.bits() != 0b1111 {
            // The radial boundary points on the segment between the interior points.
            let x0v = axis.mul_add(reach(cells_a.radius(a.radial_table()), du_a), ca4);
            let y0v = axis.mul_add(-reach(cells_b.radius(b.radial_table()), du_b), cb);
            let (ex, ey) = (x0v.sub(ca4), y0v.sub(ca4));
            order = apart.or(ex.dot(ex).lt(ey.dot(ey))).bits();
            let (gs, g0) = (V3::load(cpu, &ys).sub(V3::load(cpu, &xs)), y0v.sub(x0v));
            use_supports = supports.and(gs.dot(gs).lt(g0.dot(g0))).bits();
            (x0, y0) = (x0v.to_arrays(), y0v.to_arrays());
        }
        // Each interior point in the other body's normalized coordinates (the overlap tests).
        let ca_in_b = mat_t_mul(&rot, ca4.sub(t4)).sub(center_b).scale(-neg_inv_sb).to_arrays();
        let cb_in_a = V3::load(cpu, &cb_lanes).sub(center_a).scale(inv_sa).to_arrays();
        let (facing, apart) = (facing.bits(), apart.bits());
        for i in 0..chunk.len() {
            let bit = 1 << i;
            let start = if facing & bit != 0 || use_supports & bit != 0 {
                (V3::lane(&xs, i), V3::lane(&ys, i))
            } else {
                (V3::lane(&x0, i), V3::lane(&y0, i))
            };
            let separated = facing & bit != 0
                || (order & bit != 0
                    && (apart & bit != 0 || {
                        // Spheres that meet: separated along the segment only when each interior
                        // point lies outside the other body.
                        b.fast_polynomial().value(&V3::lane(&ca_in_b, i)) > 1.0
                            && a.fast_polynomial().value(&V3::lane(&cb_in_a, i)) > 1.0
                    }));
            out.push(separated.then_some(start));
        }
    }
    out
}
