//! Tangents for normal maps: MikkTSpace (the `bevy_mikktspace` crate, byte-identical to the
//! reference implementation) for loaded meshes without TANGENT, and a triangle's face tangent
//! from its UVs for scenes built in code.
//!
//! Convention (glTF): the tangent points along +u, the bitangent cross(normal, tangent) x w
//! along -v (up in the image, whose v runs down), so the generator sees UV (u, 1 - v), as the
//! exporters that write TANGENT do.
use glam::{Vec2, Vec3, Vec4};

struct Mesh<'a> {
    positions: &'a [Vec3],
    normals: Option<&'a [Vec3]>,
    uvs: &'a [Vec2],
    indices: &'a [u32],
    out: Vec<Vec4>,
}

impl Mesh<'_> {
    fn vertex(&self, face: usize, vert: usize) -> usize {
        self.indices[3 * face + vert] as usize
    }
}

impl bevy_mikktspace::Geometry for Mesh<'_> {
    fn num_faces(&self) -> usize {
        self.indices.len() / 3
    }

    fn num_vertices_of_face(&self, _face: usize) -> usize {
        3
    }

    fn position(&self, face: usize, vert: usize) -> [f32; 3] {
        self.positions[self.vertex(face, vert)].to_array()
    }

    fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
        match self.normals {
            Some(n) => n[self.vertex(face, vert)].to_array(),
            None => {
                let p = |k| self.positions[self.vertex(face, k)];
                (p(1) - p(0))
                    .cross(p(2) - p(0))
                    .normalize_or_zero()
                    .to_array()
            }
        }
    }

    fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
        let uv = self.uvs[self.vertex(face, vert)];
        [uv.x, 1.0 - uv.y]
    }

    fn set_tangent(
        &mut self,
        tangent_space: Option<bevy_mikktspace::TangentSpace>,
        face: usize,
        vert: usize,
    ) {
        self.out[3 * face + vert] =
            tangent_space.map_or(Vec4::ZERO, |t| Vec4::from(t.tangent_encoded()));
    }
}

/// MikkTSpace tangents of every face's three vertices (face-major), or None when the
/// generator refuses the mesh.
pub(crate) fn mikktspace(
    positions: &[Vec3],
    normals: Option<&[Vec3]>,
    uvs: &[Vec2],
    indices: &[u32],
) -> Option<Vec<Vec4>> {
    let n = indices.len() / 3 * 3;
    let mut mesh = Mesh {
        positions,
        normals,
        uvs,
        indices: &indices[..n],
        out: vec![Vec4::ZERO; n],
    };
    bevy_mikktspace::generate_tangents(&mut mesh).ok()?;
    Some(mesh.out)
}

/// The tangent of a triangle from its positions and UVs (zero where its UVs are degenerate).
pub fn face_tangent(p: [Vec3; 3], uv: [Vec2; 3], n: Vec3) -> Vec4 {
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    let flip = |v: Vec2| Vec2::new(v.x, -v.y);
    let (d1, d2) = (flip(uv[1] - uv[0]), flip(uv[2] - uv[0]));
    let det = d1.x * d2.y - d2.x * d1.y;
    if det.abs() < 1e-12 {
        return Vec4::ZERO;
    }
    let t = (e1 * d2.y - e2 * d1.y) / det;
    let b = (e2 * d1.x - e1 * d2.x) / det;
    let t = (t - n * n.dot(t)).normalize_or_zero();
    if t == Vec3::ZERO {
        return Vec4::ZERO;
    }
    let w = if n.cross(t).dot(b) < 0.0 { -1.0 } else { 1.0 };
    t.extend(w)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat quad in the xy plane with u along +x and v along -y (image rows down the
    /// quad): tangent +x, bitangent +y, both from MikkTSpace and the face tangent.
    #[test]
    fn a_flat_quad_has_the_tangent_of_its_uvs() {
        let positions = [
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 0.0),
        ];
        let uvs = [Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y];
        let normals = [Vec3::Z; 4];
        let indices = [0, 3, 2, 0, 2, 1];
        let t = mikktspace(&positions, Some(&normals), &uvs, &indices).unwrap();
        for v in &t {
            assert!((v.truncate() - Vec3::X).length() < 1e-5, "{v}");
            let b = Vec3::Z.cross(v.truncate()) * v.w;
            assert!((b - Vec3::Y).length() < 1e-5, "{v}");
        }
        let f = face_tangent(
            [positions[0], positions[3], positions[2]],
            [uvs[0], uvs[3], uvs[2]],
            Vec3::Z,
        );
        assert!((f - Vec4::new(1.0, 0.0, 0.0, 1.0)).length() < 1e-6, "{f}");
    }
}
