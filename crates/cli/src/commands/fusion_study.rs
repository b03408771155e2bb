//! `fewview fusion --study`: the transition videos of finished runs as a pairwise study.

use std::path::{Path, PathBuf};

use anyhow::Context;

/// The study configuration `fewview study serve` reads (see `fewview_study::config`).
#[derive(serde::Serialize)]
struct StudyFile {
    title: String,
    seed: u64,
    database: String,
    methods: Vec<String>,
    scenes: Vec<String>,
    questions: Vec<fewview_study::config::Question>,
    videos: std::collections::BTreeMap<String, std::collections::BTreeMap<String, String>>,
}

pub fn write_study(runs: &[PathBuf], out: &Path) -> anyhow::Result<()> {
    // Every check happens here, before anything is written.
    let plan = fewview_fusion::study::plan_study(runs)?;
    let folder = PathBuf::from("videos").join(&plan.scene);
    std::fs::create_dir_all(out.join(&folder))
        .with_context(|| format!("cannot create {}", out.join(&folder).display()))?;
    let mut videos = std::collections::BTreeMap::new();
    for (method, video) in &plan.videos {
        let relative = folder.join(format!("{method}.mp4"));
        std::fs::copy(video, out.join(&relative))
            .with_context(|| format!("cannot copy {}", video.display()))?;
        videos.insert(method.clone(), relative.to_string_lossy().into_owned());
    }
    let file = StudyFile {
        title: format!("View transitions on {}", plan.scene),
        seed: 0,
        database: "responses.sqlite".into(),
        methods: plan.videos.iter().map(|(m, _)| m.clone()).collect(),
        scenes: vec![plan.scene.clone()],
        questions: fewview_study::config::paper_questions(),
        videos: [(plan.scene.clone(), videos)].into_iter().collect(),
    };
    let config = out.join("study.toml");
    std::fs::write(&config, toml::to_string_pretty(&file)?)
        .with_context(|| format!("cannot write {}", config.display()))?;
    println!(
        "study            {} methods on {}",
        plan.videos.len(),
        plan.scene
    );
    println!(
        "serve it with    fewview study serve --config {}",
        config.display()
    );
    Ok(())
}
