//! Property tests over random small scenes: one to three spheres, boxes or
//! grids of `shadow_core::shapes`, each turned and placed at random, sized
//! over six orders of magnitude (scenes from about 1 mm to 1 km across, their
//! objects 0.1 to 3 times that), sometimes moving over a second frame,
//! sometimes deforming, sometimes glossy, under a uniform sky, a vertical
//! gradient, or a sun disc 8° to 20° in radius 400 times brighter than the
//! dim sky around it.
//!
//! A method or two of each family runs on every scene, stage by stage, against a
//! cheap reference (`ReferenceSettings::replicated(16, 2, seed)`), and on
//! every frame must
//!
//! * not panic;
//! * return a finite, non-negative radiance at every vertex;
//! * stay under the light the scene would reflect with nothing in the way,
//!   to within the tolerance below (shadowing only removes light);
//! * stay within its family's relative L2 error of the reference, and
//!   return in all at least `1 − dark` of the reference's light per channel
//!   (a method returning nothing fails here);
//! * run a scene only with every capability it needs, and refuse one
//!   otherwise with [`Error::Unsupported`] naming a capability it lacks and
//!   the scene needs: any other failure fails the test.
//!
//! Each case is one `u64` seed, printed with the scene when a property
//! fails; `RANDOM_SCENES_SEED=0x…` replays it alone (with `--nocapture`,
//! what each method needed of each bound), `RANDOM_SCENES_CASES=N` runs N
//! cases instead of 16. The seeds are the same on every run (proptest's
//! stream from a fixed seed): the test checks a fixed set of scenes;
//! `PROPTEST_RNG_SEED=N` draws others.
//!
//! # The bounds
//!
//! Per vertex and channel, with `B` the light with nothing in the way and
//! `B_max` its largest value over the scene's vertices (per channel):
//!
//! `0 ≤ L ≤ B · (1 + α) + β · B_max`
//!
//! `B` is what `unshadowed` returns (order-9 SH lighting, no visibility),
//! or the reference where that is larger. The reference includes shadows,
//! so it is below the unoccluded light too, up to its noise. For Lambert
//! surfaces `unshadowed` is exact to below a percent, and the reference
//! (32 iterations a vertex) scatters a few percent around it where nothing
//! occludes: taking the larger loosens the bound by that much at most. For
//! Phong surfaces `unshadowed` evaluates the lobe at the mirror direction
//! times n·r, which near grazing views falls far below the true integral
//! (the reference came out at 3.4 times it on a glossy sphere under the
//! sun, seed 0xe15accfe282d85d7).
//!
//! α takes errors proportional to a vertex's own light (a quadrature's
//! cosine taken at a direction's centre, Monte-Carlo noise), β those
//! proportional to the strongest light in the scene, which the brightest
//! vertex reflects: SH ringing and light leaking from a sun.
//!
//! The error is `score::vertices`' relative L2 against the cheap
//! reference, whose own noise is part of it (a few percent; tens of percent
//! on glossy surfaces under a sun). Scenes with a glossy object take the
//! glossy row for all their objects.
//!
//! # Tolerances, and what was measured
//!
//! Measured with this test (release build, GPU methods on Mesa's lavapipe,
//! AMD EPYC host) over 3200 random scenes, 200 from each of
//! `PROPTEST_RNG_SEED` 1 to 16: per family, light (uniform and gradient
//! pooled as smooth) and surface, the largest β needed at the α chosen, the
//! largest relative L2 error and darkness (1 − the method's total light
//! over the reference's), with the seed where each was largest. Allowed: β
//! and the error twice the largest (β at least 0.02), the darkness the
//! largest plus 0.2, rounded up. Under the sun the error and the
//! darkness are not bounded: every family's worst cases there have long
//! tails, and batches of fresh scenes kept finding larger ones (their seeds
//! are in docs/measurements.md), while under smooth light only a grouped
//! scene did. A method returning too little still fails on the smooth
//! scenes, which every method runs but for the deforming ones
//! `deferred-shadow` refuses. The fixed seeds the test runs pass;
//! other seeds may find further cases under the sun: findings about the
//! methods, to be recorded with their seeds.
//!
//! | family | light | surface | α | β allowed (needed) | error allowed (largest) | dark allowed (largest) |
//! |---|---|---|---:|---:|---:|---:|
//! | SH transfer (`hemi-raster`, `:flat`) | smooth | Lambert | 0.1 | 0.02 (never above `B`) | 0.18 (0.089, 0xc657bb14f9907ed8) | 0.23 (0.025) |
//! | | smooth | glossy | 0.1 | 0.05 (0.024, 0xc23ed94a7c895759) | 0.27 (0.134, 0x8ac81f853b13d12c) | 0.23 (0.024) |
//! | | sun | Lambert | 1 | 0.05 (0.021, 0xce817b452dddacd6) | none (0.688, 0xa3e6e699cd069294) | none (0.648, 0xf7dda54d1f8ddcd3) |
//! | | sun | glossy | 2 | 0.46 (0.230, 0xd847b73fb7d91cfd) | none (1.80, 0xe72b9f19c7d4d2b9) | none (0.319, 0xaa0d7415c2eb8cc5) |
//! | `occlusion-query:k=66` | smooth | Lambert | 0.1 | 0.02 (never above `B`) | 1.8 (0.869, 0x4d559bf38b18fa90; otherwise 0.21) | 0.24 (0.033) |
//! | | smooth | glossy | 0.1 | 0.07 (0.031, 0xc23ed94a7c895759) | 0.47 (0.235, 0xd02b205dba197462) | 0.25 (0.048) |
//! | | sun | Lambert | 0.5 | 1.0 (0.50, 0x27df640661809db8; otherwise 0.177) | none (0.744, 0x80189cef40fdcfa0) | none (0.251, 0x511f7dead2183cab) |
//! | | sun | glossy | 1 | 0.08 (0.039, 0x42dcb42d1add2976) | none (0.703, 0xe72b9f19c7d4d2b9) | none (0.292, 0xdbd560695ffacfd8) |
//! | `deferred-shadow:q=8` | smooth | Lambert | 0.25 | 0.02 (never above `B`) | 0.87 (0.483, 0x7722262bab0c4f23; grouped 3.70, 0x349fd861dfb2f4c2) | 0.33 (0.126, 0x749b6881cabb6410) |
//! | | smooth | glossy | 0.25 | 0.05 (0.022, 0x0d0316fb88c24b5f) | 0.82 (0.546, 0x7158be85220d1ca8; grouped 4.87, 0xd02b205dba197462) | 0.33 (0.129, 0x8c220f02e0de20c8) |
//! | | sun | Lambert | 0.5 | 0.04 (0.016, 0x268567dcc97af44a) | none (0.710, 0xbe9d7701cf442d89; grouped 2.84, 0x4134b92d6e5f5591) | none (0.430, 0x832af024e5da7bb0) |
//! | | sun | glossy | 2 | 1.0 (0.50, 0xb0831c0dc4ca7063; 0.220 in the 3200) | none (1.89, 0xe72b9f19c7d4d2b9; grouped 5.17, 0xa301f08750b2efb6) | none (0.410, 0x1a75e2932ba21701) |
//! | `raytrace:4` | smooth | Lambert | 0.5 | 0.02 (never above `B`) | 0.54 (0.266) | 0.26 (0.052) |
//! | | smooth | glossy | 2 | 0.02 (never above `B`) | 0.97 (0.481, 0x8ac81f853b13d12c) | 0.31 (0.101) |
//! | | sun | Lambert | 1 | 0.13 (0.063, 0xa7a8592a6f4455a9) | none (1.10, 0x247e1b53c7cb99c7; 0.391 in the 3200) | none (0.112) |
//! | | sun | glossy | 2 | 0.02 (never above `B`) | none (0.695, 0xe72b9f19c7d4d2b9) | none (0.125) |
//!
//! What the largest ones are:
//!
//! * `deferred-shadow`'s rows were measured again with its occluder depth
//!   per texel, over 3123 of the scenes (the batch of seed 7 stops at
//!   0x4d559bf38b18fa90, where `hemi-raster` now comes out at 56%), each
//!   frame's groups taken as the method forms them at that frame: its
//!   darkness fell (0.227 and 0.241 before) and its largest errors on
//!   scenes without groups rose (0.432 and 0.407 before; the allowances
//!   kept hold them). The largest are too bright: 0x7722262bab0c4f23,
//!   three objects about 1 mm across, 23% brighter than the reference in
//!   all, and 0x7158be85220d1ca8, a box over a glossy grid, 27%.
//! * `deferred-shadow`'s errors of several hundred percent are objects
//!   inside or through a larger one (0x4d559bf38b18fa90: a 6.6 m sphere and
//!   a 12 m grid in an 84 m box): their bounding boxes overlap, so they
//!   form one occluder group, whose members cast nothing on each other,
//!   and the enclosed ones get the unoccluded light, 13 times the
//!   reference on that sphere, an error with no bound as the reference
//!   goes dark. On such scenes (grouped: 1283 of its 3501 frames in the 3123) its
//!   error is not bounded; its upper bound and darkness are.
//! * `occlusion-query`'s 87% is the same scene: the enclosed sphere got 3.3
//!   times its reference light; `hemi-raster` 3.7% there.
//! * The SH methods are darkest and furthest off under the sun: order-5
//!   transfer cannot hold a disc of a few degrees (0x832af024e5da7bb0:
//!   `hemi-raster` 43% darker than the reference in all). On glossy
//!   surfaces the truncated lobe rings as well (0xe72b9f19c7d4d2b9, a
//!   0.2 mm glossy sphere: 180% error, where `raytrace:4`, unbiased, is 69%
//!   off the cheap reference too).
//! * No method returned a negative value.

use std::{
    cell::RefCell,
    sync::{Arc, OnceLock},
};

use glam::{Affine3A, Quat, Vec3};
use harness::{
    methods::{self, SharedGpu},
    reference::{self, ReferenceSettings, VertexReference},
    score,
};
use indicatif::ProgressBar;
use proptest::test_runner::{Config as ProptestConfig, RngSeed, TestCaseError, TestRunner};
use rand_core::Rng;
use rand_pcg::Pcg32;
use shadow_core::{
    Brdf, Camera, Capabilities, Environment, Error, Frame, Mesh, Object, Pose, Scene, ShadowMethod,
    VertexRadiance, gpu::test_context, shapes,
};

/// One method of each family, at settings cheap enough for a debug build.
const METHODS: &[&str] = &[
    "hemi-raster",
    "hemi-raster:flat",
    "occlusion-query:k=66",
    "deferred-shadow:q=8",
    "raytrace:4",
];

/// Cases per run: each runs every method.
const CASES: u32 = 16;

fn is_gpu(method: &str) -> bool {
    methods::parse(method).expect("a valid name").needs_gpu()
}

/// What a method may return on a frame: per vertex at most
/// `B · (1 + alpha) + beta · B_max`, a relative L2 error against the
/// reference of at most `error`, and in all at least `1 − dark` of the
/// reference's light (per channel).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Tolerance {
    alpha: f32,
    beta: f32,
    error: f32,
    dark: f32,
}

/// How a method gets its light, which sets how far it may stray.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Family {
    /// SH transfer: `hemi-raster`.
    Sh,
    /// Visibility toward a lightsphere: `occlusion-query`.
    Directions,
    /// Self-transfer in SH and occlusion maps per area light:
    /// `deferred-shadow`.
    AreaLights,
    /// `raytrace`.
    MonteCarlo,
}

fn family(method: &str) -> Family {
    match methods::parse(method).expect("a valid name").family() {
        "hemi-raster" => Family::Sh,
        "occlusion-query" => Family::Directions,
        "deferred-shadow" => Family::AreaLights,
        "raytrace" => Family::MonteCarlo,
        other => panic!("no tolerance is set for the {other} family"),
    }
}

/// The tolerance of `method` under `light` on a scene with or without a
/// glossy object (the table in the module's documentation).
fn tolerance(method: &str, light: Light, glossy: bool) -> Tolerance {
    let sun = light == Light::Sun;
    let (alpha, beta, error, dark) = match (family(method), sun, glossy) {
        (Family::Sh, false, false) => (0.1, 0.02, 0.18, 0.23),
        (Family::Sh, false, true) => (0.1, 0.05, 0.27, 0.23),
        (Family::Sh, true, false) => (1.0, 0.05, f32::INFINITY, f32::INFINITY),
        (Family::Sh, true, true) => (2.0, 0.46, f32::INFINITY, f32::INFINITY),
        (Family::Directions, false, false) => (0.1, 0.02, 1.8, 0.24),
        (Family::Directions, false, true) => (0.1, 0.07, 0.47, 0.25),
        (Family::Directions, true, false) => (0.5, 1.0, f32::INFINITY, f32::INFINITY),
        (Family::Directions, true, true) => (1.0, 0.08, f32::INFINITY, f32::INFINITY),
        (Family::AreaLights, false, false) => (0.25, 0.02, 0.87, 0.33),
        (Family::AreaLights, false, true) => (0.25, 0.05, 0.82, 0.33),
        (Family::AreaLights, true, false) => (0.5, 0.04, f32::INFINITY, f32::INFINITY),
        (Family::AreaLights, true, true) => (2.0, 1.0, f32::INFINITY, f32::INFINITY),
        (Family::MonteCarlo, false, false) => (0.5, 0.02, 0.54, 0.26),
        (Family::MonteCarlo, false, true) => (2.0, 0.02, 0.97, 0.31),
        (Family::MonteCarlo, true, false) => (1.0, 0.13, f32::INFINITY, f32::INFINITY),
        (Family::MonteCarlo, true, true) => (2.0, 0.02, f32::INFINITY, f32::INFINITY),
    };
    Tolerance {
        alpha,
        beta,
        error,
        dark,
    }
}

/// The device every GPU method of this test binary shares, opened once
/// ([`test_context`]: without an adapter the test fails, naming what to
/// install).
fn gpu() -> &'static SharedGpu {
    static GPU: OnceLock<SharedGpu> = OnceLock::new();
    GPU.get_or_init(|| SharedGpu::with(test_context()))
}

/// Uniform draws from a seeded stream.
struct Draw(Pcg32);

impl Draw {
    fn new(seed: u64) -> Draw {
        Draw(Pcg32::new(seed, 0x0a02_bdbf_7bb3_c0a7))
    }

    /// Uniform in [0, 1).
    fn unit(&mut self) -> f32 {
        (self.0.next_u32() >> 8) as f32 / (1u32 << 24) as f32
    }

    fn range(&mut self, low: f32, high: f32) -> f32 {
        low + (high - low) * self.unit()
    }

    /// 10^x for x uniform in [low, high).
    fn decades(&mut self, low: f32, high: f32) -> f32 {
        10f32.powf(self.range(low, high))
    }

    fn below(&mut self, n: u32) -> u32 {
        self.0.next_u32() % n
    }

    fn chance(&mut self, p: f32) -> bool {
        self.unit() < p
    }

    /// A uniformly distributed rotation (Shoemake's method).
    fn rotation(&mut self) -> Quat {
        let (u1, u2, u3) = (self.unit(), self.unit(), self.unit());
        let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
        let (t2, t3) = (std::f32::consts::TAU * u2, std::f32::consts::TAU * u3);
        Quat::from_xyzw(a * t2.sin(), a * t2.cos(), b * t3.sin(), b * t3.cos()).normalize()
    }

    fn direction(&mut self) -> Vec3 {
        self.rotation() * Vec3::Z
    }
}

/// The kind of light a random scene is under.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Light {
    Uniform,
    Gradient,
    Sun,
}

/// A random scene, its environment, and a line saying what they are.
struct Case {
    scene: Scene,
    environment: Environment,
    light: Light,
    text: String,
}

/// The scene and environment of `seed`.
fn random_case(seed: u64) -> Case {
    let mut draw = Draw::new(seed);
    let scale = draw.decades(-3.0, 3.0);
    let count = 1 + draw.below(3) as usize;
    let moving = draw.chance(0.3);
    let deforming = draw.chance(0.15);
    let mut objects = Vec::new();
    let (mut first, mut second) = (Vec::new(), Vec::new());
    let mut described = Vec::new();
    for i in 0..count {
        let size = scale * draw.decades(-1.0, 0.5);
        let mesh = random_mesh(&mut draw, i, size);
        let material = random_material(&mut draw);
        let place = Affine3A::from_rotation_translation(
            draw.rotation(),
            scale
                * Vec3::new(
                    draw.range(-0.6, 0.6),
                    draw.range(-0.3, 0.6),
                    draw.range(-0.6, 0.6),
                ),
        );
        let step = Affine3A::from_rotation_translation(
            Quat::from_axis_angle(draw.direction(), draw.range(0.0, 0.5)),
            scale * 0.2 * draw.direction(),
        );
        let deformed = deforming && i == 0;
        described.push(format!(
            "{} ({} v, {size:.3e} m{}{})",
            mesh.name(),
            mesh.vertex_count(),
            if material.is_glossy() { ", glossy" } else { "" },
            if deformed { ", deforming" } else { "" },
        ));
        if deformed {
            // A ripple across the object, its phase moving between frames.
            let ripple = |t: Affine3A, phase: f32| Pose::Deformed {
                positions: mesh
                    .positions()
                    .iter()
                    .map(|p| {
                        let lift = 0.05 * size * (phase + 6.0 * p.x / size).sin();
                        t.transform_point3(*p + Vec3::Y * lift)
                    })
                    .collect(),
                normals: None,
            };
            first.push(ripple(place, 0.0));
            second.push(ripple(step * place, 1.0));
        } else {
            first.push(Pose::Rigid(place));
            second.push(Pose::Rigid(step * place));
        }
        objects.push(Object {
            mesh: Arc::new(mesh),
            material,
        });
    }
    let mut frames = vec![Frame {
        time: 0.0,
        poses: first,
    }];
    if moving {
        frames.push(Frame {
            time: 0.1,
            poses: second,
        });
    }
    let name = format!("random-{seed:016x}");
    let camera = Camera::new(Vec3::Z, Vec3::ZERO, Vec3::Y, 0.8, 64, 48).expect("a camera");
    let placed =
        Scene::new(&name, objects.clone(), frames.clone(), camera).expect("a valid random scene");
    let bounds = placed.frame_geometry(0).expect("a rigid frame").bounds();
    let mut from = draw.direction();
    from.y = from.y.abs() + 0.2;
    let camera = Camera::framing(bounds.center(), bounds.diagonal() * 0.5, from, 64, 48)
        .expect("a finite, non-empty scene");
    let scene = placed.with_camera(camera);
    let (environment, light) = random_environment(&mut draw);
    let text = format!(
        "seed {seed:#018x}: {} frame(s), under {}: {}",
        scene.frames().len(),
        environment.name(),
        described.join(", ")
    );
    Case {
        scene,
        environment,
        light,
        text,
    }
}

/// A sphere, box or grid about the origin, `size` across, named after its
/// kind and `index`.
fn random_mesh(draw: &mut Draw, index: usize, size: f32) -> Mesh {
    match draw.below(3) {
        0 => {
            let (rings, segments) = (4 + draw.below(9), 6 + draw.below(15));
            let name = format!("sphere-{index}");
            let mesh = shapes::uv_sphere(&name, Vec3::ZERO, 0.5 * size, rings, segments);
            mesh.expect("a valid sphere")
        }
        1 => {
            let half = 0.5
                * size
                * Vec3::new(
                    draw.range(0.1, 1.0),
                    draw.range(0.1, 1.0),
                    draw.range(0.1, 1.0),
                );
            let name = format!("box-{index}");
            let mesh = shapes::cuboid(&name, -half, half, false);
            mesh.expect("a valid box")
        }
        _ => {
            let (nu, nv) = (1 + draw.below(8), 1 + draw.below(8));
            let (u, v) = (size, size * draw.range(0.2, 1.0));
            let (du, dv) = (Vec3::Z * u / nu as f32, Vec3::X * v / nv as f32);
            let origin = -0.5 * (Vec3::Z * u + Vec3::X * v);
            let name = format!("grid-{index}");
            let mesh = shapes::grid(&name, origin, du, dv, nu, nv);
            mesh.expect("a valid grid")
        }
    }
}

/// White-ish Lambert, or one time in four a Phong of exponent 2 to 16.
fn random_material(draw: &mut Draw) -> Brdf {
    let albedo = Vec3::new(
        draw.range(0.2, 1.0),
        draw.range(0.2, 1.0),
        draw.range(0.2, 1.0),
    );
    if draw.chance(0.25) {
        let share = draw.range(0.1, 0.6);
        Brdf::phong(
            albedo * (1.0 - share),
            albedo * share,
            draw.range(2.0, 16.0),
        )
        .expect("a valid Phong")
    } else {
        Brdf::lambert(albedo).expect("a valid albedo")
    }
}

/// A uniform sky, a vertical gradient, or a sun 8° to 20° in radius over a
/// dim sky, at a brightness 0.1 to 10.
fn random_environment(draw: &mut Draw) -> (Environment, Light) {
    let brightness = draw.decades(-1.0, 1.0);
    let colour = Vec3::new(
        draw.range(0.3, 1.0),
        draw.range(0.3, 1.0),
        draw.range(0.3, 1.0),
    ) * brightness;
    let (w, h) = (64, 32);
    let map = |name: &str, radiance: &dyn Fn(Vec3) -> Vec3| {
        let blank = Environment::new(name, w, h, vec![Vec3::ZERO; w * h]).unwrap();
        let texels = (0..w * h)
            .map(|i| radiance(blank.direction(i / w, i % w)))
            .collect();
        Environment::new(name, w, h, texels).expect("finite radiance")
    };
    match draw.below(3) {
        0 => (
            Environment::uniform(colour).renamed("uniform"),
            Light::Uniform,
        ),
        1 => {
            let ground = colour * draw.range(0.0, 0.5);
            let gradient = map("gradient", &|d| ground.lerp(colour, 0.5 * (d.y + 1.0)));
            (gradient, Light::Gradient)
        }
        _ => {
            let toward = draw.direction();
            let radius = draw.range(8.0, 20.0).to_radians();
            let disc = colour * 20.0;
            let sky = colour * 0.05;
            let sun = map("sun", &move |d| {
                if d.dot(toward) >= radius.cos() {
                    disc
                } else {
                    sky
                }
            });
            (sun, Light::Sun)
        }
    }
}

/// Per channel, the largest value of any vertex (at least the smallest
/// positive float).
fn brightest(values: &[Vec<Vec3>]) -> Vec3 {
    values
        .iter()
        .flatten()
        .fold(Vec3::splat(f32::MIN_POSITIVE), |a, b| a.max(*b))
}

/// A refusal is accepted only as [`Error::Unsupported`] naming a capability
/// the method lacks and the scene needs.
fn is_a_capability_refusal(error: &Error, method: &dyn ShadowMethod, scene: &Scene) -> bool {
    match error {
        Error::Unsupported { capability, .. } => {
            !method.capabilities().has(*capability)
                && Capabilities::needed_by(scene).contains(capability)
        }
        _ => false,
    }
}

/// `method` through prepare and relight, then update and shade on every
/// frame: each frame's shading.
fn shade_frames(
    method: &mut dyn ShadowMethod,
    scene: &Scene,
    environment: &Environment,
) -> shadow_core::Result<Vec<VertexRadiance>> {
    method.prepare(scene)?;
    method.relight(environment)?;
    (0..scene.frames().len())
        .map(|f| {
            method.update(&scene.frame_geometry(f)?, scene.camera())?;
            method.shade(scene.camera().eye)
        })
        .collect()
}

/// Per channel, the sum over the vertices.
fn total(values: &[Vec<Vec3>]) -> Vec3 {
    values.iter().flatten().sum()
}

/// What one method needed on one frame, to compare with its tolerance.
#[derive(Clone, Copy, Debug)]
struct Needed {
    /// The β the upper bound needed at the family's α.
    beta: f32,
    /// The relative L2 error against the reference.
    error: f32,
    /// 1 − its total light over the reference's, in the worst channel.
    dark: f32,
}

/// Checks one frame's `shading` against `bound`, the unoccluded light, and
/// against the `reference`; returns what the frame needed, or what broke.
fn check_frame(
    tolerance: &Tolerance,
    case: &Case,
    shading: &VertexRadiance,
    bound: &[Vec<Vec3>],
    reference: &VertexReference,
) -> Result<Needed, String> {
    let top = brightest(bound);
    let mut beta = f32::NEG_INFINITY;
    for (o, object) in case.scene.objects().iter().enumerate() {
        let name = object.mesh.name();
        for (v, (l, b)) in shading.radiance[o].iter().zip(&bound[o]).enumerate() {
            if shading.evaluated.as_ref().is_some_and(|e| !e[o][v]) {
                continue;
            }
            if !l.is_finite() || l.min_element() < 0.0 {
                return Err(format!("{name} vertex {v}: {l}"));
            }
            let excess = ((*l - *b * (1.0 + tolerance.alpha)) / top).max_element();
            beta = beta.max(excess);
            if excess > tolerance.beta {
                let r = reference.radiance.radiance[o][v];
                return Err(format!(
                    "{name} vertex {v}: {l} above the unoccluded light {b} \
                     (reference {r}, brightest bound {top}, {tolerance:?})"
                ));
            }
        }
    }
    let error = score::vertices(shading, reference).relative_l2;
    let (got, expected) = (
        total(&shading.radiance),
        total(&reference.radiance.radiance),
    );
    let dark = (Vec3::ONE - got / expected.max(Vec3::splat(f32::MIN_POSITIVE))).max_element();
    if error.is_nan() || error > tolerance.error {
        return Err(format!(
            "relative L2 error {error} against the reference, above {tolerance:?}"
        ));
    }
    if dark > tolerance.dark {
        return Err(format!(
            "{got} in all against the reference's {expected}: darker than {tolerance:?}"
        ));
    }
    Ok(Needed { beta, error, dark })
}

/// Whether `deferred-shadow` puts two of the scene's objects in one
/// occluder group at `frame` (its groups follow the objects), whose
/// members cast nothing on each other: its error is not bounded there.
fn grouped(scene: &Scene, frame: usize) -> bool {
    let grouping = deferred_shadow::Config::default().grouping;
    let groups =
        deferred_shadow::Groups::of_frame(&grouping, scene, frame).expect("overlap groups");
    groups.members.iter().any(|members| members.len() > 1)
}

/// Every method on the scene of `seed`, and the properties, on every frame.
fn check_scene(seed: u64) -> Result<(), TestCaseError> {
    let case = random_case(seed);
    let (scene, environment) = (&case.scene, &case.environment);
    eprintln!("{}", case.text);
    let fail = |what: String| TestCaseError::fail(format!("{}\n{what}", case.text));
    let bar = ProgressBar::hidden();
    let settings = ReferenceSettings::replicated(16, 2, seed);
    let (references, _) = reference::scene_references(scene, environment, &settings, None, &bar)
        .map_err(|e| fail(format!("reference: {e}")))?;
    let cpu_only = SharedGpu::new();
    let glossy = scene.objects().iter().any(|o| o.material.is_glossy());
    // The light with nothing in the way, per frame: unshadowed's, or where
    // the reference (shadows and all) is brighter, the reference's.
    let mut unshadowed = methods::by_name("unshadowed", &cpu_only).expect("unshadowed builds");
    let bounds: Vec<Vec<Vec<Vec3>>> = shade_frames(unshadowed.as_mut(), scene, environment)
        .map_err(|e| fail(format!("unshadowed: {e}")))?
        .iter()
        .zip(&references)
        .map(|(u, r)| {
            u.radiance
                .iter()
                .zip(&r.radiance.radiance)
                .map(|(u, r)| u.iter().zip(r).map(|(u, r)| u.max(*r)).collect())
                .collect()
        })
        .collect();
    for &name in METHODS {
        let gpu = if is_gpu(name) { gpu() } else { &cpu_only };
        let mut method =
            methods::by_name(name, gpu).map_err(|e| fail(format!("{name} does not build: {e}")))?;
        let lacks = Capabilities::needed_by(scene)
            .into_iter()
            .find(|c| !method.capabilities().has(*c));
        let shadings = match (shade_frames(method.as_mut(), scene, environment), lacks) {
            (Ok(shadings), None) => shadings,
            (Ok(_), Some(capability)) => {
                return Err(fail(format!(
                    "{name} ran a scene that needs {capability}, which it lacks"
                )));
            }
            (Err(e), _) if is_a_capability_refusal(&e, method.as_ref(), scene) => {
                eprintln!("  {name}: refused: {e}");
                continue;
            }
            (Err(e), _) => {
                return Err(fail(format!(
                    "{name} failed, or refused without naming a capability it lacks and the scene needs: {e}"
                )));
            }
        };
        for (frame, shading) in shadings.iter().enumerate() {
            let grouped = grouped(scene, frame);
            let mut tolerance = tolerance(name, case.light, glossy);
            if family(name) == Family::AreaLights && grouped {
                tolerance.error = f32::INFINITY;
            }
            let needed = check_frame(
                &tolerance,
                &case,
                shading,
                &bounds[frame],
                &references[frame],
            )
            .map_err(|what| fail(format!("{name}, frame {frame}: {what}")))?;
            eprintln!(
                "  {name}, frame {frame}: β {:.3} of {}, error {:.3} of {}, dark {:.3} of {} \
                 [{:?} {:?} {}{}]",
                needed.beta,
                tolerance.beta,
                needed.error,
                tolerance.error,
                needed.dark,
                tolerance.dark,
                family(name),
                case.light,
                if glossy { "glossy" } else { "lambert" },
                if grouped { " grouped" } else { "" }
            );
        }
    }
    Ok(())
}

#[test]
#[cfg_attr(
    skip_gpu_tests,
    ignore = "needs a GPU adapter (SOFT_SHADOWS_SKIP lists gpu)"
)]
fn every_method_stays_finite_and_under_the_unoccluded_light_on_random_scenes() {
    // Opened before the cases, so that a missing adapter fails here.
    let _ = gpu();
    let replay = std::env::var("RANDOM_SCENES_SEED").ok().map(|s| {
        u64::from_str_radix(s.trim_start_matches("0x"), 16)
            .unwrap_or_else(|_| panic!("RANDOM_SCENES_SEED={s}: not a hexadecimal u64"))
    });
    if let Some(seed) = replay {
        check_scene(seed).unwrap_or_else(|e| panic!("{e}"));
        return;
    }
    let cases = std::env::var("RANDOM_SCENES_CASES")
        .ok()
        .and_then(|c| c.parse().ok())
        .unwrap_or(CASES);
    // A case is a seed: shrinking it gives an unrelated scene, and the
    // failure message names the seed to replay, so no regression file.
    let mut config = ProptestConfig {
        failure_persistence: None,
        max_shrink_iters: 0,
        ..ProptestConfig::with_cases(cases)
    };
    // The same seeds on every run unless PROPTEST_RNG_SEED asks for others.
    if config.rng_seed == RngSeed::Random {
        config.rng_seed = RngSeed::Fixed(0x5eed_5ce9e);
    }
    let runs = RefCell::new(0);
    let outcome = TestRunner::new(config).run(&proptest::num::u64::ANY, |seed| {
        *runs.borrow_mut() += 1;
        check_scene(seed)
    });
    if let Err(e) = outcome {
        panic!("{e}");
    }
    assert_eq!(runs.into_inner(), cases);
}

/// The checks themselves: a method that returns nothing, or half the light,
/// fails them on a scene under smooth light, and only a capability the
/// method lacks and the scene needs is an accepted refusal.
#[test]
fn the_checks_refuse_a_method_that_returns_nothing() {
    let case = (0..)
        .map(random_case)
        .find(|c| c.light == Light::Uniform && c.scene.frames().len() == 1)
        .expect("a still scene under a uniform sky");
    let (scene, environment) = (&case.scene, &case.environment);
    let settings = ReferenceSettings::replicated(16, 2, 1);
    let bar = ProgressBar::hidden();
    let (references, _) =
        reference::scene_references(scene, environment, &settings, None, &bar).unwrap();
    let cpu = SharedGpu::new();
    let mut unshadowed = methods::by_name("unshadowed", &cpu).unwrap();
    let unshadowed = shade_frames(unshadowed.as_mut(), scene, environment).unwrap();
    let bound: Vec<Vec<Vec3>> = unshadowed[0]
        .radiance
        .iter()
        .zip(&references[0].radiance.radiance)
        .map(|(u, r)| u.iter().zip(r).map(|(u, r)| u.max(*r)).collect())
        .collect();
    let glossy = scene.objects().iter().any(|o| o.material.is_glossy());
    for name in METHODS {
        let tolerance = tolerance(name, case.light, glossy);
        // The reference's estimates are unbiased around the known unoccluded
        // light, so a vertex in full shadow may come out a hair below zero:
        // clamped, as a method's output would be.
        let scaled = |factor: f32| VertexRadiance {
            radiance: references[0]
                .radiance
                .radiance
                .iter()
                .map(|o| o.iter().map(|r| r.max(Vec3::ZERO) * factor).collect())
                .collect(),
            std_error: None,
            evaluated: None,
        };
        let check = |shading: &VertexRadiance| {
            check_frame(&tolerance, &case, shading, &bound, &references[0])
        };
        assert!(check(&scaled(1.0)).is_ok(), "{name}: the reference itself");
        assert!(check(&scaled(0.0)).is_err(), "{name}: nothing");
        assert!(check(&scaled(0.5)).is_err(), "{name}: half the light");
    }
    let method = methods::by_name("hemi-raster", &cpu).unwrap();
    let refusals = [
        Error::InvalidScene("uniform".into()),
        Error::Unsupported {
            method: "hemi-raster".into(),
            capability: shadow_core::Capability::PerPixel,
        },
    ];
    for refusal in refusals {
        assert!(!is_a_capability_refusal(&refusal, method.as_ref(), scene));
    }
}
