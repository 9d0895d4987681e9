//! The report of `splat tradeoff`: each setting's errors against the reference (image PSNR,
//! gradient error per parameter group and per magnitude range), printed as a table and written
//! as CSV and a plot.

use crate::plot;
use crate::tradeoff::Outcome;
use anyhow::{Context, Result, bail};
use plotters::prelude::*;
use splat_runtime::io::Outputs;
use std::fmt::Write as _;

/// Gradient magnitude ranges, relative to the group's largest reference gradient (seed 001's
/// Table IV uses absolute ranges; relative ones do not depend on the loss's scale).
const RANGES: [(f64, f64, &str); 3] = [
    (0.1, f64::INFINITY, "[0.1, 1]"),
    (1e-3, 0.1, "[1e-3, 0.1)"),
    (1e-5, 1e-3, "[1e-5, 1e-3)"),
];

/// A setting's errors against the reference.
#[derive(Default)]
pub(crate) struct Row {
    pub(crate) knob: &'static str,
    pub(crate) value: String,
    pub(crate) forward_ms: f64,
    pub(crate) backward_ms: Option<f64>,
    /// The times against the default's: beside the pace frame (GPU) or the default row (CPU).
    pub(crate) forward_x: Option<f64>,
    pub(crate) backward_x: Option<f64>,
    pub(crate) mib: f64,
    pub(crate) intersections: usize,
    pub(crate) sort_mib: Option<f64>,
    pub(crate) psnr: f64,
    pub(crate) max_abs: f64,
    /// Per parameter group: RMSE relative to the reference's RMS, and the mean relative error
    /// per magnitude range (None where the range holds no word). Only the groups the
    /// reference has with the same size (a lower SH degree has a smaller `sh`).
    pub(crate) groups: Vec<(String, f64, Vec<Option<f64>>)>,
}

impl Row {
    /// The worst group's relative RMSE (None without gradients); NaN if any group's is, which
    /// `f64::max` would pass over, reading as exact.
    fn gradient_error(&self) -> Option<f64> {
        let worst = (self.groups.iter().map(|g| g.1)).fold(0.0, |worst: f64, e| {
            if worst >= e || worst.is_nan() {
                worst
            } else {
                e
            }
        });
        (!self.groups.is_empty()).then_some(worst)
    }
}

/// A time in milliseconds, or empty.
fn ms(d: Option<f64>, digits: usize) -> String {
    d.map_or("-".into(), |v| format!("{v:.digits$}"))
}

pub(crate) fn write_outputs(dir: &std::path::Path, rows: &[Row], method: &str) -> Result<()> {
    let mut summary = String::from(
        "knob,setting,forward_ms,forward_vs_default,backward_ms,backward_vs_default,memory_mib,intersections,sort_mib,psnr_db,max_abs,gradient_rel_rmse\n",
    );
    // The ranges hold a comma: quoted, as CSV quotes such fields.
    let mut detail = String::from("knob,setting,group,rel_rmse,range,mre\n");
    for r in rows {
        let empty = |v: Option<String>| v.unwrap_or_default();
        writeln!(
            summary,
            "{},{},{:.4},{},{},{},{:.3},{},{},{:.3},{:.6e},{}",
            r.knob,
            r.value,
            r.forward_ms,
            empty(r.forward_x.map(|v| format!("{v:.4}"))),
            empty(r.backward_ms.map(|v| format!("{v:.4}"))),
            empty(r.backward_x.map(|v| format!("{v:.4}"))),
            r.mib,
            r.intersections,
            empty(r.sort_mib.map(|v| format!("{v:.3}"))),
            r.psnr,
            r.max_abs,
            empty(r.gradient_error().map(|v| format!("{v:.6e}")))
        )?;
        for (group, rmse, mres) in &r.groups {
            for ((_, _, range), mre) in RANGES.iter().zip(mres) {
                let mre = mre.map_or(String::new(), |v| format!("{v:.6e}"));
                writeln!(
                    detail,
                    "{},{},{group},{rmse:.6e},\"{range}\",{mre}",
                    r.knob, r.value
                )?;
            }
        }
    }
    // The tables and their plot appear together.
    let mut outputs = Outputs::default();
    for (name, text) in [("tradeoff.csv", &summary), ("gradients.csv", &detail)] {
        let path = dir.join(name);
        (outputs.stage(&path, |w| w.write_all(text.as_bytes())))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    draw(&mut outputs, &dir.join("tradeoff.png"), rows, method)?;
    outputs.commit()?;
    crate::wrote(dir);
    Ok(())
}

pub(crate) fn compare(knob: &'static str, value: String, o: &Outcome, reference: &Outcome) -> Row {
    let diffs = o.color.iter().zip(&reference.color);
    let (sq, max_abs) = diffs.fold((0.0f64, 0.0f64), |(sq, mx), (a, b)| {
        let d = (*a as f64 - *b as f64).abs();
        (sq + d * d, mx.max(d))
    });
    let mse = sq / o.color.len().max(1) as f64;
    let groups = o
        .gradients
        .iter()
        .filter_map(|(name, got)| {
            let (_, want) = reference
                .gradients
                .iter()
                .find(|(n, w)| n == name && w.len() == got.len())?;
            let (rmse, mres) = gradient_errors(got, want);
            Some((name.clone(), rmse, mres))
        })
        .collect();
    Row {
        knob,
        value,
        forward_ms: o.forward.as_secs_f64() * 1e3,
        backward_ms: o.backward.map(|d| d.as_secs_f64() * 1e3),
        forward_x: o.forward_x,
        backward_x: o.backward_x,
        mib: o.bytes as f64 / 1048576.0,
        intersections: o.intersections,
        sort_mib: o.sort_bytes.map(|b| b as f64 / 1048576.0),
        psnr: -10.0 * mse.log10(),
        max_abs,
        groups,
    }
}

/// RMSE relative to the reference's RMS, and the mean relative error of the words whose
/// reference magnitude (relative to the largest) falls in each of [`RANGES`].
fn gradient_errors(got: &[f64], want: &[f64]) -> (f64, Vec<Option<f64>>) {
    let n = want.len().max(1) as f64;
    let rms = (want.iter().map(|w| w * w).sum::<f64>() / n).sqrt();
    // Summed from +0: `sum` starts from -0, and an empty scene's error printed as -0.
    let sq = got
        .iter()
        .zip(want)
        .fold(0.0, |sum, (g, w)| sum + (g - w) * (g - w));
    let rmse = match rms > 0.0 {
        true => (sq / n).sqrt() / rms,
        false => (sq / n).sqrt(),
    };
    let largest = want.iter().fold(0.0f64, |m, w| m.max(w.abs()));
    let mres = RANGES
        .iter()
        .map(|&(lo, hi, _)| {
            let errors: Vec<f64> = got
                .iter()
                .zip(want)
                .filter(|(_, w)| {
                    let r = w.abs() / largest;
                    largest > 0.0 && r >= lo && r < hi
                })
                .map(|(g, w)| ((g - w) / w).abs())
                .collect();
            (!errors.is_empty()).then(|| errors.iter().sum::<f64>() / errors.len() as f64)
        })
        .collect();
    (rmse, mres)
}

pub(crate) fn print_table(rows: &[Row], paced: bool) {
    println!(
        "\n| knob | setting | forward ms | x default | backward ms | x default | MiB | sorted keys | sort MiB | PSNR dB | max abs | gradient rel. RMSE (worst group) |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for r in rows {
        println!(
            "| {} | {} | {:.2} | {} | {} | {} | {:.1} | {} | {} | {:.1} | {:.1e} | {} |",
            r.knob,
            r.value,
            r.forward_ms,
            ms(r.forward_x, 2),
            ms(r.backward_ms, 2),
            ms(r.backward_x, 2),
            r.mib,
            r.intersections,
            ms(r.sort_mib, 1),
            r.psnr,
            r.max_abs,
            r.gradient_error()
                .map_or("-".into(), |e| format!("{e:.1e}"))
        );
    }
    println!("(PSNR and errors against the reference; inf: the same image)");
    println!(
        "(x default: {})",
        match paced {
            true =>
                "each frame's time over the default frame's run after it, the median of the rounds",
            false => "the time over the default row's",
        }
    );
}

/// Errors at or below this (an exact match) are drawn on the floor of the log axis.
const FLOOR: f64 = 1e-9;

/// A color per knob, in the order the sweep first names them.
const COLORS: [RGBColor; 11] = [
    RGBColor(200, 30, 40),
    RGBColor(40, 150, 60),
    RGBColor(30, 90, 200),
    RGBColor(230, 120, 20),
    RGBColor(130, 60, 170),
    RGBColor(90, 90, 90),
    RGBColor(0, 150, 160),
    RGBColor(150, 100, 40),
    RGBColor(220, 60, 150),
    RGBColor(110, 160, 20),
    RGBColor(20, 40, 110),
];

/// Two panels: forward time against image RMSE, forward + backward time against the worst
/// group's gradient error; a color per knob, and the Pareto front of the settings measured
/// against the same reference.
fn draw(outputs: &mut Outputs, path: &std::path::Path, rows: &[Row], method: &str) -> Result<()> {
    let knobs: Vec<&str> = rows.iter().fold(vec![], |mut k, r| {
        if !k.contains(&r.knob) {
            k.push(r.knob);
        }
        k
    });
    // Times as ratios to the default's (`x default`), which hold where a GPU's clock moves; a
    // frame's forward and backward ratios weighed by the default row's times.
    let Some(default) = rows.first() else {
        bail!("no settings to plot");
    };
    let (forward, backward) = (default.forward_ms, default.backward_ms.unwrap_or(0.0));
    let x = |r: &Row| r.forward_x.unwrap_or(f64::NAN);
    let image: Vec<(f64, f64)> = rows
        .iter()
        .map(|r| (x(r), 10f64.powf(-r.psnr / 20.0)))
        .collect();
    // Only the settings with a backward pass have a gradient point.
    let with_gradients: Vec<&Row> = rows.iter().filter(|r| r.backward_ms.is_some()).collect();
    // A NaN error has no place on the axis: the tables show it.
    let gradient: Vec<(f64, f64)> = with_gradients
        .iter()
        .map(|r| {
            let b = r.backward_x.unwrap_or(f64::NAN);
            let time = (x(r) * forward + b * backward) / (forward + backward);
            (time, r.gradient_error().unwrap_or(0.0))
        })
        .filter(|(_, e)| !e.is_nan())
        .collect();
    plot::png(outputs, path, (1400, 560), |root| {
        let panels = root.split_evenly((1, 2));
        let all: Vec<&Row> = rows.iter().collect();
        let series = [
            (
                "image against forward time",
                "forward time, x the default's",
                "image RMSE",
                &image,
                &all,
            ),
            (
                "gradients against forward + backward time",
                "forward + backward time, x the default's",
                "gradient rel. RMSE, worst group",
                &gradient,
                &with_gradients,
            ),
        ];
        for (area, (caption, x_desc, y_desc, points, rows)) in panels.iter().zip(series) {
            let caption = format!("{method}: {caption}");
            let axes = (x_desc, y_desc);
            panel(area, &caption, axes, points, rows, &knobs)?;
        }
        Ok(())
    })
}

fn panel(
    area: &plot::Area,
    caption: &str,
    (x_desc, y_desc): (&str, &str),
    points: &[(f64, f64)],
    rows: &[&Row],
    knobs: &[&str],
) -> Result<()> {
    let y = |v: f64| v.max(FLOOR).log10();
    let (x_hi, y_lo, y_hi) = points.iter().fold(
        (0.0f64, f64::INFINITY, f64::NEG_INFINITY),
        |(xh, lo, hi), &(x, v)| (xh.max(x), lo.min(y(v)), hi.max(y(v))),
    );
    let err = plot::drawing(format!("chart \"{caption}\""));
    let mut chart = ChartBuilder::on(area)
        .caption(caption, plot::text(16))
        .margin(12)
        .margin_right(24)
        .x_label_area_size(40)
        .y_label_area_size(76)
        // Room on the right for the legend, past the slowest setting.
        .build_cartesian_2d(0.0..x_hi * 1.45, (y_lo - 0.5)..(y_hi + 0.5))
        .map_err(&err)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(format!("{y_desc} (exact: at {FLOOR:e})"))
        .y_label_formatter(&|v| format!("{:.0e}", 10f64.powf(*v)))
        .label_style(plot::text(13))
        .draw()
        .map_err(&err)?;
    // The Pareto front: the settings no other setting beats in both time and error. The model
    // rows are measured against another reference (the exact method's), so they stay out.
    let mut order: Vec<usize> = (0..points.len())
        .filter(|&i| rows[i].knob != "model")
        .collect();
    order.sort_by(|&a, &b| points[a].0.total_cmp(&points[b].0));
    let mut front = vec![];
    for i in order {
        if front.last().is_none_or(|&(_, e)| y(points[i].1) < e) {
            front.push((points[i].0, y(points[i].1)));
        }
    }
    chart
        .draw_series(LineSeries::new(front, BLACK.mix(0.4).stroke_width(2)))
        .map_err(&err)?
        .label("Pareto front (without model)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLACK.mix(0.4)));
    for (k, knob) in knobs.iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        let mine: Vec<(f64, f64, &str)> = rows
            .iter()
            .zip(points)
            .filter(|(r, _)| r.knob == *knob)
            .map(|(r, &(x, v))| (x, y(v), r.value.as_str()))
            .collect();
        if mine.is_empty() {
            continue;
        }
        chart
            .draw_series(
                mine.iter()
                    .map(|&(x, v, _)| Circle::new((x, v), 5, color.filled())),
            )
            .map_err(&err)?
            .label(*knob)
            .legend(move |(x, y)| Circle::new((x + 8, y), 5, color.filled()));
        if *knob != "default" {
            chart
                .draw_series(mine.iter().map(|&(x, v, label)| {
                    let style = plot::text(12).color(&color);
                    EmptyElement::at((x, v)) + Text::new(label.to_string(), (7, -14), style)
                }))
                .map_err(&err)?;
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK.mix(0.3))
        .label_font(plot::text(13))
        .position(SeriesLabelPosition::LowerRight)
        .draw()
        .map_err(&err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The worst group's error is NaN when one group's is.
    #[test]
    fn a_nan_group_is_the_worst() {
        let row = |errors: &[f64]| Row {
            groups: errors.iter().map(|&e| ("g".into(), e, vec![])).collect(),
            ..Row::default()
        };
        assert_eq!(row(&[0.5, 0.25]).gradient_error(), Some(0.5));
        assert!(
            row(&[0.5, f64::NAN, 0.25])
                .gradient_error()
                .unwrap()
                .is_nan()
        );
        assert!(row(&[f64::NAN, 0.5]).gradient_error().unwrap().is_nan());
        assert_eq!(row(&[]).gradient_error(), None);
    }

    /// Exact gradients, and none at all (an empty scene), are 0 off, not -0.
    #[test]
    fn no_error_is_plus_zero() {
        for (got, want) in [(&[][..], &[][..]), (&[1.0, -2.0][..], &[1.0, -2.0][..])] {
            let (rmse, _) = gradient_errors(got, want);
            assert_eq!(format!("{rmse:.6e}"), "0.000000e0");
        }
    }
}
