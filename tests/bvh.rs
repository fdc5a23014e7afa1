//! The BVH finds exactly the hits that testing every triangle finds (both on the GPU, with
//! the same intersection routine), on a random triangle soup and on the bundled scene.
mod common;

use glam::Vec3;
use psrestir::render::{Ray, Renderer};
use psrestir::scene::{Scene, Triangle};

struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 40) as f32) / (1u64 << 24) as f32
    }
    fn vec(&mut self) -> Vec3 {
        Vec3::new(self.next(), self.next(), self.next())
    }
    fn dir(&mut self) -> Vec3 {
        loop {
            let v = self.vec() * 2.0 - 1.0;
            if v.length_squared() > 1e-4 && v.length_squared() <= 1.0 {
                return v.normalize();
            }
        }
    }
}

fn compare(scene: &Scene, rays: &[Ray]) {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu, scene).unwrap();
    let bvh = r.trace_rays(rays, false).unwrap();
    let brute = r.trace_rays(rays, true).unwrap();
    let hits = brute.iter().filter(|h| h.tri.is_some()).count();
    assert!(
        hits > rays.len() / 10,
        "too few rays hit anything ({hits}) for a meaningful test"
    );
    assert!(hits < rays.len(), "every ray hit: misses are not tested");
    for (i, (a, b)) in bvh.iter().zip(&brute).enumerate() {
        assert_eq!(
            a.tri, b.tri,
            "ray {i}: BVH hit {:?}, brute force hit {:?}",
            a, b
        );
        assert_eq!(
            a.t.to_bits(),
            b.t.to_bits(),
            "ray {i}: t differs: {} vs {}",
            a.t,
            b.t
        );
    }
}

#[test]
fn bvh_equals_brute_force_on_random_triangles() {
    let mut rng = Lcg(7);
    let mut scene = Scene {
        materials: vec![common::material([0.5; 3], 0.0, 0.5)],
        ..Default::default()
    };
    for _ in 0..3000 {
        let c = rng.vec() * 10.0;
        let p = [c, c + (rng.vec() - 0.5) * 1.5, c + (rng.vec() - 0.5) * 1.5];
        scene.triangles.push(Triangle {
            p,
            n: [Vec3::Y; 3],
            uv: Default::default(),
            material: 0,
        });
    }
    let mut rays = Vec::new();
    for i in 0..4096 {
        // Half from inside the soup, half from outside towards it.
        let origin = if i % 2 == 0 {
            rng.vec() * 10.0
        } else {
            Vec3::splat(5.0) + rng.dir() * 20.0
        };
        let dir = if i % 2 == 0 {
            rng.dir()
        } else {
            (rng.vec() * 10.0 - origin).normalize()
        };
        let tmax = if i % 7 == 0 { 3.0 } else { f32::MAX };
        rays.push(Ray { origin, dir, tmax });
    }
    compare(&scene, &rays);
}

#[test]
fn bvh_equals_brute_force_on_the_bundled_scene() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/default/scene.gltf");
    let scene = psrestir::scene::load(std::path::Path::new(path)).unwrap();
    assert!(scene.triangles.len() > 5000);
    let mut rng = Lcg(11);
    let rays: Vec<Ray> = (0..3000)
        .map(|_| {
            let origin = Vec3::new(0.0, 1.5, 0.0) + rng.dir() * 5.0;
            let target = Vec3::new(0.0, 1.0, 0.0) + (rng.vec() - 0.5) * 3.0;
            Ray {
                origin,
                dir: (target - origin).normalize(),
                tmax: f32::MAX,
            }
        })
        .collect();
    compare(&scene, &rays);
}
