//! Running an exported shader as a compute shader through wgpu, on whatever Vulkan adapter the
//! machine has (on CI machines the CPU driver llvmpipe, Debian package `mesa-vulkan-drivers`):
//! the proof that the shader equals the Rust model, and its measured speed.

use anyhow::Result;

/// One evaluation: unit directions, normal and tangent in any frame; `at` = (height, azimuth
/// offset) evaluates `fibrefit_*_at`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Case {
    pub l: [f32; 3],
    pub v: [f32; 3],
    pub n: [f32; 3],
    pub t: [f32; 3],
    pub at: Option<(f32, f32)>,
}

/// What the shader returned for a case: `fibrefit_brdf` and `fibrefit_basis` (or their `_at`
/// forms).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Output {
    pub brdf: [f32; 3],
    pub basis: [f32; 4],
}

/// The compute harness appended to an exported library: reads 4 vec4 per case, writes 2.
#[cfg_attr(not(feature = "gpu"), allow(dead_code))]
const HARNESS: &str = "
@group(0) @binding(0) var<storage, read> fibrefit_check_in: array<vec4<f32>>;
@group(0) @binding(1) var<storage, read_write> fibrefit_check_out: array<vec4<f32>>;

// case i's four vec4 (l + height, v + azimuth offset, n + texel flag, t); false past the end
fn fibrefit_check_case(id: vec3<u32>) -> bool {
    return id.x + id.y * 4194240u < arrayLength(&fibrefit_check_out) / 2u;
}

fn fibrefit_check_input(id: vec3<u32>, k: u32) -> vec4<f32> {
    return fibrefit_check_in[4u * (id.x + id.y * 4194240u) + k];
}

@compute @workgroup_size(64)
fn fibrefit_check_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (!fibrefit_check_case(id)) {
        return;
    }
    let i = id.x + id.y * 4194240u;
    let a = fibrefit_check_input(id, 0u);
    let b = fibrefit_check_input(id, 1u);
    let c = fibrefit_check_input(id, 2u);
    let d = fibrefit_check_input(id, 3u);
    if (c.w > 0.5) {
        fibrefit_check_out[2u * i] = vec4<f32>(fibrefit_brdf_at(a.xyz, b.xyz, c.xyz, d.xyz, a.w, b.w), 0.0);
        fibrefit_check_out[2u * i + 1u] = fibrefit_basis_at(a.xyz, b.xyz, c.xyz, d.xyz, a.w, b.w);
    } else {
        fibrefit_check_out[2u * i] = vec4<f32>(fibrefit_brdf(a.xyz, b.xyz, c.xyz, d.xyz), 0.0);
        fibrefit_check_out[2u * i + 1u] = fibrefit_basis(a.xyz, b.xyz, c.xyz, d.xyz);
    }
}

@compute @workgroup_size(64)
fn fibrefit_speed_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (!fibrefit_check_case(id)) {
        return;
    }
    let i = id.x + id.y * 4194240u;
    fibrefit_check_out[2u * i] = vec4<f32>(fibrefit_brdf(fibrefit_check_input(id, 0u).xyz,
        fibrefit_check_input(id, 1u).xyz, fibrefit_check_input(id, 2u).xyz,
        fibrefit_check_input(id, 3u).xyz), 0.0);
}
";

/// Workgroups per row of the dispatch (65535 is the limit per dimension; 65535 x 64 =
/// 4194240 invocations per row, as the harness assumes).
#[cfg_attr(not(feature = "gpu"), allow(dead_code))]
const GROUPS_PER_ROW: u32 = 65535;

#[cfg(feature = "gpu")]
pub use device::Gpu;

#[cfg(feature = "gpu")]
mod device {
    use super::*;
    use anyhow::{anyhow, bail, Context};
    use std::time::Instant;
    use wgpu::util::DeviceExt;

    /// A GPU device to run exported shaders on.
    pub struct Gpu {
        device: wgpu::Device,
        queue: wgpu::Queue,
        /// "name (driver, backend, device type)".
        pub adapter: String,
    }

    impl Gpu {
        /// The first Vulkan adapter (a clear error when the machine has none).
        pub fn new() -> Result<Self> {
            // the Vulkan loader warns on stderr without it; nothing here needs a runtime directory
            if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
                // SAFETY: set before any thread of ours reads the environment (wgpu starts none yet)
                unsafe { std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir()) };
            }
            let instance = wgpu::Instance::new(&wgpu::InstanceDescriptor {
                backends: wgpu::Backends::VULKAN,
                ..Default::default()
            });
            let adapter =
                pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
                    power_preference: wgpu::PowerPreference::HighPerformance,
                    ..Default::default()
                }))
                .map_err(|e| {
                    anyhow!(
                "no GPU adapter: wgpu found no Vulkan device ({e}). On Debian/Ubuntu the CPU \
                 driver llvmpipe comes with `apt-get install mesa-vulkan-drivers`"
            )
                })?;
            let info = adapter.get_info();
            let name = format!(
                "{} ({} {}, {:?}, {:?})",
                info.name, info.driver, info.driver_info, info.backend, info.device_type
            );
            let limits = wgpu::Limits {
                max_storage_buffer_binding_size: adapter.limits().max_storage_buffer_binding_size,
                max_buffer_size: adapter.limits().max_buffer_size,
                ..wgpu::Limits::default()
            };
            let (device, queue) =
                pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
                    label: Some("fibrefit"),
                    required_limits: limits,
                    ..Default::default()
                }))
                .with_context(|| format!("cannot open the GPU device {name}"))?;
            Ok(Self {
                device,
                queue,
                adapter: name,
            })
        }

        fn pipeline(&self, wgsl: &str, entry: &str) -> Result<wgpu::ComputePipeline> {
            let src = format!("{wgsl}{HARNESS}");
            crate::export::shader::validate(&src)?;
            self.device.push_error_scope(wgpu::ErrorFilter::Validation);
            let module = self
                .device
                .create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some("fibrefit export"),
                    source: wgpu::ShaderSource::Wgsl(src.into()),
                });
            let pipeline = self
                .device
                .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some("fibrefit check"),
                    layout: None,
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    cache: None,
                });
            if let Some(e) = pollster::block_on(self.device.pop_error_scope()) {
                bail!("the GPU driver rejected the shader: {e}");
            }
            Ok(pipeline)
        }

        fn input(cases: &[Case]) -> Vec<[f32; 4]> {
            let mut data = Vec::with_capacity(4 * cases.len());
            for c in cases {
                let (h, off, flag) = match c.at {
                    Some((h, o)) => (h, o, 1.0),
                    None => (0.0, 0.0, 0.0),
                };
                data.push([c.l[0], c.l[1], c.l[2], h]);
                data.push([c.v[0], c.v[1], c.v[2], off]);
                data.push([c.n[0], c.n[1], c.n[2], flag]);
                data.push([c.t[0], c.t[1], c.t[2], 0.0]);
            }
            data
        }

        /// Run `entry` of the harness over `cases`; returns the output buffer and the time from
        /// submission to completion (seconds).
        fn dispatch(
            &self,
            wgsl: &str,
            entry: &str,
            cases: &[Case],
            uniform: Option<&[u8]>,
        ) -> Result<(Vec<[f32; 4]>, f64)> {
            if cases.is_empty() {
                return Ok((vec![], 0.0));
            }
            let pipeline = self.pipeline(wgsl, entry)?;
            let input = Self::input(cases);
            let inbuf = self
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("cases"),
                    contents: bytemuck::cast_slice(&input),
                    usage: wgpu::BufferUsages::STORAGE,
                });
            let out_bytes = (cases.len() * 2 * 16) as u64;
            let outbuf = self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("results"),
                size: out_bytes,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let read = self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("readback"),
                size: out_bytes,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let ubuf = uniform.map(|bytes| {
                self.device
                    .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                        label: Some("parameters"),
                        contents: bytes,
                        usage: wgpu::BufferUsages::UNIFORM,
                    })
            });
            let mut entries = vec![
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: inbuf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: outbuf.as_entire_binding(),
                },
            ];
            if let Some(u) = &ubuf {
                entries.push(wgpu::BindGroupEntry {
                    binding: 2,
                    resource: u.as_entire_binding(),
                });
            }
            let group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &pipeline.get_bind_group_layout(0),
                entries: &entries,
            });
            let groups = cases.len().div_ceil(64) as u32;
            let (gx, gy) = if groups <= GROUPS_PER_ROW {
                (groups, 1)
            } else {
                (GROUPS_PER_ROW, groups.div_ceil(GROUPS_PER_ROW))
            };
            let mut enc = self.device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                pass.set_pipeline(&pipeline);
                pass.set_bind_group(0, &group, &[]);
                pass.dispatch_workgroups(gx, gy, 1);
            }
            enc.copy_buffer_to_buffer(&outbuf, 0, &read, 0, out_bytes);
            let start = Instant::now();
            self.queue.submit([enc.finish()]);
            let slice = read.slice(..);
            let (tx, rx) = std::sync::mpsc::channel();
            slice.map_async(wgpu::MapMode::Read, move |r| {
                tx.send(r).ok();
            });
            self.device
                .poll(wgpu::PollType::Wait)
                .map_err(|e| anyhow!("the GPU did not finish: {e}"))?;
            rx.recv()
                .map_err(|_| anyhow!("the GPU readback was dropped"))?
                .map_err(|e| anyhow!("cannot read the GPU results back: {e}"))?;
            let seconds = start.elapsed().as_secs_f64();
            let out: Vec<[f32; 4]> = bytemuck::cast_slice(&slice.get_mapped_range()).to_vec();
            read.unmap();
            Ok((out, seconds))
        }

        /// `fibrefit_brdf` and `fibrefit_basis` (or the `_at` forms) of an exported WGSL library at
        /// each case.
        pub fn evaluate(&self, wgsl: &str, cases: &[Case]) -> Result<Vec<Output>> {
            self.evaluate_with_uniform(wgsl, cases, None)
        }

        /// [`Gpu::evaluate`] with `uniform` bound at group 0, binding 2 (a library whose parameters
        /// come from a `var<uniform>` it declares there).
        pub fn evaluate_with_uniform(
            &self,
            wgsl: &str,
            cases: &[Case],
            uniform: Option<&[u8]>,
        ) -> Result<Vec<Output>> {
            let (out, _) = self.dispatch(wgsl, "fibrefit_check_main", cases, uniform)?;
            Ok(out
                .chunks_exact(2)
                .map(|c| Output {
                    brdf: [c[0][0], c[0][1], c[0][2]],
                    basis: c[1],
                })
                .collect())
        }

        /// Seconds for `fibrefit_brdf` at every case, one dispatch (submission to results mapped),
        /// the median of `repeats`; the pipeline is built once beforehand.
        pub fn time_brdf(&self, wgsl: &str, cases: &[Case], repeats: usize) -> Result<f64> {
            let mut times = Vec::new();
            // the first run compiles the pipeline in the driver; not counted
            self.dispatch(wgsl, "fibrefit_speed_main", cases, None)?;
            for _ in 0..repeats.max(1) {
                times.push(self.dispatch(wgsl, "fibrefit_speed_main", cases, None)?.1);
            }
            times.sort_by(f64::total_cmp);
            Ok(times[times.len() / 2])
        }
    }
}

/// Without the `gpu` feature (the Python package's build): no device; [`Gpu::new`] says so.
#[cfg(not(feature = "gpu"))]
pub struct Gpu {
    pub adapter: String,
    never: std::convert::Infallible,
}

#[cfg(not(feature = "gpu"))]
impl Gpu {
    pub fn new() -> Result<Self> {
        anyhow::bail!(
            "this fibrefit was built without its `gpu` feature (wgpu), so it cannot run shaders on a GPU driver; the command-line tool has it (cargo build --release)"
        )
    }

    pub fn evaluate(&self, _wgsl: &str, _cases: &[Case]) -> Result<Vec<Output>> {
        match self.never {}
    }

    pub fn evaluate_with_uniform(
        &self,
        _wgsl: &str,
        _cases: &[Case],
        _uniform: Option<&[u8]>,
    ) -> Result<Vec<Output>> {
        match self.never {}
    }

    pub fn time_brdf(&self, _wgsl: &str, _cases: &[Case], _repeats: usize) -> Result<f64> {
        match self.never {}
    }
}
