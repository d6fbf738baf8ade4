//! The table as CSV (`table1 --csv`): one record per (row, shape), columns [`CSV_COLUMNS`].

use super::cell::Cell;
use super::paper::{Row, RowKind, ShapeRef};
use crate::csv_file::CsvFile;
use std::path::Path;
use sublevel_core::math::Real;
use sublevel_core::Result;

/// Columns of `table1 --csv`, one record per (row, shape): the row key, the formulation's name,
/// 2d and c (empty for baselines), the shape's file stem, our volume and its standard error, the
/// paper's value and ours / paper, the cell's seconds, status and kept frame, Clarabel's primal /
/// dual objectives and gap, the primary-frame volume, and the stated-program check (volume, std
/// error, gap).
pub const CSV_COLUMNS: [&str; 19] = [
    "row",
    "objective",
    "degree",
    "c",
    "shape",
    "volume",
    "std_error",
    "paper",
    "ratio",
    "fit_seconds",
    "status",
    "frame",
    "primal_objective",
    "dual_objective",
    "gap",
    "primary_frame_volume",
    "stated_volume",
    "stated_std_error",
    "stated_gap",
];

/// Writes the cells to `path` (folders created), one record per (row, shape).
pub(super) fn write_csv(path: &Path, rows: &[&Row], shapes: &[ShapeRef], cells: &[Vec<Cell>]) -> Result<()> {
    let mut csv = CsvFile::create(path, &CSV_COLUMNS)?;
    for (ri, row) in rows.iter().enumerate() {
        let (degree, c) = match row.kind {
            RowKind::Fit { degree, c, .. } => (degree.to_string(), c.to_string()),
            _ => (String::new(), String::new()),
        };
        let objective = match row.kind {
            RowKind::Fit { method, .. } => method.name(),
            _ => "",
        };
        for (si, (col, s)) in shapes.iter().enumerate() {
            let cell = &cells[ri][si];
            let paper = row.paper.map(|p| p[*col]);
            let opt = |v: Option<Real>| v.map_or_else(String::new, |v| format!("{v}"));
            let ratio = match (cell.volume, paper) {
                (Some(v), Some(p)) => Some(v / p),
                _ => None,
            };
            let (primal, dual, gap) = cell.certificate.map_or_else(
                || (String::new(), String::new(), String::new()),
                |c| (format!("{}", c.primal_objective), format!("{}", c.dual_objective), format!("{:e}", c.gap())),
            );
            let (stated_volume, stated_se, stated_gap) = cell.stated.as_ref().map_or_else(
                || (String::new(), String::new(), String::new()),
                |st| {
                    let gap = st.certificate.map_or_else(String::new, |g| format!("{:e}", g.gap()));
                    (format!("{}", st.volume), format!("{}", st.std_error), gap)
                },
            );
            csv.record([
                row.key.to_string(),
                objective.to_string(),
                degree.clone(),
                c.clone(),
                s.0.to_string(),
                opt(cell.volume),
                if cell.volume.is_some() { format!("{}", cell.std_error) } else { String::new() },
                opt(paper),
                opt(ratio),
                format!("{:.3}", cell.seconds),
                cell.status.clone(),
                cell.frame.clone(),
                primal,
                dual,
                gap,
                opt(cell.primary_volume),
                stated_volume,
                stated_se,
                stated_gap,
            ])?;
        }
    }
    csv.finish()?;
    Ok(())
}
