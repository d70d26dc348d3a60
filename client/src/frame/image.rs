//! Linear RGB images and their output: linear OpenEXR (exact values) and tone-mapped sRGB PNG.

use std::path::Path;

use anyhow::{Context, Result, bail};
use rayon::prelude::*;

/// A linear-RGB image, row-major from the top left.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear RGB radiance, row by row from the top.
    pub pixels: Vec<[f32; 3]>,
}

impl Image {
    /// A black image.
    pub fn new(width: u32, height: u32) -> Image {
        Image {
            width,
            height,
            pixels: vec![[0.0; 3]; width as usize * height as usize],
        }
    }

    /// Adds `other` pixel by pixel (same size; a different size adds nothing and is a bug of
    /// the caller, caught in debug builds).
    pub fn add(&mut self, other: &Image) {
        debug_assert_eq!((self.width, self.height), (other.width, other.height));
        for (a, b) in self.pixels.iter_mut().zip(&other.pixels) {
            for c in 0..3 {
                a[c] += b[c];
            }
        }
    }

    /// Writes `.exr` (linear, 32-bit float) or `.png` (tone-mapped with `exposure`, 8-bit sRGB),
    /// by the file's extension. Creates the parent folder.
    pub fn save(&self, path: &Path, exposure: f32) -> Result<()> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
        }
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("exr") => {
                let data: Vec<f32> = self.pixels.iter().flatten().copied().collect();
                let img = image::Rgb32FImage::from_raw(self.width, self.height, data)
                    .context("image buffer has the wrong size")?;
                image::DynamicImage::ImageRgb32F(img)
                    .save(path)
                    .with_context(|| format!("cannot write {}", path.display()))
            }
            Some("png") => self
                .to_srgb8(exposure)
                .save(path)
                .with_context(|| format!("cannot write {}", path.display())),
            _ => bail!(
                "{}: unknown image type (use .png for tone-mapped or .exr for linear)",
                path.display()
            ),
        }
    }

    /// Tone-mapped 8-bit sRGB: exposure, the ACES filmic curve (Narkowicz 2015 fit), sRGB OETF.
    pub fn to_srgb8(&self, exposure: f32) -> image::RgbImage {
        let mut out = image::RgbImage::new(self.width, self.height);
        out.par_chunks_exact_mut(3)
            .zip(&self.pixels)
            .for_each(|(o, p)| {
                for (o, &c) in o.iter_mut().zip(p) {
                    *o = encode_srgb(aces(c * exposure));
                }
            });
        out
    }

    /// [`Image::to_srgb8`] as 0x00RRGGBB words, row by row (a window's framebuffer).
    pub fn to_0rgb(&self, exposure: f32) -> Vec<u32> {
        self.pixels
            .par_iter()
            .map(|p| {
                let [r, g, b] = p.map(|c| u32::from(encode_srgb(aces(c * exposure))));
                (r << 16) | (g << 8) | b
            })
            .collect()
    }

    /// Mean of the three channels over all pixels (for reports and sanity checks).
    pub fn mean(&self) -> f64 {
        let s: f64 = self
            .pixels
            .iter()
            .map(|p| p.iter().map(|&c| f64::from(c)).sum::<f64>())
            .sum();
        s / (3 * self.pixels.len().max(1)) as f64
    }
}

/// ACES filmic tone curve, Narkowicz's fit: x(2.51x + 0.03) / (x(2.43x + 0.59) + 0.14).
fn aces(x: f32) -> f32 {
    // NaN → black; beyond 1e4 the curve is flat at 1 (and x² would overflow).
    let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1e4) };
    ((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)).clamp(0.0, 1.0)
}

fn encode_srgb(c: f32) -> u8 {
    bspvt_proto::srgb::linear_to_srgb8(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exr_round_trips_linear_values() {
        let dir = std::env::temp_dir().join(format!("bspvt-img-{}", std::process::id()));
        let mut img = Image::new(3, 2);
        img.pixels[1] = [1e-3, 2.5, 1e4];
        img.pixels[5] = [0.5, 0.25, 0.125];
        let p = dir.join("a.exr");
        img.save(&p, 1.0).expect("write exr");
        let back = image::open(&p).expect("read exr").into_rgb32f();
        let got: Vec<[f32; 3]> = back.pixels().map(|p| p.0).collect();
        assert_eq!(got, img.pixels);
        img.save(&dir.join("a.png"), 1.0).expect("write png");
        assert!(img.save(&dir.join("a.bmpx"), 1.0).is_err());
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn tone_curve_is_monotone_and_safe() {
        let mut last = 0;
        for i in 0..1000 {
            let v = encode_srgb(aces(i as f32 * 0.01));
            assert!(v >= last);
            last = v;
        }
        assert_eq!(encode_srgb(aces(f32::NAN)), 0);
        assert_eq!(encode_srgb(aces(f32::INFINITY)), 255);
        assert_eq!(encode_srgb(aces(-1.0)), 0);
        assert_eq!(encode_srgb(aces(1e30)), 255);
    }
}
