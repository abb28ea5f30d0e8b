//! Property tests over random small scenes: one to three spheres, boxes or
//! grids of `shadow_core::shapes`, each turned and placed at random, sized
//! over six orders of magnitude (scenes from about 1 mm to 1 km across, their
//! objects 0.1 to 3 times that), sometimes moving over a second frame,
//! sometimes deforming, sometimes glossy, under a uniform sky, a vertical
//! gradient, or a sun disc 8° to 20° in radius 400 times brighter than the
//! dim sky around it.
//!
//! One method of each family runs on every scene through [`run::run`],
//! against a cheap reference (`ReferenceSettings::replicated(16, 2, seed)`),
//! and must
//!
//! * not panic;
//! * return a finite radiance at every vertex, and a finite error in every
//!   frame;
//! * stay between 0 and the light the scene would reflect with nothing in
//!   the way, to within the tolerance below (shadowing only removes light);
//! * refuse a scene that needs a capability it lacks, and when it refuses
//!   one, or fails, say why by naming the capability, or the object, mesh
//!   or environment at fault.
//!
//! Each case is one `u64` seed, printed with the scene when a property
//! fails; `RANDOM_SCENES_SEED=0x…` replays it alone (with `--nocapture`, each
//! method's worst excess over its bound), `RANDOM_SCENES_CASES=N` runs N
//! cases instead of 16. The seeds are the same on every run (proptest's
//! stream from a fixed seed): the test checks a fixed set of scenes;
//! `PROPTEST_RNG_SEED=N` draws others.
//!
//! # The bound
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
//! times n·r, which near grazing views falls far below the true integral:
//! the reference came out at 3.4 times `unshadowed` on a glossy sphere
//! 186 m across under the sun (seed 0xe15accfe282d85d7), and every method
//! came out around the reference there, not around `unshadowed`.
//!
//! α takes errors proportional to a vertex's own light (a quadrature's
//! cosine taken at a direction's centre, Monte-Carlo noise), β those
//! proportional to the strongest light in the scene, which the brightest
//! vertex reflects: SH ringing and light leaking from a sun. (Against the
//! mean of `B` instead of its maximum, a sun scene whose vertices mostly
//! face away from the sun has a small mean and the same ringing.)
//!
//! # Tolerances, and what was measured
//!
//! Measured with this test (debug build, GPU methods on Mesa's lavapipe)
//! over 3500 random scenes (seeds drawn by proptest) in three runs, and 800
//! more whose every object was glossy and lit by the sun: the largest β
//! each method needed at the α chosen, against the β allowed (about twice
//! that or more, rounded up). Not every α was measured on every scene: α =
//! 0.1 on 2300, α = 2 on 1200 of the mixed scenes and on the glossy ones.
//!
//! | family | light | surface | α | β allowed | β needed |
//! |---|---|---|---:|---:|---:|
//! | SH transfer (`hemi-raster`, `:flat`) | uniform, gradient | both | 0.1 | 0.05 | 0.019 (glossy; Lambert never above `B`) |
//! | | sun | Lambert | 1 | 0.25 | 0.096 |
//! | | sun | Phong | 2 | 0.4 | 0.182 |
//! | `occlusion-query:k=66` | uniform, gradient | both | 0.1 | 0.05 | 0.017 |
//! | | sun | Lambert | 0.5 | 0.4 | 0.324 (a 7 mm grid beside a 0.3 mm one, seed 0x60f0b38671e7477b; otherwise 0.117) |
//! | | sun | Phong | 1 | 0.2 | 0.091 |
//! | `deferred-shadow:q=8` | uniform, gradient | both | 0.25 | 0.05 | 0.013 |
//! | | sun | Lambert | 0.5 | 0.1 | 0.001 |
//! | | sun | Phong | 2 | 0.2 | 0.085 |
//! | `raytrace:4` | uniform, gradient | Lambert | 0.5 | 0.1 | below `B` |
//! | | uniform, gradient | Phong | 2 | 0.2 | below `B` |
//! | | sun | Lambert | 1 | 0.35 | 0.176 |
//! | | sun | Phong | 2 | 0.1 | 0.034 |
//!
//! Why they differ:
//!
//! * Under smooth light the deterministic methods stay within 10%
//!   (`hemi-raster`, `occlusion-query`) or 25% (`deferred-shadow`) of `B`
//!   plus 2% of `B_max`; on Lambert surfaces `hemi-raster` never exceeded
//!   `B` at all.
//! * A sun rings in SH. `hemi-raster` multiplies order-5 transfer and
//!   lighting, which cannot hold a disc of a few degrees: Lambert vertices
//!   came out at up to 1.8 times `B` (a grid beside a glossy one, seed
//!   0x8c4bc37ad28a58a3), and up to 0.77 `B_max` above 1.25 `B`.
//! * Glossy surfaces under the sun are where the SH methods stray most.
//!   `hemi-raster`'s glossy SH path, which its README documents as 43% off
//!   under `studio` at exponent 20, and `deferred-shadow`'s 16-term glossy
//!   transfer returned up to 3.2 and 3.5 times `B` on vertices whose `B`
//!   was at least a tenth of `B_max`, among them every vertex of lone,
//!   unoccluded glossy grids (seeds 0x1a3503300cdfc0d1 and 0x9e3fbd149c90fadc for
//!   `hemi-raster`, 139% and 113% error against the reference;
//!   0x89dd427d1fcb878b and 0x5e237f38a96bc8b8 for `deferred-shadow`, 3.0
//!   and 2.7 times `B`): hence α = 2 there. The bound then only guards
//!   against worse.
//! * `occlusion-query:k=66` and `deferred-shadow:q=8` gather the light into
//!   66 directions (the environment blurred over each cell, a vertex's sum
//!   divided by its own quadrature of the cosine) or 8 area lights, and
//!   weigh each by the cosine at its centre: a sun filling part of a cell
//!   is counted as if it stood at the cell's centre.
//! * `raytrace:4` is unbiased but draws 4 cosine and 4 environment samples
//!   per vertex: single vertices came out at 2.2 times `B` under the sun
//!   (seed 0xebc29a199fc6eaa5), and it has no sample from the Phong lobe,
//!   so glossy vertices are noisier still (up to 0.45 `B_max` above 2 `B`
//!   under smooth light, 2.5 times `B` under the sun).
//!
//! No method returned a negative value: the lower bound has no tolerance.

use std::{
    cell::RefCell,
    sync::{Arc, OnceLock},
};

use glam::{Affine3A, Quat, Vec3};
use harness::{
    methods::{self, SharedGpu},
    reference::{self, ReferenceSettings},
    run::{self, References},
};
use indicatif::ProgressBar;
use proptest::test_runner::{Config as ProptestConfig, RngSeed, TestCaseError, TestRunner};
use rand_core::Rng;
use rand_pcg::Pcg32;
use shadow_core::{
    Brdf, Camera, Capabilities, Environment, Error, Frame, Mesh, Object, Pose, Scene,
    VertexRadiance, gpu::test_context, shapes,
};

/// One method of each family, at settings cheap enough for a debug build.
const METHODS: &[&str] = &[
    "unshadowed",
    "hemi-raster",
    "hemi-raster:flat",
    "occlusion-query:k=66",
    "deferred-shadow:q=8",
    "raytrace:4",
];

/// Cases per run: each runs every method.
const CASES: u32 = 16;

fn is_gpu(method: &str) -> bool {
    matches!(family(method), Family::Directions | Family::AreaLights)
}

/// α and β of the bound `L ≤ B · (1 + α) + β · B_max`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Tolerance {
    alpha: f32,
    beta: f32,
}

/// How a method gets its light, which sets how far it may stray above `B`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Family {
    /// `unshadowed`, the bound itself.
    Bound,
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
    if method.starts_with("hemi-raster") {
        Family::Sh
    } else if method.starts_with("occlusion-query") {
        Family::Directions
    } else if method.starts_with("deferred-shadow") {
        Family::AreaLights
    } else if method.starts_with("raytrace") {
        Family::MonteCarlo
    } else {
        Family::Bound
    }
}

/// The tolerance of `method` under `light` on a Lambert or a glossy
/// surface (the table in the module's documentation).
fn tolerance(method: &str, light: Light, glossy: bool) -> Tolerance {
    let sun = light == Light::Sun;
    let (alpha, beta) = match (family(method), sun, glossy) {
        (Family::Sh, false, _) => (0.1, 0.05),
        (Family::Sh, true, false) => (1.0, 0.25),
        (Family::Sh, true, true) => (2.0, 0.4),
        (Family::Directions, false, _) => (0.1, 0.05),
        (Family::Directions, true, false) => (0.5, 0.4),
        (Family::Directions, true, true) => (1.0, 0.2),
        (Family::AreaLights, false, _) => (0.25, 0.05),
        (Family::AreaLights, true, false) => (0.5, 0.1),
        (Family::AreaLights, true, true) => (2.0, 0.2),
        (Family::MonteCarlo, false, false) => (0.5, 0.1),
        (Family::MonteCarlo, false, true) => (2.0, 0.2),
        (Family::MonteCarlo, true, false) => (1.0, 0.35),
        (Family::MonteCarlo, true, true) => (2.0, 0.1),
        (Family::Bound, _, _) => (0.0, 0.0),
    };
    Tolerance { alpha, beta }
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

/// Checks `shading` against `bound` with `method`'s tolerances; returns the
/// worst excess `(L − B · (1 + α)) / B_max` over the β allowed (the bound
/// holds while it is at most 1) and the object where it was, or what broke
/// the bound.
fn check_bound(
    method: &str,
    case: &Case,
    shading: &VertexRadiance,
    bound: &[Vec<Vec3>],
    reference: &[Vec<Vec3>],
) -> Result<(f32, String), String> {
    let top = brightest(bound);
    let mut worst = (f32::NEG_INFINITY, String::new());
    for (o, object) in case.scene.objects().iter().enumerate() {
        let tolerance = tolerance(method, case.light, object.material.is_glossy());
        let name = object.mesh.name();
        for (v, (l, b)) in shading.radiance[o].iter().zip(&bound[o]).enumerate() {
            if shading.evaluated.as_ref().is_some_and(|e| !e[o][v]) {
                continue;
            }
            let r = reference[o][v];
            if l.min_element() < 0.0 {
                return Err(format!("{name} vertex {v}: {l} is negative"));
            }
            let allowed = *b * (1.0 + tolerance.alpha) + tolerance.beta * top;
            if l.cmpgt(allowed).any() {
                return Err(format!(
                    "{name} vertex {v}: {l} above {allowed} \
                     (bound {b}, reference {r}, brightest bound {top}, {tolerance:?})"
                ));
            }
            let excess = (*l - *b * (1.0 + tolerance.alpha)) / top / tolerance.beta;
            if excess.max_element() > worst.0 {
                worst = (
                    excess.max_element(),
                    format!("{name} vertex {v}: {l:.3} against bound {b:.3}"),
                );
            }
        }
    }
    Ok(worst)
}

/// A refusal must name the capability the method lacks (and the scene must
/// need it), or the object, mesh or environment at fault.
fn names_what_is_at_fault(error: &Error, scene: &Scene, environment: &Environment) -> bool {
    let message = error.to_string();
    if let Error::Unsupported { capability, .. } = error {
        return message.contains(&capability.to_string())
            && Capabilities::needed_by(scene).contains(capability);
    }
    scene
        .objects()
        .iter()
        .any(|o| message.contains(o.mesh.name()))
        || message.contains(environment.name())
        || Capabilities::needed_by(scene)
            .iter()
            .any(|c| message.contains(&c.to_string()))
}

/// Every method on the scene of `seed`, and the properties.
fn check_scene(seed: u64) -> Result<(), TestCaseError> {
    let case = random_case(seed);
    let (scene, environment) = (&case.scene, &case.environment);
    eprintln!("{}", case.text);
    let fail = |what: String| TestCaseError::fail(format!("{}\n{what}", case.text));
    let bar = ProgressBar::hidden();
    let settings = ReferenceSettings::replicated(16, 2, seed);
    let (references, _) = reference::scene_references(scene, environment, &settings, None, &bar)
        .map_err(|e| fail(format!("reference: {e}")))?;
    let reference = &references.last().expect("a frame").radiance.radiance;
    let mut bound: Option<Vec<Vec<Vec3>>> = None;
    let cpu_only = SharedGpu::new();
    for &name in METHODS {
        let gpu = if is_gpu(name) { gpu() } else { &cpu_only };
        let mut method =
            methods::by_name(name, gpu).map_err(|e| fail(format!("{name} does not build: {e}")))?;
        let lacks = Capabilities::needed_by(scene)
            .into_iter()
            .find(|c| !method.capabilities().has(*c));
        let run = run::run(
            method.as_mut(),
            scene,
            environment,
            References::vertices(&references),
            1,
        );
        let result = match (run, lacks) {
            (Ok(result), None) => result,
            (Ok(_), Some(capability)) => {
                return Err(fail(format!(
                    "{name} ran a scene that needs {capability}, which it lacks"
                )));
            }
            (Err(e), _) => {
                eprintln!("  {name}: refused: {e}");
                if !names_what_is_at_fault(&e, scene, environment) {
                    return Err(fail(format!(
                        "{name} failed without naming the capability or input at fault: {e}"
                    )));
                }
                continue;
            }
        };
        for (frame, stats) in result.frames.iter().enumerate() {
            if !stats.vertex.relative_l2.is_finite() {
                return Err(fail(format!(
                    "{name}: frame {frame}'s error is {}",
                    stats.vertex.relative_l2
                )));
            }
        }
        let error = result.mean_error();
        let shading = result.last_shading.expect("a frame was shaded");
        if let Some((v, l)) = shading.flat().enumerate().find(|(_, l)| !l.is_finite()) {
            return Err(fail(format!(
                "{name}: vertex {v} (over all objects) is {l}"
            )));
        }
        let Some(bound) = &bound else {
            // The light with nothing in the way: unshadowed's, or where the
            // reference (shadows and all) is brighter, the reference's.
            let larger = shading
                .radiance
                .iter()
                .zip(reference)
                .map(|(u, r)| u.iter().zip(r).map(|(u, r)| u.max(*r)).collect())
                .collect();
            bound = Some(larger);
            continue;
        };
        let (worst, at) = check_bound(name, &case, &shading, bound, reference)
            .map_err(|what| fail(format!("{name}: {what}")))?;
        eprintln!(
            "  {name}: error {error:.3} against the reference; worst excess {worst:.2} of the β allowed, at {at}"
        );
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
