//! Size limits of a robot, checked before any work starts.
//!
//! A URDF is a few kilobytes of text that can ask for hours of work: every self pair of links is
//! checked per configuration, every pair moved by one or two joints gets a clearance table
//! (0.2–2.5 s each on 2 cores), every mesh a fit. These limits bound that work, and the memory it
//! takes, well above real robots (the Panda: 11 links, 7 moving joints, 10 collision geometries,
//! 30 self pairs, 16 tables; a humanoid with two hands: about 60 links and 50 moving joints).
//! A robot over a limit is refused with RESOURCE_EXHAUSTED naming the limit, before a job exists.
//!
//! | limit | default |
//! |---|---|
//! | links | [`MAX_LINKS`] |
//! | joints (fixed included) | [`MAX_JOINTS`] |
//! | moving joints (configuration entries) | [`MAX_MOVING_JOINTS`] |
//! | collision geometries | [`MAX_GEOMETRIES`] |
//! | geometry pairs checked for self-collision | [`MAX_SELF_PAIRS`] |
//! | clearance tables | [`MAX_CLEARANCE_TABLES`] |

use crate::model::RobotModel;
use crate::{Error, Result};

/// Most links a robot may have.
pub const MAX_LINKS: usize = 512;
/// Most joints (fixed ones included) a robot may have.
pub const MAX_JOINTS: usize = 512;
/// Most moving joints (revolute, continuous, prismatic; mimic ones included) a robot may have.
pub const MAX_MOVING_JOINTS: usize = 128;
/// Most collision geometries (URDF `<collision>` elements) a robot may have.
pub const MAX_GEOMETRIES: usize = 1024;
/// Most geometry pairs a self-collision check may test (pairs of geometries on links that are
/// neither allowed to touch nor the same link).
pub const MAX_SELF_PAIRS: usize = 20_000;
/// Most clearance tables a robot file may hold (and a fit may build).
pub const MAX_CLEARANCE_TABLES: usize = 512;

/// The error of a robot over `limit`: RESOURCE_EXHAUSTED naming it.
pub(crate) fn exceeded(what: &str, count: usize, max: usize) -> Error {
    Error::ResourceExhausted(format!("the robot has {count} {what}, more than the limit of {max}"))
}

/// Checks the counts of a URDF's elements (links, joints, collision geometries) before the model
/// is built.
///
/// # Errors
/// [`Error::ResourceExhausted`] naming the first count over its limit.
pub(crate) fn check_urdf(links: usize, joints: usize, moving: usize, geometries: usize) -> Result<()> {
    for (what, count, max) in [
        ("links", links, MAX_LINKS),
        ("joints", joints, MAX_JOINTS),
        ("moving joints", moving, MAX_MOVING_JOINTS),
        ("collision geometries", geometries, MAX_GEOMETRIES),
    ] {
        if count > max {
            return Err(exceeded(what, count, max));
        }
    }
    Ok(())
}

/// Checks how many geometry pairs a self-collision check of `model` would test with the link
/// pairs `allowed` (as the SRDF's `disable_collisions` names them) skipped.
///
/// # Errors
/// [`Error::ResourceExhausted`] when they exceed [`MAX_SELF_PAIRS`].
pub fn check_self_pairs(model: &RobotModel, allowed: &[[String; 2]]) -> Result<()> {
    let counts: Vec<usize> = model.links().iter().map(|l| l.collision.len()).collect();
    let total: usize = counts.iter().sum();
    // Pairs between different links, less the allowed ones.
    let mut pairs = (total * total - counts.iter().map(|c| c * c).sum::<usize>()) / 2;
    let mut seen = std::collections::HashSet::new();
    for [a, b] in allowed {
        let (Some(i), Some(j)) = (model.link_index(a), model.link_index(b)) else { continue };
        if i != j && seen.insert((i.min(j), i.max(j))) {
            pairs = pairs.saturating_sub(counts[i] * counts[j]);
        }
    }
    if pairs > MAX_SELF_PAIRS {
        return Err(exceeded("geometry pairs to check for self-collision", pairs, MAX_SELF_PAIRS));
    }
    Ok(())
}
