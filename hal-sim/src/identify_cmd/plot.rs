//! The `--plot` figure of `hter identify`.

use std::path::Path;

use anyhow::Result;
use hter::ident::model::Structure;

use super::fit::Fit;
use super::load::Data;
use crate::plot;

/// Parameter convergence (recursive methods) and measured vs simulated output, to a .png or
/// .svg file.
pub(super) fn plot_fit(path: &Path, d: &Data, s: &Structure, f: &Fit) -> Result<()> {
    let minutes = |t: f64| t / 60.0;
    let mut panels = Vec::new();
    if !f.theta_history.is_empty() {
        let series = |range: std::ops::Range<usize>, name: &dyn Fn(usize) -> String| -> Vec<plot::Series> {
            range
                .map(|i| plot::Series {
                    name: name(i),
                    points: f.theta_history.iter().filter_map(|(t, th)| th.get(i).map(|v| (minutes(*t), *v))).collect(),
                })
                .collect()
        };
        let (na, nb) = (s.na, s.nb);
        panels.push(plot::Panel {
            title: "Parameter convergence: A and C (recursive estimate)".into(),
            y_label: "a, c".into(),
            series: series(0..na, &|i| format!("a{}", i + 1))
                .into_iter()
                .chain(series(na + nb..s.n_params(), &|i| format!("c{}", i - na - nb + 1)))
                .collect(),
            y_range: None,
        });
        panels.push(plot::Panel {
            title: "Parameter convergence: B".into(),
            y_label: "b (°C/duty)".into(),
            series: series(na..na + nb, &|i| format!("b{}", i - na)),
            y_range: None,
        });
    }
    let y0 = d.op.temp_c;
    panels.push(plot::Panel {
        title: format!("Measured vs simulated output (fit {:.1} %)", f.fit_percent),
        y_label: "°C".into(),
        series: vec![
            plot::Series {
                name: "measured".into(),
                points: d.t.iter().zip(&d.y).map(|(t, y)| (minutes(*t), y + y0)).collect(),
            },
            plot::Series {
                name: "simulated from the input".into(),
                points: d.t.iter().zip(&f.ysim).map(|(t, y)| (minutes(*t), y + y0)).collect(),
            },
        ],
        y_range: None,
    });
    plot::panels(path, "hter identify", "time (min)", &panels)
}
