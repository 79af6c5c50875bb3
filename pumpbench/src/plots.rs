//! PNG figures of `study`, drawn like the paper's figures 4, 5, 7 and 8.
//!
//! Text goes through plotters' `ab_glyph` renderer with Noto Sans Regular embedded in the
//! binary (crate `ttf-noto-sans`, font under Apache-2.0): no system font is needed.

use crate::error::Failure;
use crate::study::TargetResult;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};
use std::error::Error;
use std::path::Path;
use std::sync::OnceLock;

/// Width of the detail window of figures 4 and 7, s.
pub const DETAIL_S: f64 = 20.0;

type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;
type Drawn = Result<(), Box<dyn Error>>;

const FONT: &str = "sans-serif";
const MEASURED: RGBColor = RGBColor(40, 40, 40);
const MODEL: RGBColor = RGBColor(214, 39, 40);
const POINTS: RGBColor = RGBColor(31, 119, 180);

/// The figures' legend: a white box at `position`, the series' labels in 15 px.
pub(crate) fn legend<'a, DB, CT>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: DrawingBackend + 'a,
    CT: CoordTranslate,
{
    chart
        .configure_series_labels()
        .position(position)
        .label_font((FONT, 15))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
}

/// Writes the PNG `png` through a temporary file beside it (its name ending in `.png`: the
/// encoder picks the format by the extension), renamed into place once `draw` has written it
/// there: a failed draw leaves no partial file, and an existing file's permissions are kept.
pub(crate) fn write_png(
    png: &Path,
    draw: impl FnOnce(&Path) -> Result<(), String>,
) -> Result<(), Failure> {
    let fail = |e: String| Failure {
        code: 1,
        message: format!("cannot draw {}: {e}", png.display()),
    };
    let dir = match png.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = png
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = tempfile::Builder::new()
        .prefix(&format!(".{name}.partial-"))
        .suffix(".png")
        .tempfile_in(dir)
        .map_err(|e| fail(e.to_string()))?;
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(png).map_or(0o644, |m| m.permissions().mode());
        std::fs::set_permissions(tmp.path(), std::fs::Permissions::from_mode(mode))
            .map_err(|e| fail(e.to_string()))?;
    }
    draw(tmp.path()).map_err(fail)?;
    tmp.persist(png).map_err(|e| fail(e.error.to_string()))?;
    Ok(())
}

/// Registers the embedded font as `sans-serif` (once per process).
pub(crate) fn font() -> Result<(), Failure> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE
        .get_or_init(|| register_font(FONT, FontStyle::Normal, ttf_noto_sans::REGULAR).is_ok());
    if ok {
        Ok(())
    } else {
        Err(Failure {
            code: 1,
            message: "cannot load the embedded font".into(),
        })
    }
}

/// Unit and name of a target's axis.
fn axis(r: &TargetResult) -> (&'static str, &'static str) {
    match r.target {
        crate::modelfile::Target::Pressure => ("pressure (mca)", "Pressure"),
        crate::modelfile::Target::Flow => ("flow (l/s)", "Flow"),
    }
}

/// `[lo, hi]` of the values with 5 % margins (never an empty range).
fn span<'a>(values: impl Iterator<Item = &'a f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-3 * hi.abs().max(1.0));
    (lo - pad, hi + pad)
}

/// Measurement and model output over `window` (s) of the record.
#[allow(clippy::too_many_arguments)]
fn time_panel(
    area: &Area,
    title: &str,
    y_desc: &str,
    t: &[f64],
    measured: &[f64],
    model: &[f64],
    model_label: &str,
    window: (f64, f64),
) -> Drawn {
    let inside = |k: &usize| (window.0..=window.1).contains(&t[*k]);
    let rows: Vec<usize> = (0..t.len()).filter(inside).collect();
    let (y0, y1) = span(rows.iter().flat_map(|&k| [&measured[k], &model[k]]));
    let mut chart = ChartBuilder::on(area)
        .caption(title, (FONT, 20))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(window.0..window.1, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_desc(y_desc)
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 16))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;
    // In a detail window the measurement is drawn wider, so that both lines show.
    let width = if window.1 - window.0 <= 2.0 * DETAIL_S {
        2
    } else {
        1
    };
    chart
        .draw_series(LineSeries::new(
            rows.iter().map(|&k| (t[k], measured[k])),
            MEASURED.stroke_width(width),
        ))?
        .label("measurement")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], MEASURED.stroke_width(2)));
    chart
        .draw_series(LineSeries::new(
            rows.iter().map(|&k| (t[k], model[k])),
            MODEL.stroke_width(1),
        ))?
        .label(model_label)
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], MODEL.stroke_width(2)));
    legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    Ok(())
}

/// The detail window: `DETAIL_S` seconds in the middle of the record.
fn detail(t: &[f64]) -> (f64, f64) {
    let (a, b) = (t[0], t[t.len() - 1]);
    if b - a <= DETAIL_S {
        return (a, b);
    }
    let start = ((a + b) / 2.0 - DETAIL_S / 2.0).round();
    (start, start + DETAIL_S)
}

/// 2×2 panels: pressure (whole record, detail), flow (whole record, detail).
fn validation_figure(
    path: &Path,
    title: &str,
    results: [(&TargetResult, &[f64]); 2],
    model_label: &str,
) -> Drawn {
    let root = BitMapBackend::new(path, (1600, 1000)).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(title, (FONT, 26))?;
    let panels = root.split_evenly((2, 2));
    for (i, (r, model)) in results.into_iter().enumerate() {
        let (y_desc, name) = axis(r);
        let whole = (r.t_s[0], r.t_s[r.t_s.len() - 1]);
        let d = detail(&r.t_s);
        time_panel(
            &panels[2 * i],
            &format!("{name}: validation record"),
            y_desc,
            &r.t_s,
            &r.measured,
            model,
            model_label,
            whole,
        )?;
        time_panel(
            &panels[2 * i + 1],
            &format!("{name}: detail, {:.0} to {:.0} s", d.0, d.1),
            y_desc,
            &r.t_s,
            &r.measured,
            model,
            model_label,
            d,
        )?;
    }
    root.present()?;
    Ok(())
}

/// Measured steady-state points and the model's steady curve against torque.
fn static_panel(
    area: &Area,
    title: &str,
    y_desc: &str,
    points: &[(f64, f64)],
    curve: &[(f64, f64)],
    model_label: &str,
) -> Drawn {
    let (y0, y1) = span(points.iter().chain(curve).map(|p| &p.1));
    let (y0, y1) = (y0.min(0.0), y1);
    let mut chart = ChartBuilder::on(area)
        .caption(title, (FONT, 20))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(0.0..90.0, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc("torque reference (%)")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_desc(y_desc)
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 16))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;
    chart
        .draw_series(LineSeries::new(
            curve.iter().copied(),
            MODEL.stroke_width(2),
        ))?
        .label(model_label)
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], MODEL.stroke_width(2)));
    chart
        .draw_series(points.iter().map(|&p| Circle::new(p, 5, POINTS.filled())))?
        .label("steady-state points")
        .legend(|(x, y)| Circle::new((x + 10, y), 5, POINTS.filled()));
    legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
    Ok(())
}

/// Pressure and flow side by side: steady points and the model's curve, 5..85 %.
fn static_figure(
    path: &Path,
    title: &str,
    results: [(&TargetResult, &[(f64, f64)]); 2],
    model_label: &str,
) -> Drawn {
    let root = BitMapBackend::new(path, (1600, 650)).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(title, (FONT, 26))?;
    let panels = root.split_evenly((1, 2));
    for (area, (r, curve)) in panels.iter().zip(results) {
        let (y_desc, name) = axis(r);
        static_panel(
            area,
            &format!("{name}: steady state"),
            y_desc,
            &r.statics,
            curve,
            model_label,
        )?;
    }
    root.present()?;
    Ok(())
}

/// The figures [`figures`] writes.
pub const FIGURES: [&str; 4] = [
    "fig4_narmax_validation.png",
    "fig5_narmax_static.png",
    "fig7_whitebox_validation.png",
    "fig8_whitebox_static.png",
];

/// Writes fig4_narmax_validation.png, fig5_narmax_static.png, fig7_whitebox_validation.png
/// and fig8_whitebox_static.png ([`FIGURES`]) into `dir`.
pub fn figures(dir: &Path, p: &TargetResult, q: &TargetResult) -> Result<(), Failure> {
    font()?;
    let fail = |name: &str, e: Box<dyn Error>| Failure {
        code: 1,
        message: format!("cannot draw {}: {e}", dir.join(name).display()),
    };
    // Figures 0 and 2: free runs on the validation records; 1 and 3: static curves.
    let runs = [
        (
            0,
            "NARMAX models, free run on the validation records (cf. paper Fig. 4)",
            [(p, &p.narmax[..]), (q, &q.narmax[..])],
            "NARMAX free run",
        ),
        (
            2,
            "White-box model on the validation records (cf. paper Fig. 7)",
            [(p, &p.whitebox[..]), (q, &q.whitebox[..])],
            "white-box model",
        ),
    ];
    let curves = [
        (
            1,
            "NARMAX models, static curves (cf. paper Fig. 5)",
            [(p, &p.narmax_curve[..]), (q, &q.narmax_curve[..])],
            "NARMAX steady output",
        ),
        (
            3,
            "White-box model, static curves (cf. paper Fig. 8)",
            [(p, &p.whitebox_curve[..]), (q, &q.whitebox_curve[..])],
            "white-box steady state",
        ),
    ];
    for ((i, title, series, label), (j, c_title, c_series, c_label)) in runs.into_iter().zip(curves)
    {
        validation_figure(&dir.join(FIGURES[i]), title, series, label)
            .map_err(|e| fail(FIGURES[i], e))?;
        static_figure(&dir.join(FIGURES[j]), c_title, c_series, c_label)
            .map_err(|e| fail(FIGURES[j], e))?;
    }
    Ok(())
}

/// One panel of `observe`'s figure: the estimate, and the measurement and the truth when the
/// record has them (`None` in a series: no value at that point).
pub struct ObservePanel<'a> {
    /// Panel title.
    pub title: &'a str,
    /// Y axis, with its unit.
    pub y_desc: &'a str,
    /// The observer's estimate.
    pub estimate: &'a [f64],
    /// The measurement.
    pub measured: Option<&'a [Option<f64>]>,
    /// The truth.
    pub truth: Option<&'a [Option<f64>]>,
}

const TRUTH: RGBColor = RGBColor(31, 119, 180);
const ALARM: RGBColor = RGBColor(255, 170, 0);

/// The runs of consecutive finite values of `y` (as points at `t`).
fn runs(t: &[f64], y: &[Option<f64>]) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = vec![];
    let mut open = false;
    for (&t, v) in t.iter().zip(y) {
        match v {
            Some(v) if v.is_finite() => {
                if !open {
                    out.push(vec![]);
                    open = true;
                }
                if let Some(run) = out.last_mut() {
                    run.push((t, *v));
                }
            }
            _ => open = false,
        }
    }
    out
}

/// One panel: alarms shaded, then the measurement, the truth and the estimate.
fn observe_panel(area: &Area, t: &[f64], p: &ObservePanel, alarms: &[(f64, f64)]) -> Drawn {
    let measured = p.measured.map(|m| runs(t, m)).unwrap_or_default();
    let truth = p.truth.map(|m| runs(t, m)).unwrap_or_default();
    let (y0, y1) = span(
        p.estimate
            .iter()
            .chain(measured.iter().flatten().map(|q| &q.1))
            .chain(truth.iter().flatten().map(|q| &q.1)),
    );
    let (x0, x1) = (t[0], t[t.len() - 1].max(t[0] + 1e-9));
    let mut chart = ChartBuilder::on(area)
        .caption(p.title, (FONT, 20))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_desc(p.y_desc)
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 16))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;
    let shade = ALARM.mix(0.25).filled();
    let drawn = chart.draw_series(
        alarms
            .iter()
            .map(|&(a, b)| Rectangle::new([(a, y0), (b.max(a), y1)], shade)),
    )?;
    if !alarms.is_empty() {
        drawn.label("alarm (any bit)").legend(move |(x, y)| {
            Rectangle::new([(x, y - 6), (x + 20, y + 6)], ALARM.mix(0.4).filled())
        });
    }
    let mut lines = |runs: Vec<Vec<(f64, f64)>>, style: ShapeStyle, label: &str| -> Drawn {
        for (i, run) in runs.into_iter().enumerate() {
            let s = chart.draw_series(LineSeries::new(run, style))?;
            if i == 0 {
                s.label(label).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], style.stroke_width(2))
                });
            }
        }
        Ok(())
    };
    lines(measured, MEASURED.mix(0.6).stroke_width(1), "measurement")?;
    lines(truth, TRUTH.stroke_width(2), "truth")?;
    let estimate: Vec<Option<f64>> = p.estimate.iter().map(|&v| Some(v)).collect();
    lines(runs(t, &estimate), MODEL.stroke_width(1), "estimate")?;
    legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    Ok(())
}

/// `observe`'s figure (PNG at `path`, which must end in `.png`): the panels stacked over the
/// times `t`, alarms (from, to) shaded. The error is a one-line message without the path.
pub fn observe_figure(
    path: &Path,
    title: &str,
    t: &[f64],
    panels: &[ObservePanel],
    alarms: &[(f64, f64)],
) -> Result<(), String> {
    font().map_err(|f| f.message)?;
    let draw = || -> Drawn {
        let root =
            BitMapBackend::new(path, (1600, 300 * panels.len() as u32 + 60)).into_drawing_area();
        root.fill(&WHITE)?;
        let root = root.titled(title, (FONT, 24))?;
        for (area, p) in root.split_evenly((panels.len(), 1)).iter().zip(panels) {
            observe_panel(area, t, p, alarms)?;
        }
        root.present()?;
        Ok(())
    };
    draw().map_err(|e| e.to_string())
}
