// Pinhole camera. Keep in sync with CameraInfo in src/render/layout.rs.

struct CameraInfo {
    origin: vec3f,
    tan_half_fov_y: f32,
    right: vec3f,
    aspect: f32,
    up: vec3f,
    width: u32,
    forward: vec3f,
    height: u32,
}

// Direction through the continuous pixel position px (x right, y down, in pixels).
fn camera_direction(cam: CameraInfo, px: vec2f) -> vec3f {
    let sx = (2.0 * px.x / f32(cam.width) - 1.0) * cam.tan_half_fov_y * cam.aspect;
    let sy = (1.0 - 2.0 * px.y / f32(cam.height)) * cam.tan_half_fov_y;
    return normalize(cam.forward + sx * cam.right + sy * cam.up);
}
