//! Pictures of a summary, written next to summary.json as SVG:
//! - `curves.svg`: mean learning curve of every method with a +-1 SEM band (paper Fig. 4, 6);
//!   when the problem knows its optimum and round robin ran, curves are drawn relative to round
//!   robin with the optimum as a dashed line (Fig. 2).
//! - `selections.svg`: for 1-D contexts, the context chosen in every episode of run 0 (Fig. 3);
//!   for 2-D contexts, the log selection ratio of every training context over the first
//!   episodes (Fig. 5).
//! - for the dartboard, `board.svg` (Fig. 10), and for the throwing problems `throw.svg`, a side
//!   view of the initial throw.

use crate::experiment::Summary;
use acps_models::robot::Robot;
use acps_models::targets::Field;
use acps_models::trajectory::JointTrajectory;
use plotters::prelude::*;
use std::collections::BTreeMap;
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

/// Write every picture that fits the summary into `dir`.
pub fn write_all(summary: &Summary, dir: &Path) -> PlotResult {
    learning_curves(summary, &dir.join("curves.svg"))?;
    if matches!(summary.experiment.as_str(), "grid" | "dartboard") {
        let policy = acps_models::throw::ThrowPolicy::new(acps_models::throw::ThrowDesign::pa10(), 0.01)?;
        throw_side_view(
            &Robot::pa10(),
            &policy.trajectory(&[0.0; acps_models::throw::PARAMS])?,
            &dir.join("throw.svg"),
        )?;
    }
    if summary.experiment == "dartboard" {
        return dartboard(
            summary,
            &acps_models::environment::dartboard_fields(),
            &dir.join("board.svg"),
        );
    }
    match summary.training_contexts.first().map(Vec::len) {
        Some(1) => selection_traces(summary, &dir.join("selections.svg"))?,
        Some(2) => selection_maps(summary, &dir.join("selections.svg"))?,
        _ => {}
    }
    Ok(())
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
    let label = if reference.is_some() {
        "J - J_RR".to_string()
    } else {
        summary.metric.clone()
    };
    (curves, optimum, label)
}

fn learning_curves(summary: &Summary, path: &Path) -> PlotResult {
    let (curves, optimum, y_label) = curves(summary);
    let all = curves.iter().flat_map(|c| c.points.iter());
    // The range fits the curves; the optimum line may leave it early on, as in the paper's Fig. 2.
    let (mut y_min, mut y_max) = all.clone().fold((f64::MAX, f64::MIN), |(lo, hi), &(_, m, s)| {
        (lo.min(m - s), hi.max(m + s))
    });
    let x_max = all.map(|p| p.0).fold(1.0, f64::max);
    if y_min >= y_max {
        (y_min, y_max) = (y_min - 1.0, y_max + 1.0);
    }
    let pad = 0.05 * (y_max - y_min);
    let root = SVGBackend::new(path, (900, 560)).into_drawing_area();
    root.fill(&WHITE)?;
    let caption = format!("{}: {} runs per method", summary.experiment, summary.runs);
    let mut chart = ChartBuilder::on(&root)
        .caption(caption, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..x_max, (y_min - pad)..(y_max + pad))?;
    chart
        .configure_mesh()
        .x_desc("training episodes")
        .y_desc(short(&y_label))
        .draw()?;
    for (index, curve) in curves.iter().enumerate() {
        let color = COLORS[index % COLORS.len()];
        let band: Vec<(f64, f64)> = curve
            .points
            .iter()
            .map(|&(x, m, s)| (x, m + s))
            .chain(curve.points.iter().rev().map(|&(x, m, s)| (x, m - s)))
            .collect();
        chart.draw_series(std::iter::once(Polygon::new(band, color.mix(0.15))))?;
        chart
            .draw_series(LineSeries::new(
                curve.points.iter().map(|&(x, m, _)| (x, m)),
                color.stroke_width(2),
            ))?
            .label(curve.name.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
    }
    if let (Some(rr), Some(opt)) = (summary.methods.get("round-robin"), optimum) {
        let line: Vec<(f64, f64)> = rr
            .episodes
            .iter()
            .zip(&rr.mean)
            .filter_map(|(&e, m)| Some((e as f64, opt - (*m)?)))
            .collect();
        chart
            .draw_series(DashedLineSeries::new(line, 6, 4, BLACK.stroke_width(1)))?
            .label("J_opt")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
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

fn selection_traces(summary: &Summary, path: &Path) -> PlotResult {
    let methods: Vec<_> = summary.methods.iter().collect();
    let contexts = summary.training_contexts.len();
    let root = SVGBackend::new(path, (900, 220 * methods.len() as u32)).into_drawing_area();
    root.fill(&WHITE)?;
    for ((name, m), area) in methods.iter().zip(root.split_evenly((methods.len(), 1))) {
        let episodes = m.selections_run0.len().max(1) as f64;
        let mut chart = ChartBuilder::on(&area)
            .caption(format!("{name}: selected context, run 0"), ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(40)
            .build_cartesian_2d(0.0..episodes, -0.5..(contexts as f64 - 0.5))?;
        chart.configure_mesh().x_desc("episode").y_desc("context").draw()?;
        let points = m
            .selections_run0
            .iter()
            .enumerate()
            .filter_map(|(t, arm)| Some((t as f64, (*arm)? as f64)));
        chart.draw_series(points.map(|p| Circle::new(p, 1, COLORS[0].filled())))?;
    }
    root.present()?;
    Ok(())
}

fn selection_maps(summary: &Summary, path: &Path) -> PlotResult {
    let methods: Vec<_> = summary.methods.iter().collect();
    let columns = methods.len().min(3);
    let rows = methods.len().div_ceil(columns);
    let root = SVGBackend::new(path, (320 * columns as u32, 320 * rows as u32)).into_drawing_area();
    root.fill(&WHITE)?;
    let (lo, hi) = bounds(&summary.training_contexts);
    // Half the smallest spacing between contexts: each context is drawn as a square of that size.
    let half = half_spacing(&summary.training_contexts);
    for ((name, m), area) in methods.iter().zip(root.split_evenly((rows, columns))) {
        let title = format!(
            "{name}: ln(selections / most selected), first {}",
            summary.selection_window
        );
        let mut chart = ChartBuilder::on(&area)
            .caption(title, ("sans-serif", 12))
            .margin(8)
            .x_label_area_size(25)
            .y_label_area_size(35)
            .build_cartesian_2d((lo[0] - half)..(hi[0] + half), (lo[1] - half)..(hi[1] + half))?;
        chart.configure_mesh().disable_mesh().draw()?;
        let most = m.selection_ratio.iter().copied().fold(0.0, f64::max);
        let squares = summary
            .training_contexts
            .iter()
            .zip(&m.selection_ratio)
            .map(|(c, &ratio)| {
                // The paper's Fig. 5 colour scale: -3 (white) to 0 (dark).
                let shade = if most > 0.0 {
                    ((ratio / most).max(1e-12).ln() + 3.0) / 3.0
                } else {
                    0.0
                };
                let level = (255.0 * (1.0 - shade.clamp(0.0, 1.0))) as u8;
                Rectangle::new(
                    [(c[0] - half, c[1] - half), (c[0] + half, c[1] + half)],
                    RGBColor(level, level, 255).filled(),
                )
            });
        chart.draw_series(squares)?;
    }
    root.present()?;
    Ok(())
}

fn bounds(contexts: &[Vec<f64>]) -> (Vec<f64>, Vec<f64>) {
    let fold =
        |f: fn(f64, f64) -> f64, init: f64| (0..2).map(|d| contexts.iter().map(|c| c[d]).fold(init, f)).collect();
    (fold(f64::min, f64::MAX), fold(f64::max, f64::MIN))
}

fn half_spacing(contexts: &[Vec<f64>]) -> f64 {
    let mut smallest = f64::MAX;
    for (i, a) in contexts.iter().enumerate() {
        for b in &contexts[i + 1..] {
            let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
            if d > 1e-12 {
                smallest = smallest.min(d);
            }
        }
    }
    if smallest == f64::MAX { 0.1 } else { smallest / 2.0 }
}

/// The dartboard with every field, its target and where run 0's final policy lands (paper
/// Fig. 10 left), next to the average number of selections per field of every ring over the
/// first episodes (Fig. 10 right).
pub fn dartboard(summary: &Summary, fields: &[Field], path: &Path) -> PlotResult {
    let methods: Vec<_> = summary.methods.iter().collect();
    let root = SVGBackend::new(path, (1200, 600 * methods.len() as u32)).into_drawing_area();
    root.fill(&WHITE)?;
    let bull = fields[0].centre;
    let reach = 0.75;
    for ((name, m), row) in methods.iter().zip(root.split_evenly((methods.len(), 1))) {
        let (left, right) = row.split_horizontally(600);
        let mut board = ChartBuilder::on(&left)
            .caption(
                format!("{name}: targets (blue) and landings of run 0 (red)"),
                ("sans-serif", 15),
            )
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(45)
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
        let top = curves.values().flatten().copied().fold(1.0, f64::max);
        let mut chart = ChartBuilder::on(&right)
            .caption("average selections per field of each ring", ("sans-serif", 15))
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(45)
            .build_cartesian_2d(0.0..(100.0 * longest.max(1) as f64), 0.0..top * 1.05)?;
        chart
            .configure_mesh()
            .x_desc("episode")
            .y_desc("selections per field")
            .draw()?;
        for (index, (category, values)) in curves.iter().enumerate() {
            let color = COLORS[index % COLORS.len()];
            chart
                .draw_series(LineSeries::new(
                    values.iter().enumerate().map(|(i, &v)| (100.0 * (i + 1) as f64, v)),
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
    root.present()?;
    Ok(())
}

/// A side view of one throw: the arm every 0.1 s until the release, then the ball's flight,
/// projected on the vertical plane through the base and the landing point.
pub fn throw_side_view(robot: &Robot, trajectory: &JointTrajectory, path: &Path) -> PlotResult {
    let (q, qd) = trajectory.last().ok_or("empty trajectory")?;
    let (release, velocity) = robot.ball_state(q, qd);
    let landing = robot.landing(&release, &velocity).ok_or("the ball does not land")?;
    let norm = (landing[0].powi(2) + landing[1].powi(2)).sqrt().max(1e-9);
    let along = |x: f64, y: f64| (x * landing[0] + y * landing[1]) / norm;
    let root = SVGBackend::new(path, (1000, 420)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "throw of theta_0: arm every 0.1 s, ball after release",
            ("sans-serif", 16),
        )
        .margin(12)
        .x_label_area_size(35)
        .y_label_area_size(45)
        .build_cartesian_2d(-1.0..(norm + 0.3), 0.0..2.2)?;
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
        chart.draw_series(std::iter::once(PathElement::new(points, shade.stroke_width(2))))?;
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
    chart.draw_series(LineSeries::new(ball, COLORS[3].stroke_width(2)))?;
    chart.draw_series(std::iter::once(Circle::new(
        (norm, robot.ball.radius),
        5,
        COLORS[3].filled(),
    )))?;
    root.present()?;
    Ok(())
}
