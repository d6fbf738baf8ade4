//! Point clouds: `UpdatePointCloud`'s frames (a PointCloud2's packed float32 x, y, z, or a depth
//! image deprojected here), its filters, and the counts and summaries sent back.
//!
//! Decoding is validated field by field before anything is allocated for the points: a data
//! length that is no multiple of the point step, an offset beyond it, a depth image's size or
//! intrinsics; NaN and infinite coordinates are holes (counted by the filters), not errors.

use super::{pose_from_proto, prefix_field};
use crate::pb;
use crate::{Error, Result};
use sublevel_core::math::{Real, Vector3};
use sublevel_robot::cloud::bodies::{CloudBodySettings, UpdateReport};
use sublevel_robot::cloud::depth::{deproject, DepthPixels, Intrinsics};
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

/// The points of a depth image (sensor frame, holes left out) and the number of holes.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `depth.pixels` (none given), `depth.width`,
/// `depth.height`, `depth.fx`, `depth.fy`, `depth.cx`, `depth.cy`, `depth.depth_scale`, or
/// `depth.depth_u16` / `depth.depth_f32` (a byte count other than width × height × 2 or × 4).
pub fn depth_points(d: &pb::DepthImage) -> Result<(Vec<[f32; 3]>, usize)> {
    use pb::depth_image::Pixels;
    let intrinsics =
        Intrinsics { width: d.width as usize, height: d.height as usize, fx: d.fx, fy: d.fy, cx: d.cx, cy: d.cy };
    intrinsics.validate().map_err(|e| prefix_field(e, "depth"))?;
    let pixels = intrinsics.pixels();
    let (field, bytes, size) = match &d.pixels {
        None => return Err(Error::invalid("depth.pixels", "required: set `depth_u16` or `depth_f32`")),
        Some(Pixels::DepthU16(b)) => ("depth.depth_u16", b, 2),
        Some(Pixels::DepthF32(b)) => ("depth.depth_f32", b, 4),
    };
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
    let scale = if d.depth_scale == 0.0 { DEFAULT_DEPTH_SCALE } else { d.depth_scale };
    let mut out = Vec::new();
    let holes = match &d.pixels {
        Some(Pixels::DepthU16(b)) => {
            let raw: Vec<u16> = b.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]])).collect();
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
/// (not 2 or 4) or another `bodies.` field ([`CloudBodySettings::validate`]).
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
