//! Exact primitives: boxes, spheres, cylinders, capsules and halfspaces, each a convex set
//! given by a few constraints rather than a fitted polynomial.
//!
//! The paper's distance and separation problems (§IV) are stated for convex basic semialgebraic
//! sets `{x : gⱼ(x) ≤ 1, j = 1..m}`; a primitive is such a set whose constraints are sos-convex
//! (affine or quadratic), described by its few dimensions (a box is six numbers, exactly):
//!
//! ```text
//! box        |u_i| ≤ h_i, i = x, y, z                       (6 halfspaces; h = size / 2)
//! sphere     ‖u‖ ≤ r                                        (one quadric)
//! cylinder   u_x² + u_y² ≤ r²,  |u_z| ≤ h                   (a quadric and 2 halfspaces; h = height / 2)
//! capsule    dist(u, segment [−h, h]·e_z) ≤ r              (the segment swept by a ball; h = height / 2)
//! halfspace  n·u ≤ d                                        (unbounded: a floor, a wall)
//! ```
//!
//! in the primitive's own frame `u` (meters), centered at the origin as MoveIt's
//! `shape_msgs/SolidPrimitive` and coal / FCL define them: a box by its full side lengths, a
//! cylinder of radius r and full height along z, a capsule of radius r whose axis segment has
//! full length `height` along z. The query solvers work on this description directly
//! (`sublevel-query`'s `shape` module); this module holds the description, its file form
//! ([`PrimitiveFile`]), and the closed forms every solver starts from: support points (exact),
//! bounding spheres and boxes, and the closest boundary point to a point.

use crate::error::{Error, Result};
use crate::math::{Real, Vector3};
use serde::{Deserialize, Serialize};

/// The largest dimension a primitive may have (meters): larger values are almost surely a unit
/// error (millimeters given as meters), and would spoil the solvers' relative tolerances.
pub const MAX_DIMENSION: Real = 1.0e6;

/// The smallest dimension (side length, radius, height) a primitive may have, in meters: one
/// micrometer, the smallest body scale ([`crate::math::SCALE_RANGE`]). Below it the bounding
/// ellipsoid a stored primitive keeps does not build, and distances would sit under the solvers'
/// tolerances. One rule for every way a primitive arrives (upload, MoveIt import, URDF, attached
/// objects): [`check_dimension`].
pub const MIN_DIMENSION: Real = 1.0e-6;

/// A primitive's JSON file form: `{"primitive": "box", "size": [x, y, z]}`,
/// `{"primitive": "sphere", "radius": r}`, `{"primitive": "cylinder", "radius": r, "height": h}`,
/// `{"primitive": "capsule", "radius": r, "height": h}`,
/// `{"primitive": "halfspace", "normal": [nx, ny, nz], "offset": d}`; meters, full lengths.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "primitive", rename_all = "lowercase", deny_unknown_fields)]
pub enum PrimitiveFile {
    /// An axis-aligned box centered at the origin with full side lengths `size` (x, y, z).
    Box {
        /// Full side lengths [x, y, z] in meters, each > 0.
        size: [Real; 3],
    },
    /// A ball of radius `radius` centered at the origin.
    Sphere {
        /// Radius in meters (> 0).
        radius: Real,
    },
    /// A solid cylinder along z centered at the origin.
    Cylinder {
        /// Radius in meters (> 0).
        radius: Real,
        /// Full height along z in meters (> 0).
        height: Real,
    },
    /// The points within `radius` of the segment from (0, 0, −height/2) to (0, 0, height/2).
    Capsule {
        /// Radius in meters (> 0).
        radius: Real,
        /// Full length of the axis segment in meters (≥ 0; 0 is a sphere).
        height: Real,
    },
    /// The halfspace {u : normal·u ≤ offset}; `normal` need not be unit (it is normalized, and
    /// `offset` divided by its length).
    Halfspace {
        /// Outward normal [nx, ny, nz] (nonzero).
        normal: [Real; 3],
        /// Offset d in meters: the halfspace is {u : normal·u ≤ d}.
        offset: Real,
    },
}

/// A validated primitive in its own frame (meters): see the module docs for each set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Primitive {
    /// `|u_i| ≤ half_extents[i]`.
    Box {
        /// Half side lengths (meters, > 0).
        half_extents: Vector3,
    },
    /// `‖u‖ ≤ radius`.
    Sphere {
        /// Radius (meters, > 0).
        radius: Real,
    },
    /// `u_x² + u_y² ≤ radius²`, `|u_z| ≤ half_height`.
    Cylinder {
        /// Radius (meters, > 0).
        radius: Real,
        /// Half height (meters, > 0).
        half_height: Real,
    },
    /// `dist(u, [−half_height, half_height]·e_z) ≤ radius`.
    Capsule {
        /// Radius (meters, > 0).
        radius: Real,
        /// Half length of the axis segment (meters, ≥ 0).
        half_height: Real,
    },
    /// `normal·u ≤ offset`, `normal` unit.
    Halfspace {
        /// Unit outward normal.
        normal: Vector3,
        /// Signed offset (meters) of the boundary plane from the origin along `normal`.
        offset: Real,
    },
}

/// Checks one dimension of a primitive (a full side length, a radius or a height, meters): a
/// finite number in [[`MIN_DIMENSION`], [`MAX_DIMENSION`]]. Returns it.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `field` otherwise, with both bounds.
pub fn check_dimension(field: &str, v: Real) -> Result<Real> {
    if !(v.is_finite() && (MIN_DIMENSION..=MAX_DIMENSION).contains(&v)) {
        return Err(Error::invalid(
            field,
            format!("must be a length in [{MIN_DIMENSION:e}, {MAX_DIMENSION:e}] meters, got {v}"),
        ));
    }
    Ok(v)
}

fn positive(field: &str, v: Real) -> Result<Real> {
    check_dimension(field, v)
}

impl Primitive {
    /// Validates a file form.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the field (`size`, `radius`, `height`, `normal`,
    /// `offset`) for a non-finite length or one outside [[`MIN_DIMENSION`], [`MAX_DIMENSION`]]
    /// ([`check_dimension`]; a capsule's height may also be 0), or a zero normal.
    pub fn from_file(file: &PrimitiveFile) -> Result<Self> {
        Ok(match *file {
            PrimitiveFile::Box { size } => {
                let mut h = Vector3::zeros();
                for (i, s) in size.iter().enumerate() {
                    h[i] = 0.5 * positive(&format!("size[{i}]"), *s)?;
                }
                Primitive::Box { half_extents: h }
            }
            PrimitiveFile::Sphere { radius } => Primitive::Sphere { radius: positive("radius", radius)? },
            PrimitiveFile::Cylinder { radius, height } => Primitive::Cylinder {
                radius: positive("radius", radius)?,
                half_height: 0.5 * positive("height", height)?,
            },
            PrimitiveFile::Capsule { radius, height } => {
                let radius = positive("radius", radius)?;
                if height == 0.0 {
                    Primitive::Capsule { radius, half_height: 0.0 }
                } else {
                    Primitive::Capsule { radius, half_height: 0.5 * positive("height", height)? }
                }
            }
            PrimitiveFile::Halfspace { normal, offset } => {
                let n = Vector3::from(normal);
                let len = n.norm();
                if !len.is_finite() || len < 1e-12 {
                    return Err(Error::invalid("normal", format!("must be a finite nonzero vector, got {normal:?}")));
                }
                if !offset.is_finite() || offset.abs() > MAX_DIMENSION * len {
                    return Err(Error::invalid("offset", format!("must be finite, |offset| ≤ {MAX_DIMENSION:e} m")));
                }
                Primitive::Halfspace { normal: n / len, offset: offset / len }
            }
        })
    }

    /// The file form (full lengths, unit normal).
    pub fn to_file(&self) -> PrimitiveFile {
        match *self {
            Primitive::Box { half_extents: h } => PrimitiveFile::Box { size: [2.0 * h.x, 2.0 * h.y, 2.0 * h.z] },
            Primitive::Sphere { radius } => PrimitiveFile::Sphere { radius },
            Primitive::Cylinder { radius, half_height } => {
                PrimitiveFile::Cylinder { radius, height: 2.0 * half_height }
            }
            Primitive::Capsule { radius, half_height } => PrimitiveFile::Capsule { radius, height: 2.0 * half_height },
            Primitive::Halfspace { normal, offset } => {
                PrimitiveFile::Halfspace { normal: [normal.x, normal.y, normal.z], offset }
            }
        }
    }

    /// Reads a primitive file (JSON, [`PrimitiveFile`]).
    ///
    /// # Errors
    /// [`Error::Io`], [`Error::Json`], or a validation error of [`Primitive::from_file`].
    pub fn load(path: &std::path::Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)?;
        Primitive::from_file(&serde_json::from_str(&text)?)
    }

    /// Writes the primitive file (pretty JSON).
    ///
    /// # Errors
    /// [`Error::Io`] or [`Error::Json`].
    pub fn save(&self, path: &std::path::Path) -> Result<()> {
        std::fs::write(path, serde_json::to_string_pretty(&self.to_file())?)?;
        Ok(())
    }

    /// The primitive's kind as its file tag (`box`, `sphere`, `cylinder`, `capsule`, `halfspace`).
    pub fn kind(&self) -> &'static str {
        match self {
            Primitive::Box { .. } => "box",
            Primitive::Sphere { .. } => "sphere",
            Primitive::Cylinder { .. } => "cylinder",
            Primitive::Capsule { .. } => "capsule",
            Primitive::Halfspace { .. } => "halfspace",
        }
    }

    /// Whether the set is bounded (every primitive but the halfspace).
    pub fn is_bounded(&self) -> bool {
        !matches!(self, Primitive::Halfspace { .. })
    }

    /// Radius (meters) of the smallest ball about the frame's origin that holds the set;
    /// infinite for a halfspace.
    pub fn bounding_radius(&self) -> Real {
        match *self {
            Primitive::Box { half_extents } => half_extents.norm(),
            Primitive::Sphere { radius } => radius,
            Primitive::Cylinder { radius, half_height } => radius.hypot(half_height),
            Primitive::Capsule { radius, half_height } => radius + half_height,
            Primitive::Halfspace { .. } => Real::INFINITY,
        }
    }

    /// A length (meters) of the set's size, the unit of its solvers' relative tolerances: the
    /// largest half dimension (the offset's magnitude, at least 1, for a halfspace).
    pub fn scale(&self) -> Real {
        match *self {
            Primitive::Box { half_extents } => half_extents.max(),
            Primitive::Sphere { radius } => radius,
            Primitive::Cylinder { radius, half_height } => radius.max(half_height),
            Primitive::Capsule { radius, half_height } => radius + half_height,
            Primitive::Halfspace { offset, .. } => offset.abs().max(1.0),
        }
    }

    /// Half extents of the axis-aligned bounding box in the own frame; `None` for a halfspace.
    pub fn local_half_extents(&self) -> Option<Vector3> {
        Some(match *self {
            Primitive::Box { half_extents } => half_extents,
            Primitive::Sphere { radius } => Vector3::repeat(radius),
            Primitive::Cylinder { radius, half_height } => Vector3::new(radius, radius, half_height),
            Primitive::Capsule { radius, half_height } => Vector3::new(radius, radius, radius + half_height),
            Primitive::Halfspace { .. } => return None,
        })
    }

    /// The support point along the direction `e` (own frame, any nonzero length): a point of the
    /// set maximizing e·u, exact. For a halfspace it exists only along its normal (the plane's
    /// point closest to the origin), and is `None` otherwise.
    pub fn support_point(&self, e: &Vector3) -> Option<Vector3> {
        let sign = |v: Real, h: Real| if v >= 0.0 { h } else { -h };
        Some(match *self {
            Primitive::Box { half_extents: h } => Vector3::new(sign(e.x, h.x), sign(e.y, h.y), sign(e.z, h.z)),
            Primitive::Sphere { radius } => {
                let n = e.norm();
                if n > 0.0 {
                    e * (radius / n)
                } else {
                    Vector3::new(0.0, 0.0, radius)
                }
            }
            Primitive::Cylinder { radius, half_height } => {
                let rho = e.x.hypot(e.y);
                let (x, y) = if rho > 0.0 { (e.x * radius / rho, e.y * radius / rho) } else { (radius, 0.0) };
                Vector3::new(x, y, sign(e.z, half_height))
            }
            Primitive::Capsule { radius, half_height } => {
                let n = e.norm();
                let ball = if n > 0.0 { e * (radius / n) } else { Vector3::new(0.0, 0.0, radius) };
                ball + Vector3::new(0.0, 0.0, sign(e.z, half_height))
            }
            Primitive::Halfspace { normal, offset } => {
                if e.cross(&normal).norm() <= 1e-12 * e.norm() && e.dot(&normal) > 0.0 {
                    normal * offset
                } else {
                    return None;
                }
            }
        })
    }

    /// The support function h(e) = max_{u ∈ set} e·u (own frame); +∞ for a halfspace off its
    /// normal direction.
    pub fn support_value(&self, e: &Vector3) -> Real {
        match *self {
            Primitive::Box { half_extents: h } => e.x.abs() * h.x + e.y.abs() * h.y + e.z.abs() * h.z,
            Primitive::Sphere { radius } => radius * e.norm(),
            Primitive::Cylinder { radius, half_height } => radius * e.x.hypot(e.y) + half_height * e.z.abs(),
            Primitive::Capsule { radius, half_height } => radius * e.norm() + half_height * e.z.abs(),
            Primitive::Halfspace { normal, offset } => {
                let along = e.dot(&normal);
                if along > 0.0 && (e - normal * along).norm() <= 1e-12 * e.norm() {
                    along * offset
                } else {
                    Real::INFINITY
                }
            }
        }
    }

    /// The signed distance from the point `p` (own frame, meters) to the set's boundary
    /// (negative inside) and the boundary point closest to `p`, exact.
    pub fn closest_boundary_point(&self, p: &Vector3) -> (Real, Vector3) {
        match *self {
            Primitive::Box { half_extents: h } => box_closest(&h, p),
            Primitive::Sphere { radius } => ball_closest(&Vector3::zeros(), radius, p),
            Primitive::Cylinder { radius, half_height } => cylinder_closest(radius, half_height, p),
            Primitive::Capsule { radius, half_height } => {
                let axis = Vector3::new(0.0, 0.0, p.z.clamp(-half_height, half_height));
                ball_closest(&axis, radius, p)
            }
            Primitive::Halfspace { normal, offset } => {
                let s = normal.dot(p) - offset;
                (s, p - normal * s)
            }
        }
    }

    /// Volume in m³ (infinite for a halfspace).
    pub fn volume(&self) -> Real {
        use std::f64::consts::PI;
        match *self {
            Primitive::Box { half_extents: h } => 8.0 * h.x * h.y * h.z,
            Primitive::Sphere { radius } => 4.0 / 3.0 * PI * radius.powi(3),
            Primitive::Cylinder { radius, half_height } => PI * radius * radius * 2.0 * half_height,
            Primitive::Capsule { radius, half_height } => {
                PI * radius * radius * 2.0 * half_height + 4.0 / 3.0 * PI * radius.powi(3)
            }
            Primitive::Halfspace { .. } => Real::INFINITY,
        }
    }
}

/// Closest boundary point of the ball of radius `r` about `c` to `p`, with the signed distance.
fn ball_closest(c: &Vector3, r: Real, p: &Vector3) -> (Real, Vector3) {
    let d = p - c;
    let n = d.norm();
    let dir = if n > 0.0 { d / n } else { Vector3::z() };
    (n - r, c + dir * r)
}

/// Closest boundary point of the box |u_i| ≤ h_i to `p`, with the signed distance.
fn box_closest(h: &Vector3, p: &Vector3) -> (Real, Vector3) {
    let q = p.zip_map(h, |v, hi| v.clamp(-hi, hi));
    let outside = p - q;
    if outside.norm_squared() > 0.0 {
        return (outside.norm(), q);
    }
    // Inside: the nearest face.
    let gaps = Vector3::new(h.x - p.x.abs(), h.y - p.y.abs(), h.z - p.z.abs());
    let i = gaps.imin();
    let mut b = *p;
    b[i] = if p[i] >= 0.0 { h[i] } else { -h[i] };
    (-gaps[i], b)
}

/// Closest boundary point of the cylinder u_x² + u_y² ≤ r², |u_z| ≤ h to `p`, with the signed
/// distance.
fn cylinder_closest(r: Real, h: Real, p: &Vector3) -> (Real, Vector3) {
    let rho = p.x.hypot(p.y);
    let (cx, cy) = if rho > 0.0 { (p.x / rho, p.y / rho) } else { (1.0, 0.0) };
    let radial_out = rho - r;
    let axial_out = p.z.abs() - h;
    let z_cap = if p.z >= 0.0 { h } else { -h };
    if radial_out <= 0.0 && axial_out <= 0.0 {
        // Inside: the nearer of the side and the cap.
        return if radial_out >= axial_out {
            (radial_out, Vector3::new(cx * r, cy * r, p.z))
        } else {
            (axial_out, Vector3::new(p.x, p.y, z_cap))
        };
    }
    let q = Vector3::new(cx * rho.min(r), cy * rho.min(r), p.z.clamp(-h, h));
    ((p - q).norm(), q)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prim(file: PrimitiveFile) -> Primitive {
        Primitive::from_file(&file).unwrap()
    }

    #[test]
    fn file_forms_round_trip_and_bad_fields_are_named() {
        let json = r#"{"primitive": "box", "size": [1.2, 1.0, 0.04]}"#;
        let file: PrimitiveFile = serde_json::from_str(json).unwrap();
        let b = prim(file.clone());
        assert_eq!(b, Primitive::Box { half_extents: Vector3::new(0.6, 0.5, 0.02) });
        assert_eq!(b.to_file(), file);
        let h = prim(PrimitiveFile::Halfspace { normal: [0.0, 0.0, 2.0], offset: 1.0 });
        assert_eq!(h, Primitive::Halfspace { normal: Vector3::z(), offset: 0.5 });
        for (bad, field) in [
            (PrimitiveFile::Box { size: [1.0, -1.0, 1.0] }, "size[1]"),
            (PrimitiveFile::Sphere { radius: Real::NAN }, "radius"),
            (PrimitiveFile::Cylinder { radius: 1.0, height: 0.0 }, "height"),
            (PrimitiveFile::Halfspace { normal: [0.0; 3], offset: 1.0 }, "normal"),
            (PrimitiveFile::Capsule { radius: 1e9, height: 1.0 }, "radius"),
        ] {
            match Primitive::from_file(&bad) {
                Err(Error::InvalidArgument { field: f, .. }) => assert_eq!(f, field),
                other => panic!("{bad:?}: {other:?}"),
            }
        }
        assert!(serde_json::from_str::<PrimitiveFile>(r#"{"primitive": "cone", "radius": 1}"#).is_err());
    }

    /// The support value is the maximum of e·u over many sampled boundary points, and the
    /// support point attains it.
    #[test]
    fn support_points_attain_the_support_function() {
        let shapes = [
            prim(PrimitiveFile::Box { size: [0.4, 0.2, 1.0] }),
            prim(PrimitiveFile::Sphere { radius: 0.3 }),
            prim(PrimitiveFile::Cylinder { radius: 0.2, height: 0.8 }),
            prim(PrimitiveFile::Capsule { radius: 0.1, height: 0.5 }),
        ];
        for s in shapes {
            for k in 0..50 {
                let t = k as Real * 0.7;
                let e = Vector3::new(t.cos() * (1.3 * t).sin(), t.sin() * (1.3 * t).sin(), (1.3 * t).cos());
                let sp = s.support_point(&e).unwrap();
                assert!((e.dot(&sp) - s.support_value(&e)).abs() < 1e-14, "{s:?}");
                // The support point is on the boundary, and no sampled boundary point goes further.
                assert!(s.closest_boundary_point(&sp).0.abs() < 1e-14, "{s:?}");
                for j in 0..200 {
                    let a = j as Real * 0.37;
                    let d = Vector3::new(a.cos() * (2.1 * a).sin(), a.sin() * (2.1 * a).sin(), (2.1 * a).cos());
                    let q = s.support_point(&d).unwrap();
                    assert!(e.dot(&q) <= s.support_value(&e) + 1e-14);
                }
            }
        }
    }

    /// Closest boundary points against brute force over a fine boundary sampling (box) and
    /// closed forms (sphere, cylinder side and cap, capsule, halfspace).
    #[test]
    fn closest_boundary_points_match_references() {
        let b = prim(PrimitiveFile::Box { size: [2.0, 4.0, 6.0] });
        assert_eq!(b.closest_boundary_point(&Vector3::new(3.0, 0.0, 0.0)), (2.0, Vector3::new(1.0, 0.0, 0.0)));
        let (d, q) = b.closest_boundary_point(&Vector3::new(2.0, 3.0, 0.0));
        assert!((d - 2f64.sqrt()).abs() < 1e-15 && q == Vector3::new(1.0, 2.0, 0.0));
        assert_eq!(
            b.closest_boundary_point(&Vector3::new(0.5, 0.0, 2.9)),
            (-0.10000000000000009, Vector3::new(0.5, 0.0, 3.0))
        );
        let c = prim(PrimitiveFile::Cylinder { radius: 1.0, height: 2.0 });
        assert_eq!(c.closest_boundary_point(&Vector3::new(0.0, 3.0, 0.5)).0, 2.0);
        let (d, q) = c.closest_boundary_point(&Vector3::new(3.0, 0.0, 5.0));
        assert!((d - (4.0f64 + 16.0).sqrt()).abs() < 1e-15 && q == Vector3::new(1.0, 0.0, 1.0));
        assert_eq!(c.closest_boundary_point(&Vector3::new(0.0, 0.2, 0.9)).0, -0.09999999999999998);
        let k = prim(PrimitiveFile::Capsule { radius: 0.5, height: 2.0 });
        assert_eq!(k.closest_boundary_point(&Vector3::new(0.0, 0.0, 3.0)), (1.5, Vector3::new(0.0, 0.0, 1.5)));
        let h = prim(PrimitiveFile::Halfspace { normal: [0.0, 0.0, 1.0], offset: -1.0 });
        assert_eq!(h.closest_boundary_point(&Vector3::new(1.0, 2.0, 0.0)), (1.0, Vector3::new(1.0, 2.0, -1.0)));
    }
}
