//! The blended path: the waypoints' segments with each corner replaced by a circular arc
//! (module docs of [`super`]).

use sublevel_core::math::Real;
use sublevel_core::{Error, Result};

/// Angle (radians) below which two segments are taken as one straight line (no blend needed).
const STRAIGHT: Real = 1e-9;
/// Angle past which a corner is a reversal: the robot stops there (a blend would be a point).
const REVERSAL: Real = std::f64::consts::PI - 1e-6;
/// Segments shorter than this (joint-space distance) are dropped: repeated waypoints.
const REPEAT: Real = 1e-12;

/// One piece of a [`BlendedPath`], parameterized by arc length `u ∈ [0, length]`.
#[derive(Clone, Debug, PartialEq)]
pub enum Piece {
    /// `q(u) = from + u·direction`, `direction` a unit vector.
    Line {
        /// Its first configuration.
        from: Vec<Real>,
        /// Unit direction.
        direction: Vec<Real>,
        /// Its length.
        length: Real,
    },
    /// `q(u) = center + radius·(x cos θ + y sin θ)`, `θ = u / radius ∈ [0, angle]`, with `x`, `y`
    /// orthonormal: the blend of corner `corner` (the index of its waypoint).
    Arc {
        /// The arc's center.
        center: Vec<Real>,
        /// Unit vector from the center to the arc's first configuration.
        x: Vec<Real>,
        /// Unit tangent at the arc's first configuration (the incoming segment's direction).
        y: Vec<Real>,
        /// Radius (> 0).
        radius: Real,
        /// Angle turned (radians, in (0, π)).
        angle: Real,
        /// The waypoint whose corner it blends.
        corner: usize,
    },
}

impl Piece {
    /// Its arc length.
    pub fn length(&self) -> Real {
        match self {
            Piece::Line { length, .. } => *length,
            Piece::Arc { radius, angle, .. } => radius * angle,
        }
    }

    /// `q(u)`, `q'(u)` and `q''(u)` written into the three slices (the robot's length each).
    pub fn evaluate(&self, u: Real, q: &mut [Real], dq: &mut [Real], ddq: &mut [Real]) {
        match self {
            Piece::Line { from, direction, .. } => {
                for k in 0..from.len() {
                    q[k] = from[k] + u * direction[k];
                    dq[k] = direction[k];
                    ddq[k] = 0.0;
                }
            }
            Piece::Arc { center, x, y, radius, .. } => {
                let (sin, cos) = (u / radius).sin_cos();
                for k in 0..center.len() {
                    let radial = x[k] * cos + y[k] * sin;
                    q[k] = center[k] + radius * radial;
                    dq[k] = -x[k] * sin + y[k] * cos;
                    ddq[k] = -radial / radius;
                }
            }
        }
    }

    /// The configuration at `u`.
    pub fn at(&self, u: Real) -> Vec<Real> {
        let n = match self {
            Piece::Line { from, .. } => from.len(),
            Piece::Arc { center, .. } => center.len(),
        };
        let (mut q, mut dq, mut ddq) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        self.evaluate(u, &mut q, &mut dq, &mut ddq);
        q
    }
}

/// A path of straight pieces and circular blends, continuous in position and, except at its
/// stops, in direction (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct BlendedPath {
    /// Its pieces in order.
    pub pieces: Vec<Piece>,
    /// Per piece, whether the robot comes to rest at its end (always for the last piece).
    pub stop_after: Vec<bool>,
    /// The waypoints it was made from, consecutive repeats dropped.
    pub waypoints: Vec<Vec<Real>>,
    /// The deviation each waypoint's corner was given (0 at both ends and at stops).
    pub deviation: Vec<Real>,
}

impl BlendedPath {
    /// The path through `waypoints` with every interior corner blended within `max_deviation`
    /// (≥ 0; 0 stops at every waypoint).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `path` (fewer than two distinct waypoints), `path[i]`
    /// (a waypoint of another length than the first, or not finite), or `max_deviation`.
    pub fn new(waypoints: &[Vec<Real>], max_deviation: Real) -> Result<Self> {
        if !(max_deviation.is_finite() && max_deviation >= 0.0) {
            return Err(Error::invalid("max_deviation", format!("must be finite and ≥ 0, got {max_deviation}")));
        }
        let points = distinct(waypoints)?;
        let deviation = (0..points.len())
            .map(|i| if i == 0 || i + 1 == points.len() { 0.0 } else { max_deviation })
            .collect::<Vec<_>>();
        Ok(Self::with_deviations(points, deviation))
    }

    /// The path through `points` (distinct consecutive waypoints) with corner `i` blended within
    /// `deviation[i]`.
    pub(super) fn with_deviations(points: Vec<Vec<Real>>, mut deviation: Vec<Real>) -> Self {
        let m = points.len();
        let n = points[0].len();
        let direction = |i: usize| -> (Vec<Real>, Real) {
            let d: Vec<Real> = (0..n).map(|k| points[i + 1][k] - points[i][k]).collect();
            let len = norm(&d);
            (d.iter().map(|v| v / len).collect(), len)
        };
        let segments: Vec<(Vec<Real>, Real)> = (0..m - 1).map(direction).collect();
        // Per corner: (blend distance ℓ along each segment, the arc), or a stop / straight.
        let mut blends: Vec<Option<(Real, Piece)>> = vec![None; m];
        let mut stop = vec![false; m];
        for i in 1..m - 1 {
            let (y1, len1) = &segments[i - 1];
            let (y2, len2) = &segments[i];
            let cos = dot(y1, y2).clamp(-1.0, 1.0);
            let alpha = cos.acos();
            if alpha < STRAIGHT {
                deviation[i] = 0.0;
                continue;
            }
            if deviation[i] <= 0.0 || alpha > REVERSAL {
                deviation[i] = 0.0;
                stop[i] = true;
                continue;
            }
            let half = alpha / 2.0;
            let ell = (len1 / 2.0).min(len2 / 2.0).min(deviation[i] * half.sin() / (1.0 - half.cos()));
            let radius = ell / half.tan();
            let bisector: Vec<Real> = (0..n).map(|k| y2[k] - y1[k]).collect();
            let bn = norm(&bisector);
            let center: Vec<Real> = (0..n).map(|k| points[i][k] + bisector[k] / bn * radius / half.cos()).collect();
            let start: Vec<Real> = (0..n).map(|k| points[i][k] - ell * y1[k]).collect();
            let x: Vec<Real> = (0..n).map(|k| (start[k] - center[k]) / radius).collect();
            // The deviation the blend actually takes (ℓ may be capped by half a segment).
            deviation[i] = radius * (1.0 / half.cos() - 1.0);
            blends[i] = Some((ell, Piece::Arc { center, x, y: y1.clone(), radius, angle: alpha, corner: i }));
        }
        let mut pieces = Vec::new();
        let mut stop_after = Vec::new();
        for (i, (y, len)) in segments.iter().enumerate() {
            let cut0 = blends[i].as_ref().map_or(0.0, |b| b.0);
            let cut1 = blends[i + 1].as_ref().map_or(0.0, |b| b.0);
            let length = len - cut0 - cut1;
            if length > REPEAT * len.max(1.0) {
                let from = (0..n).map(|k| points[i][k] + cut0 * y[k]).collect();
                pieces.push(Piece::Line { from, direction: y.clone(), length });
                stop_after.push(stop[i + 1] || i + 2 == m);
            } else if let Some(last) = stop_after.last_mut() {
                *last |= stop[i + 1] || i + 2 == m;
            }
            if let Some((_, arc)) = &blends[i + 1] {
                pieces.push(arc.clone());
                stop_after.push(false);
            }
        }
        if let Some(last) = stop_after.last_mut() {
            *last = true;
        }
        Self { pieces, stop_after, waypoints: points, deviation }
    }

    /// The path parameter (arc length) at which each piece starts.
    pub fn starts(&self) -> Vec<Real> {
        let mut total = 0.0;
        self.pieces
            .iter()
            .map(|p| {
                let start = total;
                total += p.length();
                start
            })
            .collect()
    }

    /// The piece holding path parameter `s` (the later one at a boundary; `starts` from
    /// [`BlendedPath::starts`]) and the parameter within it.
    pub fn locate(&self, starts: &[Real], s: Real) -> (usize, Real) {
        let i = starts.partition_point(|&a| a <= s).saturating_sub(1).min(self.pieces.len() - 1);
        (i, (s - starts[i]).clamp(0.0, self.pieces[i].length()))
    }

    /// Its total length (joint-space distance).
    pub fn length(&self) -> Real {
        self.pieces.iter().map(Piece::length).sum()
    }

    /// The number of configuration entries.
    pub fn dof(&self) -> usize {
        self.waypoints[0].len()
    }

    /// The arcs (blends) of the path, with their index in [`BlendedPath::pieces`].
    pub fn arcs(&self) -> impl Iterator<Item = (usize, &Piece)> {
        self.pieces.iter().enumerate().filter(|(_, p)| matches!(p, Piece::Arc { .. }))
    }
}

/// `waypoints` with consecutive repeats dropped, checked.
fn distinct(waypoints: &[Vec<Real>]) -> Result<Vec<Vec<Real>>> {
    let Some(first) = waypoints.first() else {
        return Err(Error::invalid("path", "no waypoint: a path needs at least two"));
    };
    let n = first.len();
    if n == 0 {
        return Err(Error::invalid("path[0]", "a waypoint has no entry"));
    }
    let mut out: Vec<Vec<Real>> = Vec::with_capacity(waypoints.len());
    for (i, w) in waypoints.iter().enumerate() {
        if w.len() != n {
            return Err(Error::invalid(format!("path[{i}]"), format!("{} values where path[0] has {n}", w.len())));
        }
        if let Some(k) = w.iter().position(|v| !v.is_finite()) {
            return Err(Error::invalid(format!("path[{i}][{k}]"), format!("{} is not a finite number", w[k])));
        }
        let repeat = out.last().is_some_and(|last| {
            let d: Vec<Real> = (0..n).map(|k| w[k] - last[k]).collect();
            norm(&d) <= REPEAT * norm(last).max(1.0)
        });
        if !repeat {
            out.push(w.clone());
        }
    }
    if out.len() < 2 {
        return Err(Error::invalid(
            "path",
            format!("{} waypoints, all the same configuration: a path needs two distinct ones", waypoints.len()),
        ));
    }
    Ok(out)
}

fn dot(a: &[Real], b: &[Real]) -> Real {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn norm(a: &[Real]) -> Real {
    dot(a, a).sqrt()
}
