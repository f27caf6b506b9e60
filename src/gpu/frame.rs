//! One frame on the GPU, in the steps of wgpu's compute examples: prepare (the frame plan
//! turned into a program and its pipeline), bind (tables, pyramid and tile buffers), then
//! per tile: pack (the frame walk writes the points) and run (dispatch, read back).

use super::device::ShadePipelines;
use super::device::{entry, PassTimer};
use super::layout::{
    GpuBlockerNode, GpuLevel, GpuPoint, GpuShaded, GpuStep, ShadeParams, FEATURE_BLOCKERS, FEATURE_HEIGHTFIELD,
    FEATURE_PHONG, SLOT_NONE, SLOT_UNKNOWN, WORKGROUP_SIZE,
};
use super::program::{Features, MarchShape, ShadeProgram, Specialisation, VisibilityBlocks, LAVAPIPE_LOOP_LIMIT};
use super::pyramid::HeightFieldBuffers;
use super::{Gpu, GpuError};

use crate::shade::compositing::{assemble, Pixel};
use crate::shade::kernel::reflect_view;
use crate::shade::visibility_grid::{is_direct_surface, BlockPoints};

use crate::shade::{pixel_work, FramePlan, Outputs, PixelPasses, PixelWork, PlannedKernel, Shaded, ShadedFrame, Tint};
use crate::timing::{Clock, StageTimings};
use rayon::prelude::*;
use std::sync::Arc;
use std::time::Instant;
use wgpu::util::DeviceExt;

/// What a pixel of a tile is: a colour known without shading, or a shaded point whose
/// result is multiplied by a tint.
#[derive(Clone, Copy, Debug)]
enum TileWork {
    Fixed([f32; 4]),
    Shaded(Tint),
}

/// Receives each shaded tile: its first pixel, what each of its pixels is, its shaded
/// points.
type ConsumeTile<'c> = dyn FnMut(usize, &[TileWork], &[GpuShaded]) + 'c;

/// A frame's plan with the program generated from it and its compiled pipelines.
struct PreparedFrame<'p, 'a> {
    plan: &'p FramePlan<'a>,
    program: ShadeProgram,
    pipelines: Arc<ShadePipelines>,
}

/// The buffers of one frame's shading pass and the bind group over them.
struct BoundFrame {
    pipelines: Arc<ShadePipelines>,
    /// Points per tile.
    tile: usize,
    points: wgpu::Buffer,
    shaded: wgpu::Buffer,
    readback: wgpu::Buffer,
    params: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    /// The parameters of every tile but its point count.
    frame_params: ShadeParams,
    timer: Option<PassTimer>,
    /// The frame's read-only inputs, alive as long as the bind group.
    _inputs: Vec<wgpu::Buffer>,
    _heightfield: Option<HeightFieldBuffers>,
    _grid: Option<wgpu::Buffer>,
}

impl Gpu {
    /// Shades every pixel of `plan` into `outputs` (the GPU counterpart of
    /// [`crate::shade::cpu::shade_plan`]), adding its stages to `timings`;
    /// `specialisation` below [`Specialisation::Full`] only measures what specialisation
    /// saves.
    pub fn shade_plan(
        &self,
        plan: &FramePlan,
        outputs: Outputs,
        specialisation: Specialisation,
        timings: &mut StageTimings,
    ) -> Result<Shaded, GpuError> {
        let g = &plan.frame.gbuffer;
        let rgb = |v: [f32; 4]| [v[0], v[1], v[2]];
        Ok(match outputs {
            Outputs::Beauty => {
                let mut rgba = vec![[0.0f32; 4]; g.width * g.height];
                self.shade_tiles(plan, specialisation, false, timings, &mut |start, work, shaded| {
                    rgba[start..start + work.len()].par_iter_mut().zip(work.par_iter().zip(shaded)).for_each(
                        |(out, (w, s))| {
                            *out = match *w {
                                TileWork::Fixed(colour) => colour,
                                TileWork::Shaded(tint) => tint.beauty(rgb(s.diffuse), rgb(s.specular)),
                            };
                        },
                    );
                })?;
                Shaded::Beauty(ShadedFrame { width: g.width, height: g.height, rgba })
            }
            Outputs::Passes => {
                let mut pixels = vec![Pixel::fixed([0.0; 4]); g.width * g.height];
                self.shade_tiles(plan, specialisation, true, timings, &mut |start, work, shaded| {
                    for ((w, s), out) in work.iter().zip(shaded).zip(&mut pixels[start..]) {
                        *out = match *w {
                            TileWork::Fixed(colour) => Pixel::fixed(colour),
                            TileWork::Shaded(tint) => {
                                let seen = PixelPasses {
                                    diffuse: rgb(s.diffuse),
                                    specular: rgb(s.specular),
                                    visibility: s.visibility[0],
                                    visibility_heightfield: s.visibility[1],
                                    visibility_blockers: s.visibility[2],
                                };
                                Pixel::shaded(seen, tint)
                            }
                        };
                    }
                })?;
                Shaded::Passes(assemble(plan.frame, &pixels))
            }
        })
    }

    /// The frame tile by tile: `consume(first pixel, what each pixel of the tile is, its
    /// shaded points)`.
    fn shade_tiles(
        &self,
        plan: &FramePlan,
        specialisation: Specialisation,
        passes: bool,
        timings: &mut StageTimings,
        consume: &mut ConsumeTile,
    ) -> Result<(), GpuError> {
        let _turn = self.one_frame_at_a_time.lock();
        let prepared = self.prepare(plan, specialisation, passes, timings)?;
        let bound = self.bind(&prepared, timings)?;
        let pixels = plan.frame.gbuffer.width * plan.frame.gbuffer.height;
        let mut points = vec![GpuPoint::default(); bound.tile];
        let mut work = vec![TileWork::Fixed([0.0; 4]); bound.tile];
        for start in (0..pixels).step_by(bound.tile) {
            let count = bound.tile.min(pixels - start);
            let started = Instant::now();
            pack_tile(&prepared, start, &mut points[..count], &mut work[..count]);
            timings.add_wall("frame walk", started);
            self.run_tile(&bound, start, &points[..count], timings, |shaded| consume(start, &work[..count], shaded))?;
        }
        Ok(())
    }

    /// The plan's program (refused where lavapipe's loop budget would cut it
    /// short) and the program's pipeline, timing "tables" and "compile".
    fn prepare<'p, 'a>(
        &self,
        plan: &'p FramePlan<'a>,
        specialisation: Specialisation,
        passes: bool,
        timings: &mut StageTimings,
    ) -> Result<PreparedFrame<'p, 'a>, GpuError> {
        let (scene, frame, settings) = (plan.scene, plan.frame, &plan.settings);
        let started = Instant::now();
        let PlannedKernel::F32(kernel) = plan.kernel.as_ref() else {
            return Err(GpuError::double_precision());
        };
        kernel.prepare_glossy(&scene.materials, frame);
        let march = plan.terrain.as_ref().map(|t| MarchShape::of(&t.pyramid, &settings.horizon));
        // The grid where there is something to occlude, as on the CPU (cpu.rs, shade_pixels).
        let occluded = plan.contents.heightfield || plan.contents.blockers;
        let grid = if occluded { settings.visibility_grid } else { 1 };
        let features = Features { contents: plan.contents, specialisation, passes, grid };
        let program = ShadeProgram::new(kernel, features, march, &plan.sun_shadows);
        timings.add_wall("tables", started);
        if self.is_lavapipe() {
            self.check_loop_budget(&program, plan, march)?;
        }
        if grid > 1 {
            self.check_grid_bindings(grid)?;
        }
        let started = Instant::now();
        let pipelines = self.shade_pipelines(&program.source, grid > 1)?;
        timings.add_wall("compile", started);
        Ok(PreparedFrame { plan, program, pipelines })
    }

    /// lavapipe ends an invocation's loops after [`LAVAPIPE_LOOP_LIMIT`] iterations: a
    /// program that may need more would silently shade a wrong image.
    fn check_loop_budget(
        &self,
        program: &ShadeProgram,
        plan: &FramePlan,
        march: Option<MarchShape>,
    ) -> Result<(), GpuError> {
        let blockers = plan.frame.blockers.len();
        let needed = program.loop_iterations(blockers);
        if needed <= LAVAPIPE_LOOP_LIMIT {
            return Ok(());
        }
        let settings = &plan.settings;
        Err(GpuError::LoopBudget {
            adapter: self.info.name.clone(),
            needed,
            limit: LAVAPIPE_LOOP_LIMIT,
            what: format!(
                "order {}, {:?}, {blockers} blocker(s), {}",
                settings.order,
                settings.exp,
                march.map_or("no height field".to_string(), |m| format!("W {} x {} steps", m.directions, m.steps))
            ),
        })
    }

    /// Uploads the program's tables, the spheres and the pyramid, allocates the tile
    /// buffers and binds them all, timing "upload" (and "pyramid").
    fn bind(&self, prepared: &PreparedFrame, timings: &mut StageTimings) -> Result<BoundFrame, GpuError> {
        let PreparedFrame { plan, program, pipelines } = prepared;
        let features = program.features;
        let generic = features.specialisation != Specialisation::Full;
        let started = Instant::now();
        let [tables, materials, spheres] = self.upload_inputs(plan, program)?;
        timings.add_wall("upload", started);

        // The height field: level 0 uploaded, the other levels filtered on the GPU. The
        // generic program binds placeholders when the frame has none.
        let heightfield = plan.terrain.as_ref().map(|terrain| self.build_pyramid(terrain, timings)).transpose()?;
        let placeholders = if heightfield.is_none() && generic {
            Some(HeightFieldBuffers {
                levels: self.storage("levels", bytemuck::cast_slice(&[0.0f32]))?,
                level_table: self.storage(
                    "level table",
                    bytemuck::cast_slice(&[GpuLevel { columns: 1, rows: 1, ..Default::default() }]),
                )?,
                steps: self.storage("steps", bytemuck::cast_slice(&[GpuStep::default()]))?,
            })
        } else {
            None
        };

        let pixels = plan.frame.gbuffer.width * plan.frame.gbuffer.height;
        let tile = self.tile_points(pixels);
        let point_bytes = (tile * std::mem::size_of::<GpuPoint>()) as u64;
        let shaded_bytes = (tile * std::mem::size_of::<GpuShaded>()) as u64;
        use wgpu::BufferUsages as Usage;
        let points = self.buffer("points", point_bytes, Usage::STORAGE | Usage::COPY_DST);
        let shaded = self.buffer("shaded", shaded_bytes, Usage::STORAGE | Usage::COPY_SRC);
        let readback = self.buffer("readback", shaded_bytes, Usage::MAP_READ | Usage::COPY_DST);
        let params = self.buffer("params", std::mem::size_of::<ShadeParams>() as u64, Usage::UNIFORM | Usage::COPY_DST);

        let mut entries =
            vec![entry(0, &params), entry(1, &tables), entry(2, &points), entry(3, &shaded), entry(4, &materials)];
        if features.contents.blockers || generic {
            entries.push(entry(5, &spheres));
        }
        if let Some(h) = heightfield.as_ref().or(placeholders.as_ref()) {
            entries.extend([entry(6, &h.levels), entry(7, &h.level_table), entry(8, &h.steps)]);
        }
        let mut frame_params = frame_params(plan, program);
        let grid = match &pipelines.grid {
            Some(pre_pass) => {
                Some(self.visibility_grid(plan, program, pre_pass, &entries, &mut frame_params, timings)?)
            }
            None => None,
        };
        if let Some(grid) = &grid {
            entries.push(entry(9, grid));
        }
        let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("shade"),
            layout: &pipelines.shade.get_bind_group_layout(0),
            entries: &entries,
        });
        self.check_errors("binding the shading pass")?;
        drop(entries);

        Ok(BoundFrame {
            pipelines: pipelines.clone(),
            tile,
            points,
            shaded,
            readback,
            params,
            bind_group,
            frame_params,
            timer: self.timer(),
            _inputs: vec![tables, materials, spheres],
            _heightfield: heightfield.or(placeholders),
            _grid: grid,
        })
    }

    /// The program's tables and material slots, and the frame's blocker tree.
    fn upload_inputs(&self, plan: &FramePlan, program: &ShadeProgram) -> Result<[wgpu::Buffer; 3], GpuError> {
        let mut nodes: Vec<GpuBlockerNode> = plan.blockers.f32_nodes().to_vec();
        if nodes.is_empty() {
            nodes.push(GpuBlockerNode::default());
        }
        Ok([
            self.storage("tables", bytemuck::cast_slice(&program.tables))?,
            self.storage("materials", bytemuck::cast_slice(&program.materials))?,
            self.storage("blocker tree", bytemuck::cast_slice(&nodes))?,
        ])
    }

    /// An adapter binds at most so many storage buffers to a pass; the grid's is a ninth.
    fn check_grid_bindings(&self, grid: usize) -> Result<(), GpuError> {
        let limit = self.limits.max_storage_buffers_per_shader_stage;
        if limit < GRID_STORAGE_BUFFERS {
            return Err(GpuError::Unsupported(format!(
                "--visibility-grid {grid} on {}, which binds {limit} storage buffers to a pass where the grid needs \
                 {GRID_STORAGE_BUFFERS}",
                self.info.name
            )));
        }
        Ok(())
    }

    /// The visibility grid's pre-pass (`grid_visibility` in shaders/shade.wgsl): each
    /// block's point ([`BlockPoints`]) uploaded, its horizons and caps computed on the
    /// device into the buffer the shading pass then reads, timing "visibility grid".
    /// Returns the buffer, and sets the blocks along x and y in `frame_params`.
    fn visibility_grid(
        &self,
        plan: &FramePlan,
        program: &ShadeProgram,
        pre_pass: &wgpu::ComputePipeline,
        shade_entries: &[wgpu::BindGroupEntry],
        frame_params: &mut ShadeParams,
        timings: &mut StageTimings,
    ) -> Result<wgpu::Buffer, GpuError> {
        let started = Instant::now();
        let (frame, materials) = (plan.frame, &plan.scene.materials);
        let size = program.features.grid;
        let BlockPoints { blocks, points } =
            BlockPoints::new(frame, materials, size, |x, y| pixel_work(materials, frame, x, y));
        let stride = program.blocks.stride();
        let mut records = vec![0.0f32; points.len() * stride];
        records.par_chunks_mut(stride).zip(&points).for_each(|(record, point)| {
            if let Some(p) = point {
                let [x, y, z] = p.position.map(|v| v as f32);
                let [nx, ny, nz] = p.normal.map(|v| v as f32);
                record[..VisibilityBlocks::HEADER].copy_from_slice(&[
                    x,
                    y,
                    z,
                    f32::from_bits(p.object),
                    nx,
                    ny,
                    nz,
                    1.0,
                ]);
            }
        });
        let max_dimension = self.limits.max_compute_workgroups_per_dimension as usize;
        let groups = points.len().div_ceil(WORKGROUP_SIZE as usize);
        if groups > max_dimension {
            return Err(GpuError::TooLarge {
                what: format!("the visibility grid's pre-pass over {} x {} blocks", blocks[0], blocks[1]),
                needed: groups as u64,
                limit: max_dimension as u64,
                adapter: self.info.name.clone(),
            });
        }
        self.check_size("the visibility grid", (records.len() * 4) as u64)?;
        let grid = self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("visibility grid"),
            contents: bytemuck::cast_slice(&records),
            usage: wgpu::BufferUsages::STORAGE,
        });
        [frame_params.grid_columns, frame_params.grid_rows] = blocks.map(|b| b as u32);
        let params = self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("visibility grid params"),
            contents: bytemuck::bytes_of(frame_params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        // The pre-pass reads the shading pass's inputs but its points, results and
        // materials.
        let mut entries: Vec<wgpu::BindGroupEntry> =
            shade_entries.iter().filter(|e| ![0, 2, 3, 4].contains(&e.binding)).cloned().collect();
        entries.extend([entry(0, &params), entry(9, &grid)]);
        let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("visibility grid"),
            layout: &pre_pass.get_bind_group_layout(0),
            entries: &entries,
        });
        self.check_errors("binding the visibility grid's pre-pass")?;
        self.run_pass("visibility grid", started, timings, |pass| {
            pass.set_pipeline(pre_pass);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(groups as u32, 1, 1);
        })?;
        Ok(grid)
    }

    /// Shades one tile of packed points and hands the shaded points to `consume`, timing
    /// "shade" (GPU timestamps where the adapter has them), "upload + readback" and
    /// "readback".
    fn run_tile(
        &self,
        bound: &BoundFrame,
        start: usize,
        points: &[GpuPoint],
        timings: &mut StageTimings,
        consume: impl FnOnce(&[GpuShaded]),
    ) -> Result<(), GpuError> {
        let count = points.len();
        let started = Instant::now();
        let params = ShadeParams { point_count: count as u32, tile_start: start as u32, ..bound.frame_params };
        self.queue.write_buffer(&bound.params, 0, bytemuck::bytes_of(&params));
        self.queue.write_buffer(&bound.points, 0, bytemuck::cast_slice(points));
        let mut encoder = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("shade") });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("shade"),
                timestamp_writes: bound.timer.as_ref().map(|t| t.writes()),
            });
            pass.set_pipeline(&bound.pipelines.shade);
            pass.set_bind_group(0, &bound.bind_group, &[]);
            pass.dispatch_workgroups((count as u32).div_ceil(WORKGROUP_SIZE), 1, 1);
        }
        let out_bytes = (count * std::mem::size_of::<GpuShaded>()) as u64;
        encoder.copy_buffer_to_buffer(&bound.shaded, 0, &bound.readback, 0, out_bytes);
        if let Some(t) = &bound.timer {
            t.resolve(&mut encoder);
        }
        self.queue.submit([encoder.finish()]);
        self.wait("the shading pass")?;
        let shade_wall = started.elapsed().as_secs_f64() * 1e3;
        match bound.timer.as_ref().map(|t| t.read(self)).transpose()? {
            Some(ms) => {
                timings.add("shade", ms, Clock::Gpu);
                timings.add("upload + readback", (shade_wall - ms).max(0.0), Clock::Wall);
            }
            None => timings.add("shade", shade_wall, Clock::Wall),
        }

        let started = Instant::now();
        let slice = bound.readback.slice(..out_bytes);
        slice.map_async(wgpu::MapMode::Read, |_| {});
        self.wait("reading the shaded tile back")?;
        {
            let data =
                slice.get_mapped_range().map_err(|e| self.wgpu_error("reading the shaded tile back", e.to_string()))?;
            consume(bytemuck::cast_slice(&data));
        }
        bound.readback.unmap();
        timings.add_wall("readback", started);
        Ok(())
    }
}

/// The parameters of every tile of the frame but its point count.
fn frame_params(plan: &FramePlan, program: &ShadeProgram) -> ShadeParams {
    let rect = plan.terrain.as_ref().map_or([0.0; 4], |t| {
        let (min, max) = (t.field.min(), t.field.max());
        [min[0], min[1], max[0], max[1]].map(|v| v as f32)
    });
    let contents = program.features.contents;
    let settings = &plan.settings;
    ShadeParams {
        point_count: 0,
        node_count: plan.blockers.f32_nodes().len() as u32,
        log_epsilon: settings.epsilon.ln() as f32,
        hyb_threshold: settings.hyb_threshold as f32,
        heightfield_rect: rect,
        heightfield_peak: plan.terrain.as_ref().map_or(0.0, |t| t.field.highest() as f32),
        feature_bits: (if contents.heightfield { FEATURE_HEIGHTFIELD } else { 0 })
            | (if contents.blockers { FEATURE_BLOCKERS } else { 0 })
            | (if contents.phong { FEATURE_PHONG } else { 0 }),
        order: settings.order as u32,
        coefficient_count: (settings.order * settings.order) as u32,
        quad_rows: program.quadrature.rows as u32,
        quad_azimuths: program.quadrature.azimuths as u32,
        cluster_ratio: settings.cluster_ratio as f32,
        image_width: plan.frame.gbuffer.width as u32,
        ..Default::default()
    }
}

/// Storage buffers the shading pass binds with a visibility grid: tables, points, results,
/// materials, the blocker tree, the pyramid's three, and the grid.
const GRID_STORAGE_BUFFERS: u32 = 9;

/// The frame walk (shared with the CPU executor) over pixels `start..start + points.len()`:
/// fixed colours wait in `work` with the tint of each shaded point until its result is
/// back.
fn pack_tile(prepared: &PreparedFrame, start: usize, points: &mut [GpuPoint], work: &mut [TileWork]) {
    let PreparedFrame { plan, program, .. } = prepared;
    let width = plan.frame.gbuffer.width;
    points.par_iter_mut().zip(work.par_iter_mut()).enumerate().for_each(|(i, (point, out))| {
        let pixel = start + i;
        match pixel_work(&plan.scene.materials, plan.frame, pixel % width, pixel / width) {
            PixelWork::Fixed(colour) => {
                *out = TileWork::Fixed(colour);
                *point = GpuPoint { position_slot: [0.0, 0.0, 0.0, f32::from_bits(SLOT_NONE)], ..Default::default() };
            }
            PixelWork::Shade { point: p, tint } => {
                *out = TileWork::Shaded(tint);
                let served = is_direct_surface(&plan.scene.materials, plan.frame, pixel);
                let slot = program.slots.get(&p.material).copied().unwrap_or(SLOT_UNKNOWN);
                let vec4 = |v: [f64; 3], w: f32| [v[0] as f32, v[1] as f32, v[2] as f32, w];
                *point = GpuPoint {
                    position_slot: vec4(p.position, f32::from_bits(slot)),
                    normal: vec4(p.normal, f32::from_bits(p.object)),
                    reflected: vec4(reflect_view(p.view_origin, p.position, p.normal), if served { 1.0 } else { 0.0 }),
                };
            }
        }
    });
}
