//! The GPU contract's tests, which need every layer: each bind-group declaration against its
//! WGSL, and each struct mirror (render, estimators, optimizer passes) against naga's layout.
//! They live at the crate's root so that no lower module imports an upper one.
use crate::render::layout::*;

use std::mem::size_of;

#[test]
fn every_bind_group_declaration_names_its_wgsl_bindings() {
    use crate::shader_library::{bindings, passes};
    let mut decls = vec![
        crate::render::RENDER_GROUP,
        crate::render::TRACE_RAYS_GROUP,
        crate::optim::loss::LOSS_GROUP,
        crate::optim::primal::PRIMAL_CV_GROUP,
        crate::optim::primal::path_cache::PRIMAL_CACHED_GROUP,
        crate::optim::primal::path_pool::PRIMAL_CACHE_TRACE_GROUP,
        crate::optim::observed::OBSERVED_GROUP,
        crate::render::gpu_scene::TEXTURE_WRAP_TEST_GROUP,
        crate::optim::texture_export::TEXTURE_EXPORT_GROUP,
    ];
    decls.extend(crate::optim::estimator::groups());
    decls.extend(crate::optim::prior::groups());
    decls.extend(crate::optim::step::groups());
    for d in &decls {
        let wgsl: Vec<String> = bindings(d.pass, d.group)
            .unwrap()
            .into_iter()
            .map(|(n, _)| n)
            .collect();
        assert_eq!(wgsl, d.names, "group {} of {}", d.group, d.pass);
    }
    // Every group of every pass is declared, except the scene's (group 0 of the passes
    // that read the scene, bound once by GpuScene::new).
    let scene = bindings("render", 0).unwrap();
    for pass in passes() {
        for group in 0..2 {
            let b = bindings(pass, group).unwrap();
            if b.is_empty() || (group == 0 && scene.starts_with(&b)) {
                continue;
            }
            assert!(
                decls.iter().any(|d| d.pass == pass && d.group == group),
                "group {group} of {pass} has no GroupDecl"
            );
        }
    }
}

pub(crate) fn field_size<T, F>(_: impl Fn(&T) -> &F) -> usize {
    size_of::<F>()
}

/// Check a Rust mirror against the WGSL struct `name` of pass `pass` as naga lays it
/// out: the size, and every member's offset and size by name (members whose names start
/// with `_` are padding). A WGSL member without a Rust field, a Rust field without a WGSL
/// member, or two fields swapped fail here, without a GPU.
pub(crate) fn check_mirror(pass: &str, name: &str, size: usize, fields: &[(&str, usize, usize)]) {
    let module = crate::shader_library::validate(pass).unwrap();
    let mut layouter = naga::proc::Layouter::default();
    layouter.update(module.to_ctx()).unwrap();
    let (h, ty) = module
        .types
        .iter()
        .find(|(_, t)| t.name.as_deref() == Some(name))
        .unwrap_or_else(|| panic!("no WGSL struct {name} in {pass}"));
    assert_eq!(size, layouter[h].size as usize, "size of {name}");
    let naga::TypeInner::Struct { members, .. } = &ty.inner else {
        panic!("{name} is not a struct in {pass}");
    };
    for m in members {
        let member = m.name.as_deref().unwrap_or("");
        if member.starts_with('_') {
            continue;
        }
        let Some(&(_, offset, field_size)) = fields.iter().find(|f| f.0 == member) else {
            panic!("WGSL {name}.{member} has no field in the Rust mirror");
        };
        assert_eq!(offset, m.offset as usize, "offset of {name}.{member}");
        assert_eq!(
            field_size, layouter[m.ty].size as usize,
            "size of {name}.{member}"
        );
    }
    for (field, _, _) in fields {
        assert!(
            members.iter().any(|m| m.name.as_deref() == Some(field)),
            "Rust field {field} of {name}'s mirror is not in the WGSL struct"
        );
    }
}

/// Check the Rust mirror `$ty` of the WGSL struct `$wgsl` in pass `$pass`, field by field
/// ([`check_mirror`]); the estimators' folders use it for their own uniforms.
macro_rules! mirror {
    ($pass:expr, $wgsl:expr, $ty:ty, [$($field:ident),* $(,)?]) => {
        $crate::contract_tests::check_mirror(
            $pass,
            $wgsl,
            std::mem::size_of::<$ty>(),
            &[$((
                stringify!($field),
                std::mem::offset_of!($ty, $field),
                $crate::contract_tests::field_size(|s: &$ty| &s.$field),
            )),*],
        )
    };
}
pub(crate) use mirror;

// The scene's GPU structs, field by field against naga's layout of the WGSL.
#[test]
fn scene_mirrors_match_wgsl_field_by_field() {
    mirror!(
        "render",
        "TriShading",
        GpuTriShading,
        [n0, t0, n1, t1, n2, t2, uv01, uv2, material, light]
    );
    mirror!(
        "render",
        "TexRef",
        GpuTexRef,
        [offset, width, height, flags]
    );
    mirror!(
        "render",
        "Material",
        GpuMaterial,
        [
            base_color,
            emissive,
            metallic,
            roughness,
            double_sided,
            param_base_color,
            param_metallic,
            param_roughness,
            normal_scale,
            param_normal,
            base_color_tex,
            mr_tex,
            emissive_tex,
            normal_tex,
            uv_xf
        ]
    );
    mirror!(
        "render",
        "Light",
        GpuLight,
        [
            position,
            kind,
            direction,
            tri,
            intensity,
            range,
            spot_scale,
            spot_offset,
            pmf,
            cdf
        ]
    );
    mirror!(
        "render",
        "SceneInfo",
        GpuSceneInfo,
        [
            n_nodes,
            n_tris,
            n_lights,
            env_light,
            env_width,
            env_height,
            env_marginal,
            env_conditional,
            env_scale,
            env_total,
            scene_radius,
            max_depth,
            env_optimized,
            env_bilinear
        ]
    );
}

// The render passes' parameters, the optimized textures' table and the BVH, field by field
// against naga's layout of the WGSL.
#[test]
fn render_mirrors_match_wgsl_field_by_field() {
    mirror!(
        "texture_wrap_test",
        "TextureWrapTestParams",
        crate::render::gpu_scene::TextureWrapTestParams,
        [n, mode, count]
    );
    mirror!(
        "render",
        "CameraInfo",
        GpuCameraInfo,
        [origin, fx, right, fy, up, width, forward, height, cx, cy, light_base]
    );
    mirror!(
        "render",
        "RenderParams",
        GpuRenderParams,
        [
            camera,
            seed,
            sample_offset,
            spp,
            techniques,
            stride,
            two_states
        ]
    );
    mirror!(
        "render",
        "ParamTex",
        GpuParamTex,
        [
            offset,
            width,
            height,
            channels,
            filtering,
            texel_offset,
            slot
        ]
    );
    mirror!(
        "render",
        "BvhNode",
        crate::scene::bvh::BvhNode,
        [bmin, left_first, bmax, count]
    );
    mirror!(
        "trace_rays",
        "TraceParams",
        GpuTraceParams,
        [n_rays, brute_force, stride]
    );
}

// The uniforms of the passes, field by field against naga's layout of the WGSL.
#[test]
fn pass_uniform_mirrors_match_wgsl_field_by_field() {
    mirror!(
        "variance_step",
        "VarianceStepParams",
        crate::optim::variance_step::VarianceStepParams,
        [
            offset,
            count,
            lr,
            clip,
            beta,
            eps,
            bias,
            own_variance,
            lo,
            hi,
            mask,
            threshold,
            phase,
            own_weight,
            variance_scale
        ]
    );
    mirror!(
        "loss",
        "LossParams",
        crate::optim::loss::LossParams,
        [
            n_pixels,
            kind,
            norm,
            partial_offset,
            adjoint_offset,
            gain,
            gain_prev
        ]
    );
    mirror!(
        "adam",
        "AdamParams",
        crate::optim::adam::AdamParams,
        [
            offset, count, lr, beta1, beta2, eps, bias1, bias2, lo, hi, mask, phase, own_weight,
            write_back
        ]
    );
    mirror!(
        "moment_filter",
        "MomentFilterParams",
        crate::optim::moment_filter::MomentFilterParams,
        [
            offset,
            width,
            height,
            channels,
            texel_offset,
            spacing,
            sigma,
            log_space,
            radius,
            variance_of_mean
        ]
    );
    mirror!(
        "multiscale_gradient",
        "MultiscaleParams",
        crate::optim::multiscale::MultiscaleParams,
        [
            offset,
            width,
            height,
            channels,
            levels,
            shift_x,
            shift_y,
            texel_offset
        ]
    );
    mirror!(
        "smoothness",
        "SmoothnessParams",
        crate::optim::smoothness::SmoothnessParams,
        [offset, width, height, channels, texel_offset, scale]
    );
    mirror!(
        "observed_texels",
        "ObservedParams",
        crate::optim::observed::ObservedParams,
        [camera, strata, stride]
    );
    mirror!(
        "texture_export",
        "ExportParams",
        crate::optim::texture_export::ExportParams,
        [offset, width, height, channels]
    );
}

// The primal passes' uniforms (the control variate's, the path cache's).
#[test]
fn primal_uniform_mirrors_match_wgsl_field_by_field() {
    mirror!(
        "primal_cv",
        "PrimalCvParams",
        crate::optim::primal::PrimalCvParams,
        [
            n_pixels,
            pixel_offset,
            updates,
            use_weight,
            have_prev,
            beta1,
            beta2,
            phase,
            width,
            height,
            max_weight
        ]
    );
    mirror!(
        "primal_cached",
        "PrimalCachedParams",
        crate::optim::primal::path_cache::PrimalCachedParams,
        [
            camera,
            seed,
            spp,
            techniques,
            stride,
            two_states,
            refresh_first,
            refresh_count,
            vertices,
            optimized_only
        ]
    );
}
