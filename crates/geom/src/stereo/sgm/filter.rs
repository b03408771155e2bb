//! Post-filters of a fixed-point disparity map: the 3×3 median and the speckle filter, as
//! OpenCV's `StereoSGBM::compute` applies them.

/// 3×3 median with the border replicated, in place.
pub fn median3x3(map: &mut [i16], width: usize, height: usize) {
    if width == 0 || height == 0 {
        return;
    }
    let src = map.to_vec();
    let at = |x: i64, y: i64| {
        let xx = x.clamp(0, width as i64 - 1) as usize;
        let yy = y.clamp(0, height as i64 - 1) as usize;
        src[yy * width + xx]
    };
    for y in 0..height as i64 {
        for x in 0..width as i64 {
            let mut v = [0i16; 9];
            for (k, slot) in v.iter_mut().enumerate() {
                *slot = at(x + k as i64 % 3 - 1, y + k as i64 / 3 - 1);
            }
            v.sort_unstable();
            map[y as usize * width + x as usize] = v[4];
        }
    }
}

/// Marks as `invalid` every 4-connected region of valid pixels with at most `max_size` pixels,
/// where neighbours belong to one region when their values differ by at most `max_diff`.
pub fn speckle_filter(
    map: &mut [i16],
    width: usize,
    height: usize,
    invalid: i16,
    max_size: usize,
    max_diff: i32,
) {
    let mut label = vec![0u32; map.len()];
    let mut stack = Vec::new();
    let mut members = Vec::new();
    let mut next = 0u32;
    for start in 0..map.len() {
        if map[start] == invalid || label[start] != 0 {
            continue;
        }
        next += 1;
        label[start] = next;
        stack.push(start);
        members.clear();
        while let Some(p) = stack.pop() {
            members.push(p);
            let (x, y) = (p % width, p / width);
            let v = map[p] as i32;
            let neighbours = [
                (x + 1 < width).then(|| p + 1),
                (x > 0).then(|| p - 1),
                (y + 1 < height).then(|| p + width),
                (y > 0).then(|| p - width),
            ];
            for q in neighbours.into_iter().flatten() {
                if label[q] == 0 && map[q] != invalid && (map[q] as i32 - v).abs() <= max_diff {
                    label[q] = next;
                    stack.push(q);
                }
            }
        }
        if members.len() <= max_size {
            for &p in &members {
                map[p] = invalid;
            }
        }
    }
}
