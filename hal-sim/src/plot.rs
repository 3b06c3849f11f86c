//! Plots with plotters: stacked time-series panels in one PNG or SVG.
//!
//! plotters is built without system fonts (no fontconfig on the user's machine needed): the
//! DejaVu Sans face shipped in `assets/` is registered once as "sans-serif".

use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use plotters::coord::Shift;
use plotters::prelude::*;

/// One line on a panel.
pub struct Series {
    /// Legend label.
    pub name: String,
    /// (x, y) points; a point whose y is NaN breaks the line there (a gap with no data).
    pub points: Vec<(f64, f64)>,
}

/// One panel: a y axis with several series against a shared x axis.
pub struct Panel {
    /// Title shown above the panel.
    pub title: String,
    /// Y-axis label.
    pub y_label: String,
    /// The lines.
    pub series: Vec<Series>,
    /// Fixed y range, or `None` to fit the data.
    pub y_range: Option<(f64, f64)>,
}

const COLOURS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(127, 127, 127),
];

fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // The font is compiled in, so registration cannot fail on a user's machine.
        let _ =
            plotters::style::register_font("sans-serif", FontStyle::Normal, include_bytes!("../assets/DejaVuSans.ttf"));
    });
}

/// Checks, before a run, that a plot can go to `path`: a `.png` or `.svg` name in a directory
/// that exists (the run is not wasted on a plot that cannot be written, and `hter compare` does
/// not print its table before failing). The error reads as `--csv`'s: the path and the OS's
/// reason.
pub fn check_path(path: &Path) -> Result<()> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if !matches!(ext.as_deref(), Some("png" | "svg")) {
        bail!("plot file '{}' must end in .png or .svg", path.display());
    }
    check_dir(path)
}

/// The directory `path` would be written in exists, or the OS's error with the path, as
/// `cannot write 'PATH': No such file or directory (os error 2)`.
pub fn check_dir(path: &Path) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    std::fs::metadata(dir).map(|_| ()).with_context(|| format!("cannot write '{}'", path.display()))
}

/// Draws `panels` stacked vertically into `path` (`.png` or `.svg`), x axis labelled `x_label`.
pub fn panels(path: &Path, title: &str, x_label: &str, panels: &[Panel]) -> Result<()> {
    register_font();
    let height = 300 * panels.len() as u32 + 60;
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    let png = match ext.as_deref() {
        Some("png") => true,
        Some("svg") => false,
        _ => bail!("plot file '{}' must end in .png or .svg", path.display()),
    };
    // Drawn into a temporary file beside it, renamed over `path` once complete
    // ([`crate::output`]). The file is opened first: the backends report a missing directory as
    // "backend error: Drawing backend error: ImageError(IoError(Os { … }))".
    crate::output::write_with(path, |tmp| {
        std::fs::File::create(tmp).with_context(|| format!("cannot write '{}'", path.display()))?;
        let presented = if png {
            let root = BitMapBackend::new(tmp, (1100, height)).into_drawing_area();
            draw(&root, title, x_label, panels)?;
            root.present().map_err(|e| e.to_string())
        } else {
            let root = SVGBackend::new(tmp, (1100, height)).into_drawing_area();
            draw(&root, title, x_label, panels)?;
            root.present().map_err(|e| e.to_string())
        };
        presented.map_err(|e| anyhow!("cannot write plot '{}': {e}", path.display()))
    })
}

/// Draws `panels` stacked vertically, `width` px wide, into an SVG document returned as text
/// (for inlining in an HTML report).
pub fn panels_svg(width: u32, title: &str, x_label: &str, panels: &[Panel]) -> Result<String> {
    register_font();
    let height = 300 * panels.len() as u32 + 60;
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, (width, height)).into_drawing_area();
        draw(&root, title, x_label, panels)?;
        root.present().map_err(|e| anyhow!("plot: {e:?}"))?;
    }
    Ok(out)
}

fn draw<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, title: &str, x_label: &str, panels: &[Panel]) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("plot: {e:?}");
    root.fill(&WHITE).map_err(err)?;
    let root = root.titled(title, ("sans-serif", 22)).map_err(err)?;
    let areas = root.split_evenly((panels.len(), 1));
    for (area, panel) in areas.iter().zip(panels) {
        let all = || panel.series.iter().flat_map(|s| s.points.iter());
        let (x0, x1) = all().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.0), b.max(p.0)));
        let (y0, y1) = panel.y_range.unwrap_or_else(|| {
            let (a, b) = all().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.1), b.max(p.1)));
            let pad = ((b - a) * 0.05).max(0.1);
            (a - pad, b + pad)
        });
        if !(x0.is_finite() && x1.is_finite() && y0.is_finite() && y1.is_finite()) {
            bail!("plot: panel '{}' has no finite data", panel.title);
        }
        let x1 = if x1 > x0 { x1 } else { x0 + 1.0 };
        let mut chart = ChartBuilder::on(area)
            .caption(&panel.title, ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(36)
            .y_label_area_size(56)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(err)?;
        chart.configure_mesh().x_desc(x_label).y_desc(&panel.y_label).draw().map_err(err)?;
        for (i, s) in panel.series.iter().enumerate() {
            let colour = COLOURS[i % COLOURS.len()];
            // One line a run between NaN breaks: a line drawn across a gap shows a temperature
            // nobody measured. The first run carries the legend.
            let mut runs = s.points.split(|p| p.1.is_nan()).filter(|r| !r.is_empty());
            let first = runs.next().unwrap_or(&[]);
            chart
                .draw_series(LineSeries::new(first.iter().copied(), colour.stroke_width(2)))
                .map_err(err)?
                .label(s.name.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2)));
            for run in runs {
                chart.draw_series(LineSeries::new(run.iter().copied(), colour.stroke_width(2))).map_err(err)?;
            }
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(err)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A plot into a missing directory reads as `--csv`'s error does: the path and the OS's
    /// reason, on one line, not the backend's debug dump.
    #[test]
    fn a_missing_directory_is_the_os_error() {
        let path = std::env::temp_dir().join(format!("hter-plot-{}-no-dir/x.png", std::process::id()));
        let panel = Panel {
            title: "t".into(),
            y_label: "y".into(),
            series: vec![Series { name: "s".into(), points: vec![(0.0, 1.0), (1.0, 2.0)] }],
            y_range: None,
        };
        let e = format!("{:#}", panels(&path, "title", "x", &[panel]).unwrap_err());
        assert!(e.starts_with(&format!("cannot write '{}': ", path.display())), "{e}");
        assert!(e.contains("os error 2") && !e.contains("backend") && !e.contains('\n'), "{e}");
        // The check before a run says the same.
        assert_eq!(format!("{:#}", check_path(&path).unwrap_err()), e);
        assert!(check_path(&std::env::temp_dir().join("x.svg")).is_ok());
        let e = check_path(&std::env::temp_dir().join("x.jpg")).unwrap_err().to_string();
        assert!(e.contains("must end in .png or .svg"), "{e}");
    }
}
