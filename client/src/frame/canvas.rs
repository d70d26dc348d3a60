//! Text, lines and widgets drawn into the window's 0RGB framebuffer, or into a transparent
//! layer composited over the frame by the GPU (`gpu/present.wgsl`) (8×8 bitmap font,
//! public-domain glyphs from `font8x8`: Basic Latin, Latin-1 (², °, ×, µ), Greek (α, ε, σ),
//! box drawing and a few symbols).

use font8x8::{BASIC_FONTS, BOX_FONTS, GREEK_FONTS, LATIN_FONTS, MISC_FONTS, UnicodeFonts};

/// The 8×8 glyph of `ch`, `?` where the font has none.
fn glyph(ch: char) -> Option<[u8; 8]> {
    BASIC_FONTS
        .get(ch)
        .or_else(|| LATIN_FONTS.get(ch))
        .or_else(|| GREEK_FONTS.get(ch))
        .or_else(|| BOX_FONTS.get(ch))
        .or_else(|| MISC_FONTS.get(ch))
        .or_else(|| BASIC_FONTS.get('?'))
}

/// Whether the font draws `ch` (and does not fall back to `?`).
pub fn has_glyph(ch: char) -> bool {
    BASIC_FONTS.get(ch).is_some()
        || LATIN_FONTS.get(ch).is_some()
        || GREEK_FONTS.get(ch).is_some()
        || BOX_FONTS.get(ch).is_some()
        || MISC_FONTS.get(ch).is_some()
}

/// A framebuffer to draw text and widgets into.
pub struct Canvas<'a> {
    /// Pixels, row by row: 0x00RRGGBB, or premultiplied 0xAARRGGBB where `layer`.
    pub buf: &'a mut [u32],
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `false`: an opaque frame that drawing blends into. `true`: a transparent layer that
    /// takes the same drawing as "over" operations, to be put over a frame by [`composite`]
    /// (or `present.wgsl`) with the same result.
    pub layer: bool,
}

impl Canvas<'_> {
    /// `rgb` over pixel `k` with opacity `alpha`.
    fn put(&mut self, k: usize, rgb: u32, alpha: f32) {
        let p = &mut self.buf[k];
        *p = if self.layer {
            over(*p, rgb, alpha)
        } else if alpha >= 1.0 {
            rgb & 0x00ff_ffff
        } else {
            blend(*p, rgb, alpha)
        };
    }

    /// Darkens a rectangle (the text's background) by half.
    pub(crate) fn shade(&mut self, x0: usize, y0: usize, w: usize, h: usize) {
        for y in y0..(y0 + h).min(self.height) {
            for x in x0..(x0 + w).min(self.width) {
                self.put(y * self.width + x, 0, 0.5);
            }
        }
    }

    pub(crate) fn fill(&mut self, x0: usize, y0: usize, w: usize, h: usize, rgb: u32) {
        for y in y0..(y0 + h).min(self.height) {
            for x in x0..(x0 + w).min(self.width) {
                self.put(y * self.width + x, rgb, 1.0);
            }
        }
    }

    /// One line of text at (x, y) (top-left), 8 pixels per character.
    pub fn text(&mut self, x: usize, y: usize, s: &str, rgb: u32) {
        for (i, ch) in s.chars().enumerate() {
            let Some(glyph) = glyph(ch) else {
                continue;
            };
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..8 {
                    if bits & (1 << col) != 0 {
                        let (px, py) = (x + i * 8 + col, y + row);
                        if px < self.width && py < self.height {
                            self.put(py * self.width + px, rgb, 1.0);
                        }
                    }
                }
            }
        }
    }

    /// Lines of text on a darkened panel; returns the panel's height.
    pub(crate) fn panel(&mut self, x: usize, y: usize, lines: &[String]) -> usize {
        let w = lines.iter().map(|l| l.chars().count()).max().unwrap_or(0) * 8 + 8;
        let h = lines.len() * 10 + 6;
        self.shade(x, y, w, h);
        for (k, l) in lines.iter().enumerate() {
            self.text(x + 4, y + 4 + k * 10, l, 0x00ff_ffff);
        }
        h
    }

    /// A line from `a` to `b` (pixels), `rgb` blended by `alpha`. With `depth` (camera depth
    /// per pixel, `f32::INFINITY` where nothing is hit) and `za`, `zb` (the ends' depths), only
    /// the parts in front of the surface are drawn (depth interpolated in 1/z, as perspective
    /// projection maps it).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn line(
        &mut self,
        a: (f64, f64),
        b: (f64, f64),
        za: f64,
        zb: f64,
        depth: Option<&[f32]>,
        rgb: u32,
        alpha: f32,
    ) {
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let n = dx.abs().max(dy.abs()).ceil();
        if !n.is_finite() || n > 16_384.0 {
            return; // off-screen ends far away: callers clip to the view first
        }
        let steps = n.max(1.0) as usize;
        let (ia, ib) = (1.0 / za.max(1e-9), 1.0 / zb.max(1e-9));
        for i in 0..=steps {
            let t = i as f64 / steps as f64;
            let (x, y) = (a.0 + dx * t, a.1 + dy * t);
            if x < 0.0 || y < 0.0 || x >= self.width as f64 || y >= self.height as f64 {
                continue;
            }
            let k = y as usize * self.width + x as usize;
            if let Some(d) = depth {
                let z = 1.0 / (ia + (ib - ia) * t);
                // A small bias keeps lines lying on a surface (the grid on the ground) visible.
                if f64::from(d[k]) < z * (1.0 - 1e-3) {
                    continue;
                }
            }
            self.put(k, rgb, alpha);
        }
    }

    /// A horizontal slider: track, filled part, label. `t` in [0, 1].
    pub(crate) fn slider(&mut self, x: usize, y: usize, w: usize, t: f64, label: &str) {
        self.shade(x, y, w, 14);
        let filled = ((w as f64) * t.clamp(0.0, 1.0)) as usize;
        self.fill(x, y + 10, filled, 4, 0x00f0_b040);
        self.text(x + 4, y + 1, label, 0x00ff_ffff);
    }
}

/// `rgb` with opacity `alpha` over a premultiplied 0xAARRGGBB pixel: c = α·rgb + (1 − α)·c,
/// a = α + (1 − α)·a, in 8 bits.
fn over(under: u32, rgb: u32, alpha: f32) -> u32 {
    let a = alpha.clamp(0.0, 1.0);
    let src = (rgb & 0x00ff_ffff) | 0xff00_0000;
    let mut out = 0;
    for shift in [24, 16, 8, 0] {
        let u = ((under >> shift) & 0xff) as f32;
        let o = ((src >> shift) & 0xff) as f32;
        out |= ((o * a + u * (1.0 - a)).round() as u32 & 0xff) << shift;
    }
    out
}

/// A layer drawn with `layer: true` put over an opaque 0RGB frame: c = o + (1 − a)·c (what
/// `present.wgsl` does on the GPU).
pub(crate) fn composite(frame: &mut [u32], layer: &[u32]) {
    for (f, &o) in frame.iter_mut().zip(layer) {
        let k = 1.0 - ((o >> 24) & 0xff) as f32 / 255.0;
        let mut out = 0;
        for shift in [16, 8, 0] {
            let u = ((*f >> shift) & 0xff) as f32;
            let c = ((o >> shift) & 0xff) as f32;
            out |= (((c + k * u).round() as u32).min(255)) << shift;
        }
        *f = out;
    }
}

/// `over` on `under` (0RGB), `alpha` in [0, 1].
fn blend(under: u32, over: u32, alpha: f32) -> u32 {
    let a = alpha.clamp(0.0, 1.0);
    let mut out = 0;
    for shift in [16, 8, 0] {
        let u = ((under >> shift) & 0xff) as f32;
        let o = ((over >> shift) & 0xff) as f32;
        out |= ((u + (o - u) * a).round() as u32 & 0xff) << shift;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_overlay_font_has_the_symbols_it_prints() {
        for ch in "²°×÷µ·αεσ".chars() {
            assert!(has_glyph(ch), "no glyph for {ch}");
        }
        // A glyph that draws something differs from the fallback '?'.
        assert_ne!(glyph('ε'), glyph('?'));
        assert_ne!(glyph('²'), glyph('?'));
    }

    #[test]
    fn lines_behind_the_surface_are_hidden() {
        let mut buf = vec![0u32; 16 * 4];
        let depth = vec![1.0f32; 16 * 4];
        let mut c = Canvas {
            buf: &mut buf,
            width: 16,
            height: 4,
            layer: false,
        };
        // Depth 0.5 → 2.0 along the line, 1/z linear in t: in front of depth 1 for t < 2/3,
        // pixels 0–9 of 15.
        c.line(
            (0.0, 1.0),
            (15.0, 1.0),
            0.5,
            2.0,
            Some(&depth),
            0x00ff_ffff,
            1.0,
        );
        let row: Vec<bool> = (0..16).map(|x| buf[16 + x] != 0).collect();
        assert!(row[..10].iter().all(|&r| r), "{row:?}");
        assert!(row[11..].iter().all(|&r| !r), "{row:?}");
    }

    /// What is drawn into a layer and put over a frame is what is drawn into the frame
    /// itself (the GPU window's overlay against the CPU window's), within one 8-bit step.
    #[test]
    fn a_layer_over_the_frame_is_the_frame_drawn_into() {
        let (w, h) = (64, 24);
        let frame: Vec<u32> = (0..w * h)
            .map(|i| {
                let v = (i * 2654435761usize) as u32;
                v & 0x00ff_ffff
            })
            .collect();
        let draw = |c: &mut Canvas| {
            c.panel(2, 2, &["ε² × 3".to_string(), "α = 0.25".to_string()]);
            c.line((0.0, 0.0), (63.0, 23.0), 1.0, 1.0, None, 0x00ff_8020, 0.6);
            c.slider(0, 10, 64, 0.4, "roughness");
        };
        let mut direct = frame.clone();
        draw(&mut Canvas {
            buf: &mut direct,
            width: w,
            height: h,
            layer: false,
        });
        let mut layer = vec![0u32; w * h];
        draw(&mut Canvas {
            buf: &mut layer,
            width: w,
            height: h,
            layer: true,
        });
        let mut composed = frame.clone();
        composite(&mut composed, &layer);
        let mut worst = 0;
        for (a, b) in direct.iter().zip(&composed) {
            for shift in [16, 8, 0] {
                worst =
                    worst.max((((a >> shift) & 0xff) as i32 - ((b >> shift) & 0xff) as i32).abs());
            }
        }
        assert!(worst <= 1, "largest difference {worst} (8-bit)");
        // The layer drew something, and left the rest transparent.
        assert!(layer.iter().any(|&p| p >> 24 == 0xff));
        assert!(layer.contains(&0));
        assert_ne!(direct, frame);
    }
}
