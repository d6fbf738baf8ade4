//! Reads the output of the coal peer benchmark (`bash PEERS/coal/run.sh data/psb/chair_101.off
//! data/psb/human_10.off > coal.txt`, PEERS being where the peer benchmarks are checked out; coal
//! 3.0.3, `PEERS/coal/bench_coal.cpp`): one `key value` per line, and `mesh_distance i d` lines
//! with the exact mesh–mesh distance (BVH of OBBRSS) at coal's own i-th cold pose.
//!
//! ```text
//! hull_vertices_a 412            hull_gjk_cold_us 1.53         hull_gjk_warm_us 0.61
//! hull_nesterov_gjk_cold_us …    mesh_distance 0 0.412345678   mesh_bvh_cold_us 384.2
//! hull_err_mean 0.01873          mesh_separated 37
//! ```
//!
//! `bash scripts/peer-coal-collide >> coal.txt` appends coal's boolean collide on the same hulls at
//! the same cold poses (`benches/peers/coal_collide.cpp`): the narrow phase alone and behind the
//! world AABB test of coal's broad phase, means over the poses in µs, and how many poses the AABB
//! test decides (`hull_gjk_collide_cold_us`, `hull_aabb_gjk_collide_cold_us`,
//! `hull_aabb_gjk_collide_decided`, `hull_gjk_collide_colliding`, `hull_gjk_collide_poses`).
//!
//! [`CoalPeer`] holds every line; [`CoalFigures`] is the named view `sublevel-lab bench --peer
//! FILE` prints beside its own figures with the ratios ours / coal, and `sublevel-lab chart
//! speed-accuracy --peer FILE` adds coal's rows. coal's poses follow the bench's recipes (cold:
//! t ~ U[−2.5, 2.5]³, q = normalize(U[−1, 1]⁴); warm: the 500-step slide and turn) but come from
//! another generator (mt19937 vs ChaCha8): the medians are over the same distribution, not the
//! same poses, and only ratios of runs made one after the other on one machine count (the
//! machine's speed drifts between minutes).

use std::collections::BTreeMap;
use sublevel_core::math::Real;
use sublevel_core::{Error, Result};

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
    /// Boolean collide of the hulls at the cold poses, narrow phase alone (GJK with an early break
    /// at margin 0), mean over the poses (`hull_gjk_collide_cold_us`, from
    /// `scripts/peer-coal-collide`; NaN when absent).
    pub collide_us: Real,
    /// The same behind the world AABB test of coal's broad phase, mean over the poses
    /// (`hull_aabb_gjk_collide_cold_us`; NaN when absent).
    pub aabb_collide_us: Real,
    /// Poses the AABB test alone decides, poses whose hulls touch, and poses timed
    /// (`hull_aabb_gjk_collide_decided`, `hull_gjk_collide_colliding`, `hull_gjk_collide_poses`);
    /// 0 when absent.
    pub collide_counts: [usize; 3],
}

impl CoalFigures {
    /// The named figures of a parsed run.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `--peer` and the key when a time is negative or not
    /// finite, or a vertex or pose count is not a whole number.
    pub fn from_peer(peer: &CoalPeer) -> Result<Self> {
        let time = |key: &str| {
            let v = peer.get(key);
            if v.is_nan() || (v.is_finite() && v >= 0.0) {
                Ok(v)
            } else {
                Err(Error::invalid("--peer", format!("{key} = {v} is not a nonnegative time")))
            }
        };
        let count = |key: &str| {
            let v = peer.get(key);
            match v {
                v if v.is_nan() => Ok(0),
                v if v >= 0.0 && v.fract() == 0.0 && v < 1e9 => Ok(v as usize),
                v => Err(Error::invalid("--peer", format!("{key} = {v} is not a count"))),
            }
        };
        Ok(Self {
            gjk_cold_us: time("hull_gjk_cold_us")?,
            gjk_warm_us: time("hull_gjk_warm_us")?,
            nesterov_cold_us: time("hull_nesterov_gjk_cold_us")?,
            nesterov_warm_us: time("hull_nesterov_gjk_warm_us")?,
            mesh_us: time("mesh_bvh_cold_us")?,
            hull_vertices: [count("hull_vertices_a")?, count("hull_vertices_b")?],
            collide_us: time("hull_gjk_collide_cold_us")?,
            aabb_collide_us: time("hull_aabb_gjk_collide_cold_us")?,
            collide_counts: [
                count("hull_aabb_gjk_collide_decided")?,
                count("hull_gjk_collide_colliding")?,
                count("hull_gjk_collide_poses")?,
            ],
        })
    }

    /// Reads the peer file at `path` and takes its named figures.
    ///
    /// # Errors
    /// The errors of [`CoalPeer::load`] and [`CoalFigures::from_peer`], with the path.
    pub fn load(path: &std::path::Path) -> Result<Self> {
        CoalPeer::load(path).and_then(|p| Self::from_peer(&p)).map_err(|e| match e {
            Error::InvalidArgument { field, reason } => Error::invalid(field, format!("{}: {reason}", path.display())),
            other => other,
        })
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

    #[test]
    fn names_the_figures_bench_prints() {
        let text = "hull_vertices_a 320\nhull_vertices_b 364\nhull_gjk_cold_us 1.2500\nhull_gjk_warm_us 1.1000\n\
                    hull_nesterov_gjk_cold_us 2.5\nhull_nesterov_gjk_warm_us 1.5\nmesh_distance 0 0.123456789\n\
                    mesh_bvh_cold_us 812.4\nhull_err_mean 0.02000\nmesh_separated 31\n";
        let f = CoalFigures::from_peer(&CoalPeer::parse(text).unwrap()).unwrap();
        assert_eq!(f.hull_vertices, [320, 364]);
        assert_eq!((f.gjk_cold_us, f.gjk_warm_us), (1.25, 1.1));
        assert_eq!((f.nesterov_cold_us, f.nesterov_warm_us, f.mesh_us), (2.5, 1.5, 812.4));
        // Without the collide peer's lines its figures are absent, not zero.
        assert!(f.collide_us.is_nan() && f.aabb_collide_us.is_nan());
        assert_eq!(f.collide_counts, [0, 0, 0]);
        let negative = CoalPeer::parse("hull_gjk_cold_us -1\nmesh_bvh_cold_us 3\n").unwrap();
        let e = CoalFigures::from_peer(&negative).unwrap_err().to_string();
        assert!(e.contains("--peer") && e.contains("hull_gjk_cold_us"), "{e}");
    }

    #[test]
    fn names_the_collide_figures_the_collide_peer_appends() {
        // The shared script's lines, then `scripts/peer-coal-collide`'s (as `>>` leaves them).
        let text = "hull_gjk_cold_us 1.53\nmesh_bvh_cold_us 480.1\nhull_gjk_collide_cold_us 2.6449\n\
                    hull_gjk_collide_cold_median_us 2.4395\nhull_aabb_gjk_collide_cold_us 0.5882\n\
                    hull_aabb_gjk_collide_decided 250\nhull_gjk_collide_colliding 14\nhull_gjk_collide_poses 300\n";
        let f = CoalFigures::from_peer(&CoalPeer::parse(text).unwrap()).unwrap();
        assert_eq!((f.collide_us, f.aabb_collide_us), (2.6449, 0.5882));
        assert_eq!(f.collide_counts, [250, 14, 300]);
        let bad = CoalPeer::parse("hull_gjk_cold_us 1\nmesh_bvh_cold_us 3\nhull_gjk_collide_poses 2.5\n").unwrap();
        let e = CoalFigures::from_peer(&bad).unwrap_err().to_string();
        assert!(e.contains("--peer") && e.contains("hull_gjk_collide_poses") && e.contains("not a count"), "{e}");
    }
}
