//! Headless rendering with wgpu (Vulkan backend): one render pass per chunk
//! of triangles into three color targets (R32Float `Z`, R32Uint `id.prim`,
//! R32Uint `id.object`) and a Depth32Float depth buffer, then a buffer copy
//! back to the CPU.
//!
//! The draw is non-indexed: each triangle's three vertices carry its prim ID,
//! object ID and plane as flat attributes, so no adapter feature is needed
//! (`primitive_index` is optional in WebGPU). Triangles are drawn in prim
//! order, chunk after chunk, so the depth test (`Greater`, strict) keeps the
//! lower prim among equal depths, as the core does.

use crate::camera::{self, View};
use crate::precision;
use crate::scene::Scene;
use anyhow::{anyhow, bail, Context, Result};
use bytemuck::{Pod, Zeroable};
use std::sync::{Arc, Mutex};
use wgpu::util::DeviceExt;

/// Background ID (docs/DESIGN.md).
pub const BACKGROUND: u32 = u32::MAX;

/// Why a render did not happen: the two outcomes the command protocol tells
/// apart (exit 3 "skipped" vs exit 1 "error").
#[derive(Debug)]
pub enum RenderError {
    /// No Vulkan adapter on this machine: the render is skipped, not failed.
    NoAdapter(String),
    /// Anything else, as one line naming what failed.
    Failed(anyhow::Error),
}

impl From<anyhow::Error> for RenderError {
    fn from(e: anyhow::Error) -> Self {
        RenderError::Failed(e)
    }
}

/// What the adapter is, for the EXR header and for the precision model.
#[derive(Debug, Clone)]
pub struct AdapterFacts {
    /// Adapter name and driver, e.g. "llvmpipe (LLVM 15.0.6, 256 bits) / Mesa 22.3.6".
    pub description: String,
    /// Vulkan `subPixelPrecisionBits`, read from the adapter when wgpu exposes it.
    pub subpixel_bits: u32,
    /// Whether `subpixel_bits` was read (true) or assumed (false).
    pub subpixel_bits_queried: bool,
}

/// The rendered buffers, row 0 at the top.
#[derive(Debug, Clone)]
pub struct Buffers {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Planar depth, +inf for background.
    pub z: Vec<f32>,
    /// Triangle index, [`BACKGROUND`] for background.
    pub prim: Vec<u32>,
    /// Object index, [`BACKGROUND`] for background.
    pub object: Vec<u32>,
    /// The adapter that drew them.
    pub adapter: AdapterFacts,
    /// Seconds spent on the GPU work (device creation to read-back).
    pub seconds: f64,
}

/// One vertex as the vertex shader reads it (36 bytes).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Vertex {
    /// `f32(X - eye)`, subtracted in f64.
    pos: [f32; 3],
    prim: u32,
    object: u32,
    /// `(n.r, n.u, n.f, n.(a - eye))` of the triangle's unit normal.
    plane: [f32; 4],
}

/// The uniform block of shader.wgsl (80 bytes).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Uniforms {
    clip: [[f32; 4]; 4],
    near: f32,
    far: f32,
    near_clip: f32,
    width: u32,
}

const VERTEX_BYTES: u64 = std::mem::size_of::<Vertex>() as u64;
const TRIANGLE_BYTES: u64 = 3 * VERTEX_BYTES;
/// Host memory per chunk we are willing to stage at once.
const MAX_CHUNK_BYTES: u64 = 256 << 20;

/// The three vertices of triangle `i` (degenerate ones collapsed to a point,
/// which rasterizes nothing: zero-area triangles are never visible).
fn triangle_vertices(view: &View, scene: &Scene, i: usize) -> [Vertex; 3] {
    let t = scene.triangle(i);
    let p: [[f64; 3]; 3] = t.map(|v| v.map(f64::from));
    let n = camera::cross(camera::sub(p[1], p[0]), camera::sub(p[2], p[0]));
    let len = camera::dot(n, n).sqrt();
    let rel = |v: [f64; 3]| -> [f32; 3] { camera::sub(v, view.eye).map(|c| c as f32) };
    let prim = i as u32;
    let object = scene.object_ids[i];
    if !(len > 0.0 && len.is_finite()) {
        let v = Vertex {
            pos: rel(p[0]),
            prim,
            object,
            plane: [0.0; 4],
        };
        return [v; 3];
    }
    let n = n.map(|c| c / len);
    let plane = [
        camera::dot(n, view.right) as f32,
        camera::dot(n, view.up) as f32,
        camera::dot(n, view.forward) as f32,
        camera::dot(n, camera::sub(p[0], view.eye)) as f32,
    ];
    p.map(|v| Vertex {
        pos: rel(v),
        prim,
        object,
        plane,
    })
}

/// Reads `subPixelPrecisionBits` through wgpu's Vulkan HAL, if the adapter is Vulkan.
fn query_subpixel_bits(adapter: &wgpu::Adapter) -> Option<u32> {
    // SAFETY: the HAL adapter is only read (its cached physical-device
    // properties), while `adapter` is alive and nothing else uses it.
    unsafe {
        adapter.as_hal::<wgpu::hal::api::Vulkan>().map(|hal| {
            hal.physical_device_capabilities()
                .properties()
                .limits
                .sub_pixel_precision_bits
        })
    }
}

/// Finds a Vulkan adapter, or says why there is none.
fn adapter() -> std::result::Result<(wgpu::Adapter, AdapterFacts), RenderError> {
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
        backends: wgpu::Backends::VULKAN,
        ..wgpu::InstanceDescriptor::new_without_display_handle()
    });
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        force_fallback_adapter: false,
        compatible_surface: None,
        apply_limit_buckets: false,
    }))
    .map_err(|e| RenderError::NoAdapter(one_line(&e.to_string())))?;
    let info = adapter.get_info();
    let (subpixel_bits, queried) = match query_subpixel_bits(&adapter) {
        Some(b) => (b, true),
        None => (precision::ASSUMED_SUBPIXEL_BITS, false),
    };
    let facts = AdapterFacts {
        description: format!("{} / {} {}", info.name, info.driver, info.driver_info),
        subpixel_bits,
        subpixel_bits_queried: queried,
    };
    Ok((adapter, facts))
}

/// Collapses a multi-line message into one line.
pub fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Errors wgpu reports asynchronously (validation, out of memory), collected
/// instead of wgpu's default panic.
#[derive(Clone, Default)]
struct ErrorSink(Arc<Mutex<Vec<String>>>);

impl ErrorSink {
    fn check(&self, what: &str) -> Result<()> {
        let errors = self.0.lock().map(|e| e.clone()).unwrap_or_default();
        match errors.first() {
            Some(e) => bail!("wgpu: {what}: {}", one_line(e)),
            None => Ok(()),
        }
    }
}

/// Renders `scene`'s depth and IDs. `NoAdapter` when there is no Vulkan
/// adapter; `Failed` for anything that cannot be rendered (with the reason).
/// `max_chunk_triangles` caps the triangles per draw below what the
/// adapter's limits allow (tests use it to exercise the split draws).
pub fn render(
    scene: &Scene,
    max_chunk_triangles: Option<usize>,
) -> std::result::Result<Buffers, RenderError> {
    let view = View::from_json(&scene.camera);
    let (adapter, facts) = adapter()?;
    let started = std::time::Instant::now();
    let limits = adapter.limits();
    let (w, h) = (view.width, view.height);
    let max_dim = limits.max_texture_dimension_2d;
    if w > max_dim || h > max_dim {
        return Err(
            anyhow!("image {w}x{h} exceeds this adapter's largest texture ({max_dim} px)").into(),
        );
    }
    let n = scene.triangle_count();
    if n >= BACKGROUND as usize {
        return Err(anyhow!("{n} triangles: prim IDs must stay below 0xFFFFFFFF").into());
    }
    let screen_bytes = 4 * (u64::from(w) + u64::from(h));
    if screen_bytes > limits.max_storage_buffer_binding_size {
        return Err(
            anyhow!("image {w}x{h}: pixel-center table exceeds the storage binding limit").into(),
        );
    }
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("rendiff-wgpu"),
        required_features: wgpu::Features::empty(),
        required_limits: limits.clone(),
        ..Default::default()
    }))
    .map_err(|e| anyhow!("wgpu: cannot open the device: {}", one_line(&e.to_string())))?;
    let sink = ErrorSink::default();
    {
        let sink = sink.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut v) = sink.0.lock() {
                v.push(e.to_string());
            }
        }));
    }

    // Largest chunk: the adapter's buffer limit and our staging budget.
    let chunk_tris = (limits.max_buffer_size.min(MAX_CHUNK_BYTES) / TRIANGLE_BYTES).max(1) as usize;
    let chunk_tris = chunk_tris.min(max_chunk_triangles.unwrap_or(usize::MAX).max(1));

    let near_clip = view.near * 0.5;
    let uniforms = Uniforms {
        clip: camera::to_gpu(&view.projection_rotation(near_clip)),
        near: view.near as f32,
        far: if view.far.is_finite() {
            view.far as f32
        } else {
            f32::MAX
        },
        near_clip: near_clip as f32,
        width: w,
    };
    let uniform_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("uniforms"),
        contents: bytemuck::bytes_of(&uniforms),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let screen: Vec<f32> = (0..w)
        .map(|x| view.screen_x(x) as f32)
        .chain((0..h).map(|y| view.screen_y(y) as f32))
        .collect();
    let screen_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("pixel centers"),
        contents: bytemuck::cast_slice(&screen),
        usage: wgpu::BufferUsages::STORAGE,
    });

    let bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("bgl"),
        entries: &[
            wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 1,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only: true },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            },
        ],
    });
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("bg"),
        layout: &bgl,
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: uniform_buf.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: screen_buf.as_entire_binding(),
            },
        ],
    });
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("layout"),
        bind_group_layouts: &[Some(&bgl)],
        immediate_size: 0,
    });
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("shader.wgsl"),
        source: wgpu::ShaderSource::Wgsl(include_str!("shader.wgsl").into()),
    });
    let attributes = wgpu::vertex_attr_array![
        0 => Float32x3, 1 => Uint32, 2 => Uint32, 3 => Float32x4
    ];
    let target = |format| {
        Some(wgpu::ColorTargetState {
            format,
            blend: None,
            write_mask: wgpu::ColorWrites::ALL,
        })
    };
    let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("visibility"),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs"),
            compilation_options: Default::default(),
            buffers: &[Some(wgpu::VertexBufferLayout {
                array_stride: VERTEX_BYTES,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &attributes,
            })],
        },
        primitive: wgpu::PrimitiveState {
            topology: wgpu::PrimitiveTopology::TriangleList,
            strip_index_format: None,
            front_face: wgpu::FrontFace::Ccw,
            cull_mode: None,
            unclipped_depth: false,
            polygon_mode: wgpu::PolygonMode::Fill,
            conservative: false,
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: wgpu::TextureFormat::Depth32Float,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Greater),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: wgpu::MultisampleState {
            count: 1,
            mask: !0,
            alpha_to_coverage_enabled: false,
        },
        fragment: Some(wgpu::FragmentState {
            module: &module,
            entry_point: Some("fs"),
            compilation_options: Default::default(),
            targets: &[
                target(wgpu::TextureFormat::R32Float),
                target(wgpu::TextureFormat::R32Uint),
                target(wgpu::TextureFormat::R32Uint),
            ],
        }),
        multiview_mask: None,
        cache: None,
    });
    sink.check("pipeline")?;

    let size = wgpu::Extent3d {
        width: w,
        height: h,
        depth_or_array_layers: 1,
    };
    let texture = |label, format| {
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        })
    };
    let z_tex = texture("Z", wgpu::TextureFormat::R32Float);
    let prim_tex = texture("id.prim", wgpu::TextureFormat::R32Uint);
    let obj_tex = texture("id.object", wgpu::TextureFormat::R32Uint);
    let depth_tex = texture("depth", wgpu::TextureFormat::Depth32Float);
    let views =
        [&z_tex, &prim_tex, &obj_tex, &depth_tex].map(|t| t.create_view(&Default::default()));

    let chunks = n.div_ceil(chunk_tris).max(1);
    for c in 0..chunks {
        let first = c * chunk_tris;
        let last = (first + chunk_tris).min(n);
        let vertices: Vec<Vertex> = (first..last)
            .flat_map(|i| triangle_vertices(&view, scene, i))
            .collect();
        let vbuf = (!vertices.is_empty()).then(|| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("vertices"),
                contents: bytemuck::cast_slice(&vertices),
                usage: wgpu::BufferUsages::VERTEX,
            })
        });
        drop(vertices);
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let load = |clear| {
                if c == 0 {
                    wgpu::LoadOp::Clear(clear)
                } else {
                    wgpu::LoadOp::Load
                }
            };
            let color = |i: usize, clear: f64| {
                Some(wgpu::RenderPassColorAttachment {
                    view: &views[i],
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: load(wgpu::Color {
                            r: clear,
                            g: 0.0,
                            b: 0.0,
                            a: 0.0,
                        }),
                        store: wgpu::StoreOp::Store,
                    },
                })
            };
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("visibility"),
                color_attachments: &[
                    color(0, f64::INFINITY),
                    color(1, f64::from(BACKGROUND)),
                    color(2, f64::from(BACKGROUND)),
                ],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &views[3],
                    depth_ops: Some(wgpu::Operations {
                        load: if c == 0 {
                            wgpu::LoadOp::Clear(0.0)
                        } else {
                            wgpu::LoadOp::Load
                        },
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            if let Some(vbuf) = &vbuf {
                pass.set_pipeline(&pipeline);
                pass.set_bind_group(0, &bind_group, &[]);
                pass.set_vertex_buffer(0, vbuf.slice(..));
                pass.draw(0..(3 * (last - first)) as u32, 0..1);
            }
        }
        queue.submit([encoder.finish()]);
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| anyhow!("wgpu: waiting for draw chunk {c}: {e}"))?;
        sink.check(&format!("draw chunk {c} of {chunks}"))?;
    }

    let z: Vec<f32> = read_back(&device, &queue, &z_tex, w, h, &sink)?;
    let prim: Vec<u32> = read_back(&device, &queue, &prim_tex, w, h, &sink)?;
    let object: Vec<u32> = read_back(&device, &queue, &obj_tex, w, h, &sink)?;
    // Background is +inf in Z, whatever the clear value became.
    let z = z
        .into_iter()
        .zip(&prim)
        .map(|(z, &p)| if p == BACKGROUND { f32::INFINITY } else { z })
        .collect();
    Ok(Buffers {
        width: w,
        height: h,
        z,
        prim,
        object,
        adapter: facts,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// Copies a 4-byte-per-texel texture into a CPU vector, row 0 first, minding
/// the 256-byte row alignment of texture-to-buffer copies.
fn read_back<T: Pod>(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    w: u32,
    h: u32,
    sink: &ErrorSink,
) -> Result<Vec<T>> {
    let row = 4 * w;
    let align = wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let padded = row.div_ceil(align) * align;
    let bytes = u64::from(padded) * u64::from(h);
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("read-back"),
        size: bytes,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded),
                rows_per_image: Some(h),
            },
        },
        texture.size(),
    );
    queue.submit([encoder.finish()]);
    let (tx, rx) = std::sync::mpsc::channel();
    buffer.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = tx.send(r);
    });
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| anyhow!("wgpu: waiting for read-back: {e}"))?;
    sink.check("read-back")?;
    rx.recv()
        .context("wgpu: read-back callback never ran")?
        .map_err(|e| anyhow!("wgpu: cannot map read-back buffer: {e}"))?;
    let data = buffer
        .get_mapped_range(..)
        .map_err(|e| anyhow!("wgpu: cannot read mapped read-back buffer: {e}"))?;
    let mut out = Vec::with_capacity(w as usize * h as usize);
    for y in 0..h as usize {
        let start = y * padded as usize;
        out.extend_from_slice(bytemuck::cast_slice::<u8, T>(
            &data[start..start + row as usize],
        ));
    }
    drop(data);
    buffer.unmap();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::CameraJson;

    fn scene(tris: Vec<f32>) -> Scene {
        let n = tris.len() / 9;
        Scene {
            name: "t".into(),
            camera: CameraJson {
                eye: [0.3, 1.7, 5.0],
                forward: [0.0, 0.0, -1.0],
                right: [1.0, 0.0, 0.0],
                up_ortho: [0.0, 1.0, 0.0],
                tan_half_vfov: 0.41421356237309503,
                width: 96,
                height: 72,
                near: 1e-3,
                far: None,
            },
            triangles: tris,
            object_ids: (0..n as u32).collect(),
        }
    }

    /// The shader's depth formula, evaluated in f32 on the CPU exactly as
    /// shader.wgsl writes it, stays within the derived bound of the f64
    /// ray-plane depth, including at grazing angles.
    #[test]
    fn plane_depth_in_f32_is_within_the_derived_bound() {
        let sc = scene(vec![
            -1.0, -1.0, 0.0, 1.0, -1.0, 0.5, 0.0, 1.2, -0.3, // tilted
            -2.0, 0.0, -1.0, 2.0, 0.0, -1.0, 0.0, 1.6, -30.0, // grazing-ish
            -1.0, -1.0, 2.0, 1.0, -1.0, 2.0, 0.0, 1.0, 2.0, // facing
        ]);
        let view = View::from_json(&sc.camera);
        let mut worst: f64 = 0.0;
        for i in 0..sc.triangle_count() {
            let v = triangle_vertices(&view, &sc, i);
            let p = v[0].plane;
            let t = sc.triangle(i).map(|a| a.map(f64::from));
            let n = camera::cross(camera::sub(t[1], t[0]), camera::sub(t[2], t[0]));
            for y in 0..view.height {
                for x in 0..view.width {
                    let (sx, sy) = (view.screen_x(x) as f32, view.screen_y(y) as f32);
                    let den = p[2] + p[0] * sx + p[1] * sy;
                    let z32 = f64::from(p[3] / den);
                    let d = view.pixel_direction(x, y);
                    let nd = camera::dot(n, d);
                    let z = camera::dot(n, camera::sub(t[0], view.eye)) / nd;
                    if z.is_nan() || z <= 0.0 {
                        continue;
                    }
                    let cos = nd.abs() / (camera::dot(n, n).sqrt() * camera::dot(d, d).sqrt());
                    let rel = (z32 - z).abs() / z * cos;
                    worst = worst.max(rel);
                    // The shader's part of the bound: (5/|cos| + 2) u <= 7u/|cos|.
                    assert!(
                        rel <= 7.0 * precision::U * (1.0 + 1e-6),
                        "prim {i} ({x},{y}): {rel:e}"
                    );
                }
            }
        }
        assert!(worst > 0.0);
    }

    #[test]
    fn zero_area_triangles_collapse_to_a_point() {
        let sc = scene(vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0]);
        let view = View::from_json(&sc.camera);
        let v = triangle_vertices(&view, &sc, 0);
        assert_eq!(v[0].pos, v[1].pos);
        assert_eq!(v[1].pos, v[2].pos);
    }

    #[test]
    fn vertices_are_eye_relative_and_carry_their_ids() {
        let mut sc = scene(vec![1.0, 2.0, 3.0, 2.0, 2.0, 3.0, 1.0, 3.0, 3.0]);
        sc.object_ids = vec![7];
        let view = View::from_json(&sc.camera);
        let v = triangle_vertices(&view, &sc, 0);
        assert_eq!(v[0].pos, [(1.0 - 0.3) as f32, (2.0 - 1.7f64) as f32, -2.0]);
        assert!(v.iter().all(|v| v.prim == 0 && v.object == 7));
    }
}
