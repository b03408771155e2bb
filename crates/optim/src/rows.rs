//! Dropping rows of parameter arrays (a pruned Gaussian's values and its Adam moments).

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
