//! Convergence plots of a comparison: error against time, log-log, one line per method, as
//! PNG and SVG.
//!
//! The plots are drawn with plotters and the DejaVu Sans font compiled into the binary, so
//! the PNG looks the same on a machine without system fonts (CI, a render node); the SVG
//! names `sans-serif` and leaves the glyphs to its viewer.

use crate::compare::MethodResult;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Why a plot could not be written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The plotting backend failed (the file could not be written, or the font not loaded).
    #[error("{path}: cannot draw the plot: {message}")]
    Draw {
        /// The file being written.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
}

const SIZE: (u32, u32) = (800, 560);
const FONT: &str = "sans-serif";

/// Writes the convergence plot of `results` (relMSE against seconds, training included) to
/// `path` as PNG or SVG, chosen by the extension (`.svg` for SVG, anything else PNG).
/// Checkpoints with a zero or non-finite error cannot sit on a log axis and are left out.
pub fn convergence(results: &[MethodResult], title: &str, path: &Path) -> Result<(), PlotError> {
    static FONT_LOADED: OnceLock<bool> = OnceLock::new();
    let loaded = *FONT_LOADED.get_or_init(|| {
        plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok()
    });
    let fail = |message: String| PlotError::Draw { path: path.to_path_buf(), message };
    if !loaded {
        return Err(fail("the built-in font does not load".into()));
    }
    let is_svg = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("svg"));
    if is_svg {
        draw(SVGBackend::new(path, SIZE).into_drawing_area(), results, title)
    } else {
        draw(BitMapBackend::new(path, SIZE).into_drawing_area(), results, title)
    }
    .map_err(fail)
}

/// The points of one method that a log-log plot can show.
fn points(r: &MethodResult) -> Vec<(f64, f64)> {
    r.checkpoints
        .iter()
        .map(|c| (c.seconds, c.error.rel_mse.all))
        .filter(|&(t, e)| t > 0.0 && e > 0.0 && t.is_finite() && e.is_finite())
        .collect()
}

/// A range that covers `values` with a margin on a log axis, or `[1, 10]` when empty.
fn log_range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = values.fold((f64::INFINITY, 0.0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if lo > hi {
        return 1.0..10.0;
    }
    // A quarter of a decade of margin, and at least half a decade in all so that a single
    // point or a flat line still gets labelled ticks.
    let (mut lo, mut hi) = (lo / 10f64.powf(0.25), hi * 10f64.powf(0.25));
    if hi / lo < 10f64.powf(0.5) {
        let mid = (lo * hi).sqrt();
        (lo, hi) = (mid / 10f64.powf(0.25), mid * 10f64.powf(0.25));
    }
    lo..hi
}

/// A tick label with at most three significant digits.
fn short(v: f64) -> String {
    if (0.01..1e4).contains(&v.abs()) {
        let digits = (2 - v.abs().log10().floor() as i32).max(0) as usize;
        let s = format!("{v:.digits$}");
        if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.').to_string() } else { s }
    } else {
        format!("{v:.1e}")
    }
}

fn draw<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    results: &[MethodResult],
    title: &str,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let series: Vec<_> = results.iter().map(|r| (r.name.as_str(), points(r))).collect();
    let all = || series.iter().flat_map(|(_, p)| p.iter());
    let x = log_range(all().map(|p| p.0));
    let y = log_range(all().map(|p| p.1));
    root.fill(&WHITE).map_err(e)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, (FONT, 22))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(80)
        .build_cartesian_2d(x.log_scale(), y.log_scale())
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("seconds (training included)")
        .y_desc("relMSE")
        .x_labels(8)
        .y_labels(8)
        .x_label_formatter(&|v| short(*v))
        .y_label_formatter(&|v| short(*v))
        .label_style((FONT, 14))
        .draw()
        .map_err(e)?;
    for (i, (name, p)) in series.iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(p.iter().copied(), colour.stroke_width(2)))
            .map_err(e)?
            .label(*name)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 24, y)], colour.stroke_width(2)));
        chart.draw_series(p.iter().map(|&q| Circle::new(q, 4, colour.filled()))).map_err(e)?;
    }
    chart
        .configure_series_labels()
        .label_font((FONT, 14))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(e)?;
    root.present().map_err(e)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_range_covers_the_values_with_margin() {
        let r = log_range([1e-3, 1e-1].into_iter());
        assert!(r.start < 1e-3 && r.end > 1e-1);
        let single = log_range([0.5].into_iter());
        assert!(single.start < 0.5 && single.end > 0.5 && single.end / single.start >= 3.0);
        assert_eq!(log_range(std::iter::empty()), 1.0..10.0);
    }

    #[test]
    fn tick_labels_are_short() {
        assert_eq!(short(20.0), "20");
        assert_eq!(short(0.25), "0.25");
        assert_eq!(short(1.2345), "1.23");
        assert_eq!(short(0.0001), "1.0e-4");
        assert_eq!(short(123456.0), "1.2e5");
    }
}
