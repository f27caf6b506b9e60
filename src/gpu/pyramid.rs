//! The height-field pyramid pre-pass: level 0 uploaded, the coarser levels filtered on
//! the GPU from the frame plan's [`PyramidPlan`] with the CPU executor's tent taps
//! ([`decimation_taps`], `shaders/pyramid.wgsl`), so both executors march the same
//! levels.

use super::device::entry;
use super::layout::{GpuDecimation, GpuLevel, GpuStep, GpuTap, WORKGROUP_SIZE};
use super::{Gpu, GpuError};
use crate::heightfield::{decimation_taps, PyramidPlan};
use crate::shade::Terrain;
use crate::timing::StageTimings;
use std::time::Instant;

/// The height field's buffers for the shading pass.
pub(super) struct HeightFieldBuffers {
    pub(super) levels: wgpu::Buffer,
    pub(super) level_table: wgpu::Buffer,
    pub(super) steps: wgpu::Buffer,
}

/// Where each level lives in the levels buffer and which taps filter it, laid out on the
/// host from the plan.
struct PyramidTables {
    /// Level-0 size.
    base: [usize; 2],
    level_table: Vec<GpuLevel>,
    /// One per level above 0.
    decimations: Vec<GpuDecimation>,
    /// `[first tap, tap count]` per output column (pass x) or row (pass y).
    ranges: Vec<[u32; 2]>,
    taps: Vec<GpuTap>,
    /// Samples of all levels, and of the scratch between pass x and pass y.
    samples: usize,
    scratch: usize,
}

impl PyramidTables {
    fn new(plan: &PyramidPlan) -> Self {
        let base = plan.sizes[0];
        let mut level_table = Vec::with_capacity(plan.sizes.len());
        let mut samples = 0usize;
        for size in &plan.sizes {
            level_table.push(GpuLevel {
                offset: samples as u32,
                columns: size[0] as u32,
                rows: size[1] as u32,
                pad: 0,
            });
            samples += size[0] * size[1];
        }
        let mut tables = Self {
            base,
            level_table,
            decimations: Vec::new(),
            ranges: Vec::new(),
            taps: Vec::new(),
            samples,
            scratch: 0,
        };
        for (j, size) in plan.sizes.iter().enumerate().skip(1) {
            let ranges_x = tables.push_taps(base[0], size[0]);
            let ranges_y = tables.push_taps(base[1], size[1]);
            tables.decimations.push(GpuDecimation {
                in_columns: base[0] as u32,
                in_rows: base[1] as u32,
                out_columns: size[0] as u32,
                out_rows: size[1] as u32,
                ranges_x,
                ranges_y,
                scratch_offset: tables.scratch as u32,
                level_offset: tables.level_table[j].offset,
            });
            tables.scratch += base[1] * size[0];
        }
        tables
    }

    /// Appends the taps of `n_in` samples decimated to `n_out`; returns the first range.
    fn push_taps(&mut self, n_in: usize, n_out: usize) -> u32 {
        let first = self.ranges.len() as u32;
        for list in decimation_taps(n_in, n_out) {
            self.ranges.push([self.taps.len() as u32, list.len() as u32]);
            self.taps.extend(list.iter().map(|&(index, weight)| GpuTap { index: index as u32, weight: weight as f32 }));
        }
        first
    }
}

impl Gpu {
    /// The pyramid of `terrain` on the GPU, timing "upload" and "pyramid".
    pub(super) fn build_pyramid(
        &self,
        terrain: &Terrain,
        timings: &mut StageTimings,
    ) -> Result<HeightFieldBuffers, GpuError> {
        let started = Instant::now();
        let tables = PyramidTables::new(&terrain.pyramid);
        self.check_pyramid_size(&tables)?;
        let buffers = self.upload_pyramid(terrain, &tables)?;
        timings.add_wall("upload", started);
        if !tables.decimations.is_empty() {
            self.decimate(&tables, &buffers.levels, timings)?;
        }
        Ok(buffers)
    }

    /// Refuses a pyramid whose indices overflow `u32` or whose buffers or dispatch exceed
    /// the adapter's limits.
    fn check_pyramid_size(&self, tables: &PyramidTables) -> Result<(), GpuError> {
        let adapter = self.info.name.clone();
        if tables.samples > u32::MAX as usize || tables.scratch > u32::MAX as usize {
            return Err(GpuError::TooLarge {
                what: "the height-field pyramid".into(),
                needed: (tables.samples.max(tables.scratch) * 4) as u64,
                limit: u64::from(u32::MAX) * 4,
                adapter,
            });
        }
        self.check_size("the height-field pyramid levels", tables.samples as u64 * 4)?;
        self.check_size("the height-field pyramid scratch", tables.scratch as u64 * 4)?;
        let max_dimension = self.limits.max_compute_workgroups_per_dimension as usize;
        let rows = tables.base[1];
        if !tables.decimations.is_empty() && (rows > max_dimension || tables.decimations.len() > max_dimension) {
            return Err(GpuError::TooLarge {
                what: format!("a {} x {} height map's pyramid dispatch", tables.base[0], rows),
                needed: rows.max(tables.decimations.len()) as u64,
                limit: max_dimension as u64,
                adapter,
            });
        }
        Ok(())
    }

    /// Level 0 into the levels buffer, and the march's level and step tables.
    fn upload_pyramid(&self, terrain: &Terrain, tables: &PyramidTables) -> Result<HeightFieldBuffers, GpuError> {
        let levels = self.buffer(
            "levels",
            tables.samples as u64 * 4,
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        );
        self.queue.write_buffer(&levels, 0, bytemuck::cast_slice(terrain.field.heights()));
        let mut steps: Vec<GpuStep> = terrain
            .pyramid
            .steps
            .iter()
            .map(|s| GpuStep {
                distance: s.distance as f32,
                inv_distance: s.inv_distance as f32,
                level: s.level as u32,
                pad: 0,
            })
            .collect();
        if steps.is_empty() {
            steps.push(GpuStep::default());
        }
        Ok(HeightFieldBuffers {
            levels,
            level_table: self.storage("level table", bytemuck::cast_slice(&tables.level_table))?,
            steps: self.storage("steps", bytemuck::cast_slice(&steps))?,
        })
    }

    /// Filters every level above 0 in two passes (along x into the scratch, then along
    /// y into the level), one dispatch each for all levels.
    fn decimate(
        &self,
        tables: &PyramidTables,
        levels: &wgpu::Buffer,
        timings: &mut StageTimings,
    ) -> Result<(), GpuError> {
        let started = Instant::now();
        let pipelines = self.pyramid_pipelines()?;
        let decimations = self.storage("decimations", bytemuck::cast_slice(&tables.decimations))?;
        let ranges = self.storage("tap ranges", bytemuck::cast_slice(&tables.ranges))?;
        let taps = self.storage("taps", bytemuck::cast_slice(&tables.taps))?;
        let scratch = self.buffer("pyramid scratch", tables.scratch as u64 * 4, wgpu::BufferUsages::STORAGE);
        let columns = tables.decimations.iter().map(|d| d.out_columns).max().unwrap_or(1);
        let rows_x = tables.base[1] as u32;
        let rows_y = tables.decimations.iter().map(|d| d.out_rows).max().unwrap_or(1);
        let bind_groups = [&pipelines.0, &pipelines.1].map(|pipeline| {
            self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("pyramid"),
                layout: &pipeline.get_bind_group_layout(0),
                entries: &[
                    entry(0, &decimations),
                    entry(1, &ranges),
                    entry(2, &taps),
                    entry(3, &scratch),
                    entry(4, levels),
                ],
            })
        });
        self.run_pass("pyramid", started, timings, |pass| {
            for ((pipeline, bind_group), rows) in
                [&pipelines.0, &pipelines.1].into_iter().zip(&bind_groups).zip([rows_x, rows_y])
            {
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, bind_group, &[]);
                pass.dispatch_workgroups(columns.div_ceil(WORKGROUP_SIZE), rows, tables.decimations.len() as u32);
            }
        })?;
        Ok(())
    }
}
