//! Point clouds: `UpdatePointCloud`'s frames (a PointCloud2's packed float32 x, y, z, or a depth
//! image deprojected here), its filters, and the counts and summaries sent back.
//!
//! Decoding is validated field by field before anything is allocated for the points: a data
//! length that is no multiple of the point step, an offset beyond it, a depth image's size,
//! intrinsics or depth scale, and the frame's points against the server's limit
//! ([`frame_points`], called before the frame waits for its share of the decoding budget); NaN
//! and infinite coordinates are holes (counted by the filters), not errors.

use super::{pose_from_proto, prefix_field};
use crate::limits::FRAME_POINTS;
use crate::pb;
use crate::{Error, Result};
use sublevel_core::math::{Real, Vector3};
use sublevel_robot::cloud::bodies::{CloudBodySettings, UpdateReport};
use sublevel_robot::cloud::depth::{check_depth_scale, deproject, DepthPixels, Intrinsics};
use sublevel_robot::cloud::filter::{CloudFilter, FilterCounts, OutlierFilter};
use sublevel_scene::{CloudFrame, SceneCloud, DEFAULT_NOISE_RADIUS, DEFAULT_SELF_FILTER_PADDING};

/// The default depth scale of `depth_u16` (meters per unit: millimeters).
pub const DEFAULT_DEPTH_SCALE: Real = 0.001;

/// Bytes of one packed coordinate (float32).
const FLOAT: usize = 4;

/// The points of a PointCloud2's bytes (sensor frame, holes kept for the filters to count).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `points.point_step` (1 to 11 bytes), `points.x_offset` /
/// `points.y_offset` / `points.z_offset` (a float that does not fit in the step) or
/// `points.data` (a length that is no multiple of the step).
pub fn packed_points(p: &pb::PackedPoints) -> Result<Vec<[f32; 3]>> {
    let (step, offsets) = packed_layout(p)?;
    let read = |b: &[u8]| {
        let bytes = [b[0], b[1], b[2], b[3]];
        if p.is_bigendian {
            f32::from_be_bytes(bytes)
        } else {
            f32::from_le_bytes(bytes)
        }
    };
    Ok(p.data
        .chunks_exact(step)
        .map(|r| [read(&r[offsets[0]..]), read(&r[offsets[1]..]), read(&r[offsets[2]..])])
        .collect())
}

/// A PointCloud2's point step and x, y, z offsets (bytes), its data length checked to be a whole
/// number of points; reads none of the points.
///
/// # Errors
/// As [`packed_points`].
fn packed_layout(p: &pb::PackedPoints) -> Result<(usize, [usize; 3])> {
    let step = if p.point_step == 0 { 3 * FLOAT } else { p.point_step as usize };
    if step < 3 * FLOAT {
        return Err(Error::invalid(
            "points.point_step",
            format!("must be >= 12 bytes (three float32), or 0 for 12; got {step}"),
        ));
    }
    let offsets = if p.x_offset == 0 && p.y_offset == 0 && p.z_offset == 0 {
        [0, FLOAT, 2 * FLOAT]
    } else {
        [p.x_offset as usize, p.y_offset as usize, p.z_offset as usize]
    };
    for (name, o) in ["x_offset", "y_offset", "z_offset"].iter().zip(offsets) {
        if o.saturating_add(FLOAT) > step {
            return Err(Error::invalid(
                format!("points.{name}"),
                format!("{o} + 4 bytes of a float32 pass the point step of {step} bytes"),
            ));
        }
    }
    if !p.data.len().is_multiple_of(step) {
        return Err(Error::invalid(
            "points.data",
            format!("{} bytes are no whole number of points of {step} bytes (point_step)", p.data.len()),
        ));
    }
    Ok((step, offsets))
}

/// The depth image's intrinsics, its pixels' bytes and bytes per pixel, and its depth
/// scale (meters per unit of `depth_u16`), every field checked; reads none of the pixels.
///
/// # Errors
/// As [`depth_points`].
fn depth_layout(d: &pb::DepthImage) -> Result<(Intrinsics, &[u8], usize, Real)> {
    use pb::depth_image::Pixels;
    let intrinsics =
        Intrinsics { width: d.width as usize, height: d.height as usize, fx: d.fx, fy: d.fy, cx: d.cx, cy: d.cy };
    intrinsics.validate().map_err(|e| prefix_field(e, "depth"))?;
    // Checked even for float32 pixels, which do not use it: an absurd scale is a client's bug.
    if d.depth_scale != 0.0 {
        check_depth_scale(d.depth_scale).map_err(|e| prefix_field(e, "depth"))?;
    }
    let scale = if d.depth_scale == 0.0 { DEFAULT_DEPTH_SCALE } else { d.depth_scale };
    let (field, bytes, size) = match &d.pixels {
        None => return Err(Error::invalid("depth.pixels", "required: set `depth_u16` or `depth_f32`")),
        Some(Pixels::DepthU16(b)) => ("depth.depth_u16", b.as_slice(), 2),
        Some(Pixels::DepthF32(b)) => ("depth.depth_f32", b.as_slice(), 4),
    };
    let pixels = intrinsics.pixels();
    if bytes.len() != pixels * size {
        return Err(Error::invalid(
            field,
            format!(
                "{} bytes, but width × height = {} × {} pixels of {size} bytes take {}",
                bytes.len(),
                d.width,
                d.height,
                pixels * size
            ),
        ));
    }
    Ok((intrinsics, bytes, size, scale))
}

/// The number of points of the frame of `req` (a depth image's width × height, a PointCloud2's
/// records), every field of the frame checked and its size held against `max_points` (the
/// server's `--max-frame-points`), before any point is decoded: microseconds, whatever the
/// frame's size.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `frame` (none given) or a field of the frame (as
/// [`packed_points`] and [`depth_points`]); [`Error::ResourceExhausted`] naming `points.data`
/// or `depth.width × depth.height`, the frame's points, the limit and its flag when the frame
/// has more than `max_points` points.
pub fn frame_points(req: &pb::UpdatePointCloudRequest, max_points: usize) -> Result<usize> {
    use pb::update_point_cloud_request::Frame;
    let (n, field, what) = match &req.frame {
        None => return Err(Error::invalid("frame", "required: set `points` or `depth`")),
        Some(Frame::Points(p)) => {
            let (step, _) = packed_layout(p)?;
            let n = p.data.len() / step;
            (n, "points.data", format!("{} bytes of {step}-byte points: {n} points", p.data.len()))
        }
        Some(Frame::Depth(d)) => {
            let (intrinsics, ..) = depth_layout(d)?;
            let n = intrinsics.pixels();
            (n, "depth.width × depth.height", format!("{} × {} = {n} pixels", d.width, d.height))
        }
    };
    if n > max_points {
        return Err(Error::ResourceExhausted(format!(
            "{field}: {what}, more than the {max_points} of one frame (set by {} / {}); send a smaller \
             or subsampled frame",
            FRAME_POINTS.flag, FRAME_POINTS.env
        )));
    }
    Ok(n)
}

/// The points of a depth image (sensor frame, holes left out) and the number of holes.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `depth.pixels` (none given), `depth.width`,
/// `depth.height`, `depth.fx`, `depth.fy` (outside 1e-3 to 1e7 pixels), `depth.cx`,
/// `depth.cy` (beyond ±1e7 pixels), `depth.depth_scale` (set, and outside 1e-6 to 1 m per unit),
/// or `depth.depth_u16` / `depth.depth_f32` (a byte count other than width × height × 2 or × 4).
pub fn depth_points(d: &pb::DepthImage) -> Result<(Vec<[f32; 3]>, usize)> {
    let (intrinsics, bytes, size, scale) = depth_layout(d)?;
    let mut out = Vec::new();
    let holes = match size {
        2 => {
            let raw: Vec<u16> = bytes.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect();
            deproject(DepthPixels::U16(&raw), &intrinsics, scale, &mut out)
        }
        _ => {
            let raw: Vec<f32> = bytes.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
            deproject(DepthPixels::F32(&raw), &intrinsics, scale, &mut out)
        }
    }
    .map_err(|e| prefix_field(e, "depth"))?;
    Ok((out, holes))
}

/// The filters of a request (absent: the defaults, [`CloudFilter::default`]) and the self
/// filter's padding when it is on.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `filter.workspace_min` / `filter.workspace_max` (one
/// without the other); the rest is checked by [`CloudFilter::validate`] when the frame is built.
pub fn cloud_filter(f: Option<&pb::CloudFilter>) -> Result<(CloudFilter, Option<Real>)> {
    let Some(f) = f else { return Ok((CloudFilter::default(), None)) };
    let defaults = CloudFilter::default();
    let vec = |v: &pb::Vec3| Vector3::new(v.x, v.y, v.z);
    let workspace = match (&f.workspace_min, &f.workspace_max) {
        (None, None) => None,
        (Some(lo), Some(hi)) => Some((vec(lo), vec(hi))),
        (Some(_), None) => return Err(Error::invalid("filter.workspace_max", "required with `workspace_min`")),
        (None, Some(_)) => return Err(Error::invalid("filter.workspace_min", "required with `workspace_max`")),
    };
    let outliers = f.outliers.as_ref().map(|o| {
        let d = OutlierFilter::default();
        OutlierFilter {
            neighbors: if o.neighbors == 0 { d.neighbors } else { o.neighbors as usize },
            std_ratio: if o.std_ratio == 0.0 { d.std_ratio } else { o.std_ratio },
        }
    });
    let filter = CloudFilter {
        min_range: f.min_range,
        max_range: if f.max_range == 0.0 { defaults.max_range } else { f.max_range },
        workspace,
        voxel: f.voxel.unwrap_or(defaults.voxel),
        outliers,
    };
    let padding = f.self_filter.then(|| f.self_filter_padding.unwrap_or(DEFAULT_SELF_FILTER_PADDING));
    Ok((filter, padding))
}

/// The frame of an `UpdatePointCloudRequest`: decoded, deprojected, with its pose, noise radius
/// and filters. Decoding takes milliseconds for a large frame: call it off the async workers.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `frame` (none given), the frame's fields
/// ([`packed_points`], [`depth_points`]), `sensor_pose.…` or the filter's ([`cloud_filter`]).
pub fn cloud_frame(req: &pb::UpdatePointCloudRequest) -> Result<CloudFrame> {
    use pb::update_point_cloud_request::Frame;
    let sensor_pose = pose_from_proto("sensor_pose", req.sensor_pose.as_ref())?;
    let (filter, self_filter) = cloud_filter(req.filter.as_ref())?;
    let (points, holes) = match &req.frame {
        None => return Err(Error::invalid("frame", "required: set `points` or `depth`")),
        Some(Frame::Points(p)) => (packed_points(p)?, 0),
        Some(Frame::Depth(d)) => depth_points(d)?,
    };
    Ok(CloudFrame {
        points,
        holes,
        sensor_pose,
        noise_radius: req.noise_radius.unwrap_or(DEFAULT_NOISE_RADIUS),
        filter,
        self_filter,
    })
}

/// The bodies model's settings of a request, `None` for the points model: `bodies`' fields, each
/// at 0 taking [`CloudBodySettings::default`]'s value.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `model` (a value this server does not know), `bodies.degree`
/// (not 2 or 4) or another `bodies.` field ([`CloudBodySettings::validate`]: `tolerance` in
/// (0, 1] m, `min_points` 1 to `max_points`, `max_points` ≥ 4, `max_clusters` 1 to 4096,
/// `slack` 0 to 1 m, `rescale_limit` finite ≥ 1).
pub fn cloud_model(req: &pb::UpdatePointCloudRequest) -> Result<Option<CloudBodySettings>> {
    match pb::CloudModel::try_from(req.model) {
        Ok(pb::CloudModel::Points) => return Ok(None),
        Ok(pb::CloudModel::Bodies) => {}
        Err(_) => {
            return Err(Error::invalid(
                "model",
                format!("unknown cloud model {}: CLOUD_MODEL_POINTS (0) or CLOUD_MODEL_BODIES (1)", req.model),
            ))
        }
    }
    let o = req.bodies.unwrap_or_default();
    let mut settings = CloudBodySettings::default();
    if o.tolerance != 0.0 {
        settings.tolerance = o.tolerance;
    }
    if o.min_points != 0 {
        settings.min_points = o.min_points as usize;
    }
    if o.max_points != 0 {
        settings.max_points = o.max_points as usize;
    }
    if o.max_clusters != 0 {
        settings.max_clusters = o.max_clusters as usize;
    }
    match o.degree {
        0 => {}
        2 | 4 => settings.fit = settings.fit.with_degree(o.degree as usize),
        d => return Err(Error::invalid("bodies.degree", format!("must be 2 or 4 (or 0 for 4), got {d}"))),
    }
    if o.rescale_limit != 0.0 {
        settings.rescale_limit = o.rescale_limit;
    }
    settings.slack = o.slack;
    settings.validate().map_err(|e| prefix_field(e, "bodies"))?;
    Ok(Some(settings))
}

/// What the bodies model did with a frame, as the proto message.
pub fn bodies_report_to_proto(r: &UpdateReport) -> pb::CloudBodiesReport {
    let n = |v: usize| v as u32;
    pb::CloudBodiesReport {
        clusters: n(r.clusters),
        outliers: r.outliers as u64,
        reused: n(r.reused),
        rescaled: n(r.rescaled),
        fitted: n(r.refitted),
        fallbacks: n(r.fallbacks),
        cluster_seconds: r.cluster_seconds,
        fit_seconds: r.check_seconds + r.fit_seconds,
    }
}

/// Filter counts as the proto message.
pub fn filter_counts_to_proto(c: &FilterCounts) -> pb::FilterCounts {
    let n = |v: usize| v as u64;
    pb::FilterCounts {
        input: n(c.input),
        holes: n(c.holes),
        range: n(c.range),
        workspace: n(c.workspace),
        voxel: n(c.voxel),
        outliers: n(c.outliers),
        robot: n(c.robot),
        kept: n(c.kept),
    }
}

/// A scene's cloud as its GetScene summary.
pub fn cloud_summary(c: &SceneCloud) -> pb::PointCloudSummary {
    pb::PointCloudSummary {
        name: c.name.clone(),
        points: c.cloud.len() as u64,
        noise_radius: c.cloud.radius(),
        memory_bytes: c.memory_bytes as u64,
        version: c.version,
        counts: Some(filter_counts_to_proto(&c.counts)),
        model: if c.bodies.is_some() { pb::CloudModel::Bodies } else { pb::CloudModel::Points } as i32,
        bodies: c.bodies.as_ref().map_or(0, |b| b.objects.len() as u32),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(e: Error) -> String {
        match e {
            Error::InvalidArgument { field, .. } => field,
            other => panic!("{other:?}"),
        }
    }

    /// Records of 16 bytes (x, y, z, then 4 bytes of intensity), as a ROS driver packs them, in
    /// both byte orders; and custom offsets.
    #[test]
    fn packed_points_read_every_layout() {
        let pts = [[1.0f32, -2.0, 3.5], [f32::NAN, 0.25, 1e-3]];
        for big in [false, true] {
            let mut data = Vec::new();
            for p in &pts {
                for v in p {
                    data.extend(if big { v.to_be_bytes() } else { v.to_le_bytes() });
                }
                data.extend([9u8; 4]);
            }
            let msg = pb::PackedPoints { data, point_step: 16, is_bigendian: big, ..Default::default() };
            let got = packed_points(&msg).unwrap();
            assert_eq!(got[0], pts[0]);
            assert!(got[1][0].is_nan() && got[1][1..] == pts[1][1..]);
        }
        // z, y, x in reverse order after a 4-byte header.
        let mut data = vec![0u8; 4];
        for v in [3.0f32, 2.0, 1.0] {
            data.extend(v.to_le_bytes());
        }
        let msg =
            pb::PackedPoints { data, point_step: 16, x_offset: 12, y_offset: 8, z_offset: 4, ..Default::default() };
        assert_eq!(packed_points(&msg).unwrap(), vec![[1.0, 2.0, 3.0]]);
        // Tightly packed by default; no points is an empty cloud.
        let msg = pb::PackedPoints {
            data: [1.0f32, 2.0, 3.0].iter().flat_map(|v| v.to_le_bytes()).collect(),
            ..Default::default()
        };
        assert_eq!(packed_points(&msg).unwrap(), vec![[1.0, 2.0, 3.0]]);
        assert!(packed_points(&pb::PackedPoints::default()).unwrap().is_empty());
    }

    #[test]
    fn bad_packed_points_name_the_field() {
        let bad = |m: pb::PackedPoints| field(packed_points(&m).unwrap_err());
        assert_eq!(bad(pb::PackedPoints { data: vec![0; 13], ..Default::default() }), "points.data");
        assert_eq!(bad(pb::PackedPoints { point_step: 8, ..Default::default() }), "points.point_step");
        let m = pb::PackedPoints { point_step: 16, x_offset: 0, y_offset: 4, z_offset: 13, ..Default::default() };
        assert_eq!(bad(m), "points.z_offset");
        let m = pb::PackedPoints { x_offset: 9, y_offset: 4, z_offset: 8, ..Default::default() };
        assert_eq!(bad(m), "points.x_offset");
    }

    /// A flat wall 1 m away (depth 1000 mm everywhere, or 1.0 m as float32): every pixel a point
    /// at z = 1; the holes counted.
    #[test]
    fn depth_images_deproject_and_name_their_fields() {
        use pb::depth_image::Pixels;
        let (w, h) = (8u32, 6u32);
        let mut raw: Vec<u16> = vec![1000; (w * h) as usize];
        raw[5] = 0;
        let image = |pixels| pb::DepthImage {
            width: w,
            height: h,
            fx: 50.0,
            fy: 50.0,
            cx: 3.5,
            cy: 2.5,
            pixels,
            depth_scale: 0.0,
        };
        let u16s = Pixels::DepthU16(raw.iter().flat_map(|v| v.to_le_bytes()).collect());
        let (points, holes) = depth_points(&image(Some(u16s))).unwrap();
        assert_eq!((points.len(), holes), (47, 1));
        assert!(points.iter().all(|p| (p[2] - 1.0).abs() < 1e-6));
        // Pixel (0, 0): x = (0 − 3.5)/50, y = (0 − 2.5)/50.
        assert!((points[0][0] + 0.07).abs() < 1e-6 && (points[0][1] + 0.05).abs() < 1e-6);
        let f32s = Pixels::DepthF32(std::iter::repeat_n(1.0f32.to_le_bytes(), 48).flatten().collect());
        assert_eq!(depth_points(&image(Some(f32s))).unwrap().1, 0);

        assert_eq!(field(depth_points(&image(None)).unwrap_err()), "depth.pixels");
        assert_eq!(field(depth_points(&image(Some(Pixels::DepthU16(vec![0; 95])))).unwrap_err()), "depth.depth_u16");
        assert_eq!(field(depth_points(&image(Some(Pixels::DepthF32(vec![0; 96])))).unwrap_err()), "depth.depth_f32");
        let mut bad = image(Some(Pixels::DepthU16(vec![0; 96])));
        bad.width = 0;
        assert_eq!(field(depth_points(&bad).unwrap_err()), "depth.width");
        let mut bad = image(Some(Pixels::DepthU16(vec![0; 96])));
        bad.fy = Real::NAN;
        assert_eq!(field(depth_points(&bad).unwrap_err()), "depth.fy");
        let mut bad = image(Some(Pixels::DepthU16(vec![0; 96])));
        bad.depth_scale = -1.0;
        assert_eq!(field(depth_points(&bad).unwrap_err()), "depth.depth_scale");
    }

    fn depth_request(width: u32, height: u32, pixels: Option<pb::depth_image::Pixels>) -> pb::UpdatePointCloudRequest {
        let depth = pb::DepthImage { width, height, fx: 500.0, fy: 500.0, cx: 1.0, cy: 1.0, pixels, depth_scale: 0.0 };
        pb::UpdatePointCloudRequest {
            frame: Some(pb::update_point_cloud_request::Frame::Depth(depth)),
            ..Default::default()
        }
    }

    /// The frame's size is read from its fields alone: a 64 × 64 image and 1001 points of a
    /// PointCloud2 are refused past their limits naming the field, the limit and its flag; at
    /// the limit they pass. A wrong byte count is named before the size is looked at.
    #[test]
    fn frame_sizes_are_checked_before_decoding() {
        use pb::depth_image::Pixels;
        let exhausted = |r: Result<usize>| match r {
            Err(Error::ResourceExhausted(m)) => m,
            other => panic!("{other:?}"),
        };
        // Width × height pixels of 2 bytes: the byte count is checked first, so send them.
        let req = depth_request(64, 64, Some(Pixels::DepthU16(vec![0; 64 * 64 * 2])));
        assert_eq!(frame_points(&req, 4096).unwrap(), 4096);
        let m = exhausted(frame_points(&req, 4095));
        assert!(m.starts_with("depth.width × depth.height: 64 × 64 = 4096 pixels"), "{m}");
        assert!(m.contains("--max-frame-points") && m.contains("SUBLEVEL_MAX_FRAME_POINTS"), "{m}");
        // A wrong byte count names its field before the size limit is looked at.
        let req = depth_request(4096, 4096, Some(Pixels::DepthU16(vec![0; 10])));
        assert_eq!(field(frame_points(&req, 1 << 22).unwrap_err()), "depth.depth_u16");

        let points = |n: usize| pb::UpdatePointCloudRequest {
            frame: Some(pb::update_point_cloud_request::Frame::Points(pb::PackedPoints {
                data: vec![0; 16 * n],
                point_step: 16,
                ..Default::default()
            })),
            ..Default::default()
        };
        assert_eq!(frame_points(&points(1000), 1000).unwrap(), 1000);
        let m = exhausted(frame_points(&points(1001), 1000));
        assert!(m.starts_with("points.data: 16016 bytes of 16-byte points: 1001 points"), "{m}");
        assert_eq!(field(frame_points(&pb::UpdatePointCloudRequest::default(), 10).unwrap_err()), "frame");
    }

    /// Focal lengths, principal points and depth scales no camera has are refused naming the
    /// field, and the message shows the number in a few characters.
    #[test]
    fn absurd_intrinsics_are_refused_naming_the_field() {
        use pb::depth_image::Pixels;
        let image = |edit: &dyn Fn(&mut pb::DepthImage)| {
            let mut req = depth_request(2, 2, Some(Pixels::DepthU16(vec![0; 8])));
            if let Some(pb::update_point_cloud_request::Frame::Depth(d)) = &mut req.frame {
                edit(d);
            }
            req
        };
        let refused = |edit: &dyn Fn(&mut pb::DepthImage)| {
            let req = image(edit);
            let Some(pb::update_point_cloud_request::Frame::Depth(d)) = &req.frame else { unreachable!() };
            let (a, b) = (frame_points(&req, 100).unwrap_err(), depth_points(d).unwrap_err());
            assert_eq!(a.to_string(), b.to_string());
            assert!(a.to_string().len() < 300, "{a}");
            (field(a), b.to_string())
        };
        let (f, m) = refused(&|d| d.fx = 1e-300);
        assert_eq!(f, "depth.fx");
        assert!(m.contains("1e-300"), "{m}");
        assert_eq!(refused(&|d| d.fy = 1e-300).0, "depth.fy");
        assert_eq!(refused(&|d| d.fy = 1e8).0, "depth.fy");
        assert_eq!(refused(&|d| d.cx = 1e300).0, "depth.cx");
        let (f, m) = refused(&|d| d.depth_scale = 1e300);
        assert_eq!(f, "depth.depth_scale");
        assert!(m.contains("1e300"), "{m}");
        assert_eq!(refused(&|d| d.depth_scale = 2.0).0, "depth.depth_scale");
        // Checked for float32 pixels too, where it is otherwise unused.
        assert_eq!(
            refused(&|d| {
                d.depth_scale = -1.0;
                d.pixels = Some(Pixels::DepthF32(vec![0; 16]));
            })
            .0,
            "depth.depth_scale"
        );
        // Sensible values at the ends of the ranges pass.
        for edit in [
            &(|d: &mut pb::DepthImage| d.fx = 1e-3) as &dyn Fn(&mut pb::DepthImage),
            &|d| d.fy = 1e7,
            &|d| d.depth_scale = 1e-6,
            &|d| d.depth_scale = 1.0,
        ] {
            let req = image(edit);
            assert_eq!(frame_points(&req, 100).unwrap(), 4);
        }
    }

    /// The bodies settings: absurd tolerances and slacks, `min_points` above `max_points`, and
    /// `max_clusters` out of range are refused naming `bodies.<field>`; 0 takes the defaults.
    #[test]
    fn bodies_settings_are_bounded() {
        let req = |o: pb::CloudBodyOptions| pb::UpdatePointCloudRequest {
            model: pb::CloudModel::Bodies as i32,
            bodies: Some(o),
            ..Default::default()
        };
        let s = cloud_model(&req(pb::CloudBodyOptions::default())).unwrap().unwrap();
        assert_eq!((s.tolerance, s.min_points, s.max_points, s.max_clusters), (0.05, 10, 2000, 256));
        let s = cloud_model(&req(pb::CloudBodyOptions { max_clusters: 4096, ..Default::default() })).unwrap().unwrap();
        assert_eq!(s.max_clusters, 4096);
        let bad = |o: pb::CloudBodyOptions| {
            let e = cloud_model(&req(o)).unwrap_err();
            assert!(e.to_string().len() < 300, "{e}");
            field(e)
        };
        assert_eq!(bad(pb::CloudBodyOptions { tolerance: 1e300, ..Default::default() }), "bodies.tolerance");
        assert_eq!(bad(pb::CloudBodyOptions { tolerance: 1.5, ..Default::default() }), "bodies.tolerance");
        assert_eq!(bad(pb::CloudBodyOptions { slack: 1e300, ..Default::default() }), "bodies.slack");
        assert_eq!(bad(pb::CloudBodyOptions { max_clusters: 4097, ..Default::default() }), "bodies.max_clusters");
        assert_eq!(bad(pb::CloudBodyOptions { min_points: 3000, ..Default::default() }), "bodies.min_points");
        assert_eq!(
            bad(pb::CloudBodyOptions { max_points: 3, min_points: 1, ..Default::default() }),
            "bodies.max_points"
        );
        assert_eq!(bad(pb::CloudBodyOptions { rescale_limit: 0.5, ..Default::default() }), "bodies.rescale_limit");
    }

    #[test]
    fn filters_take_their_defaults() {
        let (f, padding) = cloud_filter(None).unwrap();
        assert_eq!((f, padding), (CloudFilter::default(), None));
        let msg = pb::CloudFilter {
            voxel: Some(0.0),
            outliers: Some(pb::OutlierFilter::default()),
            self_filter: true,
            ..Default::default()
        };
        let (f, padding) = cloud_filter(Some(&msg)).unwrap();
        assert_eq!((f.max_range, f.voxel, f.outliers), (10.0, 0.0, Some(OutlierFilter::default())));
        assert_eq!(padding, Some(DEFAULT_SELF_FILTER_PADDING));
        let msg = pb::CloudFilter { workspace_min: Some(pb::Vec3::default()), ..Default::default() };
        assert_eq!(field(cloud_filter(Some(&msg)).unwrap_err()), "filter.workspace_max");
    }
}
