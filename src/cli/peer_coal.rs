//! Reads the output of the shared coal peer benchmark (`bash ../shared/peers/coal/run.sh > coal.txt`,
//! coal 3.0.3, `peers/coal/bench_coal.cpp`): one `key value` per line, and `mesh_distance i d` lines
//! with the exact mesh–mesh distance (BVH of OBBRSS) at coal's own i-th cold pose.
//!
//! ```text
//! hull_vertices_a 412            hull_gjk_cold_us 1.53         hull_gjk_warm_us 0.61
//! hull_nesterov_gjk_cold_us …    mesh_distance 0 0.412345678   mesh_bvh_cold_us 384.2
//! hull_err_mean 0.01873          mesh_separated 37
//! ```

use std::collections::BTreeMap;
use sublevel::math::Real;
use sublevel::{Error, Result};

/// The figures of one coal run (times in µs, distances and errors in the meshes' units, meters).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CoalPeer {
    /// Every `key value` line, e.g. `hull_gjk_cold_us`, `mesh_bvh_cold_us`, `hull_err_mean`.
    pub values: BTreeMap<String, Real>,
    /// The `mesh_distance i d` lines: exact mesh–mesh distance at coal's i-th cold pose.
    pub mesh_distances: Vec<(usize, Real)>,
}

impl CoalPeer {
    /// Parses the benchmark's standard output.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `--peer` and the line when a line is not `key number`
    /// or `mesh_distance index number`, or when `mesh_bvh_cold_us` or `hull_gjk_cold_us` is
    /// missing.
    pub fn parse(text: &str) -> Result<Self> {
        let mut peer = CoalPeer::default();
        for (n, line) in text.lines().enumerate() {
            let bad = |why: &str| Error::invalid("--peer", format!("line {}: {why}: {line:?}", n + 1));
            let words: Vec<&str> = line.split_whitespace().collect();
            match words.as_slice() {
                [] => {}
                ["mesh_distance", i, d] => {
                    let i = i.parse().map_err(|_| bad("bad pose index"))?;
                    let d: Real = d.parse().map_err(|_| bad("bad distance"))?;
                    peer.mesh_distances.push((i, d));
                }
                [key, v] => {
                    let v: Real = v.parse().map_err(|_| bad("not a number"))?;
                    peer.values.insert((*key).to_owned(), v);
                }
                _ => return Err(bad("expected `key value`")),
            }
        }
        for key in ["mesh_bvh_cold_us", "hull_gjk_cold_us"] {
            if !peer.values.contains_key(key) {
                return Err(Error::invalid("--peer", format!("no `{key}` line: is this coal's run.sh output?")));
            }
        }
        Ok(peer)
    }

    /// Reads and parses a file.
    ///
    /// # Errors
    /// [`Error::Io`] or the errors of [`CoalPeer::parse`].
    pub fn load(path: &std::path::Path) -> Result<Self> {
        Self::parse(&std::fs::read_to_string(path)?)
    }

    /// A value by key, NaN when absent.
    pub fn get(&self, key: &str) -> Real {
        self.values.get(key).copied().unwrap_or(Real::NAN)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_benchmark_output_and_names_bad_lines() {
        let text = "hull_vertices_a 412\nhull_gjk_cold_us 1.5300\nhull_gjk_warm_us 0.6100\n\
                    mesh_distance 0 0.412345678\nmesh_distance 1 0.000000000\nmesh_bvh_cold_us 384.2\n\
                    hull_err_mean 0.01873\nmesh_separated 37\n";
        let p = CoalPeer::parse(text).unwrap();
        assert_eq!(p.get("hull_gjk_cold_us"), 1.53);
        assert_eq!(p.get("mesh_bvh_cold_us"), 384.2);
        assert_eq!(p.mesh_distances, vec![(0, 0.412345678), (1, 0.0)]);
        assert!(p.get("absent").is_nan());
        let e = CoalPeer::parse("hull_gjk_cold_us x\n").unwrap_err().to_string();
        assert!(e.contains("--peer") && e.contains("line 1"), "{e}");
        let e = CoalPeer::parse("hull_gjk_cold_us 1\n").unwrap_err().to_string();
        assert!(e.contains("mesh_bvh_cold_us"), "{e}");
    }
}
