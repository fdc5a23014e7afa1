//! The family's geometry: its shapes' meshes (wound about their normals) and the room's
//! shell, with the plain materials and panels they are built from.
use crate::assets::authoring::GltfBuilder;
use glam::Vec3;
use serde_json::json;
use std::f32::consts::PI;

/// The shape whose texture is optimized.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shape {
    /// A UV sphere on a floor.
    Sphere,
    /// A superellipsoid close to a box with rounded edges, on a floor.
    RoundedBox,
    /// A torus on a floor.
    Torus,
    /// A flat wall whose detail is in its texture (and its normal map's relief).
    Relief,
    /// The back wall of a closed room lit only through an opening in its side: no light
    /// reaches the wall but by bounces (depth 3).
    Room,
    /// A cube whose six faces share one texture as a 3 x 2 atlas: seams at every edge.
    SeamedCube,
}

/// Positions, normals, uvs and indices of a surface over a (nu x nv) grid of (u, v) in
/// [0, 1]², each triangle wound counter-clockwise about its vertices' normals and those of
/// no area (at a pole) left out.
pub(super) type Mesh = (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<[f32; 2]>, Vec<u32>);

fn grid_mesh(
    nu: u32,
    nv: u32,
    at: impl Fn(f32, f32) -> (Vec3, Vec3),
    uv_of: impl Fn(f32, f32) -> [f32; 2],
) -> Mesh {
    let (mut p, mut n, mut t, mut idx) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for j in 0..=nv {
        for i in 0..=nu {
            let (u, v) = (i as f32 / nu as f32, j as f32 / nv as f32);
            let (pos, nrm) = at(u, v);
            p.push(pos.to_array());
            n.push(nrm.normalize_or(Vec3::Y).to_array());
            t.push(uv_of(u, v));
        }
    }
    let w = nu + 1;
    for j in 0..nv {
        for i in 0..nu {
            let a = j * w + i;
            for tri in [[a, a + w, a + 1], [a + 1, a + w, a + w + 1]] {
                push_wound(&p, &n, &mut idx, tri);
            }
        }
    }
    (p, n, t, idx)
}

/// Append `tri` wound counter-clockwise about its vertices' mean normal (none where it has
/// no area).
pub(super) fn push_wound(p: &[[f32; 3]], n: &[[f32; 3]], idx: &mut Vec<u32>, tri: [u32; 3]) {
    let v = |k: usize| Vec3::from(p[tri[k] as usize]);
    let face = (v(1) - v(0)).cross(v(2) - v(0));
    if face.length() < 1e-9 {
        return;
    }
    let mean: Vec3 = tri.iter().map(|&k| Vec3::from(n[k as usize])).sum();
    if face.dot(mean) < 0.0 {
        idx.extend_from_slice(&[tri[0], tri[2], tri[1]]);
    } else {
        idx.extend_from_slice(&tri);
    }
}

/// The shape's mesh, centred at `c`, about a metre across.
pub(super) fn shape_mesh(shape: Shape, c: Vec3) -> Mesh {
    let identity = |u: f32, v: f32| [u, v];
    match shape {
        Shape::Sphere => grid_mesh(
            96,
            48,
            |u, v| {
                let (th, ph) = (v * PI, u * 2.0 * PI);
                let d = Vec3::new(th.sin() * ph.cos(), th.cos(), -th.sin() * ph.sin());
                (c + 0.9 * d, d)
            },
            identity,
        ),
        Shape::RoundedBox => {
            // |x|^q + |y|^q + |z|^q = 1 with q = 2 / e: the normal is the gradient.
            let e = 0.3f32;
            let s = |w: f32, e: f32| w.signum() * w.abs().powf(e);
            grid_mesh(
                96,
                64,
                move |u, v| {
                    let (th, ph) = (v * PI, u * 2.0 * PI);
                    let d = Vec3::new(
                        s(th.sin(), e) * s(ph.cos(), e),
                        s(th.cos(), e),
                        -s(th.sin(), e) * s(ph.sin(), e),
                    );
                    let q = 2.0 / e;
                    let g = Vec3::new(s(d.x, q - 1.0), s(d.y, q - 1.0), s(d.z, q - 1.0));
                    (c + 0.75 * d, if g.length() > 0.0 { g } else { d })
                },
                identity,
            )
        }
        Shape::Torus => grid_mesh(
            96,
            48,
            |u, v| {
                let (a, b) = (u * 2.0 * PI, v * 2.0 * PI);
                let ring = Vec3::new(a.cos(), 0.0, -a.sin());
                let d = ring * b.cos() + Vec3::Y * b.sin();
                (c + 0.75 * ring + 0.32 * d, d)
            },
            identity,
        ),
        Shape::Relief => grid_mesh(
            1,
            1,
            |u, v| (c + Vec3::new(2.0 * u - 1.0, 1.0 - 2.0 * v, 0.0), Vec3::Z),
            identity,
        ),
        Shape::SeamedCube => seamed_cube(c, 0.7),
        Shape::Room => grid_mesh(
            1,
            1,
            |u, v| (Vec3::new(3.6 * u - 1.8, 2.8 - 2.6 * v, -1.98), Vec3::Z),
            identity,
        ),
    }
}

/// A cube of half-side `h` whose faces are the cells of a 3 x 2 atlas (a small gutter
/// between cells): every edge is a seam in texture space.
fn seamed_cube(c: Vec3, h: f32) -> Mesh {
    let (mut p, mut n, mut t, mut idx) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let faces = [
        (Vec3::X, Vec3::NEG_Z, Vec3::Y),
        (Vec3::NEG_X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::X, Vec3::NEG_Z),
        (Vec3::NEG_Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (Vec3::NEG_Z, Vec3::NEG_X, Vec3::Y),
    ];
    for (k, (nrm, right, up)) in faces.into_iter().enumerate() {
        let (cu, cv) = ((k % 3) as f32 / 3.0, (k / 3) as f32 / 2.0);
        let base = p.len() as u32;
        for (a, b) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
            let pos = c + h * (nrm + (2.0 * a - 1.0) * right + (2.0 * b - 1.0) * up);
            p.push(pos.to_array());
            n.push(nrm.to_array());
            let g = 0.02;
            t.push([
                cu + (g + a * (1.0 - 2.0 * g)) / 3.0,
                cv + (g + (1.0 - b) * (1.0 - 2.0 * g)) / 2.0,
            ]);
        }
        for tri in [[base, base + 1, base + 2], [base, base + 2, base + 3]] {
            push_wound(&p, &n, &mut idx, tri);
        }
    }
    (p, n, t, idx)
}

/// A plain double-sided material.
pub(super) fn plain(b: &mut GltfBuilder, name: &str, color: [f32; 3], roughness: f32) -> usize {
    b.add_material(json!({
        "name": name, "doubleSided": true,
        "pbrMetallicRoughness": {"baseColorFactor": [color[0], color[1], color[2], 1.0],
            "metallicFactor": 0.0, "roughnessFactor": roughness}
    }))
}

/// A flat rectangle with corners `o`, `o + a`, `o + a + b`, `o + b`, facing `nrm`.
pub(super) fn panel(
    b: &mut GltfBuilder,
    name: &str,
    (o, a, bb): (Vec3, Vec3, Vec3),
    mat: usize,
) -> usize {
    let p: Vec<[f32; 3]> = [o, o + a, o + a + bb, o + bb]
        .iter()
        .map(|v| v.to_array())
        .collect();
    let nrm = a.cross(bb).normalize();
    let n = vec![nrm.to_array(); 4];
    let mut idx = Vec::new();
    push_wound(&p, &n, &mut idx, [0, 1, 2]);
    push_wound(&p, &n, &mut idx, [0, 2, 3]);
    let mesh = b.add_mesh(name, &p, Some(&n), None, Some(&idx), Some(mat));
    b.add_node(json!({"name": name, "mesh": mesh}))
}

/// The closed room around the back wall (4 x 3 x 4 m), its right wall open between 1.2 and
/// 2.4 m high and ±0.8 m deep; a sun through the opening lights a patch of the floor only.
pub(super) fn room_shell(b: &mut GltfBuilder) -> Vec<usize> {
    let wall = plain(b, "walls", [0.75, 0.73, 0.7], 0.8);
    let floor = plain(b, "floor", [0.8, 0.78, 0.74], 0.7);
    let (x, y, z) = (Vec3::X, Vec3::Y, Vec3::Z);
    let mut nodes = vec![
        panel(
            b,
            "floor",
            (Vec3::new(-2.0, 0.0, 2.0), 4.0 * x, -4.0 * z),
            floor,
        ),
        panel(
            b,
            "ceiling",
            (Vec3::new(-2.0, 3.0, -2.0), 4.0 * x, 4.0 * z),
            wall,
        ),
        panel(
            b,
            "back",
            (Vec3::new(-2.0, 0.0, -2.0), 4.0 * x, 3.0 * y),
            wall,
        ),
        panel(
            b,
            "front",
            (Vec3::new(2.0, 0.0, 2.0), -4.0 * x, 3.0 * y),
            wall,
        ),
        panel(
            b,
            "left",
            (Vec3::new(-2.0, 0.0, 2.0), -4.0 * z, 3.0 * y),
            wall,
        ),
    ];
    // The right wall (x = 2) around its opening.
    let r = Vec3::new(2.0, 0.0, 0.0);
    for (name, z0, z1, y0, y1) in [
        ("right_low", -2.0, 2.0, 0.0, 1.2),
        ("right_high", -2.0, 2.0, 2.4, 3.0),
        ("right_back", -2.0, -0.8, 1.2, 2.4),
        ("right_front", 0.8, 2.0, 1.2, 2.4),
    ] {
        let o = r + Vec3::new(0.0, y0, z0);
        nodes.push(panel(b, name, (o, (y1 - y0) * y, (z1 - z0) * z), wall));
    }
    nodes
}
