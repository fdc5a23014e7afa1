//! The BVH finds exactly the hits that testing every triangle finds (both on the GPU, with
//! the same intersection routine), on a random triangle soup and on the bundled scene; and
//! where the adapter offers ray queries, they find the same hits as the BVH.
mod common;

use glam::Vec3;
use psrestir::gpu::{Gpu, Tracer};
use psrestir::render::{Ray, RayHit, Renderer};
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

/// A device tracing with the software BVH, whatever PSRESTIR_TRACER says.
fn software_gpu() -> Option<Gpu> {
    common::gpu()?;
    Some(Gpu::with_tracer(Tracer::Software).unwrap())
}

fn compare(scene: &Scene, rays: &[Ray]) {
    let Some(gpu) = software_gpu() else { return };
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

fn random_soup() -> (Scene, Vec<Ray>) {
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
            t: Default::default(),
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
    (scene, rays)
}

#[test]
fn bvh_equals_brute_force_on_random_triangles() {
    let (scene, rays) = random_soup();
    compare(&scene, &rays);
}

fn bundled_scene() -> (Scene, Vec<Ray>) {
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
    (scene, rays)
}

#[test]
fn bvh_equals_brute_force_on_the_bundled_scene() {
    let (scene, rays) = bundled_scene();
    compare(&scene, &rays);
}

/// Ray queries (where the adapter offers them; lavapipe from Mesa 24 does) against the BVH.
/// Their intersection test is the driver's, not ours, so t may differ in the last bits and a
/// ray through a shared edge or vertex may report either triangle, or hit one where ours
/// misses both: such rays must hit within 1e-3 of an edge. Everything else agrees: the same
/// triangle, t within 1e-4 relative, barycentrics within 1e-3.
#[test]
fn ray_queries_find_the_bvh_hits() {
    if common::gpu().is_none() {
        return;
    }
    let rq = match Gpu::with_tracer(Tracer::RayQuery) {
        Ok(g) => g,
        Err(e) => {
            eprintln!("skipped: {e} (the software BVH is used)");
            return;
        }
    };
    let sw = Gpu::with_tracer(Tracer::Software).unwrap();
    for (name, (scene, rays)) in [("soup", random_soup()), ("bundled", bundled_scene())] {
        let a = Renderer::new(&sw, &scene)
            .unwrap()
            .trace_rays(&rays, false)
            .unwrap();
        let b = Renderer::new(&rq, &scene)
            .unwrap()
            .trace_rays(&rays, false)
            .unwrap();
        let near_edge = |h: &RayHit| {
            let (u, v) = (h.b[0], h.b[1]);
            h.tri.is_some() && u.min(v).min(1.0 - u - v) < 1e-3
        };
        let mut differ = 0;
        for (i, (x, y)) in a.iter().zip(&b).enumerate() {
            if x.tri == y.tri {
                if x.tri.is_some() {
                    assert!(
                        (x.t - y.t).abs() <= 1e-4 * x.t.abs() + 1e-6,
                        "{name} ray {i}: t {} (BVH) against {} (ray query)",
                        x.t,
                        y.t
                    );
                    assert!(
                        (x.b[0] - y.b[0]).abs() < 1e-3 && (x.b[1] - y.b[1]).abs() < 1e-3,
                        "{name} ray {i}: barycentrics {:?} against {:?}",
                        x.b,
                        y.b
                    );
                }
            } else {
                differ += 1;
                let same_t =
                    x.tri.is_some() && y.tri.is_some() && (x.t - y.t).abs() <= 1e-3 * x.t.abs();
                assert!(
                    same_t || near_edge(x) || near_edge(y),
                    "{name} ray {i}: BVH {x:?}, ray query {y:?}"
                );
            }
        }
        assert!(
            differ * 200 <= rays.len(),
            "{name}: {differ} of {} rays differ",
            rays.len()
        );
        eprintln!(
            "{name}: {differ} of {} rays hit another triangle",
            rays.len()
        );
    }
}
