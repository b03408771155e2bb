//! Rasterizer tests: forward against the naive reference, gradients against central finite
//! differences in `f64`.

use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

use super::inputs::TILE;
use super::render::{OUT_CHANNELS, ParamGradients, backward, forward};
use super::{GaussianRefs, RenderCamera, RenderSettings, reference};

/// A random scene of Gaussians in front of a 40×30 camera (partial edge tiles included).
pub(crate) struct Scene {
    pub means: Vec<f64>,
    pub log_scales: Vec<f64>,
    pub quats: Vec<f64>,
    pub opacity_logits: Vec<f64>,
    pub sh: Vec<f64>,
    pub sh_coeffs: usize,
}

impl Scene {
    pub fn random(seed: u64, n: usize, sh_coeffs: usize) -> Self {
        Self::random_with_opacity(seed, n, sh_coeffs, (-2.0, 1.3))
    }

    /// Like [`Scene::random`] with opacity logits drawn from `logits`.
    pub fn random_with_opacity(seed: u64, n: usize, sh_coeffs: usize, logits: (f64, f64)) -> Self {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.random::<f64>();
        let mut s = Scene {
            means: vec![],
            log_scales: vec![],
            quats: vec![],
            opacity_logits: vec![],
            sh: vec![],
            sh_coeffs,
        };
        for _ in 0..n {
            let z = u(2.0, 5.0);
            s.means.extend([u(-0.6, 0.6) * z, u(-0.45, 0.45) * z, z]);
            s.log_scales
                .extend([u(-2.6, -1.2), u(-2.6, -1.2), u(-2.6, -1.2)]);
            s.quats
                .extend([u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0), u(-1.0, 1.0)]);
            s.opacity_logits.push(u(logits.0, logits.1));
            for k in 0..sh_coeffs * 3 {
                s.sh.push(if k < 3 { u(-1.0, 1.0) } else { u(-0.3, 0.3) });
            }
        }
        s
    }

    pub fn refs(&self) -> GaussianRefs<'_, f64> {
        GaussianRefs {
            means: &self.means,
            log_scales: &self.log_scales,
            quats: &self.quats,
            opacity_logits: &self.opacity_logits,
            sh: &self.sh,
            sh_coeffs: self.sh_coeffs,
        }
    }

    pub fn to_f32(&self) -> [Vec<f32>; 5] {
        let c = |v: &Vec<f64>| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
        [
            c(&self.means),
            c(&self.log_scales),
            c(&self.quats),
            c(&self.opacity_logits),
            c(&self.sh),
        ]
    }
}

/// The parameters of [`Scene::to_f32`] as the rasterizer reads them.
pub(crate) fn f32_refs(arrays: &[Vec<f32>; 5], sh_coeffs: usize) -> GaussianRefs<'_, f32> {
    let [m, s, q, o, sh] = arrays;
    GaussianRefs {
        means: m,
        log_scales: s,
        quats: q,
        opacity_logits: o,
        sh,
        sh_coeffs,
    }
}

/// `g` rendered through the Burn op from [`camera`] over black at SH degree 0: RGB, depth and
/// alpha, `[30, 40, 5]`.
pub(crate) fn render_from_camera(g: &crate::op::GaussianTensors) -> crate::op::RenderTensors {
    let n = g.opacity_logits.dims()[0];
    crate::op::render(
        g,
        burn::tensor::Tensor::<2>::zeros([n, 2], &g.means.device()),
        &crate::op::RenderView {
            camera: camera(),
            settings: RenderSettings {
                background: [0.0; 3],
                sh_degree: 0,
                near_plane: 0.01,
            },
        },
    )
}

/// A camera looking down +z from a slightly rotated pose, 40×30 with an off-centre principal point.
pub(crate) fn camera() -> RenderCamera {
    let (a, b) = (0.05f64, -0.03f64);
    let (ca, sa, cb, sb) = (a.cos(), a.sin(), b.cos(), b.sin());
    // R = Rx(a) · Ry(b)
    let rotation = [
        [cb, 0.0, sb],
        [sa * sb, ca, -sa * cb],
        [-ca * sb, sa, ca * cb],
    ];
    RenderCamera {
        fx: 36.0,
        fy: 35.0,
        cx: 20.5,
        cy: 14.7,
        width: 40,
        height: 30,
        rotation,
        translation: [0.05, -0.02, 0.1],
    }
}

pub(crate) fn settings() -> RenderSettings {
    RenderSettings {
        background: [0.2, 0.5, 0.9],
        sh_degree: 3,
        near_plane: 0.2,
    }
}

#[test]
fn forward_f32_matches_naive_reference() {
    // Seeds 0–1: translucent; 2–3: dense and nearly opaque, so the 0.99 alpha clamp and the
    // T < 1e-4 early stop both occur.
    for seed in 0..4 {
        let logits = if seed < 2 { (-2.0, 1.3) } else { (2.0, 8.0) };
        let scene = Scene::random_with_opacity(seed, 150, 16, logits);
        let cam = camera();
        let reference = reference::render(&scene.refs(), &cam, &settings());
        let arrays = scene.to_f32();
        let (out, _) = forward(&f32_refs(&arrays, 16), &cam, &settings());
        let max_depth = reference.chunks(5).map(|p| p[3]).fold(0.0, f64::max);
        let mut worst = [0.0f64; 5];
        for (a, b) in out
            .data
            .iter()
            .zip(&reference)
            .enumerate()
            .map(|(i, (a, b))| (i, (*a as f64 - b).abs()))
        {
            worst[a % 5] = worst[a % 5].max(b);
        }
        for ch in [0, 1, 2, 4] {
            assert!(worst[ch] < 1e-5, "seed {seed} channel {ch}: {}", worst[ch]);
        }
        assert!(
            worst[3] < 1e-5 * max_depth,
            "seed {seed} depth: {}",
            worst[3]
        );
        // The scene is not trivial: most pixels are covered.
        let covered = reference.chunks(5).filter(|p| p[4] > 0.5).count();
        assert!(covered > 600, "seed {seed}: only {covered} covered pixels");
        if seed >= 2 {
            let saturated = reference.chunks(5).filter(|p| p[4] > 1.0 - 1e-3).count();
            assert!(
                saturated > 100,
                "seed {seed}: early stop never exercised ({saturated})"
            );
        }
    }
}

#[test]
fn forward_f64_matches_naive_reference_exactly() {
    let scene = Scene::random(7, 80, 9);
    let cam = camera();
    let reference = reference::render(&scene.refs(), &cam, &settings());
    let (out, _) = forward(&scene.refs(), &cam, &settings());
    assert_eq!(out.data.len(), reference.len());
    // Not an empty or blank image: many pixels are covered (alpha is channel 4 of 5).
    let covered = reference
        .chunks(OUT_CHANNELS)
        .filter(|p| p[4] > 0.5)
        .count();
    assert!(covered > 100, "only {covered} covered pixels");
    for (a, b) in out.data.iter().zip(&reference) {
        assert!((a - b).abs() < 1e-10, "{a} vs {b}");
    }
}

/// `L = Σ w ⊙ out` with fixed random weights, so `∂L/∂out = w`.
fn loss(scene: &Scene, cam: &RenderCamera, weights: &[f64]) -> f64 {
    let (out, _) = forward(&scene.refs(), cam, &settings());
    out.data.iter().zip(weights).map(|(a, b)| a * b).sum()
}

fn weights(seed: u64, n: usize) -> Vec<f64> {
    let mut rng = StdRng::seed_from_u64(seed ^ 0xABCD);
    (0..n)
        .map(|i| {
            let w = rng.random::<f64>() * 2.0 - 1.0;
            // Depth is ~3–5× larger than colours; weigh it down so every term matters.
            if i % OUT_CHANNELS == 3 { 0.2 * w } else { w }
        })
        .collect()
}

fn rel_err(a: f64, b: f64, floor: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs()).max(floor)
}

#[test]
fn gradients_match_central_differences() {
    let cam = camera();
    // Seed 3 is nearly opaque: the 0.99 clamp and the early stop are active in many pixels.
    for seed in 0..4 {
        let logits = if seed < 3 { (-2.0, 1.3) } else { (2.0, 8.0) };
        let mut scene = Scene::random_with_opacity(100 + seed, 25, 16, logits);
        let w = weights(seed, cam.num_pixels() * OUT_CHANNELS);
        let (_, ctx) = forward(&scene.refs(), &cam, &settings());
        let grads = backward(&scene.refs(), &ctx, &w);
        let h = 1e-6;
        let mut checked = 0;
        let mut worst = 0.0f64;
        // Every parameter of every Gaussian.
        macro_rules! check {
            ($field:ident, $grad:expr, $name:expr) => {
                for k in 0..scene.$field.len() {
                    let orig = scene.$field[k];
                    scene.$field[k] = orig + h;
                    let lp = loss(&scene, &cam, &w);
                    scene.$field[k] = orig - h;
                    let lm = loss(&scene, &cam, &w);
                    scene.$field[k] = orig;
                    let fd = (lp - lm) / (2.0 * h);
                    let an = $grad[k];
                    let e = rel_err(fd, an, 1e-4);
                    worst = worst.max(e);
                    assert!(
                        e < 1e-3,
                        "seed {seed} {} [{k}]: analytic {an} vs fd {fd}",
                        $name
                    );
                    checked += 1;
                }
            };
        }
        check!(means, grads.means, "means");
        check!(log_scales, grads.log_scales, "log_scales");
        check!(quats, grads.quats, "quats");
        check!(opacity_logits, grads.opacity_logits, "opacity_logits");
        check!(sh, grads.sh, "sh");
        assert!(checked > 25 * 50);
        // The gradients are not trivially zero.
        let norm: f64 = grads.means.iter().map(|g| g * g).sum();
        assert!(norm > 1e-6, "mean gradients vanish");
        eprintln!("seed {seed}: worst relative error {worst:.2e} over {checked} parameters");
    }
}

#[test]
fn screen_space_gradient_matches_principal_point_shift() {
    // Shifting (cx, cy) moves every projected centre by the same amount and nothing else (all
    // centres stay inside the FoV clamp), so ∂L/∂cx = Σᵢ ∂L/∂uᵢ.
    let cam = camera();
    let scene = Scene::random(5, 20, 4);
    let w = weights(5, cam.num_pixels() * OUT_CHANNELS);
    let (_, ctx) = forward(&scene.refs(), &cam, &settings());
    let grads = backward(&scene.refs(), &ctx, &w);
    let h = 1e-6;
    for axis in 0..2 {
        let mut cp = cam.clone();
        let mut cm = cam.clone();
        if axis == 0 {
            cp.cx += h;
            cm.cx -= h;
        } else {
            cp.cy += h;
            cm.cy -= h;
        }
        // Keep the clamp limits of the unshifted camera out of play: all centres are in view.
        let fd = (loss(&scene, &cp, &w) - loss(&scene, &cm, &w)) / (2.0 * h);
        let half = if axis == 0 {
            cam.width as f64 / 2.0
        } else {
            cam.height as f64 / 2.0
        };
        let an: f64 = grads.means2d.iter().skip(axis).step_by(2).sum::<f64>() / half;
        assert!(rel_err(fd, an, 1e-6) < 1e-4, "axis {axis}: {an} vs {fd}");
    }
}

/// A loss that reaches only some tiles: the backward skips the others (fewer pairs), and what it
/// returns is still exact. Split by tiles into two halves, the gradients of the halves add up to
/// the gradient of the whole (the loss is linear in the image) and so do the pairs evaluated.
#[test]
fn tiles_without_gradient_are_skipped_exactly() {
    let cam = camera();
    let scene = Scene::random(9, 30, 4);
    let w = weights(9, cam.num_pixels() * OUT_CHANNELS);
    let (_, ctx) = forward(&scene.refs(), &cam, &settings());
    let tile_of = |p: usize| {
        let (x, y) = (p % cam.width, p / cam.width);
        (x / TILE + y / TILE).is_multiple_of(2)
    };
    let half = |keep: bool| -> Vec<f64> {
        w.iter()
            .enumerate()
            .map(|(i, &v)| {
                if tile_of(i / OUT_CHANNELS) == keep {
                    v
                } else {
                    0.0
                }
            })
            .collect()
    };
    let whole = backward(&scene.refs(), &ctx, &w);
    let (a, b) = (
        backward(&scene.refs(), &ctx, &half(true)),
        backward(&scene.refs(), &ctx, &half(false)),
    );
    assert!(a.pairs > 0 && b.pairs > 0 && a.pairs < whole.pairs);
    assert_eq!(a.pairs + b.pairs, whole.pairs);
    let fields = |g: &ParamGradients<f64>| {
        [
            &g.means,
            &g.log_scales,
            &g.quats,
            &g.opacity_logits,
            &g.sh,
            &g.means2d,
        ]
        .map(Clone::clone)
    };
    for ((wf, af), bf) in fields(&whole).iter().zip(fields(&a)).zip(fields(&b)) {
        for ((x, y), z) in wf.iter().zip(&af).zip(&bf) {
            assert!(rel_err(*x, y + z, 1e-9) < 1e-9, "{x} vs {y} + {z}");
        }
    }
}
