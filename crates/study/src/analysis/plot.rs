//! The ranking plot: each method's posterior mean Bradley–Terry skill relative to the average
//! method (see [`super::SkillSummary::relative_mean`]) with its credible interval,
//! best on top. Drawn with `plotters` on an in-memory bitmap; the labels use the DejaVu Sans Mono
//! font embedded in the binary (`assets/`, Bitstream Vera licence), so no system font or
//! fontconfig is needed.

use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;

use super::results::QuestionAnalysis;
use crate::error::{Result, StudyError};

const FONT: &[u8] = include_bytes!("../../assets/DejaVuSansMono.ttf");
const FAMILY: &str = "fewview-mono";

fn register_font() -> Result<()> {
    static ONCE: Once = Once::new();
    let mut ok = true;
    ONCE.call_once(|| {
        ok = plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok();
    });
    if ok {
        Ok(())
    } else {
        Err(StudyError::invalid("embedded plot font failed to load"))
    }
}

/// Draws the ranking of one question to a PNG file (atomically).
pub fn ranking_plot(q: &QuestionAnalysis, path: &Path) -> Result<()> {
    register_font()?;
    let bt = &q.bradley_terry;
    let order = bt.ranking();
    let k = order.len();
    let (width, height) = (900u32, 160 + 60 * k as u32);
    let mut buffer = vec![0u8; (width * height * 3) as usize];
    let lo = bt
        .skills
        .iter()
        .map(|s| s.relative_lower)
        .fold(f64::INFINITY, f64::min);
    let hi = bt
        .skills
        .iter()
        .map(|s| s.relative_upper)
        .fold(f64::NEG_INFINITY, f64::max);
    let pad = 0.1 * (hi - lo).max(1e-3);
    let draw_err = |e: &dyn std::fmt::Display| StudyError::invalid(format!("plot: {e}"));
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_err(&e))?;
        let caption = format!(
            "{}: Bradley-Terry skill vs. the average method, mean and {:.0}% CrI",
            q.question,
            100.0 * bt.settings.credible_mass
        );
        let labels: Vec<String> = order.iter().map(|&i| bt.methods[i].clone()).collect();
        let mut chart = ChartBuilder::on(&root)
            .caption(caption, (FAMILY, 22))
            .margin(20)
            .x_label_area_size(50)
            .y_label_area_size(200)
            .build_cartesian_2d((lo - pad)..(hi + pad), -0.5f64..(k as f64 - 0.5))
            .map_err(|e| draw_err(&e))?;
        chart
            .configure_mesh()
            .disable_y_mesh()
            .y_labels(k)
            .y_label_formatter(&|v: &f64| {
                let i = v.round();
                if (v - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < k {
                    // Row 0 at the bottom: the best method is drawn at the top.
                    labels[k - 1 - i as usize].clone()
                } else {
                    String::new()
                }
            })
            .x_desc("relative skill (log-odds vs. the mean of all methods)")
            .label_style((FAMILY, 16))
            .axis_desc_style((FAMILY, 16))
            .draw()
            .map_err(|e| draw_err(&e))?;
        for (rank, &i) in order.iter().enumerate() {
            let y = (k - 1 - rank) as f64;
            let s = &bt.skills[i];
            let colour = Palette99::pick(rank).to_rgba();
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(s.relative_lower, y), (s.relative_upper, y)],
                    colour.stroke_width(3),
                )))
                .map_err(|e| draw_err(&e))?;
            chart
                .draw_series(std::iter::once(Circle::new(
                    (s.relative_mean, y),
                    7,
                    colour.filled(),
                )))
                .map_err(|e| draw_err(&e))?;
        }
        root.present().map_err(|e| draw_err(&e))?;
    }
    let data: Vec<f32> = buffer.iter().map(|&v| v as f32 / 255.0).collect();
    fewview_scene::Image::from_vec(width as usize, height as usize, 3, data).save_png(path)?;
    Ok(())
}
