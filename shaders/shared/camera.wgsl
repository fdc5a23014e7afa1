// Pinhole camera. CameraInfo is mirrored by GpuCameraInfo in src/render/layout.rs.

struct CameraInfo {
    origin: vec3f,
    // Focal lengths in pixels (of this image size).
    fx: f32,
    right: vec3f,
    fy: f32,
    up: vec3f,
    width: u32,
    forward: vec3f,
    height: u32,
    // Principal point in pixels (x right, y down; the image center is (width, height) / 2).
    cx: f32,
    cy: f32,
    // The first entry of this camera's capture's lights in lights[] (shared/lights.wgsl).
    light_base: u32,
    _pad1: u32,
}

// Direction through the continuous pixel position px (x right, y down, in pixels).
fn camera_direction(cam: CameraInfo, px: vec2f) -> vec3f {
    let sx = (px.x - cam.cx) / cam.fx;
    let sy = (cam.cy - px.y) / cam.fy;
    return normalize(cam.forward + sx * cam.right + sy * cam.up);
}

// Passes over an image walk it in 8x8 tiles, so that neighbouring lanes trace neighbouring
// pixels (coherent BVH traversal): the pixel (x, y) of invocation `linear`, or x = NONE past
// the image. The host dispatches 64 invocations per tile.
fn tile_pixel(linear: u32, width: u32, height: u32) -> vec2u {
    let tiles_x = (width + 7u) / 8u;
    let tile = linear / 64u;
    let in_tile = linear % 64u;
    let px = (tile % tiles_x) * 8u + in_tile % 8u;
    let py = (tile / tiles_x) * 8u + in_tile / 8u;
    if px >= width || py >= height {
        return vec2u(0xffffffffu, 0u);
    }
    return vec2u(px, py);
}
