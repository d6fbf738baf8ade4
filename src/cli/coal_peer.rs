//! The coal peer's figures for `sublevel bench --peer FILE` (issue 15).
//!
//! The peer script (`bash ../shared/peers/coal/run.sh > coal.txt`) builds coal 3.0.3's C++
//! library from its wheel and times the bench's pose recipes (cold: random poses t ~ U[−2.5, 2.5]³,
//! q = normalize(U[−1, 1]⁴); warm: the 500-step slide and turn) on the convex hulls of the chair
//! and the human (GJK and Nesterov-accelerated GJK) and the exact mesh–mesh distance (BVH of
//! OBBRSS). Its output is one `key value` line per figure (times in µs); this module reads it and
//! `bench` prints coal's figures and the ratios ours / coal beside its own, measured in the same
//! session (the machine's speed drifts between runs, so only ratios within one session count).
//!
//! The poses follow the same recipe but come from another generator (mt19937 vs ChaCha8): the
//! medians are over the same distribution, not the same poses.

use sublevel::math::Real;
use sublevel::{Error, Result};

/// coal's figures from one run of the peer script (µs; NaN where the file lacks a key).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoalFigures {
    /// Median cold GJK distance between the convex hulls (`hull_gjk_cold_us`).
    pub gjk_cold_us: Real,
    /// Median warm GJK distance (cached guess carried along the motion, `hull_gjk_warm_us`).
    pub gjk_warm_us: Real,
    /// Median cold Nesterov-accelerated GJK (`hull_nesterov_gjk_cold_us`).
    pub nesterov_cold_us: Real,
    /// Median warm Nesterov-accelerated GJK (`hull_nesterov_gjk_warm_us`).
    pub nesterov_warm_us: Real,
    /// Median exact mesh–mesh distance (BVH, `mesh_bvh_cold_us`).
    pub mesh_us: Real,
    /// Hull vertex counts (`hull_vertices_a`, `hull_vertices_b`); 0 when absent.
    pub hull_vertices: [usize; 2],
}

impl CoalFigures {
    /// Parses the peer script's output: lines `key value` (other keys such as `mesh_distance i d`
    /// and blank lines are skipped).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `--peer` when a known key's value is not a number, or when
    /// the file has neither `hull_gjk_cold_us` nor `hull_gjk_warm_us` (not the coal script's output).
    pub fn parse(text: &str) -> Result<Self> {
        let mut f = Self {
            gjk_cold_us: Real::NAN,
            gjk_warm_us: Real::NAN,
            nesterov_cold_us: Real::NAN,
            nesterov_warm_us: Real::NAN,
            mesh_us: Real::NAN,
            hull_vertices: [0; 2],
        };
        for (n, line) in text.lines().enumerate() {
            let mut it = line.split_whitespace();
            let (Some(key), Some(value), None) = (it.next(), it.next(), it.next()) else { continue };
            let slot = match key {
                "hull_gjk_cold_us" => &mut f.gjk_cold_us,
                "hull_gjk_warm_us" => &mut f.gjk_warm_us,
                "hull_nesterov_gjk_cold_us" => &mut f.nesterov_cold_us,
                "hull_nesterov_gjk_warm_us" => &mut f.nesterov_warm_us,
                "mesh_bvh_cold_us" => &mut f.mesh_us,
                "hull_vertices_a" | "hull_vertices_b" => {
                    let v = value.parse::<usize>().map_err(|_| bad(n, key, value))?;
                    f.hull_vertices[usize::from(key.ends_with('b'))] = v;
                    continue;
                }
                _ => continue,
            };
            *slot =
                value.parse::<Real>().ok().filter(|v| v.is_finite() && *v >= 0.0).ok_or_else(|| bad(n, key, value))?;
        }
        if f.gjk_cold_us.is_nan() && f.gjk_warm_us.is_nan() {
            return Err(Error::invalid(
                "--peer",
                "no hull_gjk_cold_us / hull_gjk_warm_us line: expected the output of ../shared/peers/coal/run.sh",
            ));
        }
        Ok(f)
    }

    /// Reads and parses the peer file at `path`.
    ///
    /// # Errors
    /// [`Error::Io`] when unreadable; the errors of [`CoalFigures::parse`] (with the path).
    pub fn load(path: &std::path::Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)?;
        Self::parse(&text).map_err(|e| match e {
            Error::InvalidArgument { field, reason } => Error::invalid(field, format!("{}: {reason}", path.display())),
            other => other,
        })
    }
}

fn bad(line: usize, key: &str, value: &str) -> Error {
    Error::invalid("--peer", format!("line {}: {key} = {value:?} is not a nonnegative number", line + 1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_coal_script_output() {
        let text = "hull_vertices_a 320\nhull_vertices_b 364\nhull_gjk_cold_us 1.2500\nhull_gjk_warm_us 1.1000\n\
                    hull_nesterov_gjk_cold_us 2.5\nhull_nesterov_gjk_warm_us 1.5\nmesh_distance 0 0.123456789\n\
                    mesh_bvh_cold_us 812.4\nhull_err_mean 0.02000\nmesh_separated 31\n";
        let f = CoalFigures::parse(text).unwrap();
        assert_eq!(f.hull_vertices, [320, 364]);
        assert_eq!((f.gjk_cold_us, f.gjk_warm_us), (1.25, 1.1));
        assert_eq!((f.nesterov_cold_us, f.nesterov_warm_us, f.mesh_us), (2.5, 1.5, 812.4));
    }

    #[test]
    fn rejects_files_that_are_not_the_peer_output() {
        let e = CoalFigures::parse("hello world\n").unwrap_err().to_string();
        assert!(e.contains("--peer") && e.contains("hull_gjk_cold_us"), "{e}");
        let e = CoalFigures::parse("hull_gjk_cold_us fast\n").unwrap_err().to_string();
        assert!(e.contains("--peer") && e.contains("line 1"), "{e}");
        assert!(CoalFigures::parse("hull_gjk_cold_us -1\n").is_err());
    }
}
