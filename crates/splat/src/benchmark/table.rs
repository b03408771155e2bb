//! The benchmark's table: per scene the mean over its seeds, the mean over the scenes, and the
//! peers' published means beside them, as Markdown and JSON.

use std::fmt::Write as _;
use std::path::Path;

use serde::Serialize;

use super::error::BenchmarkError;
use super::protocol::{Peer, Protocol};
use super::score::SeedScore;

/// Means over a set of runs.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Means {
    pub psnr: f64,
    pub ssim: f64,
    /// Present when every run was scored by ST-LPIPS.
    pub lpips: Option<f64>,
    pub gaussians: f64,
    pub train_seconds: f64,
    pub runs: usize,
}

impl Means {
    fn of<'a>(scores: impl Iterator<Item = &'a SeedScore> + Clone) -> Option<Self> {
        let n = scores.clone().count();
        if n == 0 {
            return None;
        }
        let mean = |f: &dyn Fn(&SeedScore) -> f64| scores.clone().map(f).sum::<f64>() / n as f64;
        let lpips: Option<Vec<f64>> = scores.clone().map(|s| s.lpips).collect();
        Some(Self {
            psnr: mean(&|s| s.psnr),
            ssim: mean(&|s| s.ssim),
            lpips: lpips.map(|l| l.iter().sum::<f64>() / n as f64),
            gaussians: mean(&|s| s.gaussians as f64),
            train_seconds: mean(&|s| s.train_seconds),
            runs: n,
        })
    }
}

/// One scene's runs and their means.
#[derive(Clone, Debug, Serialize)]
pub struct SceneRow {
    pub scene: String,
    pub seeds: Vec<SeedScore>,
    pub mean: Means,
}

/// The whole table.
#[derive(Clone, Debug, Serialize)]
pub struct Table {
    pub protocol: Protocol,
    pub seeds: Vec<u64>,
    pub scenes: Vec<SceneRow>,
    /// The mean of the scenes' means, over the scenes whose every seed has run.
    pub mean: Option<Means>,
    pub peers: &'static [Peer],
}

impl Table {
    pub fn new(protocol: Protocol, seeds: &[u64]) -> Self {
        Self {
            protocol,
            seeds: seeds.to_vec(),
            scenes: Vec::new(),
            mean: None,
            peers: protocol.peers(),
        }
    }

    /// Sets `scene`'s runs (replacing earlier ones) and updates the means.
    pub fn set(&mut self, scene: &str, seeds: Vec<SeedScore>) {
        let Some(mean) = Means::of(seeds.iter()) else {
            return;
        };
        let row = SceneRow {
            scene: scene.to_string(),
            seeds,
            mean,
        };
        match self.scenes.iter_mut().find(|r| r.scene == scene) {
            Some(r) => *r = row,
            None => self.scenes.push(row),
        }
        let complete: Vec<SeedScore> = self
            .scenes
            .iter()
            .filter(|r| r.seeds.len() == self.seeds.len())
            .map(|r| SeedScore {
                seed: 0,
                psnr: r.mean.psnr,
                ssim: r.mean.ssim,
                lpips: r.mean.lpips,
                gaussians: r.mean.gaussians.round() as usize,
                train_seconds: r.mean.train_seconds,
            })
            .collect();
        let runs = self
            .scenes
            .iter()
            .filter(|r| r.seeds.len() == self.seeds.len())
            .map(|r| r.mean.runs)
            .sum();
        self.mean = Means::of(complete.iter()).map(|m| Means { runs, ..m });
    }

    /// Writes `benchmark.json` and `benchmark.md` in `out`, atomically.
    pub fn write(&self, out: &Path) -> Result<(), BenchmarkError> {
        let json = serde_json::to_vec_pretty(self).expect("the table serialises");
        let write = |name: &str, bytes: &[u8]| {
            fewview_scene::atomic::write_bytes(&out.join(name), bytes)
                .map_err(|e| BenchmarkError::Pipeline(e.into()))
        };
        write("benchmark.json", &json)?;
        write("benchmark.md", self.markdown().as_bytes())
    }

    /// The table as Markdown: ours per scene and mean, then the peers'.
    pub fn markdown(&self) -> String {
        let seeds: Vec<String> = self.seeds.iter().map(u64::to_string).collect();
        let mut md = format!(
            "# Sparse-view benchmark: {}\n\nfewview with seeds {}; each row is the mean over the \
             seeds. LPIPS here is ST-LPIPS (AlexNet, shift-tolerant): the original LPIPS \
             backbones cannot be fetched, so it is not the peers' LPIPS.\n\n\
             | scene | PSNR (dB) | SSIM | ST-LPIPS | Gaussians | training (s) | runs |\n\
             |---|---|---|---|---|---|---|\n",
            self.protocol.name(),
            seeds.join(", ")
        );
        let row = |md: &mut String, name: &str, m: &Means| {
            let lpips = m.lpips.map_or("–".into(), |l| format!("{l:.3}"));
            let _ = writeln!(
                md,
                "| {name} | {:.2} | {:.3} | {lpips} | {:.0} | {:.0} | {} |",
                m.psnr, m.ssim, m.gaussians, m.train_seconds, m.runs
            );
        };
        for r in &self.scenes {
            row(&mut md, &r.scene, &r.mean);
        }
        if let Some(m) = &self.mean {
            row(&mut md, "**mean**", m);
        }
        md.push_str(
            "\nPublished means over the dataset's scenes (each paper's own LPIPS):\n\n\
             | method | PSNR (dB) | SSIM | LPIPS | source |\n|---|---|---|---|---|\n",
        );
        for p in self.peers {
            let _ = writeln!(
                md,
                "| {} | {:.2} | {:.3} | {:.3} | {} |",
                p.method, p.psnr, p.ssim, p.lpips, p.source
            );
        }
        md
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn score(seed: u64, psnr: f64, lpips: Option<f64>) -> SeedScore {
        SeedScore {
            seed,
            psnr,
            ssim: 0.5 + psnr / 100.0,
            lpips,
            gaussians: 1000 * (seed as usize + 1),
            train_seconds: 10.0,
        }
    }

    /// Scene means over seeds, the overall mean over complete scenes only, LPIPS only when
    /// every run has it.
    #[test]
    fn means_cover_complete_scenes_only() {
        let mut t = Table::new(Protocol::Llff, &[0, 1]);
        t.set(
            "a",
            vec![score(0, 20.0, Some(0.2)), score(1, 22.0, Some(0.1))],
        );
        t.set("b", vec![score(0, 10.0, None)]);
        assert_eq!(t.scenes[0].mean.psnr, 21.0);
        assert!((t.scenes[0].mean.lpips.unwrap() - 0.15).abs() < 1e-12);
        assert_eq!(t.scenes[0].mean.gaussians, 1500.0);
        assert_eq!(t.scenes[1].mean.lpips, None);
        let mean = t.mean.clone().unwrap();
        assert_eq!((mean.psnr, mean.runs), (21.0, 2), "scene b is not complete");
        t.set(
            "b",
            vec![score(0, 10.0, Some(0.3)), score(1, 12.0, Some(0.3))],
        );
        let mean = t.mean.clone().unwrap();
        assert_eq!((mean.psnr, mean.runs), (16.0, 4));
        let md = t.markdown();
        assert!(
            md.contains("| a | 21.00 | 0.710 | 0.150 | 1500 | 10 | 2 |"),
            "{md}"
        );
        assert!(md.contains("| **mean** | 16.00 |"), "{md}");
        assert!(md.contains("| CoR-GS | 20.45 | 0.712 | 0.196 |"), "{md}");
    }
}
