//! An 8-wide BVH for single-ray queries on the CPU: each node holds the
//! boxes of up to eight children as rows of eight floats per axis and side,
//! so that a ray meets all eight in a few vector instructions, and each leaf
//! holds up to eight triangles the same way ([`Block`]), met all at once
//! too: the layout of Embree's BVH8 and Triangle8 leaves (Wald et al. 2014,
//! "Embree: a kernel framework for efficient CPU ray tracing", §4). The
//! tree is collapsed from the binary BVH that obvhs builds (PLOC with
//! reinsertion): a node's children are found by opening its largest-area
//! inner child until there are eight (Wald, Benthin and Boulos 2008,
//! "Getting rid of packets", §3).

use std::time::Duration;

use glam::Vec3A;
use obvhs::{
    BvhBuildParams,
    bvh2::{Bvh2, builder::build_bvh2_from_tris},
    triangle::Triangle,
};

use super::lanes::{self, Kernel, LANES, Lanes, Ray, Row, Stack};
use crate::{Error, Result};

/// A child slot that holds nothing.
const EMPTY: u32 = u32::MAX;
/// The bit that marks a child slot as a leaf; the rest is its block's index.
const LEAF: u32 = 1 << 31;

/// The boxes of up to eight children, per axis and side, and what each
/// child is: an inner node's index, a leaf's block with [`LEAF`] set, or
/// [`EMPTY`] with an empty box (+∞ below, −∞ above), which no ray meets.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub struct Node {
    pub lo: [Row; 3],
    pub hi: [Row; 3],
    child: [u32; LANES],
}

impl Node {
    const EMPTY: Node = Node {
        lo: [[f32::INFINITY; LANES]; 3],
        hi: [[f32::NEG_INFINITY; LANES]; 3],
        child: [EMPTY; LANES],
    };
}

/// Up to eight triangles of one leaf, as Möller and Trumbore's test reads
/// them (v0, e1 = v0 − v1, e2 = v2 − v0, ng = e1 × e2), a row per
/// coordinate. Unused lanes are zero: their determinant is zero and they
/// never hit.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub struct Block {
    pub v0: [Row; 3],
    pub e1: [Row; 3],
    pub e2: [Row; 3],
    pub ng: [Row; 3],
}

impl Block {
    const EMPTY: Block = Block {
        v0: [[0.0; LANES]; 3],
        e1: [[0.0; LANES]; 3],
        e2: [[0.0; LANES]; 3],
        ng: [[0.0; LANES]; 3],
    };

    fn set(&mut self, lane: usize, tri: &Triangle) {
        let (e1, e2) = (tri.v0 - tri.v1, tri.v2 - tri.v0);
        let ng = e1.cross(e2);
        for a in 0..3 {
            self.v0[a][lane] = tri.v0[a];
            self.e1[a][lane] = e1[a];
            self.e2[a][lane] = e2[a];
            self.ng[a][lane] = ng[a];
        }
    }
}

/// The tree: nodes (the root first), leaf blocks, and which input triangle
/// each block's lane holds.
pub struct WideBvh {
    nodes: Vec<Node>,
    blocks: Vec<Block>,
    /// `primitives[b][lane]`: the input index of block b's triangle in that
    /// lane (`u32::MAX` where the lane is empty).
    primitives: Vec<[u32; LANES]>,
    /// Whether the CPU runs the AVX2 + FMA lanes ([`super::lanes`]).
    avx2: bool,
}

/// What a leaf visitor tells the traversal.
pub enum Visit {
    /// Stop: the query has its answer.
    Stop,
    /// Go on, with hits beyond this distance no longer wanted.
    Continue(f32),
}

impl WideBvh {
    /// The deepest tree the traversal's fixed stack serves.
    pub const MAX_DEPTH: usize = 96;
    /// Entries of the traversal stack: a node pushes at most seven of its
    /// children, so a tree [`WideBvh::MAX_DEPTH`] deep never needs more.
    const STACK: usize = 7 * WideBvh::MAX_DEPTH + 1;

    /// Builds the tree of `triangles` (not empty), from obvhs's
    /// `medium_build` binary tree with leaves of up to eight triangles and
    /// a collapse traversal cost of 6. On the 35k bunny's ambient-occlusion
    /// rays (Intel Xeon, AVX-512, 2 threads) that traced 11.4 M rays/s;
    /// `slow_build` and `very_slow_build` no more (11.3, 11.6) for builds
    /// 2× and 4× as long (0.03 s here), leaves of four 10.4, and a
    /// collapse cost of 3 (obvhs's default) 11.0.
    pub fn build(triangles: &[Triangle]) -> Result<WideBvh> {
        let params = BvhBuildParams {
            max_prims_per_leaf: LANES as u32,
            collapse_traversal_cost: 6.0,
            ..BvhBuildParams::medium_build()
        };
        let binary = build_bvh2_from_tris(triangles, params, &mut Duration::default());
        let mut tree = WideBvh {
            nodes: vec![Node::EMPTY],
            blocks: Vec::new(),
            primitives: Vec::new(),
            avx2: super::lanes::avx2(),
        };
        let root = &binary.nodes[0];
        let depth = if root.prim_count > 0 {
            tree.fill(&binary, triangles, 0, &[0], 1)
        } else {
            let first = root.first_index as usize;
            tree.fill(&binary, triangles, 0, &[first, first + 1], 1)
        };
        if depth > WideBvh::MAX_DEPTH {
            return Err(Error::InvalidScene(format!(
                "the scene's BVH is {depth} levels deep, more than the {} it can trace",
                WideBvh::MAX_DEPTH
            )));
        }
        Ok(tree)
    }

    /// Fills node `at` with the binary nodes `start` opened up to eight
    /// children, and its inner children in turn; returns the depth reached.
    fn fill(
        &mut self,
        binary: &Bvh2,
        triangles: &[Triangle],
        at: usize,
        start: &[usize],
        depth: usize,
    ) -> usize {
        let nodes = &binary.nodes;
        let mut children = start.to_vec();
        while children.len() < LANES {
            let largest = children
                .iter()
                .enumerate()
                .filter(|(_, c)| nodes[**c].prim_count == 0)
                .max_by(|a, b| {
                    let area = |i: usize| nodes[i].aabb.half_area();
                    area(*a.1).total_cmp(&area(*b.1))
                });
            let Some((slot, &inner)) = largest else { break };
            let first = nodes[inner].first_index as usize;
            children[slot] = first;
            children.push(first + 1);
        }
        let mut deepest = depth;
        for (slot, &c) in children.iter().enumerate() {
            let child = &nodes[c];
            for a in 0..3 {
                self.nodes[at].lo[a][slot] = child.aabb.min[a];
                self.nodes[at].hi[a][slot] = child.aabb.max[a];
            }
            if child.prim_count > 0 {
                let mut block = Block::EMPTY;
                let mut ids = [u32::MAX; LANES];
                let first = child.first_index as usize;
                let count = child.prim_count as usize;
                for (lane, &p) in binary.primitive_indices[first..first + count]
                    .iter()
                    .enumerate()
                {
                    block.set(lane, &triangles[p as usize]);
                    ids[lane] = p;
                }
                self.nodes[at].child[slot] = LEAF | self.blocks.len() as u32;
                self.blocks.push(block);
                self.primitives.push(ids);
            } else {
                let index = self.nodes.len();
                self.nodes.push(Node::EMPTY);
                self.nodes[at].child[slot] = index as u32;
                let first = child.first_index as usize;
                let reached = self.fill(binary, triangles, index, &[first, first + 1], depth + 1);
                deepest = deepest.max(reached);
            }
        }
        deepest
    }

    /// The input index of the triangle in `lane` of block `block`.
    #[inline]
    pub fn primitive(&self, block: u32, lane: usize) -> u32 {
        self.primitives[block as usize][lane]
    }

    /// The vertices of the triangle in `lane` of block `block`.
    pub fn vertices(&self, block: u32, lane: usize) -> [Vec3A; 3] {
        let b = &self.blocks[block as usize];
        let row = |rows: &[Row; 3]| Vec3A::new(rows[0][lane], rows[1][lane], rows[2][lane]);
        let (v0, e1, e2) = (row(&b.v0), row(&b.e1), row(&b.e2));
        [v0, v0 - e1, v0 + e2]
    }

    /// `e1 × e2` of the triangle in `lane` of block `block`: the opposite of
    /// its counter-clockwise normal, unnormalized.
    #[inline]
    pub fn reversed_normal(&self, block: u32, lane: usize) -> Vec3A {
        let b = &self.blocks[block as usize];
        Vec3A::new(b.ng[0][lane], b.ng[1][lane], b.ng[2][lane])
    }

    /// Walks every leaf whose box `ray` meets within `t_max`, handing
    /// `visit` the block's index, the mask of its lanes hit within the
    /// current limit and their distances; the visitor stops the walk or
    /// narrows the limit. Nodes are visited in no particular order.
    #[inline]
    pub fn walk<F: FnMut(u32, u32, &Row) -> Visit>(&self, ray: &Ray, t_max: f32, visit: F) {
        struct Walk<'a, F> {
            tree: &'a WideBvh,
            ray: &'a Ray,
            t_max: f32,
            visit: F,
        }
        impl<F: FnMut(u32, u32, &Row) -> Visit> Kernel for Walk<'_, F> {
            type Output = ();
            #[inline(always)]
            fn run<L: Lanes>(self) {
                self.tree.walk_with::<L>(self.ray, self.t_max, self.visit)
            }
        }
        let walk = Walk {
            tree: self,
            ray,
            t_max,
            visit,
        };
        lanes::run(self.avx2, walk)
    }

    #[inline(always)]
    fn walk_with<L: Lanes>(
        &self,
        ray: &Ray,
        mut t_max: f32,
        mut visit: impl FnMut(u32, u32, &Row) -> Visit,
    ) {
        let mut stack = Stack::<{ WideBvh::STACK }>::new(0);
        while let Some(index) = stack.pop() {
            let node = &self.nodes[index as usize];
            let mut hits = L::boxes(node, ray, t_max);
            while hits != 0 {
                let slot = hits.trailing_zeros() as usize;
                hits &= hits - 1;
                let child = node.child[slot];
                if child & LEAF == 0 {
                    stack.push(child);
                    continue;
                }
                let block = child & !LEAF;
                let (lanes, t) = L::triangles(&self.blocks[block as usize], ray, t_max);
                if lanes != 0 {
                    match visit(block, lanes, &t) {
                        Visit::Stop => return,
                        Visit::Continue(limit) => t_max = limit,
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3A;

    fn soup(n: usize) -> Vec<Triangle> {
        let mut state = 0x2545f4914f6cdd1du64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        (0..n)
            .map(|_| {
                let c = Vec3A::new(next(), next(), next()) * 1000.0;
                let mut corner = || c + Vec3A::new(next(), next(), next()) * 80.0;
                Triangle {
                    v0: corner(),
                    v1: corner(),
                    v2: corner(),
                }
            })
            .collect()
    }

    /// Every leaf visit of a walk: block, lanes, distances.
    fn visits<L: Lanes>(tree: &WideBvh, ray: &Ray) -> Vec<(u32, u32, Row)> {
        let mut seen = Vec::new();
        tree.walk_with::<L>(ray, f32::INFINITY, |block, lanes, t| {
            seen.push((block, lanes, *t));
            Visit::Continue(f32::INFINITY)
        });
        seen
    }

    #[test]
    fn every_triangle_sits_in_a_leaf() {
        let triangles = soup(5000);
        let tree = WideBvh::build(&triangles).unwrap();
        let mut seen = vec![false; triangles.len()];
        for ids in &tree.primitives {
            for &p in ids.iter().filter(|&&p| p != u32::MAX) {
                seen[p as usize] = true;
            }
        }
        assert!(seen.iter().all(|&s| s));
    }

    /// The AVX2 lanes and the portable ones visit the same leaves in the
    /// same order and find the same hits at the same distances, bit for
    /// bit.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn both_lane_paths_agree_bit_for_bit() {
        let triangles = soup(5000);
        let tree = WideBvh::build(&triangles).unwrap();
        assert!(
            lanes::avx2(),
            "this x86-64 CPU has no AVX2 + FMA: the AVX2 lanes cannot be compared here"
        );
        let mut hits = 0;
        for i in 0..3000 {
            let a = i as f32 * 0.618;
            let b = i as f32 * 0.377;
            let origin = Vec3A::new(a.sin(), (a * 1.3).cos(), b.sin()) * 1200.0;
            let dir = Vec3A::new((b * 2.1).cos(), a.cos(), (a + b).sin()).normalize();
            let ray = Ray::new(origin, dir);
            let portable = visits::<lanes::Portable>(&tree, &ray);
            struct Avx2Visits<'a>(&'a WideBvh, &'a Ray);
            impl Kernel for Avx2Visits<'_> {
                type Output = Vec<(u32, u32, Row)>;
                #[inline(always)]
                fn run<L: Lanes>(self) -> Self::Output {
                    visits::<L>(self.0, self.1)
                }
            }
            let avx2 = lanes::run(true, Avx2Visits(&tree, &ray));
            assert_eq!(portable.len(), avx2.len(), "ray {i}");
            for (p, v) in portable.iter().zip(&avx2) {
                assert_eq!((p.0, p.1), (v.0, v.1), "ray {i}");
                for lane in (0..LANES).filter(|l| p.1 >> l & 1 == 1) {
                    assert_eq!(p.2[lane].to_bits(), v.2[lane].to_bits(), "ray {i}");
                }
            }
            hits += portable.iter().filter(|v| v.1 != 0).count();
        }
        assert!(hits > 100, "{hits}");
    }
}
