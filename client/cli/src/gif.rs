//! The animated preview of a frame sequence (GIF, frames downscaled to at most 256 pixels).

use std::path::Path;

use anyhow::{Context, Result};
use image::codecs::gif::{GifEncoder, Repeat};
use image::imageops::FilterType;
use image::{Delay, DynamicImage, Frame};

use bspvt_client::frame::image::Image;

/// Longest side of a preview frame.
const PREVIEW_SIZE: u32 = 256;

/// Collects tone-mapped frames and writes them as one looping GIF.
#[derive(Default)]
pub(crate) struct Preview {
    frames: Vec<image::RgbaImage>,
}

impl Preview {
    pub(crate) fn push(&mut self, img: &Image, exposure: f32) {
        let rgb = DynamicImage::ImageRgb8(img.to_srgb8(exposure));
        let scale = f64::from(PREVIEW_SIZE) / f64::from(img.width.max(img.height).max(1));
        let rgb = if scale < 1.0 {
            let w = ((f64::from(img.width) * scale).round() as u32).max(1);
            let h = ((f64::from(img.height) * scale).round() as u32).max(1);
            rgb.resize_exact(w, h, FilterType::Triangle)
        } else {
            rgb
        };
        self.frames.push(rgb.to_rgba8());
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Writes the GIF, `frame_ms` per frame.
    pub(crate) fn save(self, path: &Path, frame_ms: u32) -> Result<()> {
        let file = std::fs::File::create(path)
            .with_context(|| format!("cannot create {}", path.display()))?;
        let mut enc = GifEncoder::new_with_speed(std::io::BufWriter::new(file), 10);
        enc.set_repeat(Repeat::Infinite)?;
        let delay = Delay::from_numer_denom_ms(frame_ms, 1);
        enc.encode_frames(
            self.frames
                .into_iter()
                .map(|f| Frame::from_parts(f, 0, 0, delay)),
        )
        .with_context(|| format!("cannot write {}", path.display()))
    }
}
