//! Adapter and device, the pipeline cache, and one frame's passes: the pyramid pre-pass,
//! then the shading pass tile by tile, each timed (GPU timestamps where the adapter has
//! them, wall time otherwise).

use super::layout::{
    GpuDecimation, GpuLevel, GpuStep, GpuTap, ShadeParams, FEATURE_BLOCKERS, FEATURE_HEIGHTFIELD, FEATURE_PHONG,
    SLOT_NONE, SLOT_UNKNOWN,
};
use super::program::{Features, MarchShape, ShadeProgram, Specialisation, LAVAPIPE_LOOP_LIMIT, PYRAMID_WGSL};
use super::GpuError;
use crate::heightfield::{decimation_taps, PyramidPlan};
use crate::scene::{Frame, Material, Scene};
use crate::shade::frame::{check_frame, height_field, height_map_file, pixel_work, PixelWork};
use crate::shade::kernel::PixelPasses;
use crate::shade::passes::{assemble, Pixel};
use crate::shade::{ShadeError, ShadedFrame, ShadedPasses, ShadingKernel, ShadingSettings};
use crate::timing::{Clock, StageTimings};
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Instant;
use wgpu::util::DeviceExt;

/// Invocations per workgroup of the shading pass (`@workgroup_size(64)`).
const WORKGROUP: u32 = 64;
/// `vec4<f32>` per shading point in (position and slot, normal, reflected view), and per
/// shaded point out (diffuse, specular, visibility terms).
const POINT_VEC4S: u64 = 3;
const SHADED_VEC4S: usize = 3;

/// What a pixel of a tile is: a colour known without shading, or a shaded point whose
/// result is multiplied by a tint.
#[derive(Clone, Copy, Debug)]
enum TileWork {
    Fixed([f32; 4]),
    Shaded([f32; 3]),
}

/// A GPU adapter and device with the pipelines built so far.
pub struct Gpu {
    info: wgpu::AdapterInfo,
    device: wgpu::Device,
    queue: wgpu::Queue,
    limits: wgpu::Limits,
    timestamps: bool,
    /// Errors wgpu reports outside an error scope (validation, out of memory, device
    /// lost), turned into [`GpuError`]s after each submission instead of a panic.
    errors: Arc<Mutex<Vec<String>>>,
    shade_pipelines: Mutex<HashMap<String, Arc<wgpu::ComputePipeline>>>,
    pyramid_pipelines: Mutex<Option<Arc<(wgpu::ComputePipeline, wgpu::ComputePipeline)>>>,
    /// An upper bound on the points per tile below the adapter's own.
    max_tile_points: Option<usize>,
}

impl Gpu {
    /// Takes the first high-performance adapter of the primary backends (Vulkan, Metal,
    /// DX12; `WGPU_BACKEND` overrides) and a device with its full limits.
    pub fn new() -> Result<Self, GpuError> {
        let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        if std::env::var_os("WGPU_BACKEND").is_none() {
            descriptor.backends = wgpu::Backends::PRIMARY;
        }
        let backends = format!("{:?}", descriptor.backends);
        let instance = wgpu::Instance::new(descriptor);
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|_| GpuError::NoAdapter { backends })?;
        let info = adapter.get_info();
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("logsh"),
            required_features: if timestamps { wgpu::Features::TIMESTAMP_QUERY } else { wgpu::Features::empty() },
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoDevice { adapter: info.name.clone(), message: e.to_string() })?;
        let errors = Arc::new(Mutex::new(Vec::new()));
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            sink.lock().expect("error list").push(e.to_string());
        }));
        let sink = errors.clone();
        device.set_device_lost_callback(move |reason, message| {
            sink.lock().expect("error list").push(format!("device lost ({reason:?}): {message}"));
        });
        Ok(Self {
            info,
            device,
            queue,
            limits,
            timestamps,
            errors,
            shade_pipelines: Mutex::new(HashMap::new()),
            pyramid_pipelines: Mutex::new(None),
            max_tile_points: None,
        })
    }

    /// Shades at most `points` pixels per dispatch (tiles are otherwise as large as the
    /// adapter's buffer and dispatch limits allow): bounds the GPU memory a frame takes.
    pub fn with_max_tile_points(mut self, points: usize) -> Self {
        self.max_tile_points = Some(points.max(1));
        self
    }

    /// Pixels per tile for a frame of `pixels` pixels on this adapter.
    pub fn tile_points(&self, pixels: usize) -> usize {
        let binding = self.limits.max_storage_buffer_binding_size.min(self.limits.max_buffer_size);
        let by_buffer = binding / (POINT_VEC4S * 16);
        let by_dispatch = u64::from(self.limits.max_compute_workgroups_per_dimension) * u64::from(WORKGROUP);
        let limit = by_buffer.min(by_dispatch) as usize;
        limit.min(self.max_tile_points.unwrap_or(usize::MAX)).min(pixels).max(1)
    }

    /// The adapter, as "name (backend, driver)".
    pub fn adapter(&self) -> String {
        let i = &self.info;
        format!("{} ({:?}, {} {})", i.name, i.backend, i.driver, i.driver_info).trim_end().to_string()
    }

    /// Mesa's CPU driver, whose loop budget limits what it can shade.
    pub fn is_lavapipe(&self) -> bool {
        self.info.driver == "llvmpipe" || self.info.name.starts_with("llvmpipe")
    }

    /// Whether stage times come from GPU timestamps.
    pub fn has_timestamps(&self) -> bool {
        self.timestamps
    }

    fn wgpu_error(&self, during: &str, message: String) -> GpuError {
        GpuError::Wgpu { adapter: self.info.name.clone(), during: during.to_string(), message }
    }

    /// Fails with the first error wgpu reported since the last check.
    fn check_errors(&self, during: &str) -> Result<(), GpuError> {
        let mut errors = self.errors.lock().expect("error list");
        if errors.is_empty() {
            return Ok(());
        }
        let message = errors.join("; ");
        errors.clear();
        Err(self.wgpu_error(during, message))
    }

    fn wait(&self, during: &str) -> Result<(), GpuError> {
        self.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| self.wgpu_error(during, e.to_string()))?;
        self.check_errors(during)
    }

    /// Shades one frame (the GPU counterpart of [`crate::shade::shade_frame`]).
    pub fn shade_frame(
        &self,
        scene: &Scene,
        frame: &Frame,
        settings: &ShadingSettings,
    ) -> Result<ShadedFrame, GpuError> {
        Ok(self.shade_frame_timed(scene, frame, settings, Specialisation::Full)?.0)
    }

    /// Shades one frame and times each stage; `specialisation` below
    /// [`Specialisation::Full`] only measures what specialisation saves.
    pub fn shade_frame_timed(
        &self,
        scene: &Scene,
        frame: &Frame,
        settings: &ShadingSettings,
        specialisation: Specialisation,
    ) -> Result<(ShadedFrame, StageTimings), GpuError> {
        let g = &frame.gbuffer;
        let mut rgba = vec![[0.0f32; 4]; g.width * g.height];
        let timings = self.shade_tiles(scene, frame, settings, specialisation, false, &mut |start, work, shaded| {
            rgba[start..start + work.len()].par_iter_mut().zip(work.par_iter()).enumerate().for_each(
                |(i, (out, w))| {
                    *out = match *w {
                        TileWork::Fixed(colour) => colour,
                        TileWork::Shaded(tint) => {
                            let (d, s) = (shaded[SHADED_VEC4S * i], shaded[SHADED_VEC4S * i + 1]);
                            [tint[0] * (d[0] + s[0]), tint[1] * (d[1] + s[1]), tint[2] * (d[2] + s[2]), 1.0]
                        }
                    };
                },
            );
        })?;
        Ok((ShadedFrame { width: g.width, height: g.height, rgba }, timings))
    }

    /// Shades one frame into compositing passes and visibility terms (the GPU
    /// counterpart of [`crate::shade::shade_frame_passes`]).
    pub fn shade_frame_passes(
        &self,
        scene: &Scene,
        frame: &Frame,
        settings: &ShadingSettings,
    ) -> Result<ShadedPasses, GpuError> {
        let g = &frame.gbuffer;
        let mut pixels = vec![Pixel::fixed([0.0; 4]); g.width * g.height];
        self.shade_tiles(scene, frame, settings, Specialisation::Full, true, &mut |start, work, shaded| {
            for (i, (w, out)) in work.iter().zip(&mut pixels[start..]).enumerate() {
                *out = match *w {
                    TileWork::Fixed(colour) => Pixel::fixed(colour),
                    TileWork::Shaded(tint) => {
                        let (d, s, v) =
                            (shaded[SHADED_VEC4S * i], shaded[SHADED_VEC4S * i + 1], shaded[SHADED_VEC4S * i + 2]);
                        let seen = PixelPasses {
                            diffuse: [d[0], d[1], d[2]],
                            specular: [s[0], s[1], s[2]],
                            visibility: v[0],
                            visibility_heightfield: v[1],
                            visibility_blockers: v[2],
                        };
                        Pixel::shaded(seen, tint)
                    }
                };
            }
        })?;
        Ok(assemble(frame, &pixels))
    }

    /// The frame's passes, tile by tile: `consume(first pixel, what each pixel of the tile
    /// is, SHADED_VEC4S vec4 per pixel)`.
    fn shade_tiles(
        &self,
        scene: &Scene,
        frame: &Frame,
        settings: &ShadingSettings,
        specialisation: Specialisation,
        passes: bool,
        consume: &mut dyn FnMut(usize, &[TileWork], &[[f32; 4]]),
    ) -> Result<StageTimings, GpuError> {
        settings.validate().map_err(ShadeError::Settings)?;
        if settings.double_precision {
            return Err(GpuError::Unsupported("--precision f64 (the GPU pass runs in f32)".into()));
        }
        check_frame(scene, frame)?;
        let mut timings = StageTimings::default();

        // Host tables: the CPU kernel's, re-laid for the program.
        let started = Instant::now();
        let field = height_field(scene, frame)?;
        let plan = field
            .as_ref()
            .map(|f| {
                PyramidPlan::new(f, settings.horizon)
                    .map_err(|source| ShadeError::HeightField { file: height_map_file(scene), source })
            })
            .transpose()?;
        let light = frame.light.sh_coefficients(settings.order);
        let kernel = ShadingKernel::<f32>::new(settings, &scene.materials, &light, field.is_some());
        let features = Features {
            heightfield: field.is_some(),
            blockers: !frame.blockers.is_empty(),
            phong: scene.materials.values().any(|m| matches!(m, Material::Phong { .. })),
            specialisation,
            passes,
        };
        let march =
            plan.as_ref().map(|p| MarchShape::of(p, settings.horizon.reconstruction, settings.horizon.scale_max));
        let program = ShadeProgram::new(&kernel, features, march);
        timings.add_wall("tables", started);
        if self.is_lavapipe() {
            let needed = program.loop_iterations(frame.blockers.len());
            if needed > LAVAPIPE_LOOP_LIMIT {
                return Err(GpuError::LoopBudget {
                    adapter: self.info.name.clone(),
                    needed,
                    limit: LAVAPIPE_LOOP_LIMIT,
                    what: format!(
                        "order {}, {:?}, {} blocker(s), {}",
                        settings.order,
                        settings.exp,
                        frame.blockers.len(),
                        march.map_or("no height field".to_string(), |m| format!(
                            "W {} x {} steps",
                            m.directions, m.steps
                        ))
                    ),
                });
            }
        }

        let started = Instant::now();
        let pipeline = self.shade_pipeline(&program.source)?;
        timings.add_wall("compile", started);

        let started = Instant::now();
        let tables = self.storage("tables", bytemuck::cast_slice(&program.tables))?;
        let materials = self.storage("materials", bytemuck::cast_slice(&program.materials))?;
        let spheres: Vec<[f32; 4]> = if frame.blockers.is_empty() {
            vec![[0.0; 4]]
        } else {
            frame
                .blockers
                .iter()
                .map(|s| [s.center[0] as f32, s.center[1] as f32, s.center[2] as f32, s.radius as f32])
                .collect()
        };
        let spheres = self.storage("spheres", bytemuck::cast_slice(&spheres))?;
        timings.add_wall("upload", started);

        // The height field: level 0 uploaded, the other levels filtered on the GPU.
        let mut rect = [0.0f32; 4];
        let heightfield = match (&field, &plan) {
            (Some(field), Some(plan)) => {
                rect = [field.min()[0] as f32, field.min()[1] as f32, field.max()[0] as f32, field.max()[1] as f32];
                Some(self.build_pyramid(field.heights(), plan, &mut timings)?)
            }
            _ => None,
        };
        let generic = specialisation != Specialisation::Full;
        let dummy_levels = if heightfield.is_none() && generic {
            Some((
                self.storage("levels", bytemuck::cast_slice(&[0.0f32]))?,
                self.storage(
                    "level table",
                    bytemuck::cast_slice(&[GpuLevel { columns: 1, rows: 1, ..Default::default() }]),
                )?,
                self.storage("steps", bytemuck::cast_slice(&[GpuStep::default()]))?,
            ))
        } else {
            None
        };
        let level_buffers = heightfield
            .as_ref()
            .map(|h| (&h.levels, &h.level_table, &h.steps))
            .or(dummy_levels.as_ref().map(|d| (&d.0, &d.1, &d.2)));

        let feature_bits = (if features.heightfield { FEATURE_HEIGHTFIELD } else { 0 })
            | (if features.blockers { FEATURE_BLOCKERS } else { 0 })
            | (if features.phong { FEATURE_PHONG } else { 0 });
        let g = &frame.gbuffer;
        let width = g.width;
        let pixels = width * g.height;

        // Tiles: as many points as one buffer binding and one dispatch allow.
        let tile = self.tile_points(pixels);
        let point_bytes = tile as u64 * POINT_VEC4S * 16;
        let shaded_bytes = tile as u64 * SHADED_VEC4S as u64 * 16;
        let points_buffer =
            self.buffer("points", point_bytes, wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST);
        let shaded_buffer =
            self.buffer("shaded", shaded_bytes, wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC);
        let readback =
            self.buffer("readback", shaded_bytes, wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST);
        let params_buffer = self.buffer(
            "params",
            std::mem::size_of::<ShadeParams>() as u64,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        );
        let layout = pipeline.get_bind_group_layout(0);
        let mut entries = vec![
            entry(0, &params_buffer),
            entry(1, &tables),
            entry(2, &points_buffer),
            entry(3, &shaded_buffer),
            entry(4, &materials),
        ];
        if features.blockers || generic {
            entries.push(entry(5, &spheres));
        }
        if let Some((levels, level_table, steps)) = level_buffers {
            entries.push(entry(6, levels));
            entries.push(entry(7, level_table));
            entries.push(entry(8, steps));
        }
        let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("shade"),
            layout: &layout,
            entries: &entries,
        });
        self.check_errors("binding the shading pass")?;
        let timer = self.timer();

        let mut points = vec![[0.0f32; 4]; tile * POINT_VEC4S as usize];
        let mut work = vec![TileWork::Fixed([0.0; 4]); tile];
        let mut start = 0;
        while start < pixels {
            let end = (start + tile).min(pixels);
            let count = end - start;

            // The frame walk (shared with the CPU path): fixed colours go straight to the
            // image, the tint of each shaded point waits there until its result is back.
            let started = Instant::now();
            points[..count * POINT_VEC4S as usize]
                .par_chunks_mut(POINT_VEC4S as usize)
                .zip(work[..count].par_iter_mut())
                .enumerate()
                .for_each(|(i, (point, out))| {
                    let pixel = start + i;
                    let (x, y) = (pixel % width, pixel / width);
                    match pixel_work(&scene.materials, frame, x, y) {
                        PixelWork::Fixed(colour) => {
                            *out = TileWork::Fixed(colour);
                            point[0] = [0.0, 0.0, 0.0, f32::from_bits(SLOT_NONE)];
                        }
                        PixelWork::Shade { point: p, tint } => {
                            *out = TileWork::Shaded(tint);
                            let slot = program.slots.get(&p.material).copied().unwrap_or(SLOT_UNKNOWN);
                            let reflected = crate::shade::kernel::reflect_view(p.view_origin, p.position, p.normal);
                            let f = |v: [f64; 3], w: f32| [v[0] as f32, v[1] as f32, v[2] as f32, w];
                            point[0] = f(p.position, f32::from_bits(slot));
                            point[1] = f(p.normal, 0.0);
                            point[2] = f(reflected, 0.0);
                        }
                    }
                });
            timings.add_wall("frame walk", started);

            let started = Instant::now();
            let params = ShadeParams {
                point_count: count as u32,
                sphere_count: frame.blockers.len() as u32,
                log_epsilon: settings.epsilon.ln() as f32,
                hyb_threshold: settings.hyb_threshold as f32,
                heightfield_rect: rect,
                feature_bits,
                order: settings.order as u32,
                coefficient_count: (settings.order * settings.order) as u32,
                nodes: program.nodes as u32,
            };
            self.queue.write_buffer(&params_buffer, 0, bytemuck::bytes_of(&params));
            self.queue.write_buffer(&points_buffer, 0, bytemuck::cast_slice(&points[..count * POINT_VEC4S as usize]));
            let mut encoder =
                self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("shade") });
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("shade"),
                    timestamp_writes: timer.as_ref().map(|t| t.writes()),
                });
                pass.set_pipeline(&pipeline);
                pass.set_bind_group(0, &bind_group, &[]);
                pass.dispatch_workgroups((count as u32).div_ceil(WORKGROUP), 1, 1);
            }
            let out_bytes = count as u64 * SHADED_VEC4S as u64 * 16;
            encoder.copy_buffer_to_buffer(&shaded_buffer, 0, &readback, 0, out_bytes);
            if let Some(t) = &timer {
                t.resolve(&mut encoder);
            }
            self.queue.submit([encoder.finish()]);
            self.wait("the shading pass")?;
            let shade_wall = started.elapsed().as_secs_f64() * 1e3;
            match timer.as_ref().map(|t| t.read(self)).transpose()? {
                Some(ms) => {
                    timings.add("shade", ms, Clock::Gpu);
                    timings.add("upload + readback", (shade_wall - ms).max(0.0), Clock::Wall);
                }
                None => timings.add("shade", shade_wall, Clock::Wall),
            }

            let started = Instant::now();
            let slice = readback.slice(..out_bytes);
            slice.map_async(wgpu::MapMode::Read, |_| {});
            self.wait("reading the shaded tile back")?;
            {
                let data = slice
                    .get_mapped_range()
                    .map_err(|e| self.wgpu_error("reading the shaded tile back", e.to_string()))?;
                let shaded: &[[f32; 4]] = bytemuck::cast_slice(&data);
                consume(start, &work[..count], shaded);
            }
            readback.unmap();
            timings.add_wall("readback", started);
            start = end;
        }
        Ok(timings)
    }

    fn buffer(&self, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: size.max(16),
            usage,
            mapped_at_creation: false,
        })
    }

    /// A read-only storage buffer holding `data`, after checking the adapter's limit.
    fn storage(&self, label: &str, data: &[u8]) -> Result<wgpu::Buffer, GpuError> {
        self.check_size(label, data.len() as u64)?;
        Ok(self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: data,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        }))
    }

    fn check_size(&self, what: &str, needed: u64) -> Result<(), GpuError> {
        let limit = self.limits.max_storage_buffer_binding_size.min(self.limits.max_buffer_size);
        if needed > limit {
            return Err(GpuError::TooLarge { what: what.to_string(), needed, limit, adapter: self.info.name.clone() });
        }
        Ok(())
    }

    fn compile(&self, label: &str, source: &str) -> Result<wgpu::ShaderModule, GpuError> {
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = self.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        if let Some(error) = pollster::block_on(scope.pop()) {
            return Err(self.wgpu_error(&format!("compiling {label}"), error.to_string()));
        }
        Ok(module)
    }

    fn pipeline(&self, module: &wgpu::ShaderModule, entry_point: &str) -> Result<wgpu::ComputePipeline, GpuError> {
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let pipeline = self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry_point),
            layout: None,
            module,
            entry_point: Some(entry_point),
            compilation_options: Default::default(),
            cache: None,
        });
        if let Some(error) = pollster::block_on(scope.pop()) {
            return Err(self.wgpu_error(&format!("building pipeline {entry_point}"), error.to_string()));
        }
        Ok(pipeline)
    }

    /// The shading pipeline of `source`, compiled once per distinct program.
    fn shade_pipeline(&self, source: &str) -> Result<Arc<wgpu::ComputePipeline>, GpuError> {
        if let Some(p) = self.shade_pipelines.lock().expect("pipeline cache").get(source) {
            return Ok(p.clone());
        }
        let module = self.compile("shade.wgsl", source)?;
        let pipeline = Arc::new(self.pipeline(&module, "shade")?);
        self.shade_pipelines.lock().expect("pipeline cache").insert(source.to_string(), pipeline.clone());
        Ok(pipeline)
    }

    fn pyramid_pipelines(&self) -> Result<Arc<(wgpu::ComputePipeline, wgpu::ComputePipeline)>, GpuError> {
        let mut cached = self.pyramid_pipelines.lock().expect("pipeline cache");
        if let Some(p) = cached.as_ref() {
            return Ok(p.clone());
        }
        let source = super::layout::wgsl_declarations() + PYRAMID_WGSL;
        let module = self.compile("pyramid.wgsl", &source)?;
        let pair = Arc::new((self.pipeline(&module, "decimate_x")?, self.pipeline(&module, "decimate_y")?));
        *cached = Some(pair.clone());
        Ok(pair)
    }

    /// Uploads level 0 and filters the coarser levels on the GPU with the CPU path's tent
    /// taps (`shaders/pyramid.wgsl`).
    fn build_pyramid(
        &self,
        heights: &[f32],
        plan: &PyramidPlan,
        timings: &mut StageTimings,
    ) -> Result<HeightFieldBuffers, GpuError> {
        let started = Instant::now();
        let n = plan.sizes[0];
        let mut level_table = Vec::with_capacity(plan.sizes.len());
        let mut offset = 0usize;
        for size in &plan.sizes {
            level_table.push(GpuLevel { offset: offset as u32, columns: size[0] as u32, rows: size[1] as u32, pad: 0 });
            offset += size[0] * size[1];
        }
        let total = offset;
        let mut decimations = Vec::new();
        let mut ranges: Vec<[u32; 2]> = Vec::new();
        let mut taps: Vec<GpuTap> = Vec::new();
        let mut scratch = 0usize;
        let mut push_taps = |n_in: usize, n_out: usize, ranges: &mut Vec<[u32; 2]>| {
            let first = ranges.len() as u32;
            for list in decimation_taps(n_in, n_out) {
                ranges.push([taps.len() as u32, list.len() as u32]);
                taps.extend(list.iter().map(|&(index, weight)| GpuTap { index: index as u32, weight: weight as f32 }));
            }
            first
        };
        for (j, size) in plan.sizes.iter().enumerate().skip(1) {
            let ranges_x = push_taps(n[0], size[0], &mut ranges);
            let ranges_y = push_taps(n[1], size[1], &mut ranges);
            decimations.push(GpuDecimation {
                in_columns: n[0] as u32,
                in_rows: n[1] as u32,
                out_columns: size[0] as u32,
                out_rows: size[1] as u32,
                ranges_x,
                ranges_y,
                scratch_offset: scratch as u32,
                level_offset: level_table[j].offset,
            });
            scratch += n[1] * size[0];
        }
        if total > u32::MAX as usize || scratch > u32::MAX as usize {
            return Err(GpuError::TooLarge {
                what: "the height-field pyramid".into(),
                needed: (total.max(scratch) * 4) as u64,
                limit: u64::from(u32::MAX) * 4,
                adapter: self.info.name.clone(),
            });
        }
        self.check_size("the height-field pyramid levels", total as u64 * 4)?;
        self.check_size("the height-field pyramid scratch", scratch as u64 * 4)?;
        let levels =
            self.buffer("levels", total as u64 * 4, wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST);
        self.queue.write_buffer(&levels, 0, bytemuck::cast_slice(heights));
        let steps: Vec<GpuStep> = plan
            .steps
            .iter()
            .map(|s| GpuStep {
                distance: s.distance as f32,
                inv_distance: s.inv_distance as f32,
                level: s.level as u32,
                pad: 0,
            })
            .collect();
        let steps = if steps.is_empty() { vec![GpuStep::default()] } else { steps };
        let steps = self.storage("steps", bytemuck::cast_slice(&steps))?;
        let level_table_buffer = self.storage("level table", bytemuck::cast_slice(&level_table))?;
        timings.add_wall("upload", started);

        if !decimations.is_empty() {
            let max_dimension = self.limits.max_compute_workgroups_per_dimension as usize;
            if n[1] > max_dimension || decimations.len() > max_dimension {
                return Err(GpuError::TooLarge {
                    what: format!("a {} x {} height map's pyramid dispatch", n[0], n[1]),
                    needed: n[1].max(decimations.len()) as u64,
                    limit: max_dimension as u64,
                    adapter: self.info.name.clone(),
                });
            }
            let started = Instant::now();
            let pipelines = self.pyramid_pipelines()?;
            let decimation_buffer = self.storage("decimations", bytemuck::cast_slice(&decimations))?;
            let range_buffer = self.storage("tap ranges", bytemuck::cast_slice(&ranges))?;
            let tap_buffer = self.storage("taps", bytemuck::cast_slice(&taps))?;
            let scratch_buffer = self.buffer("pyramid scratch", scratch as u64 * 4, wgpu::BufferUsages::STORAGE);
            let timer = self.timer();
            let mut encoder =
                self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("pyramid") });
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("pyramid"),
                    timestamp_writes: timer.as_ref().map(|t| t.writes()),
                });
                let columns = decimations.iter().map(|d| d.out_columns).max().unwrap_or(1);
                let rows_x = n[1] as u32;
                let rows_y = decimations.iter().map(|d| d.out_rows).max().unwrap_or(1);
                for (pipeline, rows) in [(&pipelines.0, rows_x), (&pipelines.1, rows_y)] {
                    let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some("pyramid"),
                        layout: &pipeline.get_bind_group_layout(0),
                        entries: &[
                            entry(0, &decimation_buffer),
                            entry(1, &range_buffer),
                            entry(2, &tap_buffer),
                            entry(3, &scratch_buffer),
                            entry(4, &levels),
                        ],
                    });
                    pass.set_pipeline(pipeline);
                    pass.set_bind_group(0, &bind_group, &[]);
                    pass.dispatch_workgroups(columns.div_ceil(WORKGROUP), rows, decimations.len() as u32);
                }
            }
            if let Some(t) = &timer {
                t.resolve(&mut encoder);
            }
            self.queue.submit([encoder.finish()]);
            self.wait("the pyramid pre-pass")?;
            match timer.as_ref().map(|t| t.read(self)).transpose()? {
                Some(ms) => timings.add("pyramid", ms, Clock::Gpu),
                None => timings.add_wall("pyramid", started),
            }
        }
        Ok(HeightFieldBuffers { levels, level_table: level_table_buffer, steps })
    }

    fn timer(&self) -> Option<PassTimer> {
        self.timestamps.then(|| PassTimer::new(&self.device))
    }
}

/// The height field's buffers for the shading pass.
struct HeightFieldBuffers {
    levels: wgpu::Buffer,
    level_table: wgpu::Buffer,
    steps: wgpu::Buffer,
}

fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry { binding, resource: buffer.as_entire_binding() }
}

/// Timestamps at the start and end of one compute pass.
struct PassTimer {
    queries: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    readback: wgpu::Buffer,
}

impl PassTimer {
    fn new(device: &wgpu::Device) -> Self {
        Self {
            queries: device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("pass timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            }),
            resolved: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamps"),
                size: 16,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }),
            readback: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamps readback"),
                size: 16,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        }
    }

    fn writes(&self) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: Some(0),
            end_of_pass_write_index: Some(1),
        }
    }

    fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.resolve_query_set(&self.queries, 0..2, &self.resolved, 0);
        encoder.copy_buffer_to_buffer(&self.resolved, 0, &self.readback, 0, 16);
    }

    /// Milliseconds between the two timestamps (after the submission completed).
    fn read(&self, gpu: &Gpu) -> Result<f64, GpuError> {
        let slice = self.readback.slice(..);
        slice.map_async(wgpu::MapMode::Read, |_| {});
        gpu.wait("reading timestamps")?;
        let ticks: [u64; 2] = {
            let data = slice.get_mapped_range().map_err(|e| gpu.wgpu_error("reading timestamps", e.to_string()))?;
            let t: &[u64] = bytemuck::cast_slice(&data);
            [t[0], t[1]]
        };
        self.readback.unmap();
        let period = f64::from(gpu.queue.get_timestamp_period());
        Ok(ticks[1].saturating_sub(ticks[0]) as f64 * period * 1e-6)
    }
}
