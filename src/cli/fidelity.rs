//! `--fidelity LEVEL [--tolerance T]`: the level of a command's robot checks
//! (`sublevel_robot::fidelity`), shared by `robot check`, `robot bench` and `robot plan`.

use sublevel_core::math::Real;
use sublevel_core::{Error, Result};
use sublevel_robot::Fidelity;

/// The fidelity arguments of a robot command.
#[derive(clap::Args, Debug, Clone)]
pub struct FidelityArgs {
    /// How closely the links are modelled: `mesh` (the meshes' own verdicts), `bodies` (their
    /// sos-convex bodies) or `spheres` (their sphere trees cut at the tolerance). Every level's
    /// bodies contain the meshes: no level misses a mesh collision; the conservative ones may
    /// call a configuration near contact colliding that the meshes call free.
    #[arg(long, default_value = "mesh")]
    pub fidelity: String,
    /// The spheres level's tolerance (meters, in [0.01, 1]; 0: 0.03): its balls reach at most
    /// this far past the meshes.
    #[arg(long, default_value_t = 0.0)]
    pub tolerance: Real,
}

impl FidelityArgs {
    /// The level asked for.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `--fidelity` or `--tolerance`.
    pub fn level(&self) -> Result<Fidelity> {
        Fidelity::parse("fidelity", &self.fidelity, Some(self.tolerance)).map_err(|e| match e {
            Error::InvalidArgument { field, reason } => Error::InvalidArgument {
                field: if field.ends_with("tolerance") { "--tolerance".into() } else { "--fidelity".into() },
                reason,
            },
            other => other,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(level: &str, tolerance: Real) -> FidelityArgs {
        FidelityArgs { fidelity: level.into(), tolerance }
    }

    #[test]
    fn levels_parse_and_bad_ones_name_the_flag() {
        assert_eq!(args("mesh", 0.0).level().unwrap(), Fidelity::Mesh);
        assert_eq!(args("bodies", 0.0).level().unwrap(), Fidelity::Bodies);
        assert_eq!(args("spheres", 0.1).level().unwrap(), Fidelity::Spheres { tolerance: 0.1 });
        let flag = |a: FidelityArgs| match a.level().unwrap_err() {
            Error::InvalidArgument { field, .. } => field,
            other => panic!("{other}"),
        };
        assert_eq!(flag(args("voxels", 0.0)), "--fidelity");
        assert_eq!(flag(args("spheres", 5.0)), "--tolerance");
        assert_eq!(flag(args("bodies", 0.1)), "--tolerance");
    }
}
