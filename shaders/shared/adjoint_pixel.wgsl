#import shared/types
#import shared/camera

// The pixel that a gradient-pass invocation works on, and the adjoint of its loss. Shared by
// the baseline gradient pass and the ReSTIR candidate pass; both declare
// `adjoint: array<vec4f>` (all cameras' adjoints, one after another).
struct AdjointPixel {
    // Pixel index within the camera's image; NONE outside the image or where the adjoint is
    // zero (nothing to differentiate).
    pixel: u32,
    // Pixel corner, for camera_direction.
    xy: vec2f,
    // Pixels of the camera's image (the stride between sample indices).
    n_pixels: u32,
    // dL/dI of the pixel divided by the gradient spp.
    adj: vec3f,
}

fn adjoint_pixel(linear: u32, camera: CameraInfo, adjoint_offset: u32, inv_spp: f32) -> AdjointPixel {
    let xy_px = tile_pixel(linear, camera.width, camera.height);
    if xy_px.x == NONE {
        var a: AdjointPixel;
        a.pixel = NONE;
        a.n_pixels = camera.width * camera.height;
        return a;
    }
    return adjoint_pixel_at(xy_px, camera, adjoint[adjoint_offset + xy_px.y * camera.width + xy_px.x].xyz, inv_spp);
}

// The same for pixel xy_px of the image (tile_pixel, not NONE), whose adjoint `adj` the
// caller has loaded (before the division by the spp).
fn adjoint_pixel_at(xy_px: vec2u, camera: CameraInfo, adj: vec3f, inv_spp: f32) -> AdjointPixel {
    var a: AdjointPixel;
    a.pixel = NONE;
    a.n_pixels = camera.width * camera.height;
    a.adj = adj * inv_spp;
    if all(a.adj == vec3f(0.0)) {
        return a;
    }
    a.pixel = xy_px.y * camera.width + xy_px.x;
    a.xy = vec2f(xy_px);
    return a;
}
