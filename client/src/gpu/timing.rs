//! GPU time between a frame's passes: timestamps written into the command encoder before and
//! after each pass (wgpu's timestamp queries, where the device has
//! `TIMESTAMP_QUERY_INSIDE_ENCODERS`), for `bench-gpu`'s per-pass columns. Off unless asked
//! for ([`super::frame::GpuFrames::time_passes`]); a frame without it writes no query.

use anyhow::Result;

use super::context::Gpu;

/// Timestamps a frame can hold (its passes + 1).
const CAPACITY: u32 = 16;

/// One encoder's marks: a start, then one labelled mark after each pass.
pub(crate) struct PassClock {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    readback: wgpu::Buffer,
    /// The label of each mark (the first is the start's, "").
    labels: Vec<&'static str>,
    /// Nanoseconds per tick.
    period: f64,
}

impl PassClock {
    /// A clock on `gpu`, or `None` where the device cannot write timestamps between passes.
    pub(crate) fn new(gpu: &Gpu) -> Option<PassClock> {
        let needed =
            wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS;
        if !gpu.device.features().contains(needed) {
            return None;
        }
        let bytes = u64::from(CAPACITY) * 8;
        let buffer = |label, usage| {
            gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes,
                usage,
                mapped_at_creation: false,
            })
        };
        Some(PassClock {
            set: gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("pass timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: CAPACITY,
            }),
            resolved: buffer(
                "pass timestamps",
                wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            ),
            readback: buffer(
                "pass timestamps readback",
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            ),
            labels: Vec::new(),
            period: f64::from(gpu.queue.get_timestamp_period()),
        })
    }

    /// The first timestamp of `enc` (forgets the last frame's marks).
    pub(crate) fn start(&mut self, enc: &mut wgpu::CommandEncoder) {
        self.labels.clear();
        self.mark(enc, "");
    }

    /// A timestamp after the pass `label`.
    pub(crate) fn mark(&mut self, enc: &mut wgpu::CommandEncoder, label: &'static str) {
        let i = self.labels.len() as u32;
        if i < CAPACITY {
            enc.write_timestamp(&self.set, i);
            self.labels.push(label);
        }
    }

    /// Resolves the marks into the read-back buffer (the encoder's last commands).
    pub(crate) fn resolve(&self, enc: &mut wgpu::CommandEncoder) {
        let n = self.labels.len() as u32;
        if n == 0 {
            return;
        }
        enc.resolve_query_set(&self.set, 0..n, &self.resolved, 0);
        enc.copy_buffer_to_buffer(&self.resolved, 0, &self.readback, 0, u64::from(n) * 8);
    }

    /// Each pass's GPU time, ms, of the last resolved frame (waits for it).
    pub(crate) fn read(&self, gpu: &Gpu) -> Result<Vec<(&'static str, f64)>> {
        if self.labels.len() < 2 {
            return Ok(Vec::new());
        }
        let bytes = gpu.map_read(&self.readback)?;
        let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&bytes[..self.labels.len() * 8]);
        Ok(self.labels[1..]
            .iter()
            .zip(ticks.windows(2))
            // A counter may wrap or a device reorder: no negative times.
            .map(|(&l, t)| (l, t[1].saturating_sub(t[0]) as f64 * self.period * 1e-6))
            .collect())
    }

    /// Makes `slot`'s clock if it has none (`time_passes` of the frames and the compositor):
    /// false where the device cannot write timestamps between passes.
    pub(crate) fn ensure(slot: &mut Option<PassClock>, gpu: &Gpu) -> bool {
        if slot.is_none() {
            *slot = PassClock::new(gpu);
        }
        slot.is_some()
    }

    /// [`PassClock::read`] of `slot`'s clock; nothing without one.
    pub(crate) fn read_slot(
        slot: Option<&PassClock>,
        gpu: &Gpu,
    ) -> Result<Vec<(&'static str, f64)>> {
        slot.map_or(Ok(Vec::new()), |c| c.read(gpu))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Marks come back labelled, in order, one time per pass, finite and not negative; a new
    /// frame forgets the last one's marks, and marks past the query set's capacity are dropped.
    #[test]
    fn marks_come_back_as_pass_times() {
        let Some(gpu) = Gpu::shared_or_skip() else {
            return;
        };
        let Some(mut clock) = PassClock::new(gpu) else {
            eprintln!("skipped: the adapter has no timestamps inside encoders");
            return;
        };
        let frame = |clock: &mut PassClock, labels: &[&'static str]| {
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            clock.start(&mut enc);
            for &l in labels {
                clock.mark(&mut enc, l);
            }
            clock.resolve(&mut enc);
            gpu.queue.submit([enc.finish()]);
            clock.read(gpu).expect("timestamps read back")
        };
        let times = frame(&mut clock, &["shade", "raster"]);
        let labels: Vec<_> = times.iter().map(|t| t.0).collect();
        assert_eq!(labels, ["shade", "raster"]);
        assert!(
            times.iter().all(|t| t.1.is_finite() && t.1 >= 0.0),
            "{times:?}"
        );
        let many = ["pass"; 2 * CAPACITY as usize];
        let times = frame(&mut clock, &many);
        assert_eq!(times.len(), CAPACITY as usize - 1);
        let times = frame(&mut clock, &["composite"]);
        assert_eq!(times.iter().map(|t| t.0).collect::<Vec<_>>(), ["composite"]);
    }
}
