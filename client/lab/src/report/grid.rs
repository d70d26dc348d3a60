//! The image grid of a scene: each method's image above its error heat map, labelled.

use std::path::Path;

use anyhow::{Context, Result};

use bspvt_client::frame::canvas::Canvas;

/// Label strip height (8×8 font, 2 px margins).
const LABEL: usize = 12;
/// Tiles per row.
const COLUMNS: usize = 5;

pub(crate) struct Tile {
    pub(crate) label: String,
    pub(crate) image: image::RgbImage,
    pub(crate) heat_map: Option<image::RgbImage>,
}

impl Tile {
    pub(crate) fn new(
        label: &str,
        image: image::RgbImage,
        heat_map: Option<image::RgbImage>,
    ) -> Tile {
        Tile {
            label: label.to_string(),
            image,
            heat_map,
        }
    }
}

/// Square tiles of `size` pixels.
pub(crate) struct Grid {
    size: usize,
    tiles: Vec<Tile>,
}

impl Grid {
    pub(crate) fn new(size: u32) -> Grid {
        Grid {
            size: size as usize,
            tiles: Vec::new(),
        }
    }

    pub(crate) fn push(&mut self, t: Tile) {
        self.tiles.push(t);
    }

    /// Composes the grid: per tile a label, the image, and the heat map below it (blank for
    /// the reference).
    pub(crate) fn render(&self) -> image::RgbImage {
        let s = self.size;
        let cols = self.tiles.len().clamp(1, COLUMNS);
        let rows = self.tiles.len().div_ceil(cols).max(1);
        let (cw, ch) = (s + 2, LABEL + 2 * s + 2);
        let (width, height) = (cols * cw, rows * ch);
        let mut buf = vec![0x0020_2020u32; width * height];
        let mut canvas = Canvas {
            buf: &mut buf,
            width,
            height,
            layer: false,
        };
        for (i, t) in self.tiles.iter().enumerate() {
            let (x0, y0) = ((i % cols) * cw, (i / cols) * ch);
            let max_chars = s / 8;
            let label: String = t.label.chars().take(max_chars).collect();
            canvas.text(x0 + 1, y0 + 2, &label, 0x00ff_ffff);
            blit(&mut canvas, &t.image, x0 + 1, y0 + LABEL);
            if let Some(h) = &t.heat_map {
                blit(&mut canvas, h, x0 + 1, y0 + LABEL + s);
            }
        }
        let mut out = image::RgbImage::new(width as u32, height as u32);
        for (o, p) in out.pixels_mut().zip(&buf) {
            o.0 = [(p >> 16) as u8, (p >> 8) as u8, *p as u8];
        }
        out
    }

    pub(crate) fn save(&self, path: &Path) -> Result<()> {
        self.render()
            .save(path)
            .with_context(|| format!("cannot write {}", path.display()))
    }
}

fn blit(c: &mut Canvas, img: &image::RgbImage, x0: usize, y0: usize) {
    for (x, y, p) in img.enumerate_pixels() {
        let (x, y) = (x0 + x as usize, y0 + y as usize);
        if x < c.width && y < c.height {
            let [r, g, b] = p.0;
            c.buf[y * c.width + x] = (u32::from(r) << 16) | (u32::from(g) << 8) | u32::from(b);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_land_where_the_layout_says() {
        let mut g = Grid::new(16);
        for k in 0..7u8 {
            let img = image::RgbImage::from_pixel(16, 16, image::Rgb([k * 30, 0, 0]));
            let heat =
                (k > 0).then(|| image::RgbImage::from_pixel(16, 16, image::Rgb([0, 0, 255])));
            g.push(Tile::new(&format!("m{k}"), img, heat));
        }
        let out = g.render();
        // 5 columns, 2 rows of (label + 2 × 16 + 2) × (16 + 2).
        assert_eq!(out.dimensions(), (5 * 18, 2 * (12 + 34)));
        // Tile 6 (row 1, column 1): its image and its heat map.
        let (x0, y0) = (18 + 1, 46 + 12);
        assert_eq!(out.get_pixel(x0 + 3, y0 + 3).0, [180, 0, 0]);
        assert_eq!(out.get_pixel(x0 + 3, y0 + 16 + 3).0, [0, 0, 255]);
        // Tile 0 has no heat map: background below its image.
        assert_eq!(out.get_pixel(4, 12 + 16 + 4).0, [0x20, 0x20, 0x20]);
    }
}
