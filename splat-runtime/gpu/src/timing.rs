//! Stage times measured on the GPU: a timestamp written by an empty compute pass before a
//! stage's first dispatch and after its last (only `TIMESTAMP_QUERY` is needed), resolved into
//! a buffer with the frame's other commands and read back only when the caller asks. A host
//! clock around a wait would time the submission and the wait, not the stage.

use super::{Gpu, GpuError};
use std::time::Duration;

/// Bytes between stages in the resolve buffer.
const SLOT: u64 = wgpu::QUERY_RESOLVE_BUFFER_ALIGNMENT;

/// Timestamps for `stages` stages (two queries each); inert on adapters without timestamps.
pub struct StageTimer {
    queries: Option<(wgpu::QuerySet, wgpu::Buffer, wgpu::Buffer)>,
    stages: u32,
}

impl StageTimer {
    pub fn new(gpu: &Gpu, stages: u32) -> StageTimer {
        let queries = gpu.timestamps.then(|| {
            let count = 2 * stages;
            let set = gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("stage timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count,
            });
            let buffer = |size, usage| {
                gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("stage timestamps"),
                    size,
                    usage,
                    mapped_at_creation: false,
                })
            };
            // Resolved stage by stage at offsets aligned to QUERY_RESOLVE_BUFFER_ALIGNMENT.
            let resolved = buffer(
                SLOT * stages as u64,
                wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            );
            let staging = buffer(
                16 * stages as u64,
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            );
            (set, resolved, staging)
        });
        StageTimer { queries, stages }
    }

    fn mark(&self, encoder: &mut wgpu::CommandEncoder, index: u32) {
        if let Some((set, _, _)) = &self.queries {
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: None,
                timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
                    query_set: set,
                    beginning_of_pass_write_index: Some(index),
                    end_of_pass_write_index: None,
                }),
            });
        }
    }

    /// Marks the start of `stage` (before its first dispatch).
    pub fn start(&self, encoder: &mut wgpu::CommandEncoder, stage: u32) {
        self.mark(encoder, 2 * stage);
    }

    /// Marks the end of `stage` (after its last dispatch).
    pub fn end(&self, encoder: &mut wgpu::CommandEncoder, stage: u32) {
        self.mark(encoder, 2 * stage + 1);
    }

    /// Resolves the stages `range` into the staging buffer (record after their ends).
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder, range: std::ops::Range<u32>) {
        if let Some((set, resolved, staging)) = &self.queries {
            for stage in range {
                let at = SLOT * stage as u64;
                encoder.resolve_query_set(set, 2 * stage..2 * stage + 2, resolved, at);
                encoder.copy_buffer_to_buffer(resolved, at, staging, 16 * stage as u64, 16);
            }
        }
    }

    /// Each stage's time (`None` without timestamps). Waits for the GPU.
    pub fn read(&self, gpu: &Gpu) -> Result<Option<Vec<Duration>>, GpuError> {
        let Some((_, _, staging)) = &self.queries else {
            return Ok(None);
        };
        let words = gpu.read_mappable(staging, 4 * self.stages as usize)?;
        let period = gpu.queue.get_timestamp_period() as f64;
        let ticks = |k: usize| words[2 * k] as u64 | (words[2 * k + 1] as u64) << 32;
        Ok(Some(
            (0..self.stages as usize)
                .map(|s| {
                    let (a, b) = (ticks(2 * s), ticks(2 * s + 1));
                    Duration::from_nanos((b.saturating_sub(a) as f64 * period) as u64)
                })
                .collect(),
        ))
    }
}
