//! The node hierarchy: each node's local transform and its parent, composed
//! into world matrices parents-first (glTF 2.0 §3.5.2: a node's global
//! transform is its parent's global transform times its local one).

use std::path::Path;

use glam::{Mat4, Quat, Vec3, Vec4};
use shadow_core::{Error, Result};

/// A node's transform in its parent's space.
#[derive(Clone, Copy, Debug)]
pub(super) enum Local {
    /// Given as a matrix: glTF forbids animating such nodes (§3.11.1).
    Matrix(Mat4),
    Trs(Trs),
}

/// Translation, rotation, scale: M = T · R · S.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Trs {
    pub translation: Vec3,
    pub rotation: Quat,
    pub scale: Vec3,
}

impl Local {
    pub fn matrix(&self) -> Mat4 {
        match self {
            Local::Matrix(m) => *m,
            Local::Trs(t) => {
                Mat4::from_scale_rotation_translation(t.scale, t.rotation, t.translation)
            }
        }
    }
}

/// Parents and rest transforms of every node, with an order in which each
/// node comes after its parent.
pub(super) struct Hierarchy {
    parents: Vec<Option<usize>>,
    order: Vec<usize>,
    rest: Vec<Local>,
}

impl Hierarchy {
    /// Reads the nodes, rejecting what glTF 2.0 §3.5.1 forbids and a world
    /// matrix cannot be built from: a node with two parents, a cycle, a
    /// non-affine or non-finite matrix, a zero rotation quaternion.
    pub fn new(path: &Path, document: &::gltf::Document) -> Result<Hierarchy> {
        let count = document.nodes().len();
        let bad = |what: String| Error::format(path, what);
        let mut parents = vec![None; count];
        let mut children = vec![Vec::new(); count];
        for node in document.nodes() {
            for child in node.children() {
                children[node.index()].push(child.index());
                if let Some(other) = parents[child.index()].replace(node.index()) {
                    return Err(bad(format!(
                        "node {} is a child of both node {other} and node {}",
                        child.index(),
                        node.index()
                    )));
                }
            }
        }
        let mut order = Vec::with_capacity(count);
        let mut stack: Vec<usize> = (0..count).filter(|&n| parents[n].is_none()).collect();
        while let Some(n) = stack.pop() {
            order.push(n);
            stack.extend(&children[n]);
        }
        if order.len() != count {
            let mut reached = vec![false; count];
            for &n in &order {
                reached[n] = true;
            }
            let first = reached.iter().position(|r| !r).unwrap_or(0);
            return Err(bad(format!(
                "the node hierarchy has a cycle through node {first}"
            )));
        }

        let rest = document
            .nodes()
            .map(|node| {
                local_transform(&node).map_err(|what| {
                    bad(format!(
                        "{}: {what}",
                        super::named("node", node.index(), node.name())
                    ))
                })
            })
            .collect::<Result<_>>()?;
        Ok(Hierarchy {
            parents,
            order,
            rest,
        })
    }

    /// The rest (unanimated) local transforms, one per node.
    pub fn rest(&self) -> &[Local] {
        &self.rest
    }

    /// World matrices of every node from the given local transforms.
    pub fn world(&self, locals: &[Local]) -> Vec<Mat4> {
        let mut world = vec![Mat4::IDENTITY; self.parents.len()];
        for &n in &self.order {
            let local = locals[n].matrix();
            world[n] = match self.parents[n] {
                Some(p) => world[p] * local,
                None => local,
            };
        }
        world
    }
}

fn local_transform(node: &::gltf::Node) -> std::result::Result<Local, String> {
    match node.transform() {
        ::gltf::scene::Transform::Matrix { matrix } => {
            let m = Mat4::from_cols_array_2d(&matrix);
            if !m.is_finite() {
                return Err("matrix is not finite".into());
            }
            if (m.row(3) - Vec4::W).abs().max_element() > 1e-6 {
                return Err(format!("matrix is not affine (last row {})", m.row(3)));
            }
            Ok(Local::Matrix(m))
        }
        ::gltf::scene::Transform::Decomposed {
            translation,
            rotation,
            scale,
        } => {
            let rotation = Quat::from_array(rotation);
            let (translation, scale) = (Vec3::from_array(translation), Vec3::from_array(scale));
            if !(translation.is_finite() && rotation.is_finite() && scale.is_finite()) {
                return Err("translation, rotation or scale is not finite".into());
            }
            let rotation = unit_rotation(rotation).ok_or("rotation quaternion is zero")?;
            Ok(Local::Trs(Trs {
                translation,
                rotation,
                scale,
            }))
        }
    }
}

/// A unit quaternion, or `None` for a zero one. Exporters write quaternions
/// rounded to a few digits; glTF requires unit ones, and the sampled and
/// interpolated ones drift.
pub(super) fn unit_rotation(q: Quat) -> Option<Quat> {
    let length = q.length();
    (length.is_finite() && length > 1e-6).then(|| q / length)
}
