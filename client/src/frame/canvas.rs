//! Text and widgets drawn into the window's 0RGB framebuffer (8×8 bitmap font, public-domain
//! glyphs from `font8x8`).

use font8x8::{BASIC_FONTS, UnicodeFonts};

/// A 0RGB framebuffer to draw text and widgets into.
pub struct Canvas<'a> {
    /// Pixels, row by row, 0x00RRGGBB.
    pub buf: &'a mut [u32],
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
}

impl Canvas<'_> {
    /// Darkens a rectangle (the text's background) by half.
    pub(crate) fn shade(&mut self, x0: usize, y0: usize, w: usize, h: usize) {
        for y in y0..(y0 + h).min(self.height) {
            for x in x0..(x0 + w).min(self.width) {
                let p = &mut self.buf[y * self.width + x];
                *p = (*p >> 1) & 0x007f_7f7f;
            }
        }
    }

    pub(crate) fn fill(&mut self, x0: usize, y0: usize, w: usize, h: usize, rgb: u32) {
        for y in y0..(y0 + h).min(self.height) {
            for x in x0..(x0 + w).min(self.width) {
                self.buf[y * self.width + x] = rgb;
            }
        }
    }

    /// One line of text at (x, y) (top-left), 8 pixels per character.
    pub fn text(&mut self, x: usize, y: usize, s: &str, rgb: u32) {
        for (i, ch) in s.chars().enumerate() {
            let Some(glyph) = BASIC_FONTS.get(ch).or_else(|| BASIC_FONTS.get('?')) else {
                continue;
            };
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..8 {
                    if bits & (1 << col) != 0 {
                        let (px, py) = (x + i * 8 + col, y + row);
                        if px < self.width && py < self.height {
                            self.buf[py * self.width + px] = rgb;
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

    /// A horizontal slider: track, filled part, label. `t` in [0, 1].
    pub(crate) fn slider(&mut self, x: usize, y: usize, w: usize, t: f64, label: &str) {
        self.shade(x, y, w, 14);
        let filled = ((w as f64) * t.clamp(0.0, 1.0)) as usize;
        self.fill(x, y + 10, filled, 4, 0x00f0_b040);
        self.text(x + 4, y + 1, label, 0x00ff_ffff);
    }
}
