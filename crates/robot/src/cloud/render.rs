//! A simulated depth camera: depth images ray-cast from a world of primitives and meshes, for
//! tests and benchmarks (scenes of boxes, cylinders and spheres rendered into the frames a depth
//! camera would give, then deprojected and filtered into cloud obstacles).
//!
//! ```text
//! camera   the optical frame of [`super::depth`] (z forward, x right, y down), placed in the
//!          world by an isometry ([`look_at`] builds one)
//! ray      pixel (u, v)'s ray through (u, v) itself — integer coordinates are pixel centers,
//!          as [`super::depth::deproject`] takes them — from the camera's origin along
//!          R·((u − cx)/fx, (v − cy)/fy, 1)
//! depth    the optical-axis z of the first surface the ray meets (not the ray's length), in
//!          meters; 0 when it meets none within max_range (z ≤ max_range)
//! shapes   primitives and meshes by parry's ray casts; point clouds are not rendered
//! ```
//!
//! Surfaces are hit from either side (a camera inside a box sees its walls from within). An
//! object is only ray-cast when the ray passes through its bounding ball nearer than the best hit
//! so far, so a frame costs about one ball test per pixel and object plus the casts of the
//! objects actually in view.

use super::depth::{pixel_ray, Intrinsics};
use crate::exact::{exact_primitive, parry_pose};
use crate::world::{WorldObject, WorldShape};
use crate::{Error, Result};
use parry3d_f64::query::Ray;
use parry3d_f64::shape::SharedShape;
use rand::{Rng, SeedableRng};
use sublevel_core::math::{Isometry3, Matrix3, Real, UnitQuaternion, Vector3};

/// Most a depth may be rendered out to (meters).
pub const MAX_RENDER_RANGE: Real = 1.0e4;

/// Largest depth noise a frame may ask for (meters).
pub const MAX_DEPTH_NOISE: Real = 1.0;

/// Depth noise of a simulated camera: additive Gaussian noise of standard deviation `sigma` on
/// each return's depth (misses stay 0), drawn from a generator seeded with `seed` (rand's
/// `StdRng`), so that a frame is reproducible for a given seed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthNoise {
    /// Standard deviation of the depth noise (meters, in [0, [`MAX_DEPTH_NOISE`]]).
    pub sigma: Real,
    /// Seed of the noise.
    pub seed: u64,
}

/// One object ready to cast rays at: parry's shape and pose, and the world bounding ball
/// (radius ∞ for a halfspace, which every ray is tried against).
struct Target {
    shape: SharedShape,
    pose: parry3d_f64::math::Pose,
    center: Vector3,
    radius: Real,
}

fn targets(world: &[WorldObject]) -> Vec<Target> {
    world
        .iter()
        .filter_map(|o| {
            let (shape, offset) = match &o.shape {
                WorldShape::Primitive(p) => {
                    let e = exact_primitive(p);
                    (e.shape, e.offset)
                }
                WorldShape::Mesh(m) => (m.exact.clone(), Isometry3::identity()),
                WorldShape::Body(b) => (b.exact.clone(), Isometry3::identity()),
                WorldShape::Points(_) => return None,
            };
            let (c, radius) = o.shape.ball();
            let center = o.pose.transform_point(&c.into()).coords;
            Some(Target { shape, pose: parry_pose(&(o.pose * offset)), center, radius })
        })
        .collect()
}

/// Renders the depth image (meters, `intrinsics.width × intrinsics.height`, row-major; module
/// docs) that a pinhole depth camera at `camera` (optical frame → world) sees of `world`, with
/// returns out to `max_range` meters of depth; 0.0 where a pixel sees nothing. `noise`, when
/// given, perturbs every return ([`DepthNoise`]); a return the noise pushes to a depth ≤ 0
/// becomes a hole (0.0).
///
/// # Errors
/// As [`Intrinsics::validate`]; [`Error::InvalidArgument`] naming `camera` (not finite),
/// `max_range` (not finite, ≤ 0 or above [`MAX_RENDER_RANGE`]) or `noise.sigma` (not finite,
/// negative or above [`MAX_DEPTH_NOISE`]).
pub fn render_depth(
    world: &[WorldObject],
    camera: &Isometry3,
    intrinsics: &Intrinsics,
    max_range: Real,
    noise: Option<DepthNoise>,
) -> Result<Vec<f32>> {
    intrinsics.validate()?;
    if camera.to_homogeneous().iter().any(|v| !v.is_finite()) {
        return Err(Error::invalid("camera", "must be finite"));
    }
    if !(max_range.is_finite() && max_range > 0.0 && max_range <= MAX_RENDER_RANGE) {
        return Err(Error::invalid(
            "max_range",
            format!("must be finite, in (0, {MAX_RENDER_RANGE:e}] m, got {max_range}"),
        ));
    }
    if let Some(n) = &noise {
        if !(n.sigma.is_finite() && (0.0..=MAX_DEPTH_NOISE).contains(&n.sigma)) {
            return Err(Error::invalid(
                "noise.sigma",
                format!("must be finite, in [0, {MAX_DEPTH_NOISE}] m, got {}", n.sigma),
            ));
        }
    }
    let targets = targets(world);
    let (w, h) = (intrinsics.width, intrinsics.height);
    let origin = camera.translation.vector;
    let ray_origin = parry3d_f64::math::Vector::new(origin.x, origin.y, origin.z);
    let mut depth = vec![0.0f32; w * h];
    for v in 0..h {
        for u in 0..w {
            // The ray at unit depth, in the world; its unit direction `dir` reaches depth z at
            // length z·|r|, so a hit at length t has depth t/|r|.
            let r = camera.rotation * pixel_ray(intrinsics, u as Real, v as Real);
            let len = r.norm();
            let dir = r / len;
            let mut best = max_range * len;
            let mut hit = false;
            for t in &targets {
                if t.radius.is_finite() {
                    // The ray's entry into the bounding ball, if any, before the best hit.
                    let to_center = t.center - origin;
                    let along = to_center.dot(&dir);
                    let off2 = to_center.norm_squared() - along * along;
                    let r2 = t.radius * t.radius;
                    if off2 > r2 || along + t.radius < 0.0 || along - (r2 - off2).sqrt() > best {
                        continue;
                    }
                }
                let ray = Ray::new(ray_origin, parry3d_f64::math::Vector::new(dir.x, dir.y, dir.z));
                if let Some(toi) = t.shape.cast_ray(&t.pose, &ray, best, false) {
                    if toi > 0.0 && toi <= best {
                        best = toi;
                        hit = true;
                    }
                }
            }
            if hit {
                depth[v * w + u] = (best / len) as f32;
            }
        }
    }
    if let Some(n) = noise.filter(|n| n.sigma > 0.0) {
        let mut rng = rand::rngs::StdRng::seed_from_u64(n.seed);
        for z in depth.iter_mut().filter(|z| **z > 0.0) {
            let noisy = *z as Real + n.sigma * gaussian(&mut rng);
            *z = if noisy > 0.0 { noisy as f32 } else { 0.0 };
        }
    }
    Ok(depth)
}

/// A standard normal draw (Box–Muller).
fn gaussian(rng: &mut impl Rng) -> Real {
    // u1 in (0, 1], so that its logarithm is finite.
    let u1 = 1.0 - rng.random::<Real>();
    let u2 = rng.random::<Real>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// The pose (optical frame → world) of a camera at `eye` looking at `target`: z along
/// `target − eye`, y (down in the image) along −`up` made perpendicular to z, x = y × z (right
/// in the image). `up` need not be unit nor perpendicular to the view.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `eye` or `target` (not finite, or `target` within 1e-9 m
/// of `eye`) or `up` (not finite, zero, or parallel to the view direction).
pub fn look_at(eye: Vector3, target: Vector3, up: Vector3) -> Result<Isometry3> {
    for (field, p) in [("eye", &eye), ("target", &target), ("up", &up)] {
        if !p.iter().all(|v| v.is_finite()) {
            return Err(Error::invalid(field, format!("must be finite, got {p:?}")));
        }
    }
    let view = target - eye;
    if view.norm() <= 1e-9 {
        return Err(Error::invalid("target", format!("must differ from eye {eye:?}, got {target:?}")));
    }
    let z = view.normalize();
    let down = -up;
    let side = down.cross(&z);
    if up.norm() == 0.0 || side.norm() <= 1e-9 * up.norm() {
        return Err(Error::invalid(
            "up",
            format!("must be nonzero and not parallel to the view direction {z:?}, got {up:?}"),
        ));
    }
    let x = side.normalize();
    let y = z.cross(&x);
    let frame = nalgebra::Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
    let rotation = UnitQuaternion::from_rotation_matrix(&frame);
    Ok(Isometry3::from_parts(eye.into(), rotation))
}

#[cfg(test)]
mod tests {
    use super::*;
    use sublevel_core::primitive::Primitive;

    fn intr(width: usize, height: usize, f: Real) -> Intrinsics {
        Intrinsics { width, height, fx: f, fy: f, cx: (width as Real - 1.0) / 2.0, cy: (height as Real - 1.0) / 2.0 }
    }

    fn boxed(h: Vector3, at: Vector3) -> WorldObject {
        WorldObject::primitive("box", Primitive::Box { half_extents: h }, Isometry3::translation(at.x, at.y, at.z))
    }

    #[test]
    fn box_face_on_fills_its_projected_rectangle() {
        // Camera at the origin looking along +x (up +z): image x is world −y, image y world −z.
        let camera = look_at(Vector3::zeros(), Vector3::x(), Vector3::z()).unwrap();
        let k = intr(80, 60, 50.0);
        // Front face at x = 2: y ∈ [−0.3, 0.5], z ∈ [−0.2, 0.4].
        let b = boxed(Vector3::new(0.5, 0.4, 0.3), Vector3::new(2.5, 0.1, 0.1));
        let depth = render_depth(&[b], &camera, &k, 10.0, None).unwrap();
        let mut inside = 0;
        for v in 0..k.height {
            for u in 0..k.width {
                let r = pixel_ray(&k, u as Real, v as Real);
                // The ray at depth 2 meets world (2, −2·r.x, −2·r.y).
                let (y, z) = (-2.0 * r.x, -2.0 * r.y);
                let d = depth[v * k.width + u];
                let margin = 1e-9;
                if (-0.3 + margin..=0.5 - margin).contains(&y) && (-0.2 + margin..=0.4 - margin).contains(&z) {
                    assert!((d - 2.0).abs() < 1e-6, "({u}, {v}): {d}");
                    inside += 1;
                } else if !((-0.3 - margin..=0.5 + margin).contains(&y) && (-0.2 - margin..=0.4 + margin).contains(&z))
                {
                    assert_eq!(d, 0.0, "({u}, {v})");
                }
            }
        }
        // 0.8 m × 0.6 m at 2 m and 50 px/m-at-unit-depth: about 20 × 15 pixels.
        assert!((250..=400).contains(&inside), "{inside}");
        // Out of range: nothing.
        let b = boxed(Vector3::new(0.5, 0.4, 0.3), Vector3::new(2.5, 0.1, 0.1));
        assert!(render_depth(&[b], &camera, &k, 1.9, None).unwrap().iter().all(|d| *d == 0.0));
    }

    #[test]
    fn depth_is_along_the_optical_axis_and_nearest_wins() {
        // A wall 3 m ahead: every pixel has depth 3 however oblique its ray; a sphere in front
        // of it hides it at the center pixel (depth = distance − radius).
        let camera = look_at(Vector3::new(1.0, 2.0, 0.5), Vector3::new(1.0, 2.0, 4.0), Vector3::y()).unwrap();
        let k = intr(41, 31, 30.0);
        let wall = WorldObject::primitive(
            "floor",
            Primitive::Halfspace { normal: -Vector3::z(), offset: -3.5 },
            Isometry3::identity(),
        );
        let ball =
            WorldObject::primitive("ball", Primitive::Sphere { radius: 0.25 }, Isometry3::translation(1.0, 2.0, 2.0));
        let depth = render_depth(std::slice::from_ref(&wall), &camera, &k, 10.0, None).unwrap();
        assert!(depth.iter().all(|d| (d - 3.0).abs() < 1e-6));
        let depth = render_depth(&[wall, ball], &camera, &k, 10.0, None).unwrap();
        let center = depth[15 * k.width + 20];
        assert!((center - 1.25).abs() < 1e-6, "{center}");
        assert!((depth[0] - 3.0).abs() < 1e-6);
    }

    #[test]
    fn cylinders_and_meshes_are_rendered_points_are_not() {
        let camera = look_at(Vector3::zeros(), Vector3::x(), Vector3::z()).unwrap();
        let k = intr(21, 21, 20.0);
        // A vertical cylinder (axis z) of radius 0.2 centered 2 m ahead: front at x = 1.8.
        let cyl = WorldObject::primitive(
            "cyl",
            Primitive::Cylinder { radius: 0.2, half_height: 0.5 },
            Isometry3::translation(2.0, 0.0, 0.0),
        );
        let depth = render_depth(&[cyl], &camera, &k, 10.0, None).unwrap();
        assert!((depth[10 * 21 + 10] - 1.8).abs() < 1e-5, "{}", depth[10 * 21 + 10]);
        // A triangle mesh: a square facing the camera at x = 1.5.
        let verts = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .iter()
            .map(|&(y, z)| sublevel_core::math::Point3::new(1.5, y, z))
            .collect();
        let mesh = crate::world::WorldMesh::new(verts, vec![[0, 1, 2], [0, 2, 3]], None).unwrap();
        let mesh = WorldObject::mesh("square", std::sync::Arc::new(mesh), Isometry3::identity());
        let cloud = crate::cloud::PointCloud::new(vec![[1.0, 0.0, 0.0]], 0.1).unwrap();
        let cloud = WorldObject::points("cloud", std::sync::Arc::new(cloud), Isometry3::identity());
        let depth = render_depth(&[mesh, cloud], &camera, &k, 10.0, None).unwrap();
        assert!(depth.iter().all(|d| (d - 1.5).abs() < 1e-6));
    }

    #[test]
    fn noise_has_the_stated_deviation() {
        let camera = look_at(Vector3::zeros(), Vector3::x(), Vector3::z()).unwrap();
        let k = intr(200, 150, 150.0);
        let wall = boxed(Vector3::new(0.1, 50.0, 50.0), Vector3::new(2.1, 0.0, 0.0));
        let noise = DepthNoise { sigma: 0.01, seed: 7 };
        let depth = render_depth(std::slice::from_ref(&wall), &camera, &k, 10.0, Some(noise)).unwrap();
        let n = depth.len() as Real;
        let mean = depth.iter().map(|d| *d as Real - 2.0).sum::<Real>() / n;
        let std = (depth.iter().map(|d| (*d as Real - 2.0 - mean).powi(2)).sum::<Real>() / n).sqrt();
        assert!(mean.abs() < 0.001, "{mean}");
        assert!((std - 0.01).abs() < 0.001, "{std}");
        // Reproducible for a seed, different for another.
        assert_eq!(render_depth(std::slice::from_ref(&wall), &camera, &k, 10.0, Some(noise)).unwrap(), depth);
        let other = DepthNoise { seed: 8, ..noise };
        assert_ne!(render_depth(&[wall], &camera, &k, 10.0, Some(other)).unwrap(), depth);
    }

    #[test]
    fn look_at_points_z_at_the_target() {
        let eye = Vector3::new(1.0, -2.0, 0.5);
        let target = Vector3::new(-0.5, 1.0, 2.0);
        let up = Vector3::new(0.1, 0.0, 1.0);
        let pose = look_at(eye, target, up).unwrap();
        let view = (target - eye).normalize();
        assert!((pose.rotation * Vector3::z() - view).norm() < 1e-12);
        assert!((pose.translation.vector - eye).norm() < 1e-15);
        // y points down: against up, perpendicular to the view; x to the right, x × y = z.
        let y = pose.rotation * Vector3::y();
        let x = pose.rotation * Vector3::x();
        assert!(y.dot(&up) < 0.0 && y.dot(&view).abs() < 1e-12);
        assert!(x.dot(&up).abs() < 1e-12);
        assert!((x.cross(&y) - view).norm() < 1e-12);
        // The target projects onto the principal point.
        let t = pose.inverse_transform_point(&target.into());
        assert!(t.x.abs() < 1e-12 && t.y.abs() < 1e-12 && t.z > 0.0);
    }

    #[test]
    fn bad_inputs_name_the_field() {
        let e = |r: Result<Isometry3>| r.unwrap_err().to_string();
        let o = Vector3::zeros();
        assert!(e(look_at(o, o, Vector3::z())).contains("target"));
        assert!(e(look_at(o, Vector3::z(), Vector3::z())).contains("up"));
        assert!(e(look_at(o, Vector3::z(), -2.0 * Vector3::z())).contains("up"));
        assert!(e(look_at(o, Vector3::x(), o)).contains("up"));
        assert!(e(look_at(Vector3::repeat(Real::NAN), Vector3::x(), Vector3::z())).contains("eye"));
        let k = intr(8, 6, 10.0);
        let cam = Isometry3::identity();
        let r = |cam: &Isometry3, k: &Intrinsics, range: Real, noise: Option<DepthNoise>| {
            render_depth(&[], cam, k, range, noise).unwrap_err().to_string()
        };
        assert!(r(&cam, &k, 0.0, None).contains("max_range"));
        assert!(r(&cam, &k, Real::NAN, None).contains("max_range"));
        assert!(r(&cam, &k, 1e5, None).contains("max_range"));
        assert!(r(&Isometry3::translation(Real::NAN, 0.0, 0.0), &k, 5.0, None).contains("camera"));
        assert!(r(&cam, &Intrinsics { fx: 0.0, ..k }, 5.0, None).contains("fx"));
        assert!(r(&cam, &Intrinsics { width: 0, ..k }, 5.0, None).contains("width"));
        assert!(r(&cam, &k, 5.0, Some(DepthNoise { sigma: -0.1, seed: 0 })).contains("noise.sigma"));
        assert!(r(&cam, &k, 5.0, Some(DepthNoise { sigma: Real::NAN, seed: 0 })).contains("noise.sigma"));
        assert_eq!(render_depth(&[], &cam, &k, 5.0, None).unwrap(), vec![0.0; 48]);
    }
}
