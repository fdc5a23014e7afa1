//! A binned-SAH bounding volume hierarchy, built on the host and traversed in WGSL
//! (`shaders/shared/bvh.wgsl`).
use glam::Vec3;

/// Deepest level the builder creates; the WGSL traversal stack holds 64 entries.
pub const MAX_DEPTH: usize = 60;
const BINS: usize = 16;
const MAX_LEAF: usize = 1;

/// A node, mirrored by `BvhNode` in shaders/shared/types.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct BvhNode {
    /// Box minimum.
    pub bmin: [f32; 3],
    /// First triangle (leaf) or left child (inner; the right child follows it).
    pub left_first: u32,
    /// Box maximum.
    pub bmax: [f32; 3],
    /// Triangle count; 0 for inner nodes.
    pub count: u32,
}

/// The hierarchy and the triangle order it expects.
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    /// Nodes, root first.
    pub nodes: Vec<BvhNode>,
    /// `order[k]` is the input triangle stored at position k.
    pub order: Vec<u32>,
}

#[derive(Clone, Copy)]
struct Aabb {
    lo: Vec3,
    hi: Vec3,
}

impl Aabb {
    const EMPTY: Aabb = Aabb {
        lo: Vec3::splat(f32::INFINITY),
        hi: Vec3::splat(f32::NEG_INFINITY),
    };
    fn grow(&mut self, p: Vec3) {
        self.lo = self.lo.min(p);
        self.hi = self.hi.max(p);
    }
    fn union(&mut self, o: &Aabb) {
        self.lo = self.lo.min(o.lo);
        self.hi = self.hi.max(o.hi);
    }
    fn area(&self) -> f32 {
        let d = (self.hi - self.lo).max(Vec3::ZERO);
        2.0 * (d.x * d.y + d.y * d.z + d.z * d.x)
    }
}

/// Build over triangles given by their three vertices.
pub fn build(tris: &[[Vec3; 3]]) -> Bvh {
    let n = tris.len();
    if n == 0 {
        return Bvh::default();
    }
    let boxes: Vec<Aabb> = tris
        .iter()
        .map(|t| {
            let mut b = Aabb::EMPTY;
            t.iter().for_each(|p| b.grow(*p));
            b
        })
        .collect();
    let centroids: Vec<Vec3> = boxes.iter().map(|b| 0.5 * (b.lo + b.hi)).collect();
    let mut order: Vec<u32> = (0..n as u32).collect();
    let mut nodes = vec![BvhNode::default()];
    // (node, first, count, depth)
    let mut work = vec![(0usize, 0usize, n, 0usize)];
    while let Some((node, first, count, depth)) = work.pop() {
        let items = &mut order[first..first + count];
        let mut bounds = Aabb::EMPTY;
        let mut cbounds = Aabb::EMPTY;
        for &i in items.iter() {
            bounds.union(&boxes[i as usize]);
            cbounds.grow(centroids[i as usize]);
        }
        nodes[node].bmin = bounds.lo.to_array();
        nodes[node].bmax = bounds.hi.to_array();
        let make_leaf = |nodes: &mut Vec<BvhNode>| {
            nodes[node].left_first = first as u32;
            nodes[node].count = count as u32;
        };
        let extent = cbounds.hi - cbounds.lo;
        if count <= 1 || depth >= MAX_DEPTH || extent.max_element() <= 0.0 {
            make_leaf(&mut nodes);
            continue;
        }
        // Binned SAH over the three axes.
        let mut best = (f32::INFINITY, 0usize, 0usize); // cost, axis, split bin
        for axis in 0..3 {
            if extent[axis] <= 0.0 {
                continue;
            }
            let scale = BINS as f32 / extent[axis];
            let mut bin_box = [Aabb::EMPTY; BINS];
            let mut bin_n = [0usize; BINS];
            for &i in items.iter() {
                let b = (((centroids[i as usize][axis] - cbounds.lo[axis]) * scale) as usize)
                    .min(BINS - 1);
                bin_box[b].union(&boxes[i as usize]);
                bin_n[b] += 1;
            }
            let mut right_area = [0f32; BINS];
            let mut right_n = [0usize; BINS];
            let mut acc = Aabb::EMPTY;
            let mut accn = 0;
            for b in (1..BINS).rev() {
                acc.union(&bin_box[b]);
                accn += bin_n[b];
                right_area[b] = acc.area();
                right_n[b] = accn;
            }
            let mut acc = Aabb::EMPTY;
            let mut accn = 0;
            for b in 1..BINS {
                acc.union(&bin_box[b - 1]);
                accn += bin_n[b - 1];
                if accn == 0 || right_n[b] == 0 {
                    continue;
                }
                let cost = acc.area() * accn as f32 + right_area[b] * right_n[b] as f32;
                if cost < best.0 {
                    best = (cost, axis, b);
                }
            }
        }
        let leaf_cost = bounds.area() * count as f32;
        if !best.0.is_finite() || (best.0 >= leaf_cost && count <= MAX_LEAF) {
            make_leaf(&mut nodes);
            continue;
        }
        let (_, axis, split) = best;
        let scale = BINS as f32 / extent[axis];
        let lo = cbounds.lo[axis];
        let bin_of = |i: u32| (((centroids[i as usize][axis] - lo) * scale) as usize).min(BINS - 1);
        // Partition in place.
        let mut l = 0;
        let mut r = count;
        while l < r {
            if bin_of(items[l]) < split {
                l += 1;
            } else {
                r -= 1;
                items.swap(l, r);
            }
        }
        if l == 0 || l == count {
            make_leaf(&mut nodes);
            continue;
        }
        let left = nodes.len();
        nodes.push(BvhNode::default());
        nodes.push(BvhNode::default());
        nodes[node].left_first = left as u32;
        nodes[node].count = 0;
        work.push((left, first, l, depth + 1));
        work.push((left + 1, first + l, count - l, depth + 1));
    }
    Bvh { nodes, order }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_triangle_is_in_exactly_one_leaf_inside_its_box() {
        let mut tris = Vec::new();
        let mut s = 1u32;
        let mut r = || {
            s = s.wrapping_mul(1664525).wrapping_add(1013904223);
            (s >> 8) as f32 / (1u32 << 24) as f32
        };
        for _ in 0..2000 {
            let c = Vec3::new(r(), r(), r()) * 10.0;
            tris.push([
                c,
                c + Vec3::new(r(), 0.0, r()),
                c + Vec3::new(0.0, r(), r()),
            ]);
        }
        let bvh = build(&tris);
        let mut seen = vec![0; tris.len()];
        let mut stack = vec![(0usize, 0usize)];
        let mut max_depth = 0;
        while let Some((i, depth)) = stack.pop() {
            max_depth = max_depth.max(depth);
            let n = bvh.nodes[i];
            if n.count > 0 {
                for k in n.left_first..n.left_first + n.count {
                    let t = bvh.order[k as usize] as usize;
                    seen[t] += 1;
                    for p in tris[t] {
                        for a in 0..3 {
                            assert!(p[a] >= n.bmin[a] && p[a] <= n.bmax[a]);
                        }
                    }
                }
            } else {
                stack.push((n.left_first as usize, depth + 1));
                stack.push((n.left_first as usize + 1, depth + 1));
            }
        }
        assert!(seen.iter().all(|&c| c == 1));
        assert!(max_depth <= MAX_DEPTH);
        assert!(max_depth < 40, "SAH tree unexpectedly deep: {max_depth}");
    }
}
