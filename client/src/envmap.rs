//! The environment light: an equirectangular (latitude–longitude) radiance map.
//!
//! Directions are world space, +y up (glTF). The mapping is three.js's `equirectUv`:
//! u = atan2(d.z, d.x)/(2π) + ½, v = asin(d.y)/π + ½, with the image's top row at v = 1. Texel
//! (x, y) (y from the top) covers polar angles θ ∈ [π y/H, π (y+1)/H] from +y and azimuths
//! φ ∈ [2π x/W − π, 2π (x+1)/W − π], solid angle (2π/W)(cos θ₀ − cos θ₁).
//!
//! The map is piecewise constant: [`EnvLight::eval`] returns the texel's radiance (no
//! filtering), so the Monte Carlo reference's importance sampling ([`crate::groundtruth::env`])
//! samples exactly the function it evaluates.

use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use glam::DVec3;

/// Largest map accepted (texels per side).
const MAX_SIDE: u32 = 16_384;

/// An equirectangular radiance map (linear RGB, row-major from the top).
#[derive(Clone, Debug)]
pub struct EnvLight {
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) pixels: Vec<[f32; 3]>,
}

/// The test map's path ([`bspvt_proto::paths::default_env_map`]).
pub fn default_env_path() -> PathBuf {
    bspvt_proto::paths::default_env_map()
}

impl EnvLight {
    /// Reads a Radiance `.hdr` (or any float image the `image` crate reads, e.g. `.exr`).
    /// Negative and non-finite texels become 0.
    pub fn load(path: &Path) -> Result<EnvLight> {
        let img = image::open(path)
            .with_context(|| format!("cannot read the environment map {}", path.display()))?
            .into_rgb32f();
        let (w, h) = img.dimensions();
        let pixels = img.pixels().map(|p| p.0).collect();
        EnvLight::from_pixels(w, h, pixels)
            .with_context(|| format!("{} is not a usable environment map", path.display()))
    }

    /// A map from texels; checks the size and cleans the values.
    pub(crate) fn from_pixels(
        width: u32,
        height: u32,
        mut pixels: Vec<[f32; 3]>,
    ) -> Result<EnvLight> {
        if width < 2 || height < 1 || width > MAX_SIDE || height > MAX_SIDE {
            bail!("unsupported size {width}×{height} (2×1 to {MAX_SIDE}² texels)");
        }
        if pixels.len() != width as usize * height as usize {
            bail!("{} texels for a {width}×{height} map", pixels.len());
        }
        for p in &mut pixels {
            for c in p.iter_mut() {
                if !(c.is_finite() && *c > 0.0) {
                    *c = 0.0;
                }
            }
        }
        Ok(EnvLight {
            width,
            height,
            pixels,
        })
    }

    #[cfg(test)]
    /// A constant map (tests, the furnace check).
    pub(crate) fn constant(rgb: [f32; 3]) -> EnvLight {
        EnvLight {
            width: 2,
            height: 1,
            pixels: vec![rgb; 2],
        }
    }

    /// The texel holding direction `d` (any length; zero or NaN reads as +y).
    #[inline]
    pub(crate) fn texel_of(&self, d: DVec3) -> (usize, usize) {
        let d = d.normalize_or(DVec3::Y);
        let (w, h) = (self.width as f64, self.height as f64);
        let u = d.z.atan2(d.x) / (2.0 * PI) + 0.5;
        let theta = d.y.clamp(-1.0, 1.0).acos();
        let x = ((u * w) as isize).clamp(0, self.width as isize - 1) as usize;
        let y = ((theta / PI * h) as isize).clamp(0, self.height as isize - 1) as usize;
        (x, y)
    }

    /// Radiance arriving from direction `d` (piecewise constant).
    #[inline]
    pub(crate) fn eval(&self, d: DVec3) -> DVec3 {
        let (x, y) = self.texel_of(d);
        let p = self.pixels[y * self.width as usize + x];
        DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
    }

    /// The unit direction at image position (u, v) ∈ [0, 1]² (v from the top).
    #[inline]
    pub(crate) fn direction(u: f64, v: f64) -> DVec3 {
        let phi = 2.0 * PI * u - PI;
        let theta = PI * v;
        let (st, ct) = theta.sin_cos();
        DVec3::new(st * phi.cos(), ct, st * phi.sin())
    }

    /// Solid angle of a texel of row `y`.
    #[inline]
    pub(crate) fn texel_solid_angle(&self, y: usize) -> f64 {
        let h = f64::from(self.height);
        let (t0, t1) = (PI * y as f64 / h, PI * (y + 1) as f64 / h);
        2.0 * PI / f64::from(self.width) * (t0.cos() - t1.cos())
    }

    /// A `width`×`height` map whose texels are the solid-angle-weighted means of this map over
    /// the same regions (each target texel averages the source texels whose centres fall in
    /// it; sizes need not divide).
    pub(crate) fn downsample(&self, width: u32, height: u32) -> EnvLight {
        let (width, height) = (width.clamp(2, self.width), height.clamp(1, self.height));
        let n = width as usize * height as usize;
        let mut sum = vec![[0.0f64; 3]; n];
        let mut wsum = vec![0.0f64; n];
        for y in 0..self.height as usize {
            let w = self.texel_solid_angle(y);
            let ty = ((y as f64 + 0.5) / f64::from(self.height) * f64::from(height)) as usize;
            for x in 0..self.width as usize {
                let tx = ((x as f64 + 0.5) / f64::from(self.width) * f64::from(width)) as usize;
                let k = ty.min(height as usize - 1) * width as usize + tx.min(width as usize - 1);
                let p = self.pixels[y * self.width as usize + x];
                for c in 0..3 {
                    sum[k][c] += w * f64::from(p[c]);
                }
                wsum[k] += w;
            }
        }
        let pixels = sum
            .iter()
            .zip(&wsum)
            .map(|(s, &w)| {
                if w > 0.0 {
                    s.map(|c| (c / w) as f32)
                } else {
                    [0.0; 3]
                }
            })
            .collect();
        EnvLight {
            width,
            height,
            pixels,
        }
    }

    /// The map turned by `deg` about +y: the direction d of this map appears at R_y(deg) · d.
    /// A turn about the up axis shifts the map's columns; a shift by a fraction of a column
    /// interpolates linearly between the two nearest (exact for whole columns).
    pub fn rotated_y(&self, deg: f64) -> EnvLight {
        if deg.rem_euclid(360.0) == 0.0 || !deg.is_finite() {
            return self.clone();
        }
        let w = self.width as usize;
        // Column c of the result shows the source at R⁻¹ d: the same shift for every row.
        let inv = glam::DMat3::from_rotation_y(-deg.to_radians());
        let d = inv * EnvLight::direction(0.5 / w as f64, 0.5);
        let u = d.z.atan2(d.x) / (2.0 * PI) + 0.5;
        let shift = (u * w as f64 - 0.5).rem_euclid(w as f64);
        // A whole number of columns up to the rounding of atan2: exact.
        let shift = if (shift - shift.round()).abs() < 1e-9 {
            shift.round().rem_euclid(w as f64)
        } else {
            shift
        };
        let (whole, frac) = (shift.floor() as usize, shift.fract());
        let mut pixels = Vec::with_capacity(self.pixels.len());
        for row in self.pixels.chunks_exact(w) {
            for x in 0..w {
                let a = row[(x + whole) % w];
                let b = row[(x + whole + 1) % w];
                pixels.push(std::array::from_fn(|c| {
                    ((1.0 - frac) * f64::from(a[c]) + frac * f64::from(b[c])) as f32
                }));
            }
        }
        EnvLight {
            width: self.width,
            height: self.height,
            pixels,
        }
    }

    /// The map with its radiance multiplied by `k` (finite, ≥ 0; anything else leaves it).
    pub fn scaled(mut self, k: f64) -> EnvLight {
        if k != 1.0 && k.is_finite() && k >= 0.0 {
            for p in &mut self.pixels {
                for c in p.iter_mut() {
                    *c = (f64::from(*c) * k) as f32;
                }
            }
        }
        self
    }

    #[cfg(test)]
    /// ∫ L(ω) dω over the sphere, per channel.
    pub(crate) fn power(&self) -> DVec3 {
        let mut s = DVec3::ZERO;
        for y in 0..self.height as usize {
            let w = self.texel_solid_angle(y);
            for x in 0..self.width as usize {
                let p = self.pixels[y * self.width as usize + x];
                s += w * DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
            }
        }
        s
    }
}

/// A small synthetic map for tests that must not depend on `../shared`: a bright 6×6-texel
/// sun over a dim bluish sky, written as Radiance `dir/env.hdr`. Panics when it cannot write
/// (test support only).
#[doc(hidden)]
pub fn write_test_map(dir: &Path) -> PathBuf {
    let img = image::Rgb32FImage::from_fn(64, 32, |x, y| {
        let sun = (x as i32 - 20).abs() < 3 && (y as i32 - 8).abs() < 3;
        image::Rgb(if sun {
            [40.0, 38.0, 35.0]
        } else {
            [0.3, 0.35, 0.4]
        })
    });
    let path = dir.join("env.hdr");
    if let Err(e) = image::DynamicImage::ImageRgb32F(img).save(&path) {
        panic!("cannot write the test map {}: {e}", path.display());
    }
    path
}

#[cfg(test)]
mod tests {
    use super::*;

    /// R_y(θ) · d of the turned map reads what d read in the original, for whole and
    /// fractional column shifts; a full turn is the identity.
    #[test]
    fn a_turned_map_reads_the_original_at_the_turned_direction() {
        let (w, h) = (64u32, 32u32);
        let px: Vec<[f32; 3]> = (0..w * h)
            .map(|i| [(i % w) as f32, (i / w) as f32, ((i * 7) % 13) as f32])
            .collect();
        let env = EnvLight::from_pixels(w, h, px).expect("map");
        let q = 360.0 / f64::from(w);
        for deg in [90.0, -45.0, 3.0 * q, 36.0 * q] {
            let turned = env.rotated_y(deg);
            let r = glam::DMat3::from_rotation_y(deg.to_radians());
            for y in [3usize, 16, 28] {
                for x in (0..w as usize).step_by(5) {
                    let d = EnvLight::direction(
                        (x as f64 + 0.5) / f64::from(w),
                        (y as f64 + 0.5) / f64::from(h),
                    );
                    assert_eq!(env.eval(d), turned.eval(r * d), "{deg}° at ({x}, {y})");
                }
            }
        }
        // Half a column: the mean of two neighbours.
        let half = env.rotated_y(q / 2.0);
        let (a, b) = (env.pixels[5 * 64 + 10][0], env.pixels[5 * 64 + 11][0]);
        let got = half.pixels[5 * 64 + 10][0];
        let c = env.pixels[5 * 64 + 9][0];
        assert!(
            (got - 0.5 * (a + b)).abs() < 1e-4 || (got - 0.5 * (a + c)).abs() < 1e-4,
            "{got}"
        );
        assert_eq!(env.rotated_y(360.0).pixels, env.pixels);
        assert_eq!(
            env.clone().scaled(2.0).pixels[70][1],
            2.0 * env.pixels[70][1]
        );
    }

    #[test]
    fn mapping_round_trips_and_solid_angles_sum_to_4pi() {
        let env = EnvLight::from_pixels(64, 32, vec![[1.0; 3]; 64 * 32]).expect("map");
        for y in 0..32 {
            for x in 0..64 {
                let d = EnvLight::direction((x as f64 + 0.5) / 64.0, (y as f64 + 0.5) / 32.0);
                assert_eq!(env.texel_of(d), (x, y));
            }
        }
        let total: f64 = (0..32).map(|y| 64.0 * env.texel_solid_angle(y)).sum();
        assert!((total - 4.0 * PI).abs() < 1e-12);
        assert!((env.power().x - 4.0 * PI).abs() < 1e-9);
        // +y is the top row; three.js's u: atan2(z, x).
        assert_eq!(env.texel_of(DVec3::Y).1, 0);
        assert_eq!(env.texel_of(DVec3::NEG_Y).1, 31);
        assert_eq!(env.texel_of(DVec3::new(-1.0, 0.0, -1e-9)).0, 0);
        assert!(env.eval(DVec3::ZERO).is_finite());
        assert!(env.eval(DVec3::NAN).is_finite());
    }

    #[test]
    fn downsampling_keeps_power_and_bad_input_is_refused() {
        let mut px = vec![[0.0f32; 3]; 64 * 32];
        px[5 * 64 + 7] = [100.0, 50.0, 1.0];
        px[20 * 64 + 40] = [f32::NAN, -1.0, f32::INFINITY];
        let env = EnvLight::from_pixels(64, 32, px).expect("map");
        assert_eq!(env.pixels[20 * 64 + 40], [0.0; 3]);
        let small = env.downsample(16, 8);
        let (a, b) = (env.power(), small.power());
        assert!((a - b).length() < 1e-5 * a.length(), "{a} vs {b}");
        assert!(EnvLight::from_pixels(1, 1, vec![[0.0; 3]]).is_err());
        assert!(EnvLight::from_pixels(4, 2, vec![[0.0; 3]; 7]).is_err());
        assert!(EnvLight::load(Path::new("/nonexistent/x.hdr")).is_err());
    }

    #[test]
    fn loads_the_test_map() {
        let p = default_env_path();
        if !p.exists() {
            eprintln!("SKIP: {} not found (set BSPVT_ASSETS)", p.display());
            return;
        }
        let env = EnvLight::load(&p).expect("the test map loads");
        assert_eq!((env.width, env.height), (1024, 512));
        let pw = env.power();
        assert!(pw.min_element() > 0.0 && pw.is_finite(), "{pw}");
    }
}
