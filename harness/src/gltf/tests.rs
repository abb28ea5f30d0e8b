//! Tests on the project's real assets (see assets/README.md for their
//! provenance and quirks) and on tiny files written here to isolate one rule.

use std::f32::consts::FRAC_PI_2;

use approx::assert_relative_eq;
use glam::{Affine3A, Quat, Vec3};
use serde_json::{Value, json};
use shadow_core::{Aabb, Camera, Scene};

use super::instance::Motion;
use super::*;

fn asset(name: &str) -> GltfAsset {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../assets/meshes")
        .join(name);
    GltfAsset::load(&path).unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn lambert() -> Brdf {
    Brdf::lambert(Vec3::splat(0.8)).unwrap()
}

fn deformed(pose: &Pose) -> &[Vec3] {
    match pose {
        Pose::Deformed { positions, .. } => positions,
        Pose::Rigid(_) => panic!("expected a deformed pose"),
    }
}

/// World-space positions of object `o` in `poses`.
fn world_positions(asset: &GltfAsset, poses: &[Pose], o: usize) -> Vec<Vec3> {
    let mesh = &asset.instances[o].mesh;
    match &poses[o] {
        Pose::Rigid(t) => mesh
            .positions()
            .iter()
            .map(|p| t.transform_point3(*p))
            .collect(),
        Pose::Deformed { positions, .. } => positions.to_vec(),
    }
}

fn bounds_at(asset: &GltfAsset, time: f32) -> Aabb {
    let poses = asset.pose_at(time).unwrap();
    (0..poses.len())
        .flat_map(|o| world_positions(asset, &poses, o))
        .fold(Aabb::EMPTY, Aabb::grow)
}

#[test]
fn npm_bunny_is_closed_with_its_published_counts() {
    let bunny = asset("bunny_npm_1839v.glb");
    let mesh = bunny.meshes().next().unwrap();
    assert_eq!((mesh.vertex_count(), mesh.triangle_count()), (1839, 3674));
    assert!(mesh.is_closed());
    assert!(!bunny.is_animated());
    let poses = bunny.pose_at(0.0).unwrap();
    assert!(matches!(poses[..], [Pose::Rigid(t)] if t == Affine3A::IDENTITY));
}

#[test]
fn stanford_bunny_has_its_published_counts_and_holes() {
    let bunny = asset("bunny_stanford_bun_zipper.glb");
    assert_eq!(bunny.report().objects, 1);
    let mesh = bunny.meshes().next().unwrap();
    assert_eq!(
        (mesh.vertex_count(), mesh.triangle_count()),
        (34_834, 69_451)
    );
    // The original scan's holes (assets/README.md).
    assert_eq!(mesh.boundary_edge_count(), 223);
}

#[test]
fn every_static_asset_loads_with_its_published_counts() {
    // assets/README.md: vertices / triangles.
    for (name, vertices, triangles) in [
        ("teapot_npm_792v.glb", 792, 992),
        ("pmndrs_suzi_7503v.glb", 7503, 14_842),
        ("dragon_vrip_res4.glb", 5205, 11_102),
        ("dragon_vrip_res3.glb", 22_998, 47_794),
    ] {
        let asset = asset(name);
        let mesh = asset.meshes().next().unwrap();
        assert_eq!(
            (mesh.vertex_count(), mesh.triangle_count()),
            (vertices, triangles),
            "{name}"
        );
        assert!(
            matches!(asset.pose_at(0.0).unwrap()[..], [Pose::Rigid(_)]),
            "{name}"
        );
    }
}

const HUMAN: &str = "BCN_Epileptic_skinned_animated.glb";

/// Per-vertex distance from the skinned position to the origin of the joint
/// that weighs most on it, at `time`; with `node_transform_too`, the skinned
/// mesh node's own world transform is (wrongly) applied on top.
fn distances_to_joints(
    human: &GltfAsset,
    o: usize,
    time: f32,
    node_transform_too: bool,
) -> Vec<f32> {
    let (world, _) = human.world_at(time);
    let poses = human.pose_at(time).unwrap();
    let instance = &human.instances[o];
    let Motion::Skinned { skin, .. } = &instance.motion else {
        panic!("{} is not skinned", instance.label)
    };
    let extra = if node_transform_too {
        world[instance.node]
    } else {
        Mat4::IDENTITY
    };
    let mut d: Vec<f32> = deformed(&poses[o])
        .iter()
        .enumerate()
        .map(|(v, p)| {
            (world[skin.dominant_joint(v)].w_axis.truncate() - extra.transform_point3(*p)).length()
        })
        .collect();
    d.sort_by(f32::total_cmp);
    d
}

#[test]
fn skinned_rest_pose_is_the_bind_pose() {
    // The human's skeleton at rest is its bind pose (joint world × inverse
    // bind = identity), so with the spec's rule the skinned rest pose is the
    // mesh exactly as stored. Its skinned mesh nodes carry a −90° rotation
    // about X (and the head an extra 0.5 m lift): applying those on top of the
    // joints, the common mistake, would tip the figure over.
    let mut human = asset(HUMAN);
    assert_eq!(human.report().skinned_objects, 3);
    assert_eq!(human.report().renormalized_weights, 0);
    human.select_animation(AnimationChoice::None).unwrap();
    let poses = human.pose_at(0.0).unwrap();
    let (world, _) = human.world_at(0.0);
    for (o, instance) in human.instances.iter().enumerate() {
        let skinned = deformed(&poses[o]);
        let node = Affine3A::from_mat4(world[instance.node]);
        let mut largest_node_shift = 0.0f32;
        for (p, bind) in skinned.iter().zip(instance.mesh.positions()) {
            assert!(
                (*p - *bind).length() < 1e-4,
                "{}: {p} vs bind {bind}",
                instance.label
            );
            largest_node_shift = largest_node_shift.max((node.transform_point3(*p) - *p).length());
        }
        assert!(
            largest_node_shift > 0.2,
            "{}: the node transform is not a real test",
            instance.label
        );
    }
}

#[test]
fn skinned_meshes_stay_on_their_joints_while_animating() {
    let human = asset(HUMAN);
    for time in [0.0, 1.5] {
        for o in 0..human.instances.len() {
            let label = &human.instances[o].label;
            let spec = distances_to_joints(&human, o, time, false);
            let doubled = distances_to_joints(&human, o, time, true);
            let (median, wrong) = (spec[spec.len() / 2], doubled[doubled.len() / 2]);
            // Body parts lie within a limb's thickness of their bone; applying
            // the node transform too puts them tens of centimetres off.
            assert!(
                median < 0.15,
                "{label} at {time}s: median {median} m from its joints"
            );
            assert!(
                wrong > 2.5 * median,
                "{label} at {time}s: {wrong} vs {median}"
            );
        }
    }
}

#[test]
fn skinned_human_animates_plausibly() {
    let human = asset(HUMAN);
    assert_relative_eq!(human.duration(), 3.3, epsilon = 1e-3);
    assert_eq!(human.animation_names().len(), 1);
    let start = human.pose_at(0.0).unwrap();
    let middle = human.pose_at(1.5).unwrap();
    let moved = (0..start.len())
        .flat_map(|o| {
            deformed(&start[o])
                .iter()
                .zip(deformed(&middle[o]))
                .map(|(a, b)| (*a - *b).length())
                .collect::<Vec<_>>()
        })
        .fold(0.0f32, f32::max);
    assert!(moved > 0.3, "largest vertex motion {moved} m");

    // Skinned normals (inverse transpose of the blended matrices) agree with
    // the posed surface's own area-weighted normals almost as well as the
    // file's normals agree with the bind pose's (linear blending shears the
    // surface near joints); the unskinned normals would not.
    let agreement = |o: usize, positions: &Arc<[Vec3]>, normals: &[Vec3]| {
        let surface = human.instances[o]
            .mesh
            .with_pose(positions.to_vec(), None)
            .unwrap();
        let agree = normals
            .iter()
            .zip(surface.normals())
            .filter(|(n, s)| n.dot(**s) > 0.7)
            .count();
        agree as f32 / normals.len() as f32
    };
    for (o, instance) in human.instances.iter().enumerate() {
        let Pose::Deformed {
            positions,
            normals: Some(normals),
        } = &middle[o]
        else {
            panic!("skinned poses carry skinned normals")
        };
        let at_bind = agreement(
            o,
            &instance.mesh.positions().into(),
            instance.mesh.normals(),
        );
        let skinned = agreement(o, positions, normals);
        let unskinned = agreement(o, positions, instance.mesh.normals());
        assert!(
            at_bind > 0.95 && skinned > 0.9,
            "{}: {skinned} ({at_bind} at bind)",
            instance.label
        );
        assert!(
            unskinned < 0.8,
            "{}: the pose does not turn normals ({unskinned})",
            instance.label
        );
    }

    let rest_height = human
        .meshes()
        .map(|m| m.bounds())
        .fold(Aabb::EMPTY, Aabb::union)
        .extent()
        .y;
    assert!(
        (1.5..2.1).contains(&rest_height),
        "a human is {rest_height} m tall"
    );
    let (objects, frames) = human.to_scene_parts(lambert(), 30.0, 1000).unwrap();
    assert_eq!(frames.len(), 100, "3.3 s at 30 fps, both ends included");
    for frame in &frames {
        let mut bounds = Aabb::EMPTY;
        for pose in &frame.poses {
            let Pose::Deformed {
                positions,
                normals: Some(normals),
            } = pose
            else {
                panic!("skinned poses carry skinned normals")
            };
            assert!(positions.iter().all(|p| p.is_finite()));
            assert!(normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-4));
            bounds = positions.iter().copied().fold(bounds, Aabb::grow);
        }
        let ratio = bounds.extent().y / rest_height;
        assert!(
            (0.5..2.0).contains(&ratio),
            "t = {}: height ratio {ratio}",
            frame.time
        );
    }
    let camera = Camera::new(Vec3::new(0.0, 1.0, 4.0), Vec3::ZERO, Vec3::Y, 0.8, 8, 8).unwrap();
    let scene = Scene::new("human", objects, frames, camera).unwrap();
    assert!(scene.deforms());
    scene.frame_geometry(45).unwrap();
    assert_eq!(human.to_scene_parts(lambert(), 30.0, 7).unwrap().1.len(), 7);
}

#[test]
fn simple_skin_bends_only_above_its_joint() {
    // Two joints at (0, 1, 0); inverse bind matrices translate by (−0.5, −1, 0),
    // so the strip sits at x ∈ [−0.5, 0.5]. At t = 1 s the upper joint has
    // turned 90° about Z: vertices 0 and 1 (all weight on the lower joint)
    // stay, vertices 8 and 9 (all on the upper one) swing about (0, 1, 0).
    let skin = asset("simple_skin.gltf");
    let rest = skin.pose_at(0.0).unwrap();
    let bent = skin.pose_at(1.0).unwrap();
    let (rest, bent) = (deformed(&rest[0]), deformed(&bent[0]));
    for v in [0, 1] {
        assert_relative_eq!(bent[v], rest[v], epsilon = 1e-6);
    }
    let pivot = Vec3::Y;
    for v in [8, 9] {
        let expected = pivot + Quat::from_rotation_z(FRAC_PI_2) * (rest[v] - pivot);
        assert_relative_eq!(bent[v], expected, epsilon = 1e-3);
    }
    assert_relative_eq!(rest[8], Vec3::new(-0.5, 2.0, 0.0), epsilon = 1e-6);
    // Halfway through the first key interval the slerp is at 22.5°.
    let quarter = skin.pose_at(0.25).unwrap();
    let expected = pivot + Quat::from_rotation_z(FRAC_PI_2 / 4.0) * (rest[9] - pivot);
    assert_relative_eq!(deformed(&quarter[0])[9], expected, epsilon = 1e-3);
}

#[test]
fn morph_cube_moves_by_weighted_target_deltas() {
    // The expected shape is computed from the file through the gltf crate's own
    // readers, independently of this module's accessor code.
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/meshes/AnimatedMorphCube.gltf");
    let (document, buffers, _) = ::gltf::import(&path).unwrap();
    let get = |b: ::gltf::Buffer| buffers.get(b.index()).map(|d| d.0.as_slice());
    let primitive = document
        .meshes()
        .next()
        .unwrap()
        .primitives()
        .next()
        .unwrap();
    let reader = primitive.reader(get);
    let base: Vec<Vec3> = reader.read_positions().unwrap().map(Vec3::from).collect();
    let deltas: Vec<Vec<Vec3>> = reader
        .read_morph_targets()
        .map(|(p, _, _)| p.unwrap().map(Vec3::from).collect())
        .collect();
    let channel = document
        .animations()
        .next()
        .unwrap()
        .channels()
        .next()
        .unwrap();
    let times: Vec<f32> = channel.reader(get).read_inputs().unwrap().collect();
    let ::gltf::animation::util::ReadOutputs::MorphTargetWeights(w) =
        channel.reader(get).read_outputs().unwrap()
    else {
        panic!("weights channel")
    };
    let weights: Vec<f32> = w.into_f32().collect();
    let node = Mat4::from_cols_array_2d(&document.nodes().next().unwrap().transform().matrix());

    let cube = asset("AnimatedMorphCube.gltf");
    assert_eq!(cube.report().morphed_objects, 1);
    let base_world = world_positions(&cube, &cube.pose_at(0.0).unwrap(), 0);
    for (b, expected) in base_world.iter().zip(&base) {
        assert_relative_eq!(*b, node.transform_point3(*expected), epsilon = 1e-5);
    }
    let k = 75;
    let mid = 0.5 * (times[k] + times[k + 1]);
    for (time, w) in [
        (times[k], [weights[2 * k], weights[2 * k + 1]]),
        (
            mid,
            [
                0.5 * (weights[2 * k] + weights[2 * k + 2]),
                0.5 * (weights[2 * k + 1] + weights[2 * k + 3]),
            ],
        ),
    ] {
        assert!(w[0] > 0.1 && w[1] > 0.1, "both targets active at {time}");
        let got = world_positions(&cube, &cube.pose_at(time).unwrap(), 0);
        for v in 0..base.len() {
            let expected =
                node.transform_point3(base[v] + w[0] * deltas[0][v] + w[1] * deltas[1][v]);
            assert_relative_eq!(got[v], expected, epsilon = 1e-4);
        }
        assert!(
            got.iter()
                .zip(&base_world)
                .any(|(a, b)| (*a - *b).length() > 0.5)
        );
    }
}

#[test]
fn animation_is_chosen_by_name_or_index_or_turned_off() {
    let mut human = asset(HUMAN);
    assert!(
        human
            .select_animation(AnimationChoice::Name("no such clip"))
            .is_err()
    );
    assert!(human.select_animation(AnimationChoice::Index(1)).is_err());
    human.select_animation(AnimationChoice::None).unwrap();
    assert_eq!((human.is_animated(), human.duration()), (false, 0.0));
    assert_eq!(
        human.to_scene_parts(lambert(), 30.0, 100).unwrap().1.len(),
        1
    );
    let name = "Epileptisch";
    human.select_animation(AnimationChoice::Name(name)).unwrap();
    assert_eq!(human.selected_animation(), Some(0));
    assert!(bounds_at(&human, 1.5).extent().y < 0.9 * bounds_at(&human, 0.0).extent().y);
    // Clamped to the clip.
    assert_eq!(bounds_at(&human, 100.0), bounds_at(&human, 3.3));
    assert_eq!(bounds_at(&human, -1.0), bounds_at(&human, 0.0));
    assert!(human.pose_at(f32::NAN).is_err());
}

/// Builds tiny glTF files: one buffer, embedded as a base64 `data:` URI.
#[derive(Default)]
struct Tiny {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Tiny {
    fn add(&mut self, bytes: Vec<u8>, component_type: u32, ty: &str, count: usize) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend(&bytes);
        self.views
            .push(json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len()}));
        self.accessors.push(json!({
            "bufferView": self.views.len() - 1, "componentType": component_type, "type": ty, "count": count
        }));
        self.accessors.len() - 1
    }

    fn vec3s(&mut self, values: &[Vec3]) -> usize {
        let bytes = values
            .iter()
            .flat_map(|v| v.to_array())
            .flat_map(f32::to_le_bytes)
            .collect();
        let a = self.add(bytes, 5126, "VEC3", values.len());
        let bounds = Aabb::from_points(values.iter().copied());
        self.accessors[a]["min"] = json!(bounds.min.to_array());
        self.accessors[a]["max"] = json!(bounds.max.to_array());
        a
    }

    fn floats(&mut self, values: &[f32], ty: &str, per_element: usize) -> usize {
        let bytes = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.add(bytes, 5126, ty, values.len() / per_element)
    }

    fn u16s(&mut self, values: &[u16], ty: &str, per_element: usize) -> usize {
        let bytes = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.add(bytes, 5123, ty, values.len() / per_element)
    }

    /// The document: `rest` holds nodes, meshes, skins and so on.
    fn document(&self, mut rest: Value) -> Value {
        rest["asset"] = json!({"version": "2.0"});
        rest["buffers"] = json!([{
            "byteLength": self.bin.len(),
            "uri": format!("data:application/octet-stream;base64,{}", base64(&self.bin)),
        }]);
        rest["bufferViews"] = json!(self.views);
        rest["accessors"] = json!(self.accessors);
        rest
    }
}

fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let n = chunk
            .iter()
            .enumerate()
            .fold(0u32, |n, (i, &b)| n | (b as u32) << (16 - 8 * i));
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// A triangle in the z = 0 plane, counter-clockwise seen from +Z.
const TRIANGLE: [Vec3; 3] = [Vec3::ZERO, Vec3::X, Vec3::Y];

/// One node with one triangle mesh, the node's properties given by `node`.
fn triangle_file(indices: &[u16], node: Value) -> Value {
    let mut tiny = Tiny::default();
    let positions = tiny.vec3s(&TRIANGLE);
    let indices = tiny.u16s(indices, "SCALAR", 1);
    let mut node_json = json!({"mesh": 0, "name": "tri node"});
    for (k, v) in node.as_object().unwrap() {
        node_json[k] = v.clone();
    }
    tiny.document(json!({
        "scenes": [{"nodes": [0]}],
        "nodes": [node_json],
        "meshes": [{"name": "tri", "primitives": [{"attributes": {"POSITION": positions}, "indices": indices}]}],
    }))
}

fn write(dir: &tempfile::TempDir, name: &str, document: &Value) -> PathBuf {
    let path = dir.path().join(name);
    std::fs::write(&path, serde_json::to_vec_pretty(document).unwrap()).unwrap();
    path
}

/// The error message of loading `path`, which must fail and name the file.
fn load_error(path: &Path) -> String {
    let message = match GltfAsset::load(path) {
        Ok(_) => panic!("{} loaded", path.display()),
        Err(e) => e.to_string(),
    };
    let file = path.file_name().unwrap().to_str().unwrap();
    assert!(message.contains(file), "{message:?} does not name {file}");
    message
}

#[test]
fn a_mirrored_node_keeps_the_outward_side_facing_out() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        &dir,
        "mirror.gltf",
        &triangle_file(&[0, 1, 2], json!({"scale": [-1.0, 1.0, 1.0]})),
    );
    let asset = GltfAsset::load(&path).unwrap();
    assert_eq!(asset.report().mirrored_objects, 1);
    let poses = asset.pose_at(0.0).unwrap();
    let Pose::Rigid(t) = poses[0] else {
        panic!("rigid")
    };
    assert!(t.matrix3.determinant() > 0.0);
    let world = world_positions(&asset, &poses, 0);
    let expected: Vec<Vec3> = TRIANGLE
        .iter()
        .map(|p| *p * Vec3::new(-1.0, 1.0, 1.0))
        .collect();
    for p in &expected {
        assert!(
            world.iter().any(|w| w.abs_diff_eq(*p, 1e-6)),
            "{p} missing from {world:?}"
        );
    }
    // Mirroring in X leaves a Z-facing triangle facing +Z (glTF §3.7.2.1):
    // the posed triangle must still wind counter-clockwise seen from +Z.
    let [a, b, c] = asset.instances[0].mesh.triangles()[0].map(|i| world[i as usize]);
    assert!((b - a).cross(c - a).z > 0.0);
    let camera = Camera::new(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, Vec3::Y, 0.8, 8, 8).unwrap();
    let (objects, frames) = asset.to_scene_parts(lambert(), 30.0, 10).unwrap();
    let scene = Scene::new("mirror", objects, frames, camera).unwrap();
    let geometry = scene.frame_geometry(0).unwrap();
    assert!(geometry.objects[0].normals()[0].z > 0.99);
}

#[test]
fn strips_become_triangles_and_points_are_skipped() {
    let mut tiny = Tiny::default();
    let quad = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, 0.0)];
    let positions = tiny.vec3s(&quad);
    let document = tiny.document(json!({
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [
            {"attributes": {"POSITION": positions}, "mode": 5},
            {"attributes": {"POSITION": positions}, "mode": 0},
        ]}],
    }));
    let dir = tempfile::tempdir().unwrap();
    let asset = GltfAsset::load(&write(&dir, "strip.gltf", &document)).unwrap();
    let report = asset.report();
    assert_eq!(
        (report.converted_primitives, report.skipped_primitives),
        (1, 1)
    );
    let mesh = asset.meshes().next().unwrap();
    assert_eq!(mesh.triangle_count(), 2);
    // Both strip triangles keep the strip's facing (+Z here).
    assert!(
        mesh.normals().iter().all(|n| n.z > 0.99),
        "{:?}",
        mesh.normals()
    );

    let points_only = tiny.document(json!({
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": positions}, "mode": 0}]}],
    }));
    let message = load_error(&write(&dir, "points.gltf", &points_only));
    assert!(message.contains("no node"), "{message}");
}

/// A two-joint skin over a triangle; `weights` per vertex as VEC4.
fn skinned_triangle(weights: &[f32], joints: &[u16]) -> Value {
    let mut tiny = Tiny::default();
    let positions = tiny.vec3s(&TRIANGLE);
    let joints = tiny.u16s(joints, "VEC4", 4);
    let weights = tiny.floats(weights, "VEC4", 4);
    tiny.document(json!({
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [
            {"mesh": 0, "skin": 0, "translation": [5.0, 0.0, 0.0]},
            {"translation": [0.0, 2.0, 0.0], "children": [2]},
            {"translation": [0.0, 0.0, 3.0]},
        ],
        "skins": [{"joints": [1, 2]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": positions, "JOINTS_0": joints, "WEIGHTS_0": weights}}]}],
    }))
}

#[test]
fn joint_weights_are_renormalized_and_checked() {
    let dir = tempfile::tempdir().unwrap();
    // Vertex 0 half on joint 0 (sum 0.5), vertex 1 split 1:3 (sum 2), vertex 2 exact.
    let weights = [0.5, 0.0, 0.0, 0.0, 0.5, 1.5, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
    let joints = [0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0];
    let asset = GltfAsset::load(&write(
        &dir,
        "skin.gltf",
        &skinned_triangle(&weights, &joints),
    ))
    .unwrap();
    assert_eq!(asset.report().renormalized_weights, 2);
    let poses = asset.pose_at(0.0).unwrap();
    let skinned = deformed(&poses[0]);
    // No inverse bind matrices: identity. Joint 0 at (0, 2, 0), joint 1 at
    // (0, 2, 3); the node's own (5, 0, 0) is ignored.
    let (j0, j1) = (Vec3::new(0.0, 2.0, 0.0), Vec3::new(0.0, 2.0, 3.0));
    assert_relative_eq!(skinned[0], TRIANGLE[0] + j0, epsilon = 1e-6);
    assert_relative_eq!(
        skinned[1],
        TRIANGLE[1] + 0.25 * j0 + 0.75 * j1,
        epsilon = 1e-6
    );
    assert_relative_eq!(skinned[2], TRIANGLE[2] + j1, epsilon = 1e-6);

    let unweighted = [0.0; 12];
    let message = load_error(&write(
        &dir,
        "unweighted.gltf",
        &skinned_triangle(&unweighted, &joints),
    ));
    assert!(
        message.contains("vertex 0 has no joint weight"),
        "{message}"
    );
    let far_joint = [0, 1, 0, 0, 0, 7, 0, 0, 0, 1, 0, 0];
    let message = load_error(&write(
        &dir,
        "far_joint.gltf",
        &skinned_triangle(&weights, &far_joint),
    ));
    assert!(message.contains("joint 7"), "{message}");
}

#[test]
fn missing_truncated_and_malformed_files_are_named_errors() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.glb");
    assert!(matches!(GltfAsset::load(&missing), Err(Error::Io { .. })));
    load_error(&missing);

    let glb = std::fs::read(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/meshes/bunny_npm_1839v.glb"),
    )
    .unwrap();
    for keep in [10, 100, glb.len() / 2, glb.len() - 4] {
        let path = dir.path().join(format!("truncated_{keep}.glb"));
        std::fs::write(&path, &glb[..keep]).unwrap();
        load_error(&path);
    }
    // A header declaring fewer bytes than the header itself.
    for length in [0u32, 11] {
        let mut short = glb.clone();
        short[8..12].copy_from_slice(&length.to_le_bytes());
        let path = dir.path().join(format!("short_{length}.glb"));
        std::fs::write(&path, &short).unwrap();
        assert!(load_error(&path).contains("less than the header"));
    }

    let path = dir.path().join("broken.gltf");
    std::fs::write(
        &path,
        br#"{"asset": {"version": "2.0"}, "nodes": [{"mesh": 0}"#,
    )
    .unwrap();
    load_error(&path);
}

#[test]
fn out_of_range_indices_and_accessors_are_named_errors() {
    let dir = tempfile::tempdir().unwrap();
    let message = load_error(&write(
        &dir,
        "index.gltf",
        &triangle_file(&[0, 1, 5], json!({})),
    ));
    assert!(
        message.contains("\"tri\"") && message.contains("out of range"),
        "{message}"
    );

    // An accessor claiming more elements than its buffer view holds.
    let mut document = triangle_file(&[0, 1, 2], json!({}));
    document["accessors"][1]["count"] = json!(300);
    let message = load_error(&write(&dir, "accessor.gltf", &document));
    assert!(
        message.contains("accessor 1") && message.contains("buffer view"),
        "{message}"
    );

    // A reference to an accessor that does not exist.
    let mut document = triangle_file(&[0, 1, 2], json!({}));
    document["meshes"][0]["primitives"][0]["indices"] = json!(9);
    load_error(&write(&dir, "reference.gltf", &document));

    // A buffer shorter than it declares.
    let mut document = triangle_file(&[0, 1, 2], json!({}));
    document["buffers"][0]["byteLength"] = json!(4096);
    let message = load_error(&write(&dir, "short.gltf", &document));
    assert!(message.contains("buffer 0"), "{message}");
}

#[test]
fn required_extensions_are_refused_by_name_unless_supported() {
    let dir = tempfile::tempdir().unwrap();
    for extension in ["KHR_draco_mesh_compression", "EXT_made_up"] {
        let mut document = triangle_file(&[0, 1, 2], json!({}));
        document["extensionsUsed"] = json!([extension]);
        document["extensionsRequired"] = json!([extension]);
        let message = load_error(&write(&dir, "compressed.gltf", &document));
        assert!(
            message.contains(&format!("unsupported extension {extension}")),
            "{message}"
        );
    }
    for extension in super::SUPPORTED_EXTENSIONS {
        let mut document = triangle_file(&[0, 1, 2], json!({}));
        document["extensionsUsed"] = json!([extension]);
        document["extensionsRequired"] = json!([extension]);
        GltfAsset::load(&write(&dir, "supported.gltf", &document)).unwrap();
    }
}

#[test]
fn integer_positions_need_mesh_quantization() {
    let dir = tempfile::tempdir().unwrap();
    let mut tiny = Tiny::default();
    let corners: [u16; 9] = [0, 0, 0, 4, 0, 0, 0, 4, 0];
    let positions = tiny.u16s(&corners, "VEC3", 3);
    tiny.accessors[positions]["min"] = json!([0, 0, 0]);
    tiny.accessors[positions]["max"] = json!([4, 4, 0]);
    let mut document = tiny.document(json!({
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "scale": [0.25, 0.25, 0.25]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": positions}}]}],
    }));
    let message = load_error(&write(&dir, "plain.gltf", &document));
    assert!(message.contains("KHR_mesh_quantization"), "{message}");

    document["extensionsUsed"] = json!(["KHR_mesh_quantization"]);
    document["extensionsRequired"] = json!(["KHR_mesh_quantization"]);
    let asset = GltfAsset::load(&write(&dir, "quantized.gltf", &document)).unwrap();
    let mesh = asset.meshes().next().unwrap();
    assert_eq!(mesh.positions()[1], Vec3::new(4.0, 0.0, 0.0));
    let Pose::Rigid(world) = asset.pose_at(0.0).unwrap()[0] else {
        panic!("a rigid node")
    };
    assert_eq!(world.transform_point3(mesh.positions()[2]), Vec3::Y);
}

#[test]
fn accessors_without_a_buffer_view_are_zeros() {
    let dir = tempfile::tempdir().unwrap();
    let mut tiny = Tiny::default();
    let positions = tiny.vec3s(&TRIANGLE);
    tiny.accessors
        .push(json!({"componentType": 5126, "type": "VEC3", "count": 3}));
    let zeros = tiny.accessors.len() - 1;
    let document = tiny.document(json!({
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": positions}, "targets": [{"POSITION": zeros}]}],
                    "weights": [1.0]}],
    }));
    let asset = GltfAsset::load(&write(&dir, "zeros.gltf", &document)).unwrap();
    assert_eq!(asset.meshes().next().unwrap().positions(), &TRIANGLE[..]);
}

#[test]
fn colours_and_application_attributes_are_read_per_object() {
    let dir = tempfile::tempdir().unwrap();
    let mut tiny = Tiny::default();
    let positions = tiny.vec3s(&TRIANGLE);
    let ao = tiny.floats(&[0.25, 0.5, 1.0], "SCALAR", 1);
    let colours = tiny.floats(&[0.1; 12], "VEC4", 4);
    let document = tiny.document(json!({
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [{"mesh": 0}, {"mesh": 1}],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": positions, "_AO": ao, "COLOR_0": colours}}]},
            {"primitives": [
                {"attributes": {"POSITION": positions, "_AO": ao}},
                {"attributes": {"POSITION": positions}}
            ]}
        ],
    }));
    let asset = GltfAsset::load(&write(&dir, "attributes.gltf", &document)).unwrap();
    let read = asset.vertex_attribute(0, "_AO").unwrap();
    assert_eq!(
        (read.components, &read.values[..]),
        (1, &[0.25, 0.5, 1.0][..])
    );
    assert_eq!(asset.vertex_attribute(0, "COLOR_0").unwrap().components, 4);
    // Object 1's second primitive has no _AO: per vertex it is unknown.
    assert!(asset.vertex_attribute(1, "_AO").is_none());
    let sources: Vec<_> = asset.sources().collect();
    assert_eq!(sources[1].primitives, vec![(0, 3), (1, 3)]);
}

#[test]
fn animations_that_break_the_rules_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut tiny = Tiny::default();
    let positions = tiny.vec3s(&TRIANGLE);
    let times = tiny.floats(&[0.0, 1.0, 0.5], "SCALAR", 1);
    let values = tiny.floats(&[0.0; 9], "VEC3", 3);
    let document = tiny.document(json!({
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": positions}}]}],
        "animations": [{"name": "bad", "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}],
                        "samplers": [{"input": times, "output": values}]}],
    }));
    let message = load_error(&write(&dir, "unsorted.gltf", &document));
    assert!(
        message.contains("bad") && message.contains("not increasing"),
        "{message}"
    );

    let mut document = document;
    document["nodes"][0]["matrix"] = json!(Mat4::IDENTITY.to_cols_array());
    document["accessors"][times]["count"] = json!(2);
    document["accessors"][values]["count"] = json!(2);
    let message = load_error(&write(&dir, "matrix.gltf", &document));
    assert!(message.contains("matrix"), "{message}");

    let mut document = triangle_file(
        &[0, 1, 2],
        json!({"matrix": [1.0, 0.0, 0.0, 0.5, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]}),
    );
    document["nodes"][0]["name"] = json!("projective");
    let message = load_error(&write(&dir, "projective.gltf", &document));
    assert!(message.contains("not affine"), "{message}");
}
