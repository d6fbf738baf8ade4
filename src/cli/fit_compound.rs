//! `sublevel fit MESH --parts auto [--tolerance T] --output X.json` (or `--parts N`): fit a
//! compound body — a convex decomposition fitted part by part under a containment tree
//! ([`sublevel::compound`]) — and write its compound file. MESH is a triangle mesh in OFF, OBJ
//! (every object and group), STL (ASCII or binary) or PLY, welded before the decomposition
//! (a triangle soup becomes an indexed mesh). The report (stdout, and the file's `report`) lists
//! the weld, every part count tried and every node: degree, triangles, excess, fit time. Then the
//! conservativeness check (triangles of MESH not inside any leaf: must be 0) and the tolerance
//! check: with a tolerance T (for `--parts auto` by default 1 % of the mesh's bounding-box
//! diagonal), every leaf whose excess is above T is listed on stderr, and the command exits
//! non-zero (the file is still written) unless `--allow-tolerance-miss` is given.

use super::fit::{fit_settings, progress_printer, DegreeArg, FitArgs};
use sublevel::compound::check::uncovered_triangles;
use sublevel::compound::{fit_compound, CompoundBody, CompoundSettings, PartCount};
use sublevel::fit::auto::DEFAULT_AUTO_DEGREES;
use sublevel::fit::mesh::{load_triangle_mesh_file, DEFAULT_MAX_MESH_POINTS};
use sublevel::Error;

/// Runs `sublevel fit --parts …`.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `parts`, `tolerance`, `format` or a fit setting, or `mesh`
/// with the file's path (no faces, e.g. a point-cloud PLY; bad indices); whatever loading,
/// fitting and writing return (see [`fit_compound`]); [`Error::Numerical`] when a triangle is
/// outside every leaf; [`Error::FailedPrecondition`] when a leaf misses the tolerance (the file
/// is written first) and `--allow-tolerance-miss` is not given.
pub fn run(args: FitArgs) -> sublevel::Result<()> {
    let parts: PartCount = args.parts.as_deref().unwrap_or("auto").parse()?;
    if let PartCount::Fixed(n) = parts {
        if n == 0 {
            return Err(Error::invalid("parts", "must be ≥ 1 or auto"));
        }
    }
    let format = match &args.format {
        Some(f) => Some(f.parse().map_err(|e: Error| match e {
            Error::InvalidArgument { reason, .. } => Error::invalid("format", reason),
            other => other,
        })?),
        None => None,
    };
    let mesh = load_triangle_mesh_file(&args.mesh, format, DEFAULT_MAX_MESH_POINTS)?;
    let settings = CompoundSettings {
        fit: fit_settings(&args)?,
        degrees: match args.degree.unwrap_or(DegreeArg::Auto) {
            DegreeArg::Fixed(d) => vec![d],
            // Containment (the parents) takes degrees up to 6: leaves of degree 8 would only be
            // contained at degree ≤ 6 anyway, and cost the most per query.
            DegreeArg::Auto => DEFAULT_AUTO_DEGREES.iter().copied().filter(|&d| d <= 6).collect(),
        },
        volume_tolerance: args.volume_tolerance,
        excess_tolerance: args.tolerance,
        parent_degree: args.parent_degree,
        resolution: args.resolution,
        excess_samples: args.excess_samples,
        max_parts: args.max_parts,
        ..CompoundSettings::default()
    };
    let name = args.mesh.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let mut progress = progress_printer(args.quiet);
    let body = fit_compound(&mesh, Some(&name), parts, &settings, &mut progress)?;
    let output = args.output.clone().unwrap_or_else(|| args.mesh.with_extension("compound.json"));
    body.save(&output)?;
    print_report(&name, &body);
    let uncovered = uncovered_triangles(&body, &mesh);
    println!(
        "conservative: {} of {} triangles inside a leaf body ({} uncovered) -> {}",
        mesh.triangles.len() - uncovered.len(),
        mesh.triangles.len(),
        uncovered.len(),
        output.display()
    );
    if !uncovered.is_empty() {
        return Err(Error::Numerical(format!(
            "{} triangles are not inside any leaf body (first: {:?})",
            uncovered.len(),
            &uncovered[..uncovered.len().min(5)]
        )));
    }
    let Some(t) = body.report.tolerance else { return Ok(()) };
    if body.report.misses.is_empty() {
        println!("tolerance met: every leaf's excess is ≤ {t:.4} m");
        return Ok(());
    }
    eprint!("{}", tolerance_warning(&body, t));
    if args.allow_tolerance_miss {
        return Ok(());
    }
    Err(Error::FailedPrecondition(format!(
        "{} of {} leaves miss the tolerance {t:.4} m (worst excess {:.4} m); the body was written to {} — pass \
         --allow-tolerance-miss to accept it, or raise --tolerance / --max-parts",
        body.report.misses.len(),
        body.leaf_count(),
        body.max_leaf_excess(),
        output.display()
    )))
}

/// The warning for the leaves above the tolerance `t` (meters): one line per leaf (node index,
/// triangles, excess in meters and as a multiple of `t`), then why the search stopped where the
/// report says (the `--max-parts` cap, leaves that cannot be split, no part count within `t`).
pub fn tolerance_warning(body: &CompoundBody, t: f64) -> String {
    let misses = &body.report.misses;
    let mut out = format!(
        "warning: {} of {} leaves miss the tolerance {t:.4} m (excess above T):\n",
        misses.len(),
        body.leaf_count()
    );
    for m in misses {
        out += &format!(
            "  leaf {:>4}: {:>6} triangles, excess {:.4} m = {:.2} × T\n",
            m.node,
            m.triangles,
            m.excess,
            m.excess / t
        );
    }
    let why = |n: &&String| n.contains("--max-parts") || n.contains("cannot be split") || n.contains("no part count");
    for note in body.report.notes.iter().filter(why) {
        out += &format!("  {note}\n");
    }
    out
}

/// Prints the fit report: attempts, then one line per node (leaves first).
pub fn print_report(name: &str, body: &CompoundBody) {
    let r = &body.report;
    if let Some(w) = &r.weld {
        println!(
            "{name}: welded at {:.1e} m: {} → {} vertices ({} merged, {} unused), {} → {} triangles ({} collapsed, {} repeated)",
            w.tolerance,
            w.vertices_before,
            w.vertices_after,
            w.merged_vertices,
            w.unused_vertices,
            w.triangles_before,
            w.triangles_after,
            w.degenerate_triangles,
            w.duplicate_triangles
        );
    }
    println!(
        "{name}: {} parts, {} nodes, height {}, max leaf excess {:.4} m, root excess {:.4} m; decomposition {:.2} s, leaves {:.2} s, tree {:.2} s, total {:.2} s",
        body.leaf_count(),
        body.node_count(),
        body.height(),
        body.max_leaf_excess(),
        body.node(body.root()).excess,
        r.decomposition_seconds,
        r.leaf_fit_seconds,
        r.tree_fit_seconds,
        r.total_seconds
    );
    for (asked, got, excess, seconds) in &r.attempts {
        println!("  attempt: parts asked {asked}, obtained {got}, max leaf excess {excess:.4} m, {seconds:.2} s");
    }
    for note in &r.notes {
        println!("  note: {note}");
    }
    println!("  node  kind    depth  degree  triangles  excess_m  fit_s  children");
    for (i, n) in body.nodes().iter().enumerate() {
        let kind = if n.children.is_empty() {
            "part"
        } else if i == body.root() {
            "root"
        } else {
            "parent"
        };
        println!(
            "  {i:>4}  {kind:<6}  {:>5}  {:>6}  {:>9}  {:>8.4}  {:>5.2}  {:?}",
            n.depth,
            n.body.degree(),
            n.triangles,
            n.excess,
            n.fit_seconds,
            n.children
        );
    }
}
