// shared/normal_map for a scene that optimizes no normal map (src/gpu/shaders.rs composes
// this file in its place): the same functions, for materials without param_normal, whose
// callers never reach them or get the surface's own frame.

// The slots a texture may replace, the normal map left out.
const SLOTS: u32 = 3u;

const NORMAL_MAPS: bool = false;

struct MappedNormal {
    n: vec3f,
    d: mat3x3f,
}

fn optimized_normal(sf: Surface, prev: bool) -> MappedNormal {
    return MappedNormal(sf.ng, mat3x3f());
}

fn frame_of(sf: Surface, prev: bool) -> mat3x3f {
    return sf.frame;
}

fn normal_rgb_grad(sf: Surface, prev: bool, mat: SurfaceMaterial, wo: vec3f, wi: vec3f) -> mat3x3f {
    return mat3x3f();
}
