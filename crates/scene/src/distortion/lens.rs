//! The lens models and a pinhole camera seen through one (the module docs of
//! [`crate::distortion`] give the equations).

use serde::{Deserialize, Serialize};

use crate::camera::Intrinsics;

/// Distortion of normalised image coordinates (see the module docs for the equations).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Distortion {
    /// Radial polynomial `radial` (`k1..k4` on `r², r⁴, r⁶, r⁸`), rational denominator
    /// `rational` (on `r², r⁴, r⁶`) and tangential `(p1, p2)`.
    RadialTangential {
        radial: [f64; 4],
        rational: [f64; 3],
        tangential: [f64; 2],
    },
    /// Equidistant fisheye `k1..k4` on `θ², θ⁴, θ⁶, θ⁸`.
    Fisheye { k: [f64; 4] },
}

/// As OpenCV names the coefficients: `OpenCV k1=0.06 k2=-0.08 p1=0.001 p2=0.001` (zero terms
/// beyond `k2` left out; `k4..k6` are the rational denominator's), `fisheye k1=… k2=… k3=… k4=…`.
impl std::fmt::Display for Distortion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Distortion::RadialTangential {
                radial,
                rational,
                tangential,
            } => {
                write!(f, "OpenCV k1={} k2={}", radial[0], radial[1])?;
                write!(f, " p1={} p2={}", tangential[0], tangential[1])?;
                let extra = [("k3", radial[2]), ("k4", rational[0]), ("k5", rational[1])];
                let extra = extra.into_iter().chain([("k6", rational[2])]);
                for (name, v) in extra.filter(|&(_, v)| v != 0.0) {
                    write!(f, " {name}={v}")?;
                }
                Ok(())
            }
            Distortion::Fisheye { k } => {
                write!(f, "fisheye k1={} k2={} k3={} k4={}", k[0], k[1], k[2], k[3])
            }
        }
    }
}

/// Newton iterations before undistortion gives up (COLMAP uses 100 too).
const MAX_ITERATIONS: usize = 100;

impl Distortion {
    /// A radial–tangential lens from OpenCV's coefficient vector `(k1, k2, p1, p2[, k3[, k4, k5,
    /// k6]])`.
    pub fn opencv(coeffs: &[f64]) -> Self {
        let c = |i: usize| coeffs.get(i).copied().unwrap_or(0.0);
        Distortion::RadialTangential {
            radial: [c(0), c(1), c(4), 0.0],
            rational: [c(5), c(6), c(7)],
            tangential: [c(2), c(3)],
        }
    }

    /// Whether the lens is an ideal pinhole: a radial–tangential one with every coefficient
    /// zero. A fisheye never is (with zero coefficients it is the equidistant projection).
    pub fn is_identity(&self) -> bool {
        matches!(self, Distortion::RadialTangential { .. })
            && self.coefficients().iter().all(|&v| v == 0.0)
    }

    /// The coefficients, for hashing and checks.
    pub fn coefficients(&self) -> Vec<f64> {
        match self {
            Distortion::RadialTangential {
                radial,
                rational,
                tangential,
            } => radial
                .iter()
                .chain(rational)
                .chain(tangential)
                .copied()
                .collect(),
            Distortion::Fisheye { k } => k.to_vec(),
        }
    }

    /// The radial scale `s(r²)` of the radial–tangential model and its derivative in `r²`.
    #[inline]
    fn radial_scale(radial: &[f64; 4], rational: &[f64; 3], r2: f64) -> (f64, f64) {
        let [k1, k2, k3, k4] = *radial;
        let [d1, d2, d3] = *rational;
        let num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4)));
        let dnum = k1 + r2 * (2.0 * k2 + r2 * (3.0 * k3 + r2 * 4.0 * k4));
        let den = 1.0 + r2 * (d1 + r2 * (d2 + r2 * d3));
        let dden = d1 + r2 * (2.0 * d2 + r2 * 3.0 * d3);
        (num / den, (dnum * den - num * dden) / (den * den))
    }

    /// `θ_d(θ)` of the fisheye model and its derivative.
    fn fisheye_angle(k: &[f64; 4], theta: f64) -> (f64, f64) {
        let t2 = theta * theta;
        let poly = 1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3])));
        let dpoly = t2 * (3.0 * k[0] + t2 * (5.0 * k[1] + t2 * (7.0 * k[2] + t2 * 9.0 * k[3])));
        (theta * poly, 1.0 + dpoly)
    }

    /// The distorted normalised coordinates of the ideal ones `(x, y)`.
    // Inlined, with `distort_with_jacobian` and `radial_scale`, so that per-pixel callers in
    // other crates drop the Jacobian they do not use.
    #[inline]
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        self.distort_with_jacobian(x, y).0
    }

    /// The distorted point and the 2×2 Jacobian `∂(x_d, y_d)/∂(x, y)` (row-major).
    #[inline]
    pub fn distort_with_jacobian(&self, x: f64, y: f64) -> ((f64, f64), [f64; 4]) {
        match self {
            Distortion::RadialTangential {
                radial,
                rational,
                tangential,
            } => {
                let [p1, p2] = *tangential;
                let r2 = x * x + y * y;
                let (s, ds) = Self::radial_scale(radial, rational, r2);
                let xd = x * s + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
                let yd = y * s + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
                let cross = 2.0 * x * y * ds + 2.0 * p1 * x + 2.0 * p2 * y;
                let j = [
                    s + 2.0 * x * x * ds + 2.0 * p1 * y + 6.0 * p2 * x,
                    cross,
                    cross,
                    s + 2.0 * y * y * ds + 6.0 * p1 * y + 2.0 * p2 * x,
                ];
                ((xd, yd), j)
            }
            Distortion::Fisheye { k } => {
                let r2 = x * x + y * y;
                let r = r2.sqrt();
                if r < 1e-12 {
                    // θ_d/r → 1 at the axis.
                    return ((x, y), [1.0, 0.0, 0.0, 1.0]);
                }
                let theta = r.atan();
                let (td, dtd) = Self::fisheye_angle(k, theta);
                let g = td / r;
                // d(θ_d/r)/dr = (θ_d'(θ)·θ'(r)·r − θ_d) / r², θ'(r) = 1/(1 + r²).
                let dg = (dtd / (1.0 + r2) * r - td) / r2;
                let (ux, uy) = (x / r, y / r);
                let j = [
                    g + dg * r * ux * ux,
                    dg * r * ux * uy,
                    dg * r * ux * uy,
                    g + dg * r * uy * uy,
                ];
                ((g * x, g * y), j)
            }
        }
    }

    /// The ideal normalised coordinates whose distortion is `(xd, yd)`, or `None` when the
    /// iteration does not converge (the point lies where the lens does not invert).
    pub fn undistort(&self, xd: f64, yd: f64) -> Option<(f64, f64)> {
        match self {
            Distortion::Fisheye { k } => {
                let td = (xd * xd + yd * yd).sqrt();
                if td < 1e-15 {
                    return Some((xd, yd));
                }
                let mut theta = td.min(1.5);
                for _ in 0..MAX_ITERATIONS {
                    let (f, df) = Self::fisheye_angle(k, theta);
                    if df <= 0.0 {
                        return None;
                    }
                    let step = (f - td) / df;
                    theta -= step;
                    if step.abs() < 1e-15 * theta.abs().max(1e-300) {
                        break;
                    }
                }
                let (f, _) = Self::fisheye_angle(k, theta);
                let half_pi = std::f64::consts::FRAC_PI_2;
                if !(theta >= 0.0 && theta < half_pi) || (f - td).abs() > 1e-12 * (1.0 + td) {
                    return None;
                }
                let scale = theta.tan() / td;
                Some((xd * scale, yd * scale))
            }
            Distortion::RadialTangential { .. } => {
                let (mut x, mut y) = (xd, yd);
                for _ in 0..MAX_ITERATIONS {
                    let ((fx, fy), j) = self.distort_with_jacobian(x, y);
                    let (ex, ey) = (fx - xd, fy - yd);
                    let det = j[0] * j[3] - j[1] * j[2];
                    if !det.is_finite() || det.abs() < 1e-300 {
                        return None;
                    }
                    let sx = (j[3] * ex - j[1] * ey) / det;
                    let sy = (-j[2] * ex + j[0] * ey) / det;
                    x -= sx;
                    y -= sy;
                    if sx.abs().max(sy.abs()) < 1e-15 * (1.0 + x.abs().max(y.abs())) {
                        break;
                    }
                }
                let (fx, fy) = self.distort(x, y);
                let err = (fx - xd).abs().max((fy - yd).abs());
                (x.is_finite() && y.is_finite() && err < 1e-10 * (1.0 + xd.abs().max(yd.abs())))
                    .then_some((x, y))
            }
        }
    }

    /// The radius mapping along a ray from the axis, `r ↦ r_d` (tangential terms left out) and
    /// its derivative, for the invertibility check. For the fisheye, `r` is the angle `θ`.
    fn radial_profile(&self, r: f64) -> (f64, f64) {
        match self {
            Distortion::RadialTangential {
                radial, rational, ..
            } => {
                let (s, ds) = Self::radial_scale(radial, rational, r * r);
                (r * s, s + 2.0 * r * r * ds)
            }
            Distortion::Fisheye { k } => Self::fisheye_angle(k, r),
        }
    }
}

/// A real camera: pinhole intrinsics (focal lengths and principal point in pixels, in the
/// crate's half-integer pixel convention) and the lens distortion, if any.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LensCamera {
    pub intrinsics: Intrinsics,
    /// `None` for an ideal pinhole (every coefficient zero).
    pub distortion: Option<Distortion>,
}

impl LensCamera {
    /// A camera from intrinsics and a distortion; an all-zero distortion becomes `None`.
    pub fn new(intrinsics: Intrinsics, distortion: Option<Distortion>) -> Self {
        Self {
            intrinsics,
            distortion: distortion.filter(|d| !d.is_identity()),
        }
    }

    /// The pixel where a lens with this distortion images what an ideal pinhole with the same
    /// intrinsics images at `(u, v)`.
    pub fn distort_pixel(&self, u: f64, v: f64) -> (f64, f64) {
        let k = &self.intrinsics;
        let (x, y) = ((u - k.cx) / k.fx, (v - k.cy) / k.fy);
        let (xd, yd) = match &self.distortion {
            Some(d) => d.distort(x, y),
            None => (x, y),
        };
        (k.fx * xd + k.cx, k.fy * yd + k.cy)
    }

    /// The ideal (pinhole, same intrinsics) pixel of the distorted pixel `(u, v)`, or `None`
    /// where the lens does not invert.
    pub fn undistort_pixel(&self, u: f64, v: f64) -> Option<(f64, f64)> {
        let (x, y) = self.undistort_normalized(u, v)?;
        let k = &self.intrinsics;
        Some((k.fx * x + k.cx, k.fy * y + k.cy))
    }

    /// The normalised ideal coordinates `(x/z, y/z)` seen at the distorted pixel `(u, v)`.
    pub fn undistort_normalized(&self, u: f64, v: f64) -> Option<(f64, f64)> {
        let k = &self.intrinsics;
        let (xd, yd) = ((u - k.cx) / k.fx, (v - k.cy) / k.fy);
        match &self.distortion {
            Some(d) => d.undistort(xd, yd),
            None => Some((xd, yd)),
        }
    }

    /// Checks that the lens maps the whole image one-to-one: the radius mapping rises
    /// monotonically from the axis to beyond the farthest image corner (for a fisheye, before
    /// 90° from the axis, since a pinhole image cannot hold a field of view of 180° or more),
    /// and every border pixel undistorts. The error is one line saying what fails.
    pub fn check_invertible(&self) -> std::result::Result<(), String> {
        let Some(d) = &self.distortion else {
            return Ok(());
        };
        let k = &self.intrinsics;
        let (w, h) = (k.width as f64, k.height as f64);
        let corner = [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)]
            .iter()
            .map(|&(u, v)| ((u - k.cx) / k.fx).hypot((v - k.cy) / k.fy))
            .fold(0.0f64, f64::max);
        let fisheye = matches!(d, Distortion::Fisheye { .. });
        let limit = if fisheye {
            std::f64::consts::FRAC_PI_2
        } else {
            // Far beyond any lens COLMAP or OpenCV calibrate (about 175° across).
            25.0
        };
        let steps = 20_000;
        let mut reached = false;
        for i in 1..=steps {
            let r = limit * i as f64 / steps as f64;
            let (rd, slope) = d.radial_profile(r);
            if rd >= corner * 1.0001 {
                reached = true;
                break;
            }
            if slope.is_nan() || slope <= 0.0 {
                let what = if fisheye { "θ" } else { "r" };
                return Err(format!(
                    "the lens distortion does not invert inside the image: its radius mapping turns back at {what} = {r:.4} before reaching the image corner (distorted radius {corner:.4})"
                ));
            }
        }
        if !reached {
            return Err(if fisheye {
                format!(
                    "the fisheye image reaches 90° from the optical axis (a field of view of 180° or more; corner at θ_d = {corner:.4}), which no pinhole image can hold"
                )
            } else {
                format!(
                    "the lens distortion does not invert inside the image: no undistorted radius maps to the image corner (distorted radius {corner:.4})"
                )
            });
        }
        let border = (0..=k.width)
            .flat_map(|x| [(x as f64, 0.0), (x as f64, h)])
            .chain((0..=k.height).flat_map(|y| [(0.0, y as f64), (w, y as f64)]));
        for (u, v) in border {
            if self.undistort_normalized(u, v).is_none() {
                return Err(format!(
                    "the lens distortion does not invert at pixel ({u}, {v}) of the image"
                ));
            }
        }
        Ok(())
    }
}
