//! Path simplification: what the search returns zigzags; what a robot should execute is short.
//! Every edge a step adds is checked by the checker's sampled test at the search's resolution
//! (the certification that follows proves the edges of the result).
//!
//! ```text
//! reduce     from each kept waypoint, jump to the farthest later waypoint whose straight edge is
//!            free (the redundant waypoints in between go)
//! shortcut   pick two points on the path (anywhere on two different edges), and replace the path
//!            between them by the straight edge when it is free; stop after `shortcut_attempts`
//!            tries or when `shortcut_attempts / 4` tries in a row changed nothing
//! reduce     once more
//! smooth     (optional) cut every interior corner: waypoint p_i between p_{i−1} and p_{i+1}
//!            becomes the two points a quarter of the way towards each neighbour, when the edge
//!            joining them is free (Chaikin's corner cutting, 1974); `smoothing_passes` times
//! ```
//!
//! Each step only replaces a piece of the path by one no longer than it (straight edges between
//! points of the piece), so the length never grows.

use crate::space::JointSpace;
use crate::validity::Validity;
use rand::Rng;
use std::time::Instant;
use sublevel_core::math::Real;
use sublevel_core::Result;

/// Settings of [`simplify`].
#[derive(Clone, Copy, Debug)]
pub struct SimplifySettings {
    /// Samples per unit of joint-space distance on the edges the simplification adds.
    pub resolution: Real,
    /// Most shortcut tries.
    pub shortcut_attempts: usize,
    /// Corner-cutting passes (0: none).
    pub smoothing_passes: usize,
}

/// Simplifies `path` (module docs), until `deadline` at the latest.
///
/// # Errors
/// The checker's errors.
pub fn simplify(
    checker: &mut dyn Validity,
    path: Vec<Vec<Real>>,
    settings: &SimplifySettings,
    rng: &mut impl Rng,
    deadline: Instant,
) -> Result<Vec<Vec<Real>>> {
    let space = checker.space().clone();
    let mut path = reduce(checker, path, settings.resolution, deadline)?;
    let patience = (settings.shortcut_attempts / 4).max(1);
    let (mut failures, mut a, mut b) = (0, Vec::new(), Vec::new());
    for _ in 0..settings.shortcut_attempts {
        if path.len() < 3 || failures >= patience || Instant::now() >= deadline {
            break;
        }
        let edges = path.len() - 1;
        let (mut i, mut j) = (rng.random_range(0..edges), rng.random_range(0..edges));
        if i == j {
            failures += 1;
            continue;
        }
        if i > j {
            std::mem::swap(&mut i, &mut j);
        }
        let (s, t) = (rng.random::<Real>(), rng.random::<Real>());
        space.interpolate(&path[i], &path[i + 1], s, &mut a);
        space.interpolate(&path[j], &path[j + 1], t, &mut b);
        // The piece replaced: a → path[i+1] → … → path[j] → b.
        let old = space.distance(&a, &path[i + 1]) + space.length(&path[i + 1..=j]) + space.distance(&path[j], &b);
        if space.distance(&a, &b) >= old - 1e-9 || !checker.edge_free(&a, &b, settings.resolution)? {
            failures += 1;
            continue;
        }
        failures = 0;
        let mut next = path[..=i].to_vec();
        next.extend([a.clone(), b.clone()]);
        next.extend_from_slice(&path[j + 1..]);
        next.dedup_by(|x, y| space.distance_squared(x, y) < 1e-24);
        path = next;
    }
    let mut path = reduce(checker, path, settings.resolution, deadline)?;
    for _ in 0..settings.smoothing_passes {
        if Instant::now() >= deadline {
            break;
        }
        path = smooth(checker, &space, path, settings.resolution)?;
    }
    Ok(path)
}

/// Drops redundant waypoints: from each kept waypoint, the farthest later one it sees by a free
/// straight edge comes next.
fn reduce(
    checker: &mut dyn Validity,
    path: Vec<Vec<Real>>,
    resolution: Real,
    deadline: Instant,
) -> Result<Vec<Vec<Real>>> {
    if path.len() < 3 {
        return Ok(path);
    }
    let mut out = vec![path[0].clone()];
    let mut i = 0;
    while i + 1 < path.len() {
        let mut j = path.len() - 1;
        while j > i + 1 && (Instant::now() >= deadline || !checker.edge_free(&path[i], &path[j], resolution)?) {
            j -= 1;
        }
        out.push(path[j].clone());
        i = j;
    }
    Ok(out)
}

/// One pass of corner cutting (module docs).
fn smooth(
    checker: &mut dyn Validity,
    space: &JointSpace,
    path: Vec<Vec<Real>>,
    resolution: Real,
) -> Result<Vec<Vec<Real>>> {
    if path.len() < 3 {
        return Ok(path);
    }
    let mut out = vec![path[0].clone()];
    let (mut u, mut v) = (Vec::new(), Vec::new());
    for i in 1..path.len() - 1 {
        // The corner at path[i], cut from the last point kept (itself on the edge into path[i]).
        let prev = out.last().cloned().unwrap_or_else(|| path[i - 1].clone());
        space.interpolate(&path[i], &prev, 0.25, &mut u);
        space.interpolate(&path[i], &path[i + 1], 0.25, &mut v);
        if checker.edge_free(&u, &v, resolution)? {
            out.push(u.clone());
            out.push(v.clone());
        } else {
            out.push(path[i].clone());
        }
    }
    out.push(path[path.len() - 1].clone());
    Ok(out)
}
