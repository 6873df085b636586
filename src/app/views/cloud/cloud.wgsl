// The 3D cloud view's shaders (src/app/views/cloud/renderer.rs).
//
// Pass 1 (offscreen colour + linear depth + depth buffer): every point as a
// screen-aligned quad (instanced, 6 vertices) or a point primitive (size 1),
// coloured from a 256-entry lookup texture by its one scalar.
// Pass 2 (inside egui's render pass): a full-viewport triangle copies the
// offscreen colour, optionally darkened by eye-dome lighting computed from the
// linear depth, and leaves the background transparent.

struct Uniforms {
    // Packed offset (x, y, z) to clip space, Z exaggeration included.
    clip: mat4x4<f32>,
    // Packed offset to view depth (scene units in front of the eye).
    depth_row: vec4<f32>,
    // Target width and height (px), point size (px), eye-dome sampling radius (px).
    viewport: vec4<f32>,
    // Scalar at the first and last lookup entry, eye-dome strength (0 = off), unused.
    shading: vec4<f32>,
    // Scene units per pixel at depth d: x * d + y.
    screen_unit: vec4<f32>,
    // Colour of points without a value.
    no_value: vec4<f32>,
};

@group(0) @binding(0) var<uniform> u: Uniforms;
@group(0) @binding(1) var lut: texture_2d<f32>;

// Scalars below this mark "no value" (NaN does not survive shaders portably).
const NO_VALUE_BELOW: f32 = -1.0e37;

struct PointOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) color: vec4<f32>,
    @location(1) corner: vec2<f32>,
    @location(2) depth: f32,
};

fn lut_color(s: f32) -> vec4<f32> {
    if (s < NO_VALUE_BELOW) {
        return u.no_value;
    }
    let span = u.shading.y - u.shading.x;
    var t = 0.5;
    if (span > 0.0) {
        t = (s - u.shading.x) / span;
    }
    // Same rounding as the 2D views (palette::map_value) and io::colormap.
    let i = i32(round(clamp(t, 0.0, 1.0) * 255.0));
    return textureLoad(lut, vec2<i32>(i, 0), 0);
}

fn point_out(offset: vec3<f32>, scalar: f32, corner: vec2<f32>) -> PointOut {
    let p = vec4<f32>(offset, 1.0);
    var clip = u.clip * p;
    // A corner at +-1 is half the point size away: size / viewport in NDC.
    clip.x += corner.x * u.viewport.z / u.viewport.x * clip.w;
    clip.y += corner.y * u.viewport.z / u.viewport.y * clip.w;
    var out: PointOut;
    out.clip = clip;
    out.color = lut_color(scalar);
    out.corner = corner;
    out.depth = dot(u.depth_row, p);
    return out;
}

@vertex
fn vs_quad(@builtin(vertex_index) vi: u32, @location(0) offset: vec3<f32>, @location(1) scalar: f32) -> PointOut {
    var corners = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0),
    );
    return point_out(offset, scalar, corners[vi % 6u]);
}

@vertex
fn vs_dot(@location(0) offset: vec3<f32>, @location(1) scalar: f32) -> PointOut {
    return point_out(offset, scalar, vec2<f32>(0.0, 0.0));
}

struct PointTargets {
    @location(0) color: vec4<f32>,
    // The linear depth's bits (an R32Uint target: renderable on OpenGL ES too).
    @location(1) depth_bits: u32,
};

@fragment
fn fs_point(in: PointOut) -> PointTargets {
    // Round points: the quad's corners are cut off.
    if (dot(in.corner, in.corner) > 1.0) {
        discard;
    }
    var out: PointTargets;
    out.color = vec4<f32>(in.color.rgb, 1.0);
    out.depth_bits = bitcast<u32>(in.depth);
    return out;
}

@group(1) @binding(0) var color_target: texture_2d<f32>;
@group(1) @binding(1) var depth_target: texture_2d<u32>;

// The linear depth at `p`; the target's clear value, 0, reads as 0.0: no point.
fn linear_depth(p: vec2<i32>) -> f32 {
    return bitcast<f32>(textureLoad(depth_target, p, 0).r);
}

struct CompositeOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) uv: vec2<f32>,
};

@vertex
fn vs_composite(@builtin(vertex_index) vi: u32) -> CompositeOut {
    // One triangle covering the viewport: uv (0,0), (2,0), (0,2).
    let uv = vec2<f32>(f32((vi << 1u) & 2u), f32(vi & 2u));
    var out: CompositeOut;
    out.pos = vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, 0.0, 1.0);
    out.uv = uv;
    return out;
}

// Eye-dome lighting (Boucheny 2009), scaled by the pixel footprint so it does
// not depend on the projection: each neighbour at `r` px nearer the eye than
// this pixel adds the slope (depth step / lateral step) between them. Steps
// and walls get dark outlines, faces turned away from the eye get darker.
fn composite(in: CompositeOut) -> vec4<f32> {
    let size = vec2<i32>(textureDimensions(color_target));
    let p = clamp(vec2<i32>(in.uv * vec2<f32>(size)), vec2<i32>(0, 0), size - vec2<i32>(1, 1));
    let d = linear_depth(p);
    if (d <= 0.0) {
        return vec4<f32>(0.0, 0.0, 0.0, 0.0);
    }
    var rgb = textureLoad(color_target, p, 0).rgb;
    let strength = u.shading.z;
    if (strength > 0.0) {
        let r = u.viewport.w;
        let lateral = max((u.screen_unit.x * d + u.screen_unit.y) * r, 1.0e-12);
        var response = 0.0;
        for (var k = 0; k < 8; k++) {
            let angle = f32(k) * 0.7853982;
            let step = vec2<i32>(round(vec2<f32>(cos(angle), sin(angle)) * r));
            let q = clamp(p + step, vec2<i32>(0, 0), size - vec2<i32>(1, 1));
            let dn = linear_depth(q);
            if (dn > 0.0) {
                response += max(0.0, d - dn) / lateral;
            }
        }
        rgb *= exp(-strength * 0.12 * response);
    }
    return vec4<f32>(rgb, 1.0);
}

@fragment
fn fs_composite(in: CompositeOut) -> @location(0) vec4<f32> {
    return composite(in);
}

fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    let low = c / 12.92;
    let high = pow((c + 0.055) / 1.055, vec3<f32>(2.4));
    return select(high, low, c <= vec3<f32>(0.04045));
}

// For an sRGB target the hardware encodes on write, so decode first (as egui does).
@fragment
fn fs_composite_linear(in: CompositeOut) -> @location(0) vec4<f32> {
    let c = composite(in);
    return vec4<f32>(srgb_to_linear(c.rgb), c.a);
}
