//! The GPU: adapter and device, buffers and their limits, compiled pipelines (cached
//! per program), errors turned into [`GpuError`]s, and pass timing by timestamps.

use super::layout::{wgsl_declarations, GpuPoint, GpuShaded, WORKGROUP_SIZE};
use super::program::PYRAMID_WGSL;
use super::GpuError;
use crate::timing::{Clock, StageTimings};
use parking_lot::ReentrantMutex;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use wgpu::util::DeviceExt;

/// The wgpu instance over the primary backends (Vulkan, Metal, DX12), or those
/// `WGPU_BACKEND` names, and those backends.
fn instance() -> (wgpu::Instance, wgpu::Backends) {
    let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    if std::env::var_os("WGPU_BACKEND").is_none() {
        descriptor.backends = wgpu::Backends::PRIMARY;
    }
    let backends = descriptor.backends;
    (wgpu::Instance::new(descriptor), backends)
}

/// An adapter as "name (backend, driver)".
fn describe(info: &wgpu::AdapterInfo) -> String {
    format!("{} ({:?}, {} {})", info.name, info.backend, info.driver, info.driver_info).trim_end().to_string()
}

/// The pipelines of one shading program: the pass, and the visibility grid's pre-pass
/// where the program has a grid.
pub(super) struct ShadePipelines {
    pub shade: wgpu::ComputePipeline,
    pub grid: Option<wgpu::ComputePipeline>,
}

/// A GPU adapter and device with the pipelines built so far.
pub struct Gpu {
    pub(super) info: wgpu::AdapterInfo,
    pub(super) device: wgpu::Device,
    pub(super) queue: wgpu::Queue,
    pub(super) limits: wgpu::Limits,
    pub(super) timestamps: bool,
    /// Errors wgpu reports outside an error scope (validation, out of memory, device
    /// lost), turned into [`GpuError`]s after each submission instead of a panic.
    errors: Arc<Mutex<Vec<String>>>,
    shade_pipelines: Mutex<HashMap<String, Arc<ShadePipelines>>>,
    pyramid_pipelines: Mutex<Option<Arc<(wgpu::ComputePipeline, wgpu::ComputePipeline)>>>,
    /// Held while a frame is on the device, from its plan to its last read-back, so that
    /// threads sharing one `Gpu` take turns: frames shaded from 16 threads at once never
    /// finished on an NVIDIA H200 (Vulkan, driver 580.159) while 2 or 4 did, and the
    /// uncaptured errors in `errors` are the device's, not a frame's. Re-entrant: a rayon
    /// worker waiting inside a frame's parallel work may take up another frame's job,
    /// which then shades on the same thread rather than waiting for itself.
    pub(super) one_frame_at_a_time: ReentrantMutex<()>,
    /// An upper bound on the points per tile below the adapter's own.
    max_tile_points: Option<usize>,
}

impl Gpu {
    /// Takes the first high-performance adapter of the primary backends (Vulkan, Metal,
    /// DX12; `WGPU_BACKEND` overrides), software adapters such as lavapipe included, and
    /// a device with its full limits.
    pub fn new() -> Result<Self, GpuError> {
        let (instance, backends) = instance();
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|_| GpuError::NoAdapter { backends: format!("{backends:?}") })?;
        Self::from_adapter(&adapter)
    }

    /// Takes a hardware adapter (discrete first, then integrated, then virtual): never a
    /// software one such as lavapipe, which runs the pass on the CPU more slowly than the
    /// CPU executor.
    pub fn new_hardware() -> Result<Self, GpuError> {
        let (instance, backends) = instance();
        let adapters = pollster::block_on(instance.enumerate_adapters(backends));
        let rank = |kind: wgpu::DeviceType| match kind {
            wgpu::DeviceType::DiscreteGpu => Some(0),
            wgpu::DeviceType::IntegratedGpu => Some(1),
            wgpu::DeviceType::VirtualGpu => Some(2),
            wgpu::DeviceType::Other => Some(3),
            wgpu::DeviceType::Cpu => None,
        };
        let best = adapters.iter().filter_map(|a| rank(a.get_info().device_type).map(|r| (r, a))).min_by_key(|p| p.0);
        match best {
            Some((_, adapter)) => Self::from_adapter(adapter),
            None if adapters.is_empty() => Err(GpuError::NoAdapter { backends: format!("{backends:?}") }),
            None => Err(GpuError::SoftwareOnly {
                adapters: adapters.iter().map(|a| describe(&a.get_info())).collect::<Vec<_>>().join(", "),
            }),
        }
    }

    fn from_adapter(adapter: &wgpu::Adapter) -> Result<Self, GpuError> {
        let info = adapter.get_info();
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("logsh"),
            required_features: if timestamps { wgpu::Features::TIMESTAMP_QUERY } else { wgpu::Features::empty() },
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoDevice { adapter: info.name.clone(), message: e.to_string() })?;
        Ok(Self::from_device(info, device, queue))
    }

    /// Drives an existing device and queue (of the adapter `info` describes): stage times
    /// come from GPU timestamps if the device was created with
    /// [`wgpu::Features::TIMESTAMP_QUERY`], tiles are sized by its limits, and its
    /// uncaptured errors and loss become [`GpuError`]s of the calls that meet them.
    pub fn from_device(info: wgpu::AdapterInfo, device: wgpu::Device, queue: wgpu::Queue) -> Self {
        let errors = Arc::new(Mutex::new(Vec::new()));
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            sink.lock().expect("error list").push(e.to_string());
        }));
        let sink = errors.clone();
        device.set_device_lost_callback(move |reason, message| {
            sink.lock().expect("error list").push(format!("device lost ({reason:?}): {message}"));
        });
        Self {
            timestamps: device.features().contains(wgpu::Features::TIMESTAMP_QUERY),
            limits: device.limits(),
            info,
            device,
            queue,
            errors,
            shade_pipelines: Mutex::new(HashMap::new()),
            pyramid_pipelines: Mutex::new(None),
            one_frame_at_a_time: ReentrantMutex::new(()),
            max_tile_points: None,
        }
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
        let by_buffer = binding / std::mem::size_of::<GpuPoint>().max(std::mem::size_of::<GpuShaded>()) as u64;
        let by_dispatch = u64::from(self.limits.max_compute_workgroups_per_dimension) * u64::from(WORKGROUP_SIZE);
        let limit = by_buffer.min(by_dispatch) as usize;
        limit.min(self.max_tile_points.unwrap_or(usize::MAX)).min(pixels).max(1)
    }

    /// The adapter, as "name (backend, driver)".
    pub fn adapter(&self) -> String {
        describe(&self.info)
    }

    /// Mesa's CPU driver, whose loop budget limits what it can shade.
    pub fn is_lavapipe(&self) -> bool {
        self.info.driver == "llvmpipe" || self.info.name.starts_with("llvmpipe")
    }

    pub(super) fn wgpu_error(&self, during: &str, message: String) -> GpuError {
        GpuError::Wgpu { adapter: self.info.name.clone(), during: during.to_string(), message }
    }

    /// Fails with the first error wgpu reported since the last check.
    pub(super) fn check_errors(&self, during: &str) -> Result<(), GpuError> {
        let mut errors = self.errors.lock().expect("error list");
        if errors.is_empty() {
            return Ok(());
        }
        let message = errors.join("; ");
        errors.clear();
        Err(self.wgpu_error(during, message))
    }

    pub(super) fn wait(&self, during: &str) -> Result<(), GpuError> {
        self.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| self.wgpu_error(during, e.to_string()))?;
        self.check_errors(during)
    }

    pub(super) fn buffer(&self, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: size.max(16),
            usage,
            mapped_at_creation: false,
        })
    }

    /// A read-only storage buffer holding `data`, after checking the adapter's limit.
    pub(super) fn storage(&self, label: &str, data: &[u8]) -> Result<wgpu::Buffer, GpuError> {
        self.check_size(label, data.len() as u64)?;
        Ok(self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: data,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        }))
    }

    pub(super) fn check_size(&self, what: &str, needed: u64) -> Result<(), GpuError> {
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
    /// The shading pass of `source` and, where the source has one, the visibility grid's
    /// pre-pass, compiled once per source.
    pub(super) fn shade_pipelines(&self, source: &str, grid: bool) -> Result<Arc<ShadePipelines>, GpuError> {
        if let Some(p) = self.shade_pipelines.lock().expect("pipeline cache").get(source) {
            return Ok(p.clone());
        }
        let module = self.compile("shade.wgsl", source)?;
        let pipelines = Arc::new(ShadePipelines {
            shade: self.pipeline(&module, "shade")?,
            grid: grid.then(|| self.pipeline(&module, "grid_visibility")).transpose()?,
        });
        self.shade_pipelines.lock().expect("pipeline cache").insert(source.to_string(), pipelines.clone());
        Ok(pipelines)
    }

    pub(super) fn pyramid_pipelines(&self) -> Result<Arc<(wgpu::ComputePipeline, wgpu::ComputePipeline)>, GpuError> {
        let mut cached = self.pyramid_pipelines.lock().expect("pipeline cache");
        if let Some(p) = cached.as_ref() {
            return Ok(p.clone());
        }
        let source = wgsl_declarations() + PYRAMID_WGSL;
        let module = self.compile("pyramid.wgsl", &source)?;
        let pair = Arc::new((self.pipeline(&module, "decimate_x")?, self.pipeline(&module, "decimate_y")?));
        *cached = Some(pair.clone());
        Ok(pair)
    }

    pub(super) fn timer(&self) -> Option<PassTimer> {
        self.timestamps.then(|| PassTimer::new(&self.device))
    }

    /// Records one compute pass (`record` sets its pipelines and dispatches), submits it
    /// and waits for it, timing it as `stage`: by GPU timestamps where the adapter has
    /// them, else by the wall clock from `started`.
    pub(super) fn run_pass(
        &self,
        stage: &'static str,
        started: std::time::Instant,
        timings: &mut StageTimings,
        record: impl FnOnce(&mut wgpu::ComputePass),
    ) -> Result<(), GpuError> {
        let timer = self.timer();
        let mut encoder = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(stage) });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(stage),
                timestamp_writes: timer.as_ref().map(|t| t.writes()),
            });
            record(&mut pass);
        }
        if let Some(t) = &timer {
            t.resolve(&mut encoder);
        }
        self.queue.submit([encoder.finish()]);
        self.wait(&format!("the {stage} pass"))?;
        match timer.as_ref().map(|t| t.read(self)).transpose()? {
            Some(ms) => timings.add(stage, ms, Clock::Gpu),
            None => timings.add_wall(stage, started),
        }
        Ok(())
    }
}

pub(super) fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry { binding, resource: buffer.as_entire_binding() }
}

/// Timestamps at the start and end of one compute pass.
pub(super) struct PassTimer {
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

    pub(super) fn writes(&self) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: Some(0),
            end_of_pass_write_index: Some(1),
        }
    }

    pub(super) fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.resolve_query_set(&self.queries, 0..2, &self.resolved, 0);
        encoder.copy_buffer_to_buffer(&self.resolved, 0, &self.readback, 0, 16);
    }

    /// Milliseconds between the two timestamps (after the submission completed).
    pub(super) fn read(&self, gpu: &Gpu) -> Result<f64, GpuError> {
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
