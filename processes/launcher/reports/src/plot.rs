//! Pictures of a summary, written next to summary.json, each as SVG and PNG (the same drawing
//! code on both plotters backends; PNG text uses the embedded DejaVu Sans, so no system fonts
//! are needed):
//! - `curves`: mean learning curve of every method with a +-1 SEM band (paper Fig. 4, 6, 8);
//!   when the problem knows its optimum and round robin ran, curves are drawn relative to round
//!   robin with the optimum as a dashed line (Fig. 2); the best policy of all runs, when the
//!   summary names one, is a dashed line too, beside a zoom on the second half (Fig. 8). Curves
//!   hidden under an identical one say so in the legend.
//! - `selections`: for 1-D contexts, the context chosen in every episode of run 0 (Fig. 3);
//!   for 2-D contexts, every training context's share of the first episodes, on a log colour
//!   scale centred on the uniform share (Fig. 5).
//! - `selections-time`: per method, the share of selections of every training context in 50 bins
//!   of episodes, averaged over runs, on one colour scale (Fig. 3 and 5 over the whole run).
//! - `updates`: per method, the exploration (trace Sigma, log scale) and the effective sample
//!   size of every C-REPS update, every run a thin line and the median a thick one, so that the
//!   collapse of one run in twenty shows.
//! - for the dartboard, `board` (Fig. 10), and for the throwing problems `throw`, a side view of
//!   the initial throw.
//! - `bench`, from `acps bench`: rollouts/s of every mode per environment, ratio above each bar.

use acps_experiments::settings::LearnerName;
use acps_experiments::summary::Summary;
use acps_learner::SearchReport;
use acps_models::robot::Robot;
use acps_models::targets::Field;
use acps_models::trajectory::JointTrajectory;
use acps_shared::nearest;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::Path;

type PlotResult = Result<(), Box<dyn std::error::Error>>;

const COLORS: [RGBColor; 9] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(23, 190, 207),
];

/// A picture drawn once, on any plotters backend.
trait Picture {
    /// Width and height in pixels.
    fn size(&self) -> (u32, u32);
    /// Draw on `root`, which is already white.
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> PlotResult
    where
        DB::ErrorType: 'static;
}

/// Write `picture` to `path`, as SVG or PNG by the file's extension.
fn save_as(picture: &impl Picture, path: &Path) -> PlotResult {
    fn draw_on<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, picture: &impl Picture) -> PlotResult
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        picture.draw(&root)?;
        root.present()?;
        Ok(())
    }
    static FONT: std::sync::Once = std::sync::Once::new();
    FONT.call_once(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
            .unwrap_or_else(|_| unreachable!("the embedded DejaVu Sans parses"));
    });
    match path.extension().and_then(|e| e.to_str()) {
        Some("svg") => draw_on(SVGBackend::new(path, picture.size()).into_drawing_area(), picture),
        Some("png") => {
            let (width, height) = picture.size();
            let mut pixels = vec![0; 3 * width as usize * height as usize];
            draw_on(
                BitMapBackend::with_buffer(&mut pixels, (width, height)).into_drawing_area(),
                picture,
            )?;
            write_png(path, width, height, &pixels).map_err(|e| format!("{}: {e}", path.display()).into())
        }
        _ => Err(format!("{}: a picture's file name must end in .svg or .png", path.display()).into()),
    }
}

/// `pixels`, RGB row by row, as the PNG file `path`.
fn write_png(path: &Path, width: u32, height: u32, pixels: &[u8]) -> Result<(), Box<dyn std::error::Error>> {
    let file = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut encoder = png::Encoder::new(file, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    // As the image crate wrote them: each row's filter chosen by its result, which halves the
    // file of a picture of flat areas and lines against png's default.
    encoder.set_adaptive_filter(png::AdaptiveFilterType::Adaptive);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(pixels)?;
    writer.finish()?;
    Ok(())
}

/// Write `picture` to `dir/stem.svg` and `dir/stem.png`.
fn save(picture: &impl Picture, dir: &Path, stem: &str) -> PlotResult {
    for extension in ["svg", "png"] {
        save_as(picture, &dir.join(format!("{stem}.{extension}")))?;
    }
    Ok(())
}

/// The largest magnitude an axis reaches: beyond it values are clipped, so that an axis' width
/// stays finite (plotters 0.3.7 loops forever computing the ticks of an infinite range).
const LIMIT: f64 = 1e300;

/// The most decades a log axis spans below its highest value, so that a run collapsed to 1e-300
/// does not squash every other line into a sliver.
const DECADES: i32 = 40;

/// The lowest and highest finite value, clipped to +-[`LIMIT`]; `None` when none is finite.
fn extent(values: impl IntoIterator<Item = f64>) -> Option<(f64, f64)> {
    values
        .into_iter()
        .filter(|v| v.is_finite())
        .map(|v| v.clamp(-LIMIT, LIMIT))
        .fold(None, |range, v| match range {
            None => Some((v, v)),
            Some((lo, hi)) => Some((f64::min(lo, v), f64::max(hi, v))),
        })
}

/// A linear axis over the finite `values`, widened by `pad` times its width on both sides.
/// plotters needs low < high, so equal values get an axis around them, and none at all 0..1.
fn linear_range(values: impl IntoIterator<Item = f64>, pad: f64) -> Range<f64> {
    let Some((lo, hi)) = extent(values) else {
        return 0.0..1.0;
    };
    let magnitude = lo.abs().max(hi.abs());
    // Ticks need a width well above the values' rounding error.
    if hi - lo <= 1e-9 * magnitude {
        let half = if magnitude > 0.0 { 0.1 * magnitude } else { 1.0 };
        return (lo - half)..(hi + half);
    }
    let pad = pad * (hi - lo);
    (lo - pad)..(hi + pad)
}

/// An axis from 0 to `headroom` times the highest finite value, or 0..1 when none is positive.
fn from_zero(values: impl IntoIterator<Item = f64>, headroom: f64) -> Range<f64> {
    match extent(values) {
        Some((_, hi)) if hi > 0.0 => 0.0..headroom * hi,
        _ => 0.0..1.0,
    }
}

/// A log axis a factor 2 beyond the positive finite `values` (clipped to 1/[`LIMIT`]..[`LIMIT`]),
/// at most [`DECADES`] below the highest; a decade either side of equal values, 0.1..10 for none.
fn log_range(values: impl IntoIterator<Item = f64>) -> Range<f64> {
    let positive = values.into_iter().filter(|&v| v > 0.0).map(|v| v.max(1.0 / LIMIT));
    let Some((lo, hi)) = extent(positive) else {
        return 0.1..10.0;
    };
    let lo = lo.max(hi / 10f64.powi(DECADES));
    if lo == hi {
        (lo / 10.0)..(hi * 10.0)
    } else {
        (lo / 2.0)..(hi * 2.0)
    }
}

/// Where `value` is drawn on an axis of `range`: nowhere when it is not finite, and at most
/// `slack` axis widths outside it, as plotters rasterizes a line pixel by pixel even off the
/// picture (a point 1e300 away would take forever).
fn clip(value: f64, range: &Range<f64>, slack: f64) -> Option<f64> {
    let margin = slack * (range.end - range.start);
    value
        .is_finite()
        .then(|| value.clamp(range.start - margin, range.end + margin))
}

/// The runs of consecutive `Some` items, so that a value left out breaks a line instead of being
/// bridged.
fn pieces<T>(items: impl IntoIterator<Item = Option<T>>) -> Vec<Vec<T>> {
    let (mut pieces, mut current) = (Vec::new(), Vec::new());
    for item in items {
        match item {
            Some(item) => current.push(item),
            None if !current.is_empty() => pieces.push(std::mem::take(&mut current)),
            None => {}
        }
    }
    if !current.is_empty() {
        pieces.push(current);
    }
    pieces
}

/// What a picture left out, to print in it ("" when nothing): `count` `noun`(s) `verb`.
fn left_out(count: usize, noun: &str, verb: &str) -> String {
    match count {
        0 => String::new(),
        1 => format!("1 {noun} {verb}"),
        n => format!("{n} {noun}s {verb}"),
    }
}

/// The non-empty `notes`, separated by commas.
fn joined(notes: &[String]) -> String {
    let notes: Vec<&str> = notes.iter().map(String::as_str).filter(|n| !n.is_empty()).collect();
    notes.join(", ")
}

/// `text` followed by the non-empty `notes` in parentheses.
fn with_notes(text: String, notes: &[String]) -> String {
    match joined(notes) {
        notes if notes.is_empty() => text,
        notes => format!("{text} ({notes})"),
    }
}

/// Room right of a chart for the second half of its last x tick label ("10000" at the axis' end).
const TICK_ROOM: u32 = 30;

/// The scores' unit, when known: a problem file's, or cm for the paper's throws.
fn score_unit(summary: &Summary) -> Option<&str> {
    match &summary.user_problem {
        Some(user) => Some(user.unit.as_str()).filter(|unit| !unit.is_empty()),
        None if throws_at_targets(summary) => Some("cm"),
        None => None,
    }
}

/// Whether the training contexts are the paper's throwing targets: points on the ground, in m.
fn throws_at_targets(summary: &Summary) -> bool {
    acps_experiments::summary::scores_are_distances(&summary.experiment, summary.user_problem.as_ref())
}

/// What the recorded settings say about how the scores came about, for a title: the throws'
/// simulator, the context dimensions of Section 5.1.3 or the noise of Section 4's model (what
/// tells Fig. 6's and Fig. 2's panels apart), and C-CMA-ES when it learned instead of C-REPS.
fn setting_note(summary: &Summary) -> Option<String> {
    let note = experiment_note(summary);
    match LearnerName::recorded(&summary.settings) {
        LearnerName::CReps => note,
        LearnerName::CCmaes => Some(note.map_or("C-CMA-ES".into(), |note| format!("{note}, C-CMA-ES"))),
    }
}

/// What distinguishes the run among its experiment's: the simulator, n_s or the model's noise.
fn experiment_note(summary: &Summary) -> Option<String> {
    let settings = &summary.settings;
    if let Some(sim) = settings["sim"].as_str() {
        return Some(format!("{sim} simulator"));
    }
    if summary.experiment == "dims"
        && let Some(n_s) = settings["n_s"].as_u64()
    {
        return Some(format!("n_s = {n_s}"));
    }
    let model = &settings["model"];
    let (r, b) = (model["sigma_r"].as_f64()?, model["sigma_b"].as_f64()?);
    Some(format!("sigma_r {r}, sigma_b {b}"))
}

/// A number for a label: at most two decimals and no trailing zeros, or in powers of ten when
/// that would hide it.
fn compact(value: f64) -> String {
    // A tick at 0 may come out of plotters' arithmetic as 1e-16.
    if value.abs() < 1e-12 {
        return "0".to_string();
    }
    if !(1e-2..1e5).contains(&value.abs()) {
        return format!("{value:.1e}");
    }
    let text = format!("{value:.2}");
    text.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// A training context's label: its coordinates.
fn context_label(context: &[f64]) -> String {
    let coordinates: Vec<String> = context.iter().map(|&v| compact(v)).collect();
    match coordinates.as_slice() {
        [one] => one.clone(),
        _ => format!("({})", coordinates.join(", ")),
    }
}

/// Draw `text` centred at the top of `area`, broken into lines that fit its width, and return
/// the area below it.
fn titled<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    text: &str,
    size: f64,
) -> Result<DrawingArea<DB, Shift>, Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let style = ("sans-serif", size)
        .into_font()
        .color(&BLACK)
        .pos(Pos::new(HPos::Center, VPos::Top));
    let width = area.dim_in_pixel().0.saturating_sub(40);
    let mut lines: Vec<String> = Vec::new();
    for word in text.split(' ') {
        match lines.last_mut() {
            Some(line) if area.estimate_text_size(&format!("{line} {word}"), &style)?.0 <= width => {
                line.push(' ');
                line.push_str(word);
            }
            _ => lines.push(word.to_string()),
        }
    }
    let height = (1.3 * area.estimate_text_size("Ag", &style)?.1 as f64).ceil() as i32;
    let centre = area.dim_in_pixel().0 as i32 / 2;
    for (row, line) in lines.iter().enumerate() {
        area.draw_text(line, &style, (centre, 6 + row as i32 * height))?;
    }
    Ok(area.split_vertically(12 + lines.len() as i32 * height).1)
}

/// `full` faded towards white: `t` = 0 is white, 1 is `full` (clamped; NaN is white).
fn fade(full: RGBColor, t: f64) -> RGBColor {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let mix = |c: u8| (255.0 - t * (255.0 - f64::from(c))).round() as u8;
    RGBColor(mix(full.0), mix(full.1), mix(full.2))
}

/// Below and above a reference: blue for `t` < 0 and red for `t` > 0, white at 0.
fn diverging(t: f64) -> RGBColor {
    if t < 0.0 {
        fade(RGBColor(33, 102, 172), -t)
    } else {
        fade(RGBColor(178, 24, 43), t)
    }
}

/// The colour of a cell no episode went to, beside every colour of [`diverging`].
const NEVER: RGBColor = RGBColor(150, 150, 150);

/// A horizontal colour bar in `area`: the `colour` of every value of `range`, ticks labelled by
/// `tick`, `label` below; `extra` is a swatch left of the bar with its name (a colour outside
/// the scale).
fn colour_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    range: Range<f64>,
    colour: &dyn Fn(f64) -> RGBColor,
    tick: &dyn Fn(&f64) -> String,
    label: &str,
    extra: Option<(RGBColor, &str)>,
) -> PlotResult
where
    DB::ErrorType: 'static,
{
    let (width, height) = area.dim_in_pixel();
    let side = width / 5;
    let mut chart = ChartBuilder::on(area)
        .margin_left(side)
        .margin_right(side)
        .margin_top(8)
        .x_label_area_size(44)
        .build_cartesian_2d(range.clone(), 0.0..1.0)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .disable_y_axis()
        .label_style(("sans-serif", 12))
        .axis_desc_style(("sans-serif", 13))
        .x_labels(7)
        .x_label_formatter(tick)
        .x_desc(label)
        .draw()?;
    const STEPS: usize = 200;
    let at = |i: usize| range.start + (range.end - range.start) * i as f64 / STEPS as f64;
    chart.draw_series((0..STEPS).map(|i| {
        Rectangle::new(
            [(at(i), 0.0), (at(i + 1), 1.0)],
            colour((at(i) + at(i + 1)) / 2.0).filled(),
        )
    }))?;
    if let Some((swatch, name)) = extra {
        let (x, bottom) = (side as i32 - 70, height as i32 - 44);
        area.draw(&Rectangle::new([(x, 8), (x + 24, bottom)], swatch.filled()))?;
        let style = ("sans-serif", 12)
            .into_font()
            .color(&BLACK)
            .pos(Pos::new(HPos::Center, VPos::Top));
        area.draw_text(name, &style, (x + 12, bottom + 5))?;
    }
    Ok(())
}

/// Write every picture that fits the summary into `dir`.
pub fn write_all(summary: &Summary, dir: &Path) -> PlotResult {
    save(&LearningCurves(summary), dir, "curves")?;
    if let Some(picture) = Exploration::new(summary) {
        save(&picture, dir, "updates")?;
    }
    if let Some(picture) = SelectionsOverTime::new(summary) {
        save(&picture, dir, "selections-time")?;
    }
    // A problem file's problem may have any name: only the paper's throw at targets.
    let paper = summary.user_problem.is_none();
    if paper && matches!(summary.experiment.as_str(), "grid" | "dartboard") {
        let policy = acps_models::throw::ThrowPolicy::new(acps_models::throw::ThrowDesign::pa10(), 0.01)?;
        let view = ThrowSideView {
            robot: &Robot::pa10(),
            trajectory: &policy.trajectory(&[0.0; acps_models::throw::PARAMS])?,
            title: "throw of theta_0: arm every 0.1 s, ball after release",
        };
        save(&view, dir, "throw")?;
    }
    if paper && summary.experiment == "dartboard" {
        let fields = acps_models::environment::dartboard_fields();
        return save(
            &Dartboard {
                summary,
                fields: &fields,
            },
            dir,
            "board",
        );
    }
    match summary.training_contexts.first().map(Vec::len) {
        Some(2) => {
            if let Some(maps) = SelectionMaps::new(summary) {
                save(&maps, dir, "selections")?;
            }
        }
        Some(1) => save(&SelectionTraces::new(summary), dir, "selections")?,
        // The context index stands for a point of 3 or more dimensions (a problem file's).
        Some(_) if !paper => save(&SelectionTraces::new(summary), dir, "selections")?,
        _ => {}
    }
    Ok(())
}

/// Write `acps bench`'s rows to `dir/bench.svg` and `dir/bench.png`: one panel per
/// environment, a bar of rollouts/s per mode with its ratio written above it.
pub fn save_bench(rows: &[crate::bench::Row], dir: &Path) -> PlotResult {
    save(&BenchBars(rows), dir, "bench")
}

/// Write the side view of one throw to `path` (.svg or .png), titled `title`.
pub fn save_throw(robot: &Robot, trajectory: &JointTrajectory, title: &str, path: &Path) -> PlotResult {
    save_as(
        &ThrowSideView {
            robot,
            trajectory,
            title,
        },
        path,
    )
}

/// One curve: episodes, mean, SEM.
struct Curve {
    name: String,
    points: Vec<(f64, f64, f64)>,
}

fn curves(summary: &Summary) -> (Vec<Curve>, Option<f64>, String) {
    let reference = summary.j_opt_mean.and(summary.methods.get("round-robin"));
    let offset = |i: usize| reference.and_then(|rr| rr.mean[i]).unwrap_or(0.0);
    let curves = summary
        .methods
        .iter()
        .map(|(name, m)| Curve {
            name: name.clone(),
            points: (0..m.episodes.len())
                .filter_map(|i| Some((m.episodes[i] as f64, m.mean[i]? - offset(i), m.sem[i]?)))
                .collect(),
        })
        .collect();
    let optimum = reference.and(summary.j_opt_mean);
    let label = match (&reference, &summary.user_problem) {
        (Some(_), _) => "J - J_RR, J relative to round robin's".to_string(),
        (None, Some(user)) if !user.unit.is_empty() => format!("{} ({})", summary.metric, user.unit),
        (None, _) => summary.metric.clone(),
    };
    (curves, optimum, label)
}

/// For every curve, the name of the last curve drawn after it with the very same points, which
/// hides it (Section 4's two progress heuristics without noise).
fn hidden_under(curves: &[Curve]) -> Vec<Option<String>> {
    let same = |a: &[(f64, f64, f64)], b: &[(f64, f64, f64)]| {
        let bits = |p: &(f64, f64, f64)| [p.0.to_bits(), p.1.to_bits(), p.2.to_bits()];
        !a.is_empty() && a.len() == b.len() && a.iter().zip(b).all(|(p, q)| bits(p) == bits(q))
    };
    curves
        .iter()
        .enumerate()
        .map(|(i, curve)| {
            curves[i + 1..]
                .iter()
                .rev()
                .find(|later| same(&curve.points, &later.points))
                .map(|later| later.name.clone())
        })
        .collect()
}

/// Mean learning curves with SEM bands. With a best-policy line (the grid, Fig. 8) a second
/// panel, as in the paper, zooms on the second half of training, where the curves are within a
/// few cm of each other.
struct LearningCurves<'a>(&'a Summary);

impl LearningCurves<'_> {
    fn zoomed(&self) -> bool {
        self.0.best_policy.is_some()
    }
}

impl Picture for LearningCurves<'_> {
    fn size(&self) -> (u32, u32) {
        if self.zoomed() { (1400, 560) } else { (900, 560) }
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> PlotResult
    where
        DB::ErrorType: 'static,
    {
        let summary = self.0;
        let direction = match &summary.user_problem {
            Some(user) if user.lower_is_better => ", lower is better",
            Some(_) => ", higher is better",
            None => "",
        };
        let setting = setting_note(summary).map_or(String::new(), |s| format!(", {s}"));
        let caption = format!(
            "{}{setting}: mean ± SEM of {} runs per method{direction}",
            summary.experiment, summary.runs
        );
        if !self.zoomed() {
            return learning_curves(summary, root, 0.0, caption);
        }
        let (full, zoom) = root.split_horizontally(800);
        learning_curves(summary, &full, 0.0, caption)?;
        learning_curves(
            summary,
            &zoom,
            0.5,
            "the second half, zoomed (the lines of the left panel)".to_string(),
        )
    }
}

/// The legend's name of the SEM bands.
const SEM: &str = "shaded: ± 1 SEM";

/// The legend's name of Section 4's optimum.
const OPTIMUM: &str = "J_opt, the best J";

/// Draw the curves from `from` (a fraction of the episodes) on; the y range fits what is drawn,
/// the optimum included.
fn learning_curves<DB: DrawingBackend>(
    summary: &Summary,
    root: &DrawingArea<DB, Shift>,
    from: f64,
    caption: String,
) -> PlotResult
where
    DB::ErrorType: 'static,
{
    let (mut curves, optimum, y_label) = curves(summary);
    let hidden = hidden_under(&curves);
    let best = summary.best_policy.as_ref().map(|b| b.score);
    let x_max = curves
        .iter()
        .flat_map(|c| c.points.iter())
        .map(|p| p.0)
        .fold(1.0, f64::max);
    let x_min = from * x_max;
    for curve in &mut curves {
        curve.points.retain(|p| p.0 >= x_min);
    }
    // J_opt relative to round robin, at round robin's evaluations.
    let optimum_line: Vec<Option<(f64, f64)>> = match (summary.methods.get("round-robin"), optimum) {
        (Some(rr), Some(opt)) => rr
            .episodes
            .iter()
            .zip(&rr.mean)
            .filter(|(e, _)| **e as f64 >= x_min)
            .map(|(&e, m)| Some((e as f64, opt - (*m)?)))
            .collect(),
        _ => Vec::new(),
    };
    let y_range = linear_range(
        curves
            .iter()
            .flat_map(|c| c.points.iter())
            .flat_map(|&(_, m, s)| [m, m - s, m + s])
            .chain(best)
            .chain(optimum_line.iter().flatten().map(|p| p.1)),
        0.05,
    );
    let best_note = match best {
        Some(best) if !best.is_finite() => format!("best policy {best} not drawn"),
        _ => String::new(),
    };
    let area = titled(root, &with_notes(caption, &[best_note]), 20.0)?;
    let mut chart = ChartBuilder::on(&area)
        .margin(12)
        .margin_top(4)
        .margin_right(TICK_ROOM)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(x_min..x_max, y_range.clone())?;
    chart
        .configure_mesh()
        .x_desc("training episodes")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| compact(*y))
        .y_desc(short(&y_label))
        .draw()?;
    let y = |value: f64| clip(value, &y_range, 0.0);
    // Where the lines run, for the legend to keep clear of, and the legend's lines.
    let (mut drawn, mut labels): (Vec<(f64, f64)>, Vec<String>) = (Vec::new(), Vec::new());
    for ((index, curve), hidden) in curves.iter().enumerate().zip(&hidden) {
        let color = COLORS[index % COLORS.len()];
        // A mean that is not finite (ln 0 of a log-mean metric) breaks the line; a SEM that is
        // not finite leaves the band out there.
        let lines = pieces(
            curve
                .points
                .iter()
                .map(|&(x, m, s)| Some((x, y(m)?, s.is_finite().then_some(s)))),
        );
        let bands = lines.iter().flat_map(|line| {
            pieces(line.iter().map(|&(x, m, s)| Some((x, m, s?))))
                .into_iter()
                .map(|band| {
                    let upper = band.iter().map(|&(x, m, s)| (x, y(m + s).unwrap_or(m)));
                    let lower = band.iter().rev().map(|&(x, m, s)| (x, y(m - s).unwrap_or(m)));
                    Polygon::new(upper.chain(lower).collect::<Vec<_>>(), color.mix(0.15))
                })
        });
        chart.draw_series(bands)?;
        drawn.extend(lines.iter().flatten().flat_map(|&(x, m, s)| {
            let s = s.unwrap_or(0.0);
            [(x, m), (x, m - s), (x, m + s)]
        }));
        let means = curve.points.iter().filter(|p| !p.1.is_finite()).count();
        let sems = curve
            .points
            .iter()
            .filter(|p| p.1.is_finite() && !p.2.is_finite())
            .count();
        let label = with_notes(
            curve.name.clone(),
            &[
                left_out(means, "non-finite mean", "not drawn"),
                left_out(sems, "non-finite SEM", "not drawn"),
                hidden
                    .as_ref()
                    .map_or(String::new(), |other| format!("= {other}, under it")),
            ],
        );
        labels.push(label.clone());
        chart
            .draw_series(lines.iter().map(|line| {
                PathElement::new(
                    line.iter().map(|&(x, m, _)| (x, m)).collect::<Vec<_>>(),
                    color.stroke_width(2),
                )
            }))?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
        // A point between two left out is no line: a dot shows it.
        let dots = lines.iter().filter(|line| line.len() == 1);
        chart.draw_series(dots.map(|line| Circle::new((line[0].0, line[0].1), 3, color.filled())))?;
    }
    let dashed = |(x, y): (i32, i32)| DashedPathElement::new(vec![(x, y), (x + 20, y)], 4, 3, BLACK);
    if !optimum_line.is_empty() {
        let lines = pieces(
            optimum_line
                .iter()
                .map(|p| p.and_then(|(x, v)| Some((x, clip(v, &y_range, 1.0)?)))),
        );
        drawn.extend(lines.iter().flatten());
        labels.push(OPTIMUM.to_string());
        chart
            .draw_series(
                lines
                    .into_iter()
                    .map(|line| DashedPathElement::new(line, 6, 4, BLACK.stroke_width(1))),
            )?
            .label(OPTIMUM)
            .legend(dashed);
    }
    if let Some(best) = best.filter(|b| b.is_finite()) {
        let at = y(best).unwrap_or(best);
        drawn.extend((0..=20).map(|i| (x_min + (x_max - x_min) * f64::from(i) / 20.0, at)));
        let unit = score_unit(summary).map_or(String::new(), |unit| format!(" {unit}"));
        let label = format!("best policy ({best:.2}{unit})");
        labels.push(label.clone());
        chart
            .draw_series(DashedLineSeries::new(
                [(x_min, at), (x_max, at)],
                6,
                4,
                BLACK.stroke_width(1),
            ))?
            .label(label)
            .legend(dashed);
    }
    // A zoomed panel shares the full panel's legend.
    if from == 0.0 {
        chart
            .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?
            .label(SEM)
            .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], BLACK.mix(0.15).filled()));
        let font = ("sans-serif", 13).into_font();
        labels.push(SEM.to_string());
        let corner = legend_corner(&chart, &labels, &font, &drawn)?;
        chart
            .configure_series_labels()
            .label_font(font)
            .position(corner)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
    }
    Ok(())
}

/// The corner of `chart`'s plot where a legend of `labels` (in `font`) covers the fewest of
/// `drawn` (points of the lines), top right first on a tie.
fn legend_corner<DB: DrawingBackend>(
    chart: &ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    labels: &[String],
    font: &FontDesc,
    drawn: &[(f64, f64)],
) -> Result<SeriesLabelPosition, Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let mut text = MultiLineText::<_, &str>::new((0, 0), font.clone());
    for label in labels {
        text.push_line(label.as_str());
    }
    // As plotters lays the legend out: its margin of 10 around the text and 30 for the lines.
    let (w, h) = text.estimate_dimension()?;
    let (w, h) = (w + 30 + 20, h + 20);
    let area = chart.plotting_area();
    let (width, height) = area.dim_in_pixel();
    let (width, height) = (width as i32, height as i32);
    let (left, top) = (area.get_pixel_range().0.start, area.get_pixel_range().1.start);
    let pixels: Vec<(i32, i32)> = drawn
        .iter()
        .map(|p| {
            let (x, y) = area.map_coordinate(p);
            (x - left, y - top)
        })
        .collect();
    let covered = |&(x, y): &(i32, i32)| {
        pixels
            .iter()
            .filter(|p| (x..=x + w).contains(&p.0) && (y..=y + h).contains(&p.1))
            .count()
    };
    let corners = [
        (width - w - 10, 10),
        (10, 10),
        (width - w - 10, height - h - 10),
        (10, height - h - 10),
    ];
    let best = corners.iter().min_by_key(|c| covered(c)).copied().unwrap_or(corners[0]);
    Ok(SeriesLabelPosition::Coordinate(best.0, best.1))
}

/// The first words of a metric description, for an axis.
fn short(metric: &str) -> String {
    metric
        .split(" over ")
        .next()
        .unwrap_or(metric)
        .chars()
        .take(60)
        .collect()
}

/// Per method, every run's updates: (episode, trace Sigma, the right column's value).
type UpdateTraces = Vec<(String, Vec<Vec<(f64, f64, f64)>>)>;

/// What the right column of [`Exploration`] shows.
#[derive(Clone, Copy, PartialEq)]
enum Right {
    /// C-REPS' effective sample size, on a linear axis.
    Ess,
    /// C-CMA-ES' step size sigma, on a log axis (its ESS, mu_eff, is a constant).
    Sigma,
}

/// The exploration of every policy update and, for C-REPS, its effective sample size or, for
/// C-CMA-ES, its step size: a row per method, every run a thin line and the median over runs
/// (update by update) a thick one.
struct Exploration {
    caption: String,
    methods: UpdateTraces,
    right: Right,
}

impl Exploration {
    const ROW_HEIGHT: u32 = 190;

    /// `None` when no run made an update (problems without a policy).
    fn new(summary: &Summary) -> Option<Self> {
        let methods: UpdateTraces = summary
            .run_results
            .iter()
            .map(|(name, runs)| {
                let traces = runs
                    .iter()
                    .map(|run| {
                        run.updates
                            .iter()
                            .map(|u| {
                                let right = match &u.report {
                                    SearchReport::CReps(r) => r.ess,
                                    SearchReport::CCmaes(r) => r.sigma,
                                };
                                (u.episode as f64, u.report.trace_sigma(), right)
                            })
                            .collect()
                    })
                    .collect();
                (name.clone(), traces)
            })
            .collect();
        let any = methods.iter().flat_map(|(_, runs)| runs).any(|run| !run.is_empty());
        any.then(|| Self::of(summary, methods))
    }

    /// The picture of `methods`' updates.
    fn of(summary: &Summary, methods: UpdateTraces) -> Self {
        let (right, what) = match LearnerName::recorded(&summary.settings) {
            LearnerName::CCmaes => (Right::Sigma, "step size sigma after each C-CMA-ES generation"),
            LearnerName::CReps => (Right::Ess, "effective sample size after each C-REPS update"),
        };
        Self {
            caption: format!(
                "{}: exploration (trace Sigma) and {what}, {} runs (thin) and their median (thick)",
                summary.experiment, summary.runs
            ),
            methods,
            right,
        }
    }

    /// The median over runs of the k-th update's value, at the k-th update's mean episode.
    fn median(runs: &[Vec<(f64, f64, f64)>], value: fn(&(f64, f64, f64)) -> f64) -> Vec<(f64, f64)> {
        let updates = runs.iter().map(Vec::len).max().unwrap_or(0);
        (0..updates)
            .map(|k| {
                let at: Vec<_> = runs.iter().filter_map(|run| run.get(k)).collect();
                let mut values: Vec<f64> = at.iter().map(|u| value(u)).collect();
                values.sort_by(f64::total_cmp);
                let episode = at.iter().map(|u| u.0).sum::<f64>() / at.len() as f64;
                (episode, values[values.len() / 2])
            })
            .collect()
    }
}

impl Picture for Exploration {
    fn size(&self) -> (u32, u32) {
        // One or two methods get taller rows rather than a strip.
        let rows = (Self::ROW_HEIGHT * self.methods.len() as u32).max(2 * Self::ROW_HEIGHT + 60);
        (1100, 60 + rows)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> PlotResult
    where
        DB::ErrorType: 'static,
    {
        // A gap between the caption and the first method's name.
        let root = titled(root, &self.caption, 17.0)?.margin(8, 0, 0, 0);
        let all = || self.methods.iter().flat_map(|(_, runs)| runs.iter().flatten());
        let x_max = all().map(|u| u.0).fold(1.0, f64::max);
        let trace_range = log_range(all().map(|u| u.1));
        // A Sigma collapsed to 0, or far below the others, is drawn at the log axis' floor.
        // log10 on a linear axis: plotters' own log axis leaves every tick below 1e-16 unlabelled.
        let trace = |value: f64| Some(clip(value, &trace_range, 0.0)?.log10());
        let decades = trace_range.start.log10()..trace_range.end.log10();
        let (right_range, right_axis) = match self.right {
            Right::Ess => (from_zero(all().map(|u| u.2), 1.05), None),
            Right::Sigma => {
                let range = log_range(all().map(|u| u.2));
                let axis = range.start.log10()..range.end.log10();
                (range, Some(axis))
            }
        };
        let right = |value: f64| {
            let clipped = clip(value, &right_range, 0.0)?;
            Some(if right_axis.is_some() { clipped.log10() } else { clipped })
        };
        let (right_name, right_label): (&str, &dyn Fn(&f64) -> String) = match self.right {
            Right::Ess => ("effective sample size", &|y| format!("{y:.0}")),
            Right::Sigma => ("step size sigma", &|y| format!("{:.0e}", 10f64.powf(*y))),
        };
        let panels = root.split_evenly((self.methods.len(), 2));
        for (row, (name, runs)) in self.methods.iter().enumerate() {
            let color = COLORS[row % COLORS.len()];
            let last = row + 1 == self.methods.len();
            let mut chart = panel(&panels[2 * row], last).build_cartesian_2d(0.0..x_max, decades.clone())?;
            run_lines(
                &mut chart,
                runs,
                |u| u.1,
                &trace,
                ("trace Sigma", &|y| format!("{:.0e}", 10f64.powf(*y))),
                last,
                color,
            )?;
            label(&panels[2 * row], name)?;
            let traces = || runs.iter().flatten().map(|u| u.1);
            let floored = traces().filter(|&t| t.is_finite() && t < trace_range.start).count();
            note(
                &panels[2 * row],
                &[
                    left_out(
                        traces().filter(|t| !t.is_finite()).count(),
                        "non-finite value",
                        "not drawn",
                    ),
                    left_out(floored, "value", "drawn at the floor"),
                ],
            )?;
            let y_range = right_axis.clone().unwrap_or(right_range.clone());
            let mut chart = panel(&panels[2 * row + 1], last).build_cartesian_2d(0.0..x_max, y_range)?;
            run_lines(
                &mut chart,
                runs,
                |u| u.2,
                &right,
                (right_name, right_label),
                last,
                color,
            )?;
            let values = || runs.iter().flatten().map(|u| u.2);
            let floored = match right_axis {
                Some(_) => values().filter(|&v| v.is_finite() && v < right_range.start).count(),
                None => 0,
            };
            note(
                &panels[2 * row + 1],
                &[
                    left_out(
                        values().filter(|v| !v.is_finite()).count(),
                        "non-finite value",
                        "not drawn",
                    ),
                    left_out(floored, "value", "drawn at the floor"),
                ],
            )?;
        }
        Ok(())
    }
}

/// The axes of one panel of [`Exploration`] (`y`: the axis' name and label format), every run's
/// `value` as a thin line and their median as a thick one, each value drawn where `place` says, if
/// at all.
fn run_lines<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    runs: &[Vec<(f64, f64, f64)>],
    value: fn(&(f64, f64, f64)) -> f64,
    place: &dyn Fn(f64) -> Option<f64>,
    y: (&str, &dyn Fn(&f64) -> String),
    last: bool,
    color: RGBColor,
) -> PlotResult
where
    DB::ErrorType: 'static,
{
    chart
        .configure_mesh()
        .y_desc(y.0)
        .x_desc(if last { "training episodes" } else { "" })
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(y.1)
        .y_labels(5)
        .draw()?;
    let lines = |points: Vec<(f64, f64)>| pieces(points.into_iter().map(|(x, v)| Some((x, place(v)?))));
    let median = Exploration::median(runs, value);
    let thin = runs.iter().map(|run| {
        (
            run.iter().map(|u| (u.0, value(u))).collect(),
            ShapeStyle::from(color.mix(0.45)),
        )
    });
    for (points, style) in thin.chain([(median, color.stroke_width(2))]) {
        let lines = lines(points);
        // A point between two left out is no line: a dot shows it.
        let dots: Vec<_> = lines
            .iter()
            .filter(|line| line.len() == 1)
            .map(|line| line[0])
            .collect();
        chart.draw_series(lines.into_iter().map(|line| PathElement::new(line, style)))?;
        chart.draw_series(dots.into_iter().map(|dot| Circle::new(dot, 2, style.filled())))?;
    }
    Ok(())
}

/// What a panel left out, in its top right corner.
fn note<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, notes: &[String]) -> PlotResult
where
    DB::ErrorType: 'static,
{
    let style = ("sans-serif", 13)
        .into_font()
        .color(&COLORS[3])
        .pos(Pos::new(HPos::Right, VPos::Top));
    area.draw_text(&joined(notes), &style, (area.dim_in_pixel().0 as i32 - 18, 4))?;
    Ok(())
}

/// A chart builder for one small panel; only the bottom row has room for the x axis' name.
fn panel<'a, 'b, DB: DrawingBackend>(area: &'a DrawingArea<DB, Shift>, last: bool) -> ChartBuilder<'a, 'b, DB> {
    let mut builder = ChartBuilder::on(area);
    builder
        .margin_left(8)
        .margin_right(16)
        .margin_top(22)
        .x_label_area_size(if last { 40 } else { 22 })
        .y_label_area_size(70);
    builder
}

/// The method's name in the top left corner of its row.
fn label<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, name: &str) -> PlotResult
where
    DB::ErrorType: 'static,
{
    area.draw_text(name, &("sans-serif", 16).into_font().color(&BLACK), (80, 2))?;
    Ok(())
}

/// What the problem calls a training context, for titles.
fn context_noun(summary: &Summary) -> &'static str {
    if throws_at_targets(summary) {
        "target"
    } else {
        "context"
    }
}

/// The name of an axis of training contexts, labelled with their coordinates.
fn context_axis(summary: &Summary) -> &'static str {
    match summary.training_contexts.first().map(Vec::len) {
        _ if throws_at_targets(summary) => "target (x, y) in m",
        Some(1) if summary.experiment == "toy" && summary.user_problem.is_none() => "context",
        Some(1) => "context s",
        Some(2) => "context (s_1, s_2)",
        _ => "context (coordinates)",
    }
}

/// The training episodes every run of every method has; `None` without runs.
fn common_episodes(summary: &Summary) -> Option<usize> {
    summary
        .run_results
        .values()
        .flatten()
        .map(|run| run.episodes.len())
        .min()
}

/// Per method, `shares[context][bin]`: the share of the episodes of each of `bins` equal bins of
/// the first `episodes` (at least 1) training episodes that went to each training context,
/// averaged over runs. A context drawn from the continuous space counts for the nearest training
/// context, as the learner files it.
fn selection_shares(summary: &Summary, episodes: usize, bins: usize) -> Vec<(String, Vec<Vec<f64>>)> {
    let contexts = &summary.training_contexts;
    summary
        .run_results
        .iter()
        .map(|(name, runs)| {
            let mut shares = vec![vec![0.0; bins]; contexts.len()];
            for run in runs {
                for (t, episode) in run.episodes[..episodes].iter().enumerate() {
                    let arm = episode.arm.unwrap_or_else(|| nearest(contexts, &episode.context));
                    shares[arm][t * bins / episodes] += 1.0;
                }
            }
            for (bin, width) in (0..bins).map(|b| (b, bin_width(b, bins, episodes))) {
                for row in &mut shares {
                    row[bin] /= (width * runs.len()) as f64;
                }
            }
            (name.clone(), shares)
        })
        .collect()
}

/// The height of the colour bar under a picture of shares.
const BAR_HEIGHT: u32 = 90;

/// Room for a picture's title of up to two lines.
const TITLE_HEIGHT: u32 = 60;

/// Per method, the share of selections of every training context in bins of episodes,
/// averaged over runs, on one colour scale.
struct SelectionsOverTime {
    /// What the picture shows.
    title: String,
    /// The training contexts' labels, and the name of their axis.
    contexts: Vec<String>,
    axis: &'static str,
    /// Per method: its name and `shares[context][bin]`.
    methods: Vec<(String, Vec<Vec<f64>>)>,
    /// Episodes per run.
    episodes: usize,
}

impl SelectionsOverTime {
    const BINS: usize = 50;

    fn new(summary: &Summary) -> Option<Self> {
        let contexts = &summary.training_contexts;
        let episodes = common_episodes(summary)?;
        if episodes == 0 || contexts.is_empty() {
            return None;
        }
        let shares = selection_shares(summary, episodes, Self::BINS.min(episodes));
        Some(Self::of(summary, episodes, shares))
    }

    /// The picture of `methods`' shares in bins of the first `episodes` training episodes.
    fn of(summary: &Summary, episodes: usize, methods: Vec<(String, Vec<Vec<f64>>)>) -> Self {
        let bins = methods
            .iter()
            .flat_map(|(_, shares)| shares.first())
            .map(Vec::len)
            .max()
            .unwrap_or(1)
            .max(1);
        let (narrow, wide) = (episodes / bins, episodes.div_ceil(bins));
        let width = if narrow == wide {
            format!("{narrow}")
        } else {
            format!("{narrow}-{wide}")
        };
        Self {
            title: format!(
                "{}: share of each bin of {width} training episodes that went to each {}, mean over {} runs",
                summary.experiment,
                context_noun(summary),
                summary.runs
            ),
            contexts: summary.training_contexts.iter().map(|c| context_label(c)).collect(),
            axis: context_axis(summary),
            methods,
            episodes,
        }
    }

    /// Panels per row and rows.
    fn grid(&self) -> (usize, usize) {
        let columns = if self.methods.len() > 3 { 2 } else { 1 };
        (columns, self.methods.len().div_ceil(columns).max(1))
    }

    /// Pixels per context, so that a few contexts get rows a label fits and many still fit.
    fn row_height(&self) -> u32 {
        (300 / self.contexts.len().max(1) as u32).clamp(4, 12)
    }

    fn panel_height(&self) -> u32 {
        self.row_height() * self.contexts.len() as u32 + 100
    }
}

/// The number of episodes t in 0..episodes with t * bins / episodes == bin.
fn bin_width(bin: usize, bins: usize, episodes: usize) -> usize {
    let first = |b: usize| (b * episodes).div_ceil(bins);
    first(bin + 1) - first(bin)
}

impl Picture for SelectionsOverTime {
    fn size(&self) -> (u32, u32) {
        let (columns, rows) = self.grid();
        let width = if columns == 1 { 900 } else { 700 * columns as u32 };
        (width, TITLE_HEIGHT + self.panel_height() * rows as u32 + BAR_HEIGHT)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> PlotResult
    where
        DB::ErrorType: 'static,
    {
        let shares = || {
            self.methods
                .iter()
                .flat_map(|(_, shares)| shares.iter().flatten())
                .copied()
        };
        let most = shares().filter(|s| s.is_finite()).fold(0.0, f64::max);
        let level = |share: f64| if most > 0.0 { share / most } else { 0.0 };
        let unplaced = shares().filter(|s| !s.is_finite()).count();
        let (body, bar) = root.split_vertically(root.dim_in_pixel().1 - BAR_HEIGHT);
        let title = with_notes(
            self.title.clone(),
            &[left_out(unplaced, "non-finite share", "not drawn")],
        );
        let body = titled(&body, &title, 18.0)?;
        let contexts = self.contexts.len();
        // Every k-th context is labelled, so that the labels do not overlap; k is a step plotters
        // picks for its ticks.
        let every = [1, 2, 5, 10, 20, 50, 100]
            .into_iter()
            .find(|&k| k * self.row_height() >= 12)
            .unwrap_or(100) as usize;
        let label = |y: &f64| {
            let index = y.round();
            let labelled = (y - index).abs() < 1e-6 && index >= 0.0 && (index as usize).is_multiple_of(every);
            let text = labelled.then(|| self.contexts.get(index as usize)).flatten();
            text.cloned().unwrap_or_default()
        };
        let font = TextStyle::from(("sans-serif", 12).into_font());
        let widest = self
            .contexts
            .iter()
            .map(|c| root.estimate_text_size(c, &font).map(|size| size.0))
            .try_fold(0, |widest, width| width.map(|w| widest.max(w)))?;
        let (columns, rows) = self.grid();
        for ((name, shares), area) in self.methods.iter().zip(body.split_evenly((rows, columns))) {
            let bins = shares.first().map_or(1, Vec::len).max(1);
            let area = titled(&area, name, 15.0)?;
            let mut chart = ChartBuilder::on(&area)
                .margin_left(8)
                .margin_right(TICK_ROOM)
                .margin_bottom(6)
                .x_label_area_size(40)
                .y_label_area_size(widest + 34)
                .build_cartesian_2d(0.0..self.episodes as f64, -0.5..(contexts as f64 - 0.5))?;
            chart
                .configure_mesh()
                .disable_mesh()
                .x_desc("training episode")
                .y_desc(self.axis)
                .x_label_formatter(&|x| format!("{x:.0}"))
                .y_labels(contexts.div_ceil(every))
                .y_label_formatter(&label)
                .draw()?;
            let cells = shares.iter().enumerate().flat_map(|(context, row)| {
                row.iter()
                    .enumerate()
                    .filter(|(_, share)| share.is_finite())
                    .map(move |(bin, &share)| {
                        let x = |b: usize| (b * self.episodes).div_ceil(bins) as f64;
                        Rectangle::new(
                            [(x(bin), context as f64 - 0.5), (x(bin + 1), context as f64 + 0.5)],
                            fade(DARK, level(share)).filled(),
                        )
                    })
            });
            chart.draw_series(cells)?;
        }
        let uniform = 1.0 / contexts.max(1) as f64;
        colour_bar(
            &bar,
            0.0..most.max(uniform),
            &|share| fade(DARK, level(share)),
            &|share| compact(*share),
            // The darkest share is named: the bar's last tick is often below it.
            &format!(
                "share of a bin's episodes (uniform: 1/{contexts} = {}; darkest: {})",
                compact(uniform),
                compact(most.max(uniform))
            ),
            None,
        )
    }
}

/// The darkest colour of a share.
const DARK: RGBColor = RGBColor(8, 48, 107);

/// The context chosen in every episode of run 0, per method: its coordinate for 1-D contexts
/// (Fig. 3), its index for 3 or more dimensions.
struct SelectionTraces {
    title: String,
    /// The name of the y axis.
    axis: &'static str,
    /// Per method, the chosen context in every training episode of run 0.
    methods: Vec<(String, Vec<Option<f64>>)>,
}

impl SelectionTraces {
    fn new(summary: &Summary) -> Self {
        let contexts = &summary.training_contexts;
        let one = contexts.first().is_some_and(|c| c.len() == 1);
        let chosen = |episode: &acps_learner::learner::Episode| {
            if one {
                episode.context.first().copied()
            } else {
                Some(episode.arm.unwrap_or_else(|| nearest(contexts, &episode.context)) as f64)
            }
        };
        let methods = summary
            .run_results
            .iter()
            .map(|(name, runs)| {
                let episodes = runs.first().map_or(&[][..], |run| &run.episodes[..]);
                (name.clone(), episodes.iter().map(chosen).collect())
            })
            .collect();
        Self::of(summary, methods)
    }

    /// The picture of `methods`' choices.
    fn of(summary: &Summary, methods: Vec<(String, Vec<Option<f64>>)>) -> Self {
        let one = summary.training_contexts.first().is_some_and(|c| c.len() == 1);
        Self {
            title: format!(
                "{}: the context chosen in every training episode of run 0",
                summary.experiment
            ),
            axis: if one {
                context_axis(summary)
            } else {
                "training context (index)"
            },
            methods,
        }
    }
}

impl Picture for SelectionTraces {
    fn size(&self) -> (u32, u32) {
        // A PNG of height 0 is an error: a summary without methods still gets an empty picture.
        (900, TITLE_HEIGHT + 220 * self.methods.len().max(1) as u32)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> PlotResult
    where
        DB::ErrorType: 'static,
    {
        let chosen = || {
            self.methods
                .iter()
                .flat_map(|(_, chosen)| chosen.iter().flatten().copied())
        };
        let y_range = linear_range(chosen(), 0.05);
        let unplaced = chosen().filter(|c| !c.is_finite()).count();
        let title = with_notes(
            self.title.clone(),
            &[left_out(unplaced, "non-finite context", "not drawn")],
        );
        let body = titled(root, &title, 18.0)?;
        for ((name, chosen), area) in self.methods.iter().zip(body.split_evenly((self.methods.len(), 1))) {
            let episodes = chosen.len().max(1) as f64;
            let area = titled(&area, name, 15.0)?;
            let mut chart = ChartBuilder::on(&area)
                .margin_left(8)
                .margin_right(TICK_ROOM)
                .margin_bottom(6)
                .x_label_area_size(40)
                .y_label_area_size(60)
                .build_cartesian_2d(0.0..episodes, y_range.clone())?;
            chart
                .configure_mesh()
                .x_desc("training episode")
                .y_desc(self.axis)
                .x_label_formatter(&|x| format!("{x:.0}"))
                .y_label_formatter(&|y| compact(*y))
                .draw()?;
            let points = chosen
                .iter()
                .enumerate()
                .filter_map(|(t, c)| Some((t as f64, clip((*c)?, &y_range, 0.0)?)));
            chart.draw_series(points.map(|p| Circle::new(p, 1, COLORS[0].filled())))?;
        }
        Ok(())
    }
}

/// The share of the first episodes that went to every training context, per method (2-D
/// contexts, Fig. 5), relative to the uniform share on one log colour scale.
struct SelectionMaps {
    title: String,
    /// The names of the contexts' coordinates.
    axes: [&'static str; 2],
    contexts: Vec<Vec<f64>>,
    /// The episodes counted.
    window: usize,
    /// Per method, the share of the window's episodes that went to each context.
    methods: Vec<(String, Vec<f64>)>,
}

impl SelectionMaps {
    /// The side of a method's panel.
    const PANEL: u32 = 340;

    /// `None` without episodes.
    fn new(summary: &Summary) -> Option<Self> {
        let window = common_episodes(summary)?.min(summary.selection_window);
        if window == 0 {
            return None;
        }
        let methods = selection_shares(summary, window, 1)
            .into_iter()
            .map(|(name, shares)| (name, shares.into_iter().map(|row| row[0]).collect()))
            .collect();
        Some(Self::of(summary, window, methods))
    }

    /// The picture of `methods`' shares of the first `window` training episodes.
    fn of(summary: &Summary, window: usize, methods: Vec<(String, Vec<f64>)>) -> Self {
        Self {
            title: format!(
                "{}: share of the first {window} training episodes that went to each {}, mean over {} runs",
                summary.experiment,
                context_noun(summary),
                summary.runs
            ),
            axes: if throws_at_targets(summary) {
                ["target x (m)", "target y (m)"]
            } else {
                ["s_1", "s_2"]
            },
            contexts: summary.training_contexts.clone(),
            window,
            methods,
        }
    }

    /// Panels per row and rows.
    fn grid(&self) -> (usize, usize) {
        let columns = self.methods.len().clamp(1, 3);
        (columns, self.methods.len().div_ceil(columns).max(1))
    }

    /// The side of each panel: one method's fills the width that the colour bar needs.
    fn side(&self) -> u32 {
        (2 * Self::PANEL / self.grid().0 as u32).max(Self::PANEL)
    }
}

impl Picture for SelectionMaps {
    fn size(&self) -> (u32, u32) {
        let (columns, rows) = self.grid();
        (
            self.side() * columns as u32,
            TITLE_HEIGHT + self.side() * rows as u32 + BAR_HEIGHT,
        )
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> PlotResult
    where
        DB::ErrorType: 'static,
    {
        let contexts = &self.contexts;
        let uniform = 1.0 / contexts.len().max(1) as f64;
        // log2 of the share relative to the uniform one; a share of 0 has its own colour.
        let relative = |share: f64| (share > 0.0 && share.is_finite()).then(|| (share / uniform).log2());
        let (low, high) = extent(
            self.methods
                .iter()
                .flat_map(|(_, s)| s.iter().filter_map(|&s| relative(s))),
        )
        .unwrap_or((0.0, 0.0));
        // At least a factor 2 either side, so that a near-uniform share stays near white.
        let (low, high) = (low.clamp(-60.0, -1.0), high.clamp(1.0, 60.0));
        let colour = |v: f64| diverging(if v < 0.0 { v / -low } else { v / high });
        let (half_x, half_y) = half_spacing(contexts);
        let half = [half_x, half_y];
        let axis = |d: usize| linear_range(contexts.iter().flat_map(|c| [c[d] - half[d], c[d] + half[d]]), 0.0);
        let (x_range, y_range) = (axis(0), axis(1));
        let unplaced = contexts
            .iter()
            .filter(|c| !(c[0].is_finite() && c[1].is_finite()))
            .count();
        let (body, bar) = root.split_vertically(root.dim_in_pixel().1 - BAR_HEIGHT);
        let title = with_notes(
            self.title.clone(),
            &[left_out(unplaced, "non-finite context", "not drawn")],
        );
        let body = titled(&body, &title, 18.0)?;
        let (columns, rows) = self.grid();
        for ((name, shares), area) in self.methods.iter().zip(body.split_evenly((rows, columns))) {
            let area = titled(&area, name, 14.0)?;
            let mut chart = ChartBuilder::on(&area)
                .margin_left(6)
                .margin_right(18)
                .margin_bottom(6)
                .x_label_area_size(40)
                .y_label_area_size(56)
                .build_cartesian_2d(x_range.clone(), y_range.clone())?;
            chart
                .configure_mesh()
                .disable_mesh()
                .x_desc(self.axes[0])
                .y_desc(self.axes[1])
                .x_label_formatter(&|x| compact(*x))
                .y_label_formatter(&|y| compact(*y))
                .x_labels(6)
                .y_labels(6)
                .draw()?;
            let squares = contexts.iter().zip(shares).filter_map(|(c, &share)| {
                let fill = match relative(share) {
                    Some(v) => colour(v),
                    None if share == 0.0 => NEVER,
                    None => return None,
                };
                let x = |v: f64| clip(v, &x_range, 0.0);
                let y = |v: f64| clip(v, &y_range, 0.0);
                let corners = [
                    (x(c[0] - half_x)?, y(c[1] - half_y)?),
                    (x(c[0] + half_x)?, y(c[1] + half_y)?),
                ];
                Some((corners, fill))
            });
            // An outline shows the cells as white as the background (uniform shares).
            for (corners, fill) in squares {
                chart.draw_series([
                    Rectangle::new(corners, fill.filled()),
                    Rectangle::new(corners, RGBColor(200, 200, 200)),
                ])?;
            }
        }
        colour_bar(
            &bar,
            low..high,
            &colour,
            &|v| compact(uniform * v.exp2()),
            &format!(
                "share of the first {} episodes, log scale (white: uniform, 1/{} = {})",
                self.window,
                contexts.len(),
                compact(uniform)
            ),
            // The swatch of contexts no episode went to, when there are any.
            self.methods
                .iter()
                .any(|(_, shares)| shares.contains(&0.0))
                .then_some((NEVER, "none")),
        )
    }
}

/// Half the width and height of each context's cell: on a grid, half the spacing along each
/// axis, so that a grid whose axes are spaced differently is tiled without gaps; else (scattered
/// contexts) half the smallest distance between two contexts, a square.
fn half_spacing(contexts: &[Vec<f64>]) -> (f64, f64) {
    let (mut nearest, mut along) = (f64::MAX, [f64::MAX; 2]);
    for (i, a) in contexts.iter().enumerate() {
        for b in &contexts[i + 1..] {
            let (dx, dy) = ((a[0] - b[0]).abs(), (a[1] - b[1]).abs());
            let d = dx.hypot(dy);
            if d > 1e-12 {
                nearest = nearest.min(d);
            }
            // Neighbours in a row or a column of a grid.
            if dy <= 1e-12 && dx > 1e-12 {
                along[0] = along[0].min(dx);
            }
            if dx <= 1e-12 && dy > 1e-12 {
                along[1] = along[1].min(dy);
            }
        }
    }
    let square = if nearest == f64::MAX { 0.1 } else { nearest / 2.0 };
    match along {
        [x, y] if x < f64::MAX && y < f64::MAX => (x / 2.0, y / 2.0),
        _ => (square, square),
    }
}

/// The dartboard with every field, its target and where run 0's final policy lands (paper
/// Fig. 10 left), next to the average number of selections per field of every ring over the
/// first episodes (Fig. 10 right).
struct Dartboard<'a> {
    summary: &'a Summary,
    fields: &'a [Field],
}

impl Picture for Dartboard<'_> {
    fn size(&self) -> (u32, u32) {
        (1200, 600 * self.summary.methods.len().max(1) as u32)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> PlotResult
    where
        DB::ErrorType: 'static,
    {
        let (summary, fields) = (self.summary, self.fields);
        let methods: Vec<_> = summary.methods.iter().collect();
        let bull = fields[0].centre;
        let reach = 0.75;
        for ((name, m), row) in methods.iter().zip(root.split_evenly((methods.len(), 1))) {
            let (left, right) = row.split_horizontally(600);
            let left = titled(
                &left,
                &format!("{name}: the field centres (blue) and where run 0's final policy lands (red)"),
                15.0,
            )?;
            let mut board = ChartBuilder::on(&left)
                .margin(10)
                .margin_right(TICK_ROOM)
                .x_label_area_size(40)
                .y_label_area_size(55)
                .build_cartesian_2d(
                    (bull[0] - reach)..(bull[0] + reach),
                    (bull[1] - reach)..(bull[1] + reach),
                )?;
            board
                .configure_mesh()
                .disable_mesh()
                .x_desc("x (m)")
                .y_desc("y (m)")
                .draw()?;
            for field in fields {
                let mut outline: Vec<(f64, f64)> = field.field.iter().map(|p| (p[0], p[1])).collect();
                outline.push(outline[0]);
                board.draw_series(std::iter::once(PathElement::new(outline, BLACK.mix(0.4))))?;
            }
            let landings: Vec<Option<[f64; 2]>> = m
                .detail
                .get("landings_run0")
                .and_then(|v| serde_json::from_value(v.clone()).ok())
                .unwrap_or_default();
            for (field, landing) in fields.iter().zip(&landings) {
                let centre = (field.centre[0], field.centre[1]);
                board.draw_series(std::iter::once(Circle::new(centre, 3, COLORS[0].filled())))?;
                if let Some(l) = landing {
                    board.draw_series(std::iter::once(PathElement::new(vec![centre, (l[0], l[1])], COLORS[3])))?;
                    board.draw_series(std::iter::once(Rectangle::new(
                        [(l[0] - 0.006, l[1] - 0.006), (l[0] + 0.006, l[1] + 0.006)],
                        COLORS[3].filled(),
                    )))?;
                }
            }
            let curves: BTreeMap<String, Vec<f64>> = m
                .detail
                .get("selections_per_field")
                .and_then(|s| serde_json::from_value(s["cumulative"].clone()).ok())
                .unwrap_or_default();
            let longest = curves.values().map(Vec::len).max().unwrap_or(0);
            let y_range = from_zero(curves.values().flatten().copied().chain([1.0]), 1.05);
            let right = titled(
                &right,
                &format!(
                    "selections per field of each ring in the first {} training episodes (cumulative), mean over the ring's fields and {} run{}",
                    100 * longest,
                    summary.runs,
                    if summary.runs == 1 { "" } else { "s" }
                ),
                15.0,
            )?;
            let mut chart = ChartBuilder::on(&right)
                .margin(10)
                .margin_right(TICK_ROOM)
                .x_label_area_size(40)
                .y_label_area_size(55)
                .build_cartesian_2d(0.0..(100.0 * longest.max(1) as f64), y_range.clone())?;
            chart
                .configure_mesh()
                .x_desc("training episodes")
                .y_desc("selections per field")
                .x_label_formatter(&|x| format!("{x:.0}"))
                .y_label_formatter(&|y| compact(*y))
                .draw()?;
            for (index, (category, values)) in curves.iter().enumerate() {
                let color = COLORS[index % COLORS.len()];
                chart
                    .draw_series(LineSeries::new(
                        values
                            .iter()
                            .enumerate()
                            .filter_map(|(i, &v)| Some((100.0 * (i + 1) as f64, clip(v, &y_range, 0.0)?))),
                        color.stroke_width(2),
                    ))?
                    .label(category.clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()?;
        }
        Ok(())
    }
}

/// A side view of one throw: the arm every 0.1 s until the release, then the ball's flight,
/// projected on the vertical plane through the base and the landing point.
struct ThrowSideView<'a> {
    robot: &'a Robot,
    trajectory: &'a JointTrajectory,
    title: &'a str,
}

impl Picture for ThrowSideView<'_> {
    fn size(&self) -> (u32, u32) {
        (1000, 420)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> PlotResult
    where
        DB::ErrorType: 'static,
    {
        let (robot, trajectory) = (self.robot, self.trajectory);
        let (q, qd) = trajectory.last().ok_or("empty trajectory")?;
        let (release, velocity) = robot.ball_state(q, qd);
        let landing = robot.landing(&release, &velocity).ok_or("the ball does not land")?;
        let norm = (landing[0].powi(2) + landing[1].powi(2)).sqrt().max(1e-9);
        let along = |x: f64, y: f64| (x * landing[0] + y * landing[1]) / norm;
        let area = titled(root, self.title, 16.0)?;
        let mut chart = ChartBuilder::on(&area)
            .margin(12)
            .margin_right(TICK_ROOM)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(linear_range([-1.0, norm + 0.3], 0.0), 0.0..2.2)?;
        chart
            .configure_mesh()
            .x_desc("distance towards the landing point (m)")
            .y_desc("height (m)")
            .draw()?;
        let every = ((0.1 / trajectory.dt).round() as usize).max(1);
        let samples: Vec<usize> = (0..trajectory.len())
            .step_by(every)
            .chain(std::iter::once(trajectory.len() - 1))
            .collect();
        for (k, &i) in samples.iter().enumerate() {
            let frames = robot.frames(&trajectory.positions[i]);
            let points: Vec<(f64, f64)> = std::iter::once((0.0, 0.0))
                .chain(
                    frames
                        .iter()
                        .map(|f| (along(f.translation.x, f.translation.y), f.translation.z)),
                )
                .collect();
            let shade = COLORS[0].mix(0.25 + 0.75 * k as f64 / samples.len() as f64);
            let arm = chart.draw_series(std::iter::once(PathElement::new(points, shade.stroke_width(2))))?;
            if k + 1 == samples.len() {
                arm.label("the arm every 0.1 s up to the release (paler: earlier)")
                    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], COLORS[0].stroke_width(2)));
            }
        }
        let flight_time = ((velocity.z
            + (velocity.z.powi(2) + 2.0 * robot.gravity * (release.z - robot.ball.radius)).sqrt())
            / robot.gravity)
            .max(0.0);
        let ball: Vec<(f64, f64)> = (0..=100)
            .map(|i| {
                let t = flight_time * i as f64 / 100.0;
                let p = release + velocity * t;
                (along(p.x, p.y), p.z - 0.5 * robot.gravity * t * t)
            })
            .collect();
        chart
            .draw_series(LineSeries::new(ball, COLORS[3].stroke_width(2)))?
            .label("the ball after the release, to its landing point")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], COLORS[3].stroke_width(2)));
        chart.draw_series(std::iter::once(Circle::new(
            (norm, robot.ball.radius),
            5,
            COLORS[3].filled(),
        )))?;
        // Below the ball's arc, right of the arm.
        chart
            .configure_series_labels()
            .label_font(("sans-serif", 13))
            .position(SeriesLabelPosition::LowerMiddle)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
        Ok(())
    }
}

/// A bar's ratio, with its range over rounds when there were several.
fn ratio_label(row: &crate::bench::Row) -> String {
    match row.ratio_range() {
        Some((lowest, highest)) if lowest < highest => format!("{:.2} ({lowest:.2}-{highest:.2})", row.ratio),
        _ => format!("{:.2}", row.ratio),
    }
}

/// A rate for an axis, in thousands (k) or millions (M) of rollouts per second where large.
fn rate(value: f64) -> String {
    match value.abs() {
        v if v >= 1e6 => format!("{} M", compact(value / 1e6)),
        v if v >= 1e3 => format!("{} k", compact(value / 1e3)),
        _ => compact(value),
    }
}

/// `acps bench`'s rows as bars.
struct BenchBars<'a>(&'a [crate::bench::Row]);

impl BenchBars<'_> {
    fn environments(&self) -> Vec<&'static str> {
        let mut environments: Vec<&'static str> = Vec::new();
        for row in self.0 {
            if !environments.contains(&row.env) {
                environments.push(row.env);
            }
        }
        environments
    }
}

impl Picture for BenchBars<'_> {
    fn size(&self) -> (u32, u32) {
        (900, 260 * self.environments().len().max(1) as u32)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> PlotResult
    where
        DB::ErrorType: 'static,
    {
        let environments = self.environments();
        for (env, area) in environments.iter().zip(root.split_evenly((environments.len(), 1))) {
            let bars: Vec<_> = self.0.iter().filter(|row| row.env == *env).collect();
            let labels: Vec<String> = bars
                .iter()
                .map(|row| match row.mode {
                    "inprocess-1" => "in-process, 1 thread".to_string(),
                    "inprocess-rayon" => format!("in-process, rayon {}", row.workers),
                    mode if row.workers == 1 => format!("{mode}, 1 worker"),
                    mode => format!("{mode}, {} workers", row.workers),
                })
                .collect();
            let y_range = from_zero(bars.iter().map(|row| row.rollouts_per_s).chain([1.0]), 1.2);
            let top = y_range.end;
            // A rate that is not finite (a round timed at 0 s) is drawn as no bar.
            let height = |row: &crate::bench::Row| clip(row.rollouts_per_s, &y_range, 0.0).unwrap_or(0.0);
            let unmeasured = bars.iter().filter(|row| !row.rollouts_per_s.is_finite()).count();
            let caption = with_notes(
                format!(
                    "{env}: rollouts per second of the median round; above each bar its ratio to W x one thread{} and the range over rounds",
                    if bars.iter().any(|row| row.mode == "relay") {
                        " (a relay's: to the fleet of W)"
                    } else {
                        ""
                    }
                ),
                &[left_out(unmeasured, "non-finite rate", "not drawn")],
            );
            let area = titled(&area, &caption, 16.0)?;
            let mut chart = ChartBuilder::on(&area)
                .margin(8)
                .x_label_area_size(30)
                .y_label_area_size(75)
                .build_cartesian_2d((0..bars.len().saturating_sub(1)).into_segmented(), 0.0..top)?;
            chart
                .configure_mesh()
                .disable_x_mesh()
                .y_max_light_lines(0)
                .x_label_formatter(&|x| match x {
                    SegmentValue::CenterOf(i) => labels.get(*i).cloned().unwrap_or_default(),
                    _ => String::new(),
                })
                .y_label_formatter(&|y| rate(*y))
                .y_desc("rollouts per second")
                .draw()?;
            chart.draw_series(bars.iter().enumerate().map(|(i, row)| {
                let color = match row.mode {
                    "fleet" => COLORS[1],
                    "relay" => COLORS[2],
                    _ => COLORS[0],
                };
                let mut bar = Rectangle::new(
                    [(SegmentValue::Exact(i), 0.0), (SegmentValue::Exact(i + 1), height(row))],
                    color.filled(),
                );
                bar.set_margin(0, 0, 20, 20);
                bar
            }))?;
            chart.draw_series(bars.iter().enumerate().map(|(i, row)| {
                Text::new(
                    ratio_label(row),
                    (SegmentValue::CenterOf(i), height(row) + 0.02 * top),
                    TextStyle::from(("sans-serif", 13).into_font()).pos(Pos::new(HPos::Center, VPos::Bottom)),
                )
            }))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use acps_experiments::summary::{BestPolicy, MethodSummary, UserProblem};
    use std::path::PathBuf;
    use std::sync::mpsc::{RecvTimeoutError, channel};
    use std::time::Duration;

    const INF: f64 = f64::INFINITY;
    const NAN: f64 = f64::NAN;

    /// Series a user's simulator and reward can produce, each named for the failure messages.
    const HOSTILE: [(&str, &[f64]); 13] = [
        ("minus-inf", &[-1.0, -INF, -2.0, -INF]),
        ("plus-inf", &[1.0, INF, 2.0]),
        ("nan", &[NAN, 1.0, NAN, 2.0]),
        ("only-non-finite", &[NAN, -INF, INF]),
        ("equal", &[3.0, 3.0, 3.0]),
        ("equal-huge", &[1e20, 1e20]),
        ("zeros", &[0.0, 0.0, 0.0]),
        ("negative", &[-1.0, -5.0, 0.0]),
        ("tiny-and-huge", &[1e-300, 1e300, 1.0]),
        ("extremes", &[-f64::MAX, f64::MAX, f64::MIN_POSITIVE, 5e-324]),
        ("collapse", &[1e2, 1e-30, 1e-200, 1e-320, 0.0]),
        ("single", &[5.0]),
        ("empty", &[]),
    ];

    /// A test's directory of pictures, removed when the test ends.
    struct Scratch(PathBuf);

    impl std::ops::Deref for Scratch {
        type Target = PathBuf;

        fn deref(&self) -> &PathBuf {
            &self.0
        }
    }

    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    /// A fresh directory for one test's pictures.
    fn dir(test: &str) -> Scratch {
        let dir = std::env::temp_dir().join(format!("acps-plot-{test}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
        Scratch(dir)
    }

    /// Run `draw` on a thread and fail when it errs, panics or is still drawing after 60 s (a
    /// hang detector: plotters loops forever on some axis ranges).
    fn within_a_minute(case: &str, draw: impl FnOnce() -> PlotResult + Send + 'static) {
        let (sender, receiver) = channel();
        std::thread::spawn(move || sender.send(draw().map_err(|e| e.to_string())));
        match receiver.recv_timeout(Duration::from_secs(60)) {
            Ok(result) => result.unwrap_or_else(|e| panic!("{case}: {e}")),
            Err(RecvTimeoutError::Timeout) => panic!("{case}: still drawing after 60 s"),
            Err(RecvTimeoutError::Disconnected) => panic!("{case}: drawing panicked"),
        }
    }

    /// The SVG `dir/stem.svg`, after checking that its PNG twin was written too.
    fn drawn(dir: &Path, stem: &str) -> String {
        let png = std::fs::metadata(dir.join(format!("{stem}.png"))).map_or(0, |m| m.len());
        assert!(png > 0, "{stem}.png not written");
        std::fs::read_to_string(dir.join(format!("{stem}.svg"))).unwrap_or_else(|e| panic!("{stem}.svg: {e}"))
    }

    fn method(values: &[f64], sem: f64, selections: Vec<Option<usize>>) -> MethodSummary {
        let n = values.len();
        MethodSummary {
            episodes: (0..n as u64).map(|i| 100 * i).collect(),
            mean: values.iter().map(|&v| Some(v)).collect(),
            sem: vec![Some(sem); n],
            final_mean: values.last().copied(),
            final_sem: Some(sem),
            final_scores: vec![values.last().copied()],
            longest_stay: vec![1],
            selections_run0: selections,
            selection_ratio: values.to_vec(),
            updates: 0,
            rejected_updates: 0,
            failed_episodes: 0,
            evaluation_rollouts: 0,
            failed_evaluation_rollouts: 0,
            detail: serde_json::Map::new(),
        }
    }

    /// A problem file's summary whose curves (and selection ratios) are `values`; with an
    /// optimum, round robin is the reference and the best policy scores `values[0]`.
    fn summary(values: &[f64], contexts: Vec<Vec<f64>>, optimum: Option<f64>) -> Summary {
        let selections = (0..values.len()).map(|t| Some(t % contexts.len().max(1))).collect();
        let methods = [
            ("round-robin", method(values, 0.5, selections)),
            ("nan-sem", method(values, NAN, vec![None, Some(0)])),
            ("empty", method(&[], 0.0, Vec::new())),
        ];
        Summary {
            experiment: "function".to_string(),
            metric: "log-mean reward over contexts".to_string(),
            user_problem: Some(UserProblem {
                unit: "m".to_string(),
                lower_is_better: false,
            }),
            runs: 2,
            base_seed: 0,
            training_episodes: 100 * values.len() as u64,
            in_flight: 1,
            selection_window: 10,
            training_contexts: contexts,
            j_opt_mean: optimum,
            settings: serde_json::Value::Null,
            best_policy: optimum.and(values.first()).map(|&score| BestPolicy {
                score,
                method: "round-robin".to_string(),
                run: 0,
                seed: 0,
                episode: 0,
            }),
            methods: methods.into_iter().map(|(name, m)| (name.to_string(), m)).collect(),
            run_results: BTreeMap::new(),
        }
    }

    #[test]
    fn axis_ranges_are_finite_ordered_and_bounded() {
        for (case, values) in HOSTILE {
            for range in [
                linear_range(values.iter().copied(), 0.05),
                from_zero(values.iter().copied(), 1.2),
            ] {
                assert!(range.start.is_finite() && range.end.is_finite(), "{case}: {range:?}");
                assert!(
                    (range.end - range.start).is_finite(),
                    "{case}: {range:?} is infinitely wide"
                );
                assert!(range.start < range.end, "{case}: {range:?}");
            }
            let log = log_range(values.iter().copied());
            assert!(
                0.0 < log.start && log.start < log.end && log.end.is_finite(),
                "{case}: {log:?}"
            );
            let decades = (log.end / log.start).log10();
            assert!(
                decades <= f64::from(DECADES) + 1.0,
                "{case}: {log:?} spans {decades} decades"
            );
        }
        // Equal values stay inside their axis; a constant huge value still has ticks apart.
        let equal = linear_range([1e20, 1e20], 0.05);
        assert!(equal.start < 1e20 && 1e20 < equal.end, "{equal:?}");
        assert_eq!(linear_range([-INF, 2.0, 4.0, NAN], 0.0), 2.0..4.0);
    }

    #[test]
    fn pieces_break_at_left_out_values() {
        let split = pieces([Some(1), None, None, Some(2), Some(3), None]);
        assert_eq!(split, vec![vec![1], vec![2, 3]]);
        assert!(pieces::<i32>([None, None]).is_empty());
    }

    #[test]
    fn curves_of_hostile_scores_are_drawn_and_say_what_they_left_out() {
        let dir = dir("curves");
        for (case, values) in HOSTILE {
            for optimum in [None, Some(10.0), Some(-INF)] {
                let (dir, stem) = (dir.clone(), format!("{case}-{optimum:?}"));
                let summary = summary(values, vec![vec![0.0]], optimum);
                within_a_minute(&stem.clone(), move || save(&LearningCurves(&summary), &dir, &stem));
            }
        }
        let svg = drawn(&dir, "minus-inf-None");
        assert!(svg.contains("round-robin (2 non-finite means not drawn)"), "{svg}");
        assert!(svg.contains("nan-sem (2 non-finite means not drawn, 2 non-finite SEMs not drawn)"));
        let svg = words(&drawn(&dir, "only-non-finite-Some(10.0)"));
        assert!(svg.contains("best policy NaN not drawn"), "{svg}");
    }

    #[test]
    fn exploration_of_hostile_updates_is_drawn_and_says_what_it_left_out() {
        let dir = dir("updates");
        for (case, values) in HOSTILE {
            let run = |scale: f64| -> Vec<(f64, f64, f64)> {
                values
                    .iter()
                    .enumerate()
                    .map(|(i, &v)| (100.0 * i as f64, v * scale, v))
                    .collect()
            };
            // C-REPS' effective sample sizes, and C-CMA-ES' step sizes on a log axis.
            for (right, name) in [(Right::Ess, case.to_string()), (Right::Sigma, format!("{case}-sigma"))] {
                let picture = Exploration {
                    caption: name.clone(),
                    methods: vec![
                        ("a".to_string(), vec![run(1.0), run(2.0), Vec::new()]),
                        ("b".to_string(), vec![run(-1.0)]),
                    ],
                    right,
                };
                let dir = dir.clone();
                within_a_minute(&name.clone(), move || save(&picture, &dir, &name));
            }
        }
        let svg = drawn(&dir, "collapse");
        // Zeros, 5e-324 and 1e-200 are more than 40 decades below 100.
        assert!(svg.contains("6 values drawn at the floor"), "{svg}");
        let svg = drawn(&dir, "plus-inf");
        assert!(svg.contains("2 non-finite values not drawn"), "{svg}");
        // On the step size's log axis too.
        let svg = drawn(&dir, "collapse-sigma");
        assert_eq!(svg.matches("values drawn at the floor").count(), 4, "{svg}");
    }

    #[test]
    fn a_grid_s_cells_tile_it_and_scattered_contexts_get_squares() {
        let grid: Vec<Vec<f64>> = [0.3, 0.5, 0.7]
            .iter()
            .flat_map(|&x| [-0.2, 0.2].map(|y| vec![x, y]))
            .collect();
        let (hx, hy) = half_spacing(&grid);
        assert!((hx - 0.1).abs() < 1e-12 && (hy - 0.2).abs() < 1e-12, "{hx} {hy}");
        let scattered = [vec![0.0, 0.0], vec![3.0, 4.0], vec![10.0, 1.0]];
        assert_eq!(half_spacing(&scattered), (2.5, 2.5));
    }

    #[test]
    fn selections_of_hostile_data_are_drawn() {
        let dir = dir("selections");
        let contexts: [(&str, Vec<Vec<f64>>); 5] = [
            ("one", vec![vec![0.0, 0.0]]),
            ("equal", vec![vec![1.0, 1.0], vec![1.0, 1.0]]),
            ("huge", vec![vec![-1e300, 1e-300], vec![1e300, 1e300]]),
            ("extremes", vec![vec![-f64::MAX, 0.0], vec![f64::MAX, 1.0]]),
            ("non-finite", vec![vec![NAN, 0.0], vec![INF, 1.0], vec![0.0, 0.0]]),
        ];
        let maps = |contexts: Vec<Vec<f64>>, methods: Vec<(String, Vec<f64>)>| SelectionMaps {
            title: "maps".to_string(),
            axes: ["s_1", "s_2"],
            contexts,
            window: 10,
            methods,
        };
        let traces = |methods: Vec<(String, Vec<Option<f64>>)>| SelectionTraces {
            title: "traces".to_string(),
            axis: "context",
            methods,
        };
        for (case, contexts) in contexts {
            for (values_case, values) in HOSTILE {
                let stem = format!("{case}-{values_case}");
                let zeros = vec![0.0; contexts.len()];
                let maps = maps(
                    contexts.clone(),
                    vec![("a".to_string(), values.to_vec()), ("b".to_string(), zeros)],
                );
                let traces = traces(vec![
                    ("a".to_string(), values.iter().map(|&v| Some(v)).collect()),
                    ("b".to_string(), vec![None, Some(0.0)]),
                ]);
                let dir = dir.clone();
                within_a_minute(&stem.clone(), move || {
                    save(&maps, &dir, &format!("{stem}-maps"))?;
                    save(&traces, &dir, &format!("{stem}-traces"))
                });
            }
        }
        assert!(words(&drawn(&dir, "non-finite-nan-maps")).contains("2 non-finite contexts not drawn"));
        assert!(words(&drawn(&dir, "one-nan-traces")).contains("2 non-finite contexts not drawn"));
        drawn(&dir, "one-empty-traces");
        let mut empty = summary(&[], vec![vec![0.0, 0.0]], None);
        empty.methods.clear();
        let (maps, traces) = (maps(vec![vec![0.0, 0.0]], Vec::new()), traces(Vec::new()));
        let empty_dir = dir.clone();
        within_a_minute("no methods", move || {
            save(&LearningCurves(&empty), &empty_dir, "no-methods-curves")?;
            save(&maps, &empty_dir, "no-methods-maps")?;
            save(&traces, &empty_dir, "no-methods-traces")
        });
        drawn(&dir, "no-methods-traces");
    }

    #[test]
    fn selections_over_time_of_hostile_shares_are_drawn() {
        let dir = dir("selections-time");
        for (case, values) in HOSTILE {
            let bins = values.len().max(1);
            let shares: Vec<Vec<f64>> = (0..3)
                .map(|_| values.iter().copied().chain([0.0]).take(bins).collect())
                .collect();
            let picture = SelectionsOverTime {
                title: case.to_string(),
                contexts: vec!["0".to_string(), "1".to_string(), "2".to_string()],
                axis: "context",
                methods: vec![("a".to_string(), shares)],
                episodes: 10 * bins,
            };
            let into = dir.clone();
            within_a_minute(case, move || save(&picture, &into, case));
            drawn(&dir, case);
        }
        assert!(words(&drawn(&dir, "nan")).contains("6 non-finite shares not drawn"));
    }

    #[test]
    fn bench_bars_of_hostile_rates_are_drawn_and_say_what_they_left_out() {
        let dir = dir("bench");
        for (case, values) in HOSTILE {
            let rows: Vec<crate::bench::Row> = values
                .iter()
                .map(|&rate| crate::bench::Row {
                    env: "trivial",
                    mode: "fleet",
                    workers: 2,
                    rollouts_per_s: rate,
                    ratio: rate,
                    learner_share: None,
                    startup_seconds: None,
                    learner_cpu_us_per_task: None,
                    rollouts: 10,
                    seconds: 0.0,
                    round_rates: vec![rate, rate],
                    round_ratios: vec![rate, 0.0],
                    others_share: None,
                })
                .collect();
            let dir = dir.clone();
            within_a_minute(case, move || save(&BenchBars(&rows), &dir, case));
        }
        assert!(words(&drawn(&dir, "minus-inf")).contains("2 non-finite rates not drawn"));
        drawn(&dir, "empty");
    }

    /// A text of an SVG picture as plotters wrote it: its anchor point and how it is anchored,
    /// its font size as the PNG draws it, whether it runs upwards, and what it says.
    struct Text {
        x: f64,
        y: f64,
        anchor: String,
        size: f64,
        upwards: bool,
        content: String,
    }

    /// The value of the attribute `name` of an SVG element (`element` starts with a space).
    fn attribute<'a>(element: &'a str, name: &str) -> Option<&'a str> {
        element.split(&format!(" {name}=\"")).nth(1)?.split('"').next()
    }

    /// The picture's size and its texts.
    fn svg_texts(svg: &str) -> ((f64, f64), Vec<Text>) {
        let number = |element: &str, name: &str| -> f64 {
            let value = attribute(element, name).unwrap_or_else(|| panic!("no {name} in {element}"));
            value.parse().unwrap_or_else(|e| panic!("{name}={value}: {e}"))
        };
        let svg_element = format!(" {}", svg.split('>').next().unwrap_or_default());
        let size = (number(&svg_element, "width"), number(&svg_element, "height"));
        let texts = svg
            .split("<text ")
            .skip(1)
            .map(|element| {
                let element = format!(" {element}");
                let (head, rest) = element.split_once('>').expect("a text element is closed");
                let content = rest.split("</text>").next().unwrap_or_default().trim();
                Text {
                    x: number(head, "x"),
                    y: number(head, "y"),
                    anchor: attribute(head, "text-anchor").unwrap_or("start").to_string(),
                    // plotters' SVG backend writes a font's size divided by 1.24.
                    size: number(head, "font-size") * 1.24,
                    upwards: head.contains("rotate(270"),
                    content: content
                        .replace("&lt;", "<")
                        .replace("&gt;", ">")
                        .replace("&quot;", "\"")
                        .replace("&apos;", "'")
                        .replace("&amp;", "&"),
                }
            })
            .collect();
        (size, texts)
    }

    /// Every text of `svg`, one after the other: a title broken into lines is whole again.
    fn words(svg: &str) -> String {
        let texts: Vec<String> = svg_texts(svg).1.into_iter().map(|t| t.content).collect();
        texts.join(" ")
    }

    /// The texts of `svg` that reach outside the picture, measured in the PNG's font.
    fn outside(svg: &str) -> Vec<String> {
        let ((width, height), texts) = svg_texts(svg);
        texts
            .iter()
            .filter_map(|text| {
                let font = ("sans-serif", text.size).into_font();
                let length = f64::from(font.box_size(&text.content).map_or(0, |size| size.0));
                // Along the text and across it; a text running upwards starts at its anchor and
                // ends above it.
                let (along, limit, across, room) = if text.upwards {
                    (-text.y, 0.0, text.x, width)
                } else {
                    (text.x, width, text.y, height)
                };
                let (start, end) = match text.anchor.as_str() {
                    "middle" => (along - length / 2.0, along + length / 2.0),
                    "end" => (along - length, along),
                    _ => (along, along + length),
                };
                let (low, high) = if text.upwards { (-height, limit) } else { (0.0, limit) };
                let inside = start >= low - 1.0 && end <= high + 1.0 && (0.0..=room).contains(&across);
                (!inside).then(|| {
                    format!(
                        "{:?} at ({}, {}) spans {start:.0}..{end:.0}",
                        text.content, text.x, text.y
                    )
                })
            })
            .collect()
    }

    const GRID_METHODS: [&str; 6] = [
        "best-reward",
        "diversity",
        "monotonic-progress",
        "one-step-progress",
        "random-continuous",
        "round-robin",
    ];

    /// A summary like the paper's Fig. 8 run: 6 methods over 10,000 episodes of 20 runs, the best
    /// policy, a 5 x 5 grid of targets.
    fn grid_like() -> Summary {
        let mut summary = summary(&[], Vec::new(), None);
        summary.experiment = "grid".to_string();
        summary.metric = "mean distance to the test targets in cm, exploration off".to_string();
        summary.user_problem = None;
        summary.runs = 20;
        summary.training_episodes = 10_000;
        summary.selection_window = 250;
        summary.settings = serde_json::json!({ "sim": "analytic" });
        summary.training_contexts = [-3.0, -3.5, -4.0, -4.5, -5.0]
            .iter()
            .flat_map(|&x| [-3.0, -3.5, -4.0, -4.5, -5.0].map(|y| vec![x, y]))
            .collect();
        summary.methods = GRID_METHODS
            .iter()
            .enumerate()
            .map(|(k, name)| {
                let values: Vec<f64> = (0..=100)
                    .map(|i| 2.8 + 0.3 * k as f64 + 89.0 * (-f64::from(i) / 10.0).exp())
                    .collect();
                (name.to_string(), method(&values, 0.3, Vec::new()))
            })
            .collect();
        summary.best_policy = Some(BestPolicy {
            score: 2.62,
            method: "random-continuous".to_string(),
            run: 4,
            seed: 4,
            episode: 9800,
        });
        summary
    }

    /// A summary like Section 4's model without noise: J_opt = 10, round robin the reference,
    /// and the two progress heuristics identical.
    fn toy_like() -> Summary {
        let mut summary = summary(&[], (0..10).map(|s| vec![f64::from(s)]).collect(), Some(10.0));
        summary.experiment = "toy".to_string();
        summary.metric = "J = sum over the 10 contexts of the noise-free reward r(s)".to_string();
        summary.user_problem = None;
        summary.settings = serde_json::json!({ "model": { "sigma_r": 0.0, "sigma_b": 0.0 } });
        summary.best_policy = None;
        let curve = |lead: f64| -> Vec<f64> {
            (0..=100)
                .map(|i| 10.0 * (1.0 - (-f64::from(i) / 40.0).exp()) + lead * (f64::from(i) / 20.0).sin())
                .collect()
        };
        summary.methods = [
            ("best-reward", 2.0),
            ("diversity", -3.0),
            ("monotonic-progress", 1.0),
            ("one-step-progress", 1.0),
            ("round-robin", 0.0),
        ]
        .into_iter()
        .map(|(name, lead)| (name.to_string(), method(&curve(lead), 0.1, Vec::new())))
        .collect();
        summary
    }

    /// Shares of the grid-like run's methods: `bins` bins, the early bins uneven.
    fn grid_shares(summary: &Summary, bins: usize) -> Vec<(String, Vec<Vec<f64>>)> {
        let k = summary.training_contexts.len();
        GRID_METHODS
            .iter()
            .map(|name| {
                let share = |context: usize, bin: usize| {
                    let bias = if bin < bins / 5 {
                        (context % 4) as f64 - 1.5
                    } else {
                        0.0
                    };
                    (1.0 + 0.5 * bias) / k as f64
                };
                let shares = (0..k).map(|c| (0..bins).map(|b| share(c, b)).collect()).collect();
                (name.to_string(), shares)
            })
            .collect()
    }

    /// Draws one picture into the file it is given.
    type Draw<'a> = &'a dyn Fn(&Path) -> PlotResult;

    #[test]
    fn no_text_reaches_outside_a_picture() {
        let dir = dir("layout");
        let (grid, toy) = (grid_like(), toy_like());
        let mut board = grid_like();
        board.experiment = "dartboard".to_string();
        board.methods.retain(|name, _| name == "monotonic-progress");
        let shares = grid_shares(&grid, 50);
        let maps: Vec<(String, Vec<f64>)> = grid_shares(&grid, 1)
            .into_iter()
            .map(|(name, shares)| (name, shares.into_iter().map(|row| row[0]).collect()))
            .collect();
        let choices: Vec<(String, Vec<Option<f64>>)> = toy
            .methods
            .keys()
            .map(|name| (name.clone(), (0..1000).map(|t| Some(f64::from(t % 10))).collect()))
            .collect();
        let updates: UpdateTraces = GRID_METHODS
            .iter()
            .map(|name| {
                let run = (1..200)
                    .map(|u| (50.0 * f64::from(u), 0.4 / f64::from(u), 140.0))
                    .collect();
                (name.to_string(), vec![run])
            })
            .collect();
        let rows: Vec<crate::bench::Row> = ["trivial", "analytic", "rapier"]
            .iter()
            .flat_map(|&env| {
                [
                    ("inprocess-1", 1),
                    ("inprocess-rayon", 2),
                    ("fleet", 1),
                    ("relay", 1),
                    ("fleet", 2),
                    ("relay", 2),
                ]
                .map(|(mode, workers)| crate::bench::Row {
                    env,
                    mode,
                    workers,
                    rollouts_per_s: 2.9e6 / f64::from(workers as u32),
                    ratio: 0.97,
                    learner_share: None,
                    startup_seconds: None,
                    learner_cpu_us_per_task: None,
                    rollouts: 100_000,
                    seconds: 1.0,
                    round_rates: vec![2.9e6, 2.8e6, 2.7e6],
                    round_ratios: vec![0.97, 0.91, 0.99],
                    others_share: Some(0.02),
                })
            })
            .collect();
        let policy = acps_models::throw::ThrowPolicy::new(acps_models::throw::ThrowDesign::pa10(), 0.01)
            .unwrap_or_else(|e| panic!("{e}"));
        let trajectory = policy
            .trajectory(&[0.0; acps_models::throw::PARAMS])
            .unwrap_or_else(|e| panic!("{e}"));
        let fields = acps_models::environment::dartboard_fields();
        let pictures: [(&str, Draw); 9] = [
            ("grid-curves", &|path| save_as(&LearningCurves(&grid), path)),
            ("toy-curves", &|path| save_as(&LearningCurves(&toy), path)),
            ("selections-time", &|path| {
                save_as(&SelectionsOverTime::of(&grid, 10_000, shares.clone()), path)
            }),
            ("selections", &|path| {
                save_as(&SelectionMaps::of(&grid, 250, maps.clone()), path)
            }),
            ("traces", &|path| {
                save_as(&SelectionTraces::of(&toy, choices.clone()), path)
            }),
            ("updates", &|path| {
                save_as(&Exploration::of(&grid, updates.clone()), path)
            }),
            ("bench", &|path| save_as(&BenchBars(&rows), path)),
            ("throw", &|path| {
                let view = ThrowSideView {
                    robot: &Robot::pa10(),
                    trajectory: &trajectory,
                    title: "best-reward run 0: throw at (-3.250, -3.250), arm every 0.1 s, ball after release",
                };
                save_as(&view, path)
            }),
            ("board", &|path| {
                save_as(
                    &Dartboard {
                        summary: &board,
                        fields: &fields,
                    },
                    path,
                )
            }),
        ];
        for (stem, draw) in pictures {
            for extension in ["svg", "png"] {
                draw(&dir.join(format!("{stem}.{extension}"))).unwrap_or_else(|e| panic!("{stem}: {e}"));
            }
            let outside = outside(&drawn(&dir, stem));
            assert!(outside.is_empty(), "{stem}: {outside:#?}");
        }
        // The last tick of 10,000 episodes, whole.
        let (_, labels) = svg_texts(&drawn(&dir, "selections-time"));
        assert!(labels.iter().any(|t| t.content == "10000"), "no tick 10000");
    }

    #[test]
    fn the_curves_name_the_band_the_unit_and_the_simulator() {
        let dir = dir("curves-legend");
        save(&LearningCurves(&grid_like()), &dir, "grid").unwrap_or_else(|e| panic!("{e}"));
        let (_, texts) = svg_texts(&drawn(&dir, "grid"));
        let said = |what: &str| texts.iter().any(|t| t.content == what);
        for what in [
            "grid, analytic simulator: mean ± SEM of 20 runs per method",
            "shaded: ± 1 SEM",
            "best policy (2.62 cm)",
            "the second half, zoomed (the lines of the left panel)",
        ] {
            assert!(
                said(what),
                "{what:?} not in {:?}",
                texts.iter().map(|t| &t.content).collect::<Vec<_>>()
            );
        }
        // A problem file's unit; none where the problem has none.
        let mut user = grid_like();
        user.user_problem = Some(UserProblem {
            unit: "kJ".to_string(),
            lower_is_better: true,
        });
        save(&LearningCurves(&user), &dir, "user").unwrap_or_else(|e| panic!("{e}"));
        assert!(drawn(&dir, "user").contains("best policy (2.62 kJ)"));
        user.user_problem = Some(UserProblem {
            unit: String::new(),
            lower_is_better: true,
        });
        save(&LearningCurves(&user), &dir, "unitless").unwrap_or_else(|e| panic!("{e}"));
        assert!(drawn(&dir, "unitless").contains("best policy (2.62)"));
        // A run of the other learner says so.
        let mut ccmaes = grid_like();
        ccmaes.settings["ccmaes"] = serde_json::json!({ "population": null });
        save(&LearningCurves(&ccmaes), &dir, "ccmaes").unwrap_or_else(|e| panic!("{e}"));
        let (_, texts) = svg_texts(&drawn(&dir, "ccmaes"));
        let title = "grid, analytic simulator, C-CMA-ES: mean ± SEM of 20 runs per method";
        assert!(texts.iter().any(|t| t.content == title), "{title:?} not drawn");
    }

    #[test]
    fn the_optimum_lies_inside_the_curves_and_identical_curves_say_so() {
        let dir = dir("curves-toy");
        save(&LearningCurves(&toy_like()), &dir, "toy").unwrap_or_else(|e| panic!("{e}"));
        let (_, texts) = svg_texts(&drawn(&dir, "toy"));
        // J_opt - J_RR is 10 at episode 0, far above every curve: the y axis reaches it.
        let top = texts
            .iter()
            .filter(|t| t.anchor == "end")
            .filter_map(|t| t.content.parse::<f64>().ok())
            .fold(f64::MIN, f64::max);
        assert!(top >= 10.0, "the y axis ends at {top}, below J_opt - J_RR = 10");
        let legend: Vec<&str> = texts.iter().map(|t| t.content.as_str()).collect();
        assert!(
            legend.contains(&"monotonic-progress (= one-step-progress, under it)"),
            "{legend:?}"
        );
        for name in ["best-reward", "diversity", "one-step-progress", "round-robin"] {
            assert!(legend.contains(&name), "{name} not plain in {legend:?}");
        }
    }

    #[test]
    fn selection_pictures_have_labelled_axes_and_a_colour_bar() {
        let dir = dir("selections-bars");
        let grid = grid_like();
        let shares = grid_shares(&grid, 50);
        save(&SelectionsOverTime::of(&grid, 10_000, shares), &dir, "time").unwrap_or_else(|e| panic!("{e}"));
        let (_, texts) = svg_texts(&drawn(&dir, "time"));
        let said = |what: &str| texts.iter().any(|t| t.content == what);
        assert!(said(
            "grid: share of each bin of 200 training episodes that went to each target, mean over 20 runs"
        ));
        // The darkest share is named (the first fifth's most-chosen targets: 1.75 / 25 = 0.07).
        assert!(said("share of a bin's episodes (uniform: 1/25 = 0.04; darkest: 0.07)"));
        for context in &grid.training_contexts {
            let label = context_label(context);
            assert!(said(&label), "{label} not on the axis");
        }
        let mut maps: Vec<(String, Vec<f64>)> = grid_shares(&grid, 1)
            .into_iter()
            .map(|(name, shares)| (name, shares.into_iter().map(|row| row[0]).collect()))
            .collect();
        // Every target chosen: no swatch for "none".
        save(&SelectionMaps::of(&grid, 250, maps.clone()), &dir, "maps").unwrap_or_else(|e| panic!("{e}"));
        let (_, texts) = svg_texts(&drawn(&dir, "maps"));
        let said = |what: &str| texts.iter().any(|t| t.content == what);
        for what in [
            "target x (m)",
            "target y (m)",
            "share of the first 250 episodes, log scale (white: uniform, 1/25 = 0.04)",
        ] {
            assert!(said(what), "{what:?} not in the maps");
        }
        assert!(
            !said("none"),
            "a swatch for targets never chosen, where every target was"
        );
        maps[0].1[3] = 0.0;
        save(&SelectionMaps::of(&grid, 250, maps), &dir, "maps").unwrap_or_else(|e| panic!("{e}"));
        let (_, texts) = svg_texts(&drawn(&dir, "maps"));
        assert!(
            texts.iter().any(|t| t.content == "none"),
            "no swatch for a target never chosen"
        );
    }

    #[test]
    fn one_method_s_pictures_fill_their_canvas() {
        let dir = dir("one-method");
        let grid = grid_like();
        let maps = grid_shares(&grid, 1)
            .into_iter()
            .take(1)
            .map(|(name, shares)| (name, shares.into_iter().map(|row| row[0]).collect()))
            .collect();
        save(&SelectionMaps::of(&grid, 250, maps), &dir, "maps").unwrap_or_else(|e| panic!("{e}"));
        let ((width, _), texts) = svg_texts(&drawn(&dir, "maps"));
        // The x axis' ticks (target x in m) span most of the canvas: no empty half beside them.
        let ticks: Vec<f64> = texts
            .iter()
            .filter(|t| !t.upwards && t.content.parse::<f64>().is_ok_and(|x| x < -2.0))
            .map(|t| t.x)
            .collect();
        let spread = ticks.iter().fold(f64::MIN, |a, &b| a.max(b)) - ticks.iter().fold(f64::MAX, |a, &b| a.min(b));
        assert!(spread > 0.6 * width, "the ticks span {spread:.0} of {width:.0} px");
        let run = (1..50).map(|u| (50.0 * f64::from(u), 1.0, 10.0)).collect();
        let updates = Exploration::of(&grid, vec![("random".to_string(), vec![run])]);
        let (width, height) = updates.size();
        assert!(
            3 * height >= width,
            "{width}x{height}: one method's updates are a strip"
        );
        save(&updates, &dir, "updates").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(outside(&drawn(&dir, "updates")), Vec::<String>::new());
    }

    #[test]
    fn labels_are_short_and_exact() {
        for (value, label) in [
            (-3.0, "-3"),
            (-3.5499269522, "-3.55"),
            (0.04, "0.04"),
            (2.2e-16, "0"),
            (-0.001, "-1.0e-3"),
            (1e300, "1.0e300"),
            (12345.0, "12345"),
        ] {
            assert_eq!(compact(value), label, "{value}");
        }
        assert_eq!(context_label(&[-3.0, -3.5]), "(-3, -3.5)");
        assert_eq!(context_label(&[7.0]), "7");
        assert_eq!(rate(2.9e6), "2.9 M");
        assert_eq!(rate(1200.0), "1.2 k");
        assert_eq!(rate(350.0), "350");
    }

    /// The bins cover every episode exactly once, as the heat map's cells are drawn.
    #[test]
    fn bins_partition_the_episodes() {
        for (bins, episodes) in [(50, 50), (50, 200), (50, 1001), (7, 9), (1, 5)] {
            let widths: Vec<usize> = (0..bins).map(|b| bin_width(b, bins, episodes)).collect();
            assert_eq!(widths.iter().sum::<usize>(), episodes);
            for t in 0..episodes {
                let bin = t * bins / episodes;
                let first: usize = widths[..bin].iter().sum();
                assert!(first <= t && t < first + widths[bin], "{t} in bin {bin} of {widths:?}");
            }
        }
    }
}
