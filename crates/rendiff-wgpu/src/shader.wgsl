// rendiff-wgpu: depth and triangle/object IDs of a resolved scene.
// Conventions and error bounds: src/precision.rs.

struct Uniforms {
    // Projection x rotation, applied to eye-relative positions (camera.rs).
    clip: mat4x4<f32>,
    // Visible planar depths [near, far]; far is f32::MAX when unbounded.
    near: f32,
    far: f32,
    // frag_depth = near_clip / Z (reversed depth, compare Greater).
    near_clip: f32,
    // Index of row 0's sy in `screen`.
    width: u32,
};

@group(0) @binding(0) var<uniform> u: Uniforms;
// sx of every column, then sy of every row (the resolved-scene formula in f64, rounded once).
@group(0) @binding(1) var<storage, read> screen: array<f32>;

struct VOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) @interpolate(flat) prim: u32,
    @location(1) @interpolate(flat) object: u32,
    // Unit normal in camera coordinates (n.r, n.u, n.f) and offset n.(a - eye).
    @location(2) @interpolate(flat) plane: vec4<f32>,
};

@vertex
fn vs(
    @location(0) p: vec3<f32>,
    @location(1) prim: u32,
    @location(2) object: u32,
    @location(3) plane: vec4<f32>,
) -> VOut {
    var o: VOut;
    o.pos = u.clip * vec4<f32>(p, 1.0);
    o.prim = prim;
    o.object = object;
    o.plane = plane;
    return o;
}

struct FOut {
    @location(0) z: f32,
    @location(1) prim: u32,
    @location(2) object: u32,
    @builtin(frag_depth) depth: f32,
};

@fragment
fn fs(i: VOut) -> FOut {
    // One sample per pixel, at its center: pos.xy = (x + 0.5, y + 0.5), y down.
    let x = u32(i.pos.x);
    let y = u32(i.pos.y);
    let sx = screen[x];
    let sy = screen[u.width + y];
    // Planar depth of the pixel ray's hit on the triangle's plane.
    let den = i.plane.z + i.plane.x * sx + i.plane.y * sy;
    let z = i.plane.w / den;
    if !(z >= u.near && z <= u.far) {
        discard;
    }
    var o: FOut;
    o.z = z;
    o.prim = i.prim;
    o.object = i.object;
    o.depth = u.near_clip / z;
    return o;
}
