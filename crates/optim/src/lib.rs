#![doc = include_str!("../README.md")]
//! Optimisation shared by the Gaussian and surface trainers: Adam on host parameter arrays,
//! learning-rate schedules, and the read-back of tensors (gradients and the values host steps
//! need) to those arrays.

pub mod adam;
pub mod host;
pub mod schedule;

pub use adam::{AdamConfig, AdamState};
pub use host::{ReadbackError, f32_values, flex_f32};
pub use schedule::ExpSchedule;

/// Keeps the rows (of `width` values) whose flag is set.
pub fn retain_rows<T: Copy>(v: &mut Vec<T>, width: usize, keep: &[bool]) {
    let mut w = 0;
    for (r, &k) in keep.iter().enumerate() {
        if k {
            if w != r {
                v.copy_within(r * width..(r + 1) * width, w * width);
            }
            w += 1;
        }
    }
    v.truncate(w * width);
}

#[cfg(test)]
mod tests {
    #[test]
    fn retain_rows_keeps_flagged_rows_in_order() {
        let mut v = vec![1, 1, 2, 2, 3, 3, 4, 4];
        super::retain_rows(&mut v, 2, &[false, true, false, true]);
        assert_eq!(v, vec![2, 2, 4, 4]);
    }
}
