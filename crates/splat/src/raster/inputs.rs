//! What one render reads besides the Gaussians' values: the camera, the settings, the
//! borrowed parameter arrays, and the rasterizer's constants (those of the reference CUDA
//! rasterizer of "3D Gaussian Splatting for Real-Time Radiance Field Rendering").

/// Tile edge in pixels.
pub const TILE: usize = 16;
/// Upper clamp of a Gaussian's alpha (keeps `1 − α` invertible in the backward pass).
pub const ALPHA_MAX: f64 = 0.99;
/// Contributions below this alpha are skipped.
pub const ALPHA_MIN: f64 = 1.0 / 255.0;
/// Blending stops before the transmittance would drop below this.
pub const T_MIN: f64 = 1e-4;
/// Screen-space low-pass filter added to the 2D covariance diagonal (px²).
pub const DILATION: f64 = 0.3;
/// Projected centres are clamped to this multiple of the half field of view when building the
/// EWA Jacobian (as the reference code), so Gaussians far outside the view stay well-conditioned.
pub const FOV_CLAMP: f64 = 1.3;

/// A pinhole camera as the rasterizer needs it (world-to-camera, OpenCV axes, pixel centres at
/// half-integers).
#[derive(Clone, Debug, PartialEq)]
pub struct RenderCamera {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub width: usize,
    pub height: usize,
    /// World-to-camera rotation, row-major.
    pub rotation: [[f64; 3]; 3],
    pub translation: [f64; 3],
}

impl RenderCamera {
    /// The camera centre in world coordinates, `-Rᵀ t`.
    pub fn center(&self) -> [f64; 3] {
        let r = &self.rotation;
        let t = &self.translation;
        let mut c = [0.0; 3];
        for (j, cj) in c.iter_mut().enumerate() {
            *cj = -(r[0][j] * t[0] + r[1][j] * t[1] + r[2][j] * t[2]);
        }
        c
    }

    pub fn num_pixels(&self) -> usize {
        self.width * self.height
    }

    pub fn tiles_x(&self) -> usize {
        self.width.div_ceil(TILE)
    }

    pub fn tiles_y(&self) -> usize {
        self.height.div_ceil(TILE)
    }
}

impl From<&fewview_scene::Camera> for RenderCamera {
    fn from(c: &fewview_scene::Camera) -> Self {
        let k = &c.intrinsics;
        let r = &c.world_to_camera.rotation;
        let t = &c.world_to_camera.translation;
        Self {
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            width: k.width as usize,
            height: k.height as usize,
            rotation: [
                [r[(0, 0)], r[(0, 1)], r[(0, 2)]],
                [r[(1, 0)], r[(1, 1)], r[(1, 2)]],
                [r[(2, 0)], r[(2, 1)], r[(2, 2)]],
            ],
            translation: [t[0], t[1], t[2]],
        }
    }
}

/// Options of one render that are not Gaussian parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// Colour behind the Gaussians (`C + T·bg`).
    pub background: [f32; 3],
    /// SH degree in use (≤ the degree the coefficients were allocated for).
    pub sh_degree: usize,
    /// Gaussians whose centre is closer than this (camera z) are culled; 0.2 as the reference code.
    pub near_plane: f64,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            background: [0.0; 3],
            sh_degree: 3,
            near_plane: 0.2,
        }
    }
}

/// Borrowed Gaussian parameters, flat and pre-activation, in the Inria PLY layout:
/// `means` N×3, `log_scales` N×3, `quats` N×4 (w, x, y, z; need not be normalised),
/// `opacity_logits` N, `sh` N×K×3 (coefficient-major, channel-minor; K = `sh_coeffs`).
#[derive(Clone, Copy, Debug)]
pub struct GaussianRefs<'a, F> {
    pub means: &'a [F],
    pub log_scales: &'a [F],
    pub quats: &'a [F],
    pub opacity_logits: &'a [F],
    pub sh: &'a [F],
    pub sh_coeffs: usize,
}

impl<F> GaussianRefs<'_, F> {
    pub fn len(&self) -> usize {
        self.opacity_logits.len()
    }

    pub fn is_empty(&self) -> bool {
        self.opacity_logits.is_empty()
    }

    /// Checks that every array has the length N implies.
    pub fn check_shapes(&self) -> Result<(), String> {
        let n = self.len();
        let checks = [
            ("means", self.means.len(), n * 3),
            ("log_scales", self.log_scales.len(), n * 3),
            ("quats", self.quats.len(), n * 4),
            ("sh", self.sh.len(), n * self.sh_coeffs * 3),
        ];
        for (name, got, want) in checks {
            if got != want {
                return Err(format!(
                    "{name} has {got} values, expected {want} for {n} Gaussians"
                ));
            }
        }
        if !(1..=16).contains(&self.sh_coeffs)
            || crate::sh::num_coeffs(sh_degree_of(self.sh_coeffs)) != self.sh_coeffs
        {
            return Err(format!(
                "{} SH coefficients per channel is not (d+1)² for d ≤ 3",
                self.sh_coeffs
            ));
        }
        Ok(())
    }
}

/// The SH degree whose coefficient count is `k` (`k = (d+1)²`), rounding down.
pub fn sh_degree_of(k: usize) -> usize {
    match k {
        0..=3 => 0,
        4..=8 => 1,
        9..=15 => 2,
        _ => 3,
    }
}
