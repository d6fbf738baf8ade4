//! The ratio chart (`table1 --png`, plotters): ours / the paper's per row and shape.

use super::analysis::{certified_above, Clouds};
use super::cell::Cell;
use super::paper::{Row, ShapeRef};
use plotters::prelude::*;
use std::path::Path;

/// The ratio chart: one column per row, one dot per shape (filled: ≤ 1.02 × the paper or not
/// checked; ring: above 1.02 × the paper with the paper's value below a certified optimum of its
/// stated program), the lines ratio = 1 and 1.02, row keys below the axis.
pub(super) fn draw_chart(
    path: &Path,
    rows: &[&Row],
    shapes: &[ShapeRef],
    cells: &[Vec<Cell>],
    clouds: &Clouds,
) -> std::result::Result<(), Box<dyn std::error::Error>> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    let root = BitMapBackend::new(path, (1600, 900)).into_drawing_area();
    root.fill(&WHITE)?;
    let n = rows.len() as f64;
    // (x, ratio, certified above) per shape.
    let points: Vec<Vec<(f64, f64, bool)>> = (0..shapes.len())
        .map(|si| {
            let col = shapes[si].0;
            let offset = (si as f64 - (shapes.len() as f64 - 1.0) / 2.0) * 0.12;
            rows.iter()
                .enumerate()
                .filter_map(|(ri, row)| {
                    let p = row.paper?[col];
                    let cell = &cells[ri][si];
                    let v = cell.volume?;
                    let ring = certified_above(row, col, cell, clouds[si].2) == Some(true);
                    (v > 0.0 && p > 0.0).then_some((ri as f64 + offset, v / p, ring))
                })
                .collect()
        })
        .collect();
    let ratios = points.iter().flatten().map(|p| p.1);
    let lo = ratios.clone().fold(1.0, f64::min).max(0.01) / 1.25;
    let hi = ratios.fold(1.0, f64::max).min(100.0) * 1.25;
    let mut chart = ChartBuilder::on(&root)
        .caption("Table 1: our volume / the paper's, per row and shape", ("sans-serif", 26))
        .margin(20)
        .x_label_area_size(190)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.5..n - 0.5, (lo..hi).log_scale())?;
    chart
        .configure_mesh()
        .x_labels(0)
        .disable_x_mesh()
        .y_labels(15)
        .y_label_formatter(&|y| format!("{y:.2}"))
        .y_desc("ours / paper (log scale)")
        .draw()?;
    chart.draw_series(LineSeries::new([(-0.5, 1.0), (n - 0.5, 1.0)], BLACK.stroke_width(1)))?;
    chart.draw_series(DashedLineSeries::new([(-0.5, 1.02), (n - 0.5, 1.02)], 6, 4, BLACK.mix(0.5).stroke_width(1)))?;
    // Row keys, rotated, starting just below the axis.
    let key_style = TextStyle::from(("sans-serif", 14).into_font()).transform(FontTransform::Rotate90).pos(
        plotters::style::text_anchor::Pos::new(
            plotters::style::text_anchor::HPos::Left,
            plotters::style::text_anchor::VPos::Center,
        ),
    );
    for (ri, row) in rows.iter().enumerate() {
        let (x, y) = chart.backend_coord(&(ri as f64, lo));
        root.draw(&Text::new(row.key.to_string(), (x, y + 8), key_style.clone()))?;
    }
    let colors = [RED, BLUE, GREEN, MAGENTA, CYAN];
    for (si, (_, s)) in shapes.iter().enumerate() {
        let color = colors[si % colors.len()];
        let pts = points[si].clone();
        chart
            .draw_series(pts.into_iter().map(move |(x, y, ring)| {
                let style = if ring { color.stroke_width(2) } else { color.filled() };
                Circle::new((x, y), 5, style)
            }))?
            .label(s.1)
            .legend(move |(x, y)| Circle::new((x, y), 5, color.filled()));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.draw(&Text::new(
        "dashed: 1.02 x paper; ring: above it, the paper's value below a certified optimum of its stated program",
        (90, 870),
        ("sans-serif", 15).into_font(),
    ))?;
    root.present()?;
    Ok(())
}
