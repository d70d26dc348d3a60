//! A textured polygonal light's prefiltered texture (Heitz et al. 2016, §5.3): a pyramid whose
//! level k is blurred over 2ᵏ texels, sampled trilinearly by the CPU shading
//! (client/src/texture.rs) and uploaded as words for the GPU's (`common.wgsl`, `tex_*`) — by the
//! native client and by the service for the browser viewer.

use anyhow::{Result, bail};
use glam::{DVec2, DVec3};

/// One level of the pyramid.
#[derive(Clone, Debug)]
struct Level {
    w: usize,
    h: usize,
    texels: Vec<DVec3>,
}

impl Level {
    fn at(&self, x: isize, y: isize) -> DVec3 {
        let x = x.clamp(0, self.w as isize - 1) as usize;
        let y = y.clamp(0, self.h as isize - 1) as usize;
        self.texels[y * self.w + x]
    }

    /// Bilinear, clamp-to-edge; `uv` in [0, 1]² (v down the image).
    fn bilinear(&self, uv: DVec2) -> DVec3 {
        let x = uv.x * self.w as f64 - 0.5;
        let y = uv.y * self.h as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as isize, y0 as isize);
        let top = self.at(x0, y0).lerp(self.at(x0 + 1, y0), fx);
        let bottom = self.at(x0, y0 + 1).lerp(self.at(x0 + 1, y0 + 1), fx);
        top.lerp(bottom, fy)
    }

    /// Half resolution with a [1 3 3 1]/8 binomial filter per axis (a Gaussian-like
    /// prefilter, so every level is smooth at its own scale).
    fn reduce(&self) -> Level {
        let (w, h) = (self.w.div_ceil(2).max(1), self.h.div_ceil(2).max(1));
        let k = [1.0, 3.0, 3.0, 1.0];
        let mut texels = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let mut s = DVec3::ZERO;
                for (j, ky) in k.iter().enumerate() {
                    for (i, kx) in k.iter().enumerate() {
                        let sx = 2 * x as isize + i as isize - 1;
                        let sy = 2 * y as isize + j as isize - 1;
                        s += kx * ky * self.at(sx, sy);
                    }
                }
                texels.push(s / 64.0);
            }
        }
        Level { w, h, texels }
    }
}

/// A prefiltered light texture (linear RGB multipliers of the light's radiance).
#[derive(Clone, Debug)]
pub struct LightTexture {
    levels: Vec<Level>,
}

impl LightTexture {
    /// From linear RGB texels (row-major from the top). Rejects empty or non-finite data.
    pub fn from_texels(w: usize, h: usize, texels: &[[f32; 3]]) -> Result<LightTexture> {
        if w == 0 || h == 0 || texels.len() != w * h {
            bail!("texture is empty or its size does not match its data");
        }
        if texels.iter().flatten().any(|c| !c.is_finite() || *c < 0.0) {
            bail!("texture has negative, NaN or infinite texels");
        }
        let mut levels = vec![Level {
            w,
            h,
            texels: texels
                .iter()
                .map(|t| glam::Vec3::from(*t).as_dvec3())
                .collect(),
        }];
        while levels.last().is_some_and(|l| l.w > 1 || l.h > 1) {
            let next = levels.last().map(Level::reduce);
            levels.extend(next);
        }
        Ok(LightTexture { levels })
    }

    /// The pyramid as the GPU shaders read it (`common.wgsl`, `tex_*`), one vec4 each: [0] =
    /// (levels, size) and [1 + l] = (width, height, offset) of level l, as u32 bits; then the
    /// texels of every level, row-major (f32: the f64 pyramid rounded once).
    pub fn gpu_words(&self) -> Vec<[f32; 4]> {
        let bits = |x: usize| f32::from_bits(x as u32);
        let mut out = vec![[bits(self.levels.len()), bits(self.size()), 0.0, 0.0]];
        let mut offset = 1 + self.levels.len();
        for l in &self.levels {
            out.push([bits(l.w), bits(l.h), bits(offset), 0.0]);
            offset += l.texels.len();
        }
        for l in &self.levels {
            out.extend(l.texels.iter().map(|t| t.as_vec3().extend(0.0).to_array()));
        }
        out
    }

    /// Resolution of the finest level (the larger side).
    pub fn size(&self) -> usize {
        self.levels[0].w.max(self.levels[0].h)
    }

    /// Trilinear lookup at `uv`, level `lod` (0 = finest; clamped).
    pub fn sample(&self, uv: DVec2, lod: f64) -> DVec3 {
        let top = (self.levels.len() - 1) as f64;
        let lod = if lod.is_nan() {
            top
        } else {
            lod.clamp(0.0, top)
        };
        let uv = if uv.is_finite() {
            uv
        } else {
            DVec2::splat(0.5)
        };
        let l0 = lod.floor() as usize;
        let f = lod - l0 as f64;
        let a = self.levels[l0].bilinear(uv);
        if f > 0.0 && l0 + 1 < self.levels.len() {
            a.lerp(self.levels[l0 + 1].bilinear(uv), f)
        } else {
            a
        }
    }

    /// The texture's mean (the coarsest level).
    pub fn average(&self) -> DVec3 {
        self.levels[self.levels.len() - 1].texels[0]
    }

    /// The finest level: width, height and texels (row-major from the top).
    pub fn finest(&self) -> (usize, usize, &[DVec3]) {
        let l = &self.levels[0];
        (l.w, l.h, &l.texels)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pyramid_preserves_the_mean_and_ends_in_one_texel() {
        // Bright left half, dark right half: mean ½.
        let n = 32;
        let texels: Vec<[f32; 3]> = (0..n * n)
            .map(|i| if i % n < n / 2 { [1.0; 3] } else { [0.0; 3] })
            .collect();
        let t = LightTexture::from_texels(n, n, &texels).expect("texture");
        assert_eq!(t.levels.last().map(|l| (l.w, l.h)), Some((1, 1)));
        assert!((t.average().x - 0.5).abs() < 0.05, "{}", t.average());
        let s = t.sample(DVec2::new(0.3, 0.7), 1e9);
        assert!((s - t.average()).length() < 1e-12);
        assert!(LightTexture::from_texels(2, 2, &[[f32::NAN; 3]; 4]).is_err());
        assert!(LightTexture::from_texels(0, 2, &[]).is_err());
    }
}
