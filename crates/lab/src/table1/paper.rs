//! The paper's Table 1 as data: the five shapes, the 25 rows (what each computes, the paper's
//! values and the line of the paper's LaTeX source they come from) and the `--quick` selection.

use sublevel_core::math::Real;
use sublevel_fit::FitMethod;

/// The five shapes: file stem, column title, the paper's #points / #hull vertices.
pub const SHAPES: [(&str, &str, usize, usize); 5] = [
    ("human_10", "Human (10)", 9508, 364),
    ("chair_101", "Chair (101)", 8499, 320),
    ("hand_181", "Hand (181)", 7242, 652),
    ("vase_361", "Vase (361)", 14859, 1443),
    ("octopus_121", "Octopus (121)", 5944, 414),
];

/// A selected shape: its column in [`SHAPES`] and its entry.
pub type ShapeRef = (usize, &'static (&'static str, &'static str, usize, usize));

/// What a row computes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RowKind {
    /// Convex hull volume.
    Hull,
    /// Minimum enclosing ball.
    Sphere,
    /// Minimum-volume oriented box (the paper's "AABB").
    Obb,
    /// Axis-aligned box in file coordinates (not in the paper).
    Aabb,
    /// A fitted body.
    Fit {
        /// Formulation.
        method: FitMethod,
        /// Total degree 2d.
        degree: usize,
        /// Convexity relaxation c of eq. "VAG.param.convex".
        c: Real,
    },
}

/// One row of Table 1.
#[derive(Clone, Copy, Debug)]
pub struct Row {
    /// Key for `--rows` (prefix match on `-`-separated words).
    pub key: &'static str,
    /// Label of the row ("Bounding Body" column).
    pub label: &'static str,
    /// Objective ("Objective fcn" column).
    pub objective: &'static str,
    /// What it computes.
    pub kind: RowKind,
    /// The paper's values for the five shapes (None: not in the paper).
    pub paper: Option<[Real; 5]>,
    /// Line of `sos_geom_v7.tex` the values come from (0: not in the paper).
    pub source_line: usize,
}

const fn fit(method: FitMethod, degree: usize, c: Real) -> RowKind {
    RowKind::Fit { method, degree, c }
}

use FitMethod::{InverseMoment as IM, LogDetH as LDH, LogDetP as LDP, TraceH as TRH, TraceP as TRP};

/// The paper's Table 1, row by row, with the line of the paper's LaTeX source (version 7,
/// `sos_geom_v7.tex`) it comes from.
#[rustfmt::skip]
pub const ROWS: [Row; 25] = [
    Row { key: "hull", label: "Convex-Hull", objective: "", kind: RowKind::Hull, paper: Some([0.29, 0.66, 0.36, 0.91, 0.5]), source_line: 223 },
    Row { key: "sphere", label: "Sphere", objective: "", kind: RowKind::Sphere, paper: Some([3.74, 3.73, 3.84, 3.91, 4.1]), source_line: 224 },
    Row { key: "obb", label: "Box (min-volume OBB)", objective: "", kind: RowKind::Obb, paper: Some([0.59, 1.0, 0.81, 1.73, 1.28]), source_line: 225 },
    Row { key: "aabb", label: "Box (axis-aligned)", objective: "", kind: RowKind::Aabb, paper: None, source_line: 0 },
    Row { key: "sos-convex-2-logdet_p", label: "sos-convex (2d=2)", objective: "logdet", kind: fit(LDP, 2, 0.0), paper: Some([0.58, 1.79, 0.82, 1.16, 1.30]), source_line: 227 },
    Row { key: "sos-convex-2-trace_p", label: "sos-convex (2d=2)", objective: "trace", kind: fit(TRP, 2, 0.0), paper: Some([0.97, 1.80, 1.40, 1.2, 1.76]), source_line: 228 },
    Row { key: "sos-convex-4-logdet_h", label: "sos-convex (2d=4)", objective: "logdet(H^-1)", kind: fit(LDH, 4, 0.0), paper: Some([0.57, 1.55, 0.69, 1.13, 1.04]), source_line: 230 },
    Row { key: "sos-convex-4-trace_h", label: "sos-convex (2d=4)", objective: "trace(H^-1)", kind: fit(TRH, 4, 0.0), paper: Some([0.56, 2.16, 1.28, 1.09, 3.13]), source_line: 231 },
    Row { key: "sos-convex-4-logdet_p", label: "sos-convex (2d=4)", objective: "logdet(P^-1)", kind: fit(LDP, 4, 0.0), paper: Some([0.44, 1.19, 0.53, 1.05, 0.86]), source_line: 232 },
    Row { key: "sos-convex-4-trace_p", label: "sos-convex (2d=4)", objective: "trace(P^-1)", kind: fit(TRP, 4, 0.0), paper: Some([0.57, 1.25, 0.92, 1.09, 1.02]), source_line: 233 },
    Row { key: "sos-convex-6-logdet_h", label: "sos-convex (2d=6)", objective: "logdet(H^-1)", kind: fit(LDH, 6, 0.0), paper: Some([0.57, 1.27, 0.58, 1.09, 0.93]), source_line: 235 },
    Row { key: "sos-convex-6-trace_h", label: "sos-convex (2d=6)", objective: "trace(H^-1)", kind: fit(TRH, 6, 0.0), paper: Some([0.56, 1.30, 0.57, 1.09, 0.87]), source_line: 236 },
    Row { key: "sos-convex-6-logdet_p", label: "sos-convex (2d=6)", objective: "logdet(P^-1)", kind: fit(LDP, 6, 0.0), paper: Some([0.41, 1.02, 0.45, 0.99, 0.74]), source_line: 237 },
    Row { key: "sos-convex-6-trace_p", label: "sos-convex (2d=6)", objective: "trace(P^-1)", kind: fit(TRP, 6, 0.0), paper: Some([0.45, 1.21, 0.48, 1.03, 0.79]), source_line: 238 },
    Row { key: "inverse-moment-2", label: "Inverse-Moment (2d=2)", objective: "", kind: fit(IM, 2, 0.0), paper: Some([4.02, 1.42, 2.14, 1.36, 1.74]), source_line: 241 },
    Row { key: "inverse-moment-4", label: "Inverse-Moment (2d=4)", objective: "", kind: fit(IM, 4, 0.0), paper: Some([1.53, 0.95, 0.90, 1.25, 0.75]), source_line: 242 },
    Row { key: "inverse-moment-6", label: "Inverse-Moment (2d=6)", objective: "", kind: fit(IM, 6, 0.0), paper: Some([0.48, 0.54, 0.58, 1.10, 0.57]), source_line: 243 },
    Row { key: "sos-4-c10-logdet_p", label: "sos (2d=4, c=10)", objective: "logdet(P^-1)", kind: fit(LDP, 4, 10.0), paper: Some([0.38, 0.72, 0.42, 1.05, 0.63]), source_line: 246 },
    Row { key: "sos-4-c10-trace_p", label: "sos (2d=4, c=10)", objective: "trace(P^-1)", kind: fit(TRP, 4, 10.0), paper: Some([0.51, 0.78, 0.48, 1.11, 0.71]), source_line: 247 },
    Row { key: "sos-6-c10-logdet_p", label: "sos (2d=6, c=10)", objective: "logdet(P^-1)", kind: fit(LDP, 6, 10.0), paper: Some([0.35, 0.49, 0.34, 0.92, 0.41]), source_line: 250 },
    Row { key: "sos-6-c10-trace_p", label: "sos (2d=6, c=10)", objective: "trace(P^-1)", kind: fit(TRP, 6, 10.0), paper: Some([0.37, 0.56, 0.39, 0.99, 0.54]), source_line: 251 },
    Row { key: "sos-4-c100-logdet_p", label: "sos (2d=4, c=100)", objective: "logdet(P^-1)", kind: fit(LDP, 4, 100.0), paper: Some([0.36, 0.64, 0.39, 1.05, 0.46]), source_line: 254 },
    Row { key: "sos-4-c100-trace_p", label: "sos (2d=4, c=100)", objective: "trace(P^-1)", kind: fit(TRP, 4, 100.0), paper: Some([0.42, 0.74, 0.46, 1.10, 0.54]), source_line: 255 },
    Row { key: "sos-6-c100-logdet_p", label: "sos (2d=6, c=100)", objective: "logdet(P^-1)", kind: fit(LDP, 6, 100.0), paper: Some([0.21, 0.21, 0.26, 0.82, 0.28]), source_line: 258 },
    Row { key: "sos-6-c100-trace_p", label: "sos (2d=6, c=100)", objective: "trace(P^-1)", kind: fit(TRP, 6, 100.0), paper: Some([0.22, 0.30, 0.29, 0.85, 0.37]), source_line: 259 },
];

/// Rows and shapes of `--quick`.
pub const QUICK_ROWS: [&str; 8] = [
    "hull",
    "sphere",
    "obb",
    "aabb",
    "sos-convex-2",
    "sos-convex-4-logdet_p",
    "inverse-moment-2",
    "sos-4-c10-logdet_p",
];

/// Shapes of `--quick`.
pub const QUICK_SHAPES: [&str; 2] = ["human_10", "chair_101"];
