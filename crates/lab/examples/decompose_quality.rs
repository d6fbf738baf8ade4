//! How near-convex the parts of a decomposition are: decomposes a bundled PSB mesh into N parts
//! (`sublevel_fit::compound::decompose`), fits each part's vertices with one sos-convex body of
//! degree 2d (`sublevel_fit::fit_points`, default settings) and prints the max / median / mean sampled
//! leaf excess over the mesh (meters, `MeshSurface::excess`, 1000 boundary samples) with the
//! decomposition and fit times. Run it from the repository root (it reads `data/psb/NAME.off`):
//!
//! ```text
//! cargo run --release -p sublevel-lab --example decompose_quality -- chair_101 8 [degree=4]
//! ```

use std::time::Instant;
use sublevel_core::math::{Point3, Real};
use sublevel_fit::compound::decompose::{decompose, DEFAULT_RESOLUTION};
use sublevel_fit::compound::surface::{MeshSurface, DEFAULT_EXCESS_SAMPLES};
use sublevel_fit::{fit_points, FitSettings};

fn main() -> sublevel_core::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).cloned().unwrap_or_else(|| "chair_101".into());
    let parts: usize = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(8);
    let degree: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(4);
    let bytes = std::fs::read(format!("data/psb/{name}.off"))?;
    let mesh = sublevel_fit::mesh::parse_off_mesh(&bytes, 1 << 22)?;
    let surface = MeshSurface::new(&mesh.vertices, &mesh.triangles)?;
    let t0 = Instant::now();
    let decomposition = decompose(&mesh.vertices, &mesh.triangles, parts, DEFAULT_RESOLUTION)?;
    let decompose_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let settings = FitSettings { degree, ..FitSettings::default() };
    let mut excess: Vec<Real> = Vec::new();
    for part in &decomposition {
        let own: Vec<Point3> = part.vertices.iter().map(|&i| mesh.vertices[i as usize]).collect();
        match fit_points(&own, &settings, &mut |_| {}) {
            Ok(body) => excess.push(surface.excess(&body, DEFAULT_EXCESS_SAMPLES)?),
            Err(e) => println!("part of {} triangles: fit failed: {e}", part.triangles.len()),
        }
    }
    excess.sort_by(|a, b| a.total_cmp(b));
    let mean = excess.iter().sum::<Real>() / excess.len().max(1) as Real;
    println!(
        "{name}: {} parts asked, {} made ({decompose_s:.2} s); degree {degree} leaf excess max {:.4} / median {:.4} / mean {mean:.4} m; fits {:.1} s",
        parts,
        decomposition.len(),
        excess.last().copied().unwrap_or(Real::NAN),
        excess.get(excess.len() / 2).copied().unwrap_or(Real::NAN),
        t1.elapsed().as_secs_f64()
    );
    Ok(())
}
