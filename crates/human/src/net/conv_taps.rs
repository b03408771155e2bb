//! A convolution's forward pass, input gradient and weight gradient on the host as one matrix
//! product per kernel tap, without the unfolded (im2col) copy of the input.
//!
//! The zero-padded input is split into its `s × s` stride phases (phase `(py, px)` holds the
//! padded pixels `(s·y + py, s·x + px)`), so that tap `(dy, dx)` of a stride-`s` convolution
//! reads phase `(dy mod s, dx mod s)` shifted by `(⌊dy/s⌋, ⌊dx/s⌋)` with unit stride. With the
//! output's rows widened to the phase width, the shifted phase is a plain strided view, and
//!
//! ```text
//! Y_b       += W(dy, dx) · Phase_b(dy, dx)         (O × pixels, for each tap)
//! dPhase_b  += W(dy, dx)ᵀ · G_b                    (C × pixels, accumulated at the shift)
//! dW(dy, dx) = Σ_b G_b · Phase_b(dy, dx)ᵀ           (O × C)
//! ```
//!
//! are one GEMM each. The widened columns past the output's width are discarded (forward) or
//! carry zero gradient (backward).

use std::cell::RefCell;

use burn::tensor::ops::ConvOptions;
use rayon::prelude::*;

thread_local! {
    /// Scratch buffers kept between calls: fresh multi-megabyte buffers cost the kernel's page
    /// zeroing on every convolution.
    static SCRATCH: RefCell<[Vec<f32>; 2]> = const { RefCell::new([Vec::new(), Vec::new()]) };
}

/// Runs `f` with two zeroed scratch buffers of `len0` and `len1` values. The buffers are taken
/// out of the thread's store while `f` runs, so a nested call (a task rayon runs on this thread
/// while it waits) gets fresh ones instead of a double borrow.
fn with_scratch<R>(
    len0: usize,
    len1: usize,
    f: impl FnOnce(&mut Vec<f32>, &mut Vec<f32>) -> R,
) -> R {
    let [mut a, mut b] = SCRATCH.with_borrow_mut(std::mem::take);
    for (v, len) in [(&mut a, len0), (&mut b, len1)] {
        v.clear();
        v.resize(len, 0.0);
    }
    let r = f(&mut a, &mut b);
    SCRATCH.with_borrow_mut(|s| *s = [a, b]);
    r
}

/// `v`, or zero if it is subnormal (below `f32::MIN_POSITIVE` in magnitude).
///
/// A subnormal operand makes the FPU take a microcode assist on every multiply-add it enters,
/// about a hundred times slower than the normal path, and the network meets many: the pose
/// map's Gaussians, `exp(−d²/2σ²)`, pass through the subnormal range in a ring around every
/// joint, and saturated activations pass subnormal gradients back. The GEMMs read only the
/// phases and the widened gradient, so flushing while copying into them keeps every product on
/// the fast path. The change is below 1.2·10⁻³⁸ per value, far under f32's resolution of any
/// sum the value enters.
#[inline]
fn flush_subnormal(v: f32) -> f32 {
    if v.abs() < f32::MIN_POSITIVE { 0.0 } else { v }
}

/// A strided matrix: element `(row, col)` at `ptr + row·rs + col·cs`.
struct Strided<P> {
    ptr: P,
    rs: usize,
    cs: usize,
}

/// `dst[m × n] = (accumulate ? dst : 0) + lhs[m × k] · rhs[k × n]`, on rayon's threads or on
/// this one as `parallelism` says.
///
/// # Safety
/// Every element the strides reach (`m × n` of `dst`, `m × k` of `lhs`, `k × n` of `rhs`) must
/// lie inside its buffer, and `dst` must not overlap the others.
unsafe fn gemm_on(
    parallelism: gemm::Parallelism,
    [m, n, k]: [usize; 3],
    dst: Strided<*mut f32>,
    accumulate: bool,
    lhs: Strided<*const f32>,
    rhs: Strided<*const f32>,
) {
    // SAFETY: the caller's contract.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.ptr,
            dst.cs as isize,
            dst.rs as isize,
            accumulate,
            lhs.ptr,
            lhs.cs as isize,
            lhs.rs as isize,
            rhs.ptr,
            rhs.cs as isize,
            rhs.rs as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            parallelism,
        );
    }
}

/// The geometry shared by the forward pass and both gradients.
struct Taps {
    b: usize,
    c: usize,
    o: usize,
    h: usize,
    w: usize,
    kh: usize,
    kw: usize,
    s: usize,
    top: usize,
    left: usize,
    ho: usize,
    wo: usize,
    /// Phase width.
    wpp: usize,
    /// Values per phase plane (with a tail for the last taps' widened rows).
    plane: usize,
}

impl Taps {
    fn new([b, c, h, w]: [usize; 4], [o, _, kh, kw]: [usize; 4], options: &ConvOptions<2>) -> Self {
        let [(top, bottom), (left, right)] = options.padding;
        let s = options.stride[0];
        assert_eq!(options.stride[1], s, "equal strides");
        let (hp, wp) = (h + top + bottom, w + left + right);
        let (hpp, wpp) = (hp.div_ceil(s), wp.div_ceil(s));
        Self {
            b,
            c,
            o,
            h,
            w,
            kh,
            kw,
            s,
            top,
            left,
            ho: (hp - kh) / s + 1,
            wo: (wp - kw) / s + 1,
            wpp,
            plane: hpp * wpp + wpp + kw,
        }
    }

    /// Widened output pixels per channel.
    fn pixels(&self) -> usize {
        self.ho * self.wpp
    }

    /// Runs `f` with zeroed scratch for the phases and the widened output (or its gradient).
    fn with_buffers<R>(&self, f: impl FnOnce(&mut Vec<f32>, &mut Vec<f32>) -> R) -> R {
        let phases = self.b * self.s * self.s * self.c * self.plane;
        with_scratch(phases, self.b * self.o * self.pixels(), f)
    }

    /// Start of phase `(py, px)`, channel 0, of batch item `bi`.
    fn phase_base(&self, bi: usize, py: usize, px: usize) -> usize {
        ((bi * self.s + py) * self.s + px) * self.c * self.plane
    }

    /// Where in the phases the padded pixel of input pixel `(y, x)` of channel `ci` lies.
    fn phase_index(&self, bi: usize, ci: usize, y: usize, x: usize) -> usize {
        let (yp, xp) = (y + self.top, x + self.left);
        let base = self.phase_base(bi, yp % self.s, xp % self.s);
        base + ci * self.plane + (yp / self.s) * self.wpp + xp / self.s
    }

    /// The first input column `x` with `(x + left) mod s = px`; the phase's columns are every
    /// `s`-th from it.
    fn first_column(&self, px: usize) -> usize {
        (px + self.s - self.left % self.s) % self.s
    }

    /// Phase base and shift of tap `(dy, dx)`, checked to leave the tap's `C × pixels` view
    /// inside `phases_len` values (the GEMMs read or write it unchecked).
    fn tap(&self, bi: usize, dy: usize, dx: usize, phases_len: usize) -> usize {
        let s = self.s;
        let at = self.phase_base(bi, dy % s, dx % s) + (dy / s) * self.wpp + dx / s;
        assert!(
            at + (self.c - 1) * self.plane + self.pixels() <= phases_len,
            "tap inside the phases"
        );
        at
    }

    /// Weight `(o, c)` of tap `(dy, dx)` is at `tap_weight + o·C·kh·kw + c·kh·kw`.
    fn tap_weight(&self, dy: usize, dx: usize) -> usize {
        dy * self.kw + dx
    }
}

/// The convolution `[B, C, H, W] → [B, O, Ho, Wo]` of `x` with `weight` (`[O, C, kh, kw]`) and
/// `bias`; returns the output and its shape.
pub fn forward_host(
    x: &[f32],
    xs: [usize; 4],
    weight: &[f32],
    ws: [usize; 4],
    bias: &[f32],
    options: &ConvOptions<2>,
) -> (Vec<f32>, [usize; 4]) {
    let t = Taps::new(xs, ws, options);
    t.with_buffers(|phases, wide| {
        t.scatter(x, phases);
        t.forward(weight, phases, wide);
        t.crop_with_bias(wide, bias)
    })
}

impl Taps {
    /// Writes the input `[B, C, H, W]` into its zero-padded stride phases.
    fn scatter(&self, x: &[f32], phases: &mut [f32]) {
        for bc in 0..self.b * self.c {
            let (bi, ci) = (bc / self.c, bc % self.c);
            for y in 0..self.h {
                let row = &x[(bc * self.h + y) * self.w..][..self.w];
                for px in 0..self.s {
                    let Some(src) = row.get(self.first_column(px)..) else {
                        continue;
                    };
                    let count = src.len().div_ceil(self.s);
                    let at = self.phase_index(bi, ci, y, self.first_column(px));
                    let dst = &mut phases[at..][..count];
                    if self.s == 1 {
                        for (d, &v) in dst.iter_mut().zip(src) {
                            *d = flush_subnormal(v);
                        }
                    } else {
                        for (d, &v) in dst.iter_mut().zip(src.iter().step_by(self.s)) {
                            *d = flush_subnormal(v);
                        }
                    }
                }
            }
        }
    }

    /// The phases read back into `[B, C, H, W]` (the input gradient).
    fn gather(&self, phases: &[f32]) -> Vec<f32> {
        let mut out = vec![0.0f32; self.b * self.c * self.h * self.w];
        for bc in 0..self.b * self.c {
            let (bi, ci) = (bc / self.c, bc % self.c);
            for y in 0..self.h {
                let row = &mut out[(bc * self.h + y) * self.w..][..self.w];
                for px in 0..self.s {
                    let first = self.first_column(px);
                    let Some(dst) = row.get_mut(first..) else {
                        continue;
                    };
                    let count = dst.len().div_ceil(self.s);
                    let src = &phases[self.phase_index(bi, ci, y, first)..][..count];
                    if self.s == 1 {
                        dst.copy_from_slice(src);
                    } else {
                        for (d, &v) in dst.iter_mut().step_by(self.s).zip(src) {
                            *d = v;
                        }
                    }
                }
            }
        }
        out
    }

    /// The widened output `[B, O, Ho·wpp]` of the phases, one GEMM per tap.
    fn forward(&self, weight: &[f32], phases: &[f32], wide: &mut [f32]) {
        let t = self;
        let n = t.pixels();
        let k = t.kh * t.kw;
        let (item_len, parallelism) = t.batch_split(phases.len());
        wide.par_chunks_mut(t.o * n)
            .zip(phases.par_chunks(item_len))
            .for_each(|(dst, phases)| {
                for dy in 0..t.kh {
                    for dx in 0..t.kw {
                        let at = t.tap(0, dy, dx, phases.len());
                        let lhs = &weight[t.tap_weight(dy, dx)..];
                        // dst[O × n] (+)= W_tap[O × C] · phase[C × n]
                        // SAFETY: `tap` checked the phase view; the weight view spans O·C·k
                        // values.
                        unsafe {
                            gemm_on(
                                parallelism,
                                [t.o, n, t.c],
                                Strided {
                                    ptr: dst.as_mut_ptr(),
                                    rs: n,
                                    cs: 1,
                                },
                                dy + dx > 0,
                                Strided {
                                    ptr: lhs.as_ptr(),
                                    rs: t.c * k,
                                    cs: k,
                                },
                                Strided {
                                    ptr: phases[at..].as_ptr(),
                                    rs: t.plane,
                                    cs: 1,
                                },
                            );
                        }
                    }
                }
            });
    }

    /// Values of one batch item's phases, and the parallelism of each item's products: with at
    /// least as many items as threads, one thread per item and single-threaded products (one
    /// join per convolution instead of one per product), else the products' own threads.
    fn batch_split(&self, phases_len: usize) -> (usize, gemm::Parallelism) {
        let parallelism = if self.b >= rayon::current_num_threads() {
            gemm::Parallelism::None
        } else {
            gemm::Parallelism::Rayon(0)
        };
        (phases_len / self.b, parallelism)
    }

    /// The output `[B, O, Ho, Wo]` and its shape: the widened rows cut to `Wo`, plus the bias.
    fn crop_with_bias(&self, wide: &[f32], bias: &[f32]) -> (Vec<f32>, [usize; 4]) {
        let n = self.pixels();
        let mut y = Vec::with_capacity(self.b * self.o * self.ho * self.wo);
        for bo in 0..self.b * self.o {
            let b0 = bias[bo % self.o];
            for i in 0..self.ho {
                y.extend(
                    wide[bo * n + i * self.wpp..][..self.wo]
                        .iter()
                        .map(|v| v + b0),
                );
            }
        }
        (y, [self.b, self.o, self.ho, self.wo])
    }
}

/// `dL/dx` (`[B, C, H, W]`) of the convolution given `dL/dy` (`g`, `[B, O, Ho, Wo]`).
pub fn input_grad_host(
    g: &[f32],
    xs: [usize; 4],
    weight: &[f32],
    ws: [usize; 4],
    options: &ConvOptions<2>,
) -> Vec<f32> {
    let t = Taps::new(xs, ws, options);
    t.with_buffers(|phases, wide| {
        t.widen(g, wide);
        t.backward(weight, wide, phases);
        t.gather(phases)
    })
}

impl Taps {
    /// Accumulates `W_tapᵀ · G` into the phases at each tap's shift.
    fn backward(&self, weight: &[f32], wide: &[f32], phases: &mut [f32]) {
        let t = self;
        let n = t.pixels();
        let k = t.kh * t.kw;
        let (item_len, parallelism) = t.batch_split(phases.len());
        phases
            .par_chunks_mut(item_len)
            .zip(wide.par_chunks(t.o * n))
            .for_each(|(phases, rhs)| {
                for dy in 0..t.kh {
                    for dx in 0..t.kw {
                        let at = t.tap(0, dy, dx, phases.len());
                        let lhs = &weight[t.tap_weight(dy, dx)..];
                        // dPhase[C × n] at the tap's shift += W_tapᵀ[C × O] · G[O × n]
                        // SAFETY: `tap` checked the phase view; `rhs` holds O × n values.
                        unsafe {
                            gemm_on(
                                parallelism,
                                [t.c, n, t.o],
                                Strided {
                                    ptr: phases[at..].as_mut_ptr(),
                                    rs: t.plane,
                                    cs: 1,
                                },
                                true,
                                Strided {
                                    ptr: lhs.as_ptr(),
                                    rs: k,
                                    cs: t.c * k,
                                },
                                Strided {
                                    ptr: rhs.as_ptr(),
                                    rs: n,
                                    cs: 1,
                                },
                            );
                        }
                    }
                }
            });
    }
}

/// `dL/dW` (`[O, C, kh, kw]`) of the convolution of `x` given `dL/dy` (`g`): for each tap,
/// `Σ_b G_b · Phase_b(tap)ᵀ`, one GEMM per batch item and tap.
pub fn weight_grad_host(
    x: &[f32],
    xs: [usize; 4],
    g: &[f32],
    ws: [usize; 4],
    options: &ConvOptions<2>,
) -> Vec<f32> {
    let t = Taps::new(xs, ws, options);
    t.with_buffers(|phases, wide| {
        t.scatter(x, phases);
        t.widen(g, wide);
        t.weight_grad(phases, wide)
    })
}

impl Taps {
    /// The output gradient `[B, O, Ho, Wo]` widened to rows of the phase width (zero past `Wo`).
    fn widen(&self, g: &[f32], wide: &mut [f32]) {
        let n = self.pixels();
        for bo in 0..self.b * self.o {
            for i in 0..self.ho {
                let src = &g[(bo * self.ho + i) * self.wo..][..self.wo];
                let dst = &mut wide[bo * n + i * self.wpp..][..self.wo];
                for (d, &v) in dst.iter_mut().zip(src) {
                    *d = flush_subnormal(v);
                }
            }
        }
    }

    /// The per-tap `O × C` blocks of the weight gradient, `[kh·kw][O][C]`. Each product has
    /// a tiny result and a long inner dimension (the pixels), which a GEMM does not split
    /// across threads; the taps and batch items are split instead, one single-threaded product
    /// each, and the batch items summed after.
    fn weight_grad(&self, phases: &[f32], wide: &[f32]) -> Vec<f32> {
        let t = self;
        let n = t.pixels();
        let block = t.o * t.c;
        let mut parts = vec![0.0f32; t.b * t.kh * t.kw * block];
        parts
            .par_chunks_mut(block)
            .enumerate()
            .for_each(|(i, dst)| {
                let (bi, tap) = (i / (t.kh * t.kw), i % (t.kh * t.kw));
                let at = t.tap(bi, tap / t.kw, tap % t.kw, phases.len());
                let lhs = &wide[bi * t.o * n..];
                // dst[O × C] = G_b[O × n] · phase_b[C × n]ᵀ
                // SAFETY: `tap` checked the phase view; `lhs` holds O × n values.
                unsafe {
                    gemm_on(
                        gemm::Parallelism::None,
                        [t.o, t.c, n],
                        Strided {
                            ptr: dst.as_mut_ptr(),
                            rs: t.c,
                            cs: 1,
                        },
                        false,
                        Strided {
                            ptr: lhs.as_ptr(),
                            rs: n,
                            cs: 1,
                        },
                        Strided {
                            ptr: phases[at..].as_ptr(),
                            rs: 1,
                            cs: t.plane,
                        },
                    );
                }
            });
        let (taps, rest) = parts.split_at_mut(t.kh * t.kw * block);
        for item in rest.chunks(taps.len()) {
            for (a, b) in taps.iter_mut().zip(item) {
                *a += b;
            }
        }
        let k = t.kh * t.kw;
        let mut dw = vec![0.0f32; t.o * t.c * k];
        for tap in 0..k {
            for oc in 0..t.o * t.c {
                dw[oc * k + tap] = taps[tap * t.o * t.c + oc];
            }
        }
        dw
    }
}
