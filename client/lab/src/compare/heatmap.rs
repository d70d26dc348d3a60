//! Error heat maps: |method − reference| on a fixed colour ramp.

use bspvt_client::frame::image::Image;

use super::metrics::covered_mean;

/// The error that saturates the heat map: half the reference's mean over covered pixels.
pub(crate) fn error_scale(reference: &Image, covered: &[bool]) -> f32 {
    let m = (0.5 * covered_mean(reference, covered)) as f32;
    if m.is_finite() && m > 0.0 { m } else { 1.0 }
}

/// |method − reference| (channel mean) / `scale` on a black → blue → red → yellow → white
/// ramp; background pixels grey.
pub(crate) fn heat_map(
    img: &Image,
    reference: &Image,
    covered: &[bool],
    scale: f32,
) -> image::RgbImage {
    let mut out = image::RgbImage::new(img.width, img.height);
    let it = img.pixels.iter().zip(&reference.pixels).zip(covered);
    for (o, ((a, b), &c)) in out.pixels_mut().zip(it) {
        o.0 = if c {
            let e = (0..3).map(|k| (a[k] - b[k]).abs()).sum::<f32>() / 3.0;
            ramp(e / scale)
        } else {
            [64, 64, 64]
        };
    }
    out
}

/// Piecewise-linear colour ramp on t ∈ [0, 1] (clamped; NaN saturates).
pub(crate) fn ramp(t: f32) -> [u8; 3] {
    const STOPS: [[f32; 3]; 5] = [
        [0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [1.0, 1.0, 1.0],
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        1.0
    };
    let x = t * (STOPS.len() - 1) as f32;
    let i = (x.floor() as usize).min(STOPS.len() - 2);
    let f = x - i as f32;
    std::array::from_fn(|k| {
        let v = STOPS[i][k] * (1.0 - f) + STOPS[i + 1][k] * f;
        (v * 255.0).round() as u8
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_ends_and_error_map() {
        assert_eq!(ramp(0.0), [0, 0, 0]);
        assert_eq!(ramp(1.0), [255, 255, 255]);
        assert_eq!(ramp(f32::NAN), [255, 255, 255]);
        let mut a = Image::new(3, 1);
        let b = Image::new(3, 1);
        a.pixels[0] = [0.25; 3];
        a.pixels[1] = [9.0; 3];
        let map = heat_map(&a, &b, &[true, false, true], 1.0);
        assert_eq!(map.get_pixel(0, 0).0, [0, 0, 255]);
        assert_eq!(map.get_pixel(1, 0).0, [64, 64, 64]);
        assert_eq!(map.get_pixel(2, 0).0, [0, 0, 0]);
    }
}
