//! Incremental parsing of a tree stream (a bake file arriving over the network): the header
//! frame, then chunk frames, each handed out as soon as its last byte is in.

use bspvt_proto::encoding::{BakeHeader, Chunk, decode_chunk, decode_header, peek_chunk};
use bspvt_proto::error::DecodeError;

/// One complete frame.
pub(crate) enum Frame {
    Header(BakeHeader, Vec<u8>),
    /// A decoded chunk and its frame bytes exactly as received (for the cache).
    Chunk(Chunk, Vec<u8>),
}

/// Buffers bytes and cuts them into frames.
#[derive(Default)]
pub(crate) struct FrameReader {
    buf: Vec<u8>,
    header: Option<BakeHeader>,
}

impl FrameReader {
    pub(crate) fn new() -> FrameReader {
        FrameReader::default()
    }

    pub(crate) fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    /// Bytes received but not yet part of a complete frame.
    pub(crate) fn pending(&self) -> usize {
        self.buf.len()
    }

    /// The next complete frame, `Ok(None)` when more bytes are needed.
    pub(crate) fn next_frame(&mut self) -> Result<Option<Frame>, DecodeError> {
        if self.buf.is_empty() {
            return Ok(None);
        }
        match &self.header {
            None => match decode_header(&self.buf) {
                Ok((h, used)) => {
                    let bytes: Vec<u8> = self.buf.drain(..used).collect();
                    self.header = Some(h.clone());
                    Ok(Some(Frame::Header(h, bytes)))
                }
                Err(e) if incomplete(&e) => Ok(None),
                Err(e) => Err(e),
            },
            Some(h) => {
                // Check framing and checksum before paying for decompression.
                match peek_chunk(&self.buf) {
                    Ok(_) => {}
                    Err(e) if incomplete(&e) => return Ok(None),
                    Err(e) => return Err(e),
                }
                let (chunk, used) = decode_chunk(&self.buf, h)?;
                let bytes: Vec<u8> = self.buf.drain(..used).collect();
                Ok(Some(Frame::Chunk(chunk, bytes)))
            }
        }
    }
}

/// Only a frame cut short means "wait for more bytes"; anything else is corrupt.
fn incomplete(e: &DecodeError) -> bool {
    matches!(e, DecodeError::Truncated("frame header" | "frame body"))
}
