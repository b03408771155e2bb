//! The files `fewview human eval` writes from an [`EvalReport`]: `table.md` (the runs, how each
//! was trained, and the novel-view, novel-pose and 3DGS-per-frame tables), `metrics.json` (the
//! report) and `side_by_side.mp4` (truth, ours and each baseline on the first target camera).

use std::path::Path;

use fewview_scene::Image;

use crate::depth::{DepthInput, StereoSettings};
use crate::error::{HumanError, Result};
use crate::eval::{EvalReport, Renders, RunInfo, side_by_side, table};

/// What the tables were scored on, for their headings.
#[derive(Clone, Debug)]
pub struct TableContext {
    /// The input cameras predicted from their neighbours on training frames.
    pub validation: bool,
    pub test_frames: std::ops::Range<usize>,
    /// The frames of the 3DGS-per-frame table, when there is one.
    pub splat_frames: Option<std::ops::Range<usize>>,
}

/// One line per run: its name, depth input, pose input and training steps.
pub fn runs_table(runs: &[RunInfo]) -> String {
    let mut s = String::from("| run | depth input | pose | steps |\n|---|---|---|---|\n");
    for r in runs {
        let pose = if r.use_pose { "yes" } else { "no (per-frame)" };
        let depth = depth_cell(r);
        s += &format!("| {} | {depth} | {pose} | {} |\n", r.name, r.iterations);
    }
    s
}

/// The depth input's name, with the stereo settings and the depth head's bracket where they
/// differ from the defaults, e.g. `stereo (dense, search −30/+60 cm, head −30/+30 cm)`.
fn depth_cell(r: &RunInfo) -> String {
    let cm = |front: f64, behind: f64| format!("−{:.0}/+{:.0} cm", 100.0 * front, 100.0 * behind);
    let mut notes = Vec::new();
    let name = match r.depth {
        DepthInput::Stereo => {
            let (s, default) = (&r.stereo, StereoSettings::default());
            if s.checks != default.checks {
                notes.push(format!("{:?}", s.checks).to_lowercase());
            }
            if (s.hull_front, s.hull_behind) != (default.hull_front, default.hull_behind) {
                notes.push(format!("search {}", cm(s.hull_front, s.hull_behind)));
            }
            "stereo"
        }
        DepthInput::Hull => "hull",
        DepthInput::Dataset => "dataset",
    };
    if r.bracket != r.depth.bracket() {
        let b = r.bracket;
        notes.push(format!("head {}", cm(b.front as f64, b.behind as f64)));
    }
    if notes.is_empty() {
        name.to_string()
    } else {
        format!("{name} ({})", notes.join(", "))
    }
}

/// `table.md`'s text.
pub fn markdown(report: &EvalReport, context: &TableContext) -> String {
    let (first, last) = (report.frames.start, report.frames.end.saturating_sub(1));
    let runs = runs_table(&report.runs);
    let mut md = if context.validation {
        format!(
            "{runs}\nValidation: input cameras {:?} from their neighbours, frames {first}..={last}\n\n{}",
            report.cameras,
            table(&report.novel_view)
        )
    } else {
        format!(
            "{runs}\nNovel views (cameras {:?}, frames {first}..={last})\n\n{}\nNovel poses (frames {}..={})\n\n{}",
            report.cameras,
            table(&report.novel_view),
            context.test_frames.start,
            context.test_frames.end.saturating_sub(1),
            table(&report.novel_pose)
        )
    };
    if let Some(r) = context
        .splat_frames
        .as_ref()
        .filter(|_| !report.splat_frames.is_empty())
    {
        md += &format!(
            "\n3DGS per frame and every method on its frames ({}..={})\n\n{}",
            r.start,
            r.end.saturating_sub(1),
            table(&report.splat_frames)
        );
    }
    md
}

/// Writes `table.md`, `metrics.json` and `side_by_side.mp4` into `out` (which exists); returns
/// the table's text.
pub fn write(
    out: &Path,
    report: &EvalReport,
    context: &TableContext,
    renders: &Renders,
    truths: &[Vec<Image>],
) -> Result<String> {
    let md = markdown(report, context);
    let put = |name: &str, text: &str| {
        let path = out.join(name);
        std::fs::write(&path, text).map_err(|e| HumanError::io(&path, e))
    };
    put("table.md", &md)?;
    put(
        "metrics.json",
        &serde_json::to_string_pretty(report).expect("the report serialises"),
    )?;
    let frames = truths.first().map_or(0, Vec::len);
    let video: Vec<Image> = (0..frames)
        .map(|t| {
            let mut cols = vec![&truths[0][t]];
            cols.extend(
                renders
                    .iter()
                    .filter(|(n, _)| n != "ours, no TPS" || renders.len() == 1)
                    .map(|(_, r)| &r[0][t]),
            );
            side_by_side(&cols)
        })
        .collect();
    let path = out.join("side_by_side.mp4");
    let opts = fewview_video::VideoOptions::default();
    fewview_video::write_video(&path, &video, 30.0, &opts)
        .map_err(|e| HumanError::argument(path.display().to_string(), e.to_string()))?;
    Ok(md)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::depth::{DepthBracket, StereoChecks};

    fn run(depth: DepthInput) -> RunInfo {
        RunInfo {
            name: "r".into(),
            depth,
            stereo: StereoSettings::default(),
            bracket: depth.bracket(),
            use_pose: true,
            iterations: 7,
        }
    }

    #[test]
    fn the_runs_table_names_settings_only_where_they_differ() {
        let dense = RunInfo {
            stereo: StereoSettings {
                checks: StereoChecks::Dense,
                hull_front: 0.3,
                hull_behind: 0.6,
                ..StereoSettings::default()
            },
            bracket: DepthBracket {
                front: 0.3,
                behind: 0.3,
            },
            ..run(DepthInput::Stereo)
        };
        let table = runs_table(&[run(DepthInput::Stereo), run(DepthInput::Hull), dense]);
        let rows: Vec<&str> = table.lines().skip(2).collect();
        assert_eq!(
            rows,
            [
                "| r | stereo | yes | 7 |",
                "| r | hull | yes | 7 |",
                "| r | stereo (dense, search −30/+60 cm, head −30/+30 cm) | yes | 7 |",
            ]
        );
    }
}
