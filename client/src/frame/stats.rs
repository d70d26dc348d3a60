//! The few statistics every benchmark, report and method shares: one of each.

use super::image::Image;

/// The median of `v` (the upper one for an even count; 0 for none). Sorts `v` in place; NaN
/// sorts last (`total_cmp`).
pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

/// Relative luminance of linear Rec. 709 RGB (ITU-R BT.709 weights).
#[inline]
pub fn luminance(r: f64, g: f64, b: f64) -> f64 {
    0.2126 * r + 0.7152 * g + 0.0722 * b
}

/// Root-mean-square difference over the RGB channels of the pixels `keep` selects (by index).
/// 0 when none is selected.
pub fn rmse(a: &Image, b: &Image, keep: impl Fn(usize) -> bool) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for (i, (p, q)) in a.pixels.iter().zip(&b.pixels).enumerate() {
        if !keep(i) {
            continue;
        }
        for c in 0..3 {
            let d = f64::from(p[c]) - f64::from(q[c]);
            s += d * d;
        }
        n += 3;
    }
    (s / n.max(1) as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_is_the_middle_value_and_empty_is_zero() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 3.0);
        assert_eq!(median(&mut []), 0.0);
    }

    #[test]
    fn rmse_counts_only_kept_pixels() {
        let mut a = Image::new(2, 1);
        let b = Image::new(2, 1);
        a.pixels[0] = [3.0, 3.0, 3.0];
        a.pixels[1] = [100.0, 0.0, 0.0];
        assert!((rmse(&a, &b, |i| i == 0) - 3.0).abs() < 1e-12);
        assert_eq!(rmse(&a, &b, |_| false), 0.0);
    }
}
