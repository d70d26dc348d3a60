//! Surface textures: images read from an asset (glTF base-colour, metallic-roughness and
//! emissive textures, OBJ/MTL `map_Kd`), sampled through a mesh's UVs (the material they
//! modulate is `crate::material::MaterialMaps`).
//!
//! **UV convention** (glTF 2.0 §3.8.4): (0, 0) is the top-left corner of the image, u to the
//! right, v down the rows. OBJ `vt` (v up) is flipped to this convention on import.
//!
//! **Sampling**: bilinear between the four nearest texel centres, wrapped per axis as the
//! glTF sampler says (repeat, the default; clamp to edge; mirrored repeat). Colour textures
//! (base colour, `map_Kd`, emissive) are sRGB-encoded and converted to linear before filtering
//! (IEC 61966-2-1); data textures (metallic-roughness, normal maps, alpha) are read as they
//! are. **Mipmaps**: a pixel whose footprint on the texture spans more than a texel reads a
//! box-filtered pyramid (each level half the one before, 2 × 2 texels averaged — in linear for
//! colour textures, then re-encoded to 8-bit sRGB), trilinearly: the level of detail is
//! log₂ of the footprint's longer side in texels, the OpenGL rule (isotropic) [Williams83].
//! Vertices, cut-out tests and lamps read the finest level.
//!
//! **Limits**: a texture has at most [`MAX_TEXTURE_SIDE`] texels per side and
//! [`MAX_TEXTURE_TEXELS`] texels; an asset's textures at most [`MAX_ASSET_TEXELS`] texels in
//! all. The image's header is checked before its pixels are decoded.

use std::sync::{Arc, OnceLock};

use glam::Vec2;

use crate::srgb::linear_to_srgb8;

/// Most texels per side of one texture.
pub const MAX_TEXTURE_SIDE: u32 = 8192;
/// Most texels of one texture (4096², 64 MiB as RGBA8).
pub const MAX_TEXTURE_TEXELS: u64 = 1 << 24;
/// Most texels of all the textures of one asset (256 MiB as RGBA8).
pub const MAX_ASSET_TEXELS: u64 = 1 << 26;

/// A decoded image: RGBA8 texels, row-major from the top row.
#[derive(Clone, PartialEq, Eq)]
pub struct Texture {
    /// What the asset calls it (an image name, a file name or `image N`), for messages.
    pub name: String,
    /// Texels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `width × height × 4` bytes, RGBA.
    pub rgba: Vec<u8>,
    /// The encoded image (PNG or JPEG) it was decoded from, which is what a stored scene
    /// keeps (empty: made in memory; stored as compressed texels).
    pub source: Vec<u8>,
    /// The mip pyramid, built on first use (derived from the texels: no part of equality).
    pub mips: Mips,
}

/// A texture's mip levels below the finest (level 1 first), built once per encoding the
/// texture is read with (colour textures filter in linear).
#[derive(Clone, Default)]
pub struct Mips {
    data: OnceLock<Arc<Vec<Level>>>,
    srgb: OnceLock<Arc<Vec<Level>>>,
}

impl PartialEq for Mips {
    /// Mips are derived from the texels, which the texture compares.
    fn eq(&self, _: &Mips) -> bool {
        true
    }
}

impl Eq for Mips {}

/// One mip level: RGBA8 texels, row-major from the top row.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Level {
    /// Texels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `width × height × 4` bytes.
    pub rgba: Vec<u8>,
}

/// The next coarser level of RGBA8 `rgba` (`width` × `height`): each texel the mean of the
/// 2 × 2 below it (the last row or column repeated where the size is odd), colour averaged in
/// linear when `srgb`.
fn half(width: u32, height: u32, rgba: &[u8], srgb: bool) -> Level {
    let (w, h) = ((width / 2).max(1), (height / 2).max(1));
    let mut out = Vec::with_capacity(4 * w as usize * h as usize);
    let (sw, sh) = (width as usize, height as usize);
    for y in 0..h as usize {
        for x in 0..w as usize {
            let mut sum = [0.0f32; 4];
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (tx, ty) = ((2 * x + dx).min(sw - 1), (2 * y + dy).min(sh - 1));
                let t = texel_of(rgba, width, tx, ty, srgb);
                for k in 0..4 {
                    sum[k] += 0.25 * t[k];
                }
            }
            for (k, v) in sum.iter().enumerate() {
                out.push(if srgb && k < 3 {
                    linear_to_srgb8(*v)
                } else {
                    (v * 255.0).round().clamp(0.0, 255.0) as u8
                });
            }
        }
    }
    Level {
        width: w,
        height: h,
        rgba: out,
    }
}

/// Bilinear lookup at `uv` in RGBA8 `rgba` (`width` × `height`), wrapped per axis: see the
/// module documentation. Non-finite UVs read the texel at (0, 0).
fn bilinear(
    width: u32,
    height: u32,
    rgba: &[u8],
    uv: Vec2,
    wrap: [Wrap; 2],
    srgb: bool,
) -> [f32; 4] {
    let (w, h) = (i64::from(width), i64::from(height));
    if w == 0 || h == 0 {
        return [0.0; 4];
    }
    let uv = if uv.is_finite() { uv } else { Vec2::ZERO };
    let x = f64::from(uv.x) * w as f64 - 0.5;
    let y = f64::from(uv.y) * h as f64 - 0.5;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
    // `as` saturates: a huge UV stays a (wrapped) valid index.
    let (x0, y0) = (x0 as i64, y0 as i64);
    let xs = [wrap[0].index(x0, w), wrap[0].index(x0.saturating_add(1), w)];
    let ys = [wrap[1].index(y0, h), wrap[1].index(y0.saturating_add(1), h)];
    let t = |i: usize, j: usize| texel_of(rgba, width, xs[i], ys[j], srgb);
    let (a, b, c, d) = (t(0, 0), t(1, 0), t(0, 1), t(1, 1));
    std::array::from_fn(|k| {
        let top = a[k] + (b[k] - a[k]) * fx;
        let bottom = c[k] + (d[k] - c[k]) * fx;
        top + (bottom - top) * fy
    })
}

/// Texel (x, y) of RGBA8 `rgba` `width` texels wide.
fn texel_of(rgba: &[u8], width: u32, x: usize, y: usize, srgb: bool) -> [f32; 4] {
    let i = 4 * (y * width as usize + x);
    let Some(t) = rgba.get(i..i + 4) else {
        return [0.0; 4];
    };
    let lin = |b: u8| {
        if srgb {
            crate::srgb::decode(b)
        } else {
            f32::from(b) / 255.0
        }
    };
    [lin(t[0]), lin(t[1]), lin(t[2]), f32::from(t[3]) / 255.0]
}

impl std::fmt::Debug for Texture {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Texture({:?}, {}×{})",
            self.name, self.width, self.height
        )
    }
}

/// How a texture repeats outside [0, 1] (glTF 2.0 §5.26 `sampler.wrapS` / `wrapT`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Wrap {
    /// `REPEAT` (10497), glTF's default.
    #[default]
    Repeat,
    /// `CLAMP_TO_EDGE` (33071).
    Clamp,
    /// `MIRRORED_REPEAT` (33648).
    Mirror,
}

impl Wrap {
    fn index(self, i: i64, n: i64) -> usize {
        let i = match self {
            Wrap::Clamp => i.clamp(0, n - 1),
            Wrap::Repeat => i.rem_euclid(n),
            Wrap::Mirror => {
                let m = i.rem_euclid(2 * n);
                if m < n { m } else { 2 * n - 1 - m }
            }
        };
        i as usize
    }
}

/// A texture as a material uses it: the image, its sampler's wrap modes (u, v) and the
/// transform of the mesh's UVs into it.
#[derive(Clone, Debug, PartialEq)]
pub struct TextureRef {
    /// The image (shared by every material and light that uses it).
    pub texture: Arc<Texture>,
    /// Wrap modes along u and v.
    pub wrap: [Wrap; 2],
    /// `KHR_texture_transform` (`None`: the UVs as they are).
    pub transform: Option<UvTransform>,
}

impl TextureRef {
    /// The texture's coordinates of the mesh's `uv`.
    #[inline]
    pub fn uv(&self, uv: Vec2) -> Vec2 {
        self.transform.map_or(uv, |t| t.apply(uv))
    }

    /// [`Texture::sample`] at the mesh's `uv`, through the transform.
    pub fn sample(&self, uv: Vec2, srgb: bool) -> [f32; 4] {
        self.texture.sample(self.uv(uv), self.wrap, srgb)
    }

    /// The level of detail of a pixel whose mesh UV changes by `duv` = [∂uv/∂x, ∂uv/∂y] per
    /// pixel: log₂ of the longer of the two in this texture's texels (through the transform's
    /// linear part), 0 where it is under a texel [Williams83].
    pub fn lod(&self, duv: [Vec2; 2]) -> f32 {
        let [a, b, c, d, _, _] = self.transform.unwrap_or(UvTransform::IDENTITY).matrix();
        let size = Vec2::new(self.texture.width as f32, self.texture.height as f32);
        let texels = |v: Vec2| (Vec2::new(a * v.x + b * v.y, c * v.x + d * v.y) * size).length();
        let rho = texels(duv[0]).max(texels(duv[1]));
        if rho > 1.0 { rho.log2() } else { 0.0 }
    }

    /// The texture at the mesh's `uv` as a pixel with UV footprint `duv` sees it
    /// ([`TextureRef::lod`], trilinear); `None`: a point (the finest level, bilinear).
    pub fn sample_footprint(&self, uv: Vec2, duv: Option<[Vec2; 2]>, srgb: bool) -> [f32; 4] {
        match duv {
            None => self.sample(uv, srgb),
            Some(d) => self
                .texture
                .sample_lod(self.uv(uv), self.wrap, srgb, self.lod(d)),
        }
    }
}

/// glTF's `KHR_texture_transform`: uv′ = T(offset) · R(rotation) · S(scale) · uv, with R the
/// matrix of the extension's README, columns (cos r, sin r) and (−sin r, cos r).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct UvTransform {
    /// `offset`.
    pub offset: [f32; 2],
    /// `rotation`, radians.
    pub rotation: f32,
    /// `scale`.
    pub scale: [f32; 2],
}

impl UvTransform {
    /// The UVs as they are.
    pub const IDENTITY: UvTransform = UvTransform {
        offset: [0.0, 0.0],
        rotation: 0.0,
        scale: [1.0, 1.0],
    };

    /// The affine map as (a, b, c, d, tx, ty): uv′ = (a u + b v + tx, c u + d v + ty). Non-finite
    /// parameters give the identity's.
    pub fn matrix(&self) -> [f32; 6] {
        let f = |x: f32, d: f32| if x.is_finite() { x } else { d };
        let (s, c) = f(self.rotation, 0.0).sin_cos();
        let [sx, sy] = [f(self.scale[0], 1.0), f(self.scale[1], 1.0)];
        [
            c * sx,
            -s * sy,
            s * sx,
            c * sy,
            f(self.offset[0], 0.0),
            f(self.offset[1], 0.0),
        ]
    }

    /// The transformed coordinates of `uv`.
    pub fn apply(&self, uv: Vec2) -> Vec2 {
        let [a, b, c, d, tx, ty] = self.matrix();
        Vec2::new(a * uv.x + b * uv.y + tx, c * uv.x + d * uv.y + ty)
    }
}

impl Texture {
    /// The texel at (x, y) in [0, 1]: RGB through the sRGB curve when `srgb`, alpha linear.
    fn texel(&self, x: usize, y: usize, srgb: bool) -> [f32; 4] {
        texel_of(&self.rgba, self.width, x, y, srgb)
    }

    /// A texture made in memory from RGBA8 texels (`rgba`: `width × height × 4` bytes).
    pub fn from_rgba8(name: &str, width: u32, height: u32, rgba: Vec<u8>) -> Texture {
        Texture {
            name: name.to_string(),
            width,
            height,
            rgba,
            source: Vec::new(),
            mips: Mips::default(),
        }
    }

    /// Bilinear lookup at `uv` (see the module documentation); `srgb`: a colour texture,
    /// linearised before filtering. Non-finite UVs read the texel at (0, 0).
    pub fn sample(&self, uv: Vec2, wrap: [Wrap; 2], srgb: bool) -> [f32; 4] {
        bilinear(self.width, self.height, &self.rgba, uv, wrap, srgb)
    }

    /// The levels below the finest (level 1 first, down to 1 × 1), built on first use.
    pub fn mip_levels(&self, srgb: bool) -> &[Level] {
        let cell = if srgb {
            &self.mips.srgb
        } else {
            &self.mips.data
        };
        cell.get_or_init(|| {
            let mut levels: Vec<Level> = Vec::new();
            let (mut w, mut h) = (self.width, self.height);
            while w > 0 && h > 0 && (w > 1 || h > 1) {
                let next = match levels.last() {
                    Some(l) => half(l.width, l.height, &l.rgba, srgb),
                    None => half(w, h, &self.rgba, srgb),
                };
                (w, h) = (next.width, next.height);
                levels.push(next);
            }
            Arc::new(levels)
        })
    }

    /// Trilinear lookup at level of detail `lod` (0: the finest level, bilinear; k: level k;
    /// between: the two levels blended), clamped to the pyramid.
    pub fn sample_lod(&self, uv: Vec2, wrap: [Wrap; 2], srgb: bool, lod: f32) -> [f32; 4] {
        if !(lod > 0.0) {
            return self.sample(uv, wrap, srgb);
        }
        let levels = self.mip_levels(srgb);
        let top = levels.len() as f32;
        let lod = lod.min(top);
        let k = lod.floor() as usize;
        let f = lod - k as f32;
        let at = |k: usize| match k {
            0 => self.sample(uv, wrap, srgb),
            k => levels.get(k - 1).map_or([0.0; 4], |l| {
                bilinear(l.width, l.height, &l.rgba, uv, wrap, srgb)
            }),
        };
        let a = at(k);
        if f <= 0.0 || k >= levels.len() {
            return a;
        }
        let b = at(k + 1);
        std::array::from_fn(|c| a[c] + (b[c] - a[c]) * f)
    }

    /// The mean texel (RGB linearised when `srgb`).
    pub fn mean(&self, srgb: bool) -> [f32; 4] {
        let n = (self.width as usize) * (self.height as usize);
        if n == 0 {
            return [0.0; 4];
        }
        let mut s = [0.0f64; 4];
        for y in 0..self.height as usize {
            for x in 0..self.width as usize {
                let t = self.texel(x, y, srgb);
                for k in 0..4 {
                    s[k] += f64::from(t[k]);
                }
            }
        }
        s.map(|v| (v / n as f64) as f32)
    }

    /// Decodes a PNG or JPEG (the format read from its first bytes), refusing an image over
    /// the limits before its pixels are decoded. `name` is for messages.
    pub fn decode(bytes: &[u8], name: &str) -> Result<Texture, String> {
        use image::ImageDecoder;
        let format = image::guess_format(bytes)
            .map_err(|_| "not a PNG or JPEG image".to_string())
            .and_then(|f| match f {
                image::ImageFormat::Png | image::ImageFormat::Jpeg => Ok(f),
                other => Err(format!("{other:?} images are not read (PNG or JPEG only)")),
            })?;
        let mut limits = image::Limits::default();
        limits.max_image_width = Some(MAX_TEXTURE_SIDE);
        limits.max_image_height = Some(MAX_TEXTURE_SIDE);
        limits.max_alloc = Some(MAX_TEXTURE_TEXELS * 16);
        let over = format!(
            "over the limit ({MAX_TEXTURE_SIDE} texels per side, {MAX_TEXTURE_TEXELS} in all)"
        );
        let err = |e: image::ImageError| match e {
            image::ImageError::Limits(_) => over.clone(),
            e => e.to_string(),
        };
        let cursor = std::io::Cursor::new(bytes);
        let mut decoder: Box<dyn ImageDecoder> = match format {
            image::ImageFormat::Png => Box::new(
                image::codecs::png::PngDecoder::with_limits(cursor, limits.clone()).map_err(err)?,
            ),
            _ => Box::new(image::codecs::jpeg::JpegDecoder::new(cursor).map_err(err)?),
        };
        let (w, h) = decoder.dimensions();
        if w == 0 || h == 0 {
            return Err("the image is empty".into());
        }
        if w > MAX_TEXTURE_SIDE
            || h > MAX_TEXTURE_SIDE
            || u64::from(w) * u64::from(h) > MAX_TEXTURE_TEXELS
        {
            return Err(format!("{w}×{h} texels is {over}"));
        }
        decoder.set_limits(limits).map_err(err)?;
        let img = image::DynamicImage::from_decoder(decoder).map_err(err)?;
        let rgba = img.into_rgba8();
        Ok(Texture {
            name: name.to_string(),
            width: rgba.width(),
            height: rgba.height(),
            rgba: rgba.into_raw(),
            source: bytes.to_vec(),
            mips: Default::default(),
        })
    }
}

/// The width and height an image file declares (its header alone: no pixels decoded), so
/// that memory can be set aside before it is decoded.
pub fn image_dimensions(bytes: &[u8]) -> Result<(u32, u32), String> {
    image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| e.to_string())?
        .into_dimensions()
        .map_err(|e| e.to_string())
}

/// A light's texture in the light's own parametrisation (see `bspvt_client::texture`: (u, v)
/// in the basis (p₁ − p₀, pₙ₋₁ − p₀) of its plane, v down the rows): linear RGB multipliers
/// of the light's radiance, row-major from the top.
#[derive(Clone, PartialEq)]
pub struct LightImage {
    /// Texels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `width × height` linear RGB texels, each finite and ≥ 0.
    pub texels: Vec<[f32; 3]>,
}

impl std::fmt::Debug for LightImage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "LightImage({}×{})", self.width, self.height)
    }
}

impl LightImage {
    /// A light texture file as the light's image: PNG or JPEG (sRGB → linear, IEC 61966-2-1,
    /// as every colour texture here), or OpenEXR or Radiance HDR (linear as stored), within the
    /// texture limits. A NaN or infinite texel is refused; a negative one (an EXR's filter
    /// ringing) is clamped to 0.
    pub fn decode(bytes: &[u8]) -> Result<LightImage, String> {
        let format = image::guess_format(bytes)
            .map_err(|_| "not a PNG, JPEG, OpenEXR or Radiance HDR image".to_string())?;
        if matches!(format, image::ImageFormat::Png | image::ImageFormat::Jpeg) {
            let t = Texture::decode(bytes, "")?;
            return Ok(LightImage {
                width: t.width,
                height: t.height,
                texels: t
                    .rgba
                    .chunks_exact(4)
                    .map(|c| [c[0], c[1], c[2]].map(crate::srgb::decode))
                    .collect(),
            });
        }
        if !matches!(
            format,
            image::ImageFormat::OpenExr | image::ImageFormat::Hdr
        ) {
            return Err(format!(
                "{format:?} images are not read (PNG, JPEG, OpenEXR or Radiance HDR)"
            ));
        }
        let mut reader = image::ImageReader::with_format(std::io::Cursor::new(bytes), format);
        let mut limits = image::Limits::default();
        limits.max_image_width = Some(MAX_TEXTURE_SIDE);
        limits.max_image_height = Some(MAX_TEXTURE_SIDE);
        limits.max_alloc = Some(MAX_TEXTURE_TEXELS * 16);
        reader.limits(limits);
        let img = reader.decode().map_err(|e| match e {
            image::ImageError::Limits(_) => format!(
                "over the limit ({MAX_TEXTURE_SIDE} texels per side, {MAX_TEXTURE_TEXELS} in all)"
            ),
            e => e.to_string(),
        })?;
        let (width, height) = (img.width(), img.height());
        if width == 0 || height == 0 || u64::from(width) * u64::from(height) > MAX_TEXTURE_TEXELS {
            return Err(format!(
                "{width}×{height} texels is empty or over the limit"
            ));
        }
        let mut texels = Vec::with_capacity(width as usize * height as usize);
        for (i, p) in img.into_rgb32f().pixels().enumerate() {
            if !p.0.iter().all(|c| c.is_finite()) {
                return Err(format!(
                    "texel ({}, {}) is NaN or infinite",
                    i % width as usize,
                    i / width as usize
                ));
            }
            texels.push(p.0.map(|c| c.max(0.0)));
        }
        Ok(LightImage {
            width,
            height,
            texels,
        })
    }

    /// Bytes that decoding a `width × height` light texture may hold at its peak: the
    /// decoder's buffer (at most 16 B per texel, its `max_alloc`) and the f32 texels.
    pub fn decode_bytes(width: u32, height: u32) -> u64 {
        u64::from(width) * u64::from(height) * (16 + 12)
    }

    /// Whether the size matches the data and every texel is finite and ≥ 0.
    pub fn is_valid(&self) -> bool {
        self.width > 0
            && self.height > 0
            && self.texels.len() as u64 == u64::from(self.width) * u64::from(self.height)
            && self
                .texels
                .iter()
                .flatten()
                .all(|c| c.is_finite() && *c >= 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker() -> Texture {
        // 2×2: red, green / blue, white (sRGB 255 = linear 1).
        Texture {
            name: "checker".into(),
            width: 2,
            height: 2,
            rgba: vec![
                255, 0, 0, 255, 0, 255, 0, 255, //
                0, 0, 255, 255, 255, 255, 255, 255,
            ],
            source: Vec::new(),
            mips: Default::default(),
        }
    }

    #[test]
    fn texel_centres_read_their_texel_and_wrap_modes_differ_outside() {
        let t = checker();
        let r = [Wrap::Repeat; 2];
        assert_eq!(
            t.sample(Vec2::new(0.25, 0.25), r, true),
            [1.0, 0.0, 0.0, 1.0]
        );
        assert_eq!(
            t.sample(Vec2::new(0.75, 0.25), r, true),
            [0.0, 1.0, 0.0, 1.0]
        );
        assert_eq!(
            t.sample(Vec2::new(0.25, 0.75), r, true),
            [0.0, 0.0, 1.0, 1.0]
        );
        // Half-way between red and green: 0.5 each (linear filtering).
        let mid = t.sample(Vec2::new(0.5, 0.25), r, true);
        assert!((mid[0] - 0.5).abs() < 1e-6 && (mid[1] - 0.5).abs() < 1e-6);
        // u = 1.25: repeat reads red's column again, clamp the green column.
        assert_eq!(t.sample(Vec2::new(1.25, 0.25), r, true)[0], 1.0);
        let c = t.sample(Vec2::new(1.25, 0.25), [Wrap::Clamp; 2], true);
        assert_eq!(c[1], 1.0);
        let m = t.sample(Vec2::new(1.25, 0.25), [Wrap::Mirror; 2], true);
        assert_eq!(m[1], 1.0);
        assert!(
            t.sample(Vec2::new(f32::NAN, 1e30), r, true)
                .iter()
                .all(|x| x.is_finite())
        );
    }

    #[test]
    fn srgb_mid_grey_is_linearised() {
        let t = Texture {
            name: "grey".into(),
            width: 1,
            height: 1,
            rgba: vec![188, 188, 188, 255],
            source: Vec::new(),
            mips: Default::default(),
        };
        // sRGB 188/255 ≈ 0.5029 linear; the data path reads 188/255 ≈ 0.737.
        assert!((t.sample(Vec2::ZERO, [Wrap::Repeat; 2], true)[0] - 0.5029).abs() < 1e-3);
        assert!((t.sample(Vec2::ZERO, [Wrap::Repeat; 2], false)[0] - 0.7373).abs() < 1e-3);
    }

    #[test]
    fn mip_levels_halve_down_to_one_texel_averaging_in_linear() {
        let t = checker();
        let srgb = t.mip_levels(true);
        assert_eq!(srgb.len(), 1);
        assert_eq!((srgb[0].width, srgb[0].height), (1, 1));
        // Red, green, blue, white averaged in linear: (0.5, 0.5, 0.5) → sRGB 188.
        assert_eq!(&srgb[0].rgba[..3], &[188, 188, 188]);
        // As data, the bytes' mean.
        assert_eq!(&t.mip_levels(false)[0].rgba[..3], &[128, 128, 128]);
        // A 5 × 3 image: 2 × 1, then 1 × 1.
        let odd = Texture::from_rgba8("odd", 5, 3, vec![200; 5 * 3 * 4]);
        let l = odd.mip_levels(false);
        assert_eq!(
            l.iter().map(|l| (l.width, l.height)).collect::<Vec<_>>(),
            vec![(2, 1), (1, 1)]
        );
        assert!(l.iter().all(|l| l.rgba.iter().all(|&b| b == 200)));
    }

    #[test]
    fn the_footprint_picks_the_level_trilinearly() {
        let t = Arc::new(checker());
        let r = TextureRef {
            texture: t.clone(),
            wrap: [Wrap::Repeat; 2],
            transform: None,
        };
        let uv = Vec2::new(0.25, 0.25);
        // Under a texel: the finest level (red).
        let small = [Vec2::new(0.1, 0.0), Vec2::new(0.0, 0.1)];
        assert_eq!(r.lod(small), 0.0);
        assert_eq!(
            r.sample_footprint(uv, Some(small), true),
            [1.0, 0.0, 0.0, 1.0]
        );
        // Two texels (the whole 2 × 2 image): level 1, the mean.
        let whole = [Vec2::new(1.0, 0.0), Vec2::new(0.0, 0.5)];
        assert!((r.lod(whole) - 1.0).abs() < 1e-6);
        let m = r.sample_footprint(uv, Some(whole), true);
        assert!(
            (m[0] - 0.5029).abs() < 2e-3 && (m[1] - 0.5029).abs() < 2e-3,
            "{m:?}"
        );
        // Half-way (√2 texels): half red, half the mean.
        let mid = [Vec2::new(std::f32::consts::SQRT_2 / 2.0, 0.0), Vec2::ZERO];
        let c = r.sample_footprint(uv, Some(mid), true);
        assert!((c[0] - 0.5 * (1.0 + 0.5029)).abs() < 2e-3, "{c:?}");
        // A transform that scales the UVs 4× makes the same footprint 4× longer in texels.
        let scaled = TextureRef {
            transform: Some(UvTransform {
                offset: [0.0, 0.0],
                rotation: 0.0,
                scale: [4.0, 4.0],
            }),
            ..r.clone()
        };
        assert_eq!(scaled.lod(small), 0.0, "0.8 texels: the finest level");
        assert!((scaled.lod(whole) - 3.0).abs() < 1e-6);
        // Beyond the coarsest level, and non-finite footprints: finite, the coarsest.
        for d in [
            [Vec2::new(1e30, 0.0), Vec2::ZERO],
            [Vec2::new(f32::INFINITY, 0.0), Vec2::ZERO],
            [Vec2::NAN, Vec2::NAN],
        ] {
            let c = r.sample_footprint(uv, Some(d), true);
            assert!(c.iter().all(|x| x.is_finite()), "{d:?}: {c:?}");
        }
    }
}
