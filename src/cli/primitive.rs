//! `sublevel primitive box X Y Z | sphere R | cylinder R H | capsule R H | halfspace NX NY NZ D
//! --output FILE.json`: write an exact primitive's file ([`sublevel::primitive::PrimitiveFile`];
//! meters, full lengths, centered at the origin as MoveIt and coal define them) and print a
//! one-line summary (kind, dimensions, volume). The file is validated as
//! [`sublevel::primitive::Primitive::from_file`] does: a bad dimension fails the command with an
//! error naming the field (`size[1]`, `radius`, `height`, `normal`, `offset`).

use std::path::PathBuf;
use sublevel::primitive::{Primitive, PrimitiveFile};
use sublevel::Result;

/// Arguments of `sublevel primitive`.
#[derive(clap::Args, Debug)]
pub struct PrimitiveArgs {
    /// The primitive and its dimensions.
    #[command(subcommand)]
    pub shape: PrimitiveShape,
}

/// Where a primitive's file goes.
#[derive(clap::Args, Debug)]
pub struct OutputArg {
    /// Where to write the primitive file (JSON).
    #[arg(long, short)]
    pub output: PathBuf,
}

/// One primitive with its dimensions (meters, full lengths; the set centered at the origin).
#[derive(clap::Subcommand, Debug)]
pub enum PrimitiveShape {
    /// An axis-aligned box with full side lengths X Y Z.
    Box {
        /// Full side length along x (meters, > 0).
        #[arg(value_name = "X", allow_negative_numbers = true)]
        x: f64,
        /// Full side length along y (meters, > 0).
        #[arg(value_name = "Y", allow_negative_numbers = true)]
        y: f64,
        /// Full side length along z (meters, > 0).
        #[arg(value_name = "Z", allow_negative_numbers = true)]
        z: f64,
        /// The output file.
        #[command(flatten)]
        out: OutputArg,
    },
    /// A ball of radius R.
    Sphere {
        /// Radius (meters, > 0).
        #[arg(value_name = "R", allow_negative_numbers = true)]
        radius: f64,
        /// The output file.
        #[command(flatten)]
        out: OutputArg,
    },
    /// A solid cylinder of radius R and full height H along z.
    Cylinder {
        /// Radius (meters, > 0).
        #[arg(value_name = "R", allow_negative_numbers = true)]
        radius: f64,
        /// Full height along z (meters, > 0).
        #[arg(value_name = "H", allow_negative_numbers = true)]
        height: f64,
        /// The output file.
        #[command(flatten)]
        out: OutputArg,
    },
    /// The points within R of the segment of full length H along z (H = 0: a sphere).
    Capsule {
        /// Radius (meters, > 0).
        #[arg(value_name = "R", allow_negative_numbers = true)]
        radius: f64,
        /// Full length of the axis segment (meters, ≥ 0).
        #[arg(value_name = "H", allow_negative_numbers = true)]
        height: f64,
        /// The output file.
        #[command(flatten)]
        out: OutputArg,
    },
    /// The halfspace {u : (NX, NY, NZ)·u ≤ D} (a floor, a wall); the normal need not be unit (it
    /// is normalized, and D divided by its length).
    Halfspace {
        /// Outward normal, x component.
        #[arg(value_name = "NX", allow_negative_numbers = true)]
        nx: f64,
        /// Outward normal, y component.
        #[arg(value_name = "NY", allow_negative_numbers = true)]
        ny: f64,
        /// Outward normal, z component.
        #[arg(value_name = "NZ", allow_negative_numbers = true)]
        nz: f64,
        /// Offset D (meters): the halfspace is normal·u ≤ D.
        #[arg(value_name = "D", allow_negative_numbers = true)]
        offset: f64,
        /// The output file.
        #[command(flatten)]
        out: OutputArg,
    },
}

impl PrimitiveShape {
    /// The file form as given on the command line, and where to write it.
    fn file(&self) -> (PrimitiveFile, &std::path::Path) {
        match self {
            PrimitiveShape::Box { x, y, z, out } => (PrimitiveFile::Box { size: [*x, *y, *z] }, &out.output),
            PrimitiveShape::Sphere { radius, out } => (PrimitiveFile::Sphere { radius: *radius }, &out.output),
            PrimitiveShape::Cylinder { radius, height, out } => {
                (PrimitiveFile::Cylinder { radius: *radius, height: *height }, &out.output)
            }
            PrimitiveShape::Capsule { radius, height, out } => {
                (PrimitiveFile::Capsule { radius: *radius, height: *height }, &out.output)
            }
            PrimitiveShape::Halfspace { nx, ny, nz, offset, out } => {
                (PrimitiveFile::Halfspace { normal: [*nx, *ny, *nz], offset: *offset }, &out.output)
            }
        }
    }
}

/// The one-line summary of a validated primitive: kind, dimensions (as written to its file) and
/// volume.
fn summary(p: &Primitive) -> String {
    let dims = match p.to_file() {
        PrimitiveFile::Box { size: [x, y, z] } => format!("size {x} × {y} × {z} m"),
        PrimitiveFile::Sphere { radius } => format!("radius {radius} m"),
        PrimitiveFile::Cylinder { radius, height } | PrimitiveFile::Capsule { radius, height } => {
            format!("radius {radius} m, height {height} m")
        }
        PrimitiveFile::Halfspace { normal: [x, y, z], offset } => {
            format!("normal [{x}, {y}, {z}] (unit), offset {offset} m")
        }
    };
    let volume = if p.is_bounded() { format!("volume {:.6} m³", p.volume()) } else { "volume unbounded".to_owned() };
    format!("{}: {dims}, {volume}", p.kind())
}

/// Runs `sublevel primitive`.
///
/// # Errors
/// [`sublevel::Error::InvalidArgument`] naming the field of a bad dimension (see
/// [`Primitive::from_file`]), or whatever writing the file returns.
pub fn run(args: PrimitiveArgs) -> Result<()> {
    let (file, output) = args.shape.file();
    let primitive = Primitive::from_file(&file)?;
    primitive.save(output)?;
    println!("{} -> {}", summary(&primitive), output.display());
    Ok(())
}
