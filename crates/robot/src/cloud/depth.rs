//! Depth images deprojected into sensor-frame points through pinhole intrinsics.
//!
//! ```text
//! frame   the camera's optical frame (ROS REP 103, `*_optical_frame`): z forward along the
//!         optical axis, x right, y down
//! pixel   (u, v) = (column, row), row-major; integer coordinates are pixel centers (the
//!         convention of OpenCV and of a CameraInfo's K, in which cx, cy are given)
//! point   z = depth (meters: a u16 value × depth_scale, or the f32 value),
//!         x = (u − cx)·z/fx,  y = (v − cy)·z/fy
//! hole    a depth of 0, NaN, ±∞ or below 0 (a camera's "no return"): no point
//! ```
//!
//! The depth is the distance along the optical axis (a depth camera's z-buffer), not along the
//! pixel's ray; [`super::render`] renders frames in the same convention, so that a rendered
//! frame deprojects onto the rendered surfaces.

use crate::{Error, Result};
use sublevel_core::error::show_real;
use sublevel_core::math::{Real, Vector3};

/// Most pixels a depth image may have (4096 × 4096; a 640 × 480 frame has 307 200). A server
/// bounds its frames further (`sublevel serve --max-frame-points`).
pub const MAX_PIXELS: usize = 1 << 24;

/// Smallest and largest focal length `fx`, `fy` (pixels): a lens with a focal length under a
/// thousandth of a pixel, or over ten million pixels, is no camera's; outside these bounds the
/// deprojected coordinates lose every significant digit or overflow.
pub const FOCAL_RANGE: (Real, Real) = (1e-3, 1e7);

/// Largest magnitude of the principal point `cx`, `cy` (pixels).
pub const MAX_PRINCIPAL: Real = 1e7;

/// Smallest and largest `depth_scale` of 16-bit depths (meters per unit): the largest depth,
/// 65 535 units, is then 6.6 cm to 65.5 km, and one unit 1 µm to 1 m (most cameras: 1 mm, some
/// 0.1 mm).
pub const DEPTH_SCALE_RANGE: (Real, Real) = (1e-6, 1.0);

/// Checks a 16-bit depth image's `depth_scale` (meters per unit) against [`DEPTH_SCALE_RANGE`].
///
/// # Errors
/// [`Error::InvalidArgument`] naming `depth_scale` when it is not finite or outside the range.
pub fn check_depth_scale(depth_scale: Real) -> Result<()> {
    let (lo, hi) = DEPTH_SCALE_RANGE;
    if depth_scale.is_finite() && (lo..=hi).contains(&depth_scale) {
        return Ok(());
    }
    Err(Error::invalid(
        "depth_scale",
        format!("must be finite and in [{lo:e}, {hi}] m per unit, got {}", show_real(depth_scale)),
    ))
}

/// Pinhole intrinsics of a depth image (pixels), as a ROS `sensor_msgs/CameraInfo`'s K.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    /// Image width (pixels).
    pub width: usize,
    /// Image height (pixels).
    pub height: usize,
    /// Focal length along x (pixels).
    pub fx: Real,
    /// Focal length along y (pixels).
    pub fy: Real,
    /// Principal point x (pixels).
    pub cx: Real,
    /// Principal point y (pixels).
    pub cy: Real,
}

impl Intrinsics {
    /// Checks the intrinsics.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `width` (0, or above [`MAX_PIXELS`]), `height` (0, or
    /// width × height above [`MAX_PIXELS`]), `fx` or `fy` (not finite or outside
    /// [`FOCAL_RANGE`]), `cx` or `cy` (not finite, or beyond ±[`MAX_PRINCIPAL`]).
    pub fn validate(&self) -> Result<()> {
        if self.width == 0 || self.width > MAX_PIXELS {
            return Err(Error::invalid("width", format!("must be 1–{MAX_PIXELS} pixels, got {}", self.width)));
        }
        let pixels = self.width.saturating_mul(self.height);
        if self.height == 0 || pixels > MAX_PIXELS {
            return Err(Error::invalid(
                "height",
                format!("must be ≥ 1 with width × height ≤ {MAX_PIXELS} pixels, got {} × {}", self.width, self.height),
            ));
        }
        let (lo, hi) = FOCAL_RANGE;
        for (field, f) in [("fx", self.fx), ("fy", self.fy)] {
            if !(f.is_finite() && (lo..=hi).contains(&f)) {
                return Err(Error::invalid(
                    field,
                    format!("must be finite and in [{lo:e}, {hi:e}] pixels, got {}", show_real(f)),
                ));
            }
        }
        for (field, c) in [("cx", self.cx), ("cy", self.cy)] {
            if !(c.is_finite() && c.abs() <= MAX_PRINCIPAL) {
                return Err(Error::invalid(
                    field,
                    format!("must be finite and within ±{MAX_PRINCIPAL:e} pixels, got {}", show_real(c)),
                ));
            }
        }
        Ok(())
    }

    /// How many pixels: width × height.
    pub fn pixels(&self) -> usize {
        self.width * self.height
    }
}

/// A depth image's pixels, row-major.
#[derive(Clone, Copy, Debug)]
pub enum DepthPixels<'a> {
    /// Unsigned 16-bit depths in units of `depth_scale` meters (1 mm for most cameras).
    U16(&'a [u16]),
    /// float32 depths in meters.
    F32(&'a [f32]),
}

impl DepthPixels<'_> {
    /// How many pixels.
    pub fn len(&self) -> usize {
        match self {
            DepthPixels::U16(d) => d.len(),
            DepthPixels::F32(d) => d.len(),
        }
    }

    /// Whether there are no pixels.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The ray of pixel (`u`, `v`) (column, row; pixel centers at integer coordinates) at unit
/// depth, in the optical frame: `((u − cx)/fx, (v − cy)/fy, 1)`; the point at depth z is z
/// times it. The intrinsics are taken as valid ([`Intrinsics::validate`]).
pub fn pixel_ray(intrinsics: &Intrinsics, u: Real, v: Real) -> Vector3 {
    Vector3::new((u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy, 1.0)
}

/// Deprojects `depth` (`intrinsics.width × intrinsics.height` pixels, row-major) into points of
/// the camera's optical frame (meters; module docs), one per valid pixel in pixel order,
/// appended to `out`; returns how many pixels were holes (0, NaN, ±∞ or negative depth, or a
/// point beyond float32's range). `depth_scale` (meters per unit) scales [`DepthPixels::U16`]
/// depths and is ignored for [`DepthPixels::F32`].
///
/// # Errors
/// As [`Intrinsics::validate`]; [`Error::InvalidArgument`] naming `depth_scale` (for u16
/// depths: [`check_depth_scale`]) or `depth` (its pixel count differs from width × height).
/// `out` is unchanged on error.
pub fn deproject(
    depth: DepthPixels<'_>,
    intrinsics: &Intrinsics,
    depth_scale: Real,
    out: &mut Vec<[f32; 3]>,
) -> Result<usize> {
    intrinsics.validate()?;
    if matches!(depth, DepthPixels::U16(_)) {
        check_depth_scale(depth_scale)?;
    }
    let (w, h) = (intrinsics.width, intrinsics.height);
    if depth.len() != w * h {
        return Err(Error::invalid(
            "depth",
            format!("has {} pixels, but the intrinsics' width × height is {w} × {h} = {}", depth.len(), w * h),
        ));
    }
    // The rays' x and y at unit depth, per column and per row.
    let xs: Vec<Real> = (0..w).map(|u| (u as Real - intrinsics.cx) / intrinsics.fx).collect();
    let ys: Vec<Real> = (0..h).map(|v| (v as Real - intrinsics.cy) / intrinsics.fy).collect();
    let before = out.len();
    out.reserve(w * h);
    let mut push = |i: usize, z: Real| -> bool {
        // `!(z > 0)` also catches NaN.
        if !(z > 0.0 && z.is_finite()) {
            return false;
        }
        let p = [(xs[i % w] * z) as f32, (ys[i / w] * z) as f32, z as f32];
        if !p.iter().all(|c| c.is_finite()) {
            return false;
        }
        out.push(p);
        true
    };
    let kept = match depth {
        DepthPixels::U16(d) => {
            d.iter().enumerate().filter(|&(i, &z)| z != 0 && push(i, z as Real * depth_scale)).count()
        }
        DepthPixels::F32(d) => d.iter().enumerate().filter(|&(i, &z)| push(i, z as Real)).count(),
    };
    debug_assert_eq!(out.len() - before, kept);
    Ok(w * h - kept)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloud::render::{look_at, render_depth};
    use crate::world::WorldObject;
    use sublevel_core::math::Isometry3;
    use sublevel_core::primitive::Primitive;

    fn k(width: usize, height: usize) -> Intrinsics {
        Intrinsics { width, height, fx: 500.0, fy: 400.0, cx: 1.5, cy: 0.5 }
    }

    fn close(a: [f32; 3], b: [Real; 3]) -> bool {
        (0..3).all(|i| (a[i] as Real - b[i]).abs() <= 1e-6 * (1.0 + b[i].abs()))
    }

    #[test]
    fn closed_form_points_for_u16_and_f32() {
        // 4 × 2 image; pixel i at (u, v) = (i % 4, i / 4).
        let intr = k(4, 2);
        let expect = |u: Real, v: Real, z: Real| [(u - 1.5) * z / 500.0, (v - 0.5) * z / 400.0, z];
        let raw: Vec<u16> = vec![1000, 0, 2000, 1500, 0, 3000, 250, 65535];
        let mut out = Vec::new();
        let holes = deproject(DepthPixels::U16(&raw), &intr, 0.001, &mut out).unwrap();
        assert_eq!(holes, 2);
        let want = [
            expect(0.0, 0.0, 1.0),
            expect(2.0, 0.0, 2.0),
            expect(3.0, 0.0, 1.5),
            expect(1.0, 1.0, 3.0),
            expect(2.0, 1.0, 0.25),
            expect(3.0, 1.0, 65.535),
        ];
        assert_eq!(out.len(), want.len());
        for (p, q) in out.iter().zip(&want) {
            assert!(close(*p, *q), "{p:?} vs {q:?}");
        }

        let f: Vec<f32> = vec![1.0, f32::NAN, 2.0, f32::INFINITY, -1.0, 3.0, 0.0, f32::NEG_INFINITY];
        let mut out = vec![[9.0; 3]];
        // depth_scale is not used (nor checked) for float depths.
        let holes = deproject(DepthPixels::F32(&f), &intr, Real::NAN, &mut out).unwrap();
        assert_eq!(holes, 5);
        assert_eq!(out[0], [9.0; 3]);
        let want = [expect(0.0, 0.0, 1.0), expect(2.0, 0.0, 2.0), expect(1.0, 1.0, 3.0)];
        assert_eq!(out.len(), 1 + want.len());
        for (p, q) in out[1..].iter().zip(&want) {
            assert!(close(*p, *q), "{p:?} vs {q:?}");
        }
        // The principal point's ray is the optical axis.
        let r = pixel_ray(&intr, 1.5, 0.5);
        assert_eq!(r, Vector3::new(0.0, 0.0, 1.0));
        assert_eq!(pixel_ray(&intr, 501.5, 400.5), Vector3::new(1.0, 1.0, 1.0));
    }

    #[test]
    fn bad_inputs_name_the_field() {
        let d = [1.0f32; 8];
        let run = |intr: Intrinsics, depth: DepthPixels<'_>, scale: Real| {
            let mut out = Vec::new();
            let e = deproject(depth, &intr, scale, &mut out).unwrap_err();
            assert!(out.is_empty());
            e.to_string()
        };
        let f = DepthPixels::F32(&d);
        assert!(run(k(0, 2), f, 1.0).contains("width"));
        assert!(run(k(4, 0), f, 1.0).contains("height"));
        assert!(run(k(MAX_PIXELS + 1, 1), f, 1.0).contains("width"));
        assert!(run(k(4097, 4096), f, 1.0).contains("height"));
        assert!(run(k(usize::MAX, usize::MAX), f, 1.0).contains("width"));
        assert!(run(k(1 << 20, 1 << 20), f, 1.0).contains("height"));
        assert!(run(Intrinsics { fx: 0.0, ..k(4, 2) }, f, 1.0).contains("fx"));
        assert!(run(Intrinsics { fx: Real::INFINITY, ..k(4, 2) }, f, 1.0).contains("fx"));
        assert!(run(Intrinsics { fy: -1.0, ..k(4, 2) }, f, 1.0).contains("fy"));
        assert!(run(Intrinsics { fy: Real::NAN, ..k(4, 2) }, f, 1.0).contains("fy"));
        assert!(run(Intrinsics { cx: Real::NAN, ..k(4, 2) }, f, 1.0).contains("cx"));
        assert!(run(Intrinsics { cy: Real::NEG_INFINITY, ..k(4, 2) }, f, 1.0).contains("cy"));
        let u = [1u16; 8];
        assert!(run(Intrinsics { fx: 1e-300, ..k(4, 2) }, f, 1.0).contains("fx"));
        assert!(run(Intrinsics { fy: 1e300, ..k(4, 2) }, f, 1.0).contains("fy"));
        assert!(run(Intrinsics { cx: -1e8, ..k(4, 2) }, f, 1.0).contains("cx"));
        let shown = run(Intrinsics { fy: 1e300, ..k(4, 2) }, f, 1.0);
        assert!(shown.contains("1e300") && shown.len() < 200, "{shown}");
        for scale in [0.0, -0.001, Real::NAN, Real::INFINITY, 1e300, 2.0, 1e-300] {
            assert!(run(k(4, 2), DepthPixels::U16(&u), scale).contains("depth_scale"));
        }
        let msg = run(k(3, 2), f, 1.0);
        assert!(msg.contains("depth") && msg.contains('8') && msg.contains('6'), "{msg}");
        assert!(run(k(4, 2), DepthPixels::U16(&u[..7]), 0.001).contains("depth"));
    }

    #[test]
    fn points_beyond_float32_are_holes() {
        let mut out = Vec::new();
        let holes = deproject(DepthPixels::F32(&[1e38, 2.0]), &Intrinsics { fx: 1e-3, ..k(2, 1) }, 1.0, &mut out);
        assert_eq!((holes.unwrap(), out.len()), (1, 1));
    }

    #[test]
    fn rendered_plane_deprojects_onto_the_plane() {
        // A wall 2.5 m ahead of a tilted camera: every point of the rendered frame lies on it.
        let intr = Intrinsics { width: 64, height: 48, fx: 60.0, fy: 60.0, cx: 31.5, cy: 23.5 };
        let wall = WorldObject::primitive(
            "wall",
            Primitive::Box { half_extents: Vector3::new(0.01, 20.0, 20.0) },
            Isometry3::translation(2.51, 0.0, 0.0),
        );
        let eye = Vector3::new(0.0, 0.3, 1.0);
        let camera = look_at(eye, Vector3::new(2.5, -0.5, 0.6), Vector3::z()).unwrap();
        let depth = render_depth(&[wall], &camera, &intr, 10.0, None).unwrap();
        let mut out = Vec::new();
        let holes = deproject(DepthPixels::F32(&depth), &intr, 1.0, &mut out).unwrap();
        assert_eq!((holes, out.len()), (0, intr.pixels()));
        for p in &out {
            let w = camera.transform_point(&Vector3::new(p[0] as Real, p[1] as Real, p[2] as Real).into());
            assert!((w.x - 2.5).abs() <= 1e-5, "{w:?}");
        }
    }
}
