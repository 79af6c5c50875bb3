//! `control`'s figure: the plant's true pressure and flow against the setpoint, and the
//! torque reference, for each law run, over the whole run (the pre-roll included).

use super::{EventFigures, Law, Scenario, Trace};
use crate::error::Failure;
use crate::plots;
use plotters::prelude::*;
use std::path::Path;

const FONT: &str = "sans-serif";
const SETPOINT: RGBColor = RGBColor(40, 40, 40);

/// The colour of a law's lines.
fn colour(law: Law) -> RGBColor {
    match law {
        Law::Model => RGBColor(214, 39, 40),
        Law::Pi => RGBColor(31, 119, 180),
    }
}

/// `[lo, hi]` of the values with 5 % margins (never an empty range).
fn span(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-3 * hi.abs().max(1.0));
    (lo - pad, hi + pad)
}

type Drawn = Result<(), Box<dyn std::error::Error>>;

/// One panel: each run's series `value` and, if `setpoint_mode` is given, the scenario's
/// setpoint where the run is in that mode.
fn panel(
    area: &DrawingArea<BitMapBackend, plotters::coord::Shift>,
    title: &str,
    y_desc: &str,
    scenario: &Scenario,
    runs: &[(Trace, Vec<EventFigures>)],
    value: &dyn Fn(&super::Sample) -> Option<f64>,
    setpoint_mode: Option<u16>,
) -> Drawn {
    let t0 = runs
        .first()
        .and_then(|r| r.0.samples.first())
        .map_or(0.0, |s| s.t_s);
    let t1 = runs
        .first()
        .and_then(|r| r.0.samples.last())
        .map_or(1.0, |s| s.t_s)
        .max(t0 + 1e-3);
    let setpoint = |s: &super::Sample| -> Option<f64> {
        let r = &scenario.rows[s.row];
        (Some(s.mode) == setpoint_mode).then_some(r.setpoint)
    };
    let (y0, y1) = span(runs.iter().flat_map(|(tr, _)| {
        tr.samples
            .iter()
            .flat_map(|s| [value(s), setpoint(s)].into_iter().flatten())
    }));
    let mut chart = ChartBuilder::on(area)
        .caption(title, (FONT, 20))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(t0..t1, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc(y_desc)
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 16))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;
    if let (Some(_), Some((tr, _))) = (setpoint_mode, runs.first()) {
        // The setpoint: runs of consecutive samples in the mode.
        let mut first = true;
        let mut run: Vec<(f64, f64)> = Vec::new();
        let mut flush = |run: &mut Vec<(f64, f64)>, first: &mut bool| -> Drawn {
            if run.is_empty() {
                return Ok(());
            }
            let s = chart.draw_series(LineSeries::new(run.drain(..), SETPOINT.stroke_width(1)))?;
            if *first {
                s.label("setpoint").legend(|(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], SETPOINT.stroke_width(2))
                });
                *first = false;
            }
            Ok(())
        };
        for s in &tr.samples {
            match setpoint(s) {
                Some(v) => run.push((s.t_s, v)),
                None => flush(&mut run, &mut first)?,
            }
        }
        flush(&mut run, &mut first)?;
    }
    for (tr, _) in runs {
        let c = colour(tr.law);
        let points: Vec<(f64, f64)> = tr
            .samples
            .iter()
            .filter_map(|s| value(s).map(|v| (s.t_s, v)))
            .collect();
        chart
            .draw_series(LineSeries::new(points, c.stroke_width(1)))?
            .label(tr.law.name())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
    }
    plots::legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    Ok(())
}

/// Draws the figure to `png` (through a temporary file beside it, renamed into place).
pub fn draw(
    png: &Path,
    scenario: &Scenario,
    runs: &[(Trace, Vec<EventFigures>)],
) -> Result<(), Failure> {
    plots::font()?;
    let draw = |tmp: &Path| -> Drawn {
        let root = BitMapBackend::new(tmp, (1600, 1000)).into_drawing_area();
        root.fill(&WHITE)?;
        let root = root.titled(
            &format!(
                "pumpbench control, scenario {} (plant truth)",
                scenario.name
            ),
            (FONT, 24),
        )?;
        let areas = root.split_evenly((3, 1));
        panel(
            &areas[0],
            "Outlet pressure (true)",
            "pressure (mca)",
            scenario,
            runs,
            &|s| s.truth.map(|t| t.pressure_mca),
            Some(3),
        )?;
        panel(
            &areas[1],
            "Flow (true)",
            "flow (l/s)",
            scenario,
            runs,
            &|s| s.truth.map(|t| t.flow_lps),
            Some(4),
        )?;
        panel(
            &areas[2],
            "Torque reference",
            "torque (%)",
            scenario,
            runs,
            &|s| Some(f64::from(s.torque_ref_pct)),
            None,
        )?;
        root.present()?;
        Ok(())
    };
    plots::write_png(png, |tmp| draw(tmp).map_err(|e| e.to_string()))
}
