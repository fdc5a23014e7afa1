//! Renders against references computed without the renderer, one per light kind: a plane under
//! a point, a spot and a directional light (radiance f cos E in closed form), under a
//! rectangular area light (a quadrature of the emitted radiance, itself checked against the
//! closed-form irradiance on the rectangle's axis), and under a constant environment (radiance =
//! environment x directional albedo of the BRDF, integrated on the CPU), each technique on its
//! own where the light kind has two; and the texel coordinates the shaders' texture lookups
//! wrap to.
mod common;

use common::*;
use glam::{Vec2, Vec3};
use psrestir::render::{Renderer, Techniques};
use psrestir::scene::{EnvMap, PunctualKind, PunctualLight, Wrap};

const W: u32 = 64;

#[test]
fn plane_under_point_spot_and_directional_lights_matches_the_closed_form() {
    let Some(gpu) = gpu() else { return };
    let (base, metallic, roughness) = (Vec3::new(0.6, 0.5, 0.4), 0.0, 0.5);
    let light_pos = Vec3::new(0.3, 1.5, -0.2);
    let intensity = Vec3::splat(4.0);
    // The spot points down and a little to the side; its cone edge (cos 0.35 rad) crosses
    // the view, so the glTF fall-off (a squared linear ramp in cos between the cones) shows.
    let spot_dir = Vec3::new(0.2, -1.0, 0.1).normalize();
    let (inner, outer) = (0.2f32, 0.35f32);
    let sun_dir = Vec3::new(-0.3, -1.0, 0.4).normalize();
    for (name, kind, direction) in [
        ("point", PunctualKind::Point, Vec3::NEG_Y),
        (
            "spot",
            PunctualKind::Spot {
                inner_cone: inner,
                outer_cone: outer,
            },
            spot_dir,
        ),
        ("directional", PunctualKind::Directional, sun_dir),
    ] {
        let mut scene = plane_scene(material(base.to_array(), metallic, roughness), 5.0);
        scene.lights.push(PunctualLight {
            name: name.into(),
            kind,
            position: light_pos,
            direction,
            intensity,
            range: 0.0,
        });
        let spp = 64;
        let r = Renderer::new(&gpu, &scene).unwrap();
        let out = render_image(&r, W, spp, 3, Techniques::Mis);
        // Reference (KHR_lights_punctual): point and spot lights give intensity / d^2 along
        // the direction to them, the spot times the squared ramp of cos(angle to its axis)
        // from the outer to the inner cone; a directional light gives its intensity along
        // the opposite of its direction. Averaged over an 8x8 grid inside each pixel; its
        // spread within the pixel bounds the error of the GPU's random jitter.
        let cam = &scene.cameras[0];
        let radiance = |px: Vec2| -> Vec3 {
            let (o, d) = camera_dir(cam, W, W, px);
            let t = -o.y / d.y;
            let x = o + t * d;
            let (wi, incident) = match kind {
                PunctualKind::Directional => (-direction, intensity),
                _ => {
                    let to = light_pos - x;
                    let wi = to.normalize();
                    let mut e = intensity / to.length_squared();
                    if let PunctualKind::Spot { .. } = kind {
                        let c = direction.dot(-wi);
                        let ramp =
                            ((c - outer.cos()) / (inner.cos() - outer.cos())).clamp(0.0, 1.0);
                        e *= ramp * ramp;
                    }
                    (wi, e)
                }
            };
            brdf_eval_cos(base, metallic, roughness, Vec3::Y, -d, wi) * incident
        };
        let mut worst = 0.0f64;
        let mut lit = 0;
        for y in 0..W {
            for x in 0..W {
                let mut subs = Vec::new();
                for j in 0..8 {
                    for i in 0..8 {
                        let p = Vec2::new(
                            x as f32 + (i as f32 + 0.5) / 8.0,
                            y as f32 + (j as f32 + 0.5) / 8.0,
                        );
                        subs.push(lum(radiance(p).to_array()));
                    }
                }
                let (m, sd) = mean_sd(&subs);
                lit += (m > 1e-3) as usize;
                let got = lum(out.at(x, y));
                let tol = 5.0 * sd / (spp as f64).sqrt() + 2e-3 * m + 1e-6;
                worst = worst.max((got - m).abs() / tol);
                assert!(
                    (got - m).abs() <= tol,
                    "{name}: pixel ({x},{y}): {got} vs closed form {m} (tolerance {tol})"
                );
            }
        }
        eprintln!("{name}: worst error / tolerance {worst:.3}, {lit} lit pixels");
        assert!(
            lit > (W * W / 16) as usize,
            "{name}: too few lit pixels ({lit})"
        );
        if name == "spot" {
            assert!(
                lit < (W * W) as usize,
                "the spot's cone edge is not in view"
            );
        }
    }
}

/// A flat plane whose normal map tilts the normal by 0.5 rad towards the tangent (+x, the
/// direction of +u), scaled by normalTexture.scale 0.8, under a directional light straight
/// above: every pixel is the BRDF's closed form about the tilted normal (decoded from the
/// 8-bit texel exactly as the shader decodes it), which differs from the untilted one by far
/// more than the tolerance. The plane is built in code, so its tangent is its face's.
#[test]
fn a_normal_map_tilts_the_shading_normal_by_its_angle() {
    let Some(gpu) = gpu() else { return };
    let (base, metallic, roughness) = (Vec3::new(0.6, 0.5, 0.4), 0.0, 0.6);
    let (angle, scale) = (0.5f32, 0.8f32);
    let texel = [angle.sin(), 0.0, angle.cos()].map(|c| ((c + 1.0) * 0.5 * 255.0).round() as u8);
    let decoded = Vec3::from(texel.map(|c| c as f32 / 255.0 * 2.0 - 1.0));
    let v = Vec3::new(decoded.x * scale, decoded.y * scale, decoded.z).normalize();
    // Tangent +x, bitangent +z (decreasing v), normal +y.
    let tilted = (Vec3::X * v.x + Vec3::Z * v.y + Vec3::Y * v.z).normalize();
    assert!(tilted.dot(Vec3::Y) < 0.95, "{tilted}");
    let mut mat = material(base.to_array(), metallic, roughness);
    mat.normal_texture = Some(texture_slot(0, true));
    mat.normal_scale = scale;
    let mut scene = plane_scene(mat, 5.0);
    scene.images.push(psrestir::scene::Image8 {
        name: "normal".into(),
        width: 2,
        height: 2,
        rgba: vec![[texel[0], texel[1], texel[2], 255]; 4],
    });
    let intensity = Vec3::splat(3.0);
    scene.lights.push(PunctualLight {
        name: "sun".into(),
        kind: PunctualKind::Directional,
        position: Vec3::ZERO,
        direction: Vec3::NEG_Y,
        intensity,
        range: 0.0,
    });
    let spp = 16;
    let r = Renderer::new(&gpu, &scene).unwrap();
    let out = render_image(&r, W, spp, 5, Techniques::Mis);
    let cam = &scene.cameras[0];
    let (mut worst, mut flat_off) = (0.0f64, 0usize);
    for y in 0..W {
        for x in 0..W {
            let mut subs = Vec::new();
            let mut flat = Vec::new();
            for j in 0..4 {
                for i in 0..4 {
                    let p = Vec2::new(
                        x as f32 + (i as f32 + 0.5) / 4.0,
                        y as f32 + (j as f32 + 0.5) / 4.0,
                    );
                    let (_, d) = camera_dir(cam, W, W, p);
                    let f = |n| brdf_eval_cos(base, metallic, roughness, n, -d, Vec3::Y);
                    subs.push(lum((f(tilted) * intensity).to_array()));
                    flat.push(lum((f(Vec3::Y) * intensity).to_array()));
                }
            }
            let (m, sd) = mean_sd(&subs);
            let (m_flat, _) = mean_sd(&flat);
            let got = lum(out.at(x, y));
            let tol = 5.0 * sd / (spp as f64).sqrt() + 2e-3 * m + 1e-6;
            worst = worst.max((got - m).abs() / tol);
            assert!(
                (got - m).abs() <= tol,
                "pixel ({x},{y}): {got} vs closed form {m} about the tilted normal (tolerance \
                 {tol}; about the untilted normal {m_flat})"
            );
            flat_off += ((got - m_flat).abs() > tol) as usize;
        }
    }
    eprintln!("normal map: worst error / tolerance {worst:.3}");
    // The tilt shows: most pixels are far from the untilted normal's value.
    assert!(
        flat_off > (W * W / 2) as usize,
        "{flat_off} pixels differ from flat"
    );
}

/// Irradiance at a point on the axis of a uniformly emitting rectangle (half-edges a, b at
/// distance h, radiance L): E = 2 L [X/sqrt(1+X^2) atan(Y/sqrt(1+X^2)) + Y/sqrt(1+Y^2)
/// atan(X/sqrt(1+Y^2))], X = a/h, Y = b/h (four corner rectangles of the classic form factor).
fn rectangle_axis_irradiance(a: f64, b: f64, h: f64, l: f64) -> f64 {
    let (x, y) = (a / h, b / h);
    let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
    2.0 * l * (x / sx * (y / sx).atan() + y / sy * (x / sy).atan())
}

/// Midpoint rule over a rectangle (centre c, half-edges u, v, emitting along -y) of the
/// radiance that a surface point x (normal +y) reflects towards wo: the integral of
/// f(wo, wi) cos(theta_x) cos(theta_y) / d^2 over its area. `f_cos` is f times cos(theta_x).
fn rectangle_integral(
    c: Vec3,
    u: Vec3,
    v: Vec3,
    x: Vec3,
    n: usize,
    f_cos: impl Fn(Vec3) -> Vec3,
) -> Vec3 {
    let da = 4.0 * u.length() * v.length() / (n * n) as f32;
    let mut sum = Vec3::ZERO;
    for j in 0..n {
        for i in 0..n {
            let s = 2.0 * (i as f32 + 0.5) / n as f32 - 1.0;
            let t = 2.0 * (j as f32 + 0.5) / n as f32 - 1.0;
            let to = c + s * u + t * v - x;
            let d2 = to.length_squared();
            let wi = to / d2.sqrt();
            let cos_y = wi.y.max(0.0);
            sum += f_cos(wi) * cos_y / d2;
        }
    }
    sum * da
}

#[test]
fn rectangle_quadrature_matches_the_closed_form_on_its_axis() {
    // The CPU reference of the area-light test below, checked against the closed form:
    // a Lambertian receiver (f = 1/pi) reflects E / pi.
    for (a, b, h) in [(0.4f32, 0.4, 1.5), (0.3, 0.8, 0.5), (2.0, 1.0, 0.3)] {
        let c = Vec3::new(0.1, h, -0.2);
        let x = Vec3::new(0.1, 0.0, -0.2);
        let (u, v) = (Vec3::new(a, 0.0, 0.0), Vec3::new(0.0, 0.0, b));
        let lambert = |wi: Vec3| Vec3::splat(wi.y.max(0.0) / std::f32::consts::PI);
        let got = rectangle_integral(c, u, v, x, 400, lambert).x as f64;
        let want =
            rectangle_axis_irradiance(a as f64, b as f64, h as f64, 1.0) / std::f64::consts::PI;
        assert!(
            (got - want).abs() < 2e-4 * want,
            "a {a}, b {b}, h {h}: quadrature {got} vs closed form {want}"
        );
    }
}

/// A single-sided emissive rectangle over a glossy-diffuse plane, rendered with each technique,
/// against the quadrature of the emitted radiance (whose Lambertian case is the closed form
/// above): block means within five standard errors plus 0.2% for the quadrature.
#[test]
fn plane_under_a_rectangular_area_light_matches_the_quadrature() {
    let Some(gpu) = gpu() else { return };
    let (base, metallic, roughness) = (Vec3::new(0.6, 0.5, 0.4), 0.0, 0.5);
    let half = 20.0;
    let mut scene = plane_scene(material(base.to_array(), metallic, roughness), half);
    let le = Vec3::new(5.0, 4.5, 4.0);
    scene.materials.push(psrestir::scene::Material {
        emissive: le,
        ..material([0.0; 3], 0.0, 1.0)
    });
    // Centre (0.2, 1.5, -0.3), half-edges 0.4 and 0.3, facing down (u x v = -y).
    let (c, u, v) = (
        Vec3::new(0.2, 1.5, -0.3),
        Vec3::new(0.4, 0.0, 0.0),
        Vec3::new(0.0, 0.0, 0.3),
    );
    scene.triangles.extend(quad(c - u - v, 2.0 * u, 2.0 * v, 1));
    // From below the lamp's plane, so that the camera does not see it.
    scene.cameras = vec![look_at(
        Vec3::new(0.0, 1.2, 2.2),
        Vec3::new(0.0, 0.0, -0.5),
        Vec3::Y,
        0.6,
    )];
    let w = 32u32;
    let cam = &scene.cameras[0];
    let reference: Vec<[f32; 3]> = (0..w * w)
        .map(|k| {
            let (px, py) = (k % w, k / w);
            let mut sum = Vec3::ZERO;
            for j in 0..2 {
                for i in 0..2 {
                    let p = Vec2::new(
                        px as f32 + 0.25 + 0.5 * i as f32,
                        py as f32 + 0.25 + 0.5 * j as f32,
                    );
                    let (o, d) = camera_dir(cam, w, w, p);
                    assert!(d.y < 0.0, "pixel ({px},{py}) does not look at the plane");
                    let x = o + (-o.y / d.y) * d;
                    assert!(
                        x.x.abs() < half && x.z.abs() < half,
                        "pixel ({px},{py}) looks past the plane"
                    );
                    sum += rectangle_integral(c, u, v, x, 24, |wi| {
                        brdf_eval_cos(base, metallic, roughness, Vec3::Y, -d, wi)
                    }) * le;
                }
            }
            (sum / 4.0).to_array()
        })
        .collect();
    let ref_mean = reference.iter().map(|p| lum(*p)).sum::<f64>() / (w * w) as f64;
    assert!(
        ref_mean > 0.02,
        "the lamp barely lights the view ({ref_mean})"
    );
    let r = Renderer::new(&gpu, &scene).unwrap();
    for t in [Techniques::Mis, Techniques::NeeOnly, Techniques::BsdfOnly] {
        let spp = if t == Techniques::BsdfOnly { 512 } else { 64 };
        let render = |seed| render_image(&r, w, spp, seed, t).rgb;
        let (a1, a2) = (render(1), render(2));
        let block = 4usize;
        let mut worst = 0.0f64;
        for by in (0..w as usize).step_by(block) {
            for bx in (0..w as usize).step_by(block) {
                let (mut d, mut var, mut m) = (0.0, 0.0, 0.0);
                for y in by..by + block {
                    for x in bx..bx + block {
                        let i = y * w as usize + x;
                        let (g1, g2, want) = (lum(a1[i]), lum(a2[i]), lum(reference[i]));
                        d += 0.5 * (g1 + g2) - want;
                        var += 0.25 * (g1 - g2).powi(2);
                        m += want;
                    }
                }
                let k = (block * block) as f64;
                // BSDF sampling alone rarely finds the lamp from far blocks: two renders may
                // both draw none there (a zero variance estimate), so it gets 1% of the
                // image mean on top; the faults this is for move whole regions.
                let rare = if t == Techniques::BsdfOnly {
                    0.01 * ref_mean
                } else {
                    0.0
                };
                let tol = 5.0 * (var / (k * k)).sqrt() + 2e-3 * m / k + rare + 1e-6;
                let err = (d / k).abs();
                worst = worst.max(err / tol);
                assert!(
                    err <= tol,
                    "{t:?}: block ({bx},{by}): mean {} vs quadrature {} (tolerance {tol})",
                    m / k + d / k,
                    m / k
                );
            }
        }
        eprintln!("{t:?}: worst block error / tolerance {worst:.3}");
    }
}

#[test]
fn plane_under_a_constant_environment_matches_the_albedo_integral() {
    let Some(gpu) = gpu() else { return };
    let (base, metallic, roughness) = (Vec3::new(0.5, 0.5, 0.5), 0.0, 0.6);
    let env = 0.8f32;
    let mut scene = plane_scene(material(base.to_array(), metallic, roughness), 5.0);
    scene.env = Some(EnvMap::constant([env; 3]));
    let spp = 64;
    let r = Renderer::new(&gpu, &scene).unwrap();
    for techniques in [Techniques::Mis, Techniques::NeeOnly, Techniques::BsdfOnly] {
        let out = render_image(&r, W, spp, 5, techniques);
        // The albedo depends on the view elevation only: tabulate it over cos(theta_o).
        let table: Vec<f64> = (0..=32)
            .map(|k| {
                let c = (k as f32 / 32.0).max(0.02);
                let wo = Vec3::new((1.0 - c * c).sqrt(), c, 0.0);
                lum(directional_albedo(base, metallic, roughness, wo).to_array())
            })
            .collect();
        let albedo = |c: f32| {
            let x = (c.clamp(0.02, 1.0) * 32.0).min(31.999);
            let k = x as usize;
            let f = (x - k as f32) as f64;
            table[k] * (1.0 - f) + table[k + 1] * f
        };
        let cam = &scene.cameras[0];
        let mut residual = Vec::new();
        let mut reference = Vec::new();
        for y in 0..W {
            for x in 0..W {
                let (_, d) = camera_dir(cam, W, W, Vec2::new(x as f32 + 0.5, y as f32 + 0.5));
                let want = env as f64 * albedo(-d.y);
                residual.push(lum(out.at(x, y)) - want);
                reference.push(want);
            }
        }
        let (mean_r, sd_r) = mean_sd(&residual);
        let (mean_ref, _) = mean_sd(&reference);
        let n = residual.len() as f64;
        // Unbiased: the mean residual is within 5 standard errors of zero, plus 0.2% for the
        // quadrature, the table interpolation and evaluating the albedo at pixel centres.
        let tol = 5.0 * sd_r / n.sqrt() + 2e-3 * mean_ref;
        eprintln!("{techniques:?}: mean residual {mean_r:.5}, per-pixel sd {sd_r:.4}, reference mean {mean_ref:.4}");
        assert!(
            mean_r.abs() <= tol,
            "{techniques:?}: mean radiance off by {mean_r} (tolerance {tol})"
        );
        // And not merely unbiased on average: per-pixel noise at 64 spp stays small (with
        // MIS; either technique alone is noisier by design).
        assert!(
            techniques != Techniques::Mis || sd_r < 0.1 * mean_ref,
            "{techniques:?}: per-pixel error sd {sd_r} too large"
        );
        // White furnace sanity: a plane never reflects more than it receives.
        assert!(out
            .rgb
            .iter()
            .all(|p| p.iter().all(|&v| v.is_finite() && v >= 0.0)));
    }
}

#[test]
fn texel_coordinates_wrap_as_the_integer_modulo() {
    let Some(gpu) = gpu() else { return };
    // The shaders wrap without an integer division (shared/wrap.wgsl): exact for |i| <= 2^23,
    // the range of texel coordinates that come from f32 texture coordinates with a sub-texel
    // step; beyond it, at least inside the texture.
    let exact = 1i64 << 23;
    let mut rng = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        rng
    };
    for n in [1i32, 2, 3, 7, 64, 255, 256, 1000, 4096, 65536, 1 << 22] {
        let mut coords: Vec<i32> = (-3 * n.min(5000)..=3 * n.min(5000)).collect();
        for _ in 0..20000 {
            coords.push((next() % (2 * exact as u64 + 1)) as i64 as i32 - exact as i32);
        }
        coords.extend([
            i32::MIN,
            i32::MAX,
            -(1 << 24) - 1,
            1 << 24,
            1 << 30,
            -(1 << 30),
        ]);
        for wrap in [Wrap::Repeat, Wrap::Clamp, Wrap::Mirror] {
            let got = psrestir::render::wrap_trial(&gpu, &coords, n, wrap).unwrap();
            for (&i, &g) in coords.iter().zip(&got) {
                let want = psrestir::scene::images::wrap_texel(i as i64, n as i64, wrap);
                assert!(
                    (0..n).contains(&g),
                    "{wrap:?}: {i} in width {n} wrapped to {g}"
                );
                if (i as i64).abs() <= exact {
                    assert_eq!(g as i64, want, "{wrap:?}: {i} in width {n}");
                }
            }
        }
    }
}

/// A file's normal map and an optimized map holding the same texels render alike, also where
/// the mapped normal faces away from the viewer: a plane seen at a grazing angle (80 degrees
/// from its normal) whose map tilts half its texels 45 degrees away from the camera and the
/// other half sideways. Targets rendered from a scene's own normal map are matched by the
/// true map only if both read a texel the same way. Measured (lavapipe): the summed 4x4-block
/// difference is 0.003 of the render's sum; with the file's map falling back to the
/// geometric normal where it faces away (as it did before both were bent towards the
/// viewer) it was 0.062, so the bound of 0.03 separates the two by far more than the noise.
#[test]
fn a_files_normal_map_renders_as_the_optimized_map_of_its_texels() {
    use psrestir::image_io::Image;
    use psrestir::optim::{Optimizer, Settings};
    use psrestir::render::params::ParamSet;
    use psrestir::task::{Filter, Init, Slot, TextureSpec};
    let Some(gpu) = gpu() else { return };
    const N: usize = 8;
    const SIZE: u32 = 32;
    // Map +Y is world +z here (tangent +x, bitangent +z): -Y tilts away from the camera.
    let away = [0.0, -(45f32.to_radians().sin()), 45f32.to_radians().cos()];
    let side = [30f32.to_radians().sin(), 0.0, 30f32.to_radians().cos()];
    let texels: Vec<[u8; 3]> = (0..N * N)
        .map(|k| if (k % N + k / N) % 2 == 0 { away } else { side })
        .map(|n| n.map(|c| ((c + 1.0) * 0.5 * 255.0).round() as u8))
        .collect();
    let mut mat = material([0.6, 0.5, 0.4], 0.0, 0.4);
    mat.name = "plane".into();
    mat.normal_texture = Some(texture_slot(0, true));
    let mut scene = plane_scene(mat, 2.0);
    scene.cameras = vec![look_at(
        Vec3::new(0.0, 0.55, 3.1),
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::Y,
        0.9,
    )];
    scene.images.push(psrestir::scene::Image8 {
        name: "normal".into(),
        width: N as u32,
        height: N as u32,
        rgba: texels.iter().map(|t| [t[0], t[1], t[2], 255]).collect(),
    });
    scene.lights.push(PunctualLight {
        name: "sun".into(),
        kind: PunctualKind::Directional,
        position: Vec3::ZERO,
        direction: Vec3::new(0.3, -1.0, -0.6).normalize(),
        intensity: Vec3::splat(3.0),
        range: 0.0,
    });
    scene.env = Some(EnvMap::constant([0.2, 0.2, 0.25]));
    let spp = 256;
    let file = render_image(
        &Renderer::new(&gpu, &scene).unwrap(),
        SIZE,
        spp,
        3,
        Techniques::Mis,
    );
    let spec = TextureSpec {
        material: "plane".into(),
        slot: Slot::Normal,
        resolution: [N as u32, N as u32],
        init: Init::Vector(vec![0.5, 0.5, 1.0]),
        learning_rate: None,
    };
    let set =
        ParamSet::from_specs(&scene, &[spec], Filter::Nearest, std::path::Path::new("t")).unwrap();
    let settings = Settings::new(SIZE, SIZE, vec![0]);
    let blank = [Image::new(SIZE, SIZE)];
    let opt = Optimizer::new(&gpu, &scene, set, settings, &blank).unwrap();
    let values: Vec<f32> = texels.iter().flatten().map(|&c| c as f32 / 255.0).collect();
    opt.write_params(&values).unwrap();
    let param = opt.render(0, spp, 4).unwrap();
    // Compared in 4 x 4-pixel blocks (a block's mean over 4096 samples: its noise is a few
    // percent of the mean), as a sum over blocks relative to the file render's sum.
    let block = |img: &Image, bx: u32, by: u32| -> f64 {
        let mut s = 0.0;
        for y in 4 * by..4 * by + 4 {
            for x in 4 * bx..4 * bx + 4 {
                s += img.at(x, y).iter().map(|&c| c as f64).sum::<f64>();
            }
        }
        s
    };
    let (mut diff, mut total) = (0.0, 0.0);
    for by in 0..SIZE / 4 {
        for bx in 0..SIZE / 4 {
            let (a, b) = (block(&file, bx, by), block(&param, bx, by));
            diff += (a - b).abs();
            total += a;
        }
    }
    let rel = diff / total;
    eprintln!("file map against optimized map: summed block difference {rel:.4} of the mean");
    assert!(total > 0.0, "the plane renders black");
    assert!(
        rel < 0.03,
        "the two readings of one normal map differ by {rel:.4} of the render"
    );
}
