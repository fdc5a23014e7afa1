//! A glTF mesh's triangle primitives as the scene's triangles: attributes read and checked,
//! tangents for normal-mapped materials (the file's or MikkTSpace's), faces transformed to
//! world space, and what was skipped said in the scene's warnings.
use super::{in_bounds, Loader, MAX_COORD, MAX_TRIANGLES};
use crate::scene::Triangle;
use crate::Result;
use glam::{Mat3, Mat4, Vec2, Vec3, Vec4};

/// One primitive's vertex attributes, each as long as `positions` (checked).
struct Attributes {
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    uvs: Option<Vec<Vec2>>,
    tangents: Option<Vec<Vec4>>,
    indices: Vec<u32>,
}

impl Loader<'_> {
    pub(super) fn load_mesh(&mut self, mesh: &gltf::Mesh, world: Mat4) -> Result<()> {
        let mesh_name = mesh
            .name()
            .map(|n| format!("mesh `{n}`"))
            .unwrap_or_else(|| format!("mesh {}", mesh.index()));
        for prim in mesh.primitives() {
            let what = format!("{mesh_name} primitive {}", prim.index());
            if prim.mode() != gltf::mesh::Mode::Triangles {
                self.scene.warnings.push(format!(
                    "{what}: mode {:?} is not a triangle list, skipped",
                    prim.mode()
                ));
                continue;
            }
            let Some(a) = self.read_attributes(&prim, &what)? else {
                continue;
            };
            let material = self.material_index(prim.material().index());
            let face_tangents = self.face_tangents(&a, material, &what);
            self.push_faces(&a, face_tangents.as_deref(), material, world, &what)?;
        }
        Ok(())
    }

    /// The attributes of `prim` (None, with a warning, without positions); an error when an
    /// index is out of range or the counts differ.
    fn read_attributes(
        &mut self,
        prim: &gltf::Primitive,
        what: &str,
    ) -> Result<Option<Attributes>> {
        let buffers = &self.buffers;
        let reader = prim.reader(|b| buffers.get(b.index()).map(|v| v.as_slice()));
        let Some(positions) = reader.read_positions() else {
            self.scene
                .warnings
                .push(format!("{what}: no POSITION attribute, skipped"));
            return Ok(None);
        };
        let positions: Vec<Vec3> = positions.map(Vec3::from).collect();
        let normals: Option<Vec<Vec3>> = reader.read_normals().map(|n| n.map(Vec3::from).collect());
        let uvs: Option<Vec<Vec2>> = reader
            .read_tex_coords(0)
            .map(|t| t.into_f32().map(Vec2::from).collect());
        let tangents: Option<Vec<Vec4>> =
            reader.read_tangents().map(|t| t.map(Vec4::from).collect());
        let indices: Vec<u32> = match reader.read_indices() {
            Some(i) => i.into_u32().collect(),
            None => (0..positions.len() as u32).collect(),
        };
        let nv = positions.len();
        if let Some(bad) = indices.iter().find(|&&i| i as usize >= nv) {
            return Err(self.err(format!("{what}: index {bad} out of range ({nv} vertices)")));
        }
        if normals.as_ref().is_some_and(|n| n.len() != nv)
            || uvs.as_ref().is_some_and(|u| u.len() != nv)
            || tangents.as_ref().is_some_and(|t| t.len() != nv)
        {
            return Err(self.err(format!("{what}: attribute counts differ")));
        }
        Ok(Some(Attributes {
            positions,
            normals,
            uvs,
            tangents,
            indices,
        }))
    }

    /// Tangents of each face's vertices: the file's, or MikkTSpace's from the positions,
    /// normals and UV0; and the warnings of a textured material without UVs.
    fn face_tangents(&mut self, a: &Attributes, material: u32, what: &str) -> Option<Vec<Vec4>> {
        let m = &self.scene.materials[material as usize];
        if a.uvs.is_none() {
            let textured = m.base_color_texture.is_some()
                || m.metallic_roughness_texture.is_some()
                || m.emissive_texture.is_some();
            if textured {
                self.scene.warnings.push(format!(
                    "{what}: no TEXCOORD_0 but material `{}` is textured: its textures are \
                     read at UV (0, 0) there, and texture optimization of that material \
                     gets no gradient from it",
                    m.name
                ));
            }
        }
        // Every primitive with UVs gets tangents (the file's, or MikkTSpace's), so that a
        // normal map optimized on a material without one has the frame a glTF viewer will
        // use for the exported map; a face of a primitive without UVs has none.
        let m = &self.scene.materials[material as usize];
        let normal_mapped = m.normal_texture.is_some();
        match (&a.tangents, &a.uvs) {
            (Some(t), _) => Some(a.indices.iter().map(|&i| t[i as usize]).collect()),
            (None, None) if !normal_mapped => None,
            (None, Some(uv)) => crate::scene::tangents::mikktspace(
                &a.positions,
                a.normals.as_deref(),
                uv,
                &a.indices,
            ),
            (None, None) => {
                let name = m.name.clone();
                self.scene.warnings.push(format!(
                    "{what}: material `{name}` has a normal map but the primitive has no \
                     TEXCOORD_0: the normal map is not applied there"
                ));
                None
            }
        }
    }

    /// Transform `a`'s faces by `world` and add them to the scene, skipping (with a
    /// warning) faces out of bounds or of zero area.
    fn push_faces(
        &mut self,
        a: &Attributes,
        face_tangents: Option<&[Vec4]>,
        material: u32,
        world: Mat4,
        what: &str,
    ) -> Result<()> {
        let normal_m = Mat3::from_mat4(world).inverse().transpose();
        let flip = Mat3::from_mat4(world).determinant() < 0.0;
        let tangent_m = Mat3::from_mat4(world);
        let (mut skipped, mut degenerate) = (0, 0);
        for (fi, f) in a.indices.chunks_exact(3).enumerate() {
            if self.scene.triangles.len() >= MAX_TRIANGLES {
                return Err(self.err(format!("more than {MAX_TRIANGLES} triangles")));
            }
            let mut idx = [f[0] as usize, f[1] as usize, f[2] as usize];
            // Which of the face's vertices each corner is (the winding is reversed under
            // a mirroring transform).
            let mut corner = [0, 1, 2];
            if flip {
                idx.swap(1, 2);
                corner.swap(1, 2);
            }
            let p = idx.map(|i| world.transform_point3(a.positions[i]));
            if !p.iter().all(|&v| in_bounds(v)) {
                skipped += 1;
                continue;
            }
            let face = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
            if face == Vec3::ZERO {
                // Zero area (collinear or repeated vertices): never hit, never a light.
                degenerate += 1;
                continue;
            }
            let n = idx.map(|i| match &a.normals {
                Some(ns) => {
                    let v = (normal_m * ns[i]).normalize_or_zero();
                    // Also catches vectors so short that normalizing them loses precision.
                    if v.is_finite() && (v.length() - 1.0).abs() < 1e-4 {
                        v
                    } else {
                        face
                    }
                }
                None => face,
            });
            let uv = idx.map(|i| match &a.uvs {
                Some(u) if u[i].is_finite() => u[i],
                _ => Vec2::ZERO,
            });
            // A tangent is a direction on the surface (transformed like positions); a
            // mirroring transform also mirrors the bitangent's handedness.
            let t = match face_tangents {
                Some(ft) => corner.map(|k| {
                    let v = ft[3 * fi + k];
                    let d = (tangent_m * v.truncate()).normalize_or_zero();
                    let w = if (v.w < 0.0) != flip { -1.0 } else { 1.0 };
                    if d.is_finite() {
                        d.extend(w)
                    } else {
                        Vec4::ZERO
                    }
                }),
                None => [Vec4::ZERO; 3],
            };
            self.scene.triangles.push(Triangle {
                p,
                n,
                uv,
                t,
                material,
            });
        }
        if skipped > 0 {
            self.scene.warnings.push(format!(
                "{what}: {skipped} triangles with non-finite positions or positions \
                 beyond ±{MAX_COORD:e} skipped"
            ));
        }
        if degenerate > 0 {
            self.scene.warnings.push(format!(
                "{what}: {degenerate} degenerate (zero-area) triangles skipped"
            ));
        }
        Ok(())
    }
}
