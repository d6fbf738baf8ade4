//! The fidelity dial of robot checks: which model of the links decides a pair near contact.
//!
//! ```text
//! level      a pair is free when …                                  else
//! mesh       the meshes are farther apart than the padding          collides (exact)
//! bodies     the links' sos-convex root bodies are (paper §V)       collides (conservative)
//! spheres    the balls of the links' sphere-tree cut are            collides (conservative)
//! ```
//!
//! Every level first tries the cheap bounds that hold for the meshes themselves (bounding balls,
//! boxes, the clearance tables), and a contact found on the meshes is a collision at every level.
//! The bodies of every level contain the link meshes, so **no level misses a mesh collision**:
//! a pair is called free only when a shape containing the link clears the padding. A conservative
//! level may call a pair colliding that the meshes call free (a false collision): the bodies' fit
//! decides how often; a sphere cut of tolerance `t` does so only where the meshes are within
//! `padding + t` of contact, since each of its balls of radius ≤ t / 2 holds pieces of the mesh.
//!
//! Pairs a level's model does not cover fall to the next finer model the checker has: a
//! primitive link (exact at every level), a mesh obstacle without a body (its triangles), a point
//! cloud (its point balls). [`crate::ConfigurationAnswer::fidelity`] says which model a collision
//! rests on. Distances at a conservative level are that model's distance: a certified lower bound
//! of the meshes'.
//!
//! The levels follow the cascade MoveIt's padded links, cuRobo's and VAMP's spheres and the
//! paper's sos-convex bodies sit on: coarser, faster, never optimistic.

use crate::{Error, Result};
use sublevel_core::math::Real;

/// Default tolerance of the `spheres` level (meters): its balls reach at most this far past the
/// link meshes.
pub const DEFAULT_SPHERE_TOLERANCE: Real = 0.03;

/// Smallest tolerance of the `spheres` level (meters): twice the sphere trees' leaf radius
/// ([`crate::spheres::DEFAULT_LEAF_RADIUS`]); a finer cut has no balls to offer.
pub const MIN_SPHERE_TOLERANCE: Real = 0.01;

/// Largest tolerance of the `spheres` level (meters).
pub const MAX_SPHERE_TOLERANCE: Real = 1.0;

/// How closely robot checks model the links (module docs). `Mesh` by default.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Fidelity {
    /// The meshes' own verdicts and distances: no miss, no false collision.
    #[default]
    Mesh,
    /// The links' sos-convex root bodies, each containing its whole mesh (paper §V): one
    /// Newton / active-set solve per pair near contact, no triangle.
    Bodies,
    /// The links' sphere trees cut where every ball's radius is at most `tolerance / 2`
    /// (meters, in [[`MIN_SPHERE_TOLERANCE`], [`MAX_SPHERE_TOLERANCE`]]): the balls reach at
    /// most `tolerance` past the mesh; closed forms in SIMD lanes, no solve.
    Spheres {
        /// How far the balls may reach past the mesh (meters).
        tolerance: Real,
    },
}

impl Fidelity {
    /// The level named `level` (`mesh`, `bodies` or `spheres`; empty: `mesh`), with the sphere
    /// tolerance `tolerance` (meters; `None` or 0: [`DEFAULT_SPHERE_TOLERANCE`]; only for
    /// `spheres`).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `{field}.level` (an unknown level) or
    /// `{field}.tolerance` (out of range, or given for a level other than `spheres`).
    pub fn parse(field: &str, level: &str, tolerance: Option<Real>) -> Result<Self> {
        let tolerance = tolerance.filter(|&t| t != 0.0);
        let f = match level.trim().to_ascii_lowercase().as_str() {
            "" | "mesh" => Fidelity::Mesh,
            "bodies" => Fidelity::Bodies,
            "spheres" => Fidelity::Spheres { tolerance: tolerance.unwrap_or(DEFAULT_SPHERE_TOLERANCE) },
            other => {
                return Err(Error::invalid(
                    format!("{field}.level"),
                    format!(
                        "unknown fidelity level `{}`: expected mesh, bodies or spheres",
                        sublevel_core::error::clip(other)
                    ),
                ))
            }
        };
        if let (Some(t), false) = (tolerance, matches!(f, Fidelity::Spheres { .. })) {
            return Err(Error::invalid(
                format!("{field}.tolerance"),
                format!("is only for the spheres level, got {t} m for {}", f.name()),
            ));
        }
        f.validate(field)?;
        Ok(f)
    }

    /// Checks the sphere tolerance's range.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `{field}.tolerance`.
    pub fn validate(&self, field: &str) -> Result<()> {
        if let Fidelity::Spheres { tolerance } = *self {
            if !(MIN_SPHERE_TOLERANCE..=MAX_SPHERE_TOLERANCE).contains(&tolerance) {
                return Err(Error::invalid(
                    format!("{field}.tolerance"),
                    format!("must be in [{MIN_SPHERE_TOLERANCE}, {MAX_SPHERE_TOLERANCE}] m, got {tolerance}"),
                ));
            }
        }
        Ok(())
    }

    /// The level's name: `mesh`, `bodies` or `spheres`.
    pub fn name(&self) -> &'static str {
        match self {
            Fidelity::Mesh => "mesh",
            Fidelity::Bodies => "bodies",
            Fidelity::Spheres { .. } => "spheres",
        }
    }

    /// The sphere tolerance (meters), 0 for the other levels.
    pub fn tolerance(&self) -> Real {
        match *self {
            Fidelity::Spheres { tolerance } => tolerance,
            _ => 0.0,
        }
    }

    /// Whether this is the exact level.
    pub fn is_mesh(&self) -> bool {
        matches!(self, Fidelity::Mesh)
    }
}

impl std::fmt::Display for Fidelity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Fidelity::Spheres { tolerance } => write!(f, "spheres({} m)", tolerance),
            other => f.write_str(other.name()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_parse_and_bad_input_names_the_field() {
        assert_eq!(Fidelity::parse("fidelity", "", None).unwrap(), Fidelity::Mesh);
        assert_eq!(Fidelity::parse("fidelity", "Bodies", None).unwrap(), Fidelity::Bodies);
        assert_eq!(
            Fidelity::parse("fidelity", "spheres", None).unwrap(),
            Fidelity::Spheres { tolerance: DEFAULT_SPHERE_TOLERANCE }
        );
        assert_eq!(Fidelity::parse("fidelity", "spheres", Some(0.05)).unwrap(), Fidelity::Spheres { tolerance: 0.05 });
        let field = |e: Error| match e {
            Error::InvalidArgument { field, .. } => field,
            other => panic!("{other}"),
        };
        assert_eq!(field(Fidelity::parse("fidelity", "voxels", None).unwrap_err()), "fidelity.level");
        assert_eq!(field(Fidelity::parse("fidelity", "spheres", Some(0.001)).unwrap_err()), "fidelity.tolerance");
        assert_eq!(field(Fidelity::parse("f", "spheres", Some(Real::NAN)).unwrap_err()), "f.tolerance");
        assert_eq!(field(Fidelity::parse("f", "mesh", Some(0.02)).unwrap_err()), "f.tolerance");
    }
}
